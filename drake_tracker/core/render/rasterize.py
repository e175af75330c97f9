"""The z-buffer triangle rasteriser shared by rendering and scoring (numba kernels).

The meshes come in parts: spatially compact groups of one body's triangles, each with
its own bounding sphere (:mod:`drake_tracker.core.render.mesh_parts`). Per particle, a part
whose sphere is outside the view frustum is skipped, and one wholly in front of the near
plane takes the fast path (no clipping); each
visible vertex is transformed and projected once, triangles of closed surfaces that face
away from the camera are skipped (exact: the images are the same without it), and each
triangle is scanned row by row over exactly the columns it covers. While rasterising,
the rows touched (``rows``) and, per row, the columns touched (``span``) are recorded, so
that a scorer visits only the pixels that may hold the robot.

Conventions (pixel centres, depth, near/far clipping) are those of
:mod:`drake_tracker.core.render.batched`.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from drake_tracker.core.jit.numba_threading import pick_kernel, serial_and_parallel


@njit(cache=True, inline="always")
def _raster(zbuf, u0, v0, iz0, u1, v1, iz1, u2, v2, iz2, near, far, rows, span, box_px):
    """Rasterises one projected triangle (pixel coordinates u, v and inverse depths
    1/z of its vertices, all in front of the near plane up to rounding) into ``zbuf``,
    which holds inverse depths (0: nothing drawn), keeping the largest: the nearest
    surface. 1/z is affine in screen space (perspective-correct), so a pixel costs one
    multiply-add and a max, no division. ``rows`` (r_min, r_max) grows to cover the
    rows written, and ``span[r]`` (c_min, c_max) the columns written in row r (a
    superset). A triangle whose box holds at most ``box_px`` pixel centres goes to
    :func:`_raster_box`; the same pixels and depths either way (tested)."""
    H, W = zbuf.shape
    umin = min(u0, min(u1, u2))
    umax = max(u0, max(u1, u2))
    vmin = min(v0, min(v1, v2))
    vmax = max(v0, max(v1, v2))
    if umax < 0.0 or vmax < 0.0 or umin > W - 1.0 or vmin > H - 1.0:
        return
    c0 = max(0, int(np.ceil(umin)))
    c1 = min(W - 1, int(np.floor(umax)))
    r0 = max(0, int(np.ceil(vmin)))
    r1 = min(H - 1, int(np.floor(vmax)))
    if c0 > c1 or r0 > r1:
        return
    area = (u1 - u0) * (v2 - v0) - (u2 - u0) * (v1 - v0)
    if abs(area) < 1e-12:
        return
    inv_area = 1.0 / area
    # Normalised edge functions e_k(u, v) = a_k*u + b_k*v + c_k, barycentric of vertex k.
    a0 = (v1 - v2) * inv_area
    b0 = (u2 - u1) * inv_area
    k0 = (u1 * v2 - u2 * v1) * inv_area
    a1 = (v2 - v0) * inv_area
    b1 = (u0 - u2) * inv_area
    k1 = (u2 * v0 - u0 * v2) * inv_area
    a2 = (v0 - v1) * inv_area
    b2 = (u1 - u0) * inv_area
    k2 = (u0 * v1 - u1 * v0) * inv_area
    ai = a0 * iz0 + a1 * iz1 + a2 * iz2
    bi = b0 * iz0 + b1 * iz1 + b2 * iz2
    ki = k0 * iz0 + k1 * iz1 + k2 * iz2
    eps = -1e-9
    # near <= z <= far  <=>  1/far <= 1/z <= 1/near (with a little slack at near for
    # triangles whose vertices were clipped exactly onto the near plane).
    iz_hi = (1.0 / near) * (1.0 + 1e-9)
    iz_lo = 1.0 / far
    # The depth range tests are needed only if some vertex is outside [near, far] (1/z
    # inside the triangle is a convex combination of the vertices' 1/z).
    check_range = (max(iz0, max(iz1, iz2)) > iz_hi or min(iz0, min(iz1, iz2)) < iz_lo)
    if (r1 - r0 + 1) * (c1 - c0 + 1) <= box_px:
        _raster_box(zbuf, a0, b0, k0 - eps, a1, b1, k1 - eps, a2, b2, k2 - eps, ai, bi, ki,
                    r0, r1, c0, c1, check_range, iz_lo, iz_hi, rows, span)
        return
    # Per row, the exact run of columns where all three edge functions are >= eps, so
    # that the work per row is proportional to the pixels covered (long thin triangles
    # have bounding boxes far larger than themselves) and the inner loop has no edge
    # tests. Edge k holds where a_k c + b_k r + k_k - eps >= 0: for a_k > 0 that is
    # c >= x_k(r), for a_k < 0 c <= x_k(r), with x_k(r) = -(b_k r + k_k - eps) / a_k
    # affine in r; for a_k == 0 it bounds the rows. So the run of row r is
    # [max(c0, lower edges' x_k(r)), min(c1, upper edges' x_k(r))], computed below
    # without branches (an edge that does not bound a side contributes -inf / +inf).
    lo_s0, lo_t0, hi_s0, hi_t0, r0, r1 = _edge_bounds(a0, b0, k0 - eps, r0, r1)
    lo_s1, lo_t1, hi_s1, hi_t1, r0, r1 = _edge_bounds(a1, b1, k1 - eps, r0, r1)
    lo_s2, lo_t2, hi_s2, hi_t2, r0, r1 = _edge_bounds(a2, b2, k2 - eps, r0, r1)
    fc0 = float(c0)
    fc1 = float(c1)
    if r0 > r1:
        return
    rows[0] = min(rows[0], r0)
    rows[1] = max(rows[1], r1)
    for r in range(r0, r1 + 1):
        fr = float(r)
        lo = max(max(fc0, lo_s0 * fr + lo_t0), max(lo_s1 * fr + lo_t1, lo_s2 * fr + lo_t2))
        hi = min(min(fc1, hi_s0 * fr + hi_t0), min(hi_s1 * fr + hi_t1, hi_s2 * fr + hi_t2))
        if not lo <= hi:
            continue
        c_lo = int(np.ceil(lo))
        c_hi = int(np.floor(hi))
        if c_lo > c_hi:
            continue
        span[r, 0] = min(span[r, 0], c_lo)
        span[r, 1] = max(span[r, 1], c_hi)
        ei = bi * fr + ki
        if check_range:
            for c in range(c_lo, c_hi + 1):
                iz = ai * float(c) + ei
                if iz > iz_hi or iz < iz_lo or iz <= 0.0:
                    continue
                if iz > zbuf[r, c]:
                    zbuf[r, c] = iz
        else:
            for c in range(c_lo, c_hi + 1):
                zbuf[r, c] = max(zbuf[r, c], ai * float(c) + ei)


#: A triangle whose bounding box holds at most this many pixel centres is rasterised by
#: testing every pixel of the box (:func:`_raster_box`), without the per-row setup of the
#: run of columns: cheaper for the few-pixel triangles that most meshes have at 80x60.
SMALL_BOX_PX = 32


@njit(cache=True, inline="always")
def _raster_box(zbuf, a0, b0, g0, a1, b1, g1, a2, b2, g2, ai, bi, ki, r0, r1, c0, c1,
                check_range, iz_lo, iz_hi, rows, span):
    """Rasterises a small triangle by testing each pixel of its box [r0, r1] x [c0, c1]
    against its edges a_k c + b_k r + g_k >= 0 (as :func:`_raster`), without branches;
    the box's columns are recorded in ``span`` (a superset of those written)."""
    rows[0] = min(rows[0], r0)
    rows[1] = max(rows[1], r1)
    for r in range(r0, r1 + 1):
        fr = float(r)
        h0 = b0 * fr + g0
        h1 = b1 * fr + g1
        h2 = b2 * fr + g2
        ei = bi * fr + ki
        for c in range(c0, c1 + 1):
            fc = float(c)
            iz = ai * fc + ei
            inside = (a0 * fc + h0 >= 0.0) & (a1 * fc + h1 >= 0.0) & (a2 * fc + h2 >= 0.0)
            if check_range:
                inside &= (iz <= iz_hi) & (iz >= iz_lo) & (iz > 0.0)
            zbuf[r, c] = max(zbuf[r, c], iz if inside else 0.0)
        span[r, 0] = min(span[r, 0], c0)
        span[r, 1] = max(span[r, 1], c1)


@njit(cache=True, inline="always")
def _edge_bounds(a, b, k, r0, r1):
    """For the edge a c + b r + k >= 0 of a triangle's rows r0..r1: (lo_s, lo_t, hi_s,
    hi_t, r0, r1), the edge's lower column bound lo_s r + lo_t (-inf if it has none),
    its upper bound hi_s r + hi_t (+inf if none), and the rows narrowed where a == 0
    (a horizontal edge; r0 > r1 if no row is left)."""
    if a > 0.0:
        return -b / a, -k / a, 0.0, np.inf, r0, r1
    if a < 0.0:
        return 0.0, -np.inf, -b / a, -k / a, r0, r1
    if b > 0.0:
        r0 = max(r0, int(np.ceil(-k / b)))
    elif b < 0.0:
        r1 = min(r1, int(np.floor(-k / b)))
    elif k < 0.0:
        r1 = r0 - 1
    return 0.0, -np.inf, 0.0, np.inf, r0, r1


@njit(cache=True, inline="always")
def _raster_xyz(zbuf, x0, y0, z0, x1, y1, z1, x2, y2, z2, fx, fy, cx, cy, near, far, rows,
                span):
    iz0 = 1.0 / z0
    iz1 = 1.0 / z1
    iz2 = 1.0 / z2
    _raster(zbuf, fx * x0 * iz0 + cx, fy * y0 * iz0 + cy, iz0,
            fx * x1 * iz1 + cx, fy * y1 * iz1 + cy, iz1,
            fx * x2 * iz2 + cx, fy * y2 * iz2 + cy, iz2, near, far, rows, span, SMALL_BOX_PX)


@njit(cache=True, nogil=True)
def raster_clipped(zbuf: np.ndarray, P: np.ndarray, triangles: np.ndarray, t_begin: int,
                   t_end: int, fx: float, fy: float, cx: float, cy: float, near: float,
                   far: float, poly: np.ndarray, rows: np.ndarray, span: np.ndarray) -> None:
    """Rasterises triangles ``t_begin:t_end`` whose camera-frame vertices are in ``P``
    (V, 3), clipped against the near plane (Sutherland-Hodgman: 3 or 4 vertices) and
    without back-face culling: the path of a part that reaches the near plane. ``poly``
    (4, 3) is scratch; ``rows`` and ``span`` as in :func:`_raster`."""
    for t in range(t_begin, t_end):
        ia = triangles[t, 0]
        ib = triangles[t, 1]
        ic = triangles[t, 2]
        za = P[ia, 2]
        zb = P[ib, 2]
        zc = P[ic, 2]
        if za < near and zb < near and zc < near:
            continue
        if za > far and zb > far and zc > far:
            continue
        if za >= near and zb >= near and zc >= near:
            _raster_xyz(zbuf, P[ia, 0], P[ia, 1], za, P[ib, 0], P[ib, 1], zb,
                        P[ic, 0], P[ic, 1], zc, fx, fy, cx, cy, near, far, rows, span)
            continue
        # Clip against the near plane z = near (Sutherland-Hodgman): 3 or 4 vertices.
        m = 0
        for e in range(3):
            i0 = triangles[t, e]
            i1 = triangles[t, (e + 1) % 3]
            z0 = P[i0, 2]
            z1 = P[i1, 2]
            in0 = z0 >= near
            in1 = z1 >= near
            if in0:
                poly[m, 0] = P[i0, 0]
                poly[m, 1] = P[i0, 1]
                poly[m, 2] = z0
                m += 1
            if in0 != in1:
                s = (near - z0) / (z1 - z0)
                poly[m, 0] = P[i0, 0] + s * (P[i1, 0] - P[i0, 0])
                poly[m, 1] = P[i0, 1] + s * (P[i1, 1] - P[i0, 1])
                poly[m, 2] = near
                m += 1
        for j in range(1, m - 1):
            _raster_xyz(zbuf, poly[0, 0], poly[0, 1], poly[0, 2],
                        poly[j, 0], poly[j, 1], poly[j, 2],
                        poly[j + 1, 0], poly[j + 1, 1], poly[j + 1, 2],
                        fx, fy, cx, cy, near, far, rows, span)


@njit(cache=True, nogil=True)
def render_particle(zbuf: np.ndarray, X: np.ndarray, vertices: np.ndarray,
                    triangles: np.ndarray, part_body: np.ndarray,
                    part_vertex_start: np.ndarray, part_tri_start: np.ndarray,
                    sphere_center: np.ndarray, sphere_radius: np.ndarray,
                    tri_normal: np.ndarray, tri_offset: np.ndarray, tri_closed: np.ndarray,
                    planes: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                    near: float, far: float, P: np.ndarray, UV: np.ndarray,
                    poly: np.ndarray, rows: np.ndarray, span: np.ndarray,
                    keep: np.ndarray) -> None:
    """Renders one particle into ``zbuf`` (H, W) float64 of inverse depths 1/z, which
    must hold 0 (or anything farther) where nothing was drawn yet. ``X`` (num_bodies, 4,
    4) camera-frame body poses. Vertices and triangles are grouped by part
    (``part_*_start`` delimit them; part p belongs to body ``part_body[p]``). A part is
    skipped when its bounding sphere lies outside the view frustum; triangles of closed
    surfaces facing away from the camera are skipped unless the part's sphere reaches
    the near plane (where clipping can expose back faces, or the camera may be inside).
    ``P`` (V, 3), ``UV`` (V, 3) and ``poly`` (4, 3) are scratch; ``rows`` and ``span``
    record the pixels written (see :func:`_raster`); ``keep`` (T,) int64 is scratch."""
    for part in range(part_body.shape[0]):
        b = part_body[part]
        t_begin = part_tri_start[part]
        t_end = part_tri_start[part + 1]
        if t_begin == t_end:
            continue
        # Bounding sphere against near, far and the four side planes.
        sx = sphere_center[part, 0]
        sy = sphere_center[part, 1]
        sz = sphere_center[part, 2]
        cxb = X[b, 0, 0] * sx + X[b, 0, 1] * sy + X[b, 0, 2] * sz + X[b, 0, 3]
        cyb = X[b, 1, 0] * sx + X[b, 1, 1] * sy + X[b, 1, 2] * sz + X[b, 1, 3]
        czb = X[b, 2, 0] * sx + X[b, 2, 1] * sy + X[b, 2, 2] * sz + X[b, 2, 3]
        rad = sphere_radius[part]
        if czb + rad < near or czb - rad > far:
            continue
        outside = False
        for k in range(4):
            if planes[k, 0] * cxb + planes[k, 1] * cyb + planes[k, 2] * czb < -rad:
                outside = True
                break
        if outside:
            continue
        all_front = czb - rad >= near
        # Camera origin in the body frame: -R^T p.
        ox = -(X[b, 0, 0] * X[b, 0, 3] + X[b, 1, 0] * X[b, 1, 3] + X[b, 2, 0] * X[b, 2, 3])
        oy = -(X[b, 0, 1] * X[b, 0, 3] + X[b, 1, 1] * X[b, 1, 3] + X[b, 2, 1] * X[b, 2, 3])
        oz = -(X[b, 0, 2] * X[b, 0, 3] + X[b, 1, 2] * X[b, 1, 3] + X[b, 2, 2] * X[b, 2, 3])
        for i in range(part_vertex_start[part], part_vertex_start[part + 1]):
            px = vertices[i, 0]
            py = vertices[i, 1]
            pz = vertices[i, 2]
            x = X[b, 0, 0] * px + X[b, 0, 1] * py + X[b, 0, 2] * pz + X[b, 0, 3]
            y = X[b, 1, 0] * px + X[b, 1, 1] * py + X[b, 1, 2] * pz + X[b, 1, 3]
            z = X[b, 2, 0] * px + X[b, 2, 1] * py + X[b, 2, 2] * pz + X[b, 2, 3]
            if all_front:
                iz = 1.0 / z
                UV[i, 0] = fx * x * iz + cx
                UV[i, 1] = fy * y * iz + cy
                UV[i, 2] = iz
            else:
                P[i, 0] = x
                P[i, 1] = y
                P[i, 2] = z
        if all_front:
            # Two passes: a branch-free one over all the body's triangles that lists the
            # front faces whose bounding box holds a pixel centre in ``keep`` (the same
            # tests as _raster's early returns), then _raster on those only.
            H = zbuf.shape[0]
            W = zbuf.shape[1]
            w1 = W - 1.0
            h1 = H - 1.0
            kept = 0
            for t in range(t_begin, t_end):
                ia = triangles[t, 0]
                ib = triangles[t, 1]
                ic = triangles[t, 2]
                ua = UV[ia, 0]
                ub = UV[ib, 0]
                uc = UV[ic, 0]
                va = UV[ia, 1]
                vb = UV[ib, 1]
                vc = UV[ic, 1]
                front = ((tri_normal[t, 0] * ox + tri_normal[t, 1] * oy
                          + tri_normal[t, 2] * oz > tri_offset[t]) | (not tri_closed[t]))
                cols = (max(0.0, np.ceil(min(ua, min(ub, uc))))
                        <= min(w1, np.floor(max(ua, max(ub, uc)))))
                rws = (max(0.0, np.ceil(min(va, min(vb, vc))))
                       <= min(h1, np.floor(max(va, max(vb, vc)))))
                keep[kept] = t
                kept += front & cols & rws
            for j in range(kept):
                t = keep[j]
                ia = triangles[t, 0]
                ib = triangles[t, 1]
                ic = triangles[t, 2]
                _raster(zbuf, UV[ia, 0], UV[ia, 1], UV[ia, 2], UV[ib, 0], UV[ib, 1],
                        UV[ib, 2], UV[ic, 0], UV[ic, 1], UV[ic, 2], near, far, rows, span,
                        SMALL_BOX_PX)
            continue
        # The part reaches the near plane: no back-face culling, clipping per triangle.
        raster_clipped(zbuf, P, triangles, t_begin, t_end, fx, fy, cx, cy, near, far, poly,
                       rows, span)


def _render_particles(X_CB: np.ndarray, vertices: np.ndarray, triangles: np.ndarray,
                  part_body: np.ndarray, part_vertex_start: np.ndarray,
                  part_tri_start: np.ndarray, sphere_center: np.ndarray,
                  sphere_radius: np.ndarray, tri_normal: np.ndarray, tri_offset: np.ndarray,
                  tri_closed: np.ndarray, planes: np.ndarray, fx: float, fy: float,
                  cx: float, cy: float, near: float, far: float, num_chunks: int,
                  out: np.ndarray) -> None:
    """Renders particle n's body poses ``X_CB[n]`` into ``out[n]`` (N, H, W) float32."""
    N = X_CB.shape[0]
    V = vertices.shape[0]
    H = out.shape[1]
    W = out.shape[2]
    for chunk in prange(num_chunks):
        P = np.empty((V, 3))
        UV = np.empty((V, 3))
        poly = np.empty((4, 3))
        rows = np.empty(2, dtype=np.int64)
        span = np.empty((H, 2), dtype=np.int64)
        keep = np.empty(triangles.shape[0], dtype=np.int64)
        zbuf = np.empty((H, W))
        for n in range(chunk * N // num_chunks, (chunk + 1) * N // num_chunks):
            zbuf[:, :] = 0.0
            rows[0] = H
            rows[1] = -1
            span[:, 0] = W
            span[:, 1] = -1
            render_particle(zbuf, X_CB[n], vertices, triangles, part_body,
                            part_vertex_start, part_tri_start, sphere_center, sphere_radius,
                            tri_normal, tri_offset, tri_closed, planes, fx, fy, cx, cy, near,
                            far, P, UV, poly, rows, span, keep)
            # Depth = 1/(the largest inverse depth): the same float32 as the smallest
            # float32(1/iz) over the surfaces (x -> float32(1/x) is monotone).
            for r in range(H):
                for c in range(W):
                    iz = zbuf[r, c]
                    out[n, r, c] = np.float32(1.0 / iz) if iz > 0.0 else np.float32(np.inf)


_render_serial, _render_parallel = serial_and_parallel(_render_particles, nogil=True)


def render_kernel(*args: object) -> None:
    """:func:`_render_particles` (same arguments), threaded where ``parallel_allowed()``."""
    pick_kernel(_render_serial, _render_parallel)(*args)


def num_chunks(n: int) -> int:
    """Particles are processed in this many contiguous chunks (scratch memory is per
    chunk); a few per thread."""
    return max(1, min(n, 4 * numba.get_num_threads()))


def frustum_planes(fx: float, fy: float, cx: float, cy: float, width: int, height: int,
                   margin_px: float = 1.0) -> np.ndarray:
    """Unit inward normals (4, 3) of the side planes (through the camera centre) of the
    region that projects within ``margin_px`` of the sampled pixel coordinates
    0..W-1, 0..H-1 (u = fx x/z + cx, v = fy y/z + cy)."""
    lo_u, hi_u = -margin_px, width - 1.0 + margin_px
    lo_v, hi_v = -margin_px, height - 1.0 + margin_px
    planes = np.array([
        [fx, 0.0, cx - lo_u],  # u >= lo_u
        [-fx, 0.0, hi_u - cx],  # u <= hi_u
        [0.0, fy, cy - lo_v],  # v >= lo_v
        [0.0, -fy, hi_v - cy],  # v <= hi_v
    ])
    return planes / np.linalg.norm(planes, axis=1, keepdims=True)
