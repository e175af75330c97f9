"""Bags of several depth cameras (issue 46): ``record --bag`` writes each camera's
images on its own topics, ``track --bag`` takes each as a camera of the model
(``--depth-topic NAME=TOPIC``), and the round trip gives the estimates of
``track --run`` on the same run; bad camera topics are one-line errors. Each camera's
true frame hangs on ``/tf`` from its depth frame, the truth's hand pose in the first's."""

import dataclasses
import json

import numpy as np
import pytest

pytest.importorskip("rosbags")

from cli_runs import assert_one_line_error, run_cli  # noqa: E402
from test_bag_truth import check_truth_under_tf  # noqa: E402
from test_estimates_bag import (  # noqa: E402
    drake_hand_in_nominal,
    hand_under_tf,
    offset_of,
    positions_from_csv,
    read_bag,
    transform_of,
)
from two_cameras import recorded_two_cameras  # noqa: E402

from drake_tracker.io.bag_source import BagSource, BagTopics, CameraTopics  # noqa: E402
from drake_tracker.io.estimates_out import read_estimates_csv  # noqa: E402
from drake_tracker.io.replay import model_for_run  # noqa: E402
from drake_tracker.io.run_bag import write_run_bag  # noqa: E402
from drake_tracker.robot.model import camera_offset_transform  # noqa: E402

DEPTH = ["--depth-topic", "camera=/camera/depth/image_raw",
         "--depth-topic", "post_camera=/post_camera/depth/image_raw"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """1.5 s of a two-camera preset, stamped in ns, as a run, a bag, a robot file and
    the test's parameters."""
    folder = tmp_path_factory.mktemp("two_cameras")
    run = recorded_two_cameras(folder, 10**9)
    write_run_bag(run, folder / "run.mcap")
    return run, folder


def test_each_camera_has_its_own_topics_in_the_bag(recorded):
    run, folder = recorded
    model = model_for_run(run)
    source = BagSource(folder / "run.mcap", model.robot_joint_names, BagTopics(cameras=(
        CameraTopics("camera", "/camera/depth/image_raw"),
        CameraTopics("post_camera", "/post_camera/depth/image_raw"))))
    try:
        assert [c.camera_info_topic for c in source.cameras] == [
            "/camera/depth/camera_info", "/post_camera/depth/camera_info"]
        assert source.camera_models() == {"camera": run.camera_intrinsics,
                                          "post_camera": run.other_cameras[0].intrinsics}
        images = [e for e in source.events() if hasattr(e, "depth")]
    finally:
        source.close()
    for name, capture, depth in (
            ("camera", run.image_capture_times_s, run.depth_images_m),
            ("post_camera", run.other_cameras[0].capture_times_s,
             run.other_cameras[0].depth_images_m)):
        mine = [e for e in images if e.camera == name]
        assert [e.sequence for e in mine] == list(range(len(capture)))
        np.testing.assert_array_equal([e.capture_s for e in mine], capture)
        np.testing.assert_array_equal(np.stack([e.depth for e in mine]), depth)


def test_each_cameras_true_frame_is_on_tf(recorded):
    """/tf: per truth sample, each camera's true offset from its depth frame in the bag
    to ``NAME_true``; /truth/hand_pose in ``camera_true``, and under /tf the hand in the
    first camera's nominal frame (by Drake at the true angles, and as the run's own
    arrays compose)."""
    run, folder = recorded
    model = model_for_run(run)
    frames = [("camera", "camera_depth_optical_frame", "camera_true"),
              ("post_camera", "post_camera_depth_optical_frame", "post_camera_true")]
    assert model.camera_names == [name for name, _, _ in frames]
    [post] = run.other_cameras
    assert np.any(post.truth_camera_offset != run.truth_camera_offset)  # its own
    topics = check_truth_under_tf(model, run, folder / "run.mcap", frames)
    for k, ((_, tf), (_, pose)) in enumerate(zip(topics["/tf"], topics["/truth/hand_pose"])):
        _, X = hand_under_tf(pose, tf)
        np.testing.assert_allclose(
            X, camera_offset_transform(run.truth_camera_offset[k]) @ run.truth_X_CE[k],
            rtol=0, atol=1e-9, err_msg=f"sample {k}")


def test_a_further_camera_without_its_true_offset_is_named(recorded, tmp_path):
    run, _ = recorded
    [post] = run.other_cameras
    broken = dataclasses.replace(run, other_cameras=[dataclasses.replace(post)])
    broken.other_cameras[0].truth_camera_offset = post.truth_camera_offset[:-1]
    with pytest.raises(ValueError, match=r"camera 'post_camera': its true camera offset "
                                         r"is missing .*'post_camera_true'"):
        write_run_bag(broken, tmp_path / "run.mcap")
    assert not list(tmp_path.iterdir())


def test_tracking_the_bag_gives_the_estimates_of_the_run(recorded, capsys):
    run, folder = recorded
    params = str(folder / "params.yaml")
    code, _, err = run_cli(["track", "--run", str(folder / "run.npz"), "--params", params,
                            "--out", str(folder / "from_run")], capsys)
    assert code == 0, err
    code, _, err = run_cli(["track", "--bag", str(folder / "run.mcap"), "--robot",
                            str(folder / "robot.yaml"), "--params", params, *DEPTH,
                            "--out", str(folder / "from_bag")], capsys)
    assert code == 0, err
    direct = json.loads((folder / "from_run" / "report.json").read_text())
    from_bag = json.loads((folder / "from_bag" / "report.json").read_text())
    assert direct["counts"] == from_bag["counts"]
    # Both cameras' images were taken: none skipped as an unknown camera's.
    assert direct["counts"]["images"] == len(run.image_capture_times_s) + len(
        run.other_cameras[0].capture_times_s)
    assert not direct["counts"]["source_skipped"]
    assert from_bag["input"]["cameras"]["post_camera"][1] == "/post_camera/depth/camera_info"
    a = read_estimates_csv(folder / "from_run" / "estimates.csv")
    b = read_estimates_csv(folder / "from_bag" / "estimates.csv")
    assert len(a["t_s"]) == len(run.reading_times_s)
    offsets = [c for c in a if c.startswith("post_camera_") and "_hand_" not in c]
    assert len(offsets) == 6 and np.any(a[offsets[0]] != 0.0)  # the second camera's own
    assert len([c for c in a if c.startswith("post_camera_hand_")]) == 7  # the hand there
    for column in a:
        if column in ("health", "t0_s"):
            continue
        np.testing.assert_allclose(b[column], a[column], rtol=0, atol=1e-9, err_msg=column)
    assert (a["health"] == b["health"]).all()
    # estimates.mcap: each camera's offset on /tf, as estimates.csv has it, from the
    # bag's frame id of the camera (a recorded run has none: the model's frame names).
    topics = read_bag(folder / "from_bag" / "estimates.mcap")
    tf = [m for _, m in topics["/tf"]]
    assert len(tf) == len(b["t_s"])
    frames = [("camera_depth_optical_frame", "camera_estimated"),
              ("post_camera_depth_optical_frame", "post_camera_estimated")]
    assert {tuple((t.header.frame_id, t.child_frame_id) for t in m.transforms)
            for m in tf} == {tuple(frames)}
    model = model_for_run(run)
    nominal = [(c.nominal_frame.name(), child) for c, (_, child) in zip(model.cameras,
                                                                         frames)]
    assert nominal != frames
    assert [(t.header.frame_id, t.child_frame_id) for t in read_bag(
        folder / "from_run" / "estimates.mcap")["/tf"][-1][1].transforms] == nominal
    for t, prefix in zip(tf[-1].transforms, ("camera_", "post_camera_")):
        csv = [b[prefix + c][-1] for c in ("x_m", "y_m", "z_m", "rx_rad", "ry_rad", "rz_rad")]
        np.testing.assert_allclose(offset_of(transform_of(t)), csv, rtol=0, atol=1e-12)
    # The hand pose, in the first camera's estimated frame, under /tf: the hand in the
    # bag's first camera frame as Drake's kinematics put it at the estimated positions.
    poses = [m for _, m in topics["/tracker/hand_pose"]]
    assert {p.header.frame_id for p in poses} == {"camera_estimated"}
    for row in (0, len(poses) // 2, len(poses) - 1):
        parent, X = hand_under_tf(poses[row], tf[row])
        assert parent == "camera_depth_optical_frame"
        np.testing.assert_allclose(
            X, drake_hand_in_nominal(model, positions_from_csv(model, b, row)),
            rtol=0, atol=1e-9, err_msg=f"row {row}")


@pytest.mark.parametrize("flags, fragment", [
    (["--depth-topic", "side=/camera/depth/image_raw"], "unknown camera 'side'"),
    (["--depth-topic", "camera=/camera/depth/image_raw",
      "--depth-topic", "camera=/post_camera/depth/image_raw"], "two cameras are named"),
    (["--depth-topic", "camera=/camera/depth/image_raw",
      "--depth-topic", "/post_camera/depth/image_raw"], "all NAME=TOPIC"),
    (["--depth-topic", "/camera/depth/image_raw",
      "--depth-topic", "/post_camera/depth/image_raw"], "name each camera"),
    ([*DEPTH, "--camera-info-topic", "side=/camera/depth/camera_info"],
     "no --depth-topic side=TOPIC"),
    (["--depth-topic", "camera=/nowhere"], "no depth (sensor_msgs/msg/Image, or "
     "sensor_msgs/msg/CompressedImage on .../compressedDepth) topic '/nowhere'"),
])
def test_bad_camera_topics_are_one_line_errors(recorded, capsys, flags, fragment):
    _, folder = recorded
    code, _, err = run_cli(["track", "--bag", str(folder / "run.mcap"), "--robot",
                            str(folder / "robot.yaml"), *flags], capsys)
    assert_one_line_error(code, err, fragment)


def test_a_camera_of_the_robot_without_a_depth_topic_is_named(recorded, capsys, caplog):
    """A two-camera robot tracked from the post camera's topic alone: it runs (a camera
    without images is allowed), and the warning names the head camera that gets none."""
    import logging

    _, folder = recorded
    with caplog.at_level(logging.WARNING):
        code, _, err = run_cli(["track", "--bag", str(folder / "run.mcap"), "--robot",
                                str(folder / "robot.yaml"), "--depth-topic",
                                "post_camera=/post_camera/depth/image_raw", "--out",
                                str(folder / "post_only")], capsys)
    assert code == 0, err
    assert "camera(s) ['camera'] have no --depth-topic" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        code, _, err = run_cli(["track", "--bag", str(folder / "run.mcap"), "--robot",
                                str(folder / "robot.yaml"), *DEPTH, "--out",
                                str(folder / "both")], capsys)
    assert code == 0, err
    assert "have no --depth-topic" not in caplog.text


def test_an_image_without_an_arrival_is_warned_when_the_bag_is_written(recorded, tmp_path,
                                                                       caplog):
    import logging

    run, _ = recorded
    post = run.other_cameras[0]
    arrivals = post.arrival_times_s.copy()
    arrivals[4] = np.nan
    broken = dataclasses.replace(run, other_cameras=[
        dataclasses.replace(post, arrival_times_s=arrivals)])
    with caplog.at_level(logging.WARNING):
        write_run_bag(broken, tmp_path / "broken.mcap")
    assert caplog.text.count("bag: 1 image(s) of camera 'post_camera' not written (4)") == 1
    source = BagSource(tmp_path / "broken.mcap", model_for_run(run).robot_joint_names,
                       BagTopics(cameras=(
                           CameraTopics("camera", "/camera/depth/image_raw"),
                           CameraTopics("post_camera", "/post_camera/depth/image_raw"))))
    try:
        images = [e for e in source.events() if hasattr(e, "depth")]
    finally:
        source.close()
    assert sum(e.camera == "post_camera" for e in images) == len(arrivals) - 1


def test_a_bag_is_calibrated_as_the_run_it_was_written_from(recorded, tmp_path, capsys):
    """``calibrate-cameras --bag`` reads each camera's depth topic as ``track --bag``
    does, and gives the calibration of the recorded run the bag was written from."""
    from cli_runs import run_cli

    from drake_tracker.params.loading import load_tracker_params

    run, folder = recorded
    window = ["--from", "0.3", "--to", "1.5", "--images-per-camera", "3",
              "--evaluations", "300", "--params", str(folder / "params.yaml")]
    code, _, err = run_cli(["calibrate-cameras", "--bag", str(folder / "run.mcap"),
                            "--robot", str(folder / "robot.yaml"), *DEPTH, *window,
                            "--out", str(tmp_path / "bag.yaml")], capsys)
    assert code == 0, err
    code, _, err = run_cli(["calibrate-cameras", "--run", str(folder / "run.npz"), *window,
                            "--out", str(tmp_path / "run.yaml")], capsys)
    assert code == 0, err
    from_bag = load_tracker_params(tmp_path / "bag.yaml").camera_offsets
    from_run = load_tracker_params(tmp_path / "run.yaml").camera_offsets
    assert sorted(from_bag) == ["camera", "post_camera"]
    for name in from_bag:
        np.testing.assert_allclose(from_bag[name], from_run[name], rtol=1e-5, atol=1e-9)
