"""The Coordinate Particle Filter image update as a Drake LeafSystem."""

from __future__ import annotations

import logging
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import Context, EventStatus, InputPort, LeafSystem, OutputPort

from drake_tracker.core.image_processor import ImageProcessor
from drake_tracker.core.image_step import ImagePacing, conclude_image
from drake_tracker.core.robustness.health import TrackerHealth
from drake_tracker.core.sensors.camera import CameraIntrinsics, as_intrinsics
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.core.sensors.rate_limited_warning import RateLimitedWarning
from drake_tracker.core.sensors.timestamps import problem_kind
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.systems.image_update_worker import DeadlineWaits, submit_image_update
from drake_tracker.systems.messages import ImageObservationMessage, ImagePrior
from drake_tracker.systems.shared_state import SharedAbstractState

if TYPE_CHECKING:
    from pydrake.systems.sensors import CameraInfo

    from drake_tracker.core.resolved_params import ResolvedParams
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.robot.model import TrackerModel

log = logging.getLogger(__name__)


@dataclass
class CpfState(SharedAbstractState):
    """The system's abstract state. A stored one is never modified (``_update`` changes a
    ``copy()`` of it and stores that, and every field is replaced, never mutated), so
    Drake's copies of it, two at every update (1000 a simulated second), share it."""

    last_sequence: int = -1
    #: (sequence, capture stamp) of the last frame seen: a new pair is a new frame.
    last_frame: tuple = ()
    #: Which images are due (``core/image_step.py``, step 2).
    pacing: ImagePacing = field(default_factory=ImagePacing)
    message: ImageObservationMessage = field(default_factory=ImageObservationMessage)
    health: TrackerHealth = field(default_factory=TrackerHealth)
    images_applied: int = 0
    #: Frames not processed: not due (paced at ``min_image_interval_s``), unplaceable,
    #: malformed, or replaced on the port before the system looked.
    images_skipped: int = 0
    #: The update running on the worker thread (``image.update_latency_s`` > 0).
    in_flight: ImageUpdateInFlight | None = None
    #: A frame put off for a check, until its prior holds the latest update.
    deferred_frame: tuple = ()


@dataclass(frozen=True)
class ImageUpdateInFlight:
    """An image update handed to the worker thread, applied at ``due_s``."""

    frame: DepthFrame
    prior: ImagePrior
    due_s: float
    outcome: Future


class CpfImageUpdateSystem(LeafSystem):
    """Runs the CPF image update once per new depth image (a periodic unrestricted update
    that compares the image's sequence number and capture stamp with the last frame's,
    since Python systems cannot schedule their own next update time; a sequence counter
    that restarts is logged once per restart).

    .. pydrake_system::

        name: CpfImageUpdateSystem
        input_ports:
        - depth_frame
        - image_prior
        output_ports:
        - image_observation
        - health

    ``depth_frame`` carries a :class:`DepthFrame` (full resolution of ``camera``);
    ``image_prior`` where the delay buffer places that frame, with the angles' prior at
    its time. ``image_observation`` is an :class:`ImageObservationMessage` whose id grows
    by one per applied image; ``health`` the :class:`TrackerHealth` after it. The random
    numbers of image ``k`` depend only on (``image.seed``, k). Malformed images, images
    the buffer cannot place and failed updates are skipped with a rate-limited warning.

    With ``image.update_latency_s`` L > 0 the update runs on the image-update thread
    (``image_update_worker``) while the simulation goes on, and its message appears at the
    first check L after the image was taken up (the Simulator waits there if the thread
    is not done: ``deadline_waits`` counts how often, and how long), the same message
    as with L = 0. A due image that comes while an update
    is in flight applies that one first; an image is taken up only once its prior holds
    every applied update (``ImagePrior.observation_id``). ``state(context).in_flight``
    is the running update.
    """

    def __init__(self, *, model: TrackerModel, camera: CameraIntrinsics | CameraInfo,
                 params: TrackerParams | ResolvedParams, period_s: float,
                 offset_s: float = 0.0) -> None:
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"CpfImageUpdateSystem: period_s must be > 0, got {period_s}")
        self._params = params = resolve_tracker_params(params, model)
        self.processor = ImageProcessor(model, as_intrinsics(camera), params)
        self._period_s = float(period_s)
        self._latency_s = float(params.image.update_latency_s)
        #: Updates on the worker done at their deadline or late (a diagnostic).
        self.deadline_waits = DeadlineWaits()
        self._warnings = RateLimitedWarning(log)
        self._state = self.DeclareAbstractState(AbstractValue.Make(CpfState()))
        self._frame_port = self.DeclareAbstractInputPort(
            "depth_frame", AbstractValue.Make(DepthFrame.empty()))
        self._prior_port = self.DeclareAbstractInputPort(
            "image_prior", AbstractValue.Make(ImagePrior()))
        state_ticket = {self.abstract_state_ticket(self._state)}
        self._message_port = self.DeclareAbstractOutputPort(
            "image_observation", lambda: AbstractValue.Make(ImageObservationMessage()),
            lambda c, o: o.set_value(self.state(c).message), state_ticket)
        self._health_port = self.DeclareAbstractOutputPort(
            "health", lambda: AbstractValue.Make(TrackerHealth()),
            lambda c, o: o.set_value(self.state(c).health), state_ticket)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, offset_s, self._update)

    def get_depth_frame_input_port(self) -> InputPort:
        """The ``depth_frame`` input port."""
        return self._frame_port

    def get_image_prior_input_port(self) -> InputPort:
        """The ``image_prior`` input port."""
        return self._prior_port

    def get_image_observation_output_port(self) -> OutputPort:
        """The ``image_observation`` output port."""
        return self._message_port

    def get_health_output_port(self) -> OutputPort:
        """The ``health`` output port."""
        return self._health_port

    def state(self, context: Context) -> CpfState:
        """The system's state in ``context`` (counts, health, latest message)."""
        return context.get_abstract_state(self._state).get_value()

    def _update(self, context, state) -> EventStatus | None:
        frame: DepthFrame = self._frame_port.Eval(context)
        stored, now = self.state(context), context.get_time()
        key = (frame.sequence, repr(frame.capture_time_s))
        new_frame = not frame.is_empty and key != stored.last_frame
        job = stored.in_flight
        result_due = job is not None and now >= job.due_s - 1e-9
        if not new_frame and not result_due:
            # No new frame and no result due (at 999 of 1000 checks): Drake keeps the
            # state as it is and recomputes nothing that depends on it.
            return EventStatus.DidNothing()
        s = stored.copy()
        prior = self._prior_port.Eval(context) if new_frame else None
        if result_due or (job is not None and self._may_be_due(prior, s)):
            self._count(s, self._finish(job.frame, job.prior, job.outcome, s))
            s.in_flight = None
        if new_frame and prior.anchor is not None and prior.observation_id < s.message.id:
            if s.deferred_frame != key:  # its prior lacks the latest update: look again
                s.deferred_frame, new_frame = key, False
            else:  # still: the prior does not come from a buffer that takes them in
                self._warnings.warn("prior without the latest update", (
                    f"image {frame.sequence}'s prior holds image updates up to "
                    f"{prior.observation_id}, not {s.message.id}: is image_observation "
                    f"connected to the buffer that sends image_prior? Used as it is"))
        if new_frame:
            if frame.sequence < s.last_sequence:
                log.warning("camera sequence counter restarted: image %d after image %d; "
                            "frames are told apart by sequence and stamp", frame.sequence,
                            s.last_sequence)
            elif s.last_sequence >= 0 and frame.sequence - s.last_sequence > 1:
                missed = frame.sequence - s.last_sequence - 1
                s.images_skipped += missed
                self._warnings.warn("frames never seen", (
                    f"{missed} frame(s) before image {frame.sequence} were never on the "
                    f"depth port when it was checked (every {self._period_s * 1e3:g} ms): "
                    f"dropped by the camera, or replaced by a newer one between two checks"))
            s.last_sequence, s.last_frame = frame.sequence, key
            self._count(s, self._process(frame, prior, s, now))
        state.get_mutable_abstract_state(self._state).set_value(s)

    @staticmethod
    def _count(s: CpfState, applied: bool | None) -> None:
        if applied is not None:  # None: started on the worker, counted when it is done
            s.images_applied += int(applied)
            s.images_skipped += int(not applied)

    def _may_be_due(self, prior: ImagePrior | None, s: CpfState) -> bool:
        """Whether the new frame may be due once the update in flight is applied (then
        that one is applied first, as it would have been without the latency)."""
        if prior is None or prior.anchor is None:
            return False
        pacing = s.pacing.applied(s.in_flight.prior.image_time_s)
        return pacing.wants(prior.image_time_s)

    def _process(self, frame: DepthFrame, prior: ImagePrior, s: CpfState,
                 now_s: float) -> bool | None:
        """Starts the image update on ``frame`` if it is due: None when it runs on the
        worker (``s.in_flight``); else whether it produced a new observation message."""
        t = prior.image_time_s
        if prior.sequence == frame.sequence and t == t and not s.pacing.wants(t):
            return False  # not due (NaN: its stamp was rejected)
        if prior.anchor is None or prior.sequence != frame.sequence:
            return self._skip(frame, prior.problem)
        s.pacing = s.pacing.taken_up(t, self._params.image.min_image_interval_s)
        args = (frame, prior.anchor.prior, s.pacing.jump_window_s(t, s.health), s.health)
        if self._latency_s > 0:
            outcome = submit_image_update(self.processor.observe, *args)
            s.in_flight = ImageUpdateInFlight(frame, prior, now_s + self._latency_s, outcome)
            return None
        outcome = Future()
        try:
            outcome.set_result(self.processor.observe(*args))
        except Exception as err:  # one failed image never stops the simulation
            outcome.set_exception(err)
        return self._finish(frame, prior, outcome, s)

    def _finish(self, frame: DepthFrame, prior: ImagePrior, outcome: Future,
                s: CpfState) -> bool:
        """Applies a finished update (waiting for it if it is still running); True when
        it produced a new observation message."""
        try:
            outcome = (self.deadline_waits.join(outcome) if self._latency_s > 0
                       else outcome.result())
        except Exception as err:  # one failed image never stops the simulation
            return self._skip(frame, f"{type(err).__name__}: {err}")
        verdict = conclude_image(outcome, s.health, self._params.health)
        s.health = verdict.health
        if verdict.observation is None:
            return self._skip(frame, verdict.problem, verdict.kind)
        t = prior.image_time_s
        s.message = ImageObservationMessage(s.message.id + 1, frame.sequence, t,
                                            verdict.observation, prior.anchor)
        s.pacing = s.pacing.applied(t)
        return True

    def _skip(self, frame: DepthFrame, problem: str, kind: str = "") -> bool:
        self._warnings.warn(kind or problem_kind(problem),
                            f"image {frame.sequence} skipped: {problem}")
        return False
