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
  ``NAME_rz_rad``, and the hand in its estimated frame (``TrackerEstimate.X_CkE``):
  ``NAME_hand_x_m`` ... ``NAME_hand_qz``.

``estimates.mcap`` (with the ``ros`` extra) carries the same estimates as ROS 2 messages
so Foxglove or RViz can overlay them on the input, one message per topic per estimate,
all stamped with the row's ``t_s``:

* ``/tracker/hand_pose`` (``geometry_msgs/msg/PoseStamped``): X_CE, the hand in the
  first camera's estimated frame, its frame id that frame's: the first camera's child
  on ``/tf`` (``NAME_estimated``);
* with several cameras, ``/tracker/NAME/hand_pose`` for each further camera ``NAME``:
  the hand in that camera's estimated frame (frame id ``NAME_estimated``), which a camera
  that sees the arm holds even where the first camera cannot see it;
* ``/tracker/joint_states`` (``sensor_msgs/msg/JointState``): the estimated angles;
* ``/tf`` (``tf2_msgs/msg/TFMessage``): each camera's estimated pose relative to its
  nominal one, one ``TransformStamped`` per camera from the input's frame id of the
  camera (a bag's depth frame, e.g. ``camera_depth_optical_frame``; for an input
  without frame ids, a recorded run or an LCM log, the model's nominal frame of the
  camera, ``CameraMount.frame``, e.g. ``camera_optical``) to ``NAME_estimated``: the
  transform of the camera's six offset values, ``camera_offset_transform``
  (``robot/model.py``, the virtual joints' kinematics);
* ``/tracker/health`` (``diagnostic_msgs/msg/DiagnosticArray``): the health (see
  :func:`health_status`).

The input's frame of a camera stands for the camera's nominal mount: where the input's
own TF tree (from the robot's description) puts the camera, which is what the model's
nominal frame is. So ``/tf`` hangs each estimated frame under the input's camera frame,
and the hand pose composed with it is the hand where the tracker puts it in the input's
camera frame: ``X_nominal_estimated * X_CE``. The estimated frames are named by the
model's camera names, not the frame ids: they are unique in a model (two cameras whose
input frame ids coincide still get frames of their own), match ``estimates.csv``'s
``NAME_`` columns and the tracker's ``camera_offsets[NAME]``, and stay the same
whatever the input, so a Foxglove or RViz layout that shows ``camera_estimated`` works
for every input.

Earlier bags stamped the hand pose with the input's depth frame id, while X_CE is in
the estimated frame (off by the camera offset, millimetres to centimetres), and hung
``/tf`` from the model's frame names, which need not be the input's, so the tree did
not connect to the input's frames. The pose's values are unchanged; only its frame id
and ``/tf``'s parents changed.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydrake.math import RigidTransform

from drake_tracker.core.robustness.health import HealthState
from drake_tracker.robot.model import camera_offset_transform

if TYPE_CHECKING:
    from drake_tracker.core.filter.estimate import TrackerEstimate
    from drake_tracker.core.robustness.health import TrackerHealth
    from drake_tracker.robot.model import TrackerModel

#: The camera-offset columns, in the order of ``TrackerEstimate.camera_offset``.
CAMERA_COLUMNS = ("camera_x_m", "camera_y_m", "camera_z_m", "camera_rx_rad",
                  "camera_ry_rad", "camera_rz_rad")
POSE_COLUMNS = ("x_m", "y_m", "z_m", "qw", "qx", "qy", "qz")

#: The bag's topics (see the module).
HAND_POSE_TOPIC = "/tracker/hand_pose"
JOINT_STATES_TOPIC = "/tracker/joint_states"
TF_TOPIC = "/tf"
HEALTH_TOPIC = "/tracker/health"
#: ``DiagnosticStatus.name`` of the health.
HEALTH_STATUS_NAME = "drake_tracker/health"
#: ``DiagnosticStatus.level`` of each health state: OK, WARN, ERROR.
HEALTH_LEVELS = {HealthState.TRACKING: 0, HealthState.UNCERTAIN: 1, HealthState.LOST: 2}


def camera_hand_pose_topic(camera: str) -> str:
    """The topic of the hand in a further camera ``camera``'s estimated frame."""
    return f"/tracker/{camera}/hand_pose"


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


def estimated_frame(camera: str) -> str:
    """The frame id of camera ``camera``'s estimated frame in the bag: ``NAME_estimated``."""
    return f"{camera}_estimated"


def camera_tf_frames(model: TrackerModel, frame_ids: Mapping[str, str] | None = None
                     ) -> list[tuple[str, str, str]]:
    """Each camera's (name, ``/tf`` parent, ``/tf`` child) in the bag, the model's first
    camera first: the parent is the input's frame id of the camera (``frame_ids``, by
    the model's camera name), or the model's nominal frame name of a camera it lacks;
    the child is ``NAME_estimated`` (see the module).

    Raises TypeError for a single frame id (a str: name its camera), ValueError for a
    camera the model does not have, or a frame id that is empty or ``NAME_estimated``."""
    if isinstance(frame_ids, str):
        raise TypeError(f"frame ids are by camera name, e.g. "
                        f"{{'{model.camera_names[0]}': '{frame_ids}'}}, not a str")
    frame_ids = dict(frame_ids or {})
    children = {estimated_frame(name) for name in model.camera_names}
    for name, frame in frame_ids.items():
        model.camera(name)  # ValueError naming the model's cameras
        if not frame or frame in children:
            raise ValueError(f"camera '{name}': frame id '{frame}' cannot be a /tf parent "
                             f"(empty, or an estimated frame's name); leave the camera out "
                             f"for the model's frame name")
    return [(name, frame_ids.get(name, model.camera(name).nominal_frame.name()),
             estimated_frame(name)) for name in model.camera_names]


def camera_offset_values(offset: np.ndarray) -> list[float]:
    """[x, y, z, qw, qx, qy, qz] of X_nominal_estimated for a camera's six offset values
    [x, y, z, rx, ry, rz] (m, rad), composed as the virtual joints compose them."""
    return pose_values(camera_offset_transform(offset))


def health_status(health: TrackerHealth,
                  base_ns: int = 0) -> tuple[int, str, list[tuple[str, str]]]:
    """The health as a ``DiagnosticStatus``'s (level, message, key-value pairs).

    Level: ``tracking`` OK, ``uncertain`` WARN, ``lost`` ERROR (``HEALTH_LEVELS``);
    message: the state as ``estimates.csv`` writes it. Values: ``state``, ``acquired``
    and ``restarts``, then, once an image was compared, the latest image's
    ``image_stamp`` (exact decimal seconds in the input's time base), ``robot_pixels``,
    ``agreement``, ``see_through`` and ``occluded`` (``ImageConsistency``; floats as
    ``repr``, so they read back exactly)."""
    state = HealthState(health.state)
    values = [("state", state.name.lower()), ("acquired", str(bool(health.acquired))),
              ("restarts", str(int(health.restarts)))]
    latest = health.latest
    if latest is not None:
        values += [("image_stamp", stamp_text(base_ns, latest.time_s)),
                   ("robot_pixels", str(int(latest.robot_pixels))),
                   *((k, repr(float(getattr(latest, k))))
                     for k in ("agreement", "see_through", "occluded"))]
    return HEALTH_LEVELS[state], state.name.lower(), values


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
                          for c in CAMERA_COLUMNS),
                        *(f"{name}_hand_{c}" for name in self._others for c in POSE_COLUMNS)]
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
                              for v in estimate.camera_offsets[name]),
                            *(repr(float(v)) for name in self._others
                              for v in pose_values(estimate.X_CkE(name)))])
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
    """Writes ``estimates.mcap``: the estimates as ROS 2 messages (see the module).

    ``camera_frames``: the input's frame id of each camera, by the model's camera name
    (a bag's depth frame ids); each is that camera's parent on ``/tf``, and a camera
    left out (or all, with None: an input without frame ids) hangs from the model's
    nominal frame name (:func:`camera_tf_frames`). The hand pose's frame id is the first
    camera's estimated frame, ``hand_frame``. (This replaces ``camera_frame``, the one
    frame id the hand pose was stamped with.)

    The health is a ``diagnostic_msgs/msg/DiagnosticArray`` because that is ROS's message
    for a component's health: its level (OK, WARN, ERROR) is what rqt_robot_monitor,
    Foxglove's diagnostics panels and diagnostic_aggregator show and filter on, and its
    key-value pairs carry the figures behind the state, where a ``std_msgs/String``
    would need a parser of its own. It is on ``/tracker/health``, not ``/diagnostics``:
    it comes with every estimate, far above the usual rate of ``/diagnostics``, stamped
    as the estimate; remap it there for the aggregator."""

    def __init__(self, path: str | Path, model: TrackerModel, base_ns: int = 0,
                 camera_frames: Mapping[str, str] | None = None) -> None:
        from drake_tracker.io.ros_messages import RosMessages, bag_writer

        self.path = Path(path)
        self.messages = RosMessages()
        self.base_ns = int(base_ns)
        self.names = list(model.robot_joint_names)
        self._robot = np.asarray(model.robot_joint_indices, int)
        #: Each camera's (name, /tf parent, /tf child), the first camera first.
        self.cameras = camera_tf_frames(model, camera_frames)
        #: The hand pose's frame id: the first camera's estimated frame.
        self.hand_frame = self.cameras[0][2]
        self._writer = bag_writer(path)
        store = self.messages.store
        self._pose, self._joints, self._tf, self._health = (
            self._writer.add_connection(topic, kind, typestore=store) for topic, kind in (
                (HAND_POSE_TOPIC, "geometry_msgs/msg/PoseStamped"),
                (JOINT_STATES_TOPIC, "sensor_msgs/msg/JointState"),
                (TF_TOPIC, "tf2_msgs/msg/TFMessage"),
                (HEALTH_TOPIC, "diagnostic_msgs/msg/DiagnosticArray")))
        #: Each further camera's (name, its estimated frame, the connection of the hand
        #: in that frame).
        self._camera_hands = [
            (name, child, self._writer.add_connection(
                camera_hand_pose_topic(name), "geometry_msgs/msg/PoseStamped",
                typestore=store)) for name, _, child in self.cameras[1:]]
        self.rows = 0

    def write(self, estimate: TrackerEstimate) -> None:
        """The estimate after a reading, as one message on each topic."""
        stamp = stamp_ns(self.base_ns, estimate.time_s)
        m = self.messages
        pose = m.pose_stamped(stamp, self.hand_frame, pose_values(estimate.X_CE))
        joints = m.joint_state(stamp, self.names, estimate.positions[self._robot])
        first = self.cameras[0][0]
        tf = m.tf_message([m.transform_stamped(
            stamp, parent, child, camera_offset_values(
                estimate.camera_offset if name == first else estimate.camera_offsets[name]))
            for name, parent, child in self.cameras])
        level, text, values = health_status(estimate.health, self.base_ns)
        health = m.diagnostic_array(stamp, level, HEALTH_STATUS_NAME, text, values)
        hands = [(connection, m.pose_stamped(stamp, child, pose_values(estimate.X_CkE(name))))
                 for name, child, connection in self._camera_hands]
        for connection, message in ((self._pose, pose), (self._joints, joints),
                                    (self._tf, tf), (self._health, health), *hands):
            self._writer.write(connection, stamp, m.serialize(message))
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
