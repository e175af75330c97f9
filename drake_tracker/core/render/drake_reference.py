"""Reference depth renderer: Drake's RenderEngineVtk, one ``RenderDepthImage`` per particle.

Slow (milliseconds per image, mostly fixed overhead per call) but it is Drake's own
rendering of the same model, so the batched renderer is tested against it.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import (
    ClippingRange,
    DepthRange,
    DepthRenderCamera,
    MakeRenderEngineVtk,
    RenderCameraCore,
    RenderEngineVtkParams,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.model import TrackerModel, add_robot, add_virtual_camera_joints

RENDERER_NAME = "drake_tracker_depth_vtk"


class DrakeDepthRenderer:
    """Same interface as :class:`~drake_tracker.core.render.batched.BatchedDepthRenderer`.

    Builds its own plant and scene graph from ``model.config`` (the model's diagram is
    already built, and a renderer must be added before geometry queries are made), with
    the same joints in the same position order.
    """

    def __init__(self, model: TrackerModel, intrinsics: CameraIntrinsics, near_m: float = 0.1,
                 far_m: float = 6.0) -> None:
        if not (0.0 < near_m < far_m):
            raise ValueError(f"need 0 < near_m < far_m, got near {near_m}, far {far_m}")
        self.model = model
        self.intrinsics = intrinsics
        self.near_m = float(near_m)
        self.far_m = float(far_m)
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
        scene_graph.AddRenderer(RENDERER_NAME, MakeRenderEngineVtk(RenderEngineVtkParams()))
        instance = add_robot(plant, model.config)
        nominal = plant.GetFrameByName(model.config.camera_frame, instance)
        _, camera_frame = add_virtual_camera_joints(plant, nominal)
        plant.Finalize()
        if plant.num_positions() != model.plant.num_positions():
            raise RuntimeError("DrakeDepthRenderer: rebuilt plant differs from the model's")
        self._diagram = builder.Build()
        self._plant = plant
        self._scene_graph = scene_graph
        self._context = self._diagram.CreateDefaultContext()
        self._plant_context = plant.GetMyMutableContextFromRoot(self._context)
        self._sg_context = scene_graph.GetMyContextFromRoot(self._context)
        self._camera_frame_id = plant.GetBodyFrameIdOrThrow(camera_frame.body().index())
        self._X_PC = RigidTransform(camera_frame.GetFixedPoseInBodyFrame())
        core = RenderCameraCore(RENDERER_NAME, intrinsics.to_camera_info(),
                                ClippingRange(self.near_m, self.far_m), RigidTransform())
        self._camera = DepthRenderCamera(core, DepthRange(self.near_m, self.far_m))

    def render(self, q: np.ndarray) -> np.ndarray:
        """(N, H, W) float32 depth images (m) of configurations q (N, nq) or (nq,), one
        ``RenderDepthImage`` each; inf where nothing is hit within [near_m, far_m]. ValueError
        for a wrong shape or a q that is not finite."""
        q = np.asarray(q, dtype=float)
        if q.ndim == 1:
            q = q[None, :]
        nq = self._plant.num_positions()
        if q.ndim != 2 or q.shape[1] != nq:
            raise ValueError(f"q must have shape (N, {nq}) or ({nq},), got {np.shape(q)}")
        if not np.all(np.isfinite(q)):
            raise ValueError("q contains NaN or infinite values")
        k = self.intrinsics
        out = np.empty((q.shape[0], k.height, k.width), dtype=np.float32)
        port = self._scene_graph.get_query_output_port()
        for n in range(q.shape[0]):
            self._plant.SetPositions(self._plant_context, q[n])
            query = port.Eval(self._sg_context)
            image = query.RenderDepthImage(self._camera, self._camera_frame_id, self._X_PC)
            depth = np.array(image.data, dtype=np.float32, copy=True).reshape(k.height, k.width)
            # Drake: 0 = closer than the depth range, inf = beyond it or no hit.
            depth[~(depth > 0.0)] = np.inf
            out[n] = depth
        return out
