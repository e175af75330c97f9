"""The three feedbacks of the study: an ``X_CE`` port and a joint-angle port each.

* ``encoders`` (a): forward kinematics of the raw encoder readings on the nominal robot,
  in the NOMINAL camera frame (:class:`EncoderKinematicsPose`), and the readings: what a
  robot without the tracker knows;
* ``tracker`` (b): drake_tracker's ``X_CE`` (the hand in the ESTIMATED camera frame) and
  its ``estimated_position`` (robot joints), added with ``AddTracker`` on the world's
  encoders and depth camera, in the same Diagram;
* ``truth`` (c): the hand in the TRUE camera frame and the true angles, the ideal.

The tracker's feed also says whether it may be acted on: ``usable`` is 0 while its
``health`` is ``LOST`` (the controller then holds the arm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.primitives import MatrixGain

from drake_tracker.core.robustness.health import HealthState, TrackerHealth
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import RobotConfig, add_robot
from drake_tracker.servo.config import FEEDBACKS
from drake_tracker.servo.world import ServoWorld, camera_model
from drake_tracker.sim.scenario.validation import require_one_of
from drake_tracker.systems.add_tracker import AddTracker, TrackerSystems


class EncoderKinematicsPose(LeafSystem):
    """The hand in the nominal camera frame at the encoder readings (nominal robot).

    .. pydrake_system::

        name: EncoderKinematicsPose
        input_ports:
        - measured_position
        output_ports:
        - X_CE

    ``measured_position`` (n): robot joints in ``robot_joint_names`` order (rad);
    ``X_CE``: AbstractValue[RigidTransform].
    """

    def __init__(self, robot_config: RobotConfig, robot_joint_names: list[str]):
        super().__init__()
        self._plant = MultibodyPlant(time_step=0.0)
        add_robot(self._plant, robot_config)
        self._plant.Finalize()
        self._context = self._plant.CreateDefaultContext()
        self._rows = np.array([self._plant.GetJointByName(n).position_start()
                               for n in robot_joint_names])
        self._C = self._plant.GetFrameByName(robot_config.camera_frame)
        self._E = self._plant.GetFrameByName(robot_config.end_effector_frame)
        self._readings = self.DeclareVectorInputPort("measured_position",
                                                     len(robot_joint_names))
        self.DeclareAbstractOutputPort("X_CE", lambda: AbstractValue.Make(RigidTransform()),
                                       self._calc, {self._readings.ticket()})

    def _calc(self, context, output) -> None:
        q = self._plant.GetPositions(self._context)
        q[self._rows] = self._readings.Eval(context)
        self._plant.SetPositions(self._context, q)
        output.set_value(self._plant.CalcRelativeTransform(self._context, self._C, self._E))


class HealthToUsable(LeafSystem):
    """1 while the tracker's health is not ``LOST``, else 0: whether a controller may act
    on its estimate (``TrackerSystems.health``'s advice).

    .. pydrake_system::

        name: HealthToUsable
        input_ports:
        - health
        output_ports:
        - usable
    """

    def __init__(self):
        super().__init__()
        health = self.DeclareAbstractInputPort("health", AbstractValue.Make(TrackerHealth()))
        self.DeclareVectorOutputPort(
            "usable", 1, lambda c, o: o.SetAtIndex(
                0, float(health.Eval(c).state != HealthState.LOST)),
            {health.ticket()})


@dataclass
class Feedback:
    """What one feedback gives the controller."""

    #: AbstractValue[RigidTransform]: the hand in the camera frame.
    X_CE: OutputPort
    #: The robot joints' angles (``robot_joint_names`` order), for the Jacobian.
    joints: OutputPort
    #: 1 while the feed may be acted on (the tracker's health); None: always.
    usable: OutputPort | None = None
    #: The tracker's systems in run (b).
    tracker: TrackerSystems | None = None


def AddFeedback(builder: DiagramBuilder, world: ServoWorld, feedback: str,
                params: TrackerParams | None = None) -> Feedback:
    """The ports of ``feedback`` (one of ``FEEDBACKS``); ``tracker`` adds the tracker,
    which needs the world's depth camera."""
    require_one_of(feedback, FEEDBACKS, "feedback")
    if feedback == "truth":
        return Feedback(world.ports["true_X_CE"], world.ports["true_position"])
    if feedback == "encoders":
        fk = builder.AddNamedSystem("encoders_X_CE", EncoderKinematicsPose(
            world.robot_config, world.robot_joint_names))
        builder.Connect(world.ports["measured_position"], fk.get_input_port(0))
        return Feedback(fk.GetOutputPort("X_CE"), world.ports["measured_position"])
    if "depth_frame" not in world.ports:
        raise ValueError("feedback 'tracker' needs the world's depth camera "
                         "(AddServoWorld(..., with_camera=True))")
    tracker = AddTracker(builder, model=world.model, camera=camera_model(world.scenario),
                         params=params or TrackerParams(),
                         measured_position=world.ports["measured_position"],
                         measurement_time=world.ports["measurement_time"],
                         depth=world.ports["depth_frame"], encoder_period_s=world.encoder_period_s)
    # The tracker estimates every model joint (the virtual camera joints too): keep the
    # robot's, in robot_joint_names order.
    names = world.model.joint_names
    select = np.zeros((len(world.robot_joint_names), len(names)))
    for row, name in enumerate(world.robot_joint_names):
        select[row, names.index(name)] = 1.0
    robot_joints = builder.AddNamedSystem("tracker_robot_joints", MatrixGain(select))
    builder.Connect(tracker.estimated_position, robot_joints.get_input_port())
    usable = builder.AddNamedSystem("tracker_health_to_usable", HealthToUsable())
    builder.Connect(tracker.health, usable.get_input_port(0))
    return Feedback(tracker.X_CE, robot_joints.get_output_port(),
                    usable.GetOutputPort("usable"), tracker)
