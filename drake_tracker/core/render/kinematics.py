"""Batched forward kinematics of a MultibodyPlant, vectorised over particles.

The kinematic tree (joint types, axes, frame offsets, parent/child bodies) is read once
from a finalized ``MultibodyPlant``; nothing is written by hand for a particular robot.
Evaluating the poses of all bodies for N configurations loops over the joints only and
runs in a numba kernel, in parallel over the N configurations.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit, prange
from pydrake.multibody.tree import BodyIndex, JointIndex

from drake_tracker.core.jit.numba_threading import pick_kernel, serial_and_parallel

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from pydrake.multibody.plant import MultibodyPlant
    from pydrake.multibody.tree import Frame

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


def rigid_inverse(X: np.ndarray) -> np.ndarray:
    """Inverse of rigid transform(s) ``(..., 4, 4)``."""
    R = X[..., :3, :3]
    p = X[..., :3, 3]
    out = np.zeros_like(X)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, p)
    out[..., 3, 3] = 1.0
    return out


@njit(cache=True, inline="always")
def _step_pose(X, n, s, q, kind, inboard, outboard, q_index, axis, A, B, rev, T, M):
    """X[outboard] = X[inboard] @ A[s] @ X_FM(q) @ B[s] for particle n (3x4 parts only;
    row 3 of every pose is [0, 0, 0, 1]). ``T`` and ``M`` are 4x4 scratch."""
    i = inboard[s]
    o = outboard[s]
    # M = X[i] @ A[s]
    for r in range(3):
        for c in range(4):
            M[r, c] = (X[i, r, 0] * A[s, 0, c] + X[i, r, 1] * A[s, 1, c]
                       + X[i, r, 2] * A[s, 2, c])
        M[r, 3] += X[i, r, 3]
    k = kind[s]
    if k == 2:  # weld: A[s] already holds X_PF @ X_FM, B[s] as usual
        for r in range(3):
            for c in range(4):
                X[o, r, c] = M[r, 0] * B[s, 0, c] + M[r, 1] * B[s, 1, c] + M[r, 2] * B[s, 2, c]
            X[o, r, 3] += M[r, 3]
        return
    qv = q[n, q_index[s]]
    ax = axis[s, 0]
    ay = axis[s, 1]
    az = axis[s, 2]
    if rev[s]:
        qv = -qv
    # T = X_FM(q) (inverse for reversed joints: negated angle / translation).
    if k == 0:
        sn = np.sin(qv)
        c1 = 1.0 - np.cos(qv)
        T[0, 0] = 1.0 - c1 * (ay * ay + az * az)
        T[0, 1] = -sn * az + c1 * ax * ay
        T[0, 2] = sn * ay + c1 * ax * az
        T[1, 0] = sn * az + c1 * ax * ay
        T[1, 1] = 1.0 - c1 * (ax * ax + az * az)
        T[1, 2] = -sn * ax + c1 * ay * az
        T[2, 0] = -sn * ay + c1 * ax * az
        T[2, 1] = sn * ax + c1 * ay * az
        T[2, 2] = 1.0 - c1 * (ax * ax + ay * ay)
        T[0, 3] = 0.0
        T[1, 3] = 0.0
        T[2, 3] = 0.0
    else:
        for r in range(3):
            for c in range(3):
                T[r, c] = 1.0 if r == c else 0.0
        T[0, 3] = qv * ax
        T[1, 3] = qv * ay
        T[2, 3] = qv * az
    # X[o] = (M @ T) @ B[s]
    for r in range(3):
        m0 = M[r, 0] * T[0, 0] + M[r, 1] * T[1, 0] + M[r, 2] * T[2, 0]
        m1 = M[r, 0] * T[0, 1] + M[r, 1] * T[1, 1] + M[r, 2] * T[2, 1]
        m2 = M[r, 0] * T[0, 2] + M[r, 1] * T[1, 2] + M[r, 2] * T[2, 2]
        m3 = M[r, 0] * T[0, 3] + M[r, 1] * T[1, 3] + M[r, 2] * T[2, 3] + M[r, 3]
        for c in range(4):
            X[o, r, c] = m0 * B[s, 0, c] + m1 * B[s, 1, c] + m2 * B[s, 2, c]
        X[o, r, 3] += m3


@njit(cache=True, nogil=True)
def _body_poses_one(X, n, q, kind, inboard, outboard, q_index, axis, A, B, rev, T, M):
    for r in range(4):
        for c in range(4):
            X[0, r, c] = 1.0 if r == c else 0.0
    for b in range(1, X.shape[0]):
        X[b, 3, 0] = 0.0
        X[b, 3, 1] = 0.0
        X[b, 3, 2] = 0.0
        X[b, 3, 3] = 1.0
    for s in range(kind.shape[0]):
        _step_pose(X, n, s, q, kind, inboard, outboard, q_index, axis, A, B, rev, T, M)


def _body_poses_particles(q, kind, inboard, outboard, q_index, axis, A, B, rev, out):
    for n in prange(q.shape[0]):
        T = np.empty((4, 4))
        M = np.empty((4, 4))
        _body_poses_one(out[n], n, q, kind, inboard, outboard, q_index, axis, A, B, rev, T, M)


@njit(cache=True)  # no nogil: PoseReadout calls it from the Simulator's thread
def relative_poses_one(n: int, q: np.ndarray, kind: np.ndarray, inboard: np.ndarray,
                       outboard: np.ndarray, q_index: np.ndarray, axis: np.ndarray,
                       A: np.ndarray, B: np.ndarray, rev: np.ndarray, frame_body: int,
                       X_BF: np.ndarray, X: np.ndarray, Y: np.ndarray, T: np.ndarray,
                       M: np.ndarray) -> None:
    """Y[b] = inv(X_W_body(frame_body) @ X_BF) @ X_WB[b] for particle n of q: the poses of
    all bodies in frame A (fixed at X_BF on body ``frame_body``). ``X`` (num_bodies, 4, 4)
    and ``T``, ``M`` (4, 4) are scratch; ``Y`` (num_bodies, 4, 4) the output."""
    nb = Y.shape[0]
    _body_poses_one(X, n, q, kind, inboard, outboard, q_index, axis, A, B, rev, T, M)
    # M = X_WA = X[frame_body] @ X_BF, then T = inv(X_WA) (rigid).
    f = frame_body
    for r in range(3):
        for c in range(4):
            M[r, c] = (X[f, r, 0] * X_BF[0, c] + X[f, r, 1] * X_BF[1, c]
                       + X[f, r, 2] * X_BF[2, c])
        M[r, 3] += X[f, r, 3]
    for r in range(3):
        for c in range(3):
            T[r, c] = M[c, r]
        T[r, 3] = -(M[0, r] * M[0, 3] + M[1, r] * M[1, 3] + M[2, r] * M[2, 3])
    for b in range(nb):
        for r in range(3):
            for c in range(4):
                Y[b, r, c] = T[r, 0] * X[b, 0, c] + T[r, 1] * X[b, 1, c] + T[r, 2] * X[b, 2, c]
            Y[b, r, 3] += T[r, 3]
        Y[b, 3, 0] = 0.0
        Y[b, 3, 1] = 0.0
        Y[b, 3, 2] = 0.0
        Y[b, 3, 3] = 1.0


def _relative_poses_particles(q, kind, inboard, outboard, q_index, axis, A, B, rev,
                           frame_body, X_BF, out):
    """out[n, b] = inv(X_W_body(frame_body) @ X_BF) @ X_WB[n, b]."""
    nb = out.shape[1]
    for n in prange(q.shape[0]):
        T = np.empty((4, 4))
        M = np.empty((4, 4))
        X = np.empty((nb, 4, 4))
        relative_poses_one(n, q, kind, inboard, outboard, q_index, axis, A, B, rev,
                           frame_body, X_BF, X, out[n], T, M)


_body_poses_serial, _body_poses_parallel = serial_and_parallel(_body_poses_particles,
                                                               nogil=True)
_relative_serial, _relative_parallel = serial_and_parallel(_relative_poses_particles,
                                                           nogil=True)


class BatchedKinematics:
    """Forward kinematics of a plant's tree for many configurations at once.

    Build it with :meth:`from_plant`. Supports revolute, prismatic and weld joints;
    any other joint type (including the floating joints that a finalized plant adds to
    free bodies) raises a ValueError naming the joint.
    """

    def __init__(self, plant: MultibodyPlant, steps: list[_JointStep], num_positions: int,
                 num_bodies: int):
        self._plant = plant
        self._steps = steps
        self._num_positions = num_positions
        self._num_bodies = num_bodies
        # The steps as flat arrays for the numba kernels. Welds fold X_FM into A; reversed
        # joints use inv(X_FM(q)) = X_FM(-q) (a rotation or translation along the axis).
        S = len(steps)
        self._kind = np.array([s.kind for s in steps], dtype=np.int64).reshape(S)
        self._inboard = np.array([s.inboard for s in steps], dtype=np.int64).reshape(S)
        self._outboard = np.array([s.outboard for s in steps], dtype=np.int64).reshape(S)
        self._q_index = np.array([max(s.q_index, 0) for s in steps], dtype=np.int64).reshape(S)
        self._axis = np.array([s.axis for s in steps], dtype=float).reshape(S, 3)
        self._A = np.array([s.A @ s.X_FM if s.kind == _WELD else s.A for s in steps],
                           dtype=float).reshape(S, 4, 4)
        self._B = np.array([s.B for s in steps], dtype=float).reshape(S, 4, 4)
        self._rev = np.array([s.reversed for s in steps], dtype=np.bool_).reshape(S)

    def _tables(self):
        return (self._kind, self._inboard, self._outboard, self._q_index, self._axis,
                self._A, self._B, self._rev)

    @staticmethod
    def from_plant(plant: MultibodyPlant) -> BatchedKinematics:
        """The kinematics of a finalized ``plant``, its joints ordered breadth-first from the
        world body. ValueError for a plant not finalized, an unsupported joint type, or a body
        not connected to the world."""
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
        B = rigid_inverse(_to4(joint.frame_on_child().GetFixedPoseInBodyFrame()))  # X_MC
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
            return _JointStep(kind, c, p, q_index, axis, rigid_inverse(B), rigid_inverse(A),
                              rigid_inverse(X_FM), True)
        return _JointStep(kind, p, c, q_index, axis, A, B, X_FM, False)

    @property
    def num_positions(self) -> int:
        """nq, the plant's number of positions (the width of ``q``)."""
        return self._num_positions

    @property
    def num_bodies(self) -> int:
        """The plant's number of bodies, the world body included."""
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
        q = np.ascontiguousarray(self._check_q(q))
        X = np.empty((q.shape[0], self._num_bodies, 4, 4))
        if q.shape[0]:
            pick_kernel(_body_poses_serial, _body_poses_parallel)(q, *self._tables(), X)
        return X

    def frame_poses(self, q: np.ndarray, frame: Frame) -> np.ndarray:
        """World pose X_WF of a plant Frame (body or fixed-offset frame), (N, 4, 4)."""
        X_WB = self.body_poses(q)[:, int(frame.body().index())]
        return X_WB @ _to4(frame.GetFixedPoseInBodyFrame())

    def frame_tables(self, frame_A: Frame) -> tuple:
        """The arguments of :func:`relative_poses_one` after ``q``, for frame A: the
        joint tables, A's body index and its fixed pose X_BF in that body."""
        X_BF = np.ascontiguousarray(_to4(frame_A.GetFixedPoseInBodyFrame()))
        return (*self._tables(), int(frame_A.body().index()), X_BF)

    def checked_positions(self, q: ArrayLike) -> np.ndarray:
        """q as a C-contiguous (N, nq) float array; a ValueError for a wrong shape or
        non-finite values."""
        return np.ascontiguousarray(self._check_q(q))

    def relative_poses(self, q: np.ndarray, frame_A: Frame) -> np.ndarray:
        """Poses X_AB of all bodies in frame A, (N, num_bodies, 4, 4)."""
        q = np.ascontiguousarray(self._check_q(q))
        out = np.empty((q.shape[0], self._num_bodies, 4, 4))
        if q.shape[0]:
            X_BF = np.ascontiguousarray(_to4(frame_A.GetFixedPoseInBodyFrame()))
            pick_kernel(_relative_serial, _relative_parallel)(
                q, *self._tables(), int(frame_A.body().index()), X_BF, out)
        return out
