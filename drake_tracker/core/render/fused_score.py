"""Forward kinematics, rendering and scoring in one numba kernel: the image update's
likelihood evaluations.

:func:`fused_scores` gives the same numbers as
``likelihood.log_likelihoods(images, observation, params)`` for the images that
:func:`~drake_tracker.core.render.rasterize.render_kernel` would render (the images bit for bit;
the pixel terms in float32, within
:data:`~drake_tracker.core.simd.lane_likelihood.SCORE_ATOL_PER_PIXEL` per pixel, tested),
without writing the (N, H, W) images to memory. The particles go
through in batches of :data:`~drake_tracker.core.simd.lanes.LANES`: forward kinematics per
particle (8 at a time), then one pass of :func:`~drake_tracker.core.simd.lane_render.render_lanes`
and
:func:`~drake_tracker.core.simd.lane_render.score_pixels` for the whole batch (SIMD across
the batch's particles: they are nearly the same configuration, so they share the
triangles and pixels to visit).
"""

from __future__ import annotations

import time

import numba
import numpy as np
from numba import prange

from drake_tracker.core.jit.numba_threading import (
    SerialOrParallel,
    parallel_allowed,
    serial_and_parallel,
)
from drake_tracker.core.likelihood.pixel_model import PreparedObservation
from drake_tracker.core.simd.lane_kinematics import lane_relative_poses
from drake_tracker.core.simd.lane_likelihood import PIXELS_PER_CALL
from drake_tracker.core.simd.lane_render import lane_scratch, render_lanes, score_pixels
from drake_tracker.core.simd.lanes import LANES


def kernel_workspace(chunks: int, num_bodies: int, num_vertices: int, height: int,
                     width: int) -> tuple:
    """Scratch of the scoring kernel for ``chunks`` chunks, made once and kept between
    calls: each chunk's z-buffer (H*W*LANES inverse depths and LANES zeros past them)
    is all zeros and its spans empty between calls (the kernel clears what it drew)."""
    zb = np.zeros((chunks, height * width * LANES + LANES))
    span = np.empty((chunks, height, 2), dtype=np.int64)
    span[:, :, 0] = width
    span[:, :, 1] = -1
    lanes = [lane_scratch(num_vertices) for _ in range(chunks)]
    stacked = tuple(np.stack([scratch[k] for scratch in lanes]) for k in range(len(lanes[0])))
    return (zb, span, np.empty((chunks, num_bodies * 12 * LANES)),
            np.empty((chunks, 3 * 12 * LANES)), np.empty((chunks, num_bodies, 12, LANES)),
            np.empty((chunks, height * width + PIXELS_PER_CALL), np.int64),
            np.empty((chunks, height * width + PIXELS_PER_CALL), np.int64),
            np.empty((chunks, 2), np.int64), np.zeros((chunks, LANES)), stacked)


def _score_particles(q, kind, inboard, outboard, q_index, axis, A, B, rev, frame_body, X_BF,
                     vertices, triangles, part_body, part_vertex_start, part_tri_start,
                     sphere_center, sphere_radius, tri_planes, tri_closed, planes, fx, fy,
                     cx, cy, near, far, chunks, height, width, pixel_slot, table, uniform,
                     lam, occlusion, truncation, workspace, out):
    """FK, rendering and scoring of each configuration q[n] into out[n], in ``chunks``
    contiguous chunks of LANES-particle batches (prange: parallel in the parallel
    compilation), each with its scratch from ``workspace`` (:func:`kernel_workspace`).
    A batch short of LANES particles repeats its last one. Forward kinematics is
    :func:`~drake_tracker.core.simd.lane_kinematics.lane_relative_poses`, the poses of
    :func:`~drake_tracker.core.render.kinematics.relative_poses_one` bit for bit."""
    N = q.shape[0]
    batches = (N + LANES - 1) // LANES
    zbs, spans, worlds, works, all_poses, all_offsets, all_pixels, all_rows, accs, lanes = (
        workspace)
    for chunk in prange(chunks):
        zb = zbs[chunk]
        span = spans[chunk]
        world = worlds[chunk]
        work = works[chunk]
        poses = all_poses[chunk]
        offsets = all_offsets[chunk]
        pixels = all_pixels[chunk]
        rows = all_rows[chunk]
        acc = accs[chunk]
        scratch = (lanes[0][chunk], lanes[1][chunk], lanes[2][chunk], lanes[3][chunk],
                   lanes[4][chunk], lanes[5][chunk], lanes[6][chunk], lanes[7][chunk],
                   lanes[8][chunk], lanes[9][chunk], lanes[10][chunk], lanes[11][chunk])
        for batch in range(chunk * batches // chunks, (chunk + 1) * batches // chunks):
            first = batch * LANES
            lane_relative_poses(q, first, min(LANES, N - first), kind, inboard, outboard,
                                q_index, axis, A, B, rev, frame_body, X_BF, world, poses,
                                work)
            rows[0] = height
            rows[1] = -1
            render_lanes(zb, height, width, poses, vertices, triangles, part_body,
                         part_vertex_start, part_tri_start, sphere_center, sphere_radius,
                         tri_planes, tri_closed, planes, fx, fy, cx, cy, near, far, scratch,
                         rows, span)
            acc[:] = 0.0
            score_pixels(zb, width, rows, span, pixel_slot, table, uniform, lam, occlusion,
                         truncation, offsets, pixels, acc)
            for lane in range(min(LANES, N - first)):
                out[first + lane] = acc[lane]


#: The same kernel compiled twice: serial (one thread: no threading layer, no thread
#: wake-ups, which cost milliseconds on a loaded machine) and parallel over chunks.
_score_serial, _score_parallel = serial_and_parallel(_score_particles, nogil=True)


def num_batch_chunks(n: int) -> int:
    """The ``chunks`` of a parallel call for n particles: a few per thread, whole
    batches."""
    batches = -(-n // LANES)
    return max(1, min(batches, 2 * numba.get_num_threads()))


def fused_scores(q: np.ndarray, frame_tables: tuple, lane_tables: tuple,
                 frustum_planes: np.ndarray, projection: tuple[float, float, float, float],
                 near_m: float, far_m: float, observation: PreparedObservation,
                 policy: SerialOrParallel | None = None,
                 workspace: tuple | None = None) -> np.ndarray:
    """(N,) log-likelihoods of configurations q (N, nq), C-contiguous and checked: forward
    kinematics to the camera frame (``frame_tables`` from
    :meth:`~drake_tracker.core.render.kinematics.BatchedKinematics.frame_tables`), rendering
    with ``lane_tables`` (:func:`~drake_tracker.core.simd.lane_render.lane_tables`),
    ``frustum_planes`` and ``projection`` (fx, fy, cx, cy with the pixel-centre offset
    applied), and scoring, in one kernel call. Serial or parallel as ``policy`` chooses
    (default: parallel whenever numba has more than one thread). ``workspace``: from
    :func:`kernel_workspace` for at least num_batch_chunks(N) chunks (default: made for
    this call)."""
    height, width = observation.shape
    N = q.shape[0]
    out = np.zeros(N)
    if N == 0 or observation.num_valid == 0:
        return out
    fx, fy, cx, cy = projection
    o = observation
    chunks = num_batch_chunks(N)
    if policy is None:
        parallel = parallel_allowed()
    else:
        parallel = policy.use_parallel()
    if chunks == 1:
        parallel = False
    kernel = _score_parallel if parallel else _score_serial
    t0 = time.perf_counter()
    if workspace is None:
        workspace = kernel_workspace(chunks if parallel else 1, frame_tables[0].shape[0] + 1,
                                     lane_tables[0].shape[0], height, width)
    kernel(q, *frame_tables, *lane_tables, frustum_planes, fx, fy, cx, cy, near_m, far_m,
           chunks if parallel else 1, height, width, o.pixel_slot, o.pixel_table, o.uniform,
           o.occluder_rate_per_m, o.occlusion_probability, o.truncation, workspace, out)
    if policy is not None:
        policy.record(parallel, time.perf_counter() - t0, N)
    return out
