"""Render and score in one numba kernel: the image update's likelihood evaluations.

:func:`fused_scores` gives the same numbers as
``likelihood.log_likelihoods(images, observation, params)`` for the images that
:func:`~drake_tracker.core.rasterize.render_kernel` would render, without writing the
(N, H, W) images (or the body poses) to memory: per particle, forward kinematics to the
camera frame, then each thread renders the particle into its own z-buffer, then
collects the (pixel, depth) pairs of the robot pixels that have a valid observation,
visiting only the columns each row's triangles touched (and resetting them for the next
particle), and scores that list in a branch-free loop (:func:`pixel_log_ratios`).

The pixel term is that of :mod:`drake_tracker.core.likelihood` with two differences:
erfc is evaluated from a piecewise polynomial table (:func:`erfc_table`, absolute error
about 1e-15) on [-6, 9), its argument clamped to that range (where erfc rounds to 2, or
the occlusion term is below 1e-30 of the uniform term it is added to), and the pixel loop
is compiled with the fastmath flags :data:`SAFE_FASTMATH` (fused multiply-add,
reciprocal and approximate-function contractions; never the no-NaN / no-inf assumptions,
which break the test for an empty pixel). The sums agree with ``log_likelihoods`` to
about 1e-12 relative (tested).
"""

from __future__ import annotations

import math
import time

import numba
import numpy as np
from numba import njit, prange

from drake_tracker.core.kinematics import relative_poses_one
from drake_tracker.core.likelihood import PreparedObservation
from drake_tracker.core.numba_threading import SerialOrParallel, serial_and_parallel
from drake_tracker.core.rasterize import num_chunks, render_particle
from drake_tracker.core.vector_math import exp_inplace, log_inplace

#: LLVM fast-math flags proven harmless for the pixel loop: no signed zeros, reciprocal
#: instead of division, fused multiply-add, approximate libm functions. ``fastmath=True``
#: would add ``nnan``/``ninf``, under which ``d == inf`` tests are folded away.
SAFE_FASTMATH = {"nsz", "arcp", "contract", "afn"}

#: erfc table: [_ERFC_LO, _ERFC_HI) in pieces of width 1/_ERFC_PER_UNIT, each a
#: polynomial of degree _ERFC_DEGREE in t in [-1, 1] interpolating erfc at Chebyshev nodes.
_ERFC_LO, _ERFC_HI, _ERFC_PER_UNIT, _ERFC_DEGREE = -6.0, 9.0, 16, 9


def erfc_table() -> np.ndarray:
    """Monomial coefficients (pieces, degree + 1) of the piecewise interpolant of erfc
    used by the fused kernel (see :func:`pixel_log_ratios`)."""
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
#: Largest argument given to the table (just below its upper end).
_ERFC_TOP = _ERFC_HI - 1e-9


@njit(cache=True, fastmath=SAFE_FASTMATH)
def pixel_log_ratios(slots: np.ndarray, depths: np.ndarray, count: int, z: np.ndarray,
                     inv_sigma: np.ndarray, lam_sigma2: np.ndarray, gauss_coeff: np.ndarray,
                     occ_coeff: np.ndarray, log_p_occ_inf: np.ndarray, uniform: float,
                     lam: float, occlusion: float, truncation: float,
                     erfc_coeffs: np.ndarray, terms: np.ndarray, work: np.ndarray) -> None:
    """terms[i] = log(p(z_p | d_i) / p_occ(z_p | inf)) for p = slots[i], d_i = depths[i],
    i < count: every term computed, no branches, in passes over the arrays that LLVM
    vectorises (exp and log from :mod:`~drake_tracker.core.vector_math`). ``work``:
    float64 scratch (4, >= count)."""
    inv_sqrt2 = 1.0 / math.sqrt(2.0)
    visible = 1.0 - occlusion
    gauss = work[0]
    decay = work[1]
    occluded = work[2]
    scratch = work[3]
    for i in range(count):
        p = slots[i]
        d = depths[i]
        s = inv_sigma[p]
        dz = z[p] - d
        rr = dz * s
        gauss[i] = -0.5 * rr * rr
        decay[i] = -lam * d
        x = min(max((dz - lam_sigma2[p]) * (s * inv_sqrt2), _ERFC_LO), _ERFC_TOP)
        u = (x - _ERFC_LO) * _ERFC_PER_UNIT
        k = int(u)
        t = 2.0 * (u - k) - 1.0
        acc = erfc_coeffs[k, _ERFC_DEGREE]
        for j in range(_ERFC_DEGREE - 1, -1, -1):
            acc = acc * t + erfc_coeffs[k, j]
        occluded[i] = occ_coeff[p] * (0.5 * acc)
    exp_inplace(gauss, count, scratch)
    exp_inplace(decay, count, scratch)
    for i in range(count):
        p = slots[i]
        p_vis = uniform + gauss_coeff[p] * gauss[i]
        p_occ = uniform + occluded[i] / (1.0 - truncation * decay[i])
        terms[i] = visible * p_vis + occlusion * p_occ
    log_inplace(terms, count, scratch)
    for i in range(count):
        terms[i] -= log_p_occ_inf[slots[i]]


def _score_particles(q, kind, inboard, outboard, q_index, axis, A, B, rev, frame_body, X_BF,
                     vertices, triangles, part_body, part_vertex_start, part_tri_start,
                     sphere_center, sphere_radius, tri_normal, tri_offset, tri_closed,
                     planes, fx, fy, cx, cy, near, far, chunks, height, width,
                     pixel_slot, z, inv_sigma, lam_sigma2, gauss_coeff, occ_coeff,
                     log_p_occ_inf, uniform, lam, occlusion, truncation, erfc_coeffs, out):
    """FK, rasterising and scoring of each configuration q[n] into out[n], in ``chunks``
    contiguous chunks of particles (prange: parallel in the parallel compilation)."""
    N = q.shape[0]
    V = vertices.shape[0]
    nb = kind.shape[0] + 1  # one joint step per body but the world (all are connected)
    for chunk in prange(chunks):
        X = np.empty((nb, 4, 4))
        X_CB = np.empty((nb, 4, 4))
        T = np.empty((4, 4))
        M = np.empty((4, 4))
        P = np.empty((V, 3))
        UV = np.empty((V, 3))
        poly = np.empty((4, 3))
        rows = np.empty(2, dtype=np.int64)
        span = np.empty((height, 2), dtype=np.int64)
        span[:, 0] = width
        span[:, 1] = -1
        zbuf = np.zeros((height, width))  # inverse depths, 0: nothing drawn
        slots = np.empty(height * width, dtype=np.int64)
        depths = np.empty(height * width)
        terms = np.empty(height * width)
        work = np.empty((4, height * width))
        keep = np.empty(triangles.shape[0], dtype=np.int64)
        for n in range(chunk * N // chunks, (chunk + 1) * N // chunks):
            relative_poses_one(n, q, kind, inboard, outboard, q_index, axis, A, B, rev,
                               frame_body, X_BF, X, X_CB, T, M)
            rows[0] = height
            rows[1] = -1
            render_particle(zbuf, X_CB, vertices, triangles, part_body, part_vertex_start,
                            part_tri_start, sphere_center, sphere_radius, tri_normal,
                            tri_offset, tri_closed, planes, fx, fy, cx, cy, near, far,
                            P, UV, poly, rows, span, keep)
            count = 0
            for r in range(rows[0], rows[1] + 1):
                c_lo = span[r, 0]
                c_hi = span[r, 1]
                span[r, 0] = width
                span[r, 1] = -1
                base = r * width
                for c in range(c_lo, c_hi + 1):
                    iz = zbuf[r, c]
                    if iz == 0.0:
                        continue
                    zbuf[r, c] = 0.0
                    p = pixel_slot[base + c]
                    if p >= 0:
                        slots[count] = p
                        # the rendered image's float32 depth (see render_kernel)
                        depths[count] = np.float32(1.0 / iz)
                        count += 1
            pixel_log_ratios(slots, depths, count, z, inv_sigma, lam_sigma2, gauss_coeff,
                             occ_coeff, log_p_occ_inf, uniform, lam, occlusion, truncation,
                             erfc_coeffs, terms, work)
            total = 0.0
            for i in range(count):
                total += terms[i]
            out[n] = total


#: The same kernel compiled twice: serial (one thread: no threading layer, no thread
#: wake-ups, which cost milliseconds on a loaded machine) and parallel over chunks.
_score_serial, _score_parallel = serial_and_parallel(_score_particles)


def fused_scores(q: np.ndarray, frame_tables: tuple, render_tables: tuple,
                 frustum_planes: np.ndarray, projection: tuple[float, float, float, float],
                 near_m: float, far_m: float, observation: PreparedObservation,
                 policy: SerialOrParallel | None = None) -> np.ndarray:
    """(N,) log-likelihoods of configurations q (N, nq), C-contiguous and checked: forward
    kinematics to the camera frame (``frame_tables`` from
    :meth:`~drake_tracker.core.kinematics.BatchedKinematics.frame_tables`), rendering
    with ``render_tables`` (:func:`~drake_tracker.core.mesh_parts.render_tables`),
    ``frustum_planes`` and ``projection`` (fx, fy, cx, cy with the pixel-centre offset
    applied), and scoring, in one kernel call. Serial or parallel as ``policy`` chooses
    (default: parallel whenever numba has more than one thread)."""
    height, width = observation.shape
    N = q.shape[0]
    out = np.zeros(N)
    if N == 0 or observation.num_valid == 0:
        return out
    fx, fy, cx, cy = projection
    o = observation
    chunks = num_chunks(N)
    if policy is None:
        parallel = numba.get_num_threads() > 1
    else:
        parallel = policy.use_parallel()
    if chunks == 1:
        parallel = False
    kernel = _score_parallel if parallel else _score_serial
    t0 = time.perf_counter()
    kernel(q, *frame_tables, *render_tables, frustum_planes, fx, fy, cx, cy, near_m, far_m,
           chunks if parallel else 1, height, width, o.pixel_slot, o.z, o.inv_sigma,
           o.lam_sigma2, o.gauss_coeff, o.occ_coeff, o.log_p_occ_inf, o.uniform,
           o.occluder_rate_per_m, o.occlusion_probability, o.truncation, _ERFC_COEFFS, out)
    if policy is not None:
        policy.record(parallel, time.perf_counter() - t0, N)
    return out
