"""Which joints' bias jumps an image can test: how many of its pixels a jump would change.

A bias jump of joint j moves the bodies outboard of j by ``jump_std`` (either way). The
image can tell such a jump from no jump only through the pixels where that move changes
the rendered depth *and* the image sees the robot rather than something in front of it.
Where there are too few such pixels (the bodies are out of view, hidden, or too small),
the likelihood is flat in that joint and a jump there is chosen by Monte-Carlo noise.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from drake_tracker.core.likelihood.pixel_model import LikelihoodParams, pixel_sigma, valid_pixels

if TYPE_CHECKING:
    from drake_tracker.core.render.backends import RenderThenScore
    from drake_tracker.core.render.batched import BatchedDepthRenderer


def changed_visible_pixels(base_m: np.ndarray, moved_m: np.ndarray, observed_m: np.ndarray,
                           params: LikelihoodParams, occluders: bool = True) -> np.ndarray:
    """(N,) counts of the valid pixels where ``moved_m`` (N, H, W) differs from ``base_m``
    (H, W) by more than 3σ of the pixel noise (robot on one side only counts as a change);
    with ``occluders``, only those whose observed depth is not nearer than the nearer of
    the two renderings by more than 3σ (an occluder in front hides the change). Depths:
    inf where no robot. Compiled (``_changed_counts``; tested against the whole-image
    numpy form)."""
    base = np.asarray(base_m, float)
    moved = np.asarray(moved_m, float)
    observed = np.asarray(observed_m, float)
    if base.ndim != 2 or observed.shape != base.shape or moved.shape[1:] != base.shape:
        raise ValueError(f"base_m and observed_m must be (H, W) and moved_m (N, H, W) of one "
                         f"image size, got {base.shape}, {observed.shape} and {moved.shape}")
    valid = valid_pixels(observed, params)
    z = np.where(valid, observed, 1.0)
    sigma3 = 3.0 * pixel_sigma(z, params)
    return _changed_counts(np.ascontiguousarray(base), np.ascontiguousarray(moved),
                           np.ascontiguousarray(z), np.ascontiguousarray(sigma3), valid,
                           bool(occluders))


@njit(cache=True, nogil=True)
def _changed_counts(base, moved, z, sigma3, valid, occluders):
    counts = np.zeros(moved.shape[0], np.int64)
    for n in range(moved.shape[0]):
        for i in range(base.shape[0]):
            for j in range(base.shape[1]):
                if not valid[i, j]:
                    continue
                b, m, s = base[i, j], moved[n, i, j], sigma3[i, j]
                finite_b, finite_m = np.isfinite(b), np.isfinite(m)
                differ = finite_b != finite_m or (finite_b and finite_m and abs(b - m) > s)
                if not differ:
                    continue
                if occluders:  # np.minimum: NaN if either is NaN
                    nearer = np.nan if (b != b or m != m) else min(b, m)
                    if not z[i, j] >= nearer - s:
                        continue
                counts[n] += 1
    return counts


def jump_testable(renderer: BatchedDepthRenderer | RenderThenScore, mean: np.ndarray,
                  joints: np.ndarray, step: np.ndarray,
                  base_m: np.ndarray, observed_m: np.ndarray, params: LikelihoodParams,
                  min_pixels: int, occluders: bool = True) -> np.ndarray:
    """(len(joints),) whether the image shows at least ``min_pixels`` changed pixels (see
    ``changed_visible_pixels``) for a move of each joint by +``step`` or -``step`` (its
    jump's standard deviation) from ``mean``, the belief's angles; ``base_m``: the
    rendering at ``mean``. ``occluders``: whether an image nearer than the rendering is
    taken for an occluder; pass False when the image contradicts the belief (after a bias
    step the true arm in front of the belief's is no occluder)."""
    joints = np.asarray(joints, int)
    testable = np.zeros(joints.size, bool)
    untested = np.arange(joints.size)
    # +step first; -step rendered only for the joints +step did not show (the same
    # answer as rendering both, for about half the renders: the gate is the largest
    # fixed cost of the per-image decision).
    for sign in (1.0, -1.0):
        if untested.size == 0:
            break
        q = np.repeat(np.asarray(mean, float)[None], untested.size, axis=0)
        moved = joints[untested]
        q[np.arange(untested.size), moved] += sign * step[moved]
        counts = changed_visible_pixels(base_m, renderer.render(q), observed_m, params,
                                        occluders)
        testable[untested] = counts >= min_pixels
        untested = untested[counts < min_pixels]
    return testable
