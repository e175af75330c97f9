"""The Coordinate Particle Filter image update as a Drake LeafSystem."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import Context, EventStatus, LeafSystem

from drake_tracker.core.camera import CameraIntrinsics
from drake_tracker.core.frames import DepthFrame
from drake_tracker.core.health import TrackerHealth, next_health
from drake_tracker.core.pipeline import ImageProcessor, jump_window_s
from drake_tracker.core.timestamps import RateLimitedWarning, problem_kind
from drake_tracker.params import TrackerParams
from drake_tracker.systems.messages import ImageObservationMessage, ImagePrior
from drake_tracker.systems.shared_state import SharedAbstractState

if TYPE_CHECKING:
    from drake_tracker.robot import TrackerModel

log = logging.getLogger(__name__)


@dataclass
class CpfState(SharedAbstractState):
    """The system's abstract state. A stored one is never modified (``_update`` changes a
    ``copy()`` of it and stores that, and every field is replaced, never mutated), so
    Drake's copies of it, two at every update (1000 a simulated second), share it."""

    last_sequence: int = -1
    #: (sequence, capture stamp) of the last frame seen: a new pair is a new frame.
    last_frame: tuple = ()
    next_image_due_s: float = float("-inf")
    last_applied_image_s: float = float("-inf")
    message: ImageObservationMessage = field(default_factory=ImageObservationMessage)
    health: TrackerHealth = field(default_factory=TrackerHealth)
    images_applied: int = 0
    #: Frames not processed: not due (paced at ``min_image_interval_s``), unplaceable,
    #: malformed, or replaced on the port before the system looked.
    images_skipped: int = 0


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
    """

    def __init__(self, model: TrackerModel, camera: CameraIntrinsics, params: TrackerParams,
                 period_s: float, offset_s: float = 0.0):
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"CpfImageUpdateSystem: period_s must be > 0, got {period_s}")
        self.processor = ImageProcessor(model, camera, params)
        self._period_s = float(period_s)
        self._health_params = params.health
        self._warnings = RateLimitedWarning(log)
        self._state = self.DeclareAbstractState(AbstractValue.Make(CpfState()))
        self._frame_port = self.DeclareAbstractInputPort(
            "depth_frame", AbstractValue.Make(DepthFrame.empty()))
        self._prior_port = self.DeclareAbstractInputPort(
            "image_prior", AbstractValue.Make(ImagePrior()))
        state_ticket = {self.abstract_state_ticket(self._state)}
        self.DeclareAbstractOutputPort(
            "image_observation", lambda: AbstractValue.Make(ImageObservationMessage()),
            self._calc_message, state_ticket)
        self.DeclareAbstractOutputPort(
            "health", lambda: AbstractValue.Make(TrackerHealth()), self._calc_health,
            state_ticket)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, offset_s, self._update)

    def state(self, context: Context) -> CpfState:
        """The system's state in ``context`` (counts, health, latest message)."""
        return context.get_abstract_state(self._state).get_value()

    def _update(self, context, state) -> EventStatus | None:
        frame: DepthFrame = self._frame_port.Eval(context)
        key = (frame.sequence, repr(frame.capture_time_s))
        if frame.is_empty or key == self.state(context).last_frame:
            # No new frame (at 999 of 1000 checks): Drake keeps the state as it is and
            # recomputes nothing that depends on it.
            return EventStatus.DidNothing()
        s = self.state(context).copy()
        if frame.sequence < s.last_sequence:
            log.warning("camera sequence counter restarted: image %d after image %d; "
                        "frames are told apart by sequence and stamp", frame.sequence,
                        s.last_sequence)
        elif s.last_sequence >= 0 and frame.sequence - s.last_sequence > 1:
            missed = frame.sequence - s.last_sequence - 1
            s.images_skipped += missed
            self._warnings.warn("frames never seen", (
                f"{missed} frame(s) before image {frame.sequence} were never on the depth "
                f"port when it was checked (every {self._period_s * 1e3:g} ms): dropped "
                f"by the camera, or replaced by a newer one between two checks"))
        s.last_sequence, s.last_frame = frame.sequence, key
        if self._process(frame, self._prior_port.Eval(context), s):
            s.images_applied += 1
        else:
            s.images_skipped += 1
        state.get_mutable_abstract_state(self._state).set_value(s)

    def _process(self, frame: DepthFrame, prior: ImagePrior, s: CpfState) -> bool:
        """Runs the image update on ``frame`` if it is due; True when it produced a
        new observation message."""
        t = prior.image_time_s
        if prior.sequence == frame.sequence and t == t and not self.processor.wants_at(
                t, s.next_image_due_s, s.last_applied_image_s):
            return False  # not due (NaN: its stamp was rejected)
        if prior.anchor is None or prior.sequence != frame.sequence:
            return self._skip(frame, prior.problem)
        if t >= s.last_applied_image_s:  # an out-of-order image does not pace the rest
            s.next_image_due_s = self.processor.next_due(t, s.next_image_due_s)
        try:
            window = jump_window_s(t, s.last_applied_image_s, s.health)
            outcome = self.processor.observe(frame, prior.anchor.prior, window, s.health)
        except Exception as err:  # one failed image never stops the simulation
            return self._skip(frame, f"{type(err).__name__}: {err}")
        if outcome.observation is None and outcome.consistency is not None:
            s.health = next_health(s.health, outcome.consistency, self._health_params,
                                   challenger=outcome.challenger)
            return self._skip(frame, outcome.skip_reason)
        if outcome.observation is None:
            return self._skip(frame, "no valid depth pixel")
        s.message = ImageObservationMessage(s.message.id + 1, frame.sequence,
                                            prior.image_time_s, outcome.observation,
                                            prior.anchor)
        s.health = next_health(s.health, outcome.consistency, self._health_params,
                               outcome.restarted, outcome.misplaced, outcome.challenger)
        s.last_applied_image_s = max(t, s.last_applied_image_s)
        return True

    def _skip(self, frame: DepthFrame, problem: str) -> bool:
        self._warnings.warn(problem_kind(problem), f"image {frame.sequence} skipped: {problem}")
        return False

    def _calc_message(self, context, output):
        output.set_value(self.state(context).message)

    def _calc_health(self, context, output):
        output.set_value(self.state(context).health)
