"""ROS bags in and out (``io/run_bag.py``, ``io/bag_source.py``, ``io/track_files.py``).

The round trip: a run written as a ROS 2 MCAP bag and tracked from the bag gives the
same estimates as the run tracked directly (the estimates file, to 1e-9; here exactly).
Bad input: each fault named, or skipped and counted. Bags written by rosbags' own
writers for the other two formats (a ROS 1 bag, a ROS 2 sqlite3 folder) read the same.
The truth's hand pose and ``/tf``: ``tests/io/test_bag_truth.py``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("rosbags")

from fast_params import small_params as fast_params  # noqa: E402
from test_estimates_bag import (  # noqa: E402
    drake_hand_in_nominal,
    hand_under_tf,
    positions_from_csv,
    read_bag,
)

from drake_tracker.io.bag_source import BagSource, BagTopics  # noqa: E402
from drake_tracker.io.estimates_out import read_estimates_csv, stamp_text  # noqa: E402
from drake_tracker.io.ros_messages import RosMessages, bag_writer, depth_from_image  # noqa: E402
from drake_tracker.io.run_bag import CAMERA_FRAME, DEFAULT_BASE_NS, write_run_bag  # noqa: E402
from drake_tracker.io.synthetic import synthetic_run  # noqa: E402
from drake_tracker.io.track_files import track_bag, track_run  # noqa: E402


@pytest.fixture(scope="module")
def run(apollo):
    return synthetic_run(apollo, duration_s=0.6, encoder_rate_hz=200.0,
                         seed=7).stamped_in_nanoseconds()


@pytest.fixture(scope="module")
def bag(run, tmp_path_factory):
    path = tmp_path_factory.mktemp("bag") / "run.mcap"
    write_run_bag(run, path)
    return path


def test_stamps_in_nanoseconds_are_what_a_bag_holds(run):
    for times in (run.reading_times_s, run.image_capture_times_s, run.truth_times_s):
        ns = np.round(times * 1e9).astype(np.int64)
        assert np.array_equal(ns / 1e9, times)
    assert stamp_text(DEFAULT_BASE_NS, 0.25) == "1700000000.250000000"
    assert stamp_text(0, -1.5) == "-1.500000000"


def test_the_bag_holds_the_run(run, bag, apollo):
    source = BagSource(bag, apollo.robot_joint_names)
    assert source.intrinsics == run.camera_intrinsics
    assert source.base_ns == DEFAULT_BASE_NS + round(run.reading_times_s[0] * 1e9)
    events = list(source.events())
    readings = [e for e in events if hasattr(e, "positions")]
    images = [e for e in events if hasattr(e, "depth")]
    assert len(readings) == len(run.reading_times_s) and len(images) == len(
        run.image_capture_times_s)
    np.testing.assert_array_equal([r.time_s for r in readings],
                                  run.reading_times_s - run.reading_times_s[0])
    np.testing.assert_array_equal(np.stack([r.positions for r in readings]), run.readings_rad)
    order, _ = run.cameras[0].arrival_order()
    for image, i in zip(images, order):
        np.testing.assert_array_equal(image.depth, run.depth_images_m[i].astype(np.float32))
    times, X = source.truth_X_CE()
    np.testing.assert_allclose(X, run.truth_X_CE, atol=1e-12)
    source.close()


def test_round_trip_gives_the_same_estimates(run, bag, apollo, tmp_path):
    params = fast_params()
    direct = track_run(run, apollo, params, tmp_path / "run", progress=False)
    source = BagSource(bag, apollo.robot_joint_names)
    from_bag = track_bag(source, apollo, params, tmp_path / "bag", progress=False)
    assert direct["counts"]["images_applied"] > 5
    assert direct["counts"] == from_bag["counts"]
    a = read_estimates_csv(tmp_path / "run" / "estimates.csv")
    b = read_estimates_csv(tmp_path / "bag" / "estimates.csv")
    assert len(a["t_s"]) == len(run.reading_times_s)
    for column in a:
        if column in ("health", "t0_s"):
            continue
        np.testing.assert_allclose(b[column], a[column], rtol=0, atol=1e-9, err_msg=column)
    assert (a["health"] == b["health"]).all()
    assert b["t0_s"][0] == stamp_text(DEFAULT_BASE_NS, run.reading_times_s[0])
    report = json.loads((tmp_path / "bag" / "report.json").read_text())
    assert report["methods"]["full_fusion"]["translation_mm"]["p50"] < 30.0
    assert (tmp_path / "bag" / "estimates.mcap").stat().st_size > 0
    # /tf hangs the camera from the input's frame: the bag's depth frame id; a recorded
    # run has none, so the model's frame name.
    for folder, parent in (("bag", CAMERA_FRAME),
                           ("run", apollo.cameras[0].nominal_frame.name())):
        tf = read_bag(tmp_path / folder / "estimates.mcap")["/tf"]
        assert {(t.header.frame_id, t.child_frame_id) for _, m in tf
                for t in m.transforms} == {(parent, "camera_estimated")}, folder


def test_estimates_bag_holds_one_message_per_topic_per_reading(run, bag, apollo, tmp_path):
    from rosbags.highlevel import AnyReader

    source = BagSource(bag, apollo.robot_joint_names)
    track_bag(source, apollo, fast_params(), tmp_path, progress=False)
    table = read_estimates_csv(tmp_path / "estimates.csv")
    with AnyReader([tmp_path / "estimates.mcap"]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        poses = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(
            connections=[c for c in reader.connections if c.topic == "/tracker/hand_pose"])]
    topics = ("/tracker/hand_pose", "/tracker/joint_states", "/tf", "/tracker/health")
    assert counts == dict.fromkeys(topics, len(table["t_s"]))
    last = poses[-1].pose.position
    np.testing.assert_allclose([last.x, last.y, last.z],
                               [table[c][-1] for c in ("x_m", "y_m", "z_m")], atol=1e-12)
    # The hand pose under /tf from the bag's camera frame is the hand in the nominal
    # camera frame, by Drake's kinematics at the estimated angles and camera offset.
    tf = [m for _, m in read_bag(tmp_path / "estimates.mcap")["/tf"]]
    assert {p.header.frame_id for p in poses} == {"camera_estimated"}
    for row, (pose, transforms) in enumerate(zip(poses, tf, strict=True)):
        parent, X = hand_under_tf(pose, transforms)
        assert parent == CAMERA_FRAME
        np.testing.assert_allclose(
            X, drake_hand_in_nominal(apollo, positions_from_csv(apollo, table, row)),
            rtol=0, atol=1e-9, err_msg=f"row {row}")


@pytest.mark.parametrize("frame", ["cam", ""])
def test_a_camera_without_a_frame_id_hangs_from_the_model_frame(apollo, tmp_path, frame):
    """The bag's camera frame id (its CameraInfo's) is its /tf parent in the estimates;
    a bag without one gives the model's frame name."""
    m = RosMessages()
    names = apollo.robot_joint_names
    t0 = DEFAULT_BASE_NS
    messages = [("/info", "sensor_msgs/msg/CameraInfo", t0,
                 m.camera_info(t0, frame, 8, 6, 10.0, 10.0, 4.0, 3.0)),
                ("/depth", "sensor_msgs/msg/Image", t0 + 5_000_000,
                 m.depth_image(t0, frame, np.ones((6, 8), np.float32)))]
    messages += [("/joint_states", "sensor_msgs/msg/JointState", t,
                  m.joint_state(t, names, np.zeros(len(names))))
                 for t in (t0 + k * 10_000_000 for k in range(3))]
    path = _write(tmp_path / "bag.mcap", sorted(messages, key=lambda x: x[2]))
    source = BagSource(path, names)
    assert source.frame_ids("camera") == ({"camera": "cam"} if frame else {})
    track_bag(source, apollo, fast_params(), tmp_path / "out", progress=False)
    topics = read_bag(tmp_path / "out" / "estimates.mcap")
    parent = frame or apollo.cameras[0].nominal_frame.name()
    assert [[(t.header.frame_id, t.child_frame_id) for t in tf.transforms]
            for _, tf in topics["/tf"]] == [[(parent, "camera_estimated")]] * 3
    assert {p.header.frame_id for _, p in topics["/tracker/hand_pose"]} == {
        "camera_estimated"}


def _write(path, messages):
    """A small MCAP bag of (topic, type, stamp ns, message)."""
    m = RosMessages()
    writer = bag_writer(path)
    connections = {}
    for topic, kind, stamp, message in messages:
        if topic not in connections:
            connections[topic] = writer.add_connection(topic, kind, typestore=m.store)
        writer.write(connections[topic], stamp, m.serialize(message))
    writer.close()
    return path


def _info(m, stamp, d=None):
    info = m.camera_info(stamp, "cam", 8, 6, 10.0, 10.0, 4.0, 3.0)
    if d is not None:
        info.d[:] = d
    return info


def test_bad_bags_are_named(apollo, tmp_path):
    m = RosMessages()
    names = apollo.robot_joint_names
    t0 = DEFAULT_BASE_NS
    joints = ("/joint_states", "sensor_msgs/msg/JointState")
    info = ("/info", "sensor_msgs/msg/CameraInfo")
    depth = ("/depth", "sensor_msgs/msg/Image")
    ok_info = (*info, t0, _info(m, t0))
    ok_joint = (*joints, t0, m.joint_state(t0, names, np.zeros(len(names))))

    with pytest.raises(ValueError, match="does not exist"):
        BagSource(tmp_path / "missing.mcap", names)
    corrupt = tmp_path / "corrupt.mcap"
    corrupt.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 64)
    with pytest.raises(ValueError, match="cannot be read"):
        BagSource(corrupt, names)
    # A joint of the model missing from the messages.
    short = _write(tmp_path / "short.mcap", [ok_info, (*joints, t0, m.joint_state(
        t0, names[:-1], np.zeros(len(names) - 1))), (*depth, t0, m.depth_image(
            t0, "cam", np.ones((6, 8), np.float32)))])
    with pytest.raises(ValueError, match=f"joint {names[-1]} of the model"):
        BagSource(short, names)
    # No CameraInfo topic; distortion.
    no_info = _write(tmp_path / "no_info.mcap", [ok_joint, (*depth, t0, m.depth_image(
        t0, "cam", np.ones((6, 8), np.float32)))])
    with pytest.raises(ValueError, match="CameraInfo topics"):
        BagSource(no_info, names)
    distorted = _write(tmp_path / "distorted.mcap", [(*info, t0, _info(m, t0, [0.1, 0, 0, 0,
                                                                              0])),
                                                     ok_joint])
    with pytest.raises(ValueError, match=r"the bag has 0 depth \(sensor_msgs/msg/Image"):
        BagSource(distorted, names)
    distorted_with_depth = _write(tmp_path / "distorted2.mcap", [
        (*info, t0, _info(m, t0, [0.1, 0, 0, 0, 0])), ok_joint,
        (*depth, t0, m.depth_image(t0, "cam", np.ones((6, 8), np.float32)))])
    with pytest.raises(ValueError, match="distortion"):
        BagSource(distorted_with_depth, names)
    # Two depth topics: the error lists them and names the flag.
    two = _write(tmp_path / "two.mcap", [ok_info, ok_joint,
                                         ("/a", "sensor_msgs/msg/Image", t0, m.depth_image(
                                             t0, "cam", np.ones((6, 8), np.float32))),
                                         ("/b", "sensor_msgs/msg/Image", t0, m.depth_image(
                                             t0, "cam", np.ones((6, 8), np.float32)))])
    with pytest.raises(ValueError, match=r"\['/a', '/b'\].*--depth-topic"):
        BagSource(two, names)
    assert BagSource(two, names, BagTopics(depth="/b")).depth_topic == "/b"


def test_bad_messages_are_skipped_and_counted(apollo, tmp_path):
    m = RosMessages()
    names = apollo.robot_joint_names
    t0 = DEFAULT_BASE_NS
    rgb = m.depth_image(t0, "cam", np.ones((6, 8), np.float32))
    rgb.encoding = "rgb8"
    wrong_size = m.depth_image(t0, "cam", np.ones((5, 8), np.float32))
    messages = [("/info", "sensor_msgs/msg/CameraInfo", t0, _info(m, t0))]
    for k in range(20):
        t = t0 + k * 10_000_000
        messages.append(("/joint_states", "sensor_msgs/msg/JointState", t,
                         m.joint_state(t, names, np.zeros(len(names)))))
    messages[5] = ("/joint_states", "sensor_msgs/msg/JointState", messages[5][2],
                   m.joint_state(messages[5][2], ["other"], [0.0]))
    messages += [("/depth", "sensor_msgs/msg/Image", t0 + 50_000_000, rgb),
                 ("/depth", "sensor_msgs/msg/Image", t0 + 60_000_000, wrong_size)]
    # A reading logged in order but stamped 25 ms back (a clock that jumped back), and
    # one with a NaN joint (used: that joint is predicted).
    back = t0 + 125_000_000
    messages.append(("/joint_states", "sensor_msgs/msg/JointState", back,
                     m.joint_state(back - 25_000_000, names, np.zeros(len(names)))))
    nan_joint = np.zeros(len(names))
    nan_joint[2] = np.nan
    messages[9] = ("/joint_states", "sensor_msgs/msg/JointState", messages[9][2],
                   m.joint_state(messages[9][2], names, nan_joint))
    messages.sort(key=lambda x: x[2])
    path = _write(tmp_path / "faults.mcap", messages)
    report = track_bag(BagSource(path, names), apollo, fast_params(), tmp_path / "out",
                       progress=False)
    counts = report["counts"]
    assert counts["source_skipped"] == {"joint messages without the model's joints": 1,
                                        "depth images not usable": 1,
                                        "unusable images": 1}
    assert counts["readings"] == 20 and counts["estimates"] == 19
    assert sum(counts["readings_skipped"].values()) == 1
    assert counts["readings_with_missing_joints"] == 1


def test_depth_encodings(tmp_path):
    m = RosMessages()
    mm = np.array([[0, 1000], [2500, 65535]], np.uint16)
    np.testing.assert_array_equal(depth_from_image(m.depth_image(0, "c", mm)), mm)
    big = m.depth_image(0, "c", mm)
    big.is_bigendian = 1
    big.data = np.frombuffer(mm.astype(">u2").tobytes(), np.uint8)
    np.testing.assert_array_equal(depth_from_image(big), mm)
    metres = np.array([[np.nan, 1.0], [2.5, 0.0]], np.float32)
    np.testing.assert_array_equal(depth_from_image(m.depth_image(0, "c", metres)), metres)
    bad = m.depth_image(0, "c", metres)
    bad.encoding = "rgb8"
    with pytest.raises(ValueError, match="'rgb8' is not a depth encoding"):
        depth_from_image(bad)
    bad = m.depth_image(0, "c", metres)
    bad.data = bad.data[:5]
    with pytest.raises(ValueError, match="truncated"):
        depth_from_image(bad)


def test_an_image_logged_before_the_reading_after_its_capture_waits_for_it(run, apollo):
    """A log that records each image as it is captured holds it before the reading that
    follows its capture; the stream feeds it after that reading instead of letting the
    tracker call it "from the future", and applies every image the recorded arrivals
    do."""
    from drake_tracker.io.stream import ImageEvent, ReadingEvent, merge_by_time, track_stream
    from drake_tracker.io.track_files import run_events
    from drake_tracker.tracker import Tracker

    readings = ((t, ReadingEvent(t, q)) for t, q in zip(run.reading_times_s,
                                                        run.readings_rad))
    images = ((t, ImageEvent(t, run.depth_images_m[i], i))
              for i, t in enumerate(run.image_capture_times_s))
    at_capture = track_stream(merge_by_time(images, readings),
                              Tracker(apollo, run.camera_intrinsics, fast_params()))
    recorded = track_stream(run_events(run), Tracker(apollo, run.camera_intrinsics,
                                                     fast_params()))
    assert "images: future" not in at_capture.images_skipped
    assert at_capture.images_applied == recorded.images_applied == len(
        run.image_capture_times_s)


def _as_ros1(message, store):
    """The same message as a ROS 1 (Noetic) one: fields matched by name, case aside
    (CameraInfo's ``d`` is ``D`` there), ``header.seq`` 0."""
    import dataclasses

    kind = store.types[message.__msgtype__]
    values = {}
    for f in dataclasses.fields(kind):
        if f.name == "__msgtype__":
            continue
        if f.name == "seq":
            values[f.name] = 0
            continue
        value = getattr(message, f.name, None)
        if value is None:
            value = getattr(message, f.name.lower())
        if hasattr(value, "__msgtype__"):
            value = _as_ros1(value, store)
        elif isinstance(value, list):  # e.g. TFMessage.transforms
            value = [_as_ros1(v, store) if hasattr(v, "__msgtype__") else v
                     for v in value]
        values[f.name] = value
    return kind(**values)


@pytest.mark.parametrize("storage", ["ros1", "sqlite3"])
def test_ros1_bags_and_sqlite3_folders_read_as_the_mcap_does(run, bag, apollo, tmp_path,
                                                             storage):
    """The same messages written by rosbags' own writers as a ROS 1 ``.bag`` (with ROS 1
    field names: ``header.seq``, ``CameraInfo.D``/``K``) and as a ROS 2 bag folder in
    sqlite3 storage give the events the MCAP file gives; ``/tf`` and the truth are
    copied too, and change nothing."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    if storage == "ros1":
        from rosbags.rosbag1 import Writer
        from rosbags.typesys import get_types_from_msg

        path, store = tmp_path / "run.bag", get_typestore(Stores.ROS1_NOETIC)
        # rosbags' Noetic store lacks the type of /tf (tf2_msgs/TFMessage in ROS 1).
        store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                          "tf2_msgs/msg/TFMessage"))
        writer = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        path, store = tmp_path / "run_sqlite3", get_typestore(Stores.ROS2_HUMBLE)
        writer = Writer(path, version=8, storage_plugin=StoragePlugin.SQLITE3)
    writer.open()
    connections = {}
    with AnyReader([bag]) as reader:
        for connection, log_ns, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            if connection.topic not in connections:
                connections[connection.topic] = writer.add_connection(
                    connection.topic, connection.msgtype, typestore=store)
            if storage == "ros1":
                data = store.serialize_ros1(_as_ros1(message, store), connection.msgtype)
            else:
                data = store.serialize_cdr(message, connection.msgtype)
            writer.write(connections[connection.topic], log_ns, data)
    writer.close()
    expected = list(BagSource(bag, apollo.robot_joint_names).events())
    source = BagSource(path, apollo.robot_joint_names)
    assert source.intrinsics == run.camera_intrinsics
    got = list(source.events())
    assert len(got) == len(expected)
    for a, b in zip(got, expected):
        assert type(a) is type(b)
        if hasattr(a, "positions"):
            assert a.time_s == b.time_s
            np.testing.assert_array_equal(a.positions, b.positions)
        else:
            assert (a.capture_s, a.sequence, a.arrival_s) == (b.capture_s, b.sequence,
                                                              b.arrival_s)
            np.testing.assert_array_equal(a.depth, b.depth)
