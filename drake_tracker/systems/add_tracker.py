"""``AddTracker``: wires the three tracker systems into a user's DiagramBuilder.

Event times within one encoder period ``h`` (readings are stamped at multiples of h):
the delay buffer updates at ``h/4`` (passes reading k through the readings' one gate,
records it, applies a new image observation), the Kalman bank at ``h/2`` (adopts the
buffer's correction, then filters the reading the gate admitted if the correction did
not already include it), and the CPF system at ``3h/4`` (reads the buffer's prior for
a newly arrived image). The parameters are checked and resolved once, here, and the
three systems share the resolved object. Every exchange goes through
state, so there is no algebraic loop, and the bank's estimate after its update equals
the offline :class:`~drake_tracker.tracker.Tracker`'s after the same reading, except
within ``image.update_latency_s`` of an applied image's arrival: the Diagram applies an
update that much later (it runs on a worker thread meanwhile; the offline tracker
applies it at once).

The depth input is what a Drake user has: an ``RgbdSensor``'s ``depth_image_32f``
(metres) or ``depth_image_16u`` (millimetres) with a capture-time port
(``RgbdSensorAsync``'s ``image_time``, or an :class:`ImageStamper`'s); a
:class:`DepthImageToFrame` converts it at ``5h/8``, before the CPF system looks.
A port of the package's own ``DepthFrame`` is connected as it is.

Several depth cameras (``cameras=[TrackerCamera(...), ...]``, each one of the model's
``RobotConfig.cameras``) each have their own depth and image-time ports, converter and
camera model; their images enter the one delay buffer at their own capture times,
interleaved, each through its own clock and its own image update.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Union

from pydrake.systems.framework import DiagramBuilder, OutputPort

from drake_tracker.core.sensors.camera import as_intrinsics
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.systems.cpf_system import CpfImageUpdateSystem
from drake_tracker.systems.delay_buffer_system import DelayBufferSystem, camera_port_names
from drake_tracker.systems.depth_image_adapter import DepthImageToFrame, depth_port_kind
from drake_tracker.systems.kalman_bank_system import JointKalmanBankSystem

if TYPE_CHECKING:
    from pydrake.geometry import DepthRenderCamera, RenderCameraCore
    from pydrake.systems.sensors import CameraInfo

    from drake_tracker.core.sensors.camera import CameraIntrinsics
    from drake_tracker.robot.model import TrackerModel

#: A depth camera's model: Drake's ``CameraInfo``, ``DepthRenderCamera`` or
#: ``RenderCameraCore``, or ``CameraIntrinsics``.
CameraModel = Union["CameraIntrinsics", "CameraInfo", "DepthRenderCamera", "RenderCameraCore"]


@dataclass
class TrackerCamera:
    """One depth camera of a tracker with several (``AddTracker(cameras=[...])``).

    ``name`` is one of the model's cameras (``RobotConfig.cameras``); ``camera`` its model
    (full resolution of its images); ``depth`` and ``image_time`` its ports, as
    ``AddTracker``'s ``depth`` and ``image_time``."""

    name: str
    camera: CameraModel
    depth: OutputPort
    image_time: OutputPort | None = None


#: Output ports of the Kalman bank that ``AddTracker`` exports.
ESTIMATE_PORTS = ("estimated_position", "position_variance", "bias", "bias_variance",
                  "camera_offset", "X_CE", "X_WE", "X_WC", "belief")

#: The order of the positional call of the previous release (deprecated).
_POSITIONAL = ("model", "camera", "params", "measured_position", "measurement_time", "depth",
               "encoder_period_s", "image_check_period_s", "name", "image_time")


@dataclass
class TrackerSystems:
    """The systems ``AddTracker`` added, and the tracker's output ports.

    The port fields are the ports to connect: ``X_CE`` (the hand in the estimated
    camera frame, a ``RigidTransform``), ``X_WE`` and ``X_WC`` (the hand and the
    estimated camera in the model's world), ``estimated_position``,
    ``position_variance``, ``bias``, ``bias_variance`` (each n = ``model.num_joints``,
    virtual joints included), ``camera_offset`` (the six virtual joints), ``belief``
    (the (5, n) moments, row-major) and ``health`` (a ``TrackerHealth``: fall back to the
    encoders while its ``state`` is ``HealthState.LOST``).
    """

    kalman_bank: JointKalmanBankSystem
    delay_buffer: DelayBufferSystem
    image_update: CpfImageUpdateSystem
    model: TrackerModel
    #: The image converter, when the depth input is a Drake image port.
    depth_adapter: DepthImageToFrame | None
    X_CE: OutputPort
    X_WE: OutputPort
    X_WC: OutputPort
    estimated_position: OutputPort
    position_variance: OutputPort
    bias: OutputPort
    bias_variance: OutputPort
    camera_offset: OutputPort
    belief: OutputPort
    health: OutputPort
    #: Each camera's name -> its offset (the six virtual joints), its estimated frame in
    #: the model's world (X_WC), the hand in that frame (X_CE), its health and its image
    #: converter (None for a DepthFrame port); with one camera, the model's first camera.
    camera_offsets: dict[str, OutputPort] = field(default_factory=dict)
    camera_poses: dict[str, OutputPort] = field(default_factory=dict)
    camera_hand_poses: dict[str, OutputPort] = field(default_factory=dict)
    camera_health: dict[str, OutputPort] = field(default_factory=dict)
    depth_adapters: dict[str, DepthImageToFrame | None] = field(default_factory=dict)

    def port(self, name: str) -> OutputPort:
        """The output port called ``name`` (``ESTIMATE_PORTS`` or ``health``); the fields
        are the same ports."""
        if name != "health" and name not in ESTIMATE_PORTS:
            raise ValueError(f"unknown tracker output '{name}'; known: "
                             f"{list(ESTIMATE_PORTS) + ['health']}")
        return getattr(self, name)


def AddTracker(builder: DiagramBuilder, *args: Any,
               model: TrackerModel | None = None,
               camera: CameraIntrinsics | CameraInfo | DepthRenderCamera | RenderCameraCore
               | None = None,
               params: TrackerParams | None = None,
               measured_position: OutputPort | None = None,
               measurement_time: OutputPort | None = None,
               depth: OutputPort | None = None,
               image_time: OutputPort | None = None,
               encoder_period_s: float | None = None,
               image_check_period_s: float | None = None,
               name: str = "tracker",
               cameras: list[TrackerCamera] | None = None) -> TrackerSystems:
    """Adds the tracker for ``model`` to ``builder`` and connects its inputs; returns the
    systems and the output ports (:class:`TrackerSystems`). Every argument after
    ``builder`` is keyword-only (the positional call of the previous release still works,
    with a ``DeprecationWarning``, until the next release).

    Args:
        model: the tracker's model (``build_tracker_model``).
        camera: the depth camera's model: Drake's ``CameraInfo`` or
            ``DepthRenderCamera`` (e.g. ``sensor.default_depth_render_camera()``), or a
            ``CameraIntrinsics``; full resolution of the depth images.
        params: the tracker's parameters (default: ``TrackerParams()``); validated and
            resolved against ``model`` once, here.
        measured_position: the robot joints' encoder readings, in
            ``model.robot_joint_names`` order.
        measurement_time: the readings' time stamp (s), a 1-vector.
        depth: an ``ImageDepth32F`` (metres) or ``ImageDepth16U`` (millimetres, 0 =
            invalid) port, e.g. an RgbdSensor's depth output held by an
            ``ImageStamper``, or ``RgbdSensorAsync``'s; or a ``DepthFrame`` port.
        image_time: with an image port, the images' capture time (s), a 1-vector;
            a new value marks a new image. Not with a ``DepthFrame`` port.
        encoder_period_s: the encoder's sample period (s); the bank and buffer update at
            this rate.
        image_check_period_s: how often the tracker looks for a new image (default:
            ``encoder_period_s``); an image waits at most this long.
        name: the prefix of the added systems' names.
        cameras: instead of ``camera``, ``depth`` and ``image_time``, several depth
            cameras (:class:`TrackerCamera`), each one of the model's cameras, named once;
            their ports are the systems' ``<name>_depth_frame``, ... A camera of the model
            left out has no images (its offset stays at its prior).
    """
    if args:
        if len(args) > len(_POSITIONAL):
            raise TypeError(f"AddTracker takes at most {len(_POSITIONAL) + 1} positional "
                            f"arguments, got {len(args) + 1}")
        warnings.warn("AddTracker's positional arguments are deprecated and will be "
                      "removed in the next release: pass everything after the builder by "
                      "keyword (model=..., camera=..., ...)", DeprecationWarning,
                      stacklevel=2)
        given = dict(zip(_POSITIONAL, args, strict=False))
        passed = {"model": model, "camera": camera, "params": params,
                  "measured_position": measured_position,
                  "measurement_time": measurement_time, "depth": depth,
                  "encoder_period_s": encoder_period_s,
                  "image_check_period_s": image_check_period_s, "image_time": image_time}
        twice = [k for k in given if k in passed and passed[k] is not None]
        if twice:
            raise TypeError(f"AddTracker got {twice} both by position and by keyword")
        return AddTracker(builder, **{**passed, "name": name, **given})
    several = cameras is not None
    if several and any(v is not None for v in (camera, depth, image_time)):
        raise TypeError("AddTracker: give either camera=, depth= (and image_time=) or "
                        "cameras=[TrackerCamera(...), ...], not both")
    missing = [k for k, v in (("model", model), ("camera", camera if not several else 0),
                              ("measured_position", measured_position),
                              ("measurement_time", measurement_time),
                              ("depth", depth if not several else 0),
                              ("encoder_period_s", encoder_period_s)) if v is None]
    if missing:
        raise TypeError(f"AddTracker: missing keyword argument(s) {missing}")
    h = float(encoder_period_s)
    if not h > 0:
        raise ValueError(f"AddTracker: encoder_period_s must be > 0, got {encoder_period_s}")
    check = h if image_check_period_s is None else float(image_check_period_s)
    if not several:
        cameras = [TrackerCamera(model.camera_names[0], camera, depth, image_time)]
    names = camera_port_names(model, [c.name for c in cameras] if several else None)
    given = {c.name: c for c in cameras}
    resolved = resolve_tracker_params(TrackerParams() if params is None else params, model)
    models = {c: as_intrinsics(given[c].camera) for c in names}
    frames, adapters = {}, {}
    for cam, prefix in names.items():
        frames[cam], adapters[cam] = _depth_frame_port(
            builder, f"{name}_{prefix}", given[cam].depth, given[cam].image_time, check, h)
    buffer = builder.AddNamedSystem(f"{name}_delay_buffer", DelayBufferSystem(
        model=model, params=resolved, period_s=h, offset_s=0.25 * h,
        cameras=list(names) if several else None))
    bank = builder.AddNamedSystem(f"{name}_kalman_bank", JointKalmanBankSystem(
        model=model, params=resolved, period_s=h, offset_s=0.5 * h))
    cpf = builder.AddNamedSystem(f"{name}_image_update", CpfImageUpdateSystem(
        model=model, params=resolved, period_s=check, offset_s=0.75 * h,
        **({"cameras": models} if several else {"camera": models[model.camera_names[0]]})))
    builder.Connect(measured_position, buffer.get_measured_position_input_port())
    builder.Connect(measurement_time, buffer.get_measurement_time_input_port())
    for cam, frame in frames.items():
        builder.Connect(frame, buffer.get_depth_frame_input_port(cam))
        builder.Connect(frame, cpf.get_depth_frame_input_port(cam))
        builder.Connect(buffer.get_image_prior_output_port(cam),
                        cpf.get_image_prior_input_port(cam))
    builder.Connect(buffer.get_reading_output_port(), bank.get_reading_input_port())
    builder.Connect(buffer.get_correction_output_port(), bank.get_correction_input_port())
    builder.Connect(cpf.get_image_observation_output_port(),
                    buffer.get_image_observation_input_port())
    ports = {port: bank.GetOutputPort(port) for port in ESTIMATE_PORTS}
    return TrackerSystems(
        bank, buffer, cpf, model, next(iter(adapters.values())),
        health=cpf.get_health_output_port(), **ports,
        camera_offsets=_per_camera(bank, names, "camera_offset", ports["camera_offset"]),
        camera_poses=_per_camera(bank, names, "X_WC", ports["X_WC"]),
        camera_hand_poses=_per_camera(bank, names, "X_CE", ports["X_CE"]),
        camera_health={c: cpf.get_health_output_port(c) for c in names},
        depth_adapters=adapters)


def _depth_frame_port(builder: DiagramBuilder, prefix: str, depth: OutputPort,
                      image_time: OutputPort | None, check: float, h: float
                      ) -> tuple[OutputPort, DepthImageToFrame | None]:
    """A camera's ``DepthFrame`` port: ``depth`` itself, or a converter's of the Drake
    image port ``depth`` (with its capture time ``image_time``)."""
    kind = depth_port_kind(depth)
    if kind == "depth_frame":
        if image_time is not None:
            raise ValueError("AddTracker: image_time goes with an image port; a DepthFrame "
                             "carries its own capture time")
        return depth, None
    if image_time is None:
        raise ValueError("AddTracker: a depth image port needs its capture time: pass "
                         "image_time (RgbdSensorAsync's image_time, or an "
                         "ImageStamper's)")
    adapter = builder.AddNamedSystem(
        f"{prefix}depth_image_to_frame",
        DepthImageToFrame(encoding=kind, period_s=check, offset_s=0.625 * h))
    builder.Connect(depth, adapter.get_depth_image_input_port())
    builder.Connect(image_time, adapter.get_image_time_input_port())
    return adapter.get_depth_frame_output_port(), adapter


def _per_camera(bank: JointKalmanBankSystem, names: dict[str, str], port: str,
                only: OutputPort) -> dict[str, OutputPort]:
    """Each camera's ``<name>_<port>`` of the bank (with one camera in the model, ``only``)."""
    if bank.HasOutputPort(f"{next(iter(names))}_{port}"):
        return {c: bank.GetOutputPort(f"{c}_{port}") for c in names}
    return {c: only for c in names}
