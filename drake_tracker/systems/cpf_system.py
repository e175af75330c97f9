"""The Coordinate Particle Filter image update as a Drake LeafSystem."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from drake_tracker.core.camera import CameraIntrinsics
from drake_tracker.core.frames import DepthFrame
from drake_tracker.params import TrackerParams
from drake_tracker.systems.messages import ImageObservationMessage, ImagePrior
from drake_tracker.tracker import ImageProcessor

log = logging.getLogger(__name__)


@dataclass
class CpfState:
    """The system's abstract state."""

    last_sequence: int = -1
    next_image_due_s: float = float("-inf")
    message: ImageObservationMessage = field(default_factory=ImageObservationMessage)
    images_applied: int = 0
    images_skipped: int = 0


class CpfImageUpdateSystem(LeafSystem):
    """Runs the CPF image update once per new depth image (SPEC §6: a periodic
    unrestricted update that compares the image's sequence number with the last one
    processed, since Python systems cannot schedule their own next update time).

    .. pydrake_system::

        name: CpfImageUpdateSystem
        input_ports:
        - depth_frame
        - image_prior
        output_ports:
        - image_observation

    ``depth_frame`` carries a :class:`DepthFrame` (full resolution of ``camera``);
    ``image_prior`` the delay buffer's belief at that frame's time. The output is an
    :class:`ImageObservationMessage` whose id grows by one per applied image. The random
    numbers of image ``k`` depend only on (``image.seed``, k). Malformed images and
    images the buffer cannot place are skipped with a logged warning.
    """

    def __init__(self, model, camera: CameraIntrinsics, params: TrackerParams,
                 period_s: float, offset_s: float = 0.0):
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"CpfImageUpdateSystem: period_s must be > 0, got {period_s}")
        self.processor = ImageProcessor(model, camera, params)
        self._state = self.DeclareAbstractState(AbstractValue.Make(CpfState()))
        self.DeclareAbstractInputPort("depth_frame", AbstractValue.Make(DepthFrame.empty()))
        self.DeclareAbstractInputPort("image_prior", AbstractValue.Make(ImagePrior()))
        self.DeclareAbstractOutputPort(
            "image_observation", lambda: AbstractValue.Make(ImageObservationMessage()),
            self._calc_message, {self.abstract_state_ticket(self._state)})
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, offset_s, self._update)

    def _update(self, context, state):
        s: CpfState = state.get_mutable_abstract_state(int(self._state)).get_value()
        frame: DepthFrame = self.get_input_port(0).Eval(context)
        if frame.is_empty or frame.sequence <= s.last_sequence:
            return
        if s.last_sequence >= 0:  # frames that came and went between two checks
            s.images_skipped += frame.sequence - s.last_sequence - 1
        s.last_sequence = frame.sequence
        if self.processor.wants(frame, s.next_image_due_s):
            prior: ImagePrior = self.get_input_port(1).Eval(context)
            if prior.anchor is None or prior.sequence != frame.sequence:
                log.warning("image %d skipped: %s", frame.sequence, prior.problem)
                s.images_skipped += 1
            else:
                try:
                    observation, _ = self.processor.observe(frame, prior.anchor.prior)
                except ValueError as err:
                    log.warning("image %d skipped: %s", frame.sequence, err)
                    observation = None
                s.next_image_due_s = self.processor.next_due(prior.image_time_s,
                                                             s.next_image_due_s)
                if observation is None:
                    s.images_skipped += 1
                else:
                    s.message = ImageObservationMessage(
                        s.message.id + 1, frame.sequence, prior.image_time_s, observation,
                        prior.anchor)
                    s.images_applied += 1
        else:
            s.images_skipped += 1
        state.get_mutable_abstract_state(int(self._state)).set_value(s)

    def _calc_message(self, context, output):
        output.set_value(context.get_abstract_state(int(self._state)).get_value().message)
