"""The four methods the evaluation compares, all configurations of the same tracker.

* ``encoders_only``: forward kinematics of the raw readings with the nominal camera;
* ``camera_offset_only``: images estimate only the six virtual camera joints; the robot
  joints are trusted (no bias);
* ``full_fusion``: the whole method (joint biases and camera offset);
* ``vision_only``: no joint readings; the angles follow the images alone, with a prior
  that lets them move (angle process noise ``vision_only_angle_std_rad_per_sqrt_s``).
"""

from __future__ import annotations

import copy

from drake_tracker.params.tracker_params import JointNoise, TrackerParams

METHODS = ("encoders_only", "camera_offset_only", "full_fusion", "vision_only")

#: Angle random walk of the vision-only method (rad/√s): about 1 deg per image at 30 Hz.
VISION_ONLY_ANGLE_STD_RAD_PER_SQRT_S = 0.1


def method_params(method: str, base: TrackerParams | None = None,
                  initial_positions_rad: dict[str, float] | None = None) -> TrackerParams:
    """The tracker parameters of ``method``, starting from ``base`` (default parameters).

    ``encoders_only`` has no tracker parameters (it is plain forward kinematics); its
    returned parameters disable images, which gives the same estimate through the
    tracker up to the Kalman gain's split of each reading between angle and bias.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method '{method}'; known: {list(METHODS)}")
    params = copy.deepcopy(base) if base is not None else TrackerParams()
    if method == "encoders_only":
        params.image.enabled = False
        params.estimate_camera_offset = False
    elif method == "camera_offset_only":
        k = params.kalman
        k.robot_joints, k.prismatic_joints = (_trusted(j) for j in (k.robot_joints,
                                                                    k.prismatic_joints))
        params.image.blocks = "camera"
    elif method == "vision_only":
        params.use_joint_readings = False
        k = params.kalman
        # A prismatic joint's in metres: scaled as its bias prior is against a revolute's.
        scale = k.prismatic_joints.initial_bias_std_rad / k.robot_joints.initial_bias_std_rad
        k.robot_joints = _unread(k.robot_joints, 1.0)
        k.prismatic_joints = _unread(k.prismatic_joints, scale)
        params.initial_positions_rad = dict(initial_positions_rad or {})
    return params


def _trusted(joint: JointNoise) -> JointNoise:
    """``joint`` without a bias: its encoder is taken as it reads."""
    return JointNoise(
        encoder_noise_std_rad=joint.encoder_noise_std_rad,
        angle_process_std_rad_per_sqrt_s=joint.angle_process_std_rad_per_sqrt_s,
        bias_process_std_rad_per_sqrt_s=0.0, bias_decay_per_s=joint.bias_decay_per_s,
        has_bias=False, initial_angle_std_rad=joint.encoder_noise_std_rad,
        initial_bias_std_rad=0.0)


def _unread(joint: JointNoise, scale: float) -> JointNoise:
    """``joint`` for a tracker without encoder readings: no bias, the angle a random
    walk of ``VISION_ONLY_ANGLE_STD_RAD_PER_SQRT_S`` (times ``scale``, for a joint in
    other units) from a prior of 0.05 (times ``scale``)."""
    return JointNoise(
        encoder_noise_std_rad=joint.encoder_noise_std_rad,
        angle_process_std_rad_per_sqrt_s=VISION_ONLY_ANGLE_STD_RAD_PER_SQRT_S * scale,
        bias_process_std_rad_per_sqrt_s=0.0, bias_decay_per_s=1.0, has_bias=False,
        initial_angle_std_rad=0.05 * scale, initial_bias_std_rad=0.0)
