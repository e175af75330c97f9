"""Render and score 8 particles at a time: the image update's likelihood evaluations.

The particles of a CPF block differ by a fraction of a degree, so they see the same
parts, the same triangles and nearly the same pixels. :func:`render_lanes` renders a
batch of :data:`~drake_tracker.core.simd.lanes.LANES` particles together: one pass over the
parts and triangles, each vertex projected for all lanes, each triangle set up per lane
and rasterised over the union of the lanes' pixels with per-lane edge tests (every lane
gets exactly its own image), into a z-buffer whose pixel holds the lanes side by side.
:func:`score_pixels` then scores each pixel that some lane drew, for all lanes at once.

The arithmetic is that of the scalar rasteriser (:mod:`drake_tracker.core.render.rasterize`'s
box path), so the images are the same, and the scores agree with
``likelihood.log_likelihoods`` of ``render_kernel``'s images to the float32 pixel terms'
stated tolerance (:mod:`drake_tracker.core.simd.lane_likelihood`; tested). Of a part that
reaches the near plane, the triangles that do are clipped lane by lane by the scalar
path.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from drake_tracker.core.render.rasterize import raster_clipped
from drake_tracker.core.simd.lane_likelihood import (
    PIXELS_PER_CALL,
    lane_any,
    lane_pixel_scores,
    lane_pixel_scores_truncated,
)
from drake_tracker.core.simd.lanes import (
    COEFF_ROWS,
    LANES,
    lane_project,
    lane_raster,
    lane_triangle,
)

#: A triangle whose lanes' union box holds at most this many pixel centres is
#: rasterised over the whole box; larger ones row by row over the union of the lanes'
#: runs of columns.
BOX_PX = 40


def lane_tables(render_tables: tuple) -> tuple:
    """The rasteriser's tables (:func:`~drake_tracker.core.render.mesh_parts.render_tables`) as
    :func:`render_lanes` reads them: each triangle's normal and offset in one row
    (T, 4)."""
    (vertices, triangles, part_body, part_vertex_start, part_tri_start, centers, radii,
     normals, offsets, closed) = render_tables
    planes = np.ascontiguousarray(np.column_stack([normals, offsets]), dtype=np.float64)
    return (vertices, triangles, part_body, part_vertex_start, part_tri_start, centers,
            radii, planes.reshape(-1, 4), closed)


@njit(cache=True, nogil=True)
def lane_scratch(num_vertices: int) -> tuple:
    """Scratch arrays of :func:`render_lanes` for meshes of ``num_vertices`` vertices:
    projected vertices (3 x V*LANES), camera-frame vertices of one lane (V, 3), a
    clipped polygon (4, 3), a triangle's coefficients, a box, the lanes' states for a
    part and for a triangle, the camera's origin in the body frame, and the lanes where
    the part reaches the near plane."""
    return (np.empty(num_vertices * LANES), np.empty(num_vertices * LANES),
            np.empty(num_vertices * LANES), np.empty(num_vertices * LANES),
            np.empty((num_vertices, 3)), np.empty((4, 3)), np.zeros(COEFF_ROWS * LANES),
            np.zeros(6, np.int64), np.zeros(LANES), np.zeros(LANES), np.zeros(3 * LANES),
            np.zeros(LANES, np.bool_))


@njit(cache=True, nogil=True)
def render_lanes(zb: np.ndarray, height: int, width: int, poses: np.ndarray,
                 vertices: np.ndarray, triangles: np.ndarray, part_body: np.ndarray,
                 part_vertex_start: np.ndarray, part_tri_start: np.ndarray,
                 sphere_center: np.ndarray, sphere_radius: np.ndarray,
                 tri_planes: np.ndarray, tri_closed: np.ndarray, planes: np.ndarray,
                 fx: float, fy: float, cx: float, cy: float, near: float, far: float,
                 scratch: tuple, rows: np.ndarray, span: np.ndarray) -> None:
    """Renders the LANES particles whose camera-frame body poses are ``poses``
    (num_bodies, 12, LANES: the 3x4 rows) into ``zb`` (H*W*LANES inverse depths, 0
    where nothing is drawn), with the culling of
    :func:`~drake_tracker.core.render.rasterize.render_particle`; ``tri_planes`` (T, 4) are
    the triangles' normals and offsets. ``rows``/``span`` grow to the pixels touched.
    ``scratch``: from :func:`lane_scratch`."""
    U, Vv, IZ, Z, P, poly, co, box, fast, triangle_fast, origin, near_lane = scratch
    flat = poses.reshape(-1)
    w1 = width - 1.0
    h1 = height - 1.0
    # the depth range of rasterize._raster (a little slack at the near plane)
    iz_hi = (1.0 / near) * (1.0 + 1e-9)
    iz_lo = 1.0 / far
    zb3 = zb[:height * width * LANES].reshape((height, width, LANES))
    for part in range(part_body.shape[0]):
        b = part_body[part]
        t_begin = part_tri_start[part]
        t_end = part_tri_start[part + 1]
        v_begin = part_vertex_start[part]
        v_end = part_vertex_start[part + 1]
        if t_begin == t_end:
            continue
        any_seen = False
        any_near = False
        sx = sphere_center[part, 0]
        sy = sphere_center[part, 1]
        sz = sphere_center[part, 2]
        rad = sphere_radius[part]
        for lane in range(LANES):
            X = poses[b, :, lane]
            cxb = X[0] * sx + X[1] * sy + X[2] * sz + X[3]
            cyb = X[4] * sx + X[5] * sy + X[6] * sz + X[7]
            czb = X[8] * sx + X[9] * sy + X[10] * sz + X[11]
            seen = not (czb + rad < near or czb - rad > far)
            for k in range(4):
                seen = seen and not (planes[k, 0] * cxb + planes[k, 1] * cyb
                                     + planes[k, 2] * czb < -rad)
            in_front = seen and czb - rad >= near
            fast[lane] = 1.0 if in_front else 0.0
            near_lane[lane] = seen and not in_front
            any_seen = any_seen or seen
            any_near = any_near or near_lane[lane]
            for j in range(3):  # the camera origin in the body frame: -R^T p
                origin[j * LANES + lane] = -(X[j] * X[3] + X[4 + j] * X[7]
                                             + X[8 + j] * X[11])
        if not any_seen:
            continue
        for i in range(v_begin, v_end):
            lane_project(U, Vv, IZ, Z, i, flat, b, vertices[i, 0], vertices[i, 1],
                         vertices[i, 2], fx, fy, cx, cy)
        lanes_of_triangle = fast
        for t in range(t_begin, t_end):
            if any_near:  # the part reaches the near plane in some lanes
                _near_lanes(t, triangles, vertices, poses, b, Z, near_lane, fast,
                            triangle_fast, P, poly, zb3, fx, fy, cx, cy, near, far, rows,
                            span)
                lanes_of_triangle = triangle_fast
            drawn = lane_triangle(co, box, U, Vv, IZ, triangles[t, 0], triangles[t, 1],
                                  triangles[t, 2], tri_planes, t, tri_closed[t], origin,
                                  lanes_of_triangle, w1, h1, iz_lo, iz_hi)
            if drawn == 0:
                continue
            r0 = box[0]
            r1 = box[1]
            c0 = box[2]
            c1 = box[3]
            rows[0] = min(rows[0], r0)
            rows[1] = max(rows[1], r1)
            lane_raster(zb, width, co, r0, r1, c0, c1, (r1 - r0 + 1) * (c1 - c0 + 1) > BOX_PX,
                        span)


@njit(cache=True, nogil=True)
def _near_lanes(t, triangles, vertices, poses, b, Z, near_lane, fast, triangle_fast, P,
                poly, zb3, fx, fy, cx, cy, near, far, rows, span):
    """For a part that reaches the near plane in some lanes (where render_particle
    neither culls back faces nor skips clipping): triangle t's lane states, 2 (drawn
    without culling by the lanes) in those lanes where all three of its vertices are in
    front of the near plane; in the others it is clipped and drawn by the scalar path."""
    for lane in range(LANES):
        triangle_fast[lane] = fast[lane]
        if not near_lane[lane]:
            continue
        ia = triangles[t, 0]
        ib = triangles[t, 1]
        ic = triangles[t, 2]
        if (Z[ia * LANES + lane] >= near and Z[ib * LANES + lane] >= near
                and Z[ic * LANES + lane] >= near):
            triangle_fast[lane] = 2.0
            continue
        X = poses[b, :, lane]
        for i in (ia, ib, ic):
            for j in range(3):
                P[i, j] = (X[4 * j] * vertices[i, 0] + X[4 * j + 1] * vertices[i, 1]
                           + X[4 * j + 2] * vertices[i, 2] + X[4 * j + 3])
        raster_clipped(zb3[:, :, lane], P, triangles, t, t + 1, fx, fy, cx, cy, near, far,
                       poly, rows, span)


@njit(cache=True, nogil=True)
def score_pixels(zb: np.ndarray, width: int, rows: np.ndarray, span: np.ndarray,
                 pixel_slot: np.ndarray, table: np.ndarray, uniform: float, lam: float,
                 occlusion: float, truncation: float, offsets: np.ndarray,
                 pixels: np.ndarray, acc: np.ndarray) -> None:
    """Adds each lane's log-likelihood ratios of the pixels in ``rows``/``span`` to
    ``acc`` (LANES,), and clears those pixels of ``zb`` and the span for the next batch
    (``table``: :func:`~drake_tracker.core.simd.lane_likelihood.pixel_table`). ``zb`` has
    LANES zeros past its H*W pixels; ``offsets`` and ``pixels`` are int64 scratch of
    H*W + PIXELS_PER_CALL."""
    count = 0
    for r in range(rows[0], rows[1] + 1):
        c_lo = span[r, 0]
        c_hi = span[r, 1]
        span[r, 0] = width
        span[r, 1] = -1
        base = r * width
        for c in range(c_lo, c_hi + 1):
            off = (base + c) * LANES
            if not lane_any(zb, off):
                continue
            p = pixel_slot[base + c]
            if p < 0:
                for lane in range(LANES):
                    zb[off + lane] = 0.0
                continue
            offsets[count] = off
            pixels[count] = p
            count += 1
    padding = zb.shape[0] - LANES  # the zeros past the image: score nothing
    for k in range(count, count + PIXELS_PER_CALL):
        offsets[k] = padding
        pixels[k] = 0
    for k in range(0, count, PIXELS_PER_CALL):
        if truncation != 0.0:
            lane_pixel_scores_truncated(zb, offsets, pixels, k, acc, table, uniform, lam,
                                        occlusion, truncation)
        else:
            lane_pixel_scores(zb, offsets, pixels, k, acc, table, uniform, lam, occlusion,
                              truncation)
