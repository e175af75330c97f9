"""The servo controller: a Cartesian pose-error law in the camera frame, turned into arm
joint commands by Drake's differential inverse kinematics.

Every ``control_period_s`` the :class:`CameraFrameServo`

1. reads the hand pose it is fed, ``X_CE`` (the end effector E in the camera frame C;
   from the encoders, the tracker or the truth: ``drake_tracker.servo.feedback``), and
   the current target ``X_CT``;
2. asks for the hand velocity ``V = [k_r * angle-axis(R_CT R_CE^T); k_t * (p_CT - p_CE)]``
   (spatial velocity of E in C, expressed in C; :func:`cartesian_velocity_command`),
   capped at the configured speeds;
3. solves for arm joint velocities with ``DoDifferentialInverseKinematics`` (a QP: J v
   along V, joint position and speed limits, the null space pulled towards the start
   pose), with J the Jacobian of E in C of the NOMINAL robot model at the commanded
   angles corrected by the feedback's joint estimate (``q_cmd + estimate - reading``:
   the encoders' own angles in run (a), the tracker's bias-corrected ones in (b), the
   true ones in (c));
4. integrates them into the commanded arm angles (encoder coordinates), which the
   robot's joint servo holds (``drake_tracker.servo.world``).

The same controller runs in the three runs of the study; only its ``X_CE`` input differs.
Before the first encoder reading it outputs an invalid command (the joint servo holds
home); until ``hold_s`` it holds the first reading; and it holds the arm while its
optional ``feedback_usable`` input is 0 (the tracker's health is ``LOST``).
"""

from __future__ import annotations

import logging
import time

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import (
    DifferentialInverseKinematicsParameters,
    DifferentialInverseKinematicsStatus,
    DoDifferentialInverseKinematics,
)
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import LeafSystem

from drake_tracker.robot.model import RobotConfig, add_robot
from drake_tracker.servo.config import ServoGains, ServoStudyConfig

LOGGER = logging.getLogger("drake_tracker.servo")
#: At most one warning of each kind this often (s of wall-clock time).
WARNING_INTERVAL_S = 5.0


def cartesian_velocity_command(X_CE: RigidTransform, X_CT: RigidTransform,
                               gains: ServoGains) -> np.ndarray:
    """(6,) desired spatial velocity [w; v] of E in C, expressed in C, that drives X_CE to
    X_CT: proportional to the rotation (angle-axis) and translation errors, capped."""
    rotation_error = X_CT.rotation().multiply(X_CE.rotation().inverse()).ToAngleAxis()
    w = gains.rotation_gain_per_s * rotation_error.angle() * rotation_error.axis()
    v = gains.translation_gain_per_s * (X_CT.translation() - X_CE.translation())
    w = _capped(w, np.radians(gains.max_angular_speed_deg_per_s))
    v = _capped(v, gains.max_speed_m_per_s)
    return np.concatenate([w, v])


def _capped(vector: np.ndarray, limit: float) -> np.ndarray:
    norm = float(np.linalg.norm(vector))
    return vector if norm <= limit else vector * (limit / norm)


class _RateLimitedWarning:
    """Logs a message at most once per ``WARNING_INTERVAL_S``, with a count of the rest."""

    def __init__(self):
        self._last = -np.inf
        self._skipped = 0

    def __call__(self, message: str) -> None:
        now = time.monotonic()
        if now - self._last < WARNING_INTERVAL_S:
            self._skipped += 1
            return
        more = f" ({self._skipped} more since the last warning)" if self._skipped else ""
        LOGGER.warning(message + more)
        self._last, self._skipped = now, 0


class CameraFrameServo(LeafSystem):
    """The study's controller (module doc).

    .. pydrake_system::

        name: CameraFrameServo
        input_ports:
        - X_CE
        - estimated_position
        - measured_position
        - measurement_time
        - feedback_usable (optional)
        output_ports:
        - arm_command
        - target_index

    ``X_CE``: AbstractValue[RigidTransform], the hand in the camera frame it is fed;
    ``estimated_position`` (n): the robot joints' angles it is fed (for the Jacobian);
    ``measured_position`` (n) and ``measurement_time`` (1): the encoders, in
    ``robot_joint_names`` order; ``feedback_usable`` (1, optional): 0 = do not act on
    the feed. ``arm_command`` (1 + 2m): [valid, q, v] of the arm
    joints in encoder coordinates; ``target_index`` (1): the target servoed to (-1
    during the hold). Discrete state: [valid, q (m), v (m), q_start (m)].
    """

    def __init__(self, robot_config: RobotConfig, robot_joint_names: list[str],
                 arm_joint_names: list[str], config: ServoStudyConfig):
        super().__init__()
        self._config = config
        self._gains = config.gains
        self._targets = [t.X_CT() for t in config.targets]
        self._plant = MultibodyPlant(time_step=0.0)
        add_robot(self._plant, robot_config)
        self._plant.Finalize()
        self._plant_context = self._plant.CreateDefaultContext()
        self._C = self._plant.GetFrameByName(robot_config.camera_frame)
        self._E = self._plant.GetFrameByName(robot_config.end_effector_frame)
        joints = [self._plant.GetJointByName(n) for n in robot_joint_names]
        self._robot_q_rows = np.array([j.position_start() for j in joints])
        self._arm_in_robot = np.array([robot_joint_names.index(n) for n in arm_joint_names])
        arm = [self._plant.GetJointByName(n) for n in arm_joint_names]
        self._arm_v_cols = np.array([j.velocity_start() for j in arm])
        self._lower = np.array([j.position_lower_limits()[0] for j in arm])
        self._upper = np.array([j.position_upper_limits()[0] for j in arm])
        m = len(arm_joint_names)
        self._m = m
        self._warn_feedback = _RateLimitedWarning()
        self._warn_ik = _RateLimitedWarning()
        self.DeclareAbstractInputPort("X_CE", AbstractValue.Make(RigidTransform()))
        self.DeclareVectorInputPort("estimated_position", len(robot_joint_names))
        self.DeclareVectorInputPort("measured_position", len(robot_joint_names))
        self.DeclareVectorInputPort("measurement_time", 1)
        self._usable = self.DeclareVectorInputPort("feedback_usable", 1)
        self._state = self.DeclareDiscreteState(np.zeros(1 + 3 * m))
        ticket = {self.discrete_state_ticket(self._state)}
        self.DeclareVectorOutputPort(
            "arm_command", 1 + 2 * m,
            lambda c, o: o.SetFromVector(c.get_discrete_state(self._state).get_value()[
                :1 + 2 * m]), ticket)
        self.DeclareVectorOutputPort(
            "target_index", 1,
            lambda c, o: o.SetAtIndex(0, self._config.target_index(c.get_time())),
            {self.time_ticket()})
        self.DeclarePeriodicDiscreteUpdateEvent(self._gains.control_period_s, 0.0,
                                                self._update)

    def _update(self, context, discrete_state) -> None:
        m = self._m
        x = context.get_discrete_state(self._state).get_value().copy()
        readings = self.GetInputPort("measured_position").Eval(context)
        if x[0] < 0.5:
            if self.GetInputPort("measurement_time").Eval(context)[0] >= 0:
                q = readings[self._arm_in_robot]
                x = np.concatenate([[1.0], q, np.zeros(m), q])
                discrete_state.get_mutable_vector(self._state).SetFromVector(x)
            return
        t = context.get_time()
        q, v_previous, q_start = x[1:1 + m], x[1 + m:1 + 2 * m], x[1 + 2 * m:]
        v = np.zeros(m)
        usable = (not self._usable.HasValue(context)
                  or self._usable.Eval(context)[0] > 0.5)
        if t >= self._config.hold_s and usable:
            v = self._joint_velocities(context, t, readings, q, v_previous, q_start)
        x[1:1 + m] = q + self._gains.control_period_s * v
        x[1 + m:1 + 2 * m] = v
        discrete_state.get_mutable_vector(self._state).SetFromVector(x)

    def _joint_velocities(self, context, t: float, readings: np.ndarray, q: np.ndarray,
                          v_previous: np.ndarray, q_start: np.ndarray) -> np.ndarray:
        X_CE = self.GetInputPort("X_CE").Eval(context)
        matrix = X_CE.GetAsMatrix4()
        if not np.all(np.isfinite(matrix)):
            self._warn_feedback(f"servo: the X_CE feedback is not finite at t = {t:.3f} s; "
                                "holding the arm")
            return np.zeros(self._m)
        X_CE = RigidTransform(RotationMatrix.ProjectToRotationMatrix(matrix[:3, :3]),
                              matrix[:3, 3])
        target = self._targets[max(self._config.target_index(t), 0)]
        V = cartesian_velocity_command(X_CE, target, self._gains)
        estimate = self.GetInputPort("estimated_position").Eval(context)
        J = self._jacobian(estimate, q + estimate[self._arm_in_robot]
                           - readings[self._arm_in_robot])
        result = DoDifferentialInverseKinematics(q, v_previous, V, J,
                                                 self._ik_parameters(q_start))
        if result.status != DifferentialInverseKinematicsStatus.kSolutionFound:
            self._warn_ik(f"servo: differential IK found no solution at t = {t:.3f} s "
                          f"({result.status}); holding the arm")
            return np.zeros(self._m)
        return np.asarray(result.joint_velocities, float).ravel()

    def _jacobian(self, estimate: np.ndarray, q_arm: np.ndarray) -> np.ndarray:
        """(6, m) Jacobian of E's spatial velocity in C (expressed in C) w.r.t. the arm
        joints, nominal model, arm at ``q_arm`` and the other joints at ``estimate``."""
        robot_q = np.array(estimate, float)
        robot_q[self._arm_in_robot] = q_arm
        q = self._plant.GetPositions(self._plant_context)
        q[self._robot_q_rows] = robot_q
        self._plant.SetPositions(self._plant_context, q)
        J = self._plant.CalcJacobianSpatialVelocity(
            self._plant_context, JacobianWrtVariable.kV, self._E, np.zeros(3), self._C,
            self._C)
        return J[:, self._arm_v_cols]

    def _ik_parameters(self, q_start: np.ndarray) -> DifferentialInverseKinematicsParameters:
        m, g = self._m, self._gains
        params = DifferentialInverseKinematicsParameters(m, m)
        params.set_time_step(g.control_period_s)
        speed = np.radians(g.max_joint_speed_deg_per_s)
        params.set_joint_velocity_limits((np.full(m, -speed), np.full(m, speed)))
        params.set_joint_position_limits((self._lower, self._upper))
        params.set_nominal_joint_position(q_start)
        params.set_joint_centering_gain(g.joint_centering_gain_per_s * np.eye(m))
        return params
