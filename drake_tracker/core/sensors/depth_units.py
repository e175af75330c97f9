"""Is a float depth image in metres? The check that turns a millimetre image, which the
likelihood would otherwise see as all beyond its range, into a clear error."""

from __future__ import annotations

import numpy as np

#: A float depth image whose valid pixels have a median depth above this (m) is taken to
#: be in other units: no depth camera the tracker is used with sees that far, and a
#: millimetre image of a scene 0.5-5 m away has a median of 500-5000.
MAX_PLAUSIBLE_MEDIAN_DEPTH_M = 20.0


def depth_units_problem(depth_m: np.ndarray) -> str | None:
    """Why ``depth_m`` (H, W, float) cannot be depths in metres, or None when it can:
    negative depths, or a median of the valid (finite, > 0) pixels above
    ``MAX_PLAUSIBLE_MEDIAN_DEPTH_M``. An image without a valid pixel is not a units
    problem (it is skipped downstream)."""
    depth = np.asarray(depth_m)
    with np.errstate(invalid="ignore"):
        negative = int(np.count_nonzero(depth < 0))
        if negative:
            return (f"{negative} pixels have a negative depth; depths are metres along the "
                    f"optical axis (NaN, 0 or +inf for no return)")
        sample = depth[::4, ::4]  # the median of a 1-in-16 sample is plenty here
        valid = sample[np.isfinite(sample) & (sample > 0)]
    if valid.size == 0:
        return None
    median = float(np.median(valid))
    if median > MAX_PLAUSIBLE_MEDIAN_DEPTH_M:
        return (f"the median depth of its valid pixels is {median:.1f}, implausible as "
                f"metres (limit {MAX_PLAUSIBLE_MEDIAN_DEPTH_M:.0f} m): is the image in "
                f"millimetres? Convert it with depth_to_metres(pixels, '16U_mm') or "
                f"multiply by 0.001")
    return None


def check_depth_units(depth_m: np.ndarray) -> None:
    """Raises ValueError naming the problem of :func:`depth_units_problem`."""
    problem = depth_units_problem(depth_m)
    if problem is not None:
        raise ValueError(f"depth image: {problem}")
