"""Occluders: boxes, cylinders and spheres between the camera and the robot.

Each :class:`~drake_tracker.sim.scenario.config.OccluderSpec` is one geometry frame of its own
SceneGraph source (``occluders``), posed by :class:`OccluderPoses` from the time and the
world plant's positions, so the same occluders work in kinematic and dynamic mode and
never enter the plant. Its pose while in the scene (``motion``):

* ``world``: ``xyz_m`` / ``rpy_deg`` in the world;
* ``frame``: ``xyz_m`` / ``rpy_deg`` in a frame of the robot, or in the true camera;
* ``path``: the centre through the timed waypoints (linear), orientation ``rpy_deg``;
* ``line-sweep``: on the line true camera -> end effector at ``line_fraction``, swept
  ``sweep_amplitude_m sin(2 pi t / sweep_period_s)`` along the camera's x axis.

It is in the scene during ``[enter_s, leave_s]`` (cosine ramps of ``ramp_s`` inside the
window) and parked ``park_distance_m`` along the camera's x axis otherwise:
``p = w p_active + (1 - w) p_parked``.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    Box,
    Cylinder,
    FramePoseVector,
    GeometryFrame,
    GeometryInstance,
    MakePhongIllustrationProperties,
    PerceptionProperties,
    RenderLabel,
    Rgba,
    SceneGraph,
    Sphere,
)
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, ModelInstanceIndex
from pydrake.systems.framework import DiagramBuilder, LeafSystem, OutputPort

from drake_tracker.sim.scenario.config import CAMERA_FRAME_NAME, OccluderSpec
from drake_tracker.sim.scenario.validation import require
from drake_tracker.sim.trajectories import smooth_window

#: Render labels of the occluders start here (the plant uses its body indices).
OCCLUDER_LABEL_BASE = 9000


def occluder_shape(spec: OccluderSpec) -> Box | Cylinder | Sphere:
    """The Drake shape of ``spec`` (box edges, cylinder radius and length, sphere radius)."""
    if spec.shape == "box":
        return Box(*spec.size_m)
    if spec.shape == "cylinder":
        return Cylinder(*spec.size_m)
    require(spec.shape == "sphere", "occluder.shape", spec.shape,
            "must be box, cylinder or sphere")
    return Sphere(spec.size_m[0])


def presence_weight(spec: OccluderSpec, t: float) -> float:
    """1 while the occluder is in the scene, 0 while parked, cosine ramps between."""
    hold = max(spec.leave_s - spec.enter_s - 2 * spec.ramp_s, 0.0)
    return float(smooth_window(np.array([t]), spec.enter_s, hold, spec.ramp_s)[0])


def path_position(spec: OccluderSpec, t: float) -> np.ndarray:
    """(3,) the path's centre at ``t``: linear between waypoints, held outside them."""
    points = np.asarray(spec.waypoints_m, float).reshape(-1, 3)
    times = np.asarray(spec.waypoint_times_s, float)
    return np.array([np.interp(t, times, points[:, k]) for k in range(3)])


class OccluderMotion:
    """Poses of the occluders in the world as functions of time and plant positions."""

    def __init__(self, plant: MultibodyPlant, specs: list[OccluderSpec],
                 robot_instance: ModelInstanceIndex, camera_frame: Frame,
                 end_effector_frame: Frame):
        self._plant = plant
        self._context = plant.CreateDefaultContext()
        self.specs = list(specs)
        self._camera_frame = camera_frame
        self._ee_frame = end_effector_frame
        self._frames: list[Frame | None] = []
        for k, spec in enumerate(self.specs):
            frame = None
            if spec.motion == "frame":
                if spec.frame == CAMERA_FRAME_NAME:
                    frame = camera_frame
                else:
                    require(plant.HasFrameNamed(spec.frame, robot_instance),
                            f"occluders[{k}].frame", spec.frame, "no such frame in the robot")
                    frame = plant.GetFrameByName(spec.frame, robot_instance)
            self._frames.append(frame)

    def poses(self, t: float, q: np.ndarray) -> list[RigidTransform]:
        """``X_WO`` of every occluder at time ``t`` with plant positions ``q``."""
        self._plant.SetPositions(self._context, q)
        X_WC = self._camera_frame.CalcPoseInWorld(self._context)
        side = X_WC.rotation().matrix()[:, 0]
        return [self._pose(spec, frame, t, X_WC, side)
                for spec, frame in zip(self.specs, self._frames)]

    def _pose(self, spec: OccluderSpec, frame: Frame | None, t: float, X_WC: RigidTransform,
              side: np.ndarray) -> RigidTransform:
        X_local = RigidTransform(RollPitchYaw(np.radians(spec.rpy_deg)), np.array(spec.xyz_m))
        rotation = X_local.rotation()
        if spec.motion == "line-sweep":
            p_WC = X_WC.translation()
            p_WE = self._ee_frame.CalcPoseInWorld(self._context).translation()
            centre = p_WC + spec.line_fraction * (p_WE - p_WC)
            sweep = spec.sweep_amplitude_m * np.sin(2 * np.pi * t / spec.sweep_period_s)
            active = centre + sweep * side
        elif spec.motion == "path":
            centre = active = path_position(spec, t)
        else:
            if frame is not None:
                X_local = frame.CalcPoseInWorld(self._context) @ X_local
                rotation = X_local.rotation()
            centre = active = X_local.translation()
        parked = centre + spec.park_distance_m * side
        w = presence_weight(spec, t)
        return RigidTransform(rotation, w * active + (1.0 - w) * parked)


class OccluderPoses(LeafSystem):
    """Poses the occluders' geometry frames for SceneGraph.

    .. pydrake_system::

        name: OccluderPoses
        input_ports:
        - positions
        output_ports:
        - geometry_pose

    ``positions``: the world plant's positions; ``geometry_pose``: a FramePoseVector of
    the occluders' frames (``OccluderMotion.poses`` at the context's time).
    """

    def __init__(self, motion: OccluderMotion, frame_ids: list, num_positions: int):
        super().__init__()
        self._motion = motion
        self._frame_ids = list(frame_ids)
        self._positions = self.DeclareVectorInputPort("positions", num_positions)
        self.DeclareAbstractOutputPort("geometry_pose",
                                       lambda: AbstractValue.Make(FramePoseVector()),
                                       self._calc,
                                       {self.time_ticket(), self._positions.ticket()})

    def _calc(self, context, output):
        poses = self._motion.poses(context.get_time(), self._positions.Eval(context))
        vector = output.get_mutable_value()
        vector.clear()
        for frame_id, X_WO in zip(self._frame_ids, poses):
            vector.set_value(frame_id, X_WO)


def register_occluders(scene_graph: SceneGraph, specs: list[OccluderSpec]) -> tuple:
    """Registers one frame and geometry per occluder (illustration and perception roles)
    under a new source ``occluders``; returns (source id, frame ids)."""
    source_id = scene_graph.RegisterSource("occluders")
    frame_ids = []
    for k, spec in enumerate(specs):
        name = f"occluder_{k}_{spec.shape}"
        frame_id = scene_graph.RegisterFrame(source_id, GeometryFrame(name))
        geometry_id = scene_graph.RegisterGeometry(
            source_id, frame_id, GeometryInstance(RigidTransform(), occluder_shape(spec), name))
        scene_graph.AssignRole(source_id, geometry_id,
                               MakePhongIllustrationProperties(np.array(spec.rgba)))
        perception = PerceptionProperties()
        perception.AddProperty("phong", "diffuse", Rgba(*spec.rgba))
        perception.AddProperty("label", "id", RenderLabel(OCCLUDER_LABEL_BASE + k))
        scene_graph.AssignRole(source_id, geometry_id, perception)
        frame_ids.append(frame_id)
    return source_id, frame_ids


def AddOccluders(builder: DiagramBuilder, scene_graph: SceneGraph, motion: OccluderMotion,
                 positions_port: OutputPort, name: str = "occluders") -> OccluderPoses | None:
    """Registers ``motion``'s occluders with ``scene_graph`` and adds the system that poses
    them from ``positions_port`` (the world plant's positions); None without occluders."""
    if not motion.specs:
        return None
    source_id, frame_ids = register_occluders(scene_graph, motion.specs)
    poses = builder.AddNamedSystem(
        name, OccluderPoses(motion, frame_ids, positions_port.size()))
    builder.Connect(positions_port, poses.get_input_port(0))
    builder.Connect(poses.get_output_port(0), scene_graph.get_source_pose_port(source_id))
    return poses
