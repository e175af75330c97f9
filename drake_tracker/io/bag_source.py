"""A ROS bag as the tracker's input: a ROS 1 ``.bag``, a ROS 2 bag folder (sqlite3 or
MCAP storage) or a single ``.mcap`` file, read with ``rosbags`` (the ``ros`` extra).

* Topics are found by message type: ``sensor_msgs/JointState`` for the readings, a
  ``sensor_msgs/Image`` for depth (or image_transport's ``compressedDepth``, a
  ``sensor_msgs/CompressedImage`` on ``<image topic>/compressedDepth``:
  ``io/compressed_depth.py``), ``sensor_msgs/CameraInfo`` for its intrinsics. Where a
  type has several topics, the error lists them and the flag that picks one.
* Joints are matched by name: joints the model lacks are ignored; a model joint missing
  from the messages is an error (at the first message), or a skipped, counted message
  later on.
* Depth ``16UC1``/``mono16`` (millimetres, 0: no return) and ``32FC1`` (metres, NaN or 0:
  no return), at the ``CameraInfo``'s resolution; the tracker subsamples it to its
  working size. A camera with non-zero distortion is an error: the tracker's renderer is
  a pinhole, so rectify first (``image_proc``).
* Times are each message's ``header.stamp``, relative to the first one's: integer
  nanoseconds until then (Unix stamps of 1.7e9 s would lose 0.2 µs in a float), then
  the nearest float to their count over 1e9.
* Messages stream in the bag's order, one at a time: memory stays flat on long bags.
* Several depth cameras (``BagTopics.cameras``: each a camera of the model by name, its
  depth topic and its CameraInfo topic): each camera's images are named by it
  (``ImageEvent.camera``), numbered on their own, with the camera's own intrinsics.
* Each camera's frame id (its CameraInfo's ``header.frame_id``) is where the tracker's
  ``estimates.mcap`` hangs that camera's estimated frame on ``/tf``
  (:meth:`BagSource.frame_ids`, ``io/estimates_out.py``).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.io.camera_sources import check_camera_sources
from drake_tracker.io.compressed_depth import (
    COMPRESSED_IMAGE,
    TRANSPORT_SUFFIX,
    base_image_topic,
    depth_from_compressed,
)
from drake_tracker.io.ros_messages import depth_from_image, require_rosbags, stamp_ns
from drake_tracker.io.stream import (
    Event,
    ImageEvent,
    ReadingEvent,
    SkippedMessage,
    logged_arrival,
)

JOINT_STATE = "sensor_msgs/msg/JointState"
IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
#: Topics under this prefix hold a simulated run's truth: never tracked from.
TRUTH_PREFIX = "/truth/"
#: The topic a ``record --bag`` bag keeps the true hand pose on (X_CE).
TRUTH_POSE_TOPIC = TRUTH_PREFIX + "hand_pose"


@dataclass(frozen=True)
class CameraTopics:
    """One depth camera of a bag: the model's camera ``name``, its depth Image topic and
    its CameraInfo topic (None: the only CameraInfo topic in the depth topic's
    namespace, e.g. ``/post/depth/camera_info`` beside ``/post/depth/image_raw``)."""

    name: str
    depth: str
    camera_info: str | None = None


@dataclass(frozen=True)
class BagTopics:
    """The topics a bag is tracked from (``None``: find it by type); ``cameras``:
    instead of ``depth`` and ``camera_info``, several depth cameras."""

    joints: str | None = None
    depth: str | None = None
    camera_info: str | None = None
    cameras: tuple[CameraTopics, ...] = ()


@dataclass(frozen=True)
class BagCamera:
    """A depth camera read from a bag: its topics, intrinsics and frame id (its
    CameraInfo's ``header.frame_id``; empty where the bag gives none)."""

    #: The model's camera (None: the bag's one camera, read without a name).
    name: str | None
    depth_topic: str
    camera_info_topic: str
    intrinsics: CameraIntrinsics
    frame: str


def check_camera_topics(cameras: tuple[CameraTopics, ...],
                        model_cameras: list[str] | None = None) -> None:
    """ValueError for a camera the model does not have (with ``model_cameras``, the
    model's camera names), two cameras of one name, or one depth topic for two
    cameras."""
    check_camera_sources([c.name for c in cameras], [c.depth for c in cameras],
                         "depth topic", model_cameras)


def info_topic_beside(reader: Any, depth_topic: str, camera: str) -> str:
    """The only CameraInfo topic in ``depth_topic``'s namespace (an error naming them)."""
    namespace = base_image_topic(depth_topic).rsplit("/", 1)[0] + "/"
    candidates = sorted({c.topic for c in reader.connections if c.msgtype == CAMERA_INFO
                         and c.topic.startswith(namespace)})
    if len(candidates) != 1:
        raise ValueError(f"camera '{camera}': {len(candidates)} CameraInfo topics beside "
                         f"{depth_topic} ({candidates or 'none'}): pick one with "
                         f"--camera-info-topic {camera}=TOPIC")
    return candidates[0]


def open_bag(path: str | Path) -> Any:
    """An open rosbags ``AnyReader`` over ``path``. Raises ValueError naming the file
    when it is not a bag rosbags can read (missing, truncated, corrupt)."""
    require_rosbags()
    from rosbags.highlevel import AnyReader

    path = Path(path)
    if not path.exists():
        raise ValueError(f"bag {path} does not exist")
    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as err:  # rosbags raises its own error types per format
        raise ValueError(f"bag {path} cannot be read: {err}") from err
    return reader


def pick_topic(reader: Any, msgtype: str, wanted: str | None, flag: str) -> str:
    """The topic of ``msgtype`` to read: ``wanted`` if given (an error if the bag has no
    such topic of that type), else the only one outside ``TRUTH_PREFIX`` (an error
    listing the candidates)."""
    candidates = sorted({c.topic for c in reader.connections if c.msgtype == msgtype
                         and not c.topic.startswith(TRUTH_PREFIX)})
    return _chosen(candidates, candidates, wanted, msgtype, flag)


def pick_depth_topic(reader: Any, wanted: str | None, flag: str) -> str:
    """The depth topic to read: ``wanted`` if given (a ``sensor_msgs/Image`` or a
    ``sensor_msgs/CompressedImage`` topic of the bag), else the only ``Image`` topic or
    ``compressedDepth`` topic outside ``TRUTH_PREFIX`` (a color camera's ``.../compressed``
    topic is not a candidate)."""
    ours = [c for c in reader.connections if not c.topic.startswith(TRUTH_PREFIX)]
    allowed = sorted({c.topic for c in ours if c.msgtype in (IMAGE, COMPRESSED_IMAGE)})
    candidates = sorted({c.topic for c in ours if c.msgtype == IMAGE or (
        c.msgtype == COMPRESSED_IMAGE and c.topic.endswith(TRANSPORT_SUFFIX))})
    return _chosen(candidates, allowed, wanted,
                   f"depth ({IMAGE}, or {COMPRESSED_IMAGE} on .../compressedDepth)", flag)


def _chosen(candidates: list[str], allowed: list[str], wanted: str | None, kind: str,
            flag: str) -> str:
    """``wanted`` if it is among ``allowed``, else the only one of ``candidates``;
    ValueError naming the ``kind`` of topic and listing them otherwise."""
    if wanted is not None:
        if wanted not in allowed:
            raise ValueError(f"the bag has no {kind} topic '{wanted}'; its {kind} "
                             f"topics: {allowed or 'none'}")
        return wanted
    if len(candidates) != 1:
        raise ValueError(f"the bag has {len(candidates)} {kind} topics "
                         f"({candidates or 'none'}): pick one with {flag}")
    return candidates[0]


def intrinsics_from_camera_info(message: Any) -> CameraIntrinsics:
    """The pinhole intrinsics of a ``CameraInfo``. Raises ValueError for a camera with
    distortion (the tracker does not undistort: rectify the images first) or a
    degenerate matrix."""
    d = np.asarray(message.d if hasattr(message, "d") else message.D, float)
    if np.any(np.abs(d) > 1e-12):
        raise ValueError(f"CameraInfo has distortion {d.tolist()} "
                         f"({message.distortion_model}): the tracker renders a pinhole "
                         f"camera and does not undistort; rectify the depth images first "
                         f"(e.g. image_proc) and pass the rectified CameraInfo")
    k = np.asarray(message.k if hasattr(message, "k") else message.K, float).reshape(3, 3)
    if not (k[0, 0] > 0 and k[1, 1] > 0 and message.width > 0 and message.height > 0):
        raise ValueError(f"CameraInfo is degenerate: {message.width}x{message.height}, "
                         f"K = {k.ravel().tolist()}")
    return CameraIntrinsics(int(message.width), int(message.height), float(k[0, 0]),
                            float(k[1, 1]), float(k[0, 2]), float(k[1, 2]))


class BagSource:
    """The events of a bag (``io/stream.py``) for a model's robot joints.

    Args:
        path: the bag (see the module).
        joint_names: the model's robot joints, in its order.
        topics: topic names, where the types are ambiguous.
    """

    def __init__(self, path: str | Path, joint_names: list[str],
                 topics: BagTopics = BagTopics()) -> None:
        self.path = Path(path)
        self.joint_names = list(joint_names)
        self.reader = open_bag(path)
        r = self.reader
        self.joint_topic = pick_topic(r, JOINT_STATE, topics.joints, "--joint-topic")
        if topics.cameras:
            check_camera_topics(topics.cameras)
            wanted = [(c.name, pick_depth_topic(r, c.depth, "--depth-topic"),
                       c.camera_info or info_topic_beside(r, c.depth, c.name))
                      for c in topics.cameras]
        else:
            wanted = [(None, pick_depth_topic(r, topics.depth, "--depth-topic"),
                       pick_topic(r, CAMERA_INFO, topics.camera_info,
                                  "--camera-info-topic"))]
        #: Each depth camera (name None: the bag's one camera of a one-camera call).
        self.cameras = [self._camera(*w) for w in wanted]
        first_camera = self.cameras[0]
        self.depth_topic, self.camera_info_topic = (first_camera.depth_topic,
                                                    first_camera.camera_info_topic)
        self.intrinsics, self.camera_frame = first_camera.intrinsics, first_camera.frame
        first = [self._first(t) for t in [self.joint_topic] + self.depth_topics]
        stamps = [stamp_ns(m) for m in first if m is not None]
        if first[0] is None:
            raise ValueError(f"bag {self.path}: no message on {self.joint_topic}")
        self._columns(first[0])  # a model joint the messages lack is an error here
        #: The time base (integer ns): the first joint or depth message's stamp.
        self.base_ns = min(stamps)
        self.num_images = sum(c.msgcount for c in r.connections
                              if c.topic in self.depth_topics)
        truth = [c for c in r.connections
                 if c.topic == TRUTH_POSE_TOPIC and c.msgtype == POSE_STAMPED]
        self._truth = truth

    @property
    def depth_topics(self) -> list[str]:
        """Every camera's depth topic."""
        return [c.depth_topic for c in self.cameras]

    def camera_models(self) -> dict[str, CameraIntrinsics] | CameraIntrinsics:
        """The cameras' intrinsics by name (``Tracker(cameras=...)``), or the one camera's
        (``Tracker(model, camera)``) for a bag read without camera names."""
        if self.cameras[0].name is None:
            return self.intrinsics
        return {c.name: c.intrinsics for c in self.cameras}

    def _camera(self, name: str | None, depth_topic: str, info_topic: str) -> BagCamera:
        info = self._first(info_topic)
        if info is None:
            raise ValueError(f"bag {self.path}: no CameraInfo message on {info_topic}")
        return BagCamera(name, depth_topic, info_topic, intrinsics_from_camera_info(info),
                         str(info.header.frame_id))

    def frame_ids(self, first_camera: str) -> dict[str, str]:
        """Each camera's frame id in the bag by the model's camera name, for
        ``EstimatesBag(camera_frames=...)``: the bag's one camera, read without a name,
        is ``first_camera`` (the model's first camera, the one it is tracked as); a
        camera whose CameraInfo has no frame id is left out (the model's frame name
        stands for it)."""
        return {c.name or first_camera: c.frame for c in self.cameras if c.frame}

    def _first(self, topic: str) -> Any:
        connections = [c for c in self.reader.connections if c.topic == topic]
        for connection, _, raw in self.reader.messages(connections=connections):
            return self.reader.deserialize(raw, connection.msgtype)
        return None

    def _columns(self, message: Any) -> np.ndarray:
        names = list(message.name)
        missing = [n for n in self.joint_names if n not in names]
        if missing:
            raise ValueError(f"joint {missing[0]} of the model is not in the "
                             f"{self.joint_topic} messages (they name {names}); "
                             f"missing: {missing}")
        return np.array([names.index(n) for n in self.joint_names])

    def events(self) -> Iterator[Event]:
        """The readings and depth images in the bag's order (see the module)."""
        r = self.reader
        camera_of = {c.depth_topic: c.name for c in self.cameras}
        wanted = [c for c in r.connections
                  if c.topic == self.joint_topic or c.topic in camera_of]
        columns_for: dict[tuple, np.ndarray | str] = {}
        sequences = dict.fromkeys(camera_of.values(), 0)
        try:
            for connection, log_ns, raw in r.messages(connections=wanted):
                try:
                    message = r.deserialize(raw, connection.msgtype)
                except Exception as err:  # a corrupt message: skipped and counted
                    yield SkippedMessage("undecodable messages", f"a message on "
                                         f"{connection.topic} cannot be decoded: {err}")
                    continue
                t = (stamp_ns(message) - self.base_ns) / 10**9
                if connection.topic == self.joint_topic:
                    key = tuple(message.name)
                    if key not in columns_for:
                        try:
                            columns_for[key] = self._columns(message)
                        except ValueError as err:
                            columns_for[key] = str(err)
                    columns = columns_for[key]
                    if isinstance(columns, str):
                        yield SkippedMessage("joint messages without the model's joints",
                                             f"joint message at {t:.6f} s skipped: "
                                             f"{columns}")
                        continue
                    position = np.asarray(message.position, float)
                    if position.size != len(message.name):
                        yield SkippedMessage("joint messages with mismatched lengths",
                                             f"joint message at {t:.6f} s skipped: "
                                             f"{len(message.name)} names, "
                                             f"{position.size} positions")
                        continue
                    yield ReadingEvent(t, position[columns])
                else:
                    try:
                        depth = (depth_from_compressed(message)
                                 if connection.msgtype == COMPRESSED_IMAGE
                                 else depth_from_image(message))
                    except ValueError as err:
                        yield SkippedMessage("depth images not usable",
                                             f"depth image at {t:.6f} s skipped: {err}")
                        continue
                    arrival = logged_arrival(t, (int(log_ns) - self.base_ns) / 10**9)
                    camera = camera_of[connection.topic]
                    yield ImageEvent(t, depth, sequences[camera], arrival, camera)
                    sequences[camera] += 1
        except Exception as err:
            if isinstance(err, GeneratorExit):
                raise
            raise ValueError(f"bag {self.path} is truncated or corrupt after "
                             f"{sum(sequences.values())} depth images: {err}") from err

    def truth_X_CE(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(times, (T, 4, 4) X_CE) of the bag's truth topic (``record --bag`` writes
        one), or None."""
        if not self._truth:
            return None
        from pydrake.common.eigen_geometry import Quaternion
        from pydrake.math import RigidTransform

        times, poses = [], []
        for connection, _, raw in self.reader.messages(connections=self._truth):
            m = self.reader.deserialize(raw, connection.msgtype)
            o, p = m.pose.orientation, m.pose.position
            X = RigidTransform(Quaternion(o.w, o.x, o.y, o.z), [p.x, p.y, p.z])
            times.append((stamp_ns(m) - self.base_ns) / 10**9)
            poses.append(X.GetAsMatrix4())
        return np.array(times), np.array(poses)

    def close(self) -> None:
        """Closes the bag."""
        self.reader.close()
