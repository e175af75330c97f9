"""Meshcat views of a robot driven by a joint-position port: the estimate (orange), the
encoders-only robot (white), each translucent, beside the true robot in the same scene.

Each ghost robot is its own MultibodyPlant and SceneGraph in the Diagram (not simulated:
``MultibodyPositionToGeometryPose`` places its geometry), drawn by its own
``MeshcatVisualizer`` under its own path prefix.
"""

from __future__ import annotations

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
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import DiagramBuilder, OutputPort
from pydrake.systems.rendering import MultibodyPositionToGeometryPose

from drake_tracker.robot import RobotConfig, add_robot, add_virtual_camera_joints

#: Colours of the ghost robots.
ESTIMATE_RGBA = Rgba(1.0, 0.5, 0.0, 0.5)
ENCODERS_RGBA = Rgba(1.0, 1.0, 1.0, 0.35)


def recolor_illustration(plant: MultibodyPlant, scene_graph: SceneGraph, rgba: Rgba) -> None:
    """Replaces the diffuse colour of every illustration geometry of ``plant``."""
    inspector = scene_graph.model_inspector()
    source_id = plant.get_source_id()
    for geometry_id in inspector.GetAllGeometryIds(Role.kIllustration):
        properties = IllustrationProperties(inspector.GetIllustrationProperties(geometry_id))
        properties.UpdateProperty("phong", "diffuse", rgba)
        scene_graph.AssignRole(source_id, geometry_id, properties, RoleAssign.kReplace)


def AddGhostRobot(builder: DiagramBuilder, config: RobotConfig, meshcat: Meshcat,
                  positions: OutputPort, name: str, rgba: Rgba,
                  with_camera_joints: bool = True) -> MeshcatVisualizer:
    """Draws the robot of ``config`` at ``positions`` (its joints in position order; with
    ``with_camera_joints`` the tracker model's six virtual joints come along) in
    ``meshcat`` under ``/drake/<name>``, in colour ``rgba``."""
    scene_graph = builder.AddNamedSystem(f"{name}_scene_graph", SceneGraph())
    plant = MultibodyPlant(time_step=0.0)
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    instance = add_robot(plant, config)
    if with_camera_joints:
        add_virtual_camera_joints(plant, plant.GetFrameByName(config.camera_frame, instance))
    plant.Finalize()
    recolor_illustration(plant, scene_graph, rgba)
    to_pose = builder.AddNamedSystem(f"{name}_to_pose",
                                     MultibodyPositionToGeometryPose(plant))
    builder.Connect(positions, to_pose.get_input_port())
    builder.Connect(to_pose.get_output_port(),
                    scene_graph.get_source_pose_port(plant.get_source_id()))
    params = MeshcatVisualizerParams(role=Role.kIllustration, prefix=name)
    return MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)
