"""An image update as a Gaussian pseudo-observation of the joint angles, and the restart
that may replace the prior first (the delay buffer stores both: ``core/filter/belief_buffer.py``).

An image update is kept as a per-joint observation in information form (``precision``,
``information``): the likelihood implied by the CPF's moment-matched marginals relative
to the prior they came from. Applied to that same prior it gives back exactly eq. (16);
replayed after an earlier delayed image it stays linear-Gaussian and cheap.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from drake_tracker.core.filter.kalman import (
    COV_AB,
    MEAN_A,
    MEAN_B,
    VAR_A,
    VAR_B,
    recombine_with_bias,
)


@dataclass(frozen=True)
class Restart:
    """Forgets a belief that the images showed wrong: each joint's angle goes to where
    the encoders put it with the bias mean added back (``a + b``: for a robot joint, its
    reading's angle at zero bias), within the start's angle variance ``angle_var`` (A);
    the bias is forgotten (a flat prior), so given the reading it is whatever the angle
    leaves: ``b = (a + b) - a``, mean 0, ``var_b = A + σq²``, ``cov_ab = -A`` (σq² the
    encoder's ``reading_var``). A joint without bias (``bias_var`` 0) keeps a zero bias
    and its angle takes the reading: ``var_a = A σq² / (A + σq²)``.

    The image after a restart then sets the bias as well as the angle (eq. 16), and the
    next reading keeps the image's angle. A restart that left the angle and the bias
    independent (``cov_ab`` 0, ``var_b`` the start's) lost the image's answer: the next
    reading (the angle's random walk σa lets it follow its encoder) took the angle back
    to the zero-bias arm. Measured on s-full-arm/time-varying seed 0 of the quick suite,
    a search that explained the image better (4,813 against 3,808 nats) left the hand
    112-123 mm off until the next image, 36 mm before it.

    A virtual camera joint's reading is always 0, so there ``a + b`` is 0, the nominal
    camera, unless ``pinned_angle`` (n,) sets its angle (NaN: not pinned): a pinned
    joint's angle mean becomes that, and its bias mean the prior's ``a + b`` minus it,
    so the sum the readings measure is kept. Commutes with a shift of the unpinned
    angles (the virtual joints are never shifted), so it can be stored at an image's
    anchor.

    With ``keep_bias`` it keeps what is known instead: every mean stays (the biases and
    the camera offset), and each joint's bias takes a step of variance ``bias_var``
    while its reading holds ``a + b`` (the bias-jump model): ``var_b += B``,
    ``var_a += B``, ``cov_ab -= B``. Its angle marginal then covers the zero-bias arm
    at ``|b| / sqrt(var_b + B)`` standard deviations, instead of forgetting the bias."""

    angle_var: np.ndarray
    bias_var: np.ndarray
    pinned_angle: np.ndarray | None = None
    keep_bias: bool = False
    #: Indices of joints whose prior the restart keeps as it is (with several cameras:
    #: the joints a camera's images leave, ``ResolvedParams.left_joints_for``: another
    #: camera's offset is not this camera's to forget).
    untouched: np.ndarray | None = None
    #: Each joint's encoder variance σq² (n,) (None: exact readings, which leave a joint
    #: without bias no angle variance).
    reading_var: np.ndarray | None = None
    #: Indices of joints that keep what is known, as ``keep_bias`` does for every joint
    #: (their means kept, a bias step of ``bias_var``), while the others restart: the
    #: joints an image does not contradict (``core/robustness/least_restart.py``).
    kept_joints: np.ndarray | None = None

    def touched(self, count: int) -> np.ndarray:
        """(count,) whether this restart changes each of ``count`` joints (those not
        ``untouched``)."""
        mask = np.ones(count, bool)
        if self.untouched is not None:
            mask[self.untouched] = False
        return mask

    def pinned(self, angle: np.ndarray | None) -> Restart:
        """This restart with ``pinned_angle`` = ``angle`` (None: none pinned)."""
        return replace(self, pinned_angle=angle, keep_bias=False)

    def kept(self) -> Restart:
        """This restart keeping the biases and the camera offset (``keep_bias``)."""
        return replace(self, pinned_angle=None, keep_bias=True, kept_joints=None)

    def keeping(self, joints: np.ndarray) -> Restart:
        """This restart with ``joints`` (indices) keeping what is known (``kept_joints``)."""
        joints = np.asarray(joints, np.int64)
        return replace(self, kept_joints=joints if len(joints) else None)

    def apply(self, prior: np.ndarray) -> np.ndarray:
        """The restarted (5, n) belief: angle means ``a + b`` of ``prior`` (or the pinned
        angle), bias means 0 (or ``a + b`` minus the pinned angle), ``var_a = A``,
        ``cov_ab = -A``, ``var_b = A + σq²`` (see the class); with ``keep_bias``,
        ``prior`` with a bias step of variance ``bias_var``."""
        if self.keep_bias or self.kept_joints is not None:
            kept = np.array(prior, float, copy=True)
            kept[VAR_A] += self.bias_var
            kept[VAR_B] += self.bias_var
            kept[COV_AB] -= self.bias_var
            if self.untouched is not None and len(self.untouched):
                kept[:, self.untouched] = prior[:, self.untouched]
            if self.keep_bias:
                return kept
            restarted = replace(self, kept_joints=None).apply(prior)
            restarted[:, self.kept_joints] = kept[:, self.kept_joints]
            return restarted
        restarted = np.zeros_like(prior)
        restarted[MEAN_A] = prior[MEAN_A] + prior[MEAN_B]
        if self.pinned_angle is not None:
            pin = np.isfinite(self.pinned_angle)
            restarted[MEAN_B, pin] = restarted[MEAN_A, pin] - self.pinned_angle[pin]
            restarted[MEAN_A, pin] = self.pinned_angle[pin]
        A = np.asarray(self.angle_var, float)
        R = 0.0 if self.reading_var is None else np.asarray(self.reading_var, float)
        biased = np.asarray(self.bias_var) > 0
        restarted[VAR_A] = np.where(biased, A, A * R / (A + R))
        restarted[COV_AB] = np.where(biased, -A, 0.0)
        restarted[VAR_B] = np.where(biased, A + R, 0.0)
        if self.untouched is not None and len(self.untouched):
            restarted[:, self.untouched] = prior[:, self.untouched]
        return restarted


@dataclass(frozen=True)
class AngleObservation:
    """A Gaussian pseudo-observation of the joint angles, in information form.

    Applied to a prior with angle marginal (μ, S): posterior precision ``1/S + precision``
    and posterior information ``μ/S + information``; the bias follows by eq. (16). With a
    ``restart``, the prior is first replaced by ``restart.apply(prior)``.
    """

    precision: np.ndarray
    information: np.ndarray
    restart: Restart | None = None

    @staticmethod
    def from_posterior(prior: np.ndarray, mean_post: np.ndarray,
                       var_post: np.ndarray) -> AngleObservation:
        """The observation that turns ``prior`` (5, n) into angle marginals (mean, var).

        Where the posterior is not tighter than the prior, the observation carries no
        precision and only shifts the mean.
        """
        s_prior = prior[VAR_A]
        mu_prior = prior[MEAN_A]
        with np.errstate(divide="ignore", invalid="ignore"):
            precision = 1.0 / var_post - 1.0 / s_prior
            tighter = np.isfinite(precision) & (precision > 0)
            information = np.where(
                tighter,
                mean_post / var_post - mu_prior / s_prior,
                np.where(s_prior > 0, (mean_post - mu_prior) / s_prior, 0.0),
            )
        precision = np.where(tighter, precision, 0.0)
        return AngleObservation(precision, information)

    def innovation(self, prior: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """This observation's innovation against ``prior`` (5, n), joint by joint: the
        observed angle ``z = information / precision`` (``R = 1 / precision``) against
        the prior ``N(mu, s)``, ``nu = z - mu`` with predicted variance ``S = s + R``.
        Returns ``(informs, nu, S)``, (n,) each: ``informs`` marks the joints where the
        image says at least as much as the prior (``R <= s``). Elsewhere the shift of the
        CPF's mean is mostly its Monte-Carlo error (about ``s / N_eff``), which ``R``
        does not hold, and ``nu`` and ``S`` there are finite placeholders."""
        informs = self.precision * prior[VAR_A] >= 1.0
        safe = np.where(informs, self.precision, 1.0)
        return (informs, self.information / safe - prior[MEAN_A],
                prior[VAR_A] + 1.0 / safe)

    def shifted(self, angle_shift: np.ndarray) -> AngleObservation:
        """The same observation of ``a + angle_shift`` expressed as one of ``a``.

        exp(-P (a + Δ)²/2 + I (a + Δ)) ∝ exp(-P a²/2 + (I - P Δ) a).
        """
        return AngleObservation(self.precision, self.information - self.precision * angle_shift,
                                self.restart)

    def apply(self, prior: np.ndarray) -> np.ndarray:
        """The (5, n) posterior of ``prior`` (restarted first when ``restart`` is set): angle
        marginals from the summed precision and information, the bias through eq. (16)."""
        if self.restart is not None:
            prior = self.restart.apply(prior)
        s_prior = prior[VAR_A]
        safe = s_prior > 0
        inv_s = np.where(safe, 1.0 / np.where(safe, s_prior, 1.0), 0.0)
        post_precision = inv_s + self.precision
        has_info = post_precision > 0
        var_post = np.where(has_info, 1.0 / np.where(has_info, post_precision, 1.0), s_prior)
        mean_post = np.where(
            has_info, var_post * (prior[MEAN_A] * inv_s + self.information), prior[MEAN_A])
        return recombine_with_bias(prior, mean_post, var_post)
