"""ROS messages without a ROS install: the ``rosbags`` library (the ``ros`` extra).

Builds and reads the few message types the tracker exchanges (``JointState``, depth
``Image``, ``CameraInfo``, ``PoseStamped``, ``TFMessage``, ``DiagnosticArray``) as ROS 2
(CDR) messages, and opens MCAP bags for writing. The extra's absence is one line that names it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

#: Depth encodings the tracker reads: 16-bit millimetres (0: no return), float metres.
DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")


def require_rosbags() -> None:
    """Raises ImportError (one line, naming the extra) unless ``rosbags`` is installed."""
    try:
        import rosbags  # noqa: F401
    except ImportError as err:
        raise ImportError("reading or writing ROS bags needs the 'ros' extra: pip install "
                          "'drake_tracker[ros]' (the rosbags library)") from err


def bag_writer(path: str | Path) -> Any:
    """An open ROS 2 bag writer with MCAP storage at ``path`` (a new ``.mcap`` file: the
    bag's folder is made beside it and its one MCAP file moved to ``path`` on close)."""
    require_rosbags()
    from rosbags.rosbag2 import StoragePlugin, Writer

    return _McapFileWriter(Path(path), Writer, StoragePlugin.MCAP)


class _McapFileWriter:
    """rosbags writes a bag folder (metadata.yaml beside the .mcap); a single ``.mcap``
    file is what Foxglove and ``ros2 bag`` read without the folder, so the folder's MCAP
    file becomes ``path`` and the folder is removed."""

    def __init__(self, path: Path, writer_class, plugin) -> None:
        if path.exists():
            raise FileExistsError(f"{path} exists: not overwritten")
        self.path = path
        self.folder = path.with_name(path.name + ".bag-folder")
        if self.folder.exists():
            raise FileExistsError(f"{self.folder} exists: remove it first")
        self.writer = writer_class(self.folder, version=8, storage_plugin=plugin)
        self.writer.open()

    def add_connection(self, topic: str, msgtype: str, typestore=None):
        return self.writer.add_connection(topic, msgtype, typestore=typestore)

    def write(self, connection, timestamp_ns: int, data: bytes) -> None:
        self.writer.write(connection, int(timestamp_ns), data)

    def close(self) -> None:
        import shutil

        self.writer.close()
        files = sorted(self.folder.glob("*.mcap"))
        if len(files) != 1:
            raise RuntimeError(f"expected one MCAP file in {self.folder}, found {files}")
        files[0].replace(self.path)
        shutil.rmtree(self.folder)


class RosMessages:
    """ROS 2 (Humble) message types from rosbags' type store, and builders for the
    messages the tracker writes."""

    def __init__(self) -> None:
        require_rosbags()
        from rosbags.typesys import Stores, get_typestore

        self.store = get_typestore(Stores.ROS2_HUMBLE)
        self.types = self.store.types

    def serialize(self, message: Any) -> bytes:
        """The message as CDR bytes."""
        return bytes(self.store.serialize_cdr(message, message.__msgtype__))

    def header(self, stamp_ns: int, frame_id: str) -> Any:
        """A ``std_msgs/msg/Header`` stamped ``stamp_ns`` (integer ns)."""
        t = self.types
        sec, nanosec = divmod(int(stamp_ns), 10**9)
        return t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](
            sec=sec, nanosec=nanosec), frame_id=frame_id)

    def joint_state(self, stamp_ns: int, names: list[str], positions: np.ndarray,
                    frame_id: str = "") -> Any:
        """A ``sensor_msgs/msg/JointState`` with positions only."""
        empty = np.zeros(0, np.float64)
        return self.types["sensor_msgs/msg/JointState"](
            header=self.header(stamp_ns, frame_id), name=list(names),
            position=np.ascontiguousarray(positions, np.float64), velocity=empty,
            effort=empty)

    def pose_stamped(self, stamp_ns: int, frame_id: str, xyz_wxyz: list[float]) -> Any:
        """A ``geometry_msgs/msg/PoseStamped`` from [x, y, z, qw, qx, qy, qz]."""
        t = self.types
        x, y, z, qw, qx, qy, qz = (float(v) for v in xyz_wxyz)
        pose = t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=x, y=y, z=z),
            orientation=t["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw))
        return t["geometry_msgs/msg/PoseStamped"](header=self.header(stamp_ns, frame_id),
                                                  pose=pose)

    def transform_stamped(self, stamp_ns: int, parent: str, child: str,
                          xyz_wxyz: list[float]) -> Any:
        """A ``geometry_msgs/msg/TransformStamped``: the pose of frame ``child`` in frame
        ``parent`` from [x, y, z, qw, qx, qy, qz]."""
        t = self.types
        x, y, z, qw, qx, qy, qz = (float(v) for v in xyz_wxyz)
        transform = t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
            rotation=t["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw))
        return t["geometry_msgs/msg/TransformStamped"](
            header=self.header(stamp_ns, parent), child_frame_id=child, transform=transform)

    def tf_message(self, transforms: list[Any]) -> Any:
        """A ``tf2_msgs/msg/TFMessage`` of ``TransformStamped`` messages."""
        return self.types["tf2_msgs/msg/TFMessage"](transforms=list(transforms))

    def diagnostic_array(self, stamp_ns: int, level: int, name: str, message: str,
                         values: list[tuple[str, str]], hardware_id: str = "") -> Any:
        """A ``diagnostic_msgs/msg/DiagnosticArray`` of one ``DiagnosticStatus``:
        ``level`` (``DiagnosticStatus.OK``, ``WARN``, ``ERROR``, ``STALE``: 0-3), and
        ``values`` as its key-value pairs."""
        t = self.types
        pairs = [t["diagnostic_msgs/msg/KeyValue"](key=str(k), value=str(v))
                 for k, v in values]
        status = t["diagnostic_msgs/msg/DiagnosticStatus"](
            level=int(level), name=name, message=message, hardware_id=hardware_id,
            values=pairs)
        return t["diagnostic_msgs/msg/DiagnosticArray"](header=self.header(stamp_ns, ""),
                                                        status=[status])

    def depth_image(self, stamp_ns: int, frame_id: str, depth: np.ndarray) -> Any:
        """A depth ``sensor_msgs/msg/Image``: ``32FC1`` for float metres (NaN: no return),
        ``16UC1`` for uint16 millimetres (0: no return); little-endian."""
        depth = np.ascontiguousarray(depth)
        if depth.dtype == np.uint16:
            encoding, data = "16UC1", depth.astype("<u2")
        else:
            encoding, data = "32FC1", depth.astype("<f4")
        h, w = depth.shape
        return self.types["sensor_msgs/msg/Image"](
            header=self.header(stamp_ns, frame_id), height=h, width=w, encoding=encoding,
            is_bigendian=0, step=w * data.itemsize,
            data=np.frombuffer(data.tobytes(), np.uint8))

    def camera_info(self, stamp_ns: int, frame_id: str, width: int, height: int,
                    fx: float, fy: float, cx: float, cy: float) -> Any:
        """A pinhole ``sensor_msgs/msg/CameraInfo`` without distortion."""
        t = self.types
        k = np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], np.float64)
        p = np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], np.float64)
        roi = t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0,
                                                    width=0, do_rectify=False)
        return t["sensor_msgs/msg/CameraInfo"](
            header=self.header(stamp_ns, frame_id), height=int(height), width=int(width),
            distortion_model="plumb_bob", d=np.zeros(5, np.float64), k=k,
            r=np.eye(3).ravel(), p=p, binning_x=0, binning_y=0, roi=roi)


def stamp_ns(message: Any) -> int:
    """A message's ``header.stamp`` as integer nanoseconds."""
    stamp = message.header.stamp
    return int(stamp.sec) * 10**9 + int(stamp.nanosec)


def depth_from_image(message: Any) -> np.ndarray:
    """The (H, W) depth of a ``sensor_msgs/Image``: uint16 millimetres (``16UC1``,
    ``mono16``) or float32 metres (``32FC1``). Raises ValueError naming any other
    encoding, or a buffer that does not hold the image."""
    encoding = str(message.encoding)
    if encoding not in DEPTH_ENCODINGS:
        raise ValueError(f"depth image encoding '{encoding}' is not a depth encoding "
                         f"(expected one of {', '.join(DEPTH_ENCODINGS)})")
    dtype = np.dtype("u2" if encoding != "32FC1" else "f4")
    dtype = dtype.newbyteorder(">" if message.is_bigendian else "<")
    h, w, step = int(message.height), int(message.width), int(message.step)
    data = np.asarray(message.data, np.uint8)
    if h <= 0 or w <= 0 or step < w * dtype.itemsize or data.size < h * step:
        raise ValueError(f"depth image of {w}x{h} ({encoding}, step {step}) has "
                         f"{data.size} bytes of data: truncated or inconsistent")
    rows = data[:h * step].reshape(h, step)[:, :w * dtype.itemsize]
    return np.ascontiguousarray(rows).view(dtype).reshape(h, w).astype(dtype.newbyteorder("="))
