"""``AddTracker``: wires the three tracker systems into a user's DiagramBuilder.

Event times within one encoder period ``h`` (readings are stamped at multiples of h):
the delay buffer updates at ``h/4`` (records reading k, applies a new image
observation), the Kalman bank at ``h/2`` (adopts the buffer's correction, then filters
reading k if the correction did not already include it), and the CPF system at ``3h/4``
(reads the buffer's prior for a newly arrived image). Every exchange goes through
state, so there is no algebraic loop, and the bank's estimate after its update equals
the offline :class:`~drake_tracker.tracker.Tracker`'s after the same reading.
"""

from __future__ import annotations

from dataclasses import dataclass

from pydrake.systems.framework import DiagramBuilder, OutputPort

from drake_tracker.core.camera import CameraIntrinsics
from drake_tracker.params import TrackerParams
from drake_tracker.systems.cpf_system import CpfImageUpdateSystem
from drake_tracker.systems.delay_buffer_system import DelayBufferSystem
from drake_tracker.systems.kalman_bank_system import JointKalmanBankSystem

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

    def port(self, name: str) -> OutputPort:
        """An estimate output port (``ESTIMATE_PORTS``) of the Kalman bank."""
        if name not in ESTIMATE_PORTS:
            raise ValueError(f"unknown tracker output '{name}'; known: {list(ESTIMATE_PORTS)}")
        return self.kalman_bank.GetOutputPort(name)


def AddTracker(builder: DiagramBuilder, model, camera: CameraIntrinsics,
               params: TrackerParams, measured_position: OutputPort,
               measurement_time: OutputPort, depth_frame: OutputPort,
               encoder_period_s: float, image_check_period_s: float | None = None,
               name: str = "tracker") -> TrackerSystems:
    """Adds the tracker for ``model`` (``build_tracker_model``) to ``builder``.

    Args:
        measured_position: the robot joints' encoder readings, in
            ``model.robot_joint_names`` order.
        measurement_time: the readings' time stamp (s), a 1-vector.
        depth_frame: an abstract port of ``DepthFrame`` (full resolution of ``camera``).
        encoder_period_s: the encoder's sample period (s); the bank and buffer update at
            this rate.
        image_check_period_s: how often the CPF system looks for a new image (default:
            ``encoder_period_s``); an image waits at most this long.
    """
    h = float(encoder_period_s)
    if not h > 0:
        raise ValueError(f"AddTracker: encoder_period_s must be > 0, got {encoder_period_s}")
    check = h if image_check_period_s is None else float(image_check_period_s)
    buffer = builder.AddNamedSystem(f"{name}_delay_buffer",
                                    DelayBufferSystem(model, params, h, 0.25 * h))
    bank = builder.AddNamedSystem(f"{name}_kalman_bank",
                                  JointKalmanBankSystem(model, params, h, 0.5 * h))
    cpf = builder.AddNamedSystem(f"{name}_image_update",
                                 CpfImageUpdateSystem(model, camera, params, check, 0.75 * h))
    for system in (buffer, bank):
        builder.Connect(measured_position, system.GetInputPort("measured_position"))
        builder.Connect(measurement_time, system.GetInputPort("measurement_time"))
    builder.Connect(depth_frame, buffer.GetInputPort("depth_frame"))
    builder.Connect(depth_frame, cpf.GetInputPort("depth_frame"))
    builder.Connect(buffer.GetOutputPort("correction"), bank.GetInputPort("correction"))
    builder.Connect(buffer.GetOutputPort("image_prior"), cpf.GetInputPort("image_prior"))
    builder.Connect(cpf.GetOutputPort("image_observation"),
                    buffer.GetInputPort("image_observation"))
    return TrackerSystems(bank, buffer, cpf, model)
