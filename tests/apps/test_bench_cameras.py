"""``drake-tracker bench --only cameras``: an image update's cost with one camera at
30 Hz and with two at 15 Hz, from one two-camera recording (no time is asserted: the
bench measures, the tests check what it measures)."""

import json

import numpy as np

from drake_tracker.bench.cameras import every_other_image
from drake_tracker.cli.main import main
from drake_tracker.io.recording import CameraImages
from drake_tracker.io.synthetic import synthetic_run


def test_two_cameras_at_half_rate_keep_every_other_image_of_each(apollo):
    run = synthetic_run(apollo, duration_s=0.4, seed=3)
    T = len(run.truth_times_s)
    post = CameraImages("post", run.camera_intrinsics, run.image_capture_times_s + 0.01,
                        run.image_arrival_times_s + 0.01, run.depth_images_m.copy(),
                        np.zeros((T, 6)))
    two = run.__class__(**{**run.__dict__, "other_cameras": [post]})
    one = every_other_image(two, 1)
    assert one.other_cameras == [] and len(one.image_capture_times_s) == len(
        run.image_capture_times_s)
    half = every_other_image(two, 2)
    np.testing.assert_array_equal(half.image_capture_times_s, run.image_capture_times_s[::2])
    np.testing.assert_array_equal(half.other_cameras[0].capture_times_s,
                                  post.capture_times_s[::2])
    np.testing.assert_array_equal(half.other_cameras[0].depth_images_m,
                                  post.depth_images_m[::2])
    total = len(half.image_capture_times_s) + len(half.other_cameras[0].capture_times_s)
    assert abs(total - len(one.image_capture_times_s)) <= 1  # as many images per second


def test_the_bench_measures_one_camera_against_two(tmp_path, capsys):
    assert main(["bench", "--quick", "--only", "cameras", "--out", str(tmp_path)]) == 0
    assert "two cameras / one camera" in capsys.readouterr().out
    result = json.loads((tmp_path / "bench.json").read_text())["cameras"]
    one, two = result["one_camera_30hz"], result["two_cameras_15hz"]
    assert one["cameras"] == ["camera"] and two["cameras"] == ["camera", "post_camera"]
    assert abs(two["images_per_s"] / one["images_per_s"] - 1.0) < 0.05
    assert all(n > 0 for n in two["updates_per_camera"].values())
    assert one["updates"] == sum(one["updates_per_camera"].values()) > 0
    assert result["two_over_one_per_image"] == two["update_ms_mean"] / one["update_ms_mean"]
