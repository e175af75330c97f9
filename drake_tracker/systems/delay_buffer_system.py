"""The delay buffer as a Drake LeafSystem: readings, beliefs, and delayed images."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import (
    Context,
    EventStatus,
    InputPort,
    LeafSystem,
    OutputPort,
    ValueProducer,
)

from drake_tracker.core.cameras import camera_named
from drake_tracker.core.filter.belief_buffer import BeliefBuffer
from drake_tracker.core.filter.start import full_reading, new_belief_buffer, start_reading_ok
from drake_tracker.core.image_step import judge_stamp, place_image
from drake_tracker.core.sensors.depth_frames import DepthFrame, image_time
from drake_tracker.core.sensors.reading_gate import ReadingGate
from drake_tracker.core.sensors.timestamps import StampDecision, StreamClock
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.systems.messages import (
    AdmittedReading,
    BeliefCorrection,
    ImageObservationMessage,
    ImagePrior,
)
from drake_tracker.systems.shared_state import SharedAbstractState

if TYPE_CHECKING:
    from collections.abc import Sequence

    from drake_tracker.core.resolved_params import ResolvedParams
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.robot.model import TrackerModel

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CameraFrames:
    """One camera's images at the buffer (step 1): its clock, the last frame it judged
    and its decision. Frozen: an update that judges a new frame replaces it."""

    clock: StreamClock
    #: What tells the frames apart (``frame_key``) of the frame judged last.
    key: tuple = ()
    decision: StampDecision | None = None
    #: The frame judged last (the object: the port holds the same one until a new
    #: frame, and a DepthFrame is never changed in place).
    frame: DepthFrame | None = None


@dataclass
class DelayBufferState(SharedAbstractState):
    """The system's abstract state. A stored one is never modified: ``_update`` works on
    a ``copy()`` of it and copies each part it changes (the buffer, a clock, the dict of
    cameras) before changing it, so Drake's two copies of the state at every update
    share it."""

    buffer: BeliefBuffer | None = None
    last_reading_time_s: float = float("-inf")
    last_observation_id: int = 0
    correction: BeliefCorrection = field(default_factory=BeliefCorrection)
    #: The readings' one gate, and the latest reading it admitted (the bank's input).
    readings: ReadingGate | None = None
    reading: AdmittedReading = field(default_factory=AdmittedReading)
    #: Each camera's clock and last judged frame, in the model's camera order.
    cameras: dict[str, CameraFrames] = field(default_factory=dict)

    @property
    def image_clock(self) -> StreamClock:
        """The first camera's images' clock (with one camera, the images' clock)."""
        return next(iter(self.cameras.values())).clock


def frame_key(frame: DepthFrame) -> tuple:
    """What tells two frames apart: the sequence number may restart, the stamp may
    repeat, both together do not."""
    return frame.sequence, repr(frame.capture_time_s)


def camera_port_names(model: TrackerModel, cameras: Sequence[str] | None
                      ) -> dict[str, str]:
    """Camera name -> the prefix of its ports: ``""`` for the one-camera call
    (``cameras`` None: the model's first camera, ports ``depth_frame``, ...), else
    ``"<name>_"`` for each of ``cameras``. ValueError for no camera, a name given twice
    or a camera the model does not have (naming the model's cameras)."""
    if cameras is None:
        return {model.camera_names[0]: ""}
    names = list(cameras)
    if not names:
        raise ValueError(f"no camera given: name at least one of the model's cameras "
                         f"{model.camera_names}")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"two cameras are named {twice[0]!r}: each camera of the tracker "
                         "needs its own name")
    for name in names:
        model.camera(name)  # ValueError naming the model's cameras
    return {name: f"{name}_" for name in model.camera_names if name in names}


class DelayBufferSystem(LeafSystem):
    """The readings' gate and the delay buffer: applies each image's observation at the
    image's own time t', filtering the later readings again (steps 1, 3 and 6 of
    ``core/image_step.py``; a periodic unrestricted update).

    .. pydrake_system::

        name: DelayBufferSystem
        input_ports:
        - measured_position
        - measurement_time
        - image_observation
        - depth_frame
        output_ports:
        - reading
        - correction
        - image_prior

    ``reading`` is the latest :class:`AdmittedReading` (the Kalman bank filters it);
    ``correction`` the present belief after each applied image; ``image_prior`` the
    anchor of the image on ``depth_frame`` (the prior at its time t'), or why there is
    none. Readings and images that cannot be used are skipped with a rate-limited
    warning (``core/sensors/timestamps.py``).

    With ``cameras`` (names of the model's cameras) each camera has its own
    ``<name>_depth_frame`` input and ``<name>_image_prior`` output, and its images go
    through their own clock (named ``image (<name>)``) into the one buffer, each at its
    own time; ``image_observation`` takes every camera's observations. That port is read
    when its value changed (or the context's time, state and parameters were set back):
    this system's state alone set back, the port unchanged, does not take its message
    again.
    """

    def __init__(self, *, model: TrackerModel, params: TrackerParams | ResolvedParams,
                 period_s: float, offset_s: float = 0.0,
                 cameras: Sequence[str] | None = None) -> None:
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"DelayBufferSystem: period_s must be > 0, got {period_s}")
        self._params = resolve_tracker_params(params, model)
        prefixes = camera_port_names(model, cameras)
        stamps, several = self._params.timestamps, cameras is not None and len(prefixes) > 1
        clocks = {name: CameraFrames(StreamClock(f"image ({name})" if several else "image",
                                                 stamps, self._params.buffer_horizon_s))
                  for name in prefixes}
        self._state = self.DeclareAbstractState(AbstractValue.Make(DelayBufferState(
            readings=ReadingGate(stamps, model.robot_joint_names, log), cameras=clocks)))
        self._position = self.DeclareVectorInputPort(
            "measured_position", len(model.robot_joint_names))
        self._time = self.DeclareVectorInputPort("measurement_time", 1)
        self._observation = self.DeclareAbstractInputPort(
            "image_observation", AbstractValue.Make(ImageObservationMessage()))
        # The message on image_observation, evaluated only when it changed: the update
        # asks whether this entry is out of date (cheaper than reading the port at every
        # reading). A context set back (SetTimeStateAndParametersFrom, which copies the
        # accuracy too) notes the accuracy changed: the update reads the port again.
        self._observation_seen = self.DeclareCacheEntry(
            "image_observation_seen", ValueProducer(
                allocate=AbstractValue.Make(ImageObservationMessage()).Clone,
                calc=lambda c, v: v.set_value(self._observation.EvalAbstract(c).get_value())),
            {self._observation.ticket(), self.accuracy_ticket()})
        self._frames = {name: self.DeclareAbstractInputPort(
            f"{prefix}depth_frame", AbstractValue.Make(DepthFrame.empty()))
            for name, prefix in prefixes.items()}
        state = {self.abstract_state_ticket(self._state)}
        self._index = int(self._state)  # pydrake takes a plain int fastest
        self._reading_out = self.DeclareAbstractOutputPort(
            "reading", lambda: AbstractValue.Make(AdmittedReading()),
            lambda c, o: o.set_value(c.get_abstract_state(self._index).get_value().reading),
            state)
        self._correction_out = self.DeclareAbstractOutputPort(
            "correction", lambda: AbstractValue.Make(BeliefCorrection()),
            lambda c, o: o.set_value(self.state(c).correction), state)
        self._priors_out = {name: self.DeclareAbstractOutputPort(
            f"{prefix}image_prior", lambda: AbstractValue.Make(ImagePrior()),
            lambda c, o, name=name: self.CalcImagePrior(c, o, name),
            state | {self._frames[name].ticket()}) for name, prefix in prefixes.items()}
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, offset_s, self._update)

    @property
    def camera_names(self) -> list[str]:
        """The cameras whose images the buffer takes, in the model's order."""
        return list(self._frames)

    def _camera(self, camera: str | None) -> str:
        return camera_named(camera, self.camera_names, "buffer")

    def get_measured_position_input_port(self) -> InputPort:
        """The ``measured_position`` input port."""
        return self._position

    def get_measurement_time_input_port(self) -> InputPort:
        """The ``measurement_time`` input port."""
        return self._time

    def get_image_observation_input_port(self) -> InputPort:
        """The ``image_observation`` input port."""
        return self._observation

    def get_depth_frame_input_port(self, camera: str | None = None) -> InputPort:
        """The ``depth_frame`` input port of ``camera`` (None: the only camera)."""
        return self._frames[self._camera(camera)]

    def get_reading_output_port(self) -> OutputPort:
        """The ``reading`` output port."""
        return self._reading_out

    def get_correction_output_port(self) -> OutputPort:
        """The ``correction`` output port."""
        return self._correction_out

    def get_image_prior_output_port(self, camera: str | None = None) -> OutputPort:
        """The ``image_prior`` output port of ``camera`` (None: the only camera)."""
        return self._priors_out[self._camera(camera)]

    def state(self, context: Context) -> DelayBufferState:
        """The buffer, the gate, the clocks and the latest messages, in ``context``."""
        return context.get_abstract_state(self._index).get_value()

    def _update(self, context: Context, state) -> EventStatus | None:
        # The stored state is shared with Drake's copies: the update changes its own copy.
        s = context.get_abstract_state(self._index).get_value().copy()
        # Frames are judged against the buffer the CPF system saw (before this reading).
        changed = False  # (EvalAbstract(c).get_value(): an abstract port's Eval, cheaper)
        for name, port in self._frames.items():
            frame = port.EvalAbstract(context).get_value()
            if frame is not s.cameras[name].frame:  # not the frame judged last
                changed |= self._judge_frame(name, frame, s)
        raw = self._time.EvalBasicVector(context)[0]
        if s.readings.is_new(raw):
            changed = True
            self._take_reading(raw, self._position.Eval(context), s)  # Eval gives a copy
        seen = self._observation_seen
        message = seen.Eval(context) if seen.is_out_of_date(context) else None
        if (message is not None and message.id > s.last_observation_id
                and message.observation is not None):
            changed = True
            s.last_observation_id = message.id
            self._take_observation(message, s)
        if not changed:
            return EventStatus.DidNothing()  # Drake keeps the state as it is
        state.get_mutable_abstract_state(self._index).set_value(s)
        return None

    def _take_reading(self, raw: float, values: np.ndarray, s: DelayBufferState) -> None:
        """A new sample on the reading ports through the gate, into the buffer."""
        p = self._params
        s.readings = s.readings.copy()
        t = s.readings.admit(raw, values)
        if t is None:
            return
        if not p.use_joint_readings:
            s.buffer = new_belief_buffer(p, 0.0, None) if s.buffer is None else s.buffer.copy()
            s.buffer.advance_to(t)
            s.last_reading_time_s = t
            return
        restarted = s.readings.restarted
        values = s.readings.values  # NaN for joints without a usable value
        if s.buffer is None or restarted:  # built on outlier stamps: restart from here
            if not start_reading_ok(values, s.readings.warnings):
                return
            s.buffer = new_belief_buffer(p, t, values)
        else:
            s.buffer = s.buffer.copy()
        s.buffer.add_reading(t, full_reading(p, values), checked=True)
        s.last_reading_time_s = t
        s.reading = AdmittedReading(s.reading.id + 1, t, values, restarted, s.correction.id)

    def _take_observation(self, message: ImageObservationMessage, s: DelayBufferState) -> None:
        """Step 6: an image's observation into the buffer at its anchor."""
        problem = s.buffer.image_time_problem(message.anchor.anchor_time_s) \
            if s.buffer else "no joint reading yet"
        if problem is not None:
            log.warning("image %d skipped: %s", message.sequence, problem)
            return
        s.buffer = s.buffer.copy()
        s.buffer.add_image_observation(message.anchor, message.observation)
        now, belief = s.buffer.present()
        s.correction = BeliefCorrection(s.correction.id + 1, now, s.last_reading_time_s,
                                        belief)
        s.reading = replace(s.reading, correction_id=s.correction.id)  # the bank looks

    def _judge_frame(self, camera: str, frame: DepthFrame, s: DelayBufferState) -> bool:
        """Step 1, once per new frame of ``camera``; whether there was one."""
        judged = s.cameras[camera]
        if frame.is_empty or s.buffer is None:
            return False
        key = frame_key(frame)
        if key == judged.key:
            return False
        clock = judged.clock.copy()
        decision = judge_stamp(frame, clock, s.buffer, s.readings.clock, self._params, log)
        s.cameras = {**s.cameras, camera: CameraFrames(clock, key, decision, frame)}
        return True

    def CalcImagePrior(self, context: Context, output: AbstractValue,
                       camera: str | None = None) -> None:
        """Step 3 for the frame on ``camera``'s ``depth_frame``: its :class:`ImagePrior`."""
        camera = self._camera(camera)
        s, frame = self.state(context), self._frames[camera].Eval(context)
        if frame.is_empty:
            output.set_value(ImagePrior())
            return
        if s.buffer is None:
            output.set_value(ImagePrior(frame.sequence, image_time(frame, self._params), None,
                                        "no joint reading yet"))
            return
        # The decision the next update will take for a frame it has not judged yet.
        judged = s.cameras[camera]
        decision = judged.decision if frame_key(frame) == judged.key else \
            judged.clock.peek(image_time(frame, self._params))
        if decision.time_s is None:
            output.set_value(ImagePrior(frame.sequence, float("nan"), None, decision.problem))
            return
        anchor, problem = place_image(s.buffer, decision.time_s)
        output.set_value(ImagePrior(frame.sequence, decision.time_s, anchor, problem,
                                    s.last_observation_id))
