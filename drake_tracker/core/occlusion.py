"""Each image's occlusion, estimated from the image at the belief's mean (paper §III: the
occlusion is estimated per image, not carried over time).

The pixel model mixes a visible and an occluded term with an occlusion probability o. A
fixed o (0.1) says that a robot pixel hidden behind something is a 1-in-10 event, so
every hidden pixel costs log(o) ≈ -2.3 nats against a pixel where nothing is rendered
(0): when an occluder covers most of the arm, configurations that fold the arm or move
it out of the occluded region score far better than the truth, and each image drags the
estimate away (measured: a 41.9 mm prior error became 124 mm on an image hiding 78 % of
the arm). Here o is estimated per pixel from the robot rendered at the prior mean:

* a robot pixel that the image shows nearer than the robot (by 3σ) is occluded with
  probability ``OCCLUDED_PIXEL_PROBABILITY``;
* every other pixel gets the image's occlusion fraction: the posterior mean of a Beta
  prior (mean ``likelihood.occlusion_probability``, weight ``prior_pixels``) given the
  occluded share of the robot's pixels.

A per-pixel o is folded into the prepared per-pixel constants, so the scoring kernels
are unchanged: ``(1-o) p_vis + o p_occ = u + (1-o) g + o c`` is the kernel's
``½ (u + g') + ½ (u + c')`` with ``g' = 2 (1-o) g`` and ``c' = 2 o c``.
"""

import dataclasses

import numpy as np

from drake_tracker.core.health import ImageConsistency
from drake_tracker.core.likelihood import LikelihoodParams, PreparedObservation

#: Occlusion probability of a pixel where the image shows something in front of the robot.
OCCLUDED_PIXEL_PROBABILITY = 0.9
#: Bounds of an image's occlusion fraction.
MIN_OCCLUSION_PROBABILITY, MAX_OCCLUSION_PROBABILITY = 0.01, 0.95


def image_occlusion(seen: ImageConsistency, params: LikelihoodParams,
                    prior_pixels: float) -> float:
    """The image's occlusion fraction given ``seen`` (the image against the robot
    rendered at the prior mean): a Beta posterior mean."""
    o_prior = params.occlusion_probability
    hidden = seen.occluded * seen.robot_pixels
    estimate = (o_prior * prior_pixels + hidden) / (prior_pixels + seen.robot_pixels)
    return float(np.clip(estimate, MIN_OCCLUSION_PROBABILITY, MAX_OCCLUSION_PROBABILITY))


def pixel_occlusion(observation: PreparedObservation, rendered_m: np.ndarray,
                    image_fraction: float) -> np.ndarray:
    """(P,) occlusion probability of each valid pixel of ``observation``, given the robot
    rendered at the prior mean (H, W; inf where no robot)."""
    d = np.asarray(rendered_m, float).ravel()[observation.pixel_index]
    hidden = np.isfinite(d) & (observation.z < d - 3.0 * observation.sigma)
    return np.where(hidden, OCCLUDED_PIXEL_PROBABILITY, image_fraction)


def with_pixel_occlusion(observation: PreparedObservation,
                         occlusion: np.ndarray) -> PreparedObservation:
    """``observation`` scored with a per-pixel occlusion probability (P,)."""
    occlusion = np.asarray(occlusion, float)
    if occlusion.shape != observation.z.shape or np.any((occlusion < 0) | (occlusion >= 1)):
        raise ValueError("per-pixel occlusion probabilities must be in [0, 1), one per pixel")
    return dataclasses.replace(
        observation, gauss_coeff=2.0 * (1.0 - occlusion) * observation.gauss_coeff,
        occ_coeff=2.0 * occlusion * observation.occ_coeff, occlusion_probability=0.5)


def observed_image(observation: PreparedObservation) -> np.ndarray:
    """The prepared observation back as an (H, W) image (NaN: invalid)."""
    image = np.full(int(np.prod(observation.shape)), np.nan)
    image[observation.pixel_index] = observation.z
    return image.reshape(observation.shape)

