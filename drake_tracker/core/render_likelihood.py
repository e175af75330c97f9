"""Render and score in one numba kernel: the image update's likelihood evaluations.

:func:`fused_log_likelihoods` gives the same numbers as
``likelihood.log_likelihoods(renderer.render(q), observation, params)`` without ever
writing the (N, H, W) images to memory: each thread renders a particle into its own
z-buffer, sums the pixel log-ratios over the rectangle the particle's triangles can
cover, and resets that rectangle for its next particle.

The pixel term is the one of :mod:`drake_tracker.core.likelihood`, evaluated with the same
floating point operations, except that terms too small to change a sum are not computed:
``gauss_coeff * exp(-r²/2)`` and ``occ_coeff * Φ / (1 - e^{-λd})`` are skipped when they
are below 2^-60 times the uniform term they are added to (so adding them would round to
the same double), and Φ is taken as exactly 1 where erfc rounds to 2. On [-6, 9], erfc
is evaluated from a piecewise polynomial table (:func:`erfc_table`, absolute error about
1e-15, 2-3x faster than libm's erfc), so the sums agree with ``log_likelihoods`` to about
1e-13 relative rather than bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from drake_tracker.core.likelihood import LikelihoodParams, PreparedObservation
from drake_tracker.core.render_batched import BatchedDepthRenderer, _num_chunks, _render_one

_NEGLIGIBLE = 2.0**-60

#: erfc table: [_ERFC_LO, _ERFC_HI) in pieces of width 1/_ERFC_PER_UNIT, each a
#: polynomial of degree _ERFC_DEGREE in t in [-1, 1] interpolating erfc at Chebyshev nodes.
_ERFC_LO, _ERFC_HI, _ERFC_PER_UNIT, _ERFC_DEGREE = -6.0, 9.0, 16, 9


def erfc_table() -> np.ndarray:
    """Monomial coefficients (pieces, degree + 1) of the piecewise interpolant of erfc
    used by the fused kernel (see :func:`_erfc`)."""
    pieces = int(round((_ERFC_HI - _ERFC_LO) * _ERFC_PER_UNIT))
    k = np.arange(_ERFC_DEGREE + 1)
    nodes = np.cos(np.pi * (k + 0.5) / (_ERFC_DEGREE + 1))
    vander = np.vander(nodes, _ERFC_DEGREE + 1, increasing=True)
    coeffs = np.empty((pieces, _ERFC_DEGREE + 1))
    for i in range(pieces):
        x = _ERFC_LO + (i + 0.5 * (nodes + 1.0)) / _ERFC_PER_UNIT
        coeffs[i] = np.linalg.solve(vander, [math.erfc(v) for v in x])
    return coeffs


_ERFC_COEFFS = erfc_table()


@njit(cache=True, inline="always")
def _erfc(x, coeffs):
    """erfc(x): from the table on [_ERFC_LO, _ERFC_HI), else libm."""
    if x < _ERFC_LO or x >= _ERFC_HI:
        return math.erfc(x)
    u = (x - _ERFC_LO) * _ERFC_PER_UNIT
    i = int(u)
    t = 2.0 * (u - i) - 1.0
    acc = coeffs[i, _ERFC_DEGREE]
    for j in range(_ERFC_DEGREE - 1, -1, -1):
        acc = acc * t + coeffs[i, j]
    return acc


@njit(parallel=True, cache=True)
def _fused_kernel(X_CB, vertices, triangles, body_vertex_start, body_tri_start,
                  sphere_center, sphere_radius, tri_normal, tri_offset, tri_closed,
                  planes, fx, fy, cx, cy, near, far, num_chunks, height, width,
                  pixel_slot, z, inv_sigma, lam_sigma2, gauss_coeff, occ_coeff,
                  log_p_occ_inf, uniform, lam, occlusion, gauss_skip, erfc_skip,
                  erfc_coeffs, out):
    N = X_CB.shape[0]
    V = vertices.shape[0]
    inv_sqrt2 = 1.0 / math.sqrt(2.0)
    log_uniform = math.log((1.0 - occlusion) * uniform + occlusion * uniform)
    for chunk in prange(num_chunks):
        P = np.empty((V, 3))
        UV = np.empty((V, 3))
        poly = np.empty((4, 3))
        bbox = np.empty(4, dtype=np.int64)
        zbuf = np.full((height, width), np.inf, dtype=np.float32)
        for n in range(chunk * N // num_chunks, (chunk + 1) * N // num_chunks):
            bbox[0] = height
            bbox[1] = -1
            bbox[2] = width
            bbox[3] = -1
            _render_one(zbuf, X_CB[n], vertices, triangles, body_vertex_start,
                        body_tri_start, sphere_center, sphere_radius, tri_normal,
                        tri_offset, tri_closed, planes, fx, fy, cx, cy, near, far,
                        P, UV, poly, bbox)
            total = 0.0
            for r in range(bbox[0], bbox[1] + 1):
                for c in range(bbox[2], bbox[3] + 1):
                    d = zbuf[r, c]
                    if d == np.inf:
                        continue
                    zbuf[r, c] = np.inf
                    p = pixel_slot[r * width + c]
                    if p < 0:
                        continue
                    dz = z[p] - d
                    rr = dz * inv_sigma[p]
                    if 0.5 * rr * rr > gauss_skip:
                        p_vis = uniform
                    else:
                        p_vis = uniform + gauss_coeff[p] * math.exp(-0.5 * rr * rr)
                    x = (dz - lam_sigma2[p]) * (inv_sigma[p] * inv_sqrt2)
                    if x > erfc_skip:
                        if p_vis == uniform:
                            total += log_uniform - log_p_occ_inf[p]
                            continue
                        p_occ = uniform
                    else:
                        phi = 1.0 if x < -6.0 else 0.5 * _erfc(x, erfc_coeffs)
                        p_occ = uniform + occ_coeff[p] * phi / (1.0 - math.exp(-lam * d))
                    total += (math.log((1.0 - occlusion) * p_vis + occlusion * p_occ)
                              - log_p_occ_inf[p])
            out[n] = total


def _skip_thresholds(observation: PreparedObservation, params: LikelihoodParams,
                     near_m: float) -> tuple[float, float]:
    """(g, x): for r²/2 > g the Gaussian term, and for erfc arguments x' > x the occlusion
    term, are below 2^-60 times the uniform term for every pixel and every rendered depth
    >= near_m, so skipping them leaves every sum bit for bit unchanged."""
    uniform = params.tail_weight / params.max_depth_m
    tiny = uniform * _NEGLIGIBLE
    gauss_skip = math.log(float(np.max(observation.gauss_coeff)) / tiny)
    # Rendered depths are >= near (up to 1e-9 relative); 1/(1 - e^{-λd}) is largest there.
    d_min = 0.5 * near_m
    factor = float(np.max(observation.occ_coeff)) / -math.expm1(
        -params.occluder_rate_per_m * d_min)
    x = 1.0
    while 0.5 * math.erfc(x) * factor >= tiny:
        x += 0.5
        if x > 27.0:  # erfc underflows to 0 beyond ~26.6
            break
    return max(gauss_skip, 0.0), x


def fused_log_likelihoods(renderer: BatchedDepthRenderer, q: np.ndarray,
                          observation: PreparedObservation,
                          params: LikelihoodParams) -> np.ndarray:
    """(N,) log-likelihoods of configurations q (N, nq): FK, render and score in one pass.

    Equal to ``log_likelihoods(renderer.render(q), observation, params)`` (to ~1e-13
    relative).
    """
    k = renderer.intrinsics
    if tuple(observation.shape) != (k.height, k.width):
        raise ValueError(f"observation has shape {tuple(observation.shape)}, the renderer "
                         f"renders ({k.height}, {k.width})")
    X_CB = renderer.kinematics.relative_poses(q, renderer.model.camera_frame)
    N = X_CB.shape[0]
    out = np.zeros(N)
    if N == 0 or observation.num_valid == 0:
        return out
    slot = np.full(k.height * k.width, -1, dtype=np.int64)
    slot[np.asarray(observation.pixel_index, dtype=np.int64)] = np.arange(observation.num_valid)
    gauss_skip, erfc_skip = _skip_thresholds(observation, params, renderer.near_m)

    def f64(a):
        return np.ascontiguousarray(a, dtype=np.float64)

    _fused_kernel(X_CB, *renderer._tables, renderer._planes, renderer._fx, renderer._fy,
                  renderer._cx, renderer._cy, renderer.near_m, renderer.far_m,
                  _num_chunks(N), k.height, k.width, slot, f64(observation.z),
                  1.0 / f64(observation.sigma),
                  float(params.occluder_rate_per_m) * f64(observation.sigma) ** 2,
                  f64(observation.gauss_coeff),
                  f64(observation.occ_coeff), f64(observation.log_p_occ_inf),
                  params.tail_weight / params.max_depth_m, float(params.occluder_rate_per_m),
                  float(params.occlusion_probability), gauss_skip, erfc_skip, _ERFC_COEFFS,
                  out)
    return out
