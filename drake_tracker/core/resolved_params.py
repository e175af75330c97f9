"""The parameters as the core receives them: validated once and resolved for one model.

``drake_tracker.params.resolve_tracker_params(params, model)`` builds a
:class:`ResolvedParams` from the user's ``TrackerParams`` (YAML-shaped, per joint group)
and a ``TrackerModel``: every joint's noise model as arrays in the model's position
order, the CPF blocks as index arrays, the joints whose bias may jump. The core reads
only this object, never the YAML-shaped one, so nothing in the core validates
parameters again.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from drake_tracker.core.calibration.calibration_params import SelfCalibrationParams
from drake_tracker.core.cpf.image_params import ImageParams
from drake_tracker.core.filter.kalman import KalmanBankParams
from drake_tracker.core.robustness.health import HealthParams
from drake_tracker.core.sensors.stamp_params import TimestampParams


@dataclass(frozen=True)
class JointArrays:
    """Each joint's noise model (``JointNoise``) as (n,) arrays, n = the model's joints
    (virtual camera joints included) in position order.

    ``kalman`` is what the Kalman bank runs (σb is 0 for a joint without bias);
    ``bias_process_std`` keeps each joint's own σb (rad/√s) for the plausibility of
    a bias. ``jump_rate_per_s`` is 0 where a joint's bias cannot jump (no bias, or in
    a camera's kinematic chain).
    ``initial_mean`` holds ``initial_positions_rad`` (a calibrated camera's offsets on
    its virtual joints, 0 elsewhere). ``virtual_reading`` is what each virtual joint
    reads: a calibrated camera's offsets (``camera_offsets``), 0 elsewhere (the nominal
    mount); the robot joints' entries are 0 (their encoders read them).
    """

    names: tuple[str, ...]
    kalman: KalmanBankParams
    bias_process_std: np.ndarray
    bias_decay_per_s: np.ndarray
    has_bias: np.ndarray
    jump_rate_per_s: np.ndarray
    declared_jump_rate_per_s: np.ndarray
    jump_std: np.ndarray
    initial_mean: np.ndarray
    initial_angle_std: np.ndarray
    initial_bias_std: np.ndarray
    #: Which joints are the robot's (measured); the others are the virtual camera joints.
    robot: np.ndarray
    #: Indices of the robot joints (the encoder readings' order) within ``names``.
    robot_indices: np.ndarray
    virtual_reading: np.ndarray


@dataclass(frozen=True)
class ResolvedParams:
    """Everything the core needs besides the model and the camera, checked once."""

    joints: JointArrays
    #: Index arrays into ``joints.names`` of the CPF's blocks, in sampling order.
    blocks: tuple[np.ndarray, ...]
    #: The robot joints that move the camera (e.g. a pan-tilt head), base first.
    camera_chain: tuple[str, ...]
    image: ImageParams
    health: HealthParams
    timestamps: TimestampParams
    use_joint_readings: bool
    estimate_camera_offset: bool
    buffer_horizon_s: float
    max_interpolation_gap_s: float
    #: (camera name, its blocks) of each camera, in the model's order: an image of a
    #: camera moves the robot joints and that camera's six virtual joints only. Empty:
    #: ``blocks`` for the one camera.
    camera_blocks: tuple[tuple[str, tuple[np.ndarray, ...]], ...] = ()
    #: (camera name, indices of the joints its images leave as they are: the other
    #: cameras' offset joints and the joints that move only another camera) of each
    #: camera; empty with one camera. A restart from a camera's image keeps them.
    camera_left_joints: tuple[tuple[str, np.ndarray], ...] = ()
    #: Several cameras calibrate themselves once while the tracker runs
    #: (``core/calibration/online.py``); None: they do not.
    camera_calibration: SelfCalibrationParams | None = None

    def left_joints_for(self, camera: str | None) -> np.ndarray:
        """Indices of the joints camera ``camera``'s images leave as they are (empty
        with one camera)."""
        for name, left in self.camera_left_joints:
            if name == camera:
                return left
        return np.zeros(0, np.int64)

    def blocks_for(self, camera: str | None) -> tuple[np.ndarray, ...]:
        """The CPF blocks of camera ``camera``'s images (None: ``blocks``)."""
        if camera is None or not self.camera_blocks:
            return self.blocks
        for name, blocks in self.camera_blocks:
            if name == camera:
                return blocks
        raise ValueError(f"unknown camera '{camera}': the parameters were resolved for "
                         f"the cameras {[name for name, _ in self.camera_blocks]}")

    # Cached (plain attributes after the first use): ``full_reading`` reads both at
    # every joint reading.
    @cached_property
    def robot_joint_indices(self) -> np.ndarray:
        """Indices of the robot (measured) joints within ``joints.names`` (the name
        ``TrackerModel`` uses)."""
        return self.joints.robot_indices

    @cached_property
    def num_joints(self) -> int:
        """Number of joints the tracker estimates (robot and virtual)."""
        return len(self.joints.names)
