"""One image's update: a depth frame and the angles' prior at its time in, a
pseudo-observation of the angles (and the image's consistency with the estimate) out.

:class:`ImageProcessor` is the CPF image update (``core/cpf``) with what surrounds it:
the image against the estimate and the encoders (``core/robustness``), the restart, the
per-image occlusion estimate, the bias-jump prior, and the searches that may overrule
the update. The per-image bookkeeping around it (stamps, pacing, placement, health) is
``core/image_step.py``; the method's reference is ``docs/method.md``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.cpf.image_update import CpfImageUpdate
from drake_tracker.core.cpf.particle_filter import CPFResult
from drake_tracker.core.filter.angle_observation import AngleObservation, Restart
from drake_tracker.core.filter.kalman import (
    MEAN_A,
    VAR_A,
    VAR_B,
    initial_moments,
)
from drake_tracker.core.likelihood.occlusion import (
    image_occlusion,
    observed_image,
    pixel_occlusion,
    with_pixel_occlusion,
)
from drake_tracker.core.resolved_params import ResolvedParams
from drake_tracker.core.robustness import least_restart as partial
from drake_tracker.core.robustness.health import (
    Challenger,
    ImageConsistency,
    TrackerHealth,
    agreeing_pixels,
    drifts,
    image_consistency,
    is_consistent,
    is_misplaced,
    is_surprising,
    restart_due,
    shows_no_arm,
)
from drake_tracker.core.robustness.innovation import Innovation, image_innovation
from drake_tracker.core.robustness.jump_visibility import jump_testable
from drake_tracker.core.robustness.second_opinion import EncoderSearch
from drake_tracker.core.robustness.skips import out_of_view_reason
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.core.sensors.depth_frames import DepthFrame, image_time
from drake_tracker.core.sensors.depth_units import check_depth_units

if TYPE_CHECKING:
    from drake_tracker.core.calibration.online import HeldCameras
    from drake_tracker.robot.model import TrackerModel

log = logging.getLogger(__name__)


def image_rng(seed: int, sequence: int, camera_index: int = 0) -> np.random.Generator:
    """The CPF's random stream for image ``sequence`` of the model's camera
    ``camera_index``: independent of what came before, so a re-simulated or replayed run
    draws the same numbers (the first camera's streams are the one-camera tracker's)."""
    key = [int(seed), int(sequence), 0x5EED] + ([int(camera_index)] if camera_index else [])
    return np.random.default_rng(key)


@dataclass(frozen=True)
class ImageOutcome:
    """What one image update produced (all None for an image with no valid pixel):
    ``consistency`` compares the image with the robot rendered at the prior mean."""

    observation: AngleObservation | None
    result: CPFResult | None
    consistency: ImageConsistency | None
    #: Whether the update restarted the belief from the encoders first (see ``observe``).
    restarted: bool = False
    #: Whether the estimate put the arm out of view and the encoders in it (``is_misplaced``).
    misplaced: bool = False
    #: Why the image was not applied (observation None), if not for lack of valid pixels.
    skip_reason: str = ""
    #: The challenger belief after this image (``core/robustness/second_opinion.py``).
    challenger: Challenger | None = None
    #: The joint filter's innovation of ``observation`` (``core/robustness/innovation.py``).
    innovation: Innovation | None = None


@dataclass
class DecisionTimes:
    """Wall time of :meth:`ImageProcessor.observe` (s), accumulated over its images:
    ``update_s`` is the paper's image update (the frame's preparation and the CPF search
    of the tracked belief), ``decision_s`` everything around it (the renders of the
    estimate's and the encoders' arms and their comparison with the image, the restart,
    the occlusion estimate, the jump gate, the second opinion's and the challenger's
    searches). ``images`` counts the frames observed."""

    images: int = 0
    update_s: float = 0.0
    decision_s: float = 0.0

    @property
    def decision_share(self) -> float:
        """The decision's time over the update's (NaN before any update)."""
        return self.decision_s / self.update_s if self.update_s > 0 else float("nan")


class ImageProcessor:
    """Turns a depth frame and the prior at its time into a pseudo-observation.

    Shared by the offline tracker and the Drake CPF system, so that both draw the same
    random numbers and skip the same images. With several cameras there is one per
    camera (``camera_name``): it renders through that camera's estimated frame and
    samples the robot joints and that camera's six virtual joints only
    (``ResolvedParams.blocks_for``).
    """

    def __init__(self, model: TrackerModel, camera: CameraIntrinsics,
                 params: ResolvedParams, camera_name: str | None = None) -> None:
        self.params = params
        self.camera_name = camera_name
        #: Which of the model's cameras (its random streams: ``image_rng``).
        self.camera_index = 0
        #: Whether the model has other cameras, which may hold the arm while this one
        #: does not see it (``observe``: such an image is not applied, unless it shows
        #: the arm from this camera's nominal mount: ``EncoderSearch.remounted``).
        self.several_cameras = len(model.cameras) > 1
        #: The robot joints (n,): those whose innovations test the filter's consistency.
        self._robot = np.zeros(model.num_joints, bool)
        self._robot[np.asarray(model.robot_joint_indices, int)] = True
        if camera_name is not None:
            self.camera_index = model.camera_names.index(model.camera(camera_name).name)
            model = model.for_camera(camera_name)
        im, joints = params.image, params.joints
        self._jump_rate = joints.jump_rate_per_s
        self._jump_std = joints.jump_std
        start = initial_moments(np.zeros(len(joints.names)), joints.initial_angle_std,
                                joints.initial_bias_std, joints.has_bias)
        # The variances of the start; another camera's joints are kept as they are.
        left = params.left_joints_for(camera_name)
        self.restart = Restart(start[VAR_A], start[VAR_B],
                               untouched=left if len(left) else None,
                               reading_var=joints.kalman.encoder_noise_std ** 2)
        #: With several cameras: the restart of this camera's own pose alone (its six
        #: offset joints and the joints that move only it), every other joint kept.
        self.remount = None
        if self.several_cameras:
            others = set(left.tolist())  # another camera's joints
            own = set(model.camera_joint_indices(camera_name).tolist()) | {
                i for i, name in enumerate(joints.names)
                if name in params.camera_chain and i not in others}
            kept = np.array([i for i in range(len(joints.names)) if i not in own], np.int64)
            self.remount = replace(self.restart, untouched=kept)
        self.update = CpfImageUpdate(
            model, camera, list(params.blocks_for(camera_name)), im.num_particles,
            im.likelihood, im.image_width_px, im.max_kl, im.renderer, im.near_m, im.far_m,
            tuple(im.annealing_betas), tuple(im.sweep_image_widths_px),
            im.search_depth_widening_m)
        self.search = EncoderSearch(self.update, params, self._occlusion_aware,
                                    self.restart, self.remount)
        #: The robot joints (base to tip) and camera offset joints a restart may keep.
        self._restarted = (np.flatnonzero(self.search.stepped), np.flatnonzero(
            ~joints.robot & self.restart.touched(len(joints.names))))
        #: Where :meth:`observe`'s time went (``bench/decision.py`` reads it).
        self.times = DecisionTimes()

    def jump_probability(self, elapsed_s: float) -> np.ndarray:
        """(n,) probability that each joint's bias jumped within ``elapsed_s`` (the time
        since the previous applied image; at most ``health.max_unconfirmed_s``, the
        longest a belief is held without an image confirming it, which replaces a
        constant of its own, 1 s, with the same value). Callers pass 0
        until the tracker has acquired the arm (``TrackerHealth.acquired``): the start is
        the initial prior's job, and a jump-wide prior there let the first images swing a
        shoulder 35 deg to put the arm out of view (a robot rendered nowhere scores 0, a
        misaligned one less), measured on s-head-arm/constant, 0.7 m from then on."""
        window = min(max(float(elapsed_s), 0.0), self.params.health.max_unconfirmed_s)
        return -np.expm1(-self._jump_rate * window)

    def observe(self, frame: DepthFrame, prior: np.ndarray, elapsed_s: float = np.inf,
                health: TrackerHealth | None = None, others_track: bool = False,
                held: HeldCameras | None = None) -> ImageOutcome:
        """The image's observation relative to ``prior`` (None if it has no valid pixel),
        and its consistency with the estimate; ``elapsed_s`` is the time since the
        previous applied image; ``health`` the tracker's before this image (default: it
        holds the arm): until the arm is ``acquired``, the update searches with
        ``image.acquisition_num_particles``; ``others_track``: another of several
        cameras says ``tracking`` (``cameras.another_camera_tracks``); ``held``: the
        cameras calibrated (``core/calibration/online.py``), their joints pinned. Its
        time goes into ``times``."""
        start, update_before = time.perf_counter(), self.times.update_s
        try:
            return self._observe(frame, prior, elapsed_s, health, others_track, held)
        finally:
            times = self.times
            times.images += 1
            times.decision_s += (time.perf_counter() - start) - (times.update_s
                                                                 - update_before)

    def _observe(self, frame: DepthFrame, prior: np.ndarray, elapsed_s: float,
                 health: TrackerHealth | None, others_track: bool, held) -> ImageOutcome:
        health = TrackerHealth(acquired=True) if health is None else health
        restart, blocks, search = self.restart, None, self.search  # restart: to the start
        if held is not None:  # the cameras calibrated: their joints stay where they are
            prior, restart, search = held.prior(prior), held.restart(restart), \
                self.search.held_by(held)
            blocks = held.blocks(self.update.blocks)
        acquired = health.acquired
        start = time.perf_counter()
        observation = self.update.prepare(frame.depth_m)
        self.times.update_s += time.perf_counter() - start
        check_depth_units(frame.depth_m)  # a millimetre image is an error, not a blank
        if observation.num_valid == 0:
            return ImageOutcome(None, None, None)
        # The image against the belief before it: the predictive check of the health
        # state, and which of the robot's pixels are hidden behind something.
        rendered = self.update.renderer.render(prior[MEAN_A][None])[0]
        image = self.params.image
        observed = observed_image(observation)  # z and valid pixels: occlusion keeps them
        predicted = image_consistency(image_time(frame, self.params), rendered, observed,
                                      image.likelihood)
        # Never lost for good: the belief restarts from the encoders (as at the tracker's
        # start: see ``restart_reason``) before the update.
        restarted, misplaced = False, False
        if self.params.use_joint_readings:
            candidate = restart.apply(prior)
            rendered_enc = self.update.renderer.render(candidate[MEAN_A][None])[0]
            encoders = image_consistency(predicted.time_s, rendered_enc, observed,
                                         image.likelihood)
            misplaced = is_misplaced(predicted, encoders, self.params.health, health)
            reason = self.restart_reason(predicted, encoders, health)
            if reason:
                hp = self.params.health
                restart, scores, depth = partial.least_restart(
                    self.update, restart, partial.restart_family(restart, *self._restarted),
                    prior, observation, hp.second_opinion_margin_nats_per_pixel,
                    lambda depth: partial.fits(image_consistency(
                        predicted.time_s, depth, observed, image.likelihood), encoders, hp))
                log.warning("image %d at %.3f s: %s; the belief restarts from the encoders%s",
                            frame.sequence, predicted.time_s, reason,
                            partial.kept_note(restart, scores))
                if restart.kept_joints is not None:  # a partial restart (least_restart)
                    candidate, rendered_enc = restart.apply(prior), depth
                    encoders = image_consistency(predicted.time_s, depth, observed,
                                                 image.likelihood)
                restarted, misplaced, acquired = True, False, False
                prior, rendered, predicted = candidate, rendered_enc, encoders
            elif shows_no_arm(predicted, encoders, health, self.params.health):
                return ImageOutcome(None, None, predicted, challenger=health.challenger,
                                    skip_reason=(
                    f"it sees through {predicted.see_through:.0%} of the arm where the "
                    f"estimate puts it and {encoders.see_through:.0%} where the encoders do: "
                    f"no arm where one must be (a moved camera, or a stale or foreign frame)"))
        if self.several_cameras and not restarted and (
                predicted.visible_robot_pixels < self.params.health.min_robot_pixels
                or (others_track and predicted.mostly_hidden)):
            remounted = None if held else self.search.remounted(prior, observed, predicted)
            if remounted is None:
                return ImageOutcome(None, None, predicted, challenger=health.challenger,
                                    skip_reason=out_of_view_reason(
                                        self.camera_name, predicted, self.params.health))
            log.warning("image %d at %.3f s (camera '%s'): the image hides the arm where the "
                        "estimate puts it, and shows it where the camera's nominal mount does;"
                        " the camera's pose restarts", frame.sequence, predicted.time_s,
                        self.camera_name)
            restarted, misplaced, acquired, restart = True, False, False, self.remount
            prior, rendered, predicted = remounted
        plain = observation
        observation = self._occlusion_aware(observation, rendered, predicted)
        # A bias jump is tested only on an image that sees enough of the arm (the health's
        # min_robot_pixels unhidden at the prior mean). On one that does not, the jump
        # particles meet a flat likelihood and their Monte-Carlo noise became the estimate:
        # occlusion-heavy seed 2, 22 visible pixels, a 3.8 deg move of one joint (22 prior
        # sigmas) for 2.2 nats, kept for the rest of the occlusion (README, "A bias that
        # outlasts an occlusion").
        jumps = self.jump_probability(elapsed_s)
        if restarted or predicted.visible_robot_pixels < self.params.health.min_robot_pixels:
            jumps = np.zeros_like(jumps)
        elif np.any(jumps > 0):
            # Nor of a joint whose jump the image would not see (see core/jump_visibility):
            # measured, a forearm leaving the view let the elbow's jumps walk it 120 deg in
            # 4 s, folded out of sight, and it never came back (1 m at 116 s of the
            # default scenario, health tracking on what was still rendered).
            joints = np.flatnonzero(jumps > 0)
            testable = jump_testable(self.update.renderer, prior[MEAN_A], joints,
                                     self._jump_std, rendered, observed,
                                     image.likelihood, image.min_jump_pixels,
                                     self.consistent(predicted))
            jumps[joints[~testable]] = 0.0
        rng = image_rng(self.params.image.seed, frame.sequence, self.camera_index)
        # An arm never held since the start or a restart: the search may be widened in
        # depth (image.search_depth_widening_m).
        never_held = not acquired and (restarted or not np.isfinite(health.confirmed_s))
        start = time.perf_counter()
        result = self.update(prior, observation, rng, jumps, self._jump_std,
                             None if acquired else self.params.image.acquisition_num_particles,
                             coarse_sweeps=acquired, widened=never_held, blocks=blocks)
        self.times.update_s += time.perf_counter() - start
        if result is None:
            return ImageOutcome(None, None, None)
        # (A restart above cleared ``acquired``.) A second opinion on an image that contradicts
        # the held arm; else H2 alone, after the innovations outgrew the filter's model.
        asked = self.params.use_joint_readings and not restarted and acquired
        surprising = is_surprising(predicted, self.params.health, health)
        if asked and surprising:
            overrule = search.second_opinion(plain, prior, result, predicted.time_s, rng,
                                             frame.sequence)
        elif asked and drifts(predicted, health, self.params.health):
            overrule = search.kept_search(plain, observation, prior, result,
                                          predicted.time_s, rng, frame.sequence)
        else:
            overrule = None
        # With several cameras, H4: this camera's own pose searched again, the arm the
        # others hold kept, once this camera has held the arm (at the start its pose is
        # the start-up search's).
        if overrule is None and surprising and self.several_cameras and \
                self.params.use_joint_readings and not restarted and held is None and \
                np.isfinite(health.confirmed_s):
            overrule = self.search.remount_search(plain, prior, result, predicted.time_s,
                                                  rng, frame.sequence)
        # While the estimate's biases are implausible, a challenger belief searches from
        # the encoders' arm over several images (see core/robustness/second_opinion.py).
        challenger = None
        if self.params.use_joint_readings and not restarted and overrule is None:
            overrule, challenger = search.challenge(plain, prior, result, health,
                                                    predicted.time_s, rng, frame.sequence)
        if overrule is not None:
            restarted, misplaced = True, False
            prior, result, restart = overrule.prior, overrule.result, overrule.restart
        # A degenerate particle set would claim certainty; floor the posterior variance
        # at the Monte-Carlo resolution of the prior.
        floor = np.maximum(prior[VAR_A] / self.update.num_particles, 1e-14)
        variance = np.maximum(result.variance, floor)
        if result.flat_likelihood:  # the image says nothing: the belief stays as it is
            zero = np.zeros_like(prior[MEAN_A])
            observation = AngleObservation(zero, zero)
        else:
            observation = AngleObservation.from_posterior(prior, result.mean, variance)
        if restarted:
            observation = replace(observation, restart=restart)
        innovation = image_innovation(prior, observation, self._robot)
        if held is not None:
            observation = held.pin(observation, prior)
        return ImageOutcome(observation, result, predicted, restarted, misplaced,
                            challenger=challenger, innovation=innovation)

    def restart_reason(self, estimate: ImageConsistency, encoders: ImageConsistency,
                       health: TrackerHealth) -> str:
        """Why an image restarts the belief from the encoders ("": it does not), given its
        consistency with the estimate's arm and with the encoders' (zero bias):

        * it contradicts the estimate, or cannot see it, while it agrees with the
          encoders' arm, and on more pixels;
        * the estimate has put the arm out of view while the encoders put it in view
          (``is_misplaced``: an image that shows the estimate's arm more than the
          encoders' does not count) for ``health.max_unconfirmed_s``. Measured: a
          second of images without the arm (the fault matrix's arm_out_of_view) moved
          the estimate out of view, which explains them best, and then no image could
          bring it back (840 mm 4 s after the arm returned). Counting the images that
          confirmed the estimate, an encoders' arm that a drifted bias swung towards
          the camera (rendering twice the pixels, all seen through) restarted a
          confirmed estimate each second (a 30 s random walk of 3 deg/sqrt(s):
          100-750 mm for most of 12 s; ``docs/method.md`` §7).
        """
        if not self.consistent(estimate) and self.consistent(encoders) and (
                agreeing_pixels(encoders) > agreeing_pixels(estimate)):
            return "it agrees with the encoders' arm and not with the estimate"
        if is_misplaced(estimate, encoders, self.params.health, health) and restart_due(
                health, estimate.time_s, self.params.health):
            return (f"the estimate has put the arm out of view since "
                    f"{health.misplaced_since_s:.3f} s while the encoders put it in view")
        return ""

    def _occlusion_aware(self, observation, rendered: np.ndarray,
                         predicted: ImageConsistency):
        """The observation with the per-pixel occlusion estimate read at ``rendered``.

        Read at the prior mean: only meaningful while the image does not contradict it
        (after a bias step the true arm in front of the prior's would be an occluder:
        s-full-arm, 8.6 deg of constant bias, diverged to 0.9 m without the condition)."""
        image = self.params.image
        if predicted.see_through > self.params.health.max_see_through:
            return observation
        fraction = image_occlusion(predicted, image.likelihood, image.occlusion_prior_pixels)
        return with_pixel_occlusion(observation, pixel_occlusion(observation, rendered, fraction))

    def consistent(self, image: ImageConsistency) -> bool:
        """``is_consistent`` under the tracker's health parameters."""
        return is_consistent(image, self.params.health)
