"""Ground truth of the simulated world, read from the WORLD plant's positions."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame
from pydrake.systems.framework import LeafSystem

from drake_tracker.robot.model import DEFAULT_CAMERA_NAME, virtual_joint_names_of
from drake_tracker.sim.reference import position_joint_names


class TruthSystem(LeafSystem):
    """Ground truth from the plant's positions.

    .. pydrake_system::

        name: TruthSystem
        input_ports:
        - positions
        output_ports:
        - true_position
        - true_camera_offset
        - true_camera_offsets
        - true_X_CE

    ``true_position`` (n): the robot joints (rad), order ``robot_joint_names``;
    ``true_camera_offset`` (6): the first camera's virtual joints [x y z (m), rx ry rz
    (rad)]; ``true_camera_offsets`` (6 per camera): every camera's, ``camera_names`` order;
    ``true_X_CE``: AbstractValue[RigidTransform], the end effector in the TRUE camera
    frame (m), both frames of ``plant`` (the world's robot, which may differ from the
    tracker's model).
    """

    def __init__(self, plant: MultibodyPlant, robot_joint_names: list[str],
                 camera_frame: Frame, end_effector_frame: Frame,
                 camera_names: tuple[str, ...] = (DEFAULT_CAMERA_NAME,)):
        super().__init__()
        self._plant = plant
        self._context = plant.CreateDefaultContext()
        names = position_joint_names(plant)
        self._robot_idx = np.array([names.index(n) for n in robot_joint_names])
        self._virtual_idx = np.array([names.index(n)
                                      for n in virtual_joint_names_of(camera_names[0])])
        every = [names.index(n) for c in camera_names for n in virtual_joint_names_of(c)]
        self._all_virtual_idx = np.array(every)
        self._camera_frame = camera_frame
        self._ee_frame = end_effector_frame
        self._positions = self.DeclareVectorInputPort("positions", plant.num_positions())
        positions = {self._positions.ticket()}  # what every output depends on
        self.DeclareVectorOutputPort("true_position", len(self._robot_idx),
                                     lambda c, o: o.SetFromVector(self._q(c)[self._robot_idx]),
                                     positions)
        self.DeclareVectorOutputPort(
            "true_camera_offset", 6, lambda c, o: o.SetFromVector(self._q(c)[self._virtual_idx]),
            positions)
        self.DeclareVectorOutputPort(
            "true_camera_offsets", len(every),
            lambda c, o: o.SetFromVector(self._q(c)[self._all_virtual_idx]), positions)
        self.DeclareAbstractOutputPort("true_X_CE", lambda: AbstractValue.Make(RigidTransform()),
                                       self._calc_X_CE, positions)

    def _q(self, context) -> np.ndarray:
        return self._positions.Eval(context)

    def _calc_X_CE(self, context, output):
        self._plant.SetPositions(self._context, self._q(context))
        output.set_value(self._plant.CalcRelativeTransform(self._context, self._camera_frame,
                                                           self._ee_frame))
