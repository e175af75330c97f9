"""The bias process noise, matched to the images' innovations (covariance matching).

The paper's bias is a random walk of a fixed rate σb (eq. 5). A bias that drifts faster
than that is followed at the pace of σb: each image's prior is too narrow to reach it.
Here each joint's bias variance rate ``q = σb²`` (rad²/s) follows what the images show,
by matching the innovations' variance to the one the model predicts (Mehra 1972;
Myers and Tapley 1976), one joint at a time.

An applied image observes joint j's angle as ``z ~ N(a, R)`` (the observation in
information form: ``R = 1 / precision``, ``z = information / precision``) against the
prior ``N(mu, s)`` at its anchor. With the model's rate ``q``, the innovation
``nu = z - mu`` has variance ``S = s + R``; the encoders pin ``a + b``, so the prior's
angle variance grew by the bias's ``q dt`` since the previous image, ``dt`` earlier. If
the true rate is ``q*``, ``E[nu²] = S + (q* - q) dt``, so each image gives the estimate

    q_k = q + (min(nu², 9 S) - S) / dt                                    (1)

(``nu²`` clipped at three standard deviations, so that one wrong image moves ``q`` by at
most 8 S / dt), and the rate used is their exponential average over
:data:`MATCHING_IMAGES` images,

    q <- clip(q + (q_k - q) / MATCHING_IMAGES, q_min, q_max)             (2)

with ``q_min`` the configured σb² (the model never trusts the bias more than it was told
to) and ``q_max`` the variance of the start's bias prior per second (a bias that moved
by its whole prior range within a second is a jump, not a drift: the jump model of the
image update follows those). Only robot joints with a bias adapt; the virtual camera
joints keep their σb (a drift of the arm must not be explained by a moving camera). A
joint's innovation counts only where the image says at least as much as the prior
(``R <= s``): where it says little, the shift of the CPF's mean is mostly its
Monte-Carlo error (about ``s / N_eff``), which ``R`` does not hold and which would read
as a drift. Off by default (``JointNoise.match_bias_noise_to_images``).

The rate is learnt in the order the images are applied: an image older than the latest
applied one (out of order) informs no rate, so the buffer's exactness for out-of-order
images (the same belief as the observations inserted in time order) holds for the
observations at given rates, not for the rates themselves.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from drake_tracker.core.filter.angle_observation import AngleObservation

#: Images the rate's exponential average spans (eq. 2): 2 s at 10 images/s. One image's
#: squared innovation is a chi-square of one degree of freedom (relative standard
#: deviation 1.4); averaged over 20 it is known to 30 %.
MATCHING_IMAGES = 20
#: The innovation's clip in variances of its prediction (eq. 1): three sigma.
INNOVATION_CLIP_VARIANCES = 9.0


@dataclass(frozen=True)
class BiasNoiseMatch:
    """Each joint's bias variance rate (rad²/s), matched to the images' innovations.

    ``rate_var`` (n,) is the rate the Kalman bank uses; ``min_var``/``max_var`` (n,)
    bound it (eq. 2); ``adapts`` (n,) marks the joints that adapt (elsewhere the rate
    stays ``min_var``); ``last_image_s`` is the previous applied image's anchor time.
    """

    rate_var: np.ndarray
    min_var: np.ndarray
    max_var: np.ndarray
    adapts: np.ndarray
    last_image_s: float = -np.inf

    @staticmethod
    def start(min_var: np.ndarray, max_var: np.ndarray, adapts: np.ndarray) -> BiasNoiseMatch:
        """The match at the start: every rate at its configured ``min_var``."""
        min_var = np.asarray(min_var, float)
        max_var = np.maximum(np.asarray(max_var, float), min_var)
        return BiasNoiseMatch(min_var.copy(), min_var, max_var, np.asarray(adapts, bool))

    def after_image(self, t: float, prior: np.ndarray,
                    observation: AngleObservation) -> BiasNoiseMatch:
        """The match after an image observed at ``t`` (its anchor) against ``prior``
        (5, n) there. An image before the previous one (out of order), the first image,
        a restart and an observation that does not ``informs_bias_noise`` only move
        ``last_image_s``; joints the image did not observe (zero precision) keep their
        rate."""
        dt = t - self.last_image_s
        if not (np.isfinite(dt) and dt > 0) or observation.restart is not None \
                or not observation.informs_bias_noise:
            return replace(self, last_image_s=max(t, self.last_image_s))
        # A joint counts where the image says at least as much as the prior (R <= s,
        # ``AngleObservation.innovation``): where it says little, the shift of the CPF's
        # mean would read as a drift.
        informs, nu, innovation_var = observation.innovation(prior)  # S = s + R
        seen = self.adapts & informs
        if not seen.any():
            return replace(self, last_image_s=t)
        nu2 = np.minimum(nu ** 2, INNOVATION_CLIP_VARIANCES * innovation_var)
        estimate = self.rate_var + (nu2 - innovation_var) / dt  # eq. (1)
        averaged = self.rate_var + (estimate - self.rate_var) / MATCHING_IMAGES  # eq. (2)
        rate = np.where(seen, np.clip(averaged, self.min_var, self.max_var), self.rate_var)
        return replace(self, rate_var=rate, last_image_s=t)
