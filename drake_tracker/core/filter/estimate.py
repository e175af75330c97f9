"""The tracker's output: the hand in the estimated camera frame, from a belief.

* :class:`PoseReadout`: X_CE, X_WE and X_WC of joint positions (the model's batched
  kinematics);
* :class:`TrackerEstimate` / :func:`estimate_from_belief`: the belief's angles, biases,
  camera offset and the hand's pose, as the offline tracker and the Diagram report them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.filter.kalman import MEAN_A, MEAN_B, VAR_A, VAR_B
from drake_tracker.core.render.kinematics import (
    BatchedKinematics,
    relative_poses_one,
    rigid_inverse,
)
from drake_tracker.core.robustness.health import TrackerHealth

if TYPE_CHECKING:
    from drake_tracker.robot.model import TrackerModel


@dataclass
class TrackerEstimate:
    """The tracker's belief at ``time_s``; angles in rad (m for prismatic joints)."""

    time_s: float
    joint_names: list[str]
    positions: np.ndarray
    position_variances: np.ndarray
    biases: np.ndarray
    bias_variances: np.ndarray
    #: [x, y, z (m), rx, ry, rz (rad)]: the estimated camera relative to the nominal one.
    camera_offset: np.ndarray
    #: The hand (end-effector frame) in the estimated camera frame.
    X_CE: np.ndarray
    #: The hand in the robot model's world frame.
    X_WE: np.ndarray
    #: Each camera's offset (name -> the six values of ``camera_offset``); the first
    #: camera's is ``camera_offset``.
    camera_offsets: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    #: Each camera's estimated pose in the model's world frame (name -> X_WC, 4x4); the
    #: first camera's is ``X_WE @ inv(X_CE)``. With several cameras, the hand in camera
    #: k's frame is :meth:`X_CkE` (k).
    X_WC_by_camera: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    #: Whether the images agree with the estimate (``core/robustness/health.py``): a controller
    #: should fall back to the encoders when ``health.state`` is ``HealthState.LOST``.
    health: TrackerHealth = TrackerHealth()

    def X_CkE(self, camera: str) -> np.ndarray:
        """The hand in camera ``camera``'s estimated frame (4x4): ``X_CE`` for the first
        camera. A camera that sees the arm holds it there to its own images' accuracy
        while the first camera may not see it (docs/evaluation.md, two cameras).
        ValueError naming the cameras for an unknown one."""
        if camera not in self.X_WC_by_camera:
            raise ValueError(f"unknown camera '{camera}': the estimate's cameras are "
                             f"{list(self.X_WC_by_camera)}")
        return rigid_inverse(self.X_WC_by_camera[camera][None])[0] @ self.X_WE


class PoseReadout:
    """X_CE and X_WE of joint positions, from the model's batched kinematics.

    One configuration (the estimate at each output, 1000 a simulated second in a
    Diagram) goes through the serial kernel ``relative_poses_one`` in the world frame,
    the same body poses as ``BatchedKinematics.body_poses`` without its parallel launch
    (which costs 100x the work); the rest of the arithmetic is the same either way.
    The kernel is loaded when the readout is made: its first call reads numba's cache
    (0.3 s here), which would otherwise stall a Diagram at its first output."""

    def __init__(self, model: TrackerModel):
        self.model = model
        self.kinematics = BatchedKinematics.from_plant(model.plant)
        self._world_tables = self.kinematics.frame_tables(model.plant.world_frame())
        self._frames = {}
        for key, frame in (("C", model.camera_frame), ("E", model.end_effector_frame),
                           *((("camera", c.name), c.frame) for c in model.cameras)):
            X_BF = np.asarray(frame.GetFixedPoseInBodyFrame().GetAsMatrix4(), float)
            self._frames[key] = (int(frame.body().index()), X_BF)
        self.body_poses(np.zeros(self.kinematics.num_positions))  # load the kernel now

    def body_poses(self, q: np.ndarray) -> np.ndarray:
        """World poses X_WB of all bodies, (N, num_bodies, 4, 4): those of
        ``BatchedKinematics.body_poses``, one configuration through the serial kernel."""
        q = self.kinematics.checked_positions(q)
        if q.shape[0] != 1:
            return self.kinematics.body_poses(q)
        if not q.flags.writeable:  # a Context's read-only state: one kernel signature
            q = q.copy()
        nb = self.kinematics.num_bodies
        X_WB = np.empty((1, nb, 4, 4))
        relative_poses_one(0, q, *self._world_tables, np.empty((nb, 4, 4)), X_WB[0],
                           np.empty((4, 4)), np.empty((4, 4)))
        return X_WB

    def camera_poses(self, X_WB: np.ndarray) -> dict[str, np.ndarray]:
        """Each camera's X_WC (N, 4, 4) from the body poses ``X_WB`` of
        :meth:`body_poses`."""
        out = {}
        for camera in self.model.camera_names:
            body, X_BC = self._frames[("camera", camera)]
            out[camera] = X_WB[:, body] @ X_BC
        return out

    def poses(self, q: np.ndarray, X_WB: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(X_CE, X_WE, X_WC), each (N, 4, 4), for configurations q (N, n) or (n,)
        (``X_WB``: their :meth:`body_poses`, when already computed)."""
        X_WB = self.body_poses(np.atleast_2d(q)) if X_WB is None else X_WB
        body, X_BC = self._frames["C"]
        X_WC = X_WB[:, body] @ X_BC
        body, X_BE = self._frames["E"]
        X_WE = X_WB[:, body] @ X_BE
        return rigid_inverse(X_WC) @ X_WE, X_WE, X_WC


def estimate_from_belief(model: TrackerModel, readout: PoseReadout, time_s: float,
                         belief: np.ndarray) -> TrackerEstimate:
    """The :class:`TrackerEstimate` of a (5, n) ``belief`` at ``time_s``: its angle and bias
    moments, the virtual joints' angle means as the cameras' offsets, and the hand's poses
    X_CE and X_WE (4, 4) at the mean angles."""
    X_WB = readout.body_poses(np.atleast_2d(belief[MEAN_A]))
    X_CE, X_WE, _ = readout.poses(belief[MEAN_A], X_WB)
    cameras = readout.camera_poses(X_WB)
    return TrackerEstimate(
        time_s=float(time_s),
        joint_names=list(model.joint_names),
        positions=belief[MEAN_A].copy(),
        position_variances=belief[VAR_A].copy(),
        biases=belief[MEAN_B].copy(),
        bias_variances=belief[VAR_B].copy(),
        camera_offset=belief[MEAN_A, model.camera_joint_indices(model.camera_names[0])].copy(),
        camera_offsets={c: belief[MEAN_A, model.camera_joint_indices(c)].copy()
                        for c in model.camera_names},
        X_CE=X_CE[0],
        X_WE=X_WE[0],
        X_WC_by_camera={c: X[0] for c, X in cameras.items()},
    )
