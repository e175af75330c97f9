"""Batched depth rendering of the robot for many particles at once (the tracker's hot path).

All particles are rendered in one call by a numba z-buffer rasteriser that runs in
parallel over particles. The triangles come from :mod:`drake_tracker.core.render.meshes`,
the camera-relative body poses from
:class:`~drake_tracker.core.render.kinematics.BatchedKinematics`.

The rasteriser is :mod:`drake_tracker.core.render.rasterize`. For the tracker's image update,
:meth:`BatchedDepthRenderer.score` fuses it with the pixel likelihood
(:mod:`drake_tracker.core.render.fused_score`), so no (N, H, W) images are written to
memory.

Conventions match what Drake's RenderEngineVtk actually renders (measured with drake
1.51.1): the centre of pixel (i, j) is the ray through u = i + 0.5, v = j + 0.5 of the
projection u = fx*x/z + cx, v = fy*y/z + cy (OpenGL's pixel-centre convention), i.e. half
a pixel away from the integer-centre reading in ``CameraIntrinsics``' docstring; see
``pixel_center_offset``. Depth is the z of the hit point in the camera frame (+z forward, +x right,
+y down), geometry closer than ``near_m`` is clipped away (what lies behind it shows),
and pixels with no hit, or whose nearest hit is beyond ``far_m``, are ``inf``.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.jit.numba_threading import SerialOrParallel
from drake_tracker.core.likelihood.pixel_model import PreparedObservation
from drake_tracker.core.render.configurations import (
    default_view_configuration,
    random_configurations,
)
from drake_tracker.core.render.fused_score import (
    fused_scores,
    kernel_workspace,
    num_batch_chunks,
)
from drake_tracker.core.render.kinematics import BatchedKinematics
from drake_tracker.core.render.level_of_detail import LevelOfDetail, level_of_detail
from drake_tracker.core.render.measured_detail import MeasuredDetail, measure_detail
from drake_tracker.core.render.mesh_parts import render_tables
from drake_tracker.core.render.meshes import DEFAULT_SEGMENTS, RobotMeshes, extract_robot_meshes
from drake_tracker.core.render.rasterize import frustum_planes, num_chunks, render_kernel
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.core.simd.lane_render import lane_tables

if TYPE_CHECKING:
    from drake_tracker.robot.model import TrackerModel

#: The level of detail the renderer uses unless told otherwise.
DEFAULT_DETAIL = LevelOfDetail()

#: A measured level of detail needs its calibration images to show at least this many
#: robot pixels in all.
MIN_CALIBRATION_PX = 200


class BatchedDepthRenderer:
    """Depth images of the robot seen from ``model.camera_frame`` for N configurations.

    ``render(q)`` takes q of shape (N, nq) (or (nq,)) in the plant's position order and
    returns (N, H, W) float32 depths in metres, ``inf`` where nothing is rendered.
    """

    def __init__(self, model: TrackerModel, intrinsics: CameraIntrinsics, near_m: float = 0.1,
                 far_m: float = 6.0, segments: int = DEFAULT_SEGMENTS,
                 pixel_center_offset: float = 0.5,
                 detail: LevelOfDetail | None = DEFAULT_DETAIL,
                 detail_configurations: np.ndarray | None = None) -> None:
        """``pixel_center_offset``: pixel (i, j) samples u = i + offset, v = j + offset.
        0.5 reproduces Drake's RenderEngineVtk images; 0.0 is the integer-centre reading.
        ``segments``: tessellation of curved shapes (see ``geometry``). ``detail``: the
        meshes are simplified to this level of detail for this image size (see
        ``level_of_detail``); None renders the meshes as they are. A measured level of
        detail is measured on the images of ``detail_configurations`` (N, nq), by default
        ``detail.calibration_images`` configurations about the view configuration
        (``renderer.random_configurations``); ``measured_detail`` keeps the measurement.
        ``source_meshes`` keeps the meshes as read, ``meshes`` what is rendered."""
        if not (0.0 < near_m < far_m):
            raise ValueError(f"need 0 < near_m < far_m, got near {near_m}, far {far_m}")
        self.model = model
        self.intrinsics = intrinsics
        self.near_m = float(near_m)
        self.far_m = float(far_m)
        self.pixel_center_offset = float(pixel_center_offset)
        self.kinematics = BatchedKinematics.from_plant(model.plant)
        self.source_meshes: RobotMeshes = extract_robot_meshes(model.plant, model.scene_graph,
                                                               segments)
        k = intrinsics
        self._fx = float(k.fx)
        self._fy = float(k.fy)
        self._cx = float(k.cx) - self.pixel_center_offset
        self._cy = float(k.cy) - self.pixel_center_offset
        self._planes = frustum_planes(self._fx, self._fy, self._cx, self._cy,
                                       k.width, k.height)
        self.measured_detail: MeasuredDetail | None = None
        self.meshes = self._detailed_meshes(detail, detail_configurations)
        self._tables = render_tables(self.meshes, self.kinematics.num_bodies)
        self._lane_tables = lane_tables(self._tables)
        self._frame_tables = self.kinematics.frame_tables(model.camera_frame)
        self._policy = SerialOrParallel()
        self._workspace: tuple | None = None

    def _detailed_meshes(self, detail: LevelOfDetail | None,
                         configurations: np.ndarray | None) -> RobotMeshes:
        """The meshes rendered at ``detail`` (see ``__init__``)."""
        if detail is None:
            return self.source_meshes
        uniform = level_of_detail(self.source_meshes, detail.cell_m(self.intrinsics),
                                  detail.min_reduction)
        if detail.max_disagreement is None or uniform.num_triangles == (
                self.source_meshes.num_triangles):
            return uniform  # one cell for all, or nothing to simplify
        if configurations is None:
            configurations = random_configurations(
                self.model, detail.calibration_images, seed=0,
                center=default_view_configuration(self.model))
        X_CB = self.kinematics.relative_poses(configurations, self.model.camera_frame)
        measured = measure_detail(
            self.source_meshes, lambda meshes: self._render_tables(
                render_tables(meshes, self.kinematics.num_bodies), X_CB),
            detail.ladder_m(self.intrinsics), detail.max_disagreement,
            detail.min_reduction, detail.depth_tolerance_m)
        if measured.robot_px < MIN_CALIBRATION_PX:
            warnings.warn(f"the level of detail's {len(X_CB)} calibration images show "
                          f"{measured.robot_px} robot pixels (fewer than "
                          f"{MIN_CALIBRATION_PX}): its cells are not measured, every body "
                          f"gets {detail.cell_px} px; pass detail_configurations that show "
                          f"the robot", stacklevel=3)
            return uniform
        self.measured_detail = measured
        return measured.meshes

    def workspace(self, chunks: int) -> tuple:
        """The scoring kernel's scratch (``render_likelihood.kernel_workspace``) for at
        least ``chunks`` chunks, made once (for as many chunks as numba may run threads
        in parallel) and kept: a kernel call does not allocate or clear its z-buffers."""
        if self._workspace is None or self._workspace[0].shape[0] < chunks:
            import numba

            k = self.intrinsics
            self._workspace = kernel_workspace(
                max(chunks, 2 * numba.config.NUMBA_NUM_THREADS), self.kinematics.num_bodies,
                self._lane_tables[0].shape[0], k.height, k.width)
        return self._workspace

    @property
    def num_triangles(self) -> int:
        """The number of triangles rendered (after the level of detail, if any)."""
        return self.meshes.num_triangles

    def render(self, q: np.ndarray) -> np.ndarray:
        """(N, H, W) float32 depth images (m; inf: no hit) of q (N, nq) or (nq,)."""
        X_CB = self.kinematics.relative_poses(q, self.model.camera_frame)
        return self.render_camera_poses(X_CB)

    def score(self, q: np.ndarray, observation: PreparedObservation) -> np.ndarray:
        """(N,) image log-likelihoods of configurations q (N, nq) against an observation
        prepared at this renderer's image size: FK, rendering and scoring fused (no
        (N, H, W) images in memory). Equal, to ~1e-12 relative, to
        ``likelihood.log_likelihoods(self.render(q), observation, params)`` with the
        parameters the observation was prepared with."""
        k = self.intrinsics
        if tuple(observation.shape) != (k.height, k.width):
            raise ValueError(f"observation has shape {tuple(observation.shape)}, the "
                             f"renderer renders ({k.height}, {k.width})")
        q = self.kinematics.checked_positions(q)
        return fused_scores(q, self._frame_tables, self._lane_tables, self._planes,
                            (self._fx, self._fy, self._cx, self._cy), self.near_m,
                            self.far_m, observation, self._policy,
                            self.workspace(num_batch_chunks(len(q))))

    def render_camera_poses(self, X_CB: np.ndarray) -> np.ndarray:
        """Renders from body poses in the camera frame, (N, num_bodies, 4, 4)."""
        X_CB = np.ascontiguousarray(X_CB, dtype=np.float64)
        nb = self.kinematics.num_bodies
        if X_CB.ndim != 4 or X_CB.shape[1:] != (nb, 4, 4):
            raise ValueError(f"X_CB must have shape (N, {nb}, 4, 4), got {X_CB.shape}")
        if not np.all(np.isfinite(X_CB)):
            raise ValueError("X_CB contains NaN or infinite values")
        return self._render_tables(self._tables, X_CB)

    def _render_tables(self, tables: tuple, X_CB: np.ndarray) -> np.ndarray:
        """Renders the meshes of ``tables`` (``render_tables``) at checked poses."""
        k = self.intrinsics
        out = np.empty((X_CB.shape[0], k.height, k.width), dtype=np.float32)
        if X_CB.shape[0] == 0:
            return out
        render_kernel(X_CB, *tables, self._planes, self._fx, self._fy, self._cx,
                      self._cy, self.near_m, self.far_m, num_chunks(X_CB.shape[0]), out)
        return out
