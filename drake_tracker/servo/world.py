"""The servo study's simulated world: a dynamic plant that a controller moves.

``AddServoWorld(builder, scenario, ...)`` adds

* a discrete MultibodyPlant (``scenario.time_step_s``) with the robot, the six virtual
  camera joints held at the TRUE camera offset (the camera body is the true camera, as in
  ``drake_tracker.sim.world``) and the scenario's floor, table and wall;
* the robot's joint servo: Drake's ``InverseDynamicsController`` (computed torque with
  gravity, on the plant itself) tracking a desired state from
  :class:`JointServoReference`. A real joint servo holds the ENCODER reading at the
  command, so the commanded arm angles are in encoder coordinates and the true angles
  end up at command - bias (modelled exactly: the encoders' noise and sampling are left
  out of the inner loop). The head and the virtual joints hold their home values;
* the scenario's occluders (``drake_tracker.sim.occluders``), posed from the plant;
* the :class:`~drake_tracker.sim.truth.TruthSystem`, the biased
  :class:`~drake_tracker.sim.encoders.BiasedEncoders` and, with ``with_camera``, the
  depth camera of ``drake_tracker.sim.depth_camera`` (only the tracker needs it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import SceneGraph
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import Frame
from pydrake.systems.controllers import InverseDynamicsController
from pydrake.systems.framework import (
    BasicVector,
    Context,
    DiagramBuilder,
    InputPort,
    LeafSystem,
    OutputPort,
)
from pydrake.systems.primitives import Demultiplexer

from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.model import (
    VIRTUAL_JOINT_NAMES,
    RobotConfig,
    TrackerModel,
    add_robot,
    add_virtual_camera_joints,
    build_tracker_model,
)
from drake_tracker.sim.depth_camera import (
    AddDepthCamera,
    DepthCameraSystem,
    rendered_intrinsics,
)
from drake_tracker.sim.encoders import BiasedEncoders
from drake_tracker.sim.environment import add_environment
from drake_tracker.sim.occluders import AddOccluders, OccluderMotion
from drake_tracker.sim.reference import offset_gain_matrix, position_joint_names
from drake_tracker.sim.scenario.config import Scenario, scenario_occluders
from drake_tracker.sim.scenario.profiles import robot_profile
from drake_tracker.sim.scenario.validation import require
from drake_tracker.sim.trajectories import make_joint_trajectory
from drake_tracker.sim.truth import TruthSystem
from drake_tracker.sim.world import add_truth_and_encoders


def arm_joint_names(config: RobotConfig, robot_joint_names: list[str]) -> list[str]:
    """The joints the servo moves: the robot profile's arm, else every robot joint."""
    profile = robot_profile(config)
    return list(profile.arm) if profile else list(robot_joint_names)


def home_positions(scenario: Scenario, robot_joint_names: list[str]) -> np.ndarray:
    """The robot joints' TRUE home angles (rad): the scenario's trajectory at t = 0."""
    config = scenario.resolved_robot_config()
    trajectory = make_joint_trajectory(scenario.trajectory, robot_joint_names,
                                       robot_profile(config), scenario.seed)
    return np.asarray(trajectory.positions(0.0)[0], float)


class JointServoReference(LeafSystem):
    """The joint servo's desired plant state from the arm command.

    .. pydrake_system::

        name: JointServoReference
        input_ports:
        - arm_command
        - encoder_bias
        output_ports:
        - desired_state

    ``arm_command`` (1 + 2m): [valid, q (m, encoder coordinates, rad), v (m, rad/s)] of
    the m arm joints; ``encoder_bias`` (n): the encoders' true bias of every robot joint.
    ``desired_state`` (nq + nv): the arm at q - bias with velocity v once the command is
    valid (before: the home pose), every other joint at ``home_q`` and at rest.
    """

    def __init__(self, plant: MultibodyPlant, robot_joint_names: list[str],
                 arm_joints: list[str], home_q: np.ndarray):
        super().__init__()
        names = position_joint_names(plant)
        self._arm_rows = np.array([names.index(n) for n in arm_joints])
        self._arm_in_robot = np.array([robot_joint_names.index(n) for n in arm_joints])
        self._home = np.asarray(home_q, float)
        self._nq = plant.num_positions()
        m = len(arm_joints)
        self._m = m
        self._command = self.DeclareVectorInputPort("arm_command", 1 + 2 * m)
        self._bias = self.DeclareVectorInputPort("encoder_bias", len(robot_joint_names))
        # Computed again only when an input changes: the plant reads it at every step,
        # after each of the other systems' updates.
        self.DeclareVectorOutputPort("desired_state", self._nq + plant.num_velocities(),
                                     self._calc,
                                     {self._command.ticket(), self._bias.ticket()})

    def _calc(self, context, output: BasicVector) -> None:
        command = self._command.Eval(context)
        x = np.concatenate([self._home, np.zeros(self._nq)])
        if command[0] > 0.5:
            bias = self._bias.Eval(context)[self._arm_in_robot]
            x[self._arm_rows] = command[1:1 + self._m] - bias
            x[self._nq + self._arm_rows] = command[1 + self._m:]
        output.SetFromVector(x)


@dataclass
class ServoWorld:
    """What ``AddServoWorld`` added; ports by name in ``ports``."""

    scenario: Scenario
    robot_config: RobotConfig
    plant: MultibodyPlant
    scene_graph: SceneGraph
    #: The tracker's model of the nominal robot.
    model: TrackerModel
    robot_joint_names: list[str]
    arm_joint_names: list[str]
    #: Every plant joint's TRUE home value (robot joints, then the camera offset).
    home_q: np.ndarray
    camera_frame: Frame
    end_effector_frame: Frame
    encoders: BiasedEncoders
    truth: TruthSystem
    camera: DepthCameraSystem | None
    #: The joint servo's command input (1 + 2m: valid, q, v of the arm joints).
    arm_command_input: InputPort
    ports: dict[str, OutputPort]

    @property
    def encoder_period_s(self) -> float:
        """Time between encoder samples (s)."""
        return 1.0 / self.scenario.encoders.rate_hz

    def set_initial_state(self, root_context: Context) -> None:
        """Puts the plant at rest at its home pose in the Diagram's ``root_context``."""
        plant_context = self.plant.GetMyMutableContextFromRoot(root_context)
        self.plant.SetPositions(plant_context, self.home_q)
        self.plant.SetVelocities(plant_context, np.zeros(self.plant.num_velocities()))


def AddServoWorld(builder: DiagramBuilder, scenario: Scenario,
                  joint_servo_frequency_rad_per_s: float = 40.0, with_camera: bool = True,
                  name: str = "world") -> ServoWorld:
    """Adds the world of ``scenario`` (module doc). Connect the controller's arm command
    to ``ServoWorld.arm_command_input``."""
    config = scenario.resolved_robot_config()
    require(not scenario.model_mismatch.enabled, "model_mismatch", scenario.model_mismatch,
            "the servo world simulates the nominal robot; use a scenario without it")
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, scenario.time_step_s)
    plant.set_name(f"{name}_plant")
    scene_graph.set_name(f"{name}_scene_graph")
    instance = add_robot(plant, config)
    virtual, camera_frame = add_virtual_camera_joints(
        plant, plant.GetFrameByName(config.camera_frame, instance))
    for joint_name in virtual:  # held by the joint servo, which needs every joint actuated
        plant.AddJointActuator(f"{joint_name}_actuator", plant.GetJointByName(joint_name))
    if scenario.environment:
        add_environment(plant)
    plant.Finalize()
    ee_frame = plant.GetFrameByName(config.end_effector_frame, instance)

    model = build_tracker_model(config)
    robot_names = model.robot_joint_names
    arm = arm_joint_names(config, robot_names)
    names = position_joint_names(plant)
    robot_home = home_positions(scenario, robot_names)
    home_q = np.zeros(plant.num_positions())
    home_q[[names.index(n) for n in robot_names]] = robot_home
    offset = (np.asarray(scenario.camera.offset, float)
              + offset_gain_matrix(scenario, robot_names) @ robot_home)
    home_q[[names.index(n) for n in VIRTUAL_JOINT_NAMES]] = offset
    plant.SetDefaultPositions(home_q)

    reference = builder.AddNamedSystem(f"{name}_joint_servo_reference",
                                       JointServoReference(plant, robot_names, arm, home_q))
    w = float(joint_servo_frequency_rad_per_s)
    nv = plant.num_velocities()
    servo = builder.AddNamedSystem(
        f"{name}_joint_servo",
        InverseDynamicsController(plant, np.full(nv, w * w), np.zeros(nv), np.full(nv, 2 * w),
                                  False))
    builder.Connect(plant.get_state_output_port(), servo.get_input_port_estimated_state())
    builder.Connect(reference.get_output_port(0), servo.get_input_port_desired_state())
    builder.Connect(servo.get_output_port_control(),
                    plant.get_applied_generalized_force_input_port())
    demux = builder.AddNamedSystem(f"{name}_state_demux",
                                   Demultiplexer([plant.num_positions(), nv]))
    builder.Connect(plant.get_state_output_port(), demux.get_input_port(0))
    positions = demux.get_output_port(0)
    AddOccluders(builder, scene_graph,
                 OccluderMotion(plant, scenario_occluders(scenario), instance, camera_frame,
                                ee_frame), positions, name=f"{name}_occluders")

    truth, encoders = add_truth_and_encoders(builder, plant, positions, scenario, robot_names,
                                             camera_frame, ee_frame, name)
    builder.Connect(encoders.GetOutputPort("bias"), reference.GetInputPort("encoder_bias"))
    ports = {
        "true_position": truth.GetOutputPort("true_position"),
        "measured_position": encoders.GetOutputPort("measured_position"),
        "measurement_time": encoders.GetOutputPort("measurement_time"),
        "true_bias": encoders.GetOutputPort("bias"),
        "true_X_CE": truth.GetOutputPort("true_X_CE"),
        "plant_positions": positions,
    }
    camera = None
    if with_camera:
        camera_body = plant.GetBodyByName(camera_frame.body().name())
        _, camera = AddDepthCamera(builder, scene_graph,
                                   plant.GetBodyFrameIdOrThrow(camera_body.index()),
                                   scenario.camera, scenario.seed, name=f"{name}_depth_camera",
                                   encoder_period_s=1.0 / scenario.encoders.rate_hz)
        ports["depth_frame"] = camera.GetOutputPort("depth_frame")
    return ServoWorld(scenario, config, plant, scene_graph, model, robot_names, arm, home_q,
                      camera_frame, ee_frame, encoders, truth, camera,
                      reference.GetInputPort("arm_command"), ports)


def camera_model(scenario: Scenario) -> CameraIntrinsics:
    """The intrinsics of the images the scenario's camera delivers (for ``AddTracker``):
    full resolution, or subsampled by ``camera.render_stride``."""
    return rendered_intrinsics(scenario.camera)
