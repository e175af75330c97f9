"""The tracker's estimates written out, for other tools: a CSV table and a ROS 2 MCAP bag.

``estimates.csv`` has one row per joint reading the tracker used, columns:

* ``t_s``: the reading's stamp in the input's own time base (Unix seconds for a bag),
  written exactly to the nanosecond: the base is kept as integer nanoseconds and only
  the offset from it went through the filter;
* ``x_m, y_m, z_m, qw, qx, qy, qz``: X_CE, the hand in the estimated camera frame;
* ``health``: ``tracking``, ``uncertain`` or ``lost`` (``core/robustness/health.py``);
* ``angle_<joint>_<unit>``, ``bias_<joint>_<unit>`` for each robot joint (``rad``, or
  ``m`` for a prismatic joint);
* ``camera_x_m, camera_y_m, camera_z_m, camera_rx_rad, camera_ry_rad, camera_rz_rad``:
  the estimated camera relative to the nominal one (with several cameras, the first's);
* with several cameras, each further camera ``NAME``'s offset: ``NAME_x_m`` ...
  ``NAME_rz_rad``.

``estimates.mcap`` (with the ``ros`` extra) carries the same estimates as ROS 2 messages
so Foxglove or RViz can overlay them on the input: ``/tracker/hand_pose``
(``geometry_msgs/msg/PoseStamped``, X_CE in the camera's frame) and
``/tracker/joint_states`` (``sensor_msgs/msg/JointState``, the estimated angles).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydrake.math import RigidTransform

from drake_tracker.core.robustness.health import HealthState

if TYPE_CHECKING:
    from drake_tracker.core.filter.estimate import TrackerEstimate
    from drake_tracker.robot.model import TrackerModel

#: The camera-offset columns, in the order of ``TrackerEstimate.camera_offset``.
CAMERA_COLUMNS = ("camera_x_m", "camera_y_m", "camera_z_m", "camera_rx_rad",
                  "camera_ry_rad", "camera_rz_rad")
POSE_COLUMNS = ("x_m", "y_m", "z_m", "qw", "qx", "qy", "qz")


def stamp_ns(base_ns: int, time_s: float) -> int:
    """``base_ns`` (integer nanoseconds) plus ``time_s`` rounded to the nanosecond: the
    one rule every writer stamps by, so a run and its bag hold the same times."""
    return int(base_ns) + int(round(float(time_s) * 1e9))


def stamp_text(base_ns: int, time_s: float) -> str:
    """``base_ns`` (integer nanoseconds) plus ``time_s``, as exact decimal seconds."""
    total = stamp_ns(base_ns, time_s)
    sign = "-" if total < 0 else ""
    seconds, nanos = divmod(abs(total), 10**9)
    return f"{sign}{seconds}.{nanos:09d}"


def pose_values(X_CE: np.ndarray) -> list[float]:
    """[x, y, z, qw, qx, qy, qz] of a 4x4 pose (the quaternion with qw >= 0)."""
    X = RigidTransform(np.asarray(X_CE, float))
    q = X.rotation().ToQuaternion().wxyz()
    q = -q if q[0] < 0 else q
    return [*X.translation(), *q]


class EstimatesCsv:
    """Writes ``estimates.csv`` (see the module) row by row; ``base_ns`` is the input's
    time base (integer nanoseconds) that the estimates' times are relative to."""

    def __init__(self, path: str | Path, model: TrackerModel, base_ns: int = 0) -> None:
        self.path = Path(path)
        self.base_ns = int(base_ns)
        self._robot = np.asarray(model.robot_joint_indices, int)
        prismatic = set(model.prismatic_joint_names)
        names = model.robot_joint_names
        units = ["m" if n in prismatic else "rad" for n in names]
        #: The further cameras, whose offsets follow the first camera's.
        self._others = list(model.camera_names[1:])
        self.columns = ["t_s", *POSE_COLUMNS, "health",
                        *(f"{kind}_{n}_{u}" for n, u in zip(names, units)
                          for kind in ("angle", "bias")), *CAMERA_COLUMNS,
                        *(name + c.removeprefix("camera") for name in self._others
                          for c in CAMERA_COLUMNS)]
        self._file = self.path.open("w", newline="")
        self._csv = csv.writer(self._file)
        self._csv.writerow(self.columns)
        self.rows = 0

    def write(self, estimate: TrackerEstimate) -> None:
        """One row: the estimate after a reading."""
        angles = estimate.positions[self._robot]
        biases = estimate.biases[self._robot]
        joint_values = np.column_stack([angles, biases]).ravel()
        self._csv.writerow([stamp_text(self.base_ns, estimate.time_s),
                            *(repr(float(v)) for v in pose_values(estimate.X_CE)),
                            HealthState(estimate.health.state).name.lower(),
                            *(repr(float(v)) for v in joint_values),
                            *(repr(float(v)) for v in estimate.camera_offset),
                            *(repr(float(v)) for name in self._others
                              for v in estimate.camera_offsets[name])])
        self.rows += 1

    def close(self) -> None:
        """Flushes and closes the file."""
        self._file.close()


def read_estimates_csv(path: str | Path) -> dict[str, np.ndarray]:
    """``estimates.csv`` back as columns: floats, ``t_s`` relative to its first row
    (``t0_s`` holds that row's exact stamp text), ``health`` as strings."""
    with Path(path).open(newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    out: dict[str, np.ndarray] = {}
    for k, name in enumerate(header):
        column = [r[k] for r in body]
        if name == "health":
            out[name] = np.array(column)
        elif name == "t_s":
            out["t0_s"] = np.array(column[:1])
            out[name] = np.array([_relative(t, column[0]) for t in column])
        else:
            out[name] = np.array(column, float)
    return out


def _relative(text: str, base: str) -> float:
    def ns(t: str) -> int:
        whole, _, frac = t.partition(".")
        sign = -1 if whole.startswith("-") else 1
        return sign * (abs(int(whole)) * 10**9 + int((frac + "000000000")[:9]))
    return (ns(text) - ns(base)) / 10**9


class EstimatesBag:
    """Writes ``estimates.mcap``: the estimates as ROS 2 messages (see the module);
    ``camera_frame`` names the frame of the hand pose (the input's depth frame id)."""

    def __init__(self, path: str | Path, model: TrackerModel, base_ns: int = 0,
                 camera_frame: str = "camera") -> None:
        from drake_tracker.io.ros_messages import RosMessages, bag_writer

        self.path = Path(path)
        self.messages = RosMessages()
        self.base_ns = int(base_ns)
        self.camera_frame = camera_frame
        self.names = list(model.robot_joint_names)
        self._robot = np.asarray(model.robot_joint_indices, int)
        self._writer = bag_writer(path)
        self._pose = self._writer.add_connection(
            "/tracker/hand_pose", "geometry_msgs/msg/PoseStamped",
            typestore=self.messages.store)
        self._joints = self._writer.add_connection(
            "/tracker/joint_states", "sensor_msgs/msg/JointState",
            typestore=self.messages.store)
        self.rows = 0

    def write(self, estimate: TrackerEstimate) -> None:
        """The estimate after a reading, as one message on each topic."""
        stamp = stamp_ns(self.base_ns, estimate.time_s)
        m = self.messages
        pose = m.pose_stamped(stamp, self.camera_frame, pose_values(estimate.X_CE))
        joints = m.joint_state(stamp, self.names, estimate.positions[self._robot])
        self._writer.write(self._pose, stamp, m.serialize(pose))
        self._writer.write(self._joints, stamp, m.serialize(joints))
        self.rows += 1

    def close(self) -> None:
        """Finishes the bag."""
        self._writer.close()


class EstimateSinks:
    """Several sinks as one (``track_stream`` writes to each)."""

    def __init__(self, *sinks: Any) -> None:
        self.sinks = [s for s in sinks if s is not None]

    def write(self, estimate: TrackerEstimate) -> None:
        """Writes ``estimate`` to every sink."""
        for sink in self.sinks:
            sink.write(estimate)

    def close(self) -> None:
        """Closes every sink."""
        for sink in self.sinks:
            sink.close()
