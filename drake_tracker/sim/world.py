"""The simulated world: robot, true camera offset, environment, occluders, sensors.

``AddSimulatedWorld(builder, scenario)`` adds to a DiagramBuilder

* a MultibodyPlant with the WORLD robot (the model, or with ``model_mismatch`` a
  perturbed copy: ``drake_tracker.sim.mismatch``), the six virtual camera joints (set to
  the TRUE camera offset, so the camera body is the true camera) and optionally a
  floor, a table and a back wall (``drake_tracker.sim.environment``);
* the motion (``drake_tracker.sim.reference``): in ``kinematic`` mode a
  ``TrajectoryPlayback`` evaluates the reference motion exactly and places the geometry
  through ``MultibodyPositionToGeometryPose`` (the plant itself is not simulated); in
  ``dynamic`` mode a discrete plant (``time_step_s``) is driven by an
  ``InverseDynamicsTracking`` controller;
* the occluders (``drake_tracker.sim.occluders``: the legacy ``occluder`` first, then
  ``occluders``), a geometry source of their own posed from the plant's positions;
* a ``TruthSystem`` (true joint angles, true camera offset, true hand pose in the true
  camera frame, all of the world robot), the
  :class:`~drake_tracker.sim.encoders.BiasedEncoders` (reading the world robot's
  joints) and the depth camera of :mod:`drake_tracker.sim.depth_camera`, which sees
  curved shapes as meshes within ``camera.curved_surface_tolerance_m`` of their
  surfaces (:mod:`drake_tracker.sim.curved_shapes`).

The tracker's ``model`` is always the nominal robot of ``scenario``'s RobotConfig.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import SceneGraph
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import Frame
from pydrake.systems.framework import Context, Diagram, DiagramBuilder, OutputPort
from pydrake.systems.primitives import Demultiplexer
from pydrake.systems.rendering import MultibodyPositionToGeometryPose

from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.model import (
    RobotConfig,
    TrackerModel,
    add_camera_chains,
    add_robot,
    build_tracker_model,
)
from drake_tracker.sim.depth_camera import AddDepthCamera, DepthCameraSystem
from drake_tracker.sim.encoders import BiasedEncoders
from drake_tracker.sim.environment import add_environment
from drake_tracker.sim.mismatch import apply_model_mismatch
from drake_tracker.sim.occluders import AddOccluders, OccluderMotion
from drake_tracker.sim.reference import (
    InverseDynamicsTracking,
    ReferenceMotion,
    TrajectoryPlayback,
    position_joint_names,
)
from drake_tracker.sim.scenario.config import Scenario, scenario_occluders
from drake_tracker.sim.scenario.profiles import robot_profile
from drake_tracker.sim.scenario.validation import require_one_of
from drake_tracker.sim.trajectories import (
    JointTrajectory,
    check_within_limits,
    make_joint_trajectory,
)
from drake_tracker.sim.truth import TruthSystem

#: The depth noise of the k-th camera is seeded with the scenario's seed + k times this.
CAMERA_SEED_STEP = 7919
#: Output ports of the simulated world, by name.
WORLD_PORTS = ("true_position", "measured_position", "measurement_time", "true_bias",
               "true_camera_offset", "true_X_CE", "depth_frame", "plant_positions",
               "query_object")


@dataclass
class SimulatedWorld:
    """What ``AddSimulatedWorld`` added, and its output ports (``port(name)``).

    Ports (``WORLD_PORTS``): ``true_position`` (n, rad, ``robot_joint_names`` order),
    ``measured_position`` and ``measurement_time`` (encoders; the time is -1 before the
    first sample), ``true_bias`` (n, rad), ``true_camera_offset`` (6),
    ``true_X_CE`` (AbstractValue[RigidTransform]), ``depth_frame``
    (AbstractValue[DepthFrame]; the latest arrived full-resolution image),
    ``plant_positions`` (every plant joint) and ``query_object`` (SceneGraph).
    """

    scenario: Scenario
    #: The NOMINAL robot (what the tracker and a recording use).
    robot_config: RobotConfig
    #: The world plant: the world robot (perturbed with ``model_mismatch``).
    plant: MultibodyPlant
    scene_graph: SceneGraph
    #: The tracker's model of this robot (nominal robot + virtual joints, no extras).
    model: TrackerModel
    robot_joint_names: list[str]
    #: The simulated plant's joints in position order (robot, virtual).
    plant_joint_names: list[str]
    #: The true camera frame (last virtual body) and the end effector, in ``plant``.
    camera_frame: Frame
    end_effector_frame: Frame
    intrinsics: CameraIntrinsics
    trajectory: JointTrajectory
    reference: ReferenceMotion
    encoders: BiasedEncoders
    camera: DepthCameraSystem
    truth: TruthSystem
    #: Poses of the occluders (empty ``specs`` without any).
    occluders: OccluderMotion
    ports: dict[str, OutputPort] = field(default_factory=dict)
    #: True when ``plant`` is a simulated (discrete) subsystem of the Diagram.
    dynamic: bool = False
    #: Every camera by name (the first is ``camera``), and their true frames.
    cameras: dict[str, DepthCameraSystem] = field(default_factory=dict)
    camera_frames: dict[str, Frame] = field(default_factory=dict)

    def depth_port(self, camera: str) -> OutputPort:
        """The ``depth_frame`` port of the camera named ``camera``."""
        require_one_of(camera, list(self.cameras), "camera")
        return self.cameras[camera].GetOutputPort("depth_frame")

    def set_initial_state(self, root_context: Context, time_s: float = 0.0) -> None:
        """Dynamic mode: puts the plant on the reference (positions and velocities at
        ``time_s``) in the Diagram's ``root_context``; kinematic mode: nothing to do."""
        if self.dynamic:
            plant_context = self.plant.GetMyMutableContextFromRoot(root_context)
            self.plant.SetPositions(plant_context, self.reference.positions(time_s))
            self.plant.SetVelocities(plant_context, self.reference.velocities(time_s))

    def port(self, name: str) -> OutputPort:
        """The output port ``name`` (one of ``WORLD_PORTS``)."""
        require_one_of(name, list(self.ports), "world port")
        return self.ports[name]

    @property
    def encoder_period_s(self) -> float:
        """Time between encoder samples (s)."""
        return 1.0 / self.scenario.encoders.rate_hz

    @property
    def camera_period_s(self) -> float:
        """Nominal time between depth images (s): of the fastest camera."""
        return 1.0 / max(c.rate_hz for c in self.scenario.resolved_cameras())


def resolved_biased_joints(scenario: Scenario, robot_joint_names: list[str]) -> list[str]:
    """``encoders.biased_joints``, or when empty the profile's arm joints (else all)."""
    if scenario.encoders.biased_joints:
        return list(scenario.encoders.biased_joints)
    profile = robot_profile(scenario.resolved_robot_config())
    return list(profile.arm) if profile else list(robot_joint_names)


def _add_plant(builder: DiagramBuilder, scenario: Scenario, name: str):
    if scenario.mode == "dynamic":
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, scenario.time_step_s)
        plant.set_name(f"{name}_plant")
        scene_graph.set_name(f"{name}_scene_graph")
    else:
        scene_graph = builder.AddNamedSystem(f"{name}_scene_graph", SceneGraph())
        plant = MultibodyPlant(time_step=0.0)
        plant.RegisterAsSourceForSceneGraph(scene_graph)
    return plant, scene_graph


def _add_motion(builder: DiagramBuilder, plant: MultibodyPlant, scene_graph: SceneGraph,
                reference: ReferenceMotion, dynamic: bool, name: str) -> OutputPort:
    """The systems that move the plant along ``reference``; returns the positions port."""
    if dynamic:
        plant.SetDefaultPositions(reference.positions(0.0))
        controller = builder.AddNamedSystem(f"{name}_controller",
                                            InverseDynamicsTracking(plant, reference))
        builder.Connect(plant.get_state_output_port(), controller.get_input_port(0))
        builder.Connect(controller.get_output_port(0),
                        plant.get_applied_generalized_force_input_port())
        demux = builder.AddNamedSystem(
            f"{name}_state_demux",
            Demultiplexer([plant.num_positions(), plant.num_velocities()]))
        builder.Connect(plant.get_state_output_port(), demux.get_input_port(0))
        return demux.get_output_port(0)
    playback = builder.AddNamedSystem(f"{name}_playback", TrajectoryPlayback(reference))
    to_pose = builder.AddNamedSystem(f"{name}_to_pose", MultibodyPositionToGeometryPose(plant))
    builder.Connect(playback.get_output_port(0), to_pose.get_input_port())
    builder.Connect(to_pose.get_output_port(),
                    scene_graph.get_source_pose_port(plant.get_source_id()))
    return playback.get_output_port(0)


def AddSimulatedWorld(builder: DiagramBuilder, scenario: Scenario,
                      name: str = "world") -> SimulatedWorld:
    """Adds the simulated world of ``scenario`` to ``builder`` (see the module doc)."""
    config = scenario.resolved_robot_config()
    require_one_of(scenario.mode, ("kinematic", "dynamic"), "Scenario.mode")
    dynamic = scenario.mode == "dynamic"
    plant, scene_graph = _add_plant(builder, scenario, name)
    instance = add_robot(plant, config)
    apply_model_mismatch(plant, scene_graph, instance, config.end_effector_frame,
                         scenario.model_mismatch)
    chains = add_camera_chains(plant, instance, config)
    camera_frame = chains[0][2]
    if scenario.environment:
        add_environment(plant)
    plant.Finalize()
    ee_frame = plant.GetFrameByName(config.end_effector_frame, instance)

    model = build_tracker_model(config)
    robot_names = model.robot_joint_names
    trajectory = make_joint_trajectory(scenario.trajectory, robot_names, robot_profile(config),
                                       scenario.seed)
    lower = np.array([plant.GetJointByName(n).position_lower_limits()[0] for n in robot_names])
    upper = np.array([plant.GetJointByName(n).position_upper_limits()[0] for n in robot_names])
    samples = np.arange(0.0, scenario.duration_s, 1.0 / scenario.trajectory.sample_rate_hz)
    check_within_limits(trajectory.positions(samples), lower, upper, robot_names)
    reference = ReferenceMotion(plant, scenario, trajectory, robot_names)
    positions = _add_motion(builder, plant, scene_graph, reference, dynamic, name)
    occluders = OccluderMotion(plant, scenario_occluders(scenario), instance, camera_frame,
                               ee_frame)
    AddOccluders(builder, scene_graph, occluders, positions, name=f"{name}_occluders")

    truth, encoders = add_truth_and_encoders(builder, plant, positions, scenario, robot_names,
                                             camera_frame, ee_frame, name)
    cameras, frames = {}, {}
    for k, (camera_config, (_, _, frame)) in enumerate(zip(scenario.resolved_cameras(),
                                                           chains)):
        body = plant.GetBodyByName(frame.body().name())
        # The first camera is the one camera of old (its name and its random streams).
        _, cameras[camera_config.name] = AddDepthCamera(
            builder, scene_graph, plant.GetBodyFrameIdOrThrow(body.index()),
            camera_config.sensor(), scenario.seed + CAMERA_SEED_STEP * k,
            name=f"{name}_depth_camera" + (f"_{camera_config.name}" if k else ""),
            encoder_period_s=1.0 / scenario.encoders.rate_hz)
        frames[camera_config.name] = frame
    camera = next(iter(cameras.values()))

    ports = {
        "true_position": truth.GetOutputPort("true_position"),
        "measured_position": encoders.GetOutputPort("measured_position"),
        "measurement_time": encoders.GetOutputPort("measurement_time"),
        "true_bias": encoders.GetOutputPort("bias"),
        "true_camera_offset": truth.GetOutputPort("true_camera_offset"),
        "true_X_CE": truth.GetOutputPort("true_X_CE"),
        "depth_frame": camera.GetOutputPort("depth_frame"),
        "plant_positions": positions,
        "query_object": scene_graph.get_query_output_port(),
    }
    return SimulatedWorld(
        scenario=scenario, robot_config=config, plant=plant, scene_graph=scene_graph,
        model=model, robot_joint_names=robot_names, plant_joint_names=position_joint_names(plant),
        camera_frame=camera_frame, end_effector_frame=ee_frame,
        intrinsics=camera.intrinsics, trajectory=trajectory, reference=reference,
        encoders=encoders, camera=camera, truth=truth, occluders=occluders, ports=ports,
        dynamic=dynamic, cameras=cameras, camera_frames=frames)


def build_simulated_world(scenario: Scenario) -> tuple[Diagram, SimulatedWorld]:
    """A Diagram of just the world, with every ``WORLD_PORTS`` port exported by name."""
    builder = DiagramBuilder()
    world = AddSimulatedWorld(builder, scenario)
    for port_name, port in world.ports.items():
        builder.ExportOutput(port, port_name)
    diagram = builder.Build()
    diagram.set_name("simulated_world")
    return diagram, world


def add_truth_and_encoders(builder: DiagramBuilder, plant: MultibodyPlant,
                           positions: OutputPort, scenario: Scenario, robot_names: list[str],
                           camera_frame: Frame, ee_frame: Frame, name: str
                           ) -> tuple[TruthSystem, BiasedEncoders]:
    """The ground truth of the plant's ``positions`` (joint angles, camera offset, hand in
    the camera) and the biased encoders that read the true angles."""
    cameras = tuple(c.name for c in scenario.resolved_cameras())
    truth = builder.AddNamedSystem(f"{name}_truth", TruthSystem(plant, robot_names,
                                                                camera_frame, ee_frame, cameras))
    builder.Connect(positions, truth.GetInputPort("positions"))
    encoders = builder.AddNamedSystem(
        f"{name}_encoders",
        BiasedEncoders(robot_names, scenario.encoders, scenario.seed,
                       resolved_biased_joints(scenario, robot_names)))
    builder.Connect(truth.GetOutputPort("true_position"), encoders.GetInputPort("true_position"))
    return truth, encoders
