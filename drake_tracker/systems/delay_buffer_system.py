"""The delay buffer as a Drake LeafSystem: readings, beliefs, and delayed images."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import Context, EventStatus, LeafSystem

from drake_tracker.core.filter.belief_buffer import BeliefBuffer
from drake_tracker.core.image_step import (
    full_reading,
    image_time,
    make_bank_and_prior,
    new_belief_buffer,
    robot_joint_indices,
)
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.core.sensors.reading_gate import ReadingGate
from drake_tracker.core.sensors.timestamps import (
    StampDecision,
    StreamClock,
    follow_buffer,
    log_reanchor,
)
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.systems.messages import BeliefCorrection, ImageObservationMessage, ImagePrior
from drake_tracker.systems.shared_state import SharedAbstractState

if TYPE_CHECKING:
    from drake_tracker.robot.model import TrackerModel

log = logging.getLogger(__name__)


@dataclass
class DelayBufferState(SharedAbstractState):
    """The system's abstract state. A stored one is never modified: ``_update`` works on
    a ``copy()`` of it and copies each part it changes (the buffer, a clock) before
    changing it, so Drake's two copies of the state at every update (1000 a simulated
    second) share it, and a copied Context still evolves on its own."""

    buffer: BeliefBuffer | None = None
    last_reading_time_s: float = float("-inf")
    last_observation_id: int = 0
    correction: BeliefCorrection = field(default_factory=BeliefCorrection)
    #: The readings' and images' time-stamp policy (``core/sensors/timestamps.py``), the last
    #: image it judged and its decision.
    readings: ReadingGate | None = None
    image_clock: StreamClock | None = None
    frame_key: tuple = ()
    frame_decision: StampDecision | None = None


def frame_key(frame: DepthFrame) -> tuple:
    """What tells two frames apart: the sequence number may restart, the stamp may
    repeat, both together do not."""
    return frame.sequence, repr(frame.capture_time_s)


class DelayBufferSystem(LeafSystem):
    """Keeps the joint readings and the belief after each over ``buffer_horizon_s``, and
    applies each image's observation at the image's own time t', filtering the later
    readings again (periodic unrestricted update).

    .. pydrake_system::

        name: DelayBufferSystem
        input_ports:
        - measured_position
        - measurement_time
        - image_observation
        - depth_frame
        output_ports:
        - correction
        - image_prior

    ``image_observation`` is the CPF system's :class:`ImageObservationMessage`; each new
    one is inserted at its time and yields a new ``correction`` (the present belief after
    replay) for the Kalman bank. ``image_prior`` is the belief at the time t' of the image
    on ``depth_frame`` (capture stamp minus ``image_time_offset_s``), or the reason there
    is none (no reading yet, older than the horizon, from the future).

    Images outside the buffer or in a gap of the readings, and readings or images whose
    values or stamps are not usable (``core/sensors/timestamps.py``), are skipped with a logged,
    rate-limited warning; nothing else is dropped.
    """

    def __init__(self, model: TrackerModel, params: TrackerParams, period_s: float,
                 offset_s: float = 0.0):
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"DelayBufferSystem: period_s must be > 0, got {period_s}")
        self._model = model
        self._params = params
        self._robot_indices = robot_joint_indices(model)
        make_bank_and_prior(model, params, None)  # validates the parameters now
        stamps = params.timestamps
        self._state = self.DeclareAbstractState(AbstractValue.Make(DelayBufferState(
            readings=ReadingGate(stamps, model.robot_joint_names, log),
            image_clock=StreamClock("image", stamps, params.buffer_horizon_s))))
        self._reading_port = self.DeclareVectorInputPort(
            "measured_position", len(model.robot_joint_names))
        self._time_port = self.DeclareVectorInputPort("measurement_time", 1)
        self._observation_port = self.DeclareAbstractInputPort(
            "image_observation", AbstractValue.Make(ImageObservationMessage()))
        self._frame_port = self.DeclareAbstractInputPort(
            "depth_frame", AbstractValue.Make(DepthFrame.empty()))
        state_ticket = {self.abstract_state_ticket(self._state)}
        self.DeclareAbstractOutputPort(
            "correction", lambda: AbstractValue.Make(BeliefCorrection()),
            self._calc_correction, state_ticket)
        self.DeclareAbstractOutputPort(
            "image_prior", lambda: AbstractValue.Make(ImagePrior()), self._calc_prior,
            state_ticket | {self._frame_port.ticket()})
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, offset_s, self._update)

    def state(self, context: Context) -> DelayBufferState:
        """The buffer, its clocks and the latest correction, in ``context``."""
        return context.get_abstract_state(self._state).get_value()

    def _update(self, context, state) -> EventStatus | None:
        # The stored state is shared with Drake's copies: change a copy of it.
        s = self.state(context).copy()
        # Frames are judged against the buffer the CPF system saw (before this reading).
        changed = self._judge_frame(self._frame_port.Eval(context), s)
        raw = float(self._time_port.Eval(context)[0])
        if s.readings.is_new(raw):
            changed = True
            reading = np.array(self._reading_port.Eval(context), float)
            s.readings = s.readings.copy()
            t = s.readings.admit(raw, reading)
            if t is not None and self._params.use_joint_readings:
                if s.readings.restarted:
                    s.buffer = None  # built on outlier stamps: restart from this reading
                s.buffer = (new_belief_buffer(self._model, self._params, t, reading)
                            if s.buffer is None else s.buffer.copy())
                s.buffer.add_reading(t, full_reading(self._model, reading, self._robot_indices))
                s.last_reading_time_s = t
            elif t is not None:
                s.buffer = (new_belief_buffer(self._model, self._params, 0.0, None)
                            if s.buffer is None else s.buffer.copy())
                s.buffer.advance_to(t)
                s.last_reading_time_s = t
        message = self._observation_port.Eval(context)
        if message.id > s.last_observation_id and message.observation is not None:
            changed = True
            s.last_observation_id = message.id
            problem = s.buffer.image_time_problem(message.anchor.anchor_time_s) \
                if s.buffer else "no joint reading yet"
            if problem is not None:
                log.warning("image %d skipped: %s", message.sequence, problem)
            else:
                s.buffer = s.buffer.copy()
                s.buffer.add_image_observation(message.anchor, message.observation)
                now, belief = s.buffer.present()
                s.correction = BeliefCorrection(s.correction.id + 1, now,
                                                s.last_reading_time_s, belief)
        if not changed:
            return EventStatus.DidNothing()  # Drake keeps the state as it is
        state.get_mutable_abstract_state(self._state).set_value(s)
        return None

    def _judge_frame(self, frame: DepthFrame, s: DelayBufferState) -> bool:
        """Runs a new frame's stamp through the images' clock (once per frame); whether
        there was one."""
        if frame.is_empty or s.buffer is None or frame_key(frame) == s.frame_key:
            return False
        s.frame_key = frame_key(frame)
        s.image_clock = s.image_clock.copy()
        s.frame_decision = s.image_clock.check(image_time(frame, self._params))
        if s.frame_decision.reanchored_by_s is not None:
            log_reanchor(log, "image", s.frame_decision, frame.capture_time_s, s.image_clock)
        if s.frame_decision.time_s is not None:
            follow_buffer(s.image_clock, s.buffer, s.frame_decision.time_s, log,
                          s.readings.clock)
        return True

    def _calc_correction(self, context, output):
        output.set_value(self.state(context).correction)

    def _calc_prior(self, context, output):
        s = self.state(context)
        frame: DepthFrame = self._frame_port.Eval(context)
        if frame.is_empty:
            output.set_value(ImagePrior())
            return
        if s.buffer is None:
            output.set_value(ImagePrior(frame.sequence, image_time(frame, self._params), None,
                                        "no joint reading yet"))
            return
        # The decision the next update will take for a frame it has not judged yet.
        decision = s.frame_decision if frame_key(frame) == s.frame_key else \
            s.image_clock.peek(image_time(frame, self._params))
        if decision.time_s is None:
            output.set_value(ImagePrior(frame.sequence, float("nan"), None, decision.problem))
            return
        t = decision.time_s
        problem = s.buffer.image_time_problem(t) or s.buffer.reading_gap_problem(t)
        anchor = None if problem else s.buffer.image_anchor(t)
        output.set_value(ImagePrior(frame.sequence, t, anchor, problem or "",
                                    s.last_observation_id))
