"""The per-image step, once: what happens to a depth image between the camera and the
Kalman bank. The offline :class:`~drake_tracker.tracker.Tracker` and the Drake systems
(``drake_tracker.systems``) both call these functions, in this order:

1. :func:`judge_stamp`: the image's time t' (capture stamp minus the configured offset)
   through the images' clock (``core/sensors/timestamps.py``): accepted, re-anchored,
   or rejected with a reason;
2. :meth:`ImagePacing.wants`: due under ``image.min_image_interval_s``, or out of
   order (never dropped for the pacing);
3. :func:`place_image`: where the delay buffer puts it, with the angles' prior at t'
   (``ImageAnchor``), or why it cannot (older than the horizon, from the future, in a
   gap of the readings);
4. ``ImageProcessor.observe`` (``core/image_processor.py``): the image update;
5. :func:`conclude_image`: the observation to insert into the buffer at its anchor (or
   why the image is skipped), and the next health state;
6. ``BeliefBuffer.add_image_observation``: the observation at t', the later readings
   filtered again.

The offline tracker runs 1-6 at once; in a Diagram the delay buffer system runs 1, 3
and 6 and the image-update system 2, 4 and 5, exchanging the anchor and the
observation through ports.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.filter.angle_observation import AngleObservation
from drake_tracker.core.robustness.health import (
    HealthParams,
    TrackerHealth,
    next_health,
)
from drake_tracker.core.sensors.depth_frames import DepthFrame, image_time
from drake_tracker.core.sensors.timestamps import (
    StampDecision,
    StreamClock,
    follow_buffer,
    log_reanchor,
)

if TYPE_CHECKING:
    from drake_tracker.core.calibration.online import SelfCalibration
    from drake_tracker.core.filter.belief_buffer import BeliefBuffer, ImageAnchor
    from drake_tracker.core.image_processor import ImageOutcome
    from drake_tracker.core.resolved_params import ResolvedParams
    from drake_tracker.robot.model import TrackerModel

_log = logging.getLogger(__name__)


def judge_stamp(frame: DepthFrame, clock: StreamClock, buffer: BeliefBuffer,
                readings_clock: StreamClock, params: ResolvedParams, log: logging.Logger,
                images_keep_time: bool = False) -> StampDecision:
    """Step 1: ``frame``'s time t' through the images' ``clock`` (changed in place: pass
    a copy to keep the old one); a re-anchoring is logged, and an accepted image moves
    the clock's lag behind the ``buffer``'s readings (``follow_buffer``).

    ``images_keep_time``: without joint readings (vision only) the offline tracker's
    buffer is advanced to the image's arrival first (in a Diagram the readings' stamps
    advance it)."""
    t_image = image_time(frame, params)
    decision = clock.check(t_image)
    if decision.reanchored_by_s is not None:
        log_reanchor(log, "image", decision, frame.capture_time_s, clock)
    t = decision.time_s
    if t is None:
        return decision
    if images_keep_time and not params.use_joint_readings:
        arrival = frame.arrival_time_s + t - t_image
        buffer.advance_to(max(t, arrival) if np.isfinite(arrival) else t)
    follow_buffer(clock, buffer, t, log, readings_clock)
    return decision


def place_image(buffer: BeliefBuffer, t: float) -> tuple[ImageAnchor | None, str]:
    """Step 3: where the buffer applies an image at ``t`` (its anchor: the prior at t),
    or (None, why not)."""
    problem = buffer.image_time_problem(t) or buffer.reading_gap_problem(t)
    if problem:
        return None, problem
    return buffer.image_anchor(t), ""


@dataclass(frozen=True)
class ImagePacing:
    """Step 2: which images are processed. ``next_due_s``: images stamped before it are
    not due; ``last_applied_s``: the latest applied image's time."""

    next_due_s: float = -np.inf
    last_applied_s: float = -np.inf

    def wants(self, t: float) -> bool:
        """Whether an image at ``t`` is due: at or after ``next_due_s`` (the others are
        skipped, so a fast camera builds up no backlog), or older than the latest applied
        image: an image that arrives out of order is applied at its time, as the buffer
        allows, never dropped for the pacing."""
        return bool(t >= self.next_due_s - 1e-9 or t < self.last_applied_s)

    def taken_up(self, t: float, interval_s: float) -> ImagePacing:
        """After an image at ``t`` is taken up. Images are paced at ``interval_s`` on
        average (the first frame at or after each due time: a 30 Hz camera with jitter
        gives 10 images/s at 0.1 s, not the 7.5/s that a minimum gap would), never
        closer than half of it, so a burst of frames after a stall is not all processed;
        an out-of-order image does not pace the rest."""
        if t < self.last_applied_s:
            return self
        base = self.next_due_s if np.isfinite(self.next_due_s) else t
        return replace(self, next_due_s=max(base + interval_s, t + 0.5 * interval_s))

    def applied(self, t: float) -> ImagePacing:
        """After an image at ``t`` was applied."""
        return replace(self, last_applied_s=max(t, self.last_applied_s))

    def jump_window_s(self, t: float, health: TrackerHealth) -> float:
        """The time a bias jump is looked for before an image at ``t``: since the previous
        applied image, or 0 until the tracker has acquired the arm (see
        ``ImageProcessor.jump_probability``)."""
        return t - self.last_applied_s if health.acquired else 0.0


@dataclass(frozen=True)
class ImageVerdict:
    """Step 5: the observation to insert at the image's anchor (None: skip the image,
    for ``problem``, counted and warned under ``kind``) and the health after it."""

    observation: AngleObservation | None
    health: TrackerHealth
    problem: str = ""
    kind: str = ""


def conclude_image(outcome: ImageOutcome, health: TrackerHealth,
                   params: HealthParams) -> ImageVerdict:
    """Step 5: an image update's outcome against the health before it."""
    if outcome.observation is None and outcome.consistency is not None:
        after = next_health(health, outcome.consistency, params,
                            challenger=outcome.challenger)
        return ImageVerdict(None, after, outcome.skip_reason, "images that show no arm")
    if outcome.observation is None:
        return ImageVerdict(None, health, "no valid depth pixel",
                            "images without a valid pixel")
    after = next_health(health, outcome.consistency, params, outcome.restarted,
                        outcome.misplaced, outcome.challenger, outcome.innovation)
    return ImageVerdict(outcome.observation, after)


def calibrate_after(calibration: SelfCalibration | None, camera: str, t: float,
                    frame: DepthFrame, prior: np.ndarray, health: TrackerHealth,
                    processors: dict, model: TrackerModel,
                    params: ResolvedParams) -> SelfCalibration | None:
    """After step 5, with several cameras (``core/calibration/online.py``): the
    calibration's next state once camera ``camera``'s image at ``t`` (its anchor's
    ``prior``, the camera's ``health`` after it) was taken; the image that completes the
    window runs the fit. ``processors``: each camera's ``ImageProcessor``."""
    if calibration is None or calibration.held is not None:
        return calibration
    window_s = params.camera_calibration.window_s
    calibration = calibration.took(camera, t, frame.depth_m, prior, health,
                                   processors[camera].update,
                                   params.health.min_robot_pixels, window_s)
    start = calibration.window(t, list(processors), window_s)
    if start is None:
        return calibration
    calibration = calibration.calibrated(
        model, params, {name: p.update for name, p in processors.items()}, prior, start, t)
    held = calibration.held
    _log.info("the cameras calibrated on their images of %.2f-%.2f s (log-likelihood "
              "%.0f -> %.0f, %d evaluations, %.1f s); their offsets and the joints that "
              "move only them are held from now on", start, t, *held.log_likelihood,
              held.evaluations, held.fit_wall_s)
    return calibration
