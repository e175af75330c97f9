"""The tracker's output: the hand in the estimated camera frame, from a belief.

* :class:`PoseReadout`: X_CE, X_WE and X_WC of joint positions (the model's batched
  kinematics);
* :class:`TrackerEstimate` / :func:`estimate_from_belief`: the belief's angles, biases,
  camera offset and the hand's pose, as the offline tracker and the Diagram report them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.health import TrackerHealth
from drake_tracker.core.kalman import MEAN_A, MEAN_B, VAR_A, VAR_B
from drake_tracker.core.kinematics import BatchedKinematics

if TYPE_CHECKING:
    from drake_tracker.robot import TrackerModel


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
    #: Whether the images agree with the estimate (``core/health.py``): a controller
    #: should fall back to the encoders when ``health.state`` is ``HealthState.LOST``.
    health: TrackerHealth = TrackerHealth()


class PoseReadout:
    """X_CE and X_WE of joint positions, from the model's batched kinematics."""

    def __init__(self, model: TrackerModel):
        self.model = model
        self.kinematics = BatchedKinematics.from_plant(model.plant)

    def poses(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(X_CE, X_WE, X_WC), each (N, 4, 4), for configurations q (N, n) or (n,)."""
        q = np.atleast_2d(q)
        X_WC = self.kinematics.frame_poses(q, self.model.camera_frame)
        X_WE = self.kinematics.frame_poses(q, self.model.end_effector_frame)
        X_CE = np.linalg.inv(X_WC) @ X_WE
        return X_CE, X_WE, X_WC


def estimate_from_belief(model: TrackerModel, readout: PoseReadout, time_s: float,
                         belief: np.ndarray) -> TrackerEstimate:
    """The :class:`TrackerEstimate` of a (5, n) ``belief`` at ``time_s``: its angle and bias
    moments, the virtual joints' angle means as the camera offset, and the hand's poses
    X_CE and X_WE (4, 4) at the mean angles."""
    X_CE, X_WE, _ = readout.poses(belief[MEAN_A])
    return TrackerEstimate(
        time_s=float(time_s),
        joint_names=list(model.joint_names),
        positions=belief[MEAN_A].copy(),
        position_variances=belief[VAR_A].copy(),
        biases=belief[MEAN_B].copy(),
        bias_variances=belief[VAR_B].copy(),
        camera_offset=belief[MEAN_A, model.virtual_joint_indices].copy(),
        X_CE=X_CE[0],
        X_WE=X_WE[0],
    )
