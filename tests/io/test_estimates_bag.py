"""``estimates.mcap`` read back with rosbags (``io/estimates_out.EstimatesBag``): each
camera's offset from its nominal mount on ``/tf`` (the six values back to float
precision, the transform as Drake's kinematics of the virtual joints give it), hung
from the input's frame id of the camera (the model's frame name without one), the hand
pose in the first camera's estimated frame, so that the two composed are the hand in
the input's (nominal) camera frame as Drake's kinematics give it at the estimated
positions, and the health on ``/tracker/health``, for one camera and for two."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rosbags")

from pydrake.common.eigen_geometry import Quaternion  # noqa: E402
from pydrake.math import RigidTransform  # noqa: E402
from two_cameras import two_camera_config  # noqa: E402

from drake_tracker.core.filter.estimate import (  # noqa: E402
    PoseReadout,
    TrackerEstimate,
    estimate_from_belief,
)
from drake_tracker.core.filter.kalman import MEAN_A, VAR_A, VAR_B  # noqa: E402
from drake_tracker.core.robustness.health import (  # noqa: E402
    HealthState,
    ImageConsistency,
    TrackerHealth,
)
from drake_tracker.io.estimates_out import (  # noqa: E402
    CAMERA_COLUMNS,
    HAND_POSE_TOPIC,
    HEALTH_STATUS_NAME,
    HEALTH_TOPIC,
    JOINT_STATES_TOPIC,
    TF_TOPIC,
    EstimatesBag,
    camera_hand_pose_topic,
    camera_tf_frames,
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
#: The input's frame ids of the cameras (as a ``record --bag`` bag names them), and the
#: model's nominal frames, which differ from them.
FRAME_IDS = {"camera": "camera_depth_optical_frame", "post": "post_depth_optical_frame"}
NOMINAL = {"camera": "camera_optical", "post": "post_nominal"}


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
        X_WC = {name: RigidTransform(Quaternion(w / np.linalg.norm(w)),
                                     rng.normal(size=3)).GetAsMatrix4()
                for name, w in zip(model.camera_names, rng.normal(size=(4, 4)))}
        out.append(TrackerEstimate(
            time_s=0.05 * k, joint_names=list(model.joint_names), positions=q,
            position_variances=np.ones(model.num_joints), biases=np.zeros(model.num_joints),
            bias_variances=np.ones(model.num_joints), camera_offset=offsets[first].copy(),
            X_CE=X_CE, X_WE=X_WC[first] @ X_CE, camera_offsets=offsets,
            X_WC_by_camera=X_WC, health=HEALTHS[k % len(HEALTHS)]))
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


def bag_of(model, written, path, frame_ids=None):
    """``written`` estimates through an :class:`EstimatesBag` at ``path`` (the input's
    frame ids ``frame_ids``), read back by :func:`read_bag`."""
    bag = EstimatesBag(path, model, BASE_NS, frame_ids)
    for estimate in written:
        bag.write(estimate)
    bag.close()
    return read_bag(path)


def transform_of(message):
    """The 4x4 pose of a ``TransformStamped``'s child frame in its parent."""
    r, p = message.transform.rotation, message.transform.translation
    return RigidTransform(Quaternion([r.w, r.x, r.y, r.z]), [p.x, p.y, p.z]).GetAsMatrix4()


def pose_of(message):
    """The 4x4 pose of a ``PoseStamped`` in its frame."""
    o, p = message.pose.orientation, message.pose.position
    return RigidTransform(Quaternion([o.w, o.x, o.y, o.z]), [p.x, p.y, p.z]).GetAsMatrix4()


def hand_under_tf(pose, tf):
    """(parent, X_parent_hand): a ``/tracker/hand_pose`` message composed with the
    ``/tf`` transform whose child is the pose's frame (one there must be)."""
    [t] = [t for t in tf.transforms if t.child_frame_id == pose.header.frame_id]
    return t.header.frame_id, transform_of(t) @ pose_of(pose)


def drake_hand_in_nominal(model, q, camera=0):
    """X_nominal_hand of the model's camera ``camera`` (index; the first by default) at
    positions ``q``, by Drake."""
    context = model.plant.CreateDefaultContext()
    model.plant.SetPositions(context, q)
    return model.plant.CalcRelativeTransform(context, model.cameras[camera].nominal_frame,
                                             model.end_effector_frame).GetAsMatrix4()


def positions_from_csv(model, table, row):
    """Every joint's estimated position (robot angles and camera offsets) in row ``row``
    of ``read_estimates_csv``'s columns."""
    q = np.zeros(model.num_joints)
    prismatic = set(model.prismatic_joint_names)
    for k, name in zip(model.robot_joint_indices, model.robot_joint_names):
        q[k] = table[f"angle_{name}_{'m' if name in prismatic else 'rad'}"][row]
    for i, name in enumerate(model.camera_names):
        columns = CAMERA_COLUMNS if i == 0 else [name + c.removeprefix("camera")
                                                 for c in CAMERA_COLUMNS]
        q[model.camera_joint_indices(name)] = [table[c][row] for c in columns]
    return q


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
    frame_ids = {name: FRAME_IDS[name] for name in model.camera_names}
    topics = bag_of(model, written, tmp_path / "estimates.mcap", frame_ids)
    further = [camera_hand_pose_topic(name) for name in model.camera_names[1:]]
    assert further == ([] if cameras == "one" else ["/tracker/post/hand_pose"])
    assert sorted(topics) == sorted([HAND_POSE_TOPIC, JOINT_STATES_TOPIC, TF_TOPIC,
                                     HEALTH_TOPIC, *further])
    stamps = [stamp_ns(BASE_NS, e.time_s) for e in written]
    for topic, messages in topics.items():
        assert [t for t, _ in messages] == stamps, topic
    # The hand pose is in the first camera's estimated frame, its child on /tf.
    assert {m.header.frame_id for _, m in topics[HAND_POSE_TOPIC]} == {"camera_estimated"}

    for estimate, stamp, (_, tf) in zip(written, stamps, topics[TF_TOPIC]):
        # Each camera hangs from the input's frame id of it.
        assert [(t.header.frame_id, t.child_frame_id) for t in tf.transforms] == [
            (FRAME_IDS[name], f"{name}_estimated") for name in model.camera_names]
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


@pytest.mark.parametrize("cameras", ["one", "two"])
def test_the_hand_pose_under_tf_is_the_hand_in_the_input_camera_frame(
        cameras, apollo, two_cameras, tmp_path):
    """Estimates as the tracker makes them (``estimate_from_belief``: X_CE by the
    package's kinematics at the mean angles), with camera offsets of 5 cm and 0.25 rad:
    the hand pose composed with /tf from the input's camera frame is the hand in the
    nominal camera frame by Drake's kinematics at the same angles; the hand pose alone
    (what the bag said before, labelled with the input's frame) is off by the offset."""
    model = apollo if cameras == "one" else two_cameras
    readout = PoseReadout(model)
    rng = np.random.default_rng(11)
    written = []
    for k in range(4):
        belief = np.zeros((5, model.num_joints))
        belief[MEAN_A] = rng.normal(0.0, 0.3, model.num_joints)
        for name in model.camera_names:
            belief[MEAN_A, model.camera_joint_indices(name)] = rng.normal(
                0.0, [0.05] * 3 + [0.25] * 3)
        belief[VAR_A] = belief[VAR_B] = 1.0
        written.append(estimate_from_belief(model, readout, 0.1 * k, belief))
    frame_ids = {name: FRAME_IDS[name] for name in model.camera_names}
    topics = bag_of(model, written, tmp_path / "estimates.mcap", frame_ids)
    for estimate, (_, pose), (_, tf) in zip(written, topics[HAND_POSE_TOPIC],
                                            topics[TF_TOPIC], strict=True):
        parent, X = hand_under_tf(pose, tf)
        assert parent == FRAME_IDS[model.camera_names[0]]
        expected = drake_hand_in_nominal(model, estimate.positions)
        np.testing.assert_allclose(X, expected, rtol=0, atol=1e-9)
        assert np.linalg.norm(pose_of(pose)[:3, 3] - expected[:3, 3]) > 1e-3
    # Each further camera's hand pose, under /tf, is the hand in that camera's nominal
    # frame by Drake's kinematics (the same positions).
    for k, name in enumerate(model.camera_names[1:], 1):
        for estimate, (_, pose), (_, tf) in zip(
                written, topics[camera_hand_pose_topic(name)], topics[TF_TOPIC], strict=True):
            assert pose.header.frame_id == f"{name}_estimated"
            parent, X = hand_under_tf(pose, tf)
            assert parent == FRAME_IDS[name]
            np.testing.assert_allclose(X, drake_hand_in_nominal(model, estimate.positions, k),
                                       rtol=0, atol=1e-9)


def test_without_frame_ids_the_cameras_hang_from_the_model_frames(two_cameras, tmp_path):
    model = two_cameras
    assert camera_tf_frames(model) == [("camera", NOMINAL["camera"], "camera_estimated"),
                                       ("post", NOMINAL["post"], "post_estimated")]
    # A camera left out keeps the model's frame; the others take the input's.
    partial = {"post": FRAME_IDS["post"]}
    assert [p for _, p, _ in camera_tf_frames(model, partial)] == [NOMINAL["camera"],
                                                                    FRAME_IDS["post"]]
    topics = bag_of(model, estimates(model, count=1), tmp_path / "estimates.mcap")
    [(_, tf)], [(_, pose)] = topics[TF_TOPIC], topics[HAND_POSE_TOPIC]
    assert [(t.header.frame_id, t.child_frame_id) for t in tf.transforms] == [
        (NOMINAL["camera"], "camera_estimated"), (NOMINAL["post"], "post_estimated")]
    assert pose.header.frame_id == "camera_estimated"


@pytest.mark.parametrize("frame_ids, error, fragment", [
    ("camera_depth_optical_frame", TypeError, "by camera name"),
    ({"side": "side_frame"}, ValueError, "unknown camera 'side'"),
    ({"post": ""}, ValueError, "camera 'post': frame id ''"),
    ({"camera": "post_estimated"}, ValueError, "an estimated frame's name"),
])
def test_bad_frame_ids_are_named_before_the_bag_is_made(two_cameras, tmp_path, frame_ids,
                                                        error, fragment):
    with pytest.raises(error, match=fragment):
        EstimatesBag(tmp_path / "estimates.mcap", two_cameras, BASE_NS, frame_ids)
    assert not list(tmp_path.iterdir())


def test_the_csv_has_the_hand_in_each_further_cameras_frame(two_cameras, tmp_path):
    """``NAME_hand_*`` of ``estimates.csv``, read back, is the hand in camera ``NAME``'s
    estimated frame by Drake's kinematics at the row's positions (themselves read back
    from the CSV)."""
    from drake_tracker.io.estimates_out import EstimatesCsv, read_estimates_csv

    model = two_cameras
    readout = PoseReadout(model)
    rng = np.random.default_rng(12)
    writer = EstimatesCsv(tmp_path / "estimates.csv", model, BASE_NS)
    for k in range(3):
        belief = np.zeros((5, model.num_joints))
        belief[MEAN_A] = rng.normal(0.0, 0.3, model.num_joints)
        writer.write(estimate_from_belief(model, readout, 0.1 * k, belief))
    writer.close()
    table = read_estimates_csv(tmp_path / "estimates.csv")
    context = model.plant.CreateDefaultContext()
    for row in range(3):
        model.plant.SetPositions(context, positions_from_csv(model, table, row))
        X = model.plant.CalcRelativeTransform(context, model.camera("post").frame,
                                              model.end_effector_frame).GetAsMatrix4()
        xyz = [table[f"post_hand_{c}"][row] for c in ("x_m", "y_m", "z_m")]
        wxyz = [table[f"post_hand_{c}"][row] for c in ("qw", "qx", "qy", "qz")]
        np.testing.assert_allclose(xyz, X[:3, 3], atol=1e-9)
        np.testing.assert_allclose(Quaternion(wxyz).rotation(), X[:3, :3], atol=1e-9)
