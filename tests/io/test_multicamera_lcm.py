"""LCM logs of several depth cameras (issue 46): ``record --lcm-log`` writes each camera's
images on its own channel, ``DRAKE_RGBD_CAMERA_IMAGES_<name>`` as Drake's
``ApplyCameraConfig`` publishes them; ``track --lcm-log`` takes each as a camera of the
model (``--camera NAME=WxH:...``), and the round trip gives the estimates of
``track --run`` on the same run, bit for bit. Bad camera flags are one-line errors."""

import json
import logging
from collections import Counter

import numpy as np
import pytest

pytest.importorskip("lcm")

from cli_runs import assert_one_line_error, run_cli  # noqa: E402
from two_cameras import recorded_two_cameras  # noqa: E402

from drake_tracker.io.estimates_out import read_estimates_csv  # noqa: E402
from drake_tracker.io.lcm_log import LcmCamera, LcmLogSource, read_log  # noqa: E402
from drake_tracker.io.lcm_messages import camera_channel, camera_text  # noqa: E402
from drake_tracker.io.replay import model_for_run  # noqa: E402
from drake_tracker.io.run_lcm_log import image_channels, write_run_lcm_log  # noqa: E402

CAMERAS = ("camera", "post_camera")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """1.5 s of a two-camera preset, stamped in µs, as a run, an LCM log, a robot file
    and the test's parameters."""
    folder = tmp_path_factory.mktemp("two_cameras_lcm")
    run = recorded_two_cameras(folder, 10**6)
    write_run_lcm_log(run, folder / "run.lcmlog")
    return run, folder


def _camera_flags(run, names=CAMERAS):
    flags = []
    for name in names:
        flags += ["--camera", f"{name}={camera_text(run.intrinsics_by_camera[name])}"]
    return flags


def test_each_camera_has_its_own_channel(recorded):
    run, folder = recorded
    assert run.camera_names == list(CAMERAS)
    channels = image_channels(run)
    assert channels == {name: f"DRAKE_RGBD_CAMERA_IMAGES_{name}" for name in CAMERAS}
    counts = Counter(event.channel for event in read_log(folder / "run.lcmlog"))
    assert counts == {"IIWA_STATUS": len(run.reading_times_s),
                      channels["camera"]: len(run.image_capture_times_s),
                      channels["post_camera"]: len(run.other_cameras[0].capture_times_s)}
    model = model_for_run(run)
    source = LcmLogSource(folder / "run.lcmlog", model.robot_joint_names, [
        LcmCamera(name, camera_channel(name), run.intrinsics_by_camera[name])
        for name in CAMERAS])
    assert source.camera_models() == run.intrinsics_by_camera
    assert source.num_images == counts[channels["camera"]] + counts[channels["post_camera"]]
    images = [e for e in source.events() if hasattr(e, "depth")]
    t0 = run.reading_times_s[0]  # the log's time base: its first stamp
    for name, capture, arrival, depth in (
            ("camera", run.image_capture_times_s, run.image_arrival_times_s,
             run.depth_images_m),
            ("post_camera", run.other_cameras[0].capture_times_s,
             run.other_cameras[0].arrival_times_s, run.other_cameras[0].depth_images_m)):
        mine = [e for e in images if e.camera == name]
        order = np.argsort(arrival, kind="stable")
        assert [e.sequence for e in mine] == list(range(len(capture)))
        np.testing.assert_allclose([e.capture_s for e in mine], capture[order] - t0,
                                   rtol=0, atol=1e-9)
        np.testing.assert_allclose([e.arrival_s for e in mine], arrival[order] - t0,
                                   rtol=0, atol=1e-9)
        np.testing.assert_array_equal(np.stack([e.depth for e in mine]),
                                      depth[order].astype(np.float32))


def test_round_trip_gives_the_same_estimates(recorded, capsys):
    """``track --run`` and ``track --lcm-log`` with a ``--camera NAME=...`` per camera."""
    run, folder = recorded
    params = str(folder / "params.yaml")
    code, _, err = run_cli(["track", "--run", str(folder / "run.npz"), "--params", params,
                            "--out", str(folder / "from_run")], capsys)
    assert code == 0, err
    code, out, err = run_cli(["track", "--lcm-log", str(folder / "run.lcmlog"), "--robot",
                              str(folder / "robot.yaml"), *_camera_flags(run), "--params",
                              params, "--out", str(folder / "from_log")], capsys)
    assert code == 0, err
    assert ("DRAKE_RGBD_CAMERA_IMAGES_camera (camera), DRAKE_RGBD_CAMERA_IMAGES_post_camera "
            "(post_camera)") in out
    direct = json.loads((folder / "from_run" / "report.json").read_text())
    from_log = json.loads((folder / "from_log" / "report.json").read_text())
    assert direct["counts"] == from_log["counts"]
    assert direct["counts"]["images"] == len(run.image_capture_times_s) + len(
        run.other_cameras[0].capture_times_s)
    assert from_log["input"]["image_channels"] == image_channels(run)
    # Each camera's images, applied and skipped, adding up to the whole's.
    cameras = direct["counts"]["cameras"]
    assert {name: c["images"] for name, c in cameras.items()} == {
        "camera": len(run.image_capture_times_s),
        "post_camera": len(run.other_cameras[0].capture_times_s)}
    assert all(c["applied"] > 0 and c["applied"] + c["skipped"] == c["images"]
               for c in cameras.values())
    assert sum(c["applied"] for c in cameras.values()) == direct["counts"]["images_applied"]
    assert "  camera post_camera: " in out
    a = read_estimates_csv(folder / "from_run" / "estimates.csv")
    b = read_estimates_csv(folder / "from_log" / "estimates.csv")
    assert "post_camera_hand_x_m" in a and set(a) == set(b)
    assert len(a["t_s"]) == len(run.reading_times_s)
    for column in a:
        if column == "t0_s":
            continue
        if column == "health":
            assert (a[column] == b[column]).all()
            continue
        np.testing.assert_allclose(b[column], a[column], rtol=0, atol=1e-9, err_msg=column)


def test_a_camera_left_out_is_warned(recorded, capsys, caplog):
    run, folder = recorded
    with caplog.at_level(logging.WARNING):
        code, _, err = run_cli(["track", "--lcm-log", str(folder / "run.lcmlog"), "--robot",
                                str(folder / "robot.yaml"),
                                *_camera_flags(run, ["post_camera"]), "--params",
                                str(folder / "params.yaml")], capsys)
    assert code == 0, err
    assert "camera(s) ['camera'] have no --camera NAME=WxH" in caplog.text


def test_bad_camera_flags_are_one_line_errors(recorded, capsys):
    run, folder = recorded
    base = ["track", "--lcm-log", str(folder / "run.lcmlog"), "--robot",
            str(folder / "robot.yaml")]
    post = camera_text(run.other_cameras[0].intrinsics)
    cases = [
        (_camera_flags(run) + ["--camera", f"side={post}"],
         "unknown camera 'side': the model's cameras are ['camera', 'post_camera']"),
        (_camera_flags(run, ["post_camera", "post_camera"]),
         "two cameras are named 'post_camera'"),
        (_camera_flags(run) + ["--image-channel", "camera=X", "--image-channel",
                               "post_camera=X"], "image channel X is given for two cameras"),
        (_camera_flags(run, ["post_camera"]) + ["--camera", post],
         "either all WxH:fx,fy,cx,cy (one camera) or all NAME=WxH:fx,fy,cx,cy (several)"),
        (_camera_flags(run, ["post_camera"]) + ["--image-channel", "camera=X"],
         "--image-channel camera=...: no --camera camera=WxH:fx,fy,cx,cy"),
        (_camera_flags(run) + ["--image-channel", "post_camera=NOPE"],
         "has no channel 'NOPE' (--image-channel); its channels (messages): "
         "DRAKE_RGBD_CAMERA_IMAGES_camera"),
        (["--camera", "post_camera=80x60"],
         "camera 'post_camera': camera '80x60' is not WIDTHxHEIGHT:fx,fy,cx,cy"),
        (["--camera", post, "--camera", post], "several --camera or --image-channel: name "
                                               "each camera"),
    ]
    for flags, message in cases:
        code, _, err = run_cli(base + flags, capsys)
        assert_one_line_error(code, err, message)


def test_images_without_an_arrival_are_counted_or_warned_never_lost_silently(
        recorded, tmp_path, caplog):
    """An image stamped with no finite arrival cannot be played or written in arrival
    order: the replay counts it (each camera's), the LCM writer warns, per camera."""
    import dataclasses

    from drake_tracker.io.stream import SkippedMessage
    from drake_tracker.io.track_files import run_events

    run, _ = recorded
    first = run.image_arrival_times_s.copy()
    first[2] = np.nan
    post = run.other_cameras[0]
    arrivals = post.arrival_times_s.copy()
    arrivals[[1, 3]] = np.inf
    broken = dataclasses.replace(run, image_arrival_times_s=first, other_cameras=[
        dataclasses.replace(post, arrival_times_s=arrivals)])
    skipped = [e.why for e in run_events(broken) if isinstance(e, SkippedMessage)]
    assert len(skipped) == 3
    assert sum("of camera 'post_camera'" in why for why in skipped) == 2
    with caplog.at_level(logging.WARNING):
        write_run_lcm_log(broken, tmp_path / "broken.lcmlog")
    assert caplog.text.count("1 image(s) of camera 'camera' not written (2)") == 1
    assert "2 image(s) of camera 'post_camera' not written (1, 3)" in caplog.text
    counts = Counter(event.channel for event in read_log(tmp_path / "broken.lcmlog"))
    assert counts["DRAKE_RGBD_CAMERA_IMAGES_camera"] == len(first) - 1
    assert counts["DRAKE_RGBD_CAMERA_IMAGES_post_camera"] == len(arrivals) - 2


def test_an_lcm_log_is_calibrated_as_the_run_it_was_written_from(recorded, tmp_path,
                                                                 capsys):
    """``calibrate-cameras --lcm-log`` with a ``--camera NAME=...`` per camera gives the
    calibration of the recorded run the log was written from."""
    from drake_tracker.params.loading import load_tracker_params

    run, folder = recorded
    t0 = run.reading_times_s[0]  # the log's time base: its first stamp
    window = ["--images-per-camera", "3", "--evaluations", "300", "--params",
              str(folder / "params.yaml")]
    code, _, err = run_cli(["calibrate-cameras", "--lcm-log", str(folder / "run.lcmlog"),
                            "--robot", str(folder / "robot.yaml"), *_camera_flags(run),
                            "--from", f"{0.3 - t0}", "--to", f"{1.5 - t0}", *window,
                            "--out", str(tmp_path / "log.yaml")], capsys)
    assert code == 0, err
    code, _, err = run_cli(["calibrate-cameras", "--run", str(folder / "run.npz"),
                            "--from", "0.3", "--to", "1.5", *window,
                            "--out", str(tmp_path / "run.yaml")], capsys)
    assert code == 0, err
    from_log = load_tracker_params(tmp_path / "log.yaml").camera_offsets
    from_run = load_tracker_params(tmp_path / "run.yaml").camera_offsets
    assert sorted(from_log) == list(CAMERAS)
    for name in CAMERAS:
        np.testing.assert_allclose(from_log[name], from_run[name], rtol=1e-5, atol=1e-9)
