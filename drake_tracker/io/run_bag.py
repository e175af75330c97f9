"""A recorded run written as a ROS 2 MCAP bag (``drake-tracker record --bag``), so the
bag path can be tried end to end without a robot.

Topics: ``/joint_states`` (``sensor_msgs/msg/JointState``), ``/camera/depth/image_raw``
(``32FC1``, metres, NaN: no return), ``/camera/depth/camera_info`` (one per image), and
the truth:

* ``/truth/hand_pose`` (``geometry_msgs/msg/PoseStamped``): X_CE, the hand in the first
  camera's true frame, its frame id that frame's: the first camera's child on ``/tf``
  (``NAME_true``);
* ``/truth/joint_states`` (``sensor_msgs/msg/JointState``): the true angles;
* ``/tf`` (``tf2_msgs/msg/TFMessage``): each camera's true pose relative to its nominal
  one (the mounting error), one message per truth sample holding one
  ``TransformStamped`` per camera, the first camera first, from the camera's depth
  frame id in this bag (:func:`camera_topics`) to ``NAME_true``: the transform of the
  run's six true offset values of the camera (``truth_camera_offset``),
  ``camera_offset_transform`` (``robot/model.py``). A camera without them (none, not
  one row of six per truth sample, or not finite) is an error before the bag is made.

Header stamps are the run's times plus ``base_ns`` (a Unix time: real bags' stamps
are); each message is logged at its stamp, an image at its arrival.

The depth frame id stands for the camera's nominal mount, as in the tracker's
``estimates.mcap`` (``io/estimates_out.py``), which hangs ``NAME_estimated`` from the
input's frame id of the camera: tracking this bag puts ``camera_estimated`` beside
``camera_true`` under ``camera_depth_optical_frame``, and ``/tracker/hand_pose`` and
``/truth/hand_pose`` composed with ``/tf`` are both the hand in that frame. The true
frames are named by the run's camera names (unique in a run, and whatever the frame
ids), as the estimated frames are by the model's. Earlier bags stamped the truth pose
with the depth frame id, off by the mounting error, and had no ``/tf``; the pose's
values are unchanged.

A run of several cameras (``RecordedRun.other_cameras``) writes each further camera
``NAME``'s images on ``/NAME/depth/image_raw`` and ``/NAME/depth/camera_info``
(:func:`camera_topics`; frame ``NAME_depth_optical_frame``); ``track --bag`` takes them
back with ``--depth-topic NAME=TOPIC``. ``track --bag`` reads only the JointState,
Image and CameraInfo topics outside ``/truth/``, so ``/tf`` does not reach the tracker.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.io.bag_source import TRUTH_POSE_TOPIC
from drake_tracker.io.estimates_out import (
    TF_TOPIC,
    camera_offset_values,
    pose_values,
    stamp_ns,
)
from drake_tracker.io.ros_messages import RosMessages, bag_writer

if TYPE_CHECKING:
    from drake_tracker.io.recording import RecordedRun

#: 2023-11-14T22:13:20Z: the default time base of a written bag (ns).
DEFAULT_BASE_NS = 1_700_000_000 * 10**9
CAMERA_FRAME = "camera_depth_optical_frame"
#: The first camera's topics (its name aside).
DEPTH_TOPIC, CAMERA_INFO_TOPIC = "/camera/depth/image_raw", "/camera/depth/camera_info"


def camera_topics(run: RecordedRun) -> dict[str, tuple[str, str, str]]:
    """Each camera's (depth topic, camera-info topic, frame id) in a written bag: the
    first camera's are ``DEPTH_TOPIC``, ``CAMERA_INFO_TOPIC`` and ``CAMERA_FRAME``
    whatever its name, a further camera ``NAME``'s ``/NAME/depth/...``."""
    topics = {run.camera_name: (DEPTH_TOPIC, CAMERA_INFO_TOPIC, CAMERA_FRAME)}
    for camera in run.other_cameras:
        topics[camera.name] = (f"/{camera.name}/depth/image_raw",
                               f"/{camera.name}/depth/camera_info",
                               f"{camera.name}_depth_optical_frame")
    return topics


def true_frame(camera: str) -> str:
    """The frame id of camera ``camera``'s true frame in a written bag: ``NAME_true``."""
    return f"{camera}_true"


def truth_tf_frames(run: RecordedRun) -> list[tuple[str, str, str, np.ndarray]]:
    """Each camera's (name, ``/tf`` parent, ``/tf`` child, (T, 6) true offsets) in a
    written bag, the first camera first: the parent is the camera's depth frame id
    (:func:`camera_topics`), the child ``NAME_true`` (see the module).

    Raises ValueError naming a camera whose true offsets are missing: none, not one row
    of six values per truth sample, or a value that is not finite."""
    frames = {name: frame for name, (_, _, frame) in camera_topics(run).items()}
    offsets = run.truth_offsets_by_camera
    expected = (len(run.truth_times_s), 6)
    out = []
    for name, frame in frames.items():
        values = offsets[name]
        shape = None if values is None else np.shape(values)
        if shape != expected:
            raise ValueError(f"camera '{name}': its true camera offset is missing "
                             f"(truth_camera_offset of shape {shape}, expected "
                             f"{expected}: six values per truth sample), so the bag "
                             f"cannot place its true frame '{true_frame(name)}' on /tf")
        values = np.asarray(values, float)
        bad = np.flatnonzero(~np.isfinite(values).all(axis=1))
        if bad.size:
            raise ValueError(f"camera '{name}': its true camera offset at truth sample "
                             f"{int(bad[0])} is not finite ({values[bad[0]].tolist()}), "
                             f"so the bag cannot place its true frame "
                             f"'{true_frame(name)}' on /tf")
        out.append((name, frame, true_frame(name), values))
    return out


def write_run_bag(run: RecordedRun, path: str | Path, base_ns: int = DEFAULT_BASE_NS
                  ) -> int:
    """Writes ``run`` to the MCAP file ``path`` (see the module); returns the number of
    messages written. Raises ValueError (before making the file) for a camera without
    its true offsets (:func:`truth_tf_frames`)."""
    frames = truth_tf_frames(run)
    m = RosMessages()
    writer = bag_writer(path)
    try:
        topics = {
            "joints": ("/joint_states", "sensor_msgs/msg/JointState"),
            "tf": (TF_TOPIC, "tf2_msgs/msg/TFMessage"),
            "truth_pose": (TRUTH_POSE_TOPIC, "geometry_msgs/msg/PoseStamped"),
            "truth_joints": ("/truth/joint_states", "sensor_msgs/msg/JointState"),
        }
        for name, (depth, info, _) in camera_topics(run).items():
            topics[("info", name)] = (info, "sensor_msgs/msg/CameraInfo")
            topics[("depth", name)] = (depth, "sensor_msgs/msg/Image")
        connections = {k: writer.add_connection(topic, kind, typestore=m.store)
                       for k, (topic, kind) in topics.items()}
        count = 0
        for log_ns, key, message in _messages(run, m, base_ns, frames):
            writer.write(connections[key], log_ns, m.serialize(message))
            count += 1
    finally:
        writer.close()
    return count


def _messages(run: RecordedRun, m: RosMessages, base_ns: int,
              true_frames: list[tuple[str, str, str, np.ndarray]]) -> Iterator[tuple]:
    """(log time ns, topic key, message) in log order, built one at a time;
    ``true_frames``: :func:`truth_tf_frames`. At a truth stamp, ``/tf`` comes first."""
    names = list(run.joint_names)

    def readings():
        for t, q in zip(run.reading_times_s, run.readings_rad):
            yield stamp_ns(base_ns, t), 0, "joints", lambda t=t, q=q: m.joint_state(
                stamp_ns(base_ns, t), names, q)

    def images(camera, frame):
        cam = camera.intrinsics
        order, _ = camera.arrival_order()
        for i in order:
            stamp = stamp_ns(base_ns, camera.capture_times_s[i])
            arrival = stamp_ns(base_ns, camera.arrival_times_s[i])
            yield arrival, 1, ("info", camera.name), lambda s=stamp: m.camera_info(
                s, frame, cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy)
            yield arrival, 2, ("depth", camera.name), lambda s=stamp, i=i: m.depth_image(
                s, frame, np.asarray(camera.depth_images_m[i], np.float32))

    hand_frame = true_frames[0][2]

    def tf(stamp, k):
        return m.tf_message([m.transform_stamped(stamp, parent, child,
                                                 camera_offset_values(offsets[k]))
                             for _, parent, child, offsets in true_frames])

    def truth():
        for k, (t, X, q) in enumerate(zip(run.truth_times_s, run.truth_X_CE,
                                          run.truth_positions_rad)):
            stamp = stamp_ns(base_ns, t)
            yield stamp, 3, "tf", lambda s=stamp, k=k: tf(s, k)
            yield stamp, 4, "truth_pose", lambda s=stamp, X=X: m.pose_stamped(
                s, hand_frame, pose_values(X))
            yield stamp, 5, "truth_joints", lambda s=stamp, q=q: m.joint_state(s, names, q)

    run.warn_unplayable("bag")
    frames = {name: frame for name, (_, _, frame) in camera_topics(run).items()}
    cameras = [images(c, frames[c.name]) for c in run.cameras]
    for log_ns, _, key, build in heapq.merge(readings(), *cameras, truth(),
                                             key=lambda e: (e[0], e[1])):
        yield log_ns, key, build()
