"""The Coordinate Particle Filter image update as a Drake LeafSystem."""

from __future__ import annotations

import copy
import logging
from dataclasses import dataclass, field

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from drake_tracker.core.camera import CameraIntrinsics
from drake_tracker.core.frames import DepthFrame
from drake_tracker.core.health import TrackerHealth, next_health
from drake_tracker.core.pipeline import ImageProcessor, jump_window_s
from drake_tracker.params import TrackerParams
from drake_tracker.systems.messages import ImageObservationMessage, ImagePrior

log = logging.getLogger(__name__)


@dataclass
class CpfState:
    """The system's abstract state."""

    last_sequence: int = -1
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
    that compares the image's sequence number with the last one processed, since Python
    systems cannot schedule their own next update time).

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
    numbers of image ``k`` depend only on (``image.seed``, k). Malformed images and
    images the buffer cannot place are skipped with a logged warning.
    """

    def __init__(self, model, camera: CameraIntrinsics, params: TrackerParams,
                 period_s: float, offset_s: float = 0.0):
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"CpfImageUpdateSystem: period_s must be > 0, got {period_s}")
        self.processor = ImageProcessor(model, camera, params)
        self._health_params = params.health
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

    def state(self, context) -> CpfState:
        """The system's state in ``context`` (counts, health, latest message)."""
        return context.get_abstract_state(self._state).get_value()

    def _update(self, context, state):
        s: CpfState = copy.copy(self.state(context))
        frame: DepthFrame = self._frame_port.Eval(context)
        if frame.is_empty or frame.sequence <= s.last_sequence:
            return
        if s.last_sequence >= 0:  # frames that came and went between two checks
            s.images_skipped += frame.sequence - s.last_sequence - 1
        s.last_sequence = frame.sequence
        if self._process(frame, self._prior_port.Eval(context), s):
            s.images_applied += 1
        else:
            s.images_skipped += 1
        state.get_mutable_abstract_state(self._state).set_value(s)

    def _process(self, frame: DepthFrame, prior: ImagePrior, s: CpfState) -> bool:
        """Runs the image update on ``frame`` if it is due; True when it produced a
        new observation message."""
        if not self.processor.wants(frame, s.next_image_due_s):
            return False
        if prior.anchor is None or prior.sequence != frame.sequence:
            log.warning("image %d skipped: %s", frame.sequence, prior.problem)
            return False
        s.next_image_due_s = self.processor.next_due(prior.image_time_s, s.next_image_due_s)
        try:
            window = jump_window_s(prior.image_time_s, s.last_applied_image_s, s.health)
            outcome = self.processor.observe(frame, prior.anchor.prior, window)
        except ValueError as err:
            log.warning("image %d skipped: %s", frame.sequence, err)
            return False
        if outcome.observation is None:
            log.warning("image %d skipped: no valid depth pixel", frame.sequence)
            return False
        s.message = ImageObservationMessage(s.message.id + 1, frame.sequence,
                                            prior.image_time_s, outcome.observation,
                                            prior.anchor)
        s.health = next_health(s.health, outcome.consistency, self._health_params)
        s.last_applied_image_s = prior.image_time_s
        return True

    def _calc_message(self, context, output):
        output.set_value(self.state(context).message)

    def _calc_health(self, context, output):
        output.set_value(self.state(context).health)
