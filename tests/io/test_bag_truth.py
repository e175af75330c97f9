"""The truth in a ``record --bag`` bag (``io/run_bag.py``): ``/truth/hand_pose`` in the
first camera's true frame (``NAME_true``), which ``/tf`` hangs from the bag's depth
frame of the camera by the run's true camera offset, one ``TFMessage`` per truth sample
with a transform per camera; composed, the hand in the nominal camera frame as Drake's
kinematics give it at the true angles. A missing true offset is named before the bag is
made. (Two cameras: ``tests/io/test_multicamera_bags.py``; tracking such a bag:
``tests/io/test_bags.py``.)"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("rosbags")

from test_estimates_bag import (  # noqa: E402
    drake_hand_in_nominal,
    hand_under_tf,
    offset_of,
    pose_of,
    read_bag,
    transform_of,
)

from drake_tracker.core.filter.estimate import PoseReadout  # noqa: E402
from drake_tracker.io.run_bag import (  # noqa: E402
    CAMERA_FRAME,
    DEFAULT_BASE_NS,
    truth_tf_frames,
    write_run_bag,
)
from drake_tracker.io.synthetic import synthetic_run  # noqa: E402


@pytest.fixture(scope="module")
def run(apollo):
    return synthetic_run(apollo, duration_s=0.6, encoder_rate_hz=200.0,
                         seed=7).stamped_in_nanoseconds()


@pytest.fixture(scope="module")
def bag(run, tmp_path_factory):
    path = tmp_path_factory.mktemp("bag") / "run.mcap"
    write_run_bag(run, path)
    return path


def truth_positions(model, run, k, offsets):
    """Every joint of ``model`` at truth sample ``k``: the run's true angles, and each
    camera's virtual joints at its true offset (``offsets``: by camera name)."""
    q = np.zeros(model.num_joints)
    q[model.robot_joint_indices] = [run.truth_positions_rad[k, run.joint_names.index(n)]
                                    for n in model.robot_joint_names]
    for name, values in offsets.items():
        q[model.camera_joint_indices(name)] = values[k]
    return q


def check_truth_under_tf(model, run, path, frames):
    """The bag's ``/tf`` and ``/truth/hand_pose`` against the run: one TFMessage per truth
    sample holding one transform per camera (``frames``: [(name, parent, child)]), each
    the camera's true offset; the hand pose in the first camera's true frame, stamped and
    logged as its ``/tf``, and under it the hand in the nominal camera frame by Drake's
    kinematics at the true angles (independent of the offset); the pose alone is off by
    the offset. Returns the messages read."""
    topics = read_bag(path)
    tf, poses = topics["/tf"], topics["/truth/hand_pose"]
    T = len(run.truth_times_s)
    assert len(tf) == len(poses) == T
    assert {p.header.frame_id for _, p in poses} == {frames[0][2]}
    offsets = {run.camera_name: run.truth_camera_offset}
    offsets.update({c.name: c.truth_camera_offset for c in run.other_cameras})
    for k, ((tf_log, message), (pose_log, pose)) in enumerate(zip(tf, poses, strict=True)):
        stamp = DEFAULT_BASE_NS + round(run.truth_times_s[k] * 1e9)
        assert tf_log == pose_log == stamp
        assert pose.header.stamp.sec * 10**9 + pose.header.stamp.nanosec == stamp
        assert [(t.header.frame_id, t.child_frame_id) for t in message.transforms] == [
            (parent, child) for _, parent, child in frames]
        for (name, _, _), t in zip(frames, message.transforms):
            assert t.header.stamp.sec * 10**9 + t.header.stamp.nanosec == stamp
            np.testing.assert_allclose(offset_of(transform_of(t)), offsets[name][k],
                                       rtol=0, atol=1e-12, err_msg=f"{name} at {k}")
        parent, X = hand_under_tf(pose, message)
        assert parent == frames[0][1]
        expected = drake_hand_in_nominal(model, truth_positions(model, run, k, offsets))
        np.testing.assert_allclose(X, expected, rtol=0, atol=1e-9, err_msg=f"sample {k}")
        assert np.linalg.norm(pose_of(pose)[:3, 3] - expected[:3, 3]) > 1e-3
    return topics


def test_the_truth_hand_pose_is_in_the_true_camera_frame(run, bag, apollo, tmp_path):
    """The run's constant offset (1 cm, 1 deg), then an offset that changes at every
    truth sample (a few cm and degrees, X_CE recomputed): /tf carries each sample's."""
    frames = [("camera", CAMERA_FRAME, "camera_true")]
    assert [f[:3] for f in truth_tf_frames(run)] == frames
    topics = check_truth_under_tf(apollo, run, bag, frames)
    assert sorted(topics) == sorted(
        ["/joint_states", "/camera/depth/image_raw", "/camera/depth/camera_info", "/tf",
         "/truth/hand_pose", "/truth/joint_states"])

    rng = np.random.default_rng(3)
    T = len(run.truth_times_s)
    offset = rng.normal(0.0, [0.03] * 3 + [0.05] * 3, (T, 6))
    q = np.stack([truth_positions(apollo, run, k, {"camera": offset}) for k in range(T)])
    varying = dataclasses.replace(run, truth_camera_offset=offset,
                                  truth_X_CE=PoseReadout(apollo).poses(q)[0])
    write_run_bag(varying, tmp_path / "varying.mcap")
    check_truth_under_tf(apollo, varying, tmp_path / "varying.mcap", frames)


@pytest.mark.parametrize("offset, fragment", [
    (np.zeros((0, 6)), r"camera 'camera': its true camera offset is missing .*shape "
                       r"\(0, 6\)"),
    (None, r"camera 'camera': its true camera offset is missing .*shape None"),
    ("nan", r"camera 'camera': its true camera offset at truth sample 2 is not finite"),
])
def test_a_missing_true_offset_is_named_before_the_bag_is_made(run, tmp_path, offset,
                                                               fragment):
    broken = dataclasses.replace(run)
    if isinstance(offset, str):
        broken.truth_camera_offset = run.truth_camera_offset.copy()
        broken.truth_camera_offset[2, 4] = np.nan
    else:
        broken.truth_camera_offset = offset  # past validate(), as a hand-made run can be
    with pytest.raises(ValueError, match=fragment):
        write_run_bag(broken, tmp_path / "broken.mcap")
    assert not list(tmp_path.iterdir())
