"""Searches from the encoders' arm that can overrule the image update (a restart).

The CPF follows its prior: once it holds a wrong configuration that explains the image
about as well as its neighbours, no single update leaves it. Two searches start where
the tracker itself starts, at the encoders' arm (the challenger's first image also from
the estimate's camera offset: ``EncoderSearch.restarts``), and replace the update's
answer when the image's log-likelihood at their mean beats it by
``health.second_opinion_margin_nats_per_pixel`` times the image's valid pixels (both
scored on the image without the occlusion estimate):

* :meth:`EncoderSearch.second_opinion`: one image's search, on an image that contradicts
  the estimate (``is_surprising``);
* :meth:`EncoderSearch.challenge`: a *challenger belief* (:class:`Challenger`) kept
  over images while the estimate's biases are implausible (beyond
  :data:`IMPLAUSIBLE_BIAS_SIGMAS` of the bias model's spread on some joint). One image
  cannot move a search 5 deg on each of seven joints, as the start needs a second of
  images to; kept over images, the challenger converges as the start does, and wins.

Measured on the protocol's occlusion/time-varying seed 0 (a 5 deg square wave on every
arm joint, an occluder crossing the arm): the estimate folded joints 3-4 to biases of
30-55 deg, 100-570 mm off for 30 s, the health saying ``tracking``; the truth scored
1,300-2,500 nats above it, and a one-image search from the encoders' arm stayed at their
5 deg biases, 5,000 nats below.

The searches once started from the nominal camera: a restart sets each angle to its
``a + b``, and a virtual joint's readings hold that at 0. On arm/time-varying seed 8 the
estimate's camera stood 2.2 cm and 0.9 deg from nominal before a 10 deg bias step; the
challenger, seeing the encoders' arm from nominal, scored -1,300 nats against the
wrong fold's +3,200 for 20 images and won only 8.6 s later (1 m off until then).
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from statistics import NormalDist
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.cpf.particle_filter import CPFResult
from drake_tracker.core.filter.angle_observation import Restart
from drake_tracker.core.filter.kalman import MEAN_A, MEAN_B, VAR_A
from drake_tracker.core.likelihood.occlusion import observed_image
from drake_tracker.core.robustness.health import (
    Challenger,
    ImageConsistency,
    TrackerHealth,
    agreeing_pixels,
    image_consistency,
    is_consistent,
)
from drake_tracker.core.robustness.innovation import FALSE_ALARM_PROBABILITY

if TYPE_CHECKING:
    from drake_tracker.core.calibration.online import HeldCameras
    from drake_tracker.core.cpf.image_update import CpfImageUpdate
    from drake_tracker.core.likelihood.pixel_model import PreparedObservation
    from drake_tracker.core.resolved_params import ResolvedParams

log = logging.getLogger(__name__)

#: A bias estimate is implausible where the bias model's own test rejects it, at the
#: false-alarm probability of the filter's innovation test (two-sided, one degree of
#: freedom): beyond 2.81 of its spread (29 deg by default). It replaces the parameter
#: ``challenger_bias_sigmas`` (2.25): on the quick suite's 130 recorded runs (Zen 5 VM,
#: the code of 20e3126) 3 runs changed on tracker stream 0 and 6 on stream 100, no cell
#: beyond 10 % + 0.5 mm but random-walk-6's median on stream 100 (123 -> 147 mm).
IMPLAUSIBLE_BIAS_SIGMAS = NormalDist().inv_cdf(1.0 - FALSE_ALARM_PROBABILITY / 2.0)


def plausible_bias_std(bias_process_std: np.ndarray, bias_decay_per_s: np.ndarray,
                       initial_bias_std: np.ndarray, jump_std: np.ndarray,
                       jump_rate: np.ndarray) -> np.ndarray:
    """(n,) spread of the bias model (rad): the larger of its stationary standard deviation
    σb/√(-2 ln c) (none for c = 1, a random walk) and the initial one, with one jump's
    added where jumps happen."""
    decay = np.asarray(bias_decay_per_s, float)
    with np.errstate(divide="ignore"):
        stationary = np.where(decay < 1.0, np.asarray(bias_process_std) ** 2
                              / (-2.0 * np.log(np.minimum(decay, 1.0 - 1e-12))), 0.0)
    var = np.maximum(stationary, np.asarray(initial_bias_std) ** 2)
    return np.sqrt(var + np.where(np.asarray(jump_rate) > 0, np.asarray(jump_std) ** 2, 0.0))


def implausible_biases(prior: np.ndarray, plausible_std: np.ndarray,
                       sigmas: float) -> np.ndarray:
    """(n,) whether each joint's bias mean lies beyond ``sigmas`` of ``plausible_std``
    (inf: never); ``sigmas`` 0: none is."""
    if sigmas <= 0:
        return np.zeros(prior.shape[1], bool)
    return np.abs(prior[MEAN_B]) > sigmas * plausible_std


def challenger_prior(candidate: np.ndarray, challenger: Challenger | None, time_s: float,
                     growth_var_per_s: np.ndarray) -> np.ndarray:
    """The challenger's (5, n) prior at ``time_s``: the restart's belief ``candidate``
    (the encoders' arm; its angle variance the start's, its bias given the reading)
    shifted by the challenger's offset, its angle variance the offset's grown by the
    bias random walk since its last image, never above the restart's; a new
    challenger's is the restart's. (The search reads the angle marginals only.)
    Measured on the protocol's occlusion/time-varying runs, median / p75
    from 5 s, tracker seed 0: simulation seed 0 10.1 / 47.4 mm (the code before: 47.3 /
    383.2), simulation seed 1 6.6 / 49.4; starting instead as wide as the bias prior
    (5.7 deg, as the tracker's start effectively is), 13.6 / 51.6 and 17.3 / 133.5."""
    if challenger is None:
        return candidate
    prior = candidate.copy()
    prior[MEAN_A] += challenger.offset_mean
    elapsed = max(time_s - challenger.time_s, 0.0)
    prior[VAR_A] = np.minimum(challenger.offset_var + growth_var_per_s * elapsed,
                              candidate[VAR_A])
    return prior


@dataclass(frozen=True)
class Overrule:
    """A search's answer that replaces the update's: ``result``, found from ``prior``,
    the belief restarted by ``restart`` (which the delay buffer applies again)."""

    result: CPFResult
    prior: np.ndarray
    restart: Restart


class EncoderSearch:
    """The second opinion, the kept search, the challenger and, with several cameras,
    the remount of a camera's own pose, over one image update (``update``: a
    ``CpfImageUpdate``); ``occlusion_aware(observation, rendered, consistency)`` reads
    the per-pixel occlusion at a rendered arm (``ImageProcessor._occlusion_aware``);
    ``params`` the resolved parameters (each joint's noise model; the virtual camera
    joints' biases are never implausible); ``restart``, the tracker's restart to the
    encoders' arm; ``remount`` (several cameras), the restart of this camera's own
    pose."""

    def __init__(self, update: CpfImageUpdate, params: ResolvedParams,
                 occlusion_aware: Callable, restart: Restart,
                 remount: Restart | None = None) -> None:
        self.update = update
        self.params = params
        self.restart = restart
        #: With several cameras, the restart of this camera's own pose, and the CPF
        #: blocks that hold the joints it restarts (``remount_search``).
        self.remount = remount
        self._remount_blocks = []
        if remount is not None:
            self._remount_blocks = self._blocks_holding(
                remount.touched(len(params.joints.names)))
        joints = params.joints
        self._virtual = ~joints.robot
        self._occlusion_aware = occlusion_aware
        sigma_b = joints.bias_process_std
        spread = plausible_bias_std(sigma_b, joints.bias_decay_per_s,
                                    joints.initial_bias_std, joints.jump_std,
                                    joints.declared_jump_rate_per_s)
        self.plausible_std = np.where(joints.robot & joints.has_bias, spread, np.inf)
        self._growth = sigma_b ** 2  # the bias random walk's variance per second
        # The kept search's step: the robot joints with a bias that this camera's images
        # may move, and the CPF blocks that hold them.
        #: (n,) the robot joints with a bias that the restart touches: the kept
        #: search's, and the ones a partial restart chooses among (``least_restart``).
        self.stepped = joints.robot & (np.asarray(restart.bias_var) > 0) & restart.touched(
            len(joints.names))
        self._drift_step = replace(restart.kept(), untouched=np.flatnonzero(~self.stepped))
        self._drift_blocks = self._blocks_holding(self.stepped)
        #: The blocks a search covers when none are given (None: every block).
        self._blocks: list[np.ndarray] | None = None

    def held_by(self, held: HeldCameras) -> EncoderSearch:
        """These searches with the cameras held (``core/calibration/online.py``): their
        restarts return the offsets to the calibration, and no search samples a held
        joint."""
        search = copy.copy(self)
        search.restart = held.restart(self.restart)
        search._blocks = held.blocks(self.update.blocks)
        search._drift_blocks = held.blocks(self._drift_blocks)
        return search

    def _blocks_holding(self, joints: np.ndarray) -> list[np.ndarray]:
        """The update's CPF blocks that hold any of ``joints`` (n,) bool."""
        return [b for b in self.update.blocks if joints[b].any()]

    def _beats(self, result: CPFResult, alternative: CPFResult,
               plain: PreparedObservation) -> tuple[bool, np.ndarray]:
        scores = self.update.log_likelihood(np.stack([result.mean, alternative.mean]), plain)
        margin = self.params.health.second_opinion_margin_nats_per_pixel * plain.num_valid
        return bool(scores[1] > scores[0] + margin), scores

    def restarts(self, prior: np.ndarray) -> list[Restart]:
        """The restarts a challenger tries at its first image: to the encoders' arm seen
        from the nominal camera (a virtual joint's ``a + b`` is 0: the tracker's start),
        and from ``prior``'s camera offset (``Restart.pinned_angle``) when that differs.
        Measured: after a bias step the estimate's offset was the right one
        (arm/time-varying seed 8: from nominal, a challenger scored -1,300 nats against a
        wrong fold's +3,200 for 20 images; from the estimate's, +2,800 at its first
        image); after the arm was out of view it can be far off (in-out-in/time-varying
        seed 8: restarts that kept it put the arm out of view again within a second, ten
        times). Which camera made the encoders' arm itself score better did not tell
        them apart (a 4 cm, 2 deg offset against 3 deg biases on three joints: the
        nominal scored higher), so the challenger searches from both, and the better
        answer counts."""
        kept = self.restart.pinned(np.where(self._virtual, prior[MEAN_A], np.nan))
        if np.allclose(kept.apply(prior)[MEAN_A], self.restart.apply(prior)[MEAN_A],
                       rtol=0.0, atol=1e-9):
            return [self.restart]
        return [self.restart, kept]

    def _search(self, plain: PreparedObservation, starts: list[tuple[np.ndarray, Restart]],
                time_s: float, rng: np.random.Generator,
                blocks: list[np.ndarray] | None = None
                ) -> tuple[CPFResult, np.ndarray, Restart] | None:
        """The start-up search from each (prior, restart) of ``starts`` on the image
        ``plain`` (over ``blocks`` only, if given); the answer whose mean scores best,
        with its prior and restart (None: no search had a usable answer)."""
        found = []
        for start, restart in starts:
            rendered = self.update.renderer.render(start[MEAN_A][None])[0]
            seen = image_consistency(time_s, rendered, observed_image(plain),
                                     self.params.image.likelihood)
            answer = self.update(start, self._occlusion_aware(plain, rendered, seen), rng,
                                 None, None, self.params.image.acquisition_num_particles,
                                 coarse_sweeps=False,
                                 blocks=self._blocks if blocks is None else blocks)
            if answer is not None and not answer.flat_likelihood:
                found.append((answer, start, restart))
        if len(found) < 2:
            return found[0] if found else None
        scores = self.update.log_likelihood(np.stack([f[0].mean for f in found]), plain)
        return found[int(np.argmax(scores))]

    def second_opinion(self, plain: PreparedObservation, prior: np.ndarray,
                       result: CPFResult, time_s: float, rng: np.random.Generator,
                       sequence: int) -> Overrule | None:
        """The start-up search from the encoders' arm (the restart: nominal camera) on one
        image: its answer if it beats the update's ``result``, else None. Measured: after
        a bias step the update put a wrong fold of two joints (-28 deg, +25 deg) that
        explained the image at 94 % agreement, 300 mm off, 1300 nats below the truth, and
        followed it for good. (Searching from the estimate's camera offset as well, as
        the challenger does, was worse where the head moves the camera: on both and
        both++ time-varying, seeds 4-9, 28 s above 200 mm in all against 7 s.)"""
        kept = self.restart.kept()
        best = self._search(plain, [(self.restart.apply(prior), self.restart),
                                    (kept.apply(prior), kept)], time_s, rng)
        return self._adopted(best, result, plain, sequence, time_s, "it contradicts the "
                             "estimate's arm, and a search from the encoders' arm")

    def _adopted(self, best: tuple[CPFResult, np.ndarray, Restart] | None,
                 result: CPFResult, plain: PreparedObservation, sequence: int,
                 time_s: float, why: str) -> Overrule | None:
        """A search's ``best`` (answer, prior, restart) as the overrule of the update's
        ``result`` if it beats it by the margin (logged: ``why`` explains it better),
        else None."""
        if best is None:
            return None
        alternative, candidate, restart = best
        wins, scores = self._beats(result, alternative, plain)
        if not wins:
            log.debug("image %d: a search scored %.0f against the update's %.0f: kept the "
                      "update", sequence, scores[1], scores[0])
            return None
        log.warning("image %d at %.3f s: %s explains it better (log-likelihood %.0f against "
                    "%.0f); the belief restarts from there", sequence, time_s, why,
                    scores[1], scores[0])
        return Overrule(alternative, candidate, restart)

    def kept_search(self, plain: PreparedObservation, observation: PreparedObservation,
                    prior: np.ndarray, result: CPFResult, time_s: float,
                    rng: np.random.Generator, sequence: int) -> Overrule | None:
        """H2 alone, on an image after the filter's innovations outgrew its model
        (``health.drifts``): the robot joints with a bias take the kept restart's step
        (``Restart.kept``: every mean kept, the bias variance of the start added, the
        reading held), every other joint (the camera offsets) stays, and the image
        update searches those joints' blocks with its own particles and sweeps (coarse
        where ``image.sweep_image_widths_px`` makes them so; not at the defaults).
        Its answer replaces the update's if it explains the image better by the margin,
        as the second opinion's does. The CPF moves a joint by about two prior standard
        deviations per image, so a bias that walks or ramps faster than its model is
        followed late; the step reaches it in one image. The step keeps the means, so
        the search scores ``observation``, the update's own (its occlusion read at the
        prior mean), and ``plain`` decides."""
        start = self._drift_step.apply(prior)
        answer = self.update(start, observation, rng, blocks=self._drift_blocks)
        if answer is None or answer.flat_likelihood:
            return None
        return self._adopted((answer, start, self._drift_step), result, plain, sequence,
                             time_s, "the filter's innovations outgrew its model, and a "
                             "search keeping the biases")

    def remounted(self, prior: np.ndarray, observed: np.ndarray,
                  predicted: ImageConsistency
                  ) -> tuple[np.ndarray, np.ndarray, ImageConsistency] | None:
        """The prior with this camera's own pose restarted (``remount``: its offset
        joints to the nominal mount, the joints that move only it to their readings; the
        arm and the other cameras' joints kept), its rendering and its consistency, when
        the image hides the estimate's arm (at least ``health.min_robot_pixels`` in view,
        too few of them unhidden) and agrees, consistently and on more pixels, with the
        held arm seen from there; else None (the image is skipped).

        An image that hides the arm where the estimate puts it is not only an occluder's:
        a camera whose estimated pose is centimetres behind its true one sees the arm
        nearer than the estimate puts it, all of it "hidden". Measured on the quick
        suite's in-out-in-2cam/constant seed 3 (the code of b598ba4), the head camera's
        first image (the arm 8.6 deg off on every joint) moved its pose 89 mm; from then
        its images saw 575-970 robot pixels, 95-99 % of them hidden, and all were skipped,
        also when the arm came back into its view: 85-121 mm in its frame to the end. A
        plate in front of the arm hides it from the nominal mount too, and stays skipped.
        """
        if predicted.robot_pixels < self.params.health.min_robot_pixels:
            return None
        candidate = self.remount.apply(prior)
        rendered = self.update.renderer.render(candidate[MEAN_A][None])[0]
        seen = image_consistency(predicted.time_s, rendered, observed,
                                 self.params.image.likelihood)
        if is_consistent(seen, self.params.health) and (
                agreeing_pixels(seen) > agreeing_pixels(predicted)):
            return candidate, rendered, seen
        return None

    def remount_search(self, plain: PreparedObservation, prior: np.ndarray,
                       result: CPFResult, time_s: float, rng: np.random.Generator,
                       sequence: int) -> Overrule | None:
        """This camera's own pose searched again, the arm and the other cameras kept: on
        an image of one of several cameras that contradicts the arm the others hold. Its
        own joints (its six offset joints, the joints that move only it) restart as at
        the tracker's start (``remount``: nominal mount, readings at zero bias, the
        start's variances), and the start-up search runs over their blocks alone. Its
        answer replaces the update's if it explains the image better by the margin.
        Measured on in-out-in-2cam/time-varying seed 1: the head's estimated pan and tilt
        were 1 and 3 deg off when the arm came back into the head camera's view, and each
        of its images, contradicting the arm the post camera held, pushed the head
        further off (pan 1 -> 18 deg, tilt -3 -> -16 deg in 1.2 s): 0.1 -> 0.7 m in the
        head camera's frame; with this search, 5 mm."""
        best = self._search(plain, [(self.remount.apply(prior), self.remount)], time_s, rng,
                            self._remount_blocks)
        return self._adopted(best, result, plain, sequence, time_s, "it contradicts the arm "
                             "the other cameras hold, and a search of this camera's own pose")

    def challenge(self, plain: PreparedObservation, prior: np.ndarray, result: CPFResult,
                  tracker: TrackerHealth, time_s: float, rng: np.random.Generator,
                  sequence: int) -> tuple[Overrule | None, Challenger | None]:
        """One image of the challenger. Returns (its answer if it beats the update's
        ``result``, else None; the challenger after this image, None once it won or is no
        longer needed). It starts while the estimate (``prior``) has an implausible bias,
        and searches from the restart's belief at this image, seen from the camera whose
        search did best on its first image (``restarts``), for
        ``health.max_unconfirmed_s`` (the longest a belief no image confirms is held),
        then rests as long; ``tracker``, the health before this image, holds the
        challenger so far."""
        challenger, hold_s = tracker.challenger, self.params.health.max_unconfirmed_s
        implausible = implausible_biases(prior, self.plausible_std, IMPLAUSIBLE_BIAS_SIGMAS)
        if challenger is None and not implausible.any():
            return None, None
        if challenger is not None and time_s - challenger.started_s >= 2 * hold_s:
            challenger = None  # rested: a fresh start if still needed
        if challenger is not None and time_s - challenger.started_s >= hold_s:  # resting
            return None, replace(challenger, time_s=time_s, images=challenger.images + 1)
        images = 0 if challenger is None else challenger.images
        started_s = time_s if challenger is None else challenger.started_s
        restarts = (self.restarts(prior) if challenger is None
                    else [self.restart.pinned(challenger.pinned_angle)])
        starts = [(challenger_prior(r.apply(prior), challenger, time_s, self._growth), r)
                  for r in restarts]
        best = self._search(plain, starts, time_s, rng)
        if best is None:
            return None, challenger
        alternative, ch_prior, restart = best
        candidate = restart.apply(prior)
        wins, scores = self._beats(result, alternative, plain)
        if wins:
            log.warning("image %d at %.3f s: the estimate's biases are implausible (joints "
                        "%s), and a challenger searched from the encoders' arm over %d "
                        "images explains the image better (log-likelihood %.0f against "
                        "%.0f); the belief restarts from there", sequence, time_s,
                        np.flatnonzero(implausible).tolist(), images + 1, scores[1],
                        scores[0])
            return Overrule(alternative, candidate, restart), None
        log.debug("image %d at %.3f s: challenger image %d scored %.0f against the "
                  "update's %.0f", sequence, time_s, images + 1, scores[1], scores[0])
        if not implausible.any():  # the estimate came back by itself
            return None, None
        floor = ch_prior[VAR_A] / self.update.num_particles
        return None, Challenger(alternative.mean - candidate[MEAN_A],
                                np.maximum(alternative.variance, floor), time_s, images + 1,
                                restart.pinned_angle, started_s)
