"""Each image's occlusion, estimated from the image at the belief's mean (paper §III: the
occlusion is estimated per image, not carried over time).

The pixel model mixes a visible and an occluded term with an occlusion probability o. A
fixed o (0.1) says that a robot pixel hidden behind something is a 1-in-10 event, so
every hidden pixel costs log(o) ≈ -2.3 nats against a pixel where nothing is rendered
(0): when an occluder covers most of the arm, configurations that fold the arm or move
it out of the occluded region score far better than the truth, and each image drags the
estimate away (measured: a 41.9 mm prior error became 124 mm on an image hiding 78 % of
the arm). Here o is estimated per pixel from the robot rendered at the prior mean:

* a robot pixel that the image shows well in front of the robot (by
  ``OCCLUDER_MIN_GAP_M``), and the pixels of the same surface next to it, are occluded
  with probability ``OCCLUDED_PIXEL_PROBABILITY``: they say nothing about the robot;
* every other pixel gets the image's occlusion fraction: the posterior mean of a Beta
  prior (mean ``likelihood.occlusion_probability``, weight ``prior_pixels``) given the
  occluded share of the robot's pixels.

A per-pixel o is folded into the prepared per-pixel constants, so the scoring kernels
are unchanged: ``(1-o) p_vis + o p_occ = u + (1-o) g + o c`` is the kernel's
``½ (u + g') + ½ (u + c')`` with ``g' = 2 (1-o) g`` and ``c' = 2 o c``.
"""

import dataclasses

import numpy as np
from numba import njit

from drake_tracker.core.likelihood.pixel_model import LikelihoodParams, PreparedObservation
from drake_tracker.core.robustness.health import ImageConsistency

#: Occlusion probability of a pixel where the image shows something in front of the robot
#: (at the prior mean), or of the same surface next to one. Such a pixel says nothing about
#: the robot: o -> 1 makes its score the same for every configuration. With 0.9, a
#: configuration that put the arm *onto* the occluder's surface gained log(0.1 N(z; z)) ≈ +3.7
#: nats per pixel, and on occlusion-heavy the arm was pulled onto the box (135-400 mm, and
#: no recovery after the box left); with 0.999, 17-115 mm and back to 3 mm.
OCCLUDED_PIXEL_PROBABILITY = 0.999
#: An occluder is a surface: a pixel next to an occluded one whose depth differs from it by
#: less than this is the same occluder (m) ...
OCCLUDER_SURFACE_STEP_M = 0.03
#: ... up to this many pixels (at the processing resolution) outside the robot's pixels.
#: Only a surface that reaches this far out is an occluder: one that ends sooner, hugging
#: the robot's outline, may be the robot itself, moved towards the camera by a bias the
#: prior has not caught up with (on s-head-arm, a 10 deg bias step brought the true arm
#: 2-5 cm in front of the estimate; written off as an occluder, it was never followed:
#: 0.6 m). Those pixels keep ``NEAR_PIXEL_OCCLUSION_PROBABILITY``.
OCCLUDER_GROWTH_PX = 6
#: Occlusion probability of a hidden pixel whose surface does not reach beyond the robot.
NEAR_PIXEL_OCCLUSION_PROBABILITY = 0.9
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
    rendered_m = np.asarray(rendered_m, float)
    d = rendered_m.ravel()[observation.pixel_index]
    hidden = np.isfinite(d) & (observation.z < d - 3.0 * observation.sigma)
    mask = np.zeros(int(np.prod(observation.shape)), bool)
    mask[observation.pixel_index] = hidden
    mask = mask.reshape(observation.shape)
    outside = ~np.isfinite(rendered_m)
    image = observed_image(observation)
    steps = surface_steps(mask, image, outside, OCCLUDER_SURFACE_STEP_M, OCCLUDER_GROWTH_PX)
    grown = steps >= 0
    # The surfaces that reached OCCLUDER_GROWTH_PX out, traced back through the grown mask.
    far = steps == OCCLUDER_GROWTH_PX
    occluder = grow_surface(far, image, grown, np.inf, grown.size)
    occluder = occluder.ravel()[observation.pixel_index]
    return np.where(occluder, OCCLUDED_PIXEL_PROBABILITY,
                    np.where(hidden, NEAR_PIXEL_OCCLUSION_PROBABILITY, image_fraction))


def grow_surface(seed: np.ndarray, depth_m: np.ndarray, allowed: np.ndarray,
                 max_step_m: float, steps: int) -> np.ndarray:
    """``seed`` (H, W bool) grown ``steps`` times into 4-neighbours that are ``allowed``,
    valid in ``depth_m`` (NaN: invalid) and within ``max_step_m`` of the neighbour they
    are reached from: the rest of a surface that the seed pixels lie on."""
    return surface_steps(seed, depth_m, allowed, max_step_m, steps) >= 0


def surface_steps(seed: np.ndarray, depth_m: np.ndarray, allowed: np.ndarray,
                  max_step_m: float, steps: int) -> np.ndarray:
    """(H, W) int: the growth step at which :func:`grow_surface` reaches each pixel (0 for
    the seed, -1 where it does not). A breadth-first growth, layer by layer, compiled
    (``_surface_steps``; tested against a pixel-by-pixel reference)."""
    seed = np.asarray(seed, bool)
    depth_m = np.asarray(depth_m, float)
    allowed = np.asarray(allowed, bool)
    if seed.ndim != 2 or depth_m.shape != seed.shape or allowed.shape != seed.shape:
        raise ValueError(f"seed, depth_m and allowed must be one (H, W) shape, got "
                         f"{seed.shape}, {depth_m.shape} and {allowed.shape}")
    if not max_step_m > 0 or int(steps) < 0:
        raise ValueError(f"max_step_m must be > 0 and steps >= 0, got {max_step_m} and "
                         f"{steps}")
    return _surface_steps(np.ascontiguousarray(seed), np.ascontiguousarray(depth_m),
                          np.ascontiguousarray(allowed), float(max_step_m), int(steps))


@njit(cache=True, nogil=True)
def _surface_steps(seed, depth_m, allowed, max_step_m, steps):
    h, w = seed.shape
    reached = np.full((h, w), -1, np.int64)
    frontier = np.empty(h * w, np.int64)
    count = 0
    for i in range(h):
        for j in range(w):
            if seed[i, j]:
                reached[i, j] = 0
                frontier[count] = i * w + j
                count += 1
    added = np.empty(h * w, np.int64)
    for step in range(1, steps + 1):
        new = 0
        for k in range(count):
            i, j = divmod(frontier[k], w)
            zq = depth_m[i, j]  # NaN (invalid) is never within a step of anything
            for a, b in ((i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)):
                if 0 <= a < h and 0 <= b < w and reached[a, b] < 0 and allowed[a, b]:
                    zp = depth_m[a, b]
                    if np.isfinite(zp) and abs(zp - zq) < max_step_m:
                        reached[a, b] = step
                        added[new] = a * w + b
                        new += 1
        if new == 0:
            break
        frontier, added = added, frontier
        count = new
    return reached


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

