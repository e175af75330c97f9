"""The filter's start: the Kalman bank for a model, its first belief, the delay buffer,
and the bank's reading vector (robot joints, then each virtual camera joint's calibrated
offset or 0)."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from drake_tracker.core.filter.belief_buffer import BeliefBuffer
from drake_tracker.core.filter.kalman import JointKalmanBank, initial_moments
from drake_tracker.core.resolved_params import ResolvedParams
from drake_tracker.core.sensors.rate_limited_warning import RateLimitedWarning


def new_bank(params: ResolvedParams) -> JointKalmanBank:
    """The Kalman bank on (angle, bias) for every joint of the resolved model; a joint
    whose reading lacks a value keeps an angle prior no wider than the start's."""
    return JointKalmanBank(params.joints.kalman, params.joints.initial_angle_std ** 2)


def initial_belief(params: ResolvedParams, first_reading: np.ndarray | None) -> np.ndarray:
    """The initial (5, n) belief: angles at the first reading of the robot joints (or
    ``initial_positions_rad``; None: vision only), virtual joints at 0, each joint's
    initial angle and bias spread."""
    joints = params.joints
    mean = joints.initial_mean.copy()
    if first_reading is not None:
        mean[params.robot_joint_indices] = first_reading
    return initial_moments(mean, joints.initial_angle_std, joints.initial_bias_std,
                           joints.kalman.has_bias)


def new_belief_buffer(params: ResolvedParams, t: float,
                      first_reading: np.ndarray | None) -> BeliefBuffer:
    """The delay buffer started at ``t`` from the first reading (None: vision only)."""
    return BeliefBuffer(new_bank(params), initial_belief(params, first_reading), t,
                        params.buffer_horizon_s, params.max_interpolation_gap_s)


def start_reading_ok(reading: np.ndarray, warnings: RateLimitedWarning) -> bool:
    """Whether the filter can start from ``reading``: it has a value for every joint
    (a joint without one would start nowhere); if not, a rate-limited warning."""
    if np.isfinite(reading).all():
        return True
    warnings.warn("first readings with missing joints", "joint reading skipped: the "
                  "filter starts from a reading with a value for every joint")
    return False


def new_bank_and_belief(params: ResolvedParams, first_reading: np.ndarray | None
                        ) -> tuple[JointKalmanBank, np.ndarray]:
    """:func:`new_bank` and :func:`initial_belief` together."""
    return new_bank(params), initial_belief(params, first_reading)


class JointLayout(Protocol):
    """What :func:`full_reading` reads: a ``TrackerModel`` or a ``ResolvedParams``."""

    @property
    def num_joints(self) -> int:
        """Number of joints the tracker estimates (robot and virtual)."""

    @property
    def robot_joint_indices(self) -> np.ndarray:
        """Indices of the robot (measured) joints among them."""


def full_reading(layout: JointLayout, robot_reading: np.ndarray) -> np.ndarray:
    """The bank's reading vector: the robot joints' readings (``robot_reading``, in
    ``robot_joint_names`` order), and for the virtual joints a calibrated camera's
    offsets (``ResolvedParams``: ``camera_offsets``) or 0 (a model: the nominal mount)."""
    if isinstance(layout, ResolvedParams):
        q = layout.joints.virtual_reading.copy()
    else:
        q = np.zeros(layout.num_joints)
    q[layout.robot_joint_indices] = robot_reading
    return q
