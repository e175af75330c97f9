"""``estimates.mcap`` read back with rosbags (``io/estimates_out.EstimatesBag``): each
camera's offset from its nominal mount on ``/tf`` (the six values back to float
precision, the transform as Drake's kinematics of the virtual joints give it), the
health on ``/tracker/health``, for one camera and for two."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rosbags")

from pydrake.common.eigen_geometry import Quaternion  # noqa: E402
from pydrake.math import RigidTransform  # noqa: E402
from test_multicamera import two_camera_config  # noqa: E402

from drake_tracker.core.filter.estimate import TrackerEstimate  # noqa: E402
from drake_tracker.core.robustness.health import (  # noqa: E402
    HealthState,
    ImageConsistency,
    TrackerHealth,
)
from drake_tracker.io.estimates_out import (  # noqa: E402
    HAND_POSE_TOPIC,
    HEALTH_STATUS_NAME,
    HEALTH_TOPIC,
    JOINT_STATES_TOPIC,
    TF_TOPIC,
    EstimatesBag,
    stamp_ns,
    stamp_text,
)
from drake_tracker.robot.model import build_tracker_model  # noqa: E402

BASE_NS = 1_700_000_000_123_456_789
HEALTHS = (
    TrackerHealth(),
    TrackerHealth(HealthState.TRACKING, ImageConsistency(0.1, 512, 0.97, 0.01, 0.125),
                  acquired=True),
    TrackerHealth(HealthState.LOST, ImageConsistency(0.2333, 40, 0.3, 0.6, 0.0),
                  restarts=2),
)
LEVELS = {HealthState.TRACKING: 0, HealthState.UNCERTAIN: 1, HealthState.LOST: 2}


@pytest.fixture(scope="module")
def two_cameras():
    return build_tracker_model(two_camera_config())


def estimates(model, count=3, seed=5):
    """``count`` estimates of ``model`` with random angles and camera offsets (5 cm and
    0.25 rad spreads, far above a real mount's error so that a swapped axis shows) and
    the health of ``HEALTHS`` in turn."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(count):
        q = rng.normal(0.0, 0.3, model.num_joints)
        offsets = {name: rng.normal(0.0, [0.05] * 3 + [0.25] * 3)
                   for name in model.camera_names}
        for name, offset in offsets.items():
            q[model.camera_joint_indices(name)] = offset
        wxyz = rng.normal(size=4)
        X_CE = RigidTransform(Quaternion(wxyz / np.linalg.norm(wxyz)),
                              rng.normal(size=3)).GetAsMatrix4()
        first = model.camera_names[0]
        out.append(TrackerEstimate(
            time_s=0.05 * k, joint_names=list(model.joint_names), positions=q,
            position_variances=np.ones(model.num_joints), biases=np.zeros(model.num_joints),
            bias_variances=np.ones(model.num_joints), camera_offset=offsets[first].copy(),
            X_CE=X_CE, X_WE=np.eye(4), camera_offsets=offsets,
            health=HEALTHS[k % len(HEALTHS)]))
    return out


def read_bag(path):
    """{topic: [(log time ns, message), ...]} of an MCAP file."""
    from rosbags.highlevel import AnyReader

    out = {}
    with AnyReader([path]) as reader:
        for connection, time_ns, raw in reader.messages():
            out.setdefault(connection.topic, []).append(
                (time_ns, reader.deserialize(raw, connection.msgtype)))
    return out


def transform_of(message):
    """The 4x4 pose of a ``TransformStamped``'s child frame in its parent."""
    r, p = message.transform.rotation, message.transform.translation
    return RigidTransform(Quaternion([r.w, r.x, r.y, r.z]), [p.x, p.y, p.z]).GetAsMatrix4()


def offset_of(X):
    """[x, y, z, rx, ry, rz] of X = p(x, y, z) Rx(rx) Ry(ry) Rz(rz) (|ry| < pi/2)."""
    R = X[:3, :3]
    rx = np.arctan2(-R[1, 2], R[2, 2])
    ry = np.arctan2(R[0, 2], np.hypot(R[1, 2], R[2, 2]))
    rz = np.arctan2(-R[0, 1], R[0, 0])
    return np.array([*X[:3, 3], rx, ry, rz])


def drake_offset(model, name, offset):
    """X_nominal_estimated of camera ``name`` by Drake's kinematics, with only its six
    virtual joints set (every other joint at zero)."""
    context = model.plant.CreateDefaultContext()
    q = np.zeros(model.num_joints)
    q[model.camera_joint_indices(name)] = offset
    model.plant.SetPositions(context, q)
    camera = model.camera(name)
    return model.plant.CalcRelativeTransform(context, camera.nominal_frame,
                                             camera.frame).GetAsMatrix4()


@pytest.mark.parametrize("cameras", ["one", "two"])
def test_each_cameras_offset_and_the_health_read_back(cameras, apollo, two_cameras,
                                                      tmp_path):
    model = apollo if cameras == "one" else two_cameras
    written = estimates(model)
    bag = EstimatesBag(tmp_path / "estimates.mcap", model, BASE_NS, "depth_optical")
    for estimate in written:
        bag.write(estimate)
    bag.close()
    topics = read_bag(tmp_path / "estimates.mcap")
    assert sorted(topics) == sorted([HAND_POSE_TOPIC, JOINT_STATES_TOPIC, TF_TOPIC,
                                     HEALTH_TOPIC])
    stamps = [stamp_ns(BASE_NS, e.time_s) for e in written]
    for topic, messages in topics.items():
        assert [t for t, _ in messages] == stamps, topic
    # The hand pose keeps the input's depth frame.
    assert {m.header.frame_id for _, m in topics[HAND_POSE_TOPIC]} == {"depth_optical"}

    nominal = {"camera": "camera_optical", "post": "post_nominal"}
    for estimate, stamp, (_, tf) in zip(written, stamps, topics[TF_TOPIC]):
        assert [(t.header.frame_id, t.child_frame_id) for t in tf.transforms] == [
            (nominal[name], f"{name}_estimated") for name in model.camera_names]
        for name, t in zip(model.camera_names, tf.transforms):
            assert t.header.stamp.sec * 10**9 + t.header.stamp.nanosec == stamp
            X = transform_of(t)
            np.testing.assert_allclose(offset_of(X), estimate.camera_offsets[name],
                                       rtol=0, atol=1e-12, err_msg=name)
            np.testing.assert_allclose(X, drake_offset(model, name,
                                                       estimate.camera_offsets[name]),
                                       rtol=0, atol=1e-12, err_msg=name)
        # The first camera's is ``camera_offset``.
        np.testing.assert_allclose(offset_of(transform_of(tf.transforms[0])),
                                   estimate.camera_offset, rtol=0, atol=1e-12)

    for estimate, (_, array) in zip(written, topics[HEALTH_TOPIC]):
        [status] = array.status
        health = estimate.health
        state = HealthState(health.state)
        assert status.name == HEALTH_STATUS_NAME
        assert status.level == LEVELS[state] and status.message == state.name.lower()
        values = {v.key: v.value for v in status.values}
        assert HealthState[values.pop("state").upper()] == state
        assert values.pop("acquired") == str(health.acquired)
        assert int(values.pop("restarts")) == health.restarts
        if health.latest is None:
            assert not values
            continue
        latest = health.latest
        assert values.pop("image_stamp") == stamp_text(BASE_NS, latest.time_s)
        assert int(values.pop("robot_pixels")) == latest.robot_pixels
        assert {k: float(v) for k, v in values.items()} == {
            "agreement": latest.agreement, "see_through": latest.see_through,
            "occluded": latest.occluded}
