"""Meshcat views of the demo: the true robot in its own colours, the encoders-only robot
(translucent blue) and the estimate (translucent green) in the same scene, each ghost
placed so that its camera is the real camera (its hand shows the hand pose in the camera
frame, what the errors measure), the camera's frustum at its true and at its estimated
pose, a legend, and a view that frames the robot.

Each ghost robot is its own MultibodyPlant and SceneGraph in the Diagram (not simulated:
``MultibodyPositionToGeometryPose`` places its geometry), drawn by its own
``MeshcatVisualizer`` under its own path (``/drake/<name>``), so the scene tree's
controls name and toggle each one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    IllustrationProperties,
    Meshcat,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    Rgba,
    Role,
    RoleAssign,
    SceneGraph,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, ModelInstanceIndex
from pydrake.systems.framework import DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.rendering import MultibodyPositionToGeometryPose

from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.model import RobotConfig, add_robot, add_virtual_camera_joints

#: Colours of the ghost robots, the camera frusta and the depth points.
ENCODERS_RGBA = Rgba(0.2, 0.45, 1.0, 0.45)
ESTIMATE_RGBA = Rgba(0.05, 0.8, 0.2, 0.5)
TRUE_CAMERA_RGBA = Rgba(0.1, 0.1, 0.1, 1.0)
POINTS_RGBA = Rgba(0.85, 0.1, 0.85, 1.0)


@dataclass
class LegendEntry:
    """One line of the legend: a colour swatch and what it stands for."""

    rgba: Rgba | None
    text: str


def recolor_illustration(plant: MultibodyPlant, scene_graph: SceneGraph, rgba: Rgba,
                         hide_anchored: bool = False) -> None:
    """Gives every illustration geometry of ``plant`` the diffuse colour ``rgba``; with
    ``hide_anchored``, bodies welded to the world (which no joint moves) are not drawn.

    Call it before any visualizer is initialised: the old illustration role is removed
    and a new one assigned (replacing the role in place is what Drake warns about)."""
    inspector = scene_graph.model_inspector()
    source_id = plant.get_source_id()
    for geometry_id in inspector.GetAllGeometryIds(Role.kIllustration):
        body = plant.GetBodyFromFrameId(inspector.GetFrameId(geometry_id))
        properties = IllustrationProperties(inspector.GetIllustrationProperties(geometry_id))
        properties.UpdateProperty("phong", "diffuse", rgba)
        scene_graph.RemoveRole(source_id, geometry_id, Role.kIllustration)
        if not (hide_anchored and body is not None and plant.IsAnchored(body)):
            scene_graph.AssignRole(source_id, geometry_id, properties, RoleAssign.kNew)


def AddGhostRobot(builder: DiagramBuilder, config: RobotConfig, meshcat: Meshcat,
                  positions: OutputPort, name: str, rgba: Rgba,
                  with_camera_joints: bool = True,
                  camera_pose: OutputPort | None = None,
                  publish_period_s: float = 1.0 / 30.0) -> MeshcatVisualizer:
    """Draws the robot of ``config`` at ``positions`` (its joints in position order; with
    ``with_camera_joints`` the tracker model's six virtual joints come along) in
    ``meshcat`` under ``/drake/<name>``, in colour ``rgba``. Bodies welded to the world
    are left out: they coincide with the true robot's and would only tint it.

    With ``camera_pose`` (AbstractValue[RigidTransform] X_WC of the true camera) the
    whole ghost is moved so that its own camera frame sits there: its hand then shows
    the hand pose in the camera frame that ``positions`` imply (what the demo's errors
    measure), seen from the real camera. Both are published every ``publish_period_s``
    (the recording's frame period; Drake's default would publish twice as often)."""
    scene_graph = builder.AddNamedSystem(f"{name}_scene_graph", SceneGraph())
    plant = MultibodyPlant(time_step=0.0)
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    instance = add_robot(plant, config)
    camera_frame = plant.GetFrameByName(config.camera_frame, instance)
    if with_camera_joints:
        _, camera_frame = add_virtual_camera_joints(plant, camera_frame)
    plant.Finalize()
    recolor_illustration(plant, scene_graph, rgba, hide_anchored=True)
    to_pose = builder.AddNamedSystem(f"{name}_to_pose",
                                     MultibodyPositionToGeometryPose(plant))
    builder.Connect(positions, to_pose.get_input_port())
    builder.Connect(to_pose.get_output_port(),
                    scene_graph.get_source_pose_port(plant.get_source_id()))
    params = MeshcatVisualizerParams(role=Role.kIllustration, prefix=name,
                                     publish_period=publish_period_s)
    visualizer = MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)
    if camera_pose is not None:
        align = builder.AddNamedSystem(
            f"{name}_camera_alignment",
            AlignGhostToCamera(meshcat, f"/drake/{name}", plant, camera_frame,
                               publish_period_s))
        builder.Connect(positions, align.GetInputPort("positions"))
        builder.Connect(camera_pose, align.GetInputPort("X_WC"))
    return visualizer


class AlignGhostToCamera(LeafSystem):
    """Moves the Meshcat path of a ghost robot (drawn in its own plant's world G) so that
    the ghost's camera frame C lands on the pose X_WC on its input: X_WG = X_WC X_GC⁻¹,
    every ``publish_period_s``, into the recording too."""

    def __init__(self, meshcat: Meshcat, path: str, plant: MultibodyPlant, camera_frame: Frame,
                 publish_period_s: float = 1.0 / 30.0):
        super().__init__()
        self._meshcat, self._path = meshcat, path
        self._plant, self._camera_frame = plant, camera_frame
        self._plant_context = plant.CreateDefaultContext()
        self.DeclareVectorInputPort("positions", plant.num_positions())
        self.DeclareAbstractInputPort("X_WC", AbstractValue.Make(RigidTransform()))
        self.DeclarePeriodicPublishEvent(publish_period_s, 0.0, self._publish)

    def _publish(self, context) -> None:
        positions = self.GetInputPort("positions").Eval(context)
        if not np.all(np.isfinite(positions)):
            return  # nothing to place yet (no reading); the ghost keeps its last pose
        self._plant.SetPositions(self._plant_context, positions)
        X_GC = self._camera_frame.CalcPoseInWorld(self._plant_context)
        X_WC = self.GetInputPort("X_WC").Eval(context)
        self._meshcat.SetTransform(self._path, X_WC @ X_GC.inverse(), context.get_time())


def frustum_segments(camera: CameraIntrinsics, depth_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Start and end points (3 x 8) of the pyramid of ``camera``'s view, apex at the
    optical centre, cut at ``depth_m``, in the camera frame (+z forward)."""
    u = np.array([0.0, camera.width, camera.width, 0.0])
    v = np.array([0.0, 0.0, camera.height, camera.height])
    corners = np.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy,
                        np.ones(4)]) * depth_m
    start = np.hstack([np.zeros((3, 4)), corners])
    end = np.hstack([corners, np.roll(corners, -1, axis=1)])
    return start, end


class FramePoseInWorld(LeafSystem):
    """X_WF of one frame of ``plant`` from a vector of all its positions."""

    def __init__(self, plant: MultibodyPlant, frame: Frame):
        super().__init__()
        self._plant, self._frame = plant, frame
        self._plant_context = plant.CreateDefaultContext()
        self._positions = self.DeclareVectorInputPort("positions", plant.num_positions())
        self.DeclareAbstractOutputPort("X_WF", lambda: AbstractValue.Make(RigidTransform()),
                                       self._calc, {self._positions.ticket()})

    def _calc(self, context, output) -> None:
        self._plant.SetPositions(self._plant_context, self._positions.Eval(context))
        output.set_value(self._frame.CalcPoseInWorld(self._plant_context))


class CameraFrustumVisualizer(LeafSystem):
    """Draws a camera's frustum at ``/drake/<name>`` and moves it to the pose on its input
    (AbstractValue[RigidTransform] X_WC) every ``publish_period_s``, into the recording
    too when Meshcat is recording."""

    def __init__(self, meshcat: Meshcat, name: str, camera: CameraIntrinsics, rgba: Rgba,
                 depth_m: float = 0.25, publish_period_s: float = 1.0 / 30.0):
        super().__init__()
        self._meshcat, self._path = meshcat, f"/drake/{name}"
        start, end = frustum_segments(camera, depth_m)
        meshcat.SetLineSegments(f"{self._path}/frustum", start, end, 2.0, rgba)
        self.DeclareAbstractInputPort("X_WC", AbstractValue.Make(RigidTransform()))
        self.DeclarePeriodicPublishEvent(publish_period_s, 0.0, self._publish)

    def _publish(self, context) -> None:
        X_WC = self.get_input_port().Eval(context)
        self._meshcat.SetTransform(self._path, X_WC, context.get_time())


def frame_the_robot(meshcat: Meshcat, plant: MultibodyPlant, instance: ModelInstanceIndex,
                    positions: np.ndarray, view_direction: np.ndarray = (-0.5, 0.6, 0.9),
                    distance_per_radius: float = 2.2) -> None:
    """Points Meshcat's camera at the centre of the bodies of model ``instance`` of
    ``plant`` at ``positions``, from ``view_direction`` (world frame), far enough to see
    all of them."""
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, positions)
    points = np.array([plant.EvalBodyPoseInWorld(context, plant.get_body(i)).translation()
                       for i in plant.GetBodyIndices(instance)])
    center = 0.5 * (points.min(axis=0) + points.max(axis=0))
    radius = max(0.3, float(np.max(np.linalg.norm(points - center, axis=1))))
    direction = np.asarray(view_direction, float)
    direction /= np.linalg.norm(direction)
    meshcat.SetCameraPose(center + distance_per_radius * radius * direction, center)


def legend_html(entries: list[LegendEntry]) -> str:
    """A fixed box of colour swatches and names, for the standalone Meshcat page."""
    rows = []
    for entry in entries:
        swatch = ""
        if entry.rgba is not None:
            r, g, b = (int(255 * c) for c in (entry.rgba.r(), entry.rgba.g(), entry.rgba.b()))
            alpha = max(entry.rgba.a(), 0.6)
            swatch = (f'<span style="color:rgba({r},{g},{b},{alpha:.2f});font-size:18px">'
                      "&#9632;</span> ")
        rows.append(f"<div>{swatch}{entry.text}</div>")
    return ('<div id="drake-tracker-legend" style="position:fixed;left:10px;bottom:10px;'
            "background:rgba(255,255,255,0.85);padding:6px 10px;border-radius:4px;"
            'font:13px sans-serif;line-height:20px;z-index:10">' + "".join(rows) + "</div>")


def add_legend(static_html: str, entries: list[LegendEntry]) -> str:
    """``static_html`` (``Meshcat.StaticHtml()``) with the legend box in its body."""
    legend = legend_html(entries)
    index = static_html.rfind("</body>")
    if index < 0:
        return static_html + legend
    return static_html[:index] + legend + "\n" + static_html[index:]
