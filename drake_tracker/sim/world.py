"""The simulated world: robot, true camera offset, environment, occluder, sensors.

``AddSimulatedWorld(builder, scenario)`` adds to a DiagramBuilder

* a MultibodyPlant with the robot, the six virtual camera joints (set to the TRUE
  camera offset, so the camera body is the true camera), optionally a floor, a table and
  a back wall (so the background has valid depth), and optionally an occluder box on
  three prismatic joints;
* the motion: in ``kinematic`` mode a :class:`TrajectoryPlayback` evaluates the
  reference motion exactly and places the geometry through
  ``MultibodyPositionToGeometryPose`` (the plant itself is not simulated); in
  ``dynamic`` mode a discrete plant (``time_step_s``) is driven by an
  :class:`InverseDynamicsTracking` controller (computed torque with PD feedback on every
  degree of freedom, virtual and occluder joints included);
* :class:`TruthSystem` (true joint angles, true camera offset, true hand pose in the
  true camera frame), :class:`~drake_tracker.sim.encoders.BiasedEncoders` and the depth
  camera of :mod:`drake_tracker.sim.depth_camera`.

The reference motion: robot joints follow ``make_joint_trajectory``; the virtual joints
are ``camera.offset + sum_j gain_j * q_j`` (``offset_gain_per_rad``); the occluder box
sits on the line from the true camera to the end effector (``line_fraction``), swept
sideways along the camera's x axis, during ``[start_s, end_s]`` (2 s cosine ramps) and
``park_distance_m`` aside (out of view) otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Box, SceneGraph
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import (
    Frame,
    MultibodyForces,
    PrismaticJoint,
    SpatialInertia,
    UnitInertia,
)
from pydrake.systems.framework import (
    BasicVector,
    Diagram,
    DiagramBuilder,
    LeafSystem,
    OutputPort,
)
from pydrake.systems.primitives import Demultiplexer
from pydrake.systems.rendering import MultibodyPositionToGeometryPose

from drake_tracker.core.camera import CameraIntrinsics
from drake_tracker.robot import (
    VIRTUAL_JOINT_NAMES,
    RobotConfig,
    TrackerModel,
    add_robot,
    add_virtual_camera_joints,
    build_tracker_model,
    joint_names,
)
from drake_tracker.sim.depth_camera import AddDepthCamera, DepthCameraSystem
from drake_tracker.sim.encoders import BiasedEncoders
from drake_tracker.sim.scenario import OccluderConfig, Scenario, robot_profile
from drake_tracker.sim.trajectories import (
    JointTrajectory,
    check_within_limits,
    make_joint_trajectory,
    smooth_window,
)

#: Output ports of the simulated world, by name.
WORLD_PORTS = ("true_position", "measured_position", "measurement_time", "true_bias",
               "true_camera_offset", "true_X_CE", "depth_frame", "plant_positions",
               "query_object")
#: Names of the occluder's joints (prismatic along world x, y, z).
OCCLUDER_JOINT_NAMES = ("occluder_x", "occluder_y", "occluder_z")
#: Ramp time of the occluder's moves in and out of view (s).
OCCLUDER_RAMP_S = 2.0


def add_environment(plant: MultibodyPlant) -> None:
    """A floor (z = 0), a table and a back wall, visual (illustration and perception)
    geometry on the world body, in front of (+x of) the robot's base."""
    world = plant.world_body()
    items = (
        ("floor", (6.0, 6.0, 0.02), (1.0, 0.0, -0.01), (0.55, 0.5, 0.45, 1.0)),
        ("table", (0.8, 1.4, 0.04), (1.05, 0.0, 0.35), (0.45, 0.3, 0.2, 1.0)),
        ("back_wall", (0.05, 6.0, 3.0), (2.6, 0.0, 1.5), (0.8, 0.8, 0.75, 1.0)),
    )
    for name, size, xyz, rgba in items:
        plant.RegisterVisualGeometry(world, RigidTransform(np.array(xyz)), Box(*size),
                                     f"environment_{name}", np.array(rgba))


def add_occluder(plant: MultibodyPlant, config: OccluderConfig) -> list[str]:
    """A box on three prismatic joints (world x, y, z) in its own model instance."""
    instance = plant.AddModelInstance("occluder")
    inertia = SpatialInertia(mass=1e-3, p_PScm_E=np.zeros(3),
                             G_SP_E=UnitInertia.SolidSphere(0.01))
    parent = plant.world_frame()
    for k, name in enumerate(OCCLUDER_JOINT_NAMES):
        body = plant.AddRigidBody("occluder_box" if k == 2 else f"{name}_body", instance,
                                  inertia)
        plant.AddJoint(PrismaticJoint(name, parent, body.body_frame(), np.eye(3)[k]))
        parent = body.body_frame()
    plant.RegisterVisualGeometry(plant.GetBodyByName("occluder_box"), RigidTransform(),
                                 Box(*config.size_m), "occluder_box",
                                 np.array([0.2, 0.5, 0.9, 1.0]))
    return list(OCCLUDER_JOINT_NAMES)


def offset_gain_matrix(scenario: Scenario, robot_joint_names: list[str]) -> np.ndarray:
    """(6, n) gains of the configuration-dependent camera offset (per rad of each joint)."""
    G = np.zeros((6, len(robot_joint_names)))
    for name, gains in scenario.camera.offset_gain_per_rad.items():
        if name not in robot_joint_names:
            raise ValueError(f"camera.offset_gain_per_rad: joint '{name}' does not exist; "
                             f"joints: {robot_joint_names}")
        G[:, robot_joint_names.index(name)] = gains
    return G


class ReferenceMotion:
    """The world's reference positions of every plant joint as a function of time (a pure
    function of t; it keeps a scratch plant Context for the occluder's FK only)."""

    def __init__(self, plant: MultibodyPlant, scenario: Scenario, trajectory: JointTrajectory,
                 robot_joint_names: list[str], camera_frame: Frame, end_effector_frame: Frame):
        self._plant = plant
        self._trajectory = trajectory
        names = joint_names(plant)
        self._robot_idx = np.array([names.index(n) for n in robot_joint_names])
        self._virtual_idx = np.array([names.index(n) for n in VIRTUAL_JOINT_NAMES])
        self._occ_idx = np.array([names.index(n) for n in OCCLUDER_JOINT_NAMES
                                  if n in names], int)
        self._offset = np.asarray(scenario.camera.offset, float)
        self._gains = offset_gain_matrix(scenario, robot_joint_names)
        self._occluder = scenario.occluder
        self._camera_frame = camera_frame
        self._ee_frame = end_effector_frame
        self._context = plant.CreateDefaultContext()
        self.num_positions = plant.num_positions()

    def camera_offset(self, robot_q: np.ndarray) -> np.ndarray:
        """(6,) true virtual joint values for robot joint angles ``robot_q``."""
        return self._offset + self._gains @ np.asarray(robot_q, float)

    def occluder_position(self, t: float, q: np.ndarray) -> np.ndarray:
        """World position of the box centre (m) given the other joints' positions ``q``."""
        o = self._occluder
        self._plant.SetPositions(self._context, q)
        X_WC = self._camera_frame.CalcPoseInWorld(self._context)
        p_WE = self._ee_frame.CalcPoseInWorld(self._context).translation()
        p_WC = X_WC.translation()
        side = X_WC.rotation().matrix()[:, 0]
        on_line = p_WC + o.line_fraction * (p_WE - p_WC)
        sweep = o.sweep_amplitude_m * np.sin(2 * np.pi * t / o.sweep_period_s)
        active = on_line + sweep * side
        parked = on_line + o.park_distance_m * side
        hold = max(o.end_s - o.start_s - 2 * OCCLUDER_RAMP_S, 0.0)
        w = float(smooth_window(np.array([t]), o.start_s, hold, OCCLUDER_RAMP_S)[0])
        return w * active + (1.0 - w) * parked

    def velocities(self, t: float, h: float = 1e-4) -> np.ndarray:
        """(nv,) central differences of ``positions`` (every joint is single-DoF)."""
        return (self.positions(t + h) - self.positions(t - h)) / (2 * h)

    def positions(self, t: float) -> np.ndarray:
        """(nq,) plant positions at time ``t`` (s)."""
        q = np.zeros(self.num_positions)
        robot_q = self._trajectory.positions(t)[0]
        q[self._robot_idx] = robot_q
        q[self._virtual_idx] = self.camera_offset(robot_q)
        if len(self._occ_idx):
            q[self._occ_idx] = self.occluder_position(t, q)
        return q


class TrajectoryPlayback(LeafSystem):
    """Plays the reference motion back exactly (kinematic mode).

    .. pydrake_system::

        name: TrajectoryPlayback
        output_ports:
        - positions

    ``positions`` (nq): every joint of the simulated plant, in its position order (rad
    or m), a function of time only.
    """

    def __init__(self, reference: ReferenceMotion):
        super().__init__()
        self._reference = reference
        self.DeclareVectorOutputPort("positions", reference.num_positions, self._calc,
                                     {self.time_ticket()})

    def _calc(self, context, output: BasicVector):
        output.SetFromVector(self._reference.positions(context.get_time()))


class InverseDynamicsTracking(LeafSystem):
    """Computed-torque tracking of the reference motion on every degree of freedom.

    .. pydrake_system::

        name: InverseDynamicsTracking
        input_ports:
        - state
        output_ports:
        - generalized_force

    ``generalized_force`` (nv) = ID(q, v, a_ref + kp (q_ref - q) + kd (v_ref - v)),
    gravity included, for the plant's ``applied_generalized_force`` input; the reference
    velocity and acceleration are central differences (h = 0.1 ms) of the reference.
    """

    def __init__(self, plant: MultibodyPlant, reference: ReferenceMotion,
                 natural_frequency_rad_s: float = 60.0):
        super().__init__()
        self._plant = plant
        self._reference = reference
        self._context = plant.CreateDefaultContext()
        self._forces = MultibodyForces(plant)
        w = float(natural_frequency_rad_s)
        self._kp, self._kd = w * w, 2.0 * w
        nq, nv = plant.num_positions(), plant.num_velocities()
        self._nq = nq
        self.DeclareVectorInputPort("state", nq + nv)
        self.DeclareVectorOutputPort("generalized_force", nv, self._calc)

    def _calc(self, context, output: BasicVector):
        t, h = context.get_time(), 1e-4
        q_m, q_0, q_p = (self._reference.positions(s) for s in (t - h, t, t + h))
        v_ref = (q_p - q_m) / (2 * h)
        a_ref = (q_p - 2 * q_0 + q_m) / (h * h)
        x = self.get_input_port(0).Eval(context)
        q, v = x[:self._nq], x[self._nq:]
        vdot = a_ref + self._kp * (q_0 - q) + self._kd * (v_ref - v)
        self._plant.SetPositionsAndVelocities(self._context, x)
        # CalcInverseDynamics takes the applied forces as given: add gravity (the force
        # elements) so that it is compensated.
        self._forces.SetZero()
        self._plant.CalcForceElementsContribution(self._context, self._forces)
        tau = self._plant.CalcInverseDynamics(self._context, vdot, self._forces)
        output.SetFromVector(tau)


class TruthSystem(LeafSystem):
    """Ground truth from the plant's positions.

    .. pydrake_system::

        name: TruthSystem
        input_ports:
        - positions
        output_ports:
        - true_position
        - true_camera_offset
        - true_X_CE

    ``true_position`` (n): the robot joints (rad), order ``robot_joint_names``;
    ``true_camera_offset`` (6): the virtual joints [x y z (m), rx ry rz (rad)];
    ``true_X_CE``: AbstractValue[RigidTransform], the end effector in the TRUE camera
    frame (m).
    """

    def __init__(self, plant: MultibodyPlant, robot_joint_names: list[str],
                 camera_frame: Frame, end_effector_frame: Frame):
        super().__init__()
        self._plant = plant
        self._context = plant.CreateDefaultContext()
        names = joint_names(plant)
        self._robot_idx = np.array([names.index(n) for n in robot_joint_names])
        self._virtual_idx = np.array([names.index(n) for n in VIRTUAL_JOINT_NAMES])
        self._camera_frame = camera_frame
        self._ee_frame = end_effector_frame
        self.DeclareVectorInputPort("positions", plant.num_positions())
        self.DeclareVectorOutputPort("true_position", len(self._robot_idx),
                                     lambda c, o: o.SetFromVector(self._q(c)[self._robot_idx]))
        self.DeclareVectorOutputPort(
            "true_camera_offset", 6, lambda c, o: o.SetFromVector(self._q(c)[self._virtual_idx]))
        self.DeclareAbstractOutputPort("true_X_CE", lambda: AbstractValue.Make(RigidTransform()),
                                       self._calc_X_CE)

    def _q(self, context) -> np.ndarray:
        return self.get_input_port(0).Eval(context)

    def _calc_X_CE(self, context, output):
        self._plant.SetPositions(self._context, self._q(context))
        output.set_value(self._plant.CalcRelativeTransform(self._context, self._camera_frame,
                                                           self._ee_frame))


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
    robot_config: RobotConfig
    plant: MultibodyPlant
    scene_graph: SceneGraph
    #: The tracker's model of this robot (robot + virtual joints, no world extras).
    model: TrackerModel
    robot_joint_names: list[str]
    #: The simulated plant's joints in position order (robot, virtual, occluder).
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
    ports: dict[str, OutputPort] = field(default_factory=dict)
    #: True when ``plant`` is a simulated (discrete) subsystem of the Diagram.
    dynamic: bool = False

    def set_initial_state(self, root_context, time_s: float = 0.0) -> None:
        """Dynamic mode: puts the plant on the reference (positions and velocities at
        ``time_s``) in the Diagram's ``root_context``; kinematic mode: nothing to do."""
        if self.dynamic:
            plant_context = self.plant.GetMyMutableContextFromRoot(root_context)
            self.plant.SetPositions(plant_context, self.reference.positions(time_s))
            self.plant.SetVelocities(plant_context, self.reference.velocities(time_s))

    def port(self, name: str) -> OutputPort:
        """The output port ``name`` (one of ``WORLD_PORTS``)."""
        if name not in self.ports:
            raise ValueError(f"unknown world port '{name}'; known: {list(self.ports)}")
        return self.ports[name]

    @property
    def encoder_period_s(self) -> float:
        return 1.0 / self.scenario.encoders.rate_hz

    @property
    def camera_period_s(self) -> float:
        return 1.0 / self.scenario.camera.rate_hz


def resolved_biased_joints(scenario: Scenario, robot_joint_names: list[str]) -> list[str]:
    """``encoders.biased_joints``, or when empty the profile's arm joints (else all)."""
    if scenario.encoders.biased_joints:
        return list(scenario.encoders.biased_joints)
    profile = robot_profile(scenario.resolved_robot_config())
    return list(profile.arm) if profile else list(robot_joint_names)


def AddSimulatedWorld(builder: DiagramBuilder, scenario: Scenario,
                      name: str = "world") -> SimulatedWorld:
    """Adds the simulated world of ``scenario`` to ``builder`` (see the module doc)."""
    config = scenario.resolved_robot_config()
    dynamic = scenario.mode == "dynamic"
    if scenario.mode not in ("kinematic", "dynamic"):
        raise ValueError(f"Scenario.mode: '{scenario.mode}' is not kinematic or dynamic")
    if dynamic:
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, scenario.time_step_s)
        plant.set_name(f"{name}_plant")
        scene_graph.set_name(f"{name}_scene_graph")
    else:
        scene_graph = builder.AddNamedSystem(f"{name}_scene_graph", SceneGraph())
        plant = MultibodyPlant(time_step=0.0)
        plant.RegisterAsSourceForSceneGraph(scene_graph)
    instance = add_robot(plant, config)
    nominal = plant.GetFrameByName(config.camera_frame, instance)
    _, camera_frame = add_virtual_camera_joints(plant, nominal)
    if scenario.environment:
        add_environment(plant)
    if scenario.occluder.enabled:
        add_occluder(plant, scenario.occluder)
    plant.Finalize()
    ee_frame = plant.GetFrameByName(config.end_effector_frame, instance)

    model = build_tracker_model(config)
    robot_names = model.robot_joint_names
    profile = robot_profile(config)
    trajectory = make_joint_trajectory(scenario.trajectory, robot_names, profile, scenario.seed)
    lower = np.array([plant.GetJointByName(n).position_lower_limits()[0] for n in robot_names])
    upper = np.array([plant.GetJointByName(n).position_upper_limits()[0] for n in robot_names])
    samples = np.arange(0.0, scenario.duration_s, 1.0 / scenario.trajectory.sample_rate_hz)
    check_within_limits(trajectory.positions(samples), lower, upper, robot_names)
    reference = ReferenceMotion(plant, scenario, trajectory, robot_names, camera_frame,
                                ee_frame)

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
        positions = demux.get_output_port(0)
    else:
        playback = builder.AddNamedSystem(f"{name}_playback", TrajectoryPlayback(reference))
        to_pose = builder.AddNamedSystem(f"{name}_to_pose",
                                         MultibodyPositionToGeometryPose(plant))
        builder.Connect(playback.get_output_port(0), to_pose.get_input_port())
        builder.Connect(to_pose.get_output_port(),
                        scene_graph.get_source_pose_port(plant.get_source_id()))
        positions = playback.get_output_port(0)

    truth = builder.AddNamedSystem(f"{name}_truth",
                                   TruthSystem(plant, robot_names, camera_frame, ee_frame))
    builder.Connect(positions, truth.get_input_port(0))
    encoders = builder.AddNamedSystem(
        f"{name}_encoders",
        BiasedEncoders(robot_names, scenario.encoders, scenario.seed,
                       resolved_biased_joints(scenario, robot_names)))
    builder.Connect(truth.GetOutputPort("true_position"), encoders.get_input_port(0))
    camera_body = plant.GetBodyByName(camera_frame.body().name())
    _, camera = AddDepthCamera(builder, scene_graph,
                               plant.GetBodyFrameIdOrThrow(camera_body.index()),
                               scenario.camera, scenario.seed, name=f"{name}_depth_camera",
                               encoder_period_s=1.0 / scenario.encoders.rate_hz)

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
        model=model, robot_joint_names=robot_names, plant_joint_names=joint_names(plant),
        camera_frame=camera_frame, end_effector_frame=ee_frame,
        intrinsics=camera.intrinsics, trajectory=trajectory, reference=reference,
        encoders=encoders, camera=camera, truth=truth, ports=ports, dynamic=dynamic)


def build_simulated_world(scenario: Scenario) -> tuple[Diagram, SimulatedWorld]:
    """A Diagram of just the world, with every ``WORLD_PORTS`` port exported by name."""
    builder = DiagramBuilder()
    world = AddSimulatedWorld(builder, scenario)
    for port_name, port in world.ports.items():
        builder.ExportOutput(port, port_name)
    diagram = builder.Build()
    diagram.set_name("simulated_world")
    return diagram, world
