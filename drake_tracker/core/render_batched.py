"""Batched depth rendering of the robot for many particles at once (the tracker's hot path).

All particles are rendered in one call by a numba z-buffer rasteriser that runs in
parallel over particles. The triangles come from :mod:`drake_tracker.core.geometry`,
the camera-relative body poses from :class:`~drake_tracker.core.kinematics.BatchedKinematics`.

Conventions match what Drake's RenderEngineVtk actually renders (measured with drake
1.51.1): the centre of pixel (i, j) is the ray through u = i + 0.5, v = j + 0.5 of the
projection u = fx*x/z + cx, v = fy*y/z + cy (OpenGL's pixel-centre convention), i.e. half
a pixel away from the integer-centre reading in ``CameraIntrinsics``' docstring; see
``pixel_center_offset``. Depth is the z of the hit point in the camera frame (+z forward, +x right,
+y down), geometry closer than ``near_m`` is clipped away (what lies behind it shows),
and pixels with no hit, or whose nearest hit is beyond ``far_m``, are ``inf``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from drake_tracker.core.camera import CameraIntrinsics
from drake_tracker.core.geometry import DEFAULT_SEGMENTS, RobotMeshes, extract_robot_meshes
from drake_tracker.core.kinematics import BatchedKinematics


@njit(cache=True, inline="always")
def _raster_triangle(zbuf, x0, y0, z0, x1, y1, z1, x2, y2, z2,
                     fx, fy, cx, cy, near, far):
    """Rasterises one camera-frame triangle with all z >= near (approximately) into zbuf,
    keeping the minimum depth. Depth is interpolated perspective-correctly as 1/z."""
    H, W = zbuf.shape
    iz0 = 1.0 / z0
    iz1 = 1.0 / z1
    iz2 = 1.0 / z2
    u0 = fx * x0 * iz0 + cx
    v0 = fy * y0 * iz0 + cy
    u1 = fx * x1 * iz1 + cx
    v1 = fy * y1 * iz1 + cy
    u2 = fx * x2 * iz2 + cx
    v2 = fy * y2 * iz2 + cy
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
    # 1/z is affine in screen space.
    ai = a0 * iz0 + a1 * iz1 + a2 * iz2
    bi = b0 * iz0 + b1 * iz1 + b2 * iz2
    ki = k0 * iz0 + k1 * iz1 + k2 * iz2
    eps = -1e-9
    inv_near = 1.0 / near
    inv_far = 1.0 / far
    for r in range(r0, r1 + 1):
        fr = float(r)
        for c in range(c0, c1 + 1):
            fc = float(c)
            w0 = a0 * fc + b0 * fr + k0
            if w0 < eps:
                continue
            w1 = a1 * fc + b1 * fr + k1
            if w1 < eps:
                continue
            w2 = a2 * fc + b2 * fr + k2
            if w2 < eps:
                continue
            iz = ai * fc + bi * fr + ki
            # near <= z <= far  <=>  1/far <= 1/z <= 1/near (with a little slack at near
            # for triangles whose vertices were clipped exactly onto the near plane).
            if iz > inv_near * (1.0 + 1e-9) or iz < inv_far or iz <= 0.0:
                continue
            z = 1.0 / iz
            if z < zbuf[r, c]:
                zbuf[r, c] = z


@njit(parallel=True, cache=True)
def _render_kernel(X_CB, vertices, vertex_body, triangles, fx, fy, cx, cy, near, far, out):
    N = X_CB.shape[0]
    V = vertices.shape[0]
    T = triangles.shape[0]
    for n in prange(N):
        zbuf = out[n]
        zbuf[:, :] = np.inf
        P = np.empty((V, 3))
        for i in range(V):
            b = vertex_body[i]
            px = vertices[i, 0]
            py = vertices[i, 1]
            pz = vertices[i, 2]
            for k in range(3):
                P[i, k] = (X_CB[n, b, k, 0] * px + X_CB[n, b, k, 1] * py
                           + X_CB[n, b, k, 2] * pz + X_CB[n, b, k, 3])
        poly = np.empty((4, 3))
        for t in range(T):
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
                _raster_triangle(zbuf, P[ia, 0], P[ia, 1], za, P[ib, 0], P[ib, 1], zb,
                                 P[ic, 0], P[ic, 1], zc, fx, fy, cx, cy, near, far)
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
                _raster_triangle(zbuf, poly[0, 0], poly[0, 1], poly[0, 2],
                                 poly[j, 0], poly[j, 1], poly[j, 2],
                                 poly[j + 1, 0], poly[j + 1, 1], poly[j + 1, 2],
                                 fx, fy, cx, cy, near, far)


class BatchedDepthRenderer:
    """Depth images of the robot seen from ``model.camera_frame`` for N configurations.

    ``render(q)`` takes q of shape (N, nq) (or (nq,)) in the plant's position order and
    returns (N, H, W) float32 depths in metres, ``inf`` where nothing is rendered.
    """

    def __init__(self, model, intrinsics: CameraIntrinsics, near_m: float = 0.1,
                 far_m: float = 6.0, segments: int = DEFAULT_SEGMENTS,
                 pixel_center_offset: float = 0.5):
        """``pixel_center_offset``: pixel (i, j) samples u = i + offset, v = j + offset.
        0.5 reproduces Drake's RenderEngineVtk images; 0.0 is the integer-centre reading.
        ``segments``: tessellation of curved shapes (see ``geometry``)."""
        if not (0.0 < near_m < far_m):
            raise ValueError(f"need 0 < near_m < far_m, got near {near_m}, far {far_m}")
        self.model = model
        self.intrinsics = intrinsics
        self.near_m = float(near_m)
        self.far_m = float(far_m)
        self.pixel_center_offset = float(pixel_center_offset)
        self.kinematics = BatchedKinematics.from_plant(model.plant)
        self.meshes: RobotMeshes = extract_robot_meshes(model.plant, model.scene_graph,
                                                        segments)
        self._vertices = np.ascontiguousarray(self.meshes.vertices, dtype=np.float64)
        self._vertex_body = np.ascontiguousarray(self.meshes.vertex_body, dtype=np.int64)
        self._triangles = np.ascontiguousarray(self.meshes.triangles, dtype=np.int64)

    @property
    def num_triangles(self) -> int:
        return self.meshes.num_triangles

    def render(self, q: np.ndarray) -> np.ndarray:
        X_CB = self.kinematics.relative_poses(q, self.model.camera_frame)
        return self.render_camera_poses(X_CB)

    def render_camera_poses(self, X_CB: np.ndarray) -> np.ndarray:
        """Renders from body poses in the camera frame, (N, num_bodies, 4, 4)."""
        X_CB = np.ascontiguousarray(X_CB, dtype=np.float64)
        nb = self.kinematics.num_bodies
        if X_CB.ndim != 4 or X_CB.shape[1:] != (nb, 4, 4):
            raise ValueError(f"X_CB must have shape (N, {nb}, 4, 4), got {X_CB.shape}")
        if not np.all(np.isfinite(X_CB)):
            raise ValueError("X_CB contains NaN or infinite values")
        k = self.intrinsics
        out = np.empty((X_CB.shape[0], k.height, k.width), dtype=np.float32)
        if X_CB.shape[0] == 0:
            return out
        _render_kernel(X_CB, self._vertices, self._vertex_body, self._triangles,
                       float(k.fx), float(k.fy), float(k.cx) - self.pixel_center_offset,
                       float(k.cy) - self.pixel_center_offset,
                       self.near_m, self.far_m, out)
        return out
