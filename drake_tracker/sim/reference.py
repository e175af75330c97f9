"""The world's reference motion and the two ways to realise it.

The robot joints follow ``make_joint_trajectory``; the six virtual joints are the TRUE
camera offset ``camera.offset + sum_j gain_j * q_j`` (``offset_gain_per_rad``).
:class:`TrajectoryPlayback` plays the positions back exactly (kinematic mode);
:class:`InverseDynamicsTracking` drives a discrete plant along them (dynamic mode).
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import MultibodyForces
from pydrake.systems.framework import BasicVector, LeafSystem

from drake_tracker.robot.model import virtual_joint_names_of
from drake_tracker.sim.scenario.config import CameraConfig, Scenario
from drake_tracker.sim.scenario.validation import require
from drake_tracker.sim.trajectories import JointTrajectory


def position_joint_names(plant: MultibodyPlant) -> list[str]:
    """Names of the plant's single-DoF joints in position-vector order (as
    ``drake_tracker.robot.model.joint_names``, but also for a plant with removed joints)."""
    joints = [plant.get_joint(index) for index in plant.GetJointIndices()]
    joints = sorted((j for j in joints if j.num_positions() == 1),
                    key=lambda j: j.position_start())
    require(len(joints) == plant.num_positions(), "world plant", plant.num_positions(),
            "only single-DoF joints (revolute, prismatic) are supported")
    return [j.name() for j in joints]


def offset_gain_matrix(scenario: Scenario, robot_joint_names: list[str],
                       camera: CameraConfig | None = None) -> np.ndarray:
    """(6, n) gains of the configuration-dependent offset of ``camera`` (default:
    ``scenario.camera``), per rad of each joint."""
    camera = scenario.camera if camera is None else camera
    G = np.zeros((6, len(robot_joint_names)))
    for name, gains in camera.offset_gain_per_rad.items():
        require(name in robot_joint_names, "camera.offset_gain_per_rad", name,
                f"no such joint; joints: {robot_joint_names}")
        G[:, robot_joint_names.index(name)] = gains
    return G


class ReferenceMotion:
    """The world's reference positions of every plant joint as a pure function of time."""

    def __init__(self, plant: MultibodyPlant, scenario: Scenario, trajectory: JointTrajectory,
                 robot_joint_names: list[str]):
        self._trajectory = trajectory
        names = position_joint_names(plant)
        self._robot_idx = np.array([names.index(n) for n in robot_joint_names])
        cameras = scenario.resolved_cameras()
        self._virtual_idx = [np.array([names.index(n) for n in virtual_joint_names_of(c.name)])
                             for c in cameras]
        self._offsets = [np.asarray(c.offset, float) for c in cameras]
        self._gains = [offset_gain_matrix(scenario, robot_joint_names, c) for c in cameras]
        self.num_positions = plant.num_positions()

    def camera_offset(self, robot_q: np.ndarray, camera: int = 0) -> np.ndarray:
        """(6,) true virtual joint values of the ``camera``-th camera (the first: the
        one camera) for robot joint angles ``robot_q``."""
        return self._offsets[camera] + self._gains[camera] @ np.asarray(robot_q, float)

    def velocities(self, t: float, h: float = 1e-4) -> np.ndarray:
        """(nv,) central differences of ``positions`` (every joint is single-DoF)."""
        return (self.positions(t + h) - self.positions(t - h)) / (2 * h)

    def positions(self, t: float) -> np.ndarray:
        """(nq,) plant positions at time ``t`` (s)."""
        q = np.zeros(self.num_positions)
        robot_q = self._trajectory.position_at(t)
        q[self._robot_idx] = robot_q
        for k, virtual in enumerate(self._virtual_idx):
            q[virtual] = self.camera_offset(robot_q, k)
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
        self._state = self.DeclareVectorInputPort("state", nq + nv)
        self.DeclareVectorOutputPort("generalized_force", nv, self._calc,
                                     {self.time_ticket(), self._state.ticket()})

    def _calc(self, context, output: BasicVector):
        t, h = context.get_time(), 1e-4
        q_m, q_0, q_p = (self._reference.positions(s) for s in (t - h, t, t + h))
        v_ref = (q_p - q_m) / (2 * h)
        a_ref = (q_p - 2 * q_0 + q_m) / (h * h)
        x = self._state.Eval(context)
        q, v = x[:self._nq], x[self._nq:]
        vdot = a_ref + self._kp * (q_0 - q) + self._kd * (v_ref - v)
        self._plant.SetPositionsAndVelocities(self._context, x)
        # CalcInverseDynamics takes the applied forces as given: add gravity (the force
        # elements) so that it is compensated.
        self._forces.SetZero()
        self._plant.CalcForceElementsContribution(self._context, self._forces)
        tau = self._plant.CalcInverseDynamics(self._context, vdot, self._forces)
        output.SetFromVector(tau)
