"""Batched forward kinematics of a MultibodyPlant, vectorised over particles.

The kinematic tree (joint types, axes, frame offsets, parent/child bodies) is read once
from a finalized ``MultibodyPlant``; nothing is written by hand for a particular robot.
Evaluating the poses of all bodies for N configurations loops over the joints only and
is vectorised over the N configurations with numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.tree import BodyIndex, JointIndex

_REVOLUTE, _PRISMATIC, _WELD = 0, 1, 2
_SUPPORTED = {"revolute": _REVOLUTE, "prismatic": _PRISMATIC, "weld": _WELD}


@dataclass(frozen=True)
class _JointStep:
    """One joint of the tree in a form that FK can evaluate without the plant.

    The pose of the outboard body is ``X_W_out = X_W_in @ A @ X_FM(q) @ B``, where for
    a joint modelled from parent to child ``A = X_PF`` and ``B = X_MC``. If the tree
    reaches the joint from its child side (``reversed``), FK goes the other way:
    ``X_W_P = X_W_C @ inv(B) @ inv(X_FM(q)) @ inv(A)``.
    """

    kind: int
    inboard: int  # body index whose pose is known when this step runs
    outboard: int  # body index this step computes
    q_index: int  # -1 for welds
    axis: np.ndarray  # unit axis in F (revolute / prismatic)
    A: np.ndarray  # 4x4 constant on the inboard side
    B: np.ndarray  # 4x4 constant on the outboard side
    X_FM: np.ndarray  # 4x4 constant X_FM for welds
    reversed: bool


def _to4(X) -> np.ndarray:
    """A RigidTransform as a 4x4 numpy array."""
    return np.asarray(X.GetAsMatrix4(), dtype=float)


def _inv4(X: np.ndarray) -> np.ndarray:
    """Inverse of rigid transform(s) ``(..., 4, 4)``."""
    R = X[..., :3, :3]
    p = X[..., :3, 3]
    out = np.zeros_like(X)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, p)
    out[..., 3, 3] = 1.0
    return out


def _axis_transforms(kind: int, axis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """X_FM(q) for all N values of q (N,) of a revolute or prismatic joint: (N, 4, 4)."""
    n = q.shape[0]
    X = np.zeros((n, 4, 4))
    X[:, 3, 3] = 1.0
    if kind == _PRISMATIC:
        X[:, 0, 0] = X[:, 1, 1] = X[:, 2, 2] = 1.0
        X[:, :3, 3] = q[:, None] * axis[None, :]
        return X
    # Rodrigues: R = I + sin(q) K + (1 - cos(q)) K^2, with K the cross matrix of axis.
    K = np.array(
        [[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]]
    )
    K2 = K @ K
    s = np.sin(q)[:, None, None]
    c1 = (1.0 - np.cos(q))[:, None, None]
    X[:, :3, :3] = np.eye(3)[None] + s * K[None] + c1 * K2[None]
    return X


class BatchedKinematics:
    """Forward kinematics of a plant's tree for many configurations at once.

    Build it with :meth:`from_plant`. Supports revolute, prismatic and weld joints;
    any other joint type (including the floating joints that a finalized plant adds to
    free bodies) raises a ValueError naming the joint.
    """

    def __init__(self, plant, steps: list[_JointStep], num_positions: int, num_bodies: int):
        self._plant = plant
        self._steps = steps
        self._num_positions = num_positions
        self._num_bodies = num_bodies

    @staticmethod
    def from_plant(plant) -> BatchedKinematics:
        if not plant.is_finalized():
            raise ValueError("BatchedKinematics.from_plant: the plant must be finalized")
        num_bodies = plant.num_bodies()
        joints = [plant.get_joint(JointIndex(i)) for i in range(plant.num_joints())]
        adjacency: dict[int, list] = {b: [] for b in range(num_bodies)}
        for joint in joints:
            type_name = joint.type_name()
            if type_name not in _SUPPORTED:
                raise ValueError(
                    f"BatchedKinematics: joint '{joint.name()}' has unsupported type "
                    f"'{type_name}'; supported: {sorted(_SUPPORTED)}"
                )
            p = int(joint.parent_body().index())
            c = int(joint.child_body().index())
            adjacency[p].append(joint)
            adjacency[c].append(joint)

        # Breadth-first from the world body gives a topological order.
        steps: list[_JointStep] = []
        known = {0}
        frontier = [0]
        while frontier:
            nxt = []
            for body in frontier:
                for joint in adjacency[body]:
                    p = int(joint.parent_body().index())
                    c = int(joint.child_body().index())
                    other = c if p == body else p
                    if other in known:
                        continue
                    steps.append(BatchedKinematics._make_step(joint, body == c))
                    known.add(other)
                    nxt.append(other)
            frontier = nxt
        missing = sorted(set(range(num_bodies)) - known)
        if missing:
            names = [plant.get_body(BodyIndex(b)).name() for b in missing]
            raise ValueError(f"BatchedKinematics: bodies not connected to the world: {names}")
        return BatchedKinematics(plant, steps, plant.num_positions(), num_bodies)

    @staticmethod
    def _make_step(joint, reversed_: bool) -> _JointStep:
        kind = _SUPPORTED[joint.type_name()]
        A = _to4(joint.frame_on_parent().GetFixedPoseInBodyFrame())  # X_PF
        B = _inv4(_to4(joint.frame_on_child().GetFixedPoseInBodyFrame()))  # X_MC
        axis = np.zeros(3)
        X_FM = np.eye(4)
        q_index = -1
        if kind == _REVOLUTE:
            axis = np.asarray(joint.revolute_axis(), float)
        elif kind == _PRISMATIC:
            axis = np.asarray(joint.translation_axis(), float)
        else:
            X_FM = _to4(joint.X_FM())
        if kind != _WELD:
            axis = axis / np.linalg.norm(axis)
            q_index = int(joint.position_start())
        p = int(joint.parent_body().index())
        c = int(joint.child_body().index())
        if reversed_:
            return _JointStep(kind, c, p, q_index, axis, _inv4(B), _inv4(A), _inv4(X_FM), True)
        return _JointStep(kind, p, c, q_index, axis, A, B, X_FM, False)

    @property
    def num_positions(self) -> int:
        return self._num_positions

    @property
    def num_bodies(self) -> int:
        return self._num_bodies

    def _check_q(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.ndim == 1:
            q = q[None, :]
        if q.ndim != 2 or q.shape[1] != self._num_positions:
            raise ValueError(
                f"BatchedKinematics: q must have shape (N, {self._num_positions}) or "
                f"({self._num_positions},), got {np.shape(q)}"
            )
        if not np.all(np.isfinite(q)):
            raise ValueError("BatchedKinematics: q contains NaN or infinite values")
        return q

    def body_poses(self, q: np.ndarray) -> np.ndarray:
        """World poses X_WB of all bodies, (N, num_bodies, 4, 4), indexed by BodyIndex."""
        q = self._check_q(q)
        n = q.shape[0]
        X = np.empty((n, self._num_bodies, 4, 4))
        X[:, 0] = np.eye(4)
        for s in self._steps:
            X_in_A = X[:, s.inboard] @ s.A
            if s.kind == _WELD:
                X_FM = s.X_FM
                X[:, s.outboard] = (X_in_A @ X_FM) @ s.B
                continue
            X_FM = _axis_transforms(s.kind, s.axis, q[:, s.q_index])
            if s.reversed:
                X_FM = _inv4(X_FM)
            X[:, s.outboard] = (X_in_A @ X_FM) @ s.B
        return X

    def frame_poses(self, q: np.ndarray, frame) -> np.ndarray:
        """World pose X_WF of a plant Frame (body or fixed-offset frame), (N, 4, 4)."""
        X_WB = self.body_poses(q)[:, int(frame.body().index())]
        return X_WB @ _to4(frame.GetFixedPoseInBodyFrame())

    def relative_poses(self, q: np.ndarray, frame_A) -> np.ndarray:
        """Poses X_AB of all bodies in frame A, (N, num_bodies, 4, 4)."""
        X_WB = self.body_poses(q)
        X_BF = _to4(frame_A.GetFixedPoseInBodyFrame())
        X_WA = X_WB[:, int(frame_A.body().index())] @ X_BF
        return _inv4(X_WA)[:, None] @ X_WB
