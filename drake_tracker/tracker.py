"""The offline tracker: joint readings and depth images in, the current estimate out.

:class:`Tracker` is the whole method as plain Python over numpy: a Kalman bank on
(angle, bias) for every joint of the tracker's model (the robot's joints and the six
virtual camera joints, whose "reading" is always 0), a delay buffer, and the
CPF image update. Readings and images may come in any interleaving: an image stamped
``t'`` (its capture stamp minus ``image_time_offset_s``) is applied to the belief at
``t'`` and the readings after it are filtered again.

The Drake systems in ``drake_tracker.systems`` call the same pieces
(``drake_tracker.core.image_step``), and give the same estimates from the same data
(``tests/test_systems.py``).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.cpf.particle_filter import CPFResult
from drake_tracker.core.filter.belief_buffer import BeliefBuffer
from drake_tracker.core.filter.estimate import PoseReadout, TrackerEstimate, estimate_from_belief
from drake_tracker.core.image_step import (
    ImageProcessor,
    full_reading,
    jump_window_s,
    make_bank_and_prior,
    new_belief_buffer,
    robot_joint_indices,
)
from drake_tracker.core.robustness.health import TrackerHealth, next_health
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.core.sensors.depth_frames import DepthFrame, depth_to_metres
from drake_tracker.core.sensors.depth_units import check_depth_units
from drake_tracker.core.sensors.rate_limited_warning import RateLimitedWarning
from drake_tracker.core.sensors.reading_gate import ReadingGate
from drake_tracker.core.sensors.timestamps import (
    StreamClock,
    follow_buffer,
    log_reanchor,
    problem_kind,
)
from drake_tracker.params.tracker_params import TrackerParams, validate_tracker_params

if TYPE_CHECKING:
    from drake_tracker.robot.model import TrackerModel

log = logging.getLogger(__name__)

__all__ = ["Tracker", "TrackerEstimate"]


class Tracker:
    """The offline tracker. Feed it ``add_reading`` and ``add_image`` in arrival order.

    Args:
        model: the tracker's model (``build_tracker_model``).
        camera: intrinsics of the depth images that will be passed in.
        params: tracker parameters.
    """

    def __init__(self, model: TrackerModel, camera: CameraIntrinsics,
                 params: TrackerParams | None = None):
        self.model = model
        self.camera = camera
        self.params = params if params is not None else TrackerParams()
        validate_tracker_params(self.params)
        make_bank_and_prior(model, self.params, None)  # joint names checked now, not later
        self.readout = PoseReadout(model)
        self.images = ImageProcessor(model, camera, self.params) \
            if self.params.image.enabled else None
        self.buffer: BeliefBuffer | None = None
        #: Images stamped before this are not due yet (``ImageProcessor.next_due``).
        self.next_image_due_s = -np.inf
        self.last_applied_image_s = -np.inf
        #: Updated after every applied image (``core/robustness/health.py``).
        self.health = TrackerHealth()
        self.last_result: CPFResult | None = None
        self.num_images_applied = 0
        self.num_images_skipped = 0
        self._robot = robot_joint_indices(model)
        stamps = self.params.timestamps
        self.readings = ReadingGate(stamps, model.robot_joint_names, log)
        self.image_clock = StreamClock("image", stamps, self.params.buffer_horizon_s)
        self.warnings = RateLimitedWarning(log)
        if not self.params.use_joint_readings:
            self._start(0.0, None)

    def _start(self, t: float, first_reading: np.ndarray | None) -> None:
        self.buffer = new_belief_buffer(self.model, self.params, t, first_reading)

    def add_reading(self, t: float, robot_reading: np.ndarray) -> None:
        """An encoder reading of the robot joints (``model.robot_joint_names`` order),
        stamped ``t`` (s). Raises ValueError for a wrong length. A reading with a value or
        stamp that is not usable is skipped with a warning (``core/sensors/timestamps.py``): one
        per run of non-finite values, rate-limited for stamps."""
        try:
            t = float(t)
        except (TypeError, ValueError) as err:
            raise ValueError(f"joint reading time stamp {t!r} is not a number") from err
        try:
            reading = np.asarray(robot_reading, float)
        except (TypeError, ValueError) as err:
            raise ValueError(f"joint reading stamped {t} s is not numeric: {err}") from err
        if reading.shape != (len(self._robot),):
            raise ValueError(f"joint reading has shape {reading.shape}, expected "
                             f"({len(self._robot)},) for joints {self.model.robot_joint_names}")
        t = self.readings.admit(t, reading)
        if t is None:
            return
        if self.readings.restarted and self.params.use_joint_readings:
            self.buffer = None  # built on outlier stamps: restart from this reading
        if not self.params.use_joint_readings:
            if self.buffer is not None:
                self.buffer.advance_to(t)
            return
        if self.buffer is None:
            self._start(t, reading)
        self.buffer.add_reading(t, full_reading(self.model, reading))

    def add_image(self, frame: DepthFrame) -> bool:
        """A depth image (full resolution of ``camera``; float metres, or uint16
        millimetres with 0 and 65535 for no return); True when it was applied.

        Images before the first reading, with a stamp the time-stamp policy rejects
        (``core/sensors/timestamps.py``), older than the buffer horizon, from the future, in a gap
        of the readings, not due yet (``min_image_interval_s``) or without a valid pixel
        are skipped, with a rate-limited warning for all but the not-due ones. A
        malformed image, or one not in metres (``core/sensors/depth_units.py``), raises
        ValueError.
        """
        if frame.is_empty:
            if np.size(frame.depth_m):
                raise ValueError(f"image with sequence {frame.sequence}: a negative sequence "
                                 "number marks the empty placeholder (DepthFrame.empty()), "
                                 "not an image; number images from 0")
            return self._skip(frame, "it is the empty placeholder (DepthFrame.empty()): "
                              "no image yet", "empty placeholder frames")
        if self.images is None:
            return False
        if np.asarray(frame.depth_m).dtype == np.uint16:  # a 16-bit camera's millimetres
            frame = replace(frame, depth_m=depth_to_metres(frame.depth_m, "16U_mm"))
        self.images.update.prepare(frame.depth_m)  # validates before anything changes
        check_depth_units(frame.depth_m)
        if self.buffer is None:
            return self._skip(frame, "no joint reading yet", "images before a reading")
        decision = self.image_clock.check(self.images.image_time(frame))
        if decision.reanchored_by_s is not None:
            log_reanchor(log, "image", decision, frame.capture_time_s, self.image_clock)
        t = decision.time_s
        if t is None:
            return self._skip(frame, decision.problem, decision.kind)
        if not self.params.use_joint_readings:
            arrival = frame.arrival_time_s + decision.time_s - self.images.image_time(frame)
            self.buffer.advance_to(max(t, arrival) if np.isfinite(arrival) else t)
        follow_buffer(self.image_clock, self.buffer, t, log, self.readings.clock)
        if not self.images.wants_at(t, self.next_image_due_s, self.last_applied_image_s):
            self.num_images_skipped += 1
            return False
        problem = self.buffer.image_time_problem(t) or self.buffer.reading_gap_problem(t)
        if problem is not None:
            return self._skip(frame, problem, problem_kind(problem))
        anchor = self.buffer.image_anchor(t)
        outcome = self.images.observe(
            frame, anchor.prior, jump_window_s(t, self.last_applied_image_s, self.health),
            self.health)
        if t >= self.last_applied_image_s:  # an out-of-order image does not pace the rest
            self.next_image_due_s = self.images.next_due(t, self.next_image_due_s)
        self.last_result = outcome.result
        if outcome.observation is None and outcome.consistency is not None:
            self.health = next_health(self.health, outcome.consistency, self.params.health,
                                      challenger=outcome.challenger)
            return self._skip(frame, outcome.skip_reason, "images that show no arm")
        if outcome.observation is None:
            return self._skip(frame, "no valid depth pixel", "images without a valid pixel")
        self.health = next_health(self.health, outcome.consistency, self.params.health,
                                  outcome.restarted, outcome.misplaced, outcome.challenger)
        self.buffer.add_image_observation(anchor, outcome.observation)
        self.last_applied_image_s = max(t, self.last_applied_image_s)
        self.num_images_applied += 1
        return True

    def _skip(self, frame: DepthFrame, problem: str, kind: str) -> bool:
        self.warnings.warn(kind, f"image {frame.sequence} skipped: {problem}")
        self.num_images_skipped += 1
        return False

    @property
    def started(self) -> bool:
        """Whether the tracker has a belief buffer, hence an estimate: after its first joint
        reading, or from the start when it does not use joint readings."""
        return self.buffer is not None

    def estimate(self) -> TrackerEstimate:
        """The current estimate (after the latest reading)."""
        if self.buffer is None:
            raise RuntimeError("the tracker has no estimate before its first joint reading")
        t, belief = self.buffer.present()
        estimate = estimate_from_belief(self.model, self.readout, t, belief)
        estimate.health = self.health
        return estimate
