"""``AddTracker``: wires the three tracker systems into a user's DiagramBuilder.

Event times within one encoder period ``h`` (readings are stamped at multiples of h):
the delay buffer updates at ``h/4`` (records reading k, applies a new image
observation), the Kalman bank at ``h/2`` (adopts the buffer's correction, then filters
reading k if the correction did not already include it), and the CPF system at ``3h/4``
(reads the buffer's prior for a newly arrived image). Every exchange goes through
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
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from pydrake.systems.framework import DiagramBuilder, OutputPort

from drake_tracker.core.sensors.camera import as_intrinsics
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.systems.cpf_system import CpfImageUpdateSystem
from drake_tracker.systems.delay_buffer_system import DelayBufferSystem
from drake_tracker.systems.depth_image_adapter import DepthImageToFrame, depth_port_kind
from drake_tracker.systems.kalman_bank_system import JointKalmanBankSystem

if TYPE_CHECKING:
    from pydrake.geometry import DepthRenderCamera, RenderCameraCore
    from pydrake.systems.sensors import CameraInfo

    from drake_tracker.core.sensors.camera import CameraIntrinsics
    from drake_tracker.robot.model import TrackerModel

#: Output ports of the Kalman bank that ``AddTracker`` exports.
ESTIMATE_PORTS = ("estimated_position", "position_variance", "bias", "bias_variance",
                  "camera_offset", "X_CE", "X_WE", "X_WC", "belief")


@dataclass
class TrackerSystems:
    """The systems ``AddTracker`` added, and its output ports by name."""

    kalman_bank: JointKalmanBankSystem
    delay_buffer: DelayBufferSystem
    image_update: CpfImageUpdateSystem
    model: object
    #: The image converter, when the depth input is a Drake image port.
    depth_adapter: DepthImageToFrame | None = None

    def port(self, name: str) -> OutputPort:
        """An estimate output port (``ESTIMATE_PORTS``) of the Kalman bank, or ``health``
        (``TrackerHealth`` after the latest image: fall back to the encoders while its
        ``state`` is ``HealthState.LOST``)."""
        if name == "health":
            return self.image_update.GetOutputPort("health")
        if name not in ESTIMATE_PORTS:
            raise ValueError(f"unknown tracker output '{name}'; known: "
                             f"{list(ESTIMATE_PORTS) + ['health']}")
        return self.kalman_bank.GetOutputPort(name)


def AddTracker(builder: DiagramBuilder, model: TrackerModel,
               camera: CameraIntrinsics | CameraInfo | DepthRenderCamera | RenderCameraCore,
               params: TrackerParams,
               measured_position: OutputPort, measurement_time: OutputPort,
               depth: OutputPort, encoder_period_s: float,
               image_check_period_s: float | None = None, name: str = "tracker",
               image_time: OutputPort | None = None) -> TrackerSystems:
    """Adds the tracker for ``model`` (``build_tracker_model``) to ``builder``.

    Args:
        camera: the depth camera's model: Drake's ``CameraInfo`` or
            ``DepthRenderCamera`` (e.g. ``sensor.default_depth_render_camera()``), or a
            ``CameraIntrinsics``; full resolution of the depth images.
        measured_position: the robot joints' encoder readings, in
            ``model.robot_joint_names`` order.
        measurement_time: the readings' time stamp (s), a 1-vector.
        depth: an ``ImageDepth32F`` (metres) or ``ImageDepth16U`` (millimetres, 0 =
            invalid) port, e.g. an RgbdSensor's depth output held by an
            ``ImageStamper``, or ``RgbdSensorAsync``'s; or a ``DepthFrame`` port.
        encoder_period_s: the encoder's sample period (s); the bank and buffer update at
            this rate.
        image_check_period_s: how often the tracker looks for a new image (default:
            ``encoder_period_s``); an image waits at most this long.
        image_time: with an image port, the images' capture time (s), a 1-vector;
            a new value marks a new image.
    """
    h = float(encoder_period_s)
    if not h > 0:
        raise ValueError(f"AddTracker: encoder_period_s must be > 0, got {encoder_period_s}")
    check = h if image_check_period_s is None else float(image_check_period_s)
    intrinsics = as_intrinsics(camera)
    kind = depth_port_kind(depth)
    adapter = None
    if kind != "depth_frame":
        if image_time is None:
            raise ValueError("AddTracker: a depth image port needs its capture time: pass "
                             "image_time (RgbdSensorAsync's image_time, or an "
                             "ImageStamper's)")
        adapter = builder.AddNamedSystem(f"{name}_depth_image_to_frame",
                                         DepthImageToFrame(kind, check, 0.625 * h))
        builder.Connect(depth, adapter.GetInputPort("depth_image"))
        builder.Connect(image_time, adapter.GetInputPort("image_time"))
        depth = adapter.GetOutputPort("depth_frame")
    elif image_time is not None:
        raise ValueError("AddTracker: image_time goes with an image port; a DepthFrame "
                         "carries its own capture time")
    buffer = builder.AddNamedSystem(f"{name}_delay_buffer",
                                    DelayBufferSystem(model, params, h, 0.25 * h))
    bank = builder.AddNamedSystem(f"{name}_kalman_bank",
                                  JointKalmanBankSystem(model, params, h, 0.5 * h))
    cpf = builder.AddNamedSystem(f"{name}_image_update",
                                 CpfImageUpdateSystem(model, intrinsics, params, check, 0.75 * h))
    for system in (buffer, bank):
        builder.Connect(measured_position, system.GetInputPort("measured_position"))
        builder.Connect(measurement_time, system.GetInputPort("measurement_time"))
    builder.Connect(depth, buffer.GetInputPort("depth_frame"))
    builder.Connect(depth, cpf.GetInputPort("depth_frame"))
    builder.Connect(buffer.GetOutputPort("correction"), bank.GetInputPort("correction"))
    builder.Connect(buffer.GetOutputPort("image_prior"), cpf.GetInputPort("image_prior"))
    builder.Connect(cpf.GetOutputPort("image_observation"),
                    buffer.GetInputPort("image_observation"))
    return TrackerSystems(bank, buffer, cpf, model, adapter)
