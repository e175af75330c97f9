"""The tracker on a simulated world's ports, every camera of its scenario wired in, and
Meshcat's view of each camera: its frustum at its true and at its estimated pose, and
its depth points."""

from __future__ import annotations

from typing import TYPE_CHECKING

from drake_tracker.systems.add_tracker import AddTracker, TrackerCamera, TrackerSystems

if TYPE_CHECKING:
    from pydrake.geometry import Meshcat
    from pydrake.systems.framework import DiagramBuilder, OutputPort

    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.robot.model import TrackerModel
    from drake_tracker.sim.world import SimulatedWorld


def AddWorldTracker(builder: DiagramBuilder, world: SimulatedWorld,
                    params: TrackerParams, name: str = "tracker") -> TrackerSystems:
    """``AddTracker`` on ``world``'s encoder ports and the depth port of every camera of
    its scenario (``Scenario.cameras``; one camera: the one-camera call, its ports and
    systems named as ever), each with the intrinsics of the images it delivers."""
    common = dict(model=world.model, params=params, name=name,
                  measured_position=world.port("measured_position"),
                  measurement_time=world.port("measurement_time"),
                  encoder_period_s=world.encoder_period_s)
    if len(world.cameras) == 1:
        return AddTracker(builder, camera=world.intrinsics, depth=world.port("depth_frame"),
                          **common)
    return AddTracker(builder, cameras=[
        TrackerCamera(camera, system.intrinsics, world.depth_port(camera))
        for camera, system in world.cameras.items()], **common)


def AddCameraViews(builder: DiagramBuilder, world: SimulatedWorld, meshcat: Meshcat,
                   tracker: TrackerSystems, publish_period_s: float) -> dict[str, OutputPort]:
    """For each camera of ``world``: its frustum at its true pose (black) and at the
    tracker's estimate of it (green), at ``/drake/true_<name>`` and
    ``/drake/estimated_<name>`` (one camera: ``true_camera`` and ``estimated_camera``),
    and its depth points (``camera_points``; a further camera's ``<name>_points``).
    Returns each camera's true pose port (X_WC)."""
    from pydrake.geometry import MeshcatPointCloudVisualizer

    from drake_tracker.demo.meshcat_views import (
        ESTIMATE_RGBA,
        POINTS_RGBA,
        TRUE_CAMERA_RGBA,
        CameraFrustumVisualizer,
        FramePoseInWorld,
    )
    from drake_tracker.sim.depth_camera import camera_intrinsics
    from drake_tracker.systems.point_cloud import DepthFrameToPointCloud

    several = len(world.cameras) > 1
    configs = {c.name: c for c in world.scenario.resolved_cameras()}
    true_poses = {}
    for k, (camera, system) in enumerate(world.cameras.items()):
        label = camera if several else "camera"
        true_pose = builder.AddNamedSystem(
            f"true_{label}_pose" if several else "true_camera_pose",
            FramePoseInWorld(world.plant, world.camera_frames[camera]))
        builder.Connect(world.port("plant_positions"), true_pose.get_input_port())
        true_poses[camera] = true_pose.get_output_port()
        full = camera_intrinsics(configs[camera])
        for view, pose, rgba in ((f"true_{label}", true_poses[camera], TRUE_CAMERA_RGBA),
                                 (f"estimated_{label}", tracker.camera_poses[camera],
                                  ESTIMATE_RGBA)):
            frustum = builder.AddNamedSystem(f"{view}_frustum", CameraFrustumVisualizer(
                meshcat, view, full, rgba, publish_period_s=publish_period_s))
            builder.Connect(pose, frustum.get_input_port())
        points_name = "camera_points" if k == 0 else f"{camera}_points"
        cloud = builder.AddNamedSystem(
            "point_cloud" if k == 0 else f"{camera}_point_cloud",
            DepthFrameToPointCloud(system.intrinsics))
        builder.Connect(world.depth_port(camera), cloud.get_input_port())
        points = builder.AddNamedSystem(
            "point_cloud_visualizer" if k == 0 else f"{camera}_point_cloud_visualizer",
            MeshcatPointCloudVisualizer(meshcat, points_name, publish_period=publish_period_s))
        points.set_default_rgba(POINTS_RGBA)
        points.set_point_size(0.006)
        builder.Connect(cloud.get_output_port(), points.cloud_input_port())
        builder.Connect(true_poses[camera], points.pose_input_port())
    return true_poses


def first_camera_positions(builder: DiagramBuilder, model: TrackerModel,
                           positions: OutputPort) -> OutputPort:
    """The robot joints and the first camera's six virtual joints of ``positions`` (all of
    ``model.joint_names``): what a ghost robot with one camera chain
    (``AddGhostRobot``) draws. With one camera, ``positions`` itself."""
    import numpy as np
    from pydrake.systems.primitives import MatrixGain

    if len(model.cameras) == 1:
        return positions
    keep = [model.joint_names.index(n) for n in model.robot_joint_names]
    keep += list(model.camera_joint_indices(model.camera_names[0]))
    select = np.zeros((len(keep), model.num_joints))
    select[np.arange(len(keep)), sorted(keep)] = 1.0
    gain = builder.AddNamedSystem("estimate_ghost_positions", MatrixGain(select))
    builder.Connect(positions, gain.get_input_port())
    return gain.get_output_port()
