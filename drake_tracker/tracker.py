"""The offline tracker: joint readings and depth images in, the current estimate out.

:class:`Tracker` is the whole method as plain Python over numpy: a Kalman bank on
(angle, bias) for every joint of the tracker's model (the robot's joints and the six
virtual camera joints, whose "reading" is always 0), a delay buffer, and the
CPF image update. Readings and images may come in any interleaving: an image stamped
``t'`` (its capture stamp minus ``image_time_offset_s``) is applied to the belief at
``t'`` and the readings after it are filtered again.

The Drake systems in ``drake_tracker.systems`` call the same pieces
(``drake_tracker.core.image_step``), and give the same estimates from the same data
(``tests/systems/test_systems.py``).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.calibration.online import SelfCalibration, self_calibration
from drake_tracker.core.cameras import (
    CameraChannel,
    another_camera_tracks,
    best_health,
    camera_channels,
    camera_named,
    clock_disagreement,
)
from drake_tracker.core.cpf.image_update import check_depth_image
from drake_tracker.core.cpf.particle_filter import CPFResult
from drake_tracker.core.filter.belief_buffer import BeliefBuffer
from drake_tracker.core.filter.estimate import PoseReadout, TrackerEstimate, estimate_from_belief
from drake_tracker.core.filter.start import full_reading, new_belief_buffer, start_reading_ok
from drake_tracker.core.image_processor import ImageProcessor
from drake_tracker.core.image_step import (
    ImagePacing,
    calibrate_after,
    conclude_image,
    judge_stamp,
    place_image,
)
from drake_tracker.core.robustness.health import TrackerHealth
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.core.sensors.depth_frames import DepthFrame, in_metres
from drake_tracker.core.sensors.depth_units import check_depth_units
from drake_tracker.core.sensors.rate_limited_warning import RateLimitedWarning
from drake_tracker.core.sensors.reading_gate import ReadingGate
from drake_tracker.core.sensors.timestamps import StreamClock, problem_kind
from drake_tracker.params.resolve import resolve_tracker_params

if TYPE_CHECKING:
    from pydrake.systems.sensors import CameraInfo

    from drake_tracker.core.calibration.online import HeldCameras
    from drake_tracker.core.resolved_params import ResolvedParams
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.robot.model import TrackerModel

log = logging.getLogger(__name__)

__all__ = ["Tracker", "TrackerEstimate"]


class Tracker:
    """The offline tracker. Feed it ``add_reading`` and ``add_image`` in arrival order.

    Args:
        model: the tracker's model (``build_tracker_model``).
        camera: intrinsics of the depth images that will be passed in (or Drake's
            ``CameraInfo``): the model's first (with one camera, only) camera.
        params: tracker parameters (default: ``TrackerParams()``), checked and resolved
            for ``model`` once, here; or already resolved (``resolve_tracker_params``).
        cameras: instead of ``camera``, several of the model's cameras by name
            (``RobotConfig.cameras``) -> their intrinsics; images then name their camera
            (``add_image(frame, camera=NAME)``). A camera of the model left out has no
            images: its offset stays at its prior.
    """

    def __init__(self, model: TrackerModel, camera: CameraIntrinsics | CameraInfo | None = None,
                 params: TrackerParams | ResolvedParams | None = None, *,
                 cameras: dict[str, CameraIntrinsics | CameraInfo] | None = None) -> None:
        if (camera is None) == (cameras is None):
            raise ValueError("Tracker: give either camera= (the model's first camera) or "
                             "cameras={name: intrinsics}, one of the two")
        self.model = model
        #: The resolved parameters every step reads.
        self.params = resolve_tracker_params(params, model)
        self.readout = PoseReadout(model)
        #: Each camera's image update, clock, pacing and health (``core/cameras.py``).
        self.channels: dict[str, CameraChannel] = camera_channels(
            model, {model.camera_names[0]: camera} if cameras is None else cameras,
            self.params)
        first = next(iter(self.channels.values()))
        self.camera = first.intrinsics
        self.images: ImageProcessor | None = first.images
        self.image_clock: StreamClock = first.clock
        self.buffer: BeliefBuffer | None = None
        self.last_result: CPFResult | None = None
        self.num_images_applied = 0
        self.num_images_skipped = 0
        stamps = self.params.timestamps
        self.readings = ReadingGate(stamps, model.robot_joint_names, log)
        #: Several cameras calibrate themselves once (``core/calibration/online.py``).
        self.calibration: SelfCalibration | None = self_calibration(
            self.params, model, [n for n, c in self.channels.items() if c.images])
        self.warnings = RateLimitedWarning(log)
        if not self.params.use_joint_readings:
            self.buffer = new_belief_buffer(self.params, 0.0, None)

    def add_reading(self, t: float, robot_reading: np.ndarray) -> bool:
        """An encoder reading of the robot joints (``model.robot_joint_names`` order),
        stamped ``t`` (s); True when it was used. Raises ValueError for a wrong length. A
        reading whose stamp is not usable, or with no usable value, is skipped with a
        warning (``core/sensors/timestamps.py``): one per run of non-finite readings,
        rate-limited for stamps. Joints whose value alone is not usable (NaN) are
        predicted and the others filtered (``ReadingGate.admit``); the first reading
        must have them all."""
        try:
            t = float(t)
        except (TypeError, ValueError) as err:
            raise ValueError(f"joint reading time stamp {t!r} is not a number") from err
        try:
            reading = np.asarray(robot_reading, float)
        except (TypeError, ValueError) as err:
            raise ValueError(f"joint reading stamped {t} s is not numeric: {err}") from err
        n = len(self.params.robot_joint_indices)
        if reading.shape != (n,):
            raise ValueError(f"joint reading has shape {reading.shape}, expected "
                             f"({n},) for joints {self.model.robot_joint_names}")
        t = self.readings.admit(t, reading)
        if t is None:
            return False
        if not self.params.use_joint_readings:
            self.buffer.advance_to(t)
            return True
        reading = self.readings.values
        if self.buffer is None or self.readings.restarted:  # a restart: from this reading
            if not start_reading_ok(reading, self.readings.warnings):
                return False
            self.buffer = new_belief_buffer(self.params, t, reading)
        self.buffer.add_reading(t, full_reading(self.params, reading), checked=True)
        return True

    @property
    def pacing(self) -> ImagePacing:
        """Which images of the first camera are due (``core/image_step.py``, step 2)."""
        return next(iter(self.channels.values())).pacing

    @property
    def health(self) -> TrackerHealth:
        """Updated after every applied image (``core/robustness/health.py``): with several
        cameras, that of the camera in the best state (``core/cameras.best_health``)."""
        return best_health(self.channels)

    def channel(self, camera: str | None) -> CameraChannel:
        """The channel of the camera named ``camera`` (None: the only one); ValueError
        naming the tracker's cameras for an unknown name, or None with several."""
        return self.channels[camera_named(
            camera, list(self.channels), "tracker",
            "name the image's camera (add_image(frame, camera=NAME))")]

    def add_image(self, frame: DepthFrame, camera: str | None = None) -> bool:
        """A depth image of the camera named ``camera`` (None: the tracker's only one; an
        unknown name raises ValueError) at its full resolution (float metres, or uint16
        millimetres with 0 and 65535 for no return); True when it was applied.

        Images before the first reading, with a stamp the time-stamp policy rejects
        (``core/sensors/timestamps.py``), older than the buffer horizon, from the future,
        in a gap of the readings, not due yet (``min_image_interval_s``) or without a
        valid pixel are skipped, with a rate-limited warning for all but the not-due
        ones. A malformed image, or one not in metres (``core/sensors/depth_units.py``),
        raises ValueError. The steps are ``core/image_step.py``'s, through the camera's
        image update, clock, pacing and health, into the one delay buffer; an image whose
        camera's clock disagrees with another camera's by more than the buffer horizon is
        skipped, warned and counted.
        """
        channel = self.channel(camera)
        if frame.is_empty:
            if np.size(frame.depth_m):
                raise ValueError(f"image with sequence {frame.sequence}: a negative sequence "
                                 "number marks the empty placeholder (DepthFrame.empty()), "
                                 "not an image; number images from 0")
            return self._skip(frame, channel, "it is the empty placeholder "
                              "(DepthFrame.empty()): no image yet", "empty placeholder frames")
        if channel.images is None:
            return False
        frame = replace(frame, depth_m=in_metres(frame.depth_m))  # a 16-bit camera's mm
        check_depth_image(frame.depth_m, channel.intrinsics)  # before anything changes
        check_depth_units(frame.depth_m)
        if self.buffer is None:
            return self._skip(frame, channel, "no joint reading yet",
                              "images before a reading")
        decision = judge_stamp(frame, channel.clock, self.buffer, self.readings.clock,
                               self.params, log, images_keep_time=True)
        t = decision.time_s
        if t is None:
            return self._skip(frame, channel, decision.problem, decision.kind)
        lag = frame.arrival_time_s - t
        problem = clock_disagreement(channel, self.channels, lag, self.params.buffer_horizon_s)
        if problem:
            return self._skip(frame, channel, problem, "images whose camera clock disagrees")
        if not channel.pacing.wants(t):
            self.num_images_skipped += 1
            return False
        anchor, problem = place_image(self.buffer, t)
        if anchor is None:
            return self._skip(frame, channel, problem, problem_kind(problem))
        channel.lag_s = lag
        health = channel.health
        outcome = channel.images.observe(frame, anchor.prior,
                                         channel.pacing.jump_window_s(t, health), health,
                                         another_camera_tracks(
                                             {n: c.health for n, c in self.channels.items()},
                                             channel.name),
                                         held=self.held)
        channel.pacing = channel.pacing.taken_up(t, self.params.image.min_image_interval_s)
        self.last_result = outcome.result
        verdict = conclude_image(outcome, health, self.params.health)
        channel.health = verdict.health
        self.calibration = calibrate_after(
            self.calibration, channel.name, t, frame, anchor.prior, verdict.health,
            {n: c.images for n, c in self.channels.items()}, self.model, self.params)
        if verdict.observation is None:
            return self._skip(frame, channel, verdict.problem, verdict.kind)
        self.buffer.add_image_observation(anchor, verdict.observation)
        channel.pacing = channel.pacing.applied(t)
        self.num_images_applied += 1
        return True

    def _skip(self, frame: DepthFrame, channel: CameraChannel, problem: str,
              kind: str) -> bool:
        if len(self.channels) > 1:
            problem = f"(camera '{channel.name}') {problem}"
        self.warnings.warn(kind, f"image {frame.sequence} skipped: {problem}")
        self.num_images_skipped += 1
        return False

    @property
    def held(self) -> HeldCameras | None:
        """What the cameras' calibration holds (None: not calibrated)."""
        return None if self.calibration is None else self.calibration.held

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
