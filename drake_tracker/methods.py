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

from drake_tracker.params import JointNoise, TrackerParams

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
        robot = params.kalman.robot_joints
        params.kalman.robot_joints = JointNoise(
            encoder_noise_std_rad=robot.encoder_noise_std_rad,
            angle_process_std_rad_per_sqrt_s=robot.angle_process_std_rad_per_sqrt_s,
            bias_process_std_rad_per_sqrt_s=0.0, bias_decay_per_s=robot.bias_decay_per_s,
            has_bias=False, initial_angle_std_rad=robot.encoder_noise_std_rad,
            initial_bias_std_rad=0.0)
        params.image.blocks = "camera"
    elif method == "vision_only":
        params.use_joint_readings = False
        robot = params.kalman.robot_joints
        params.kalman.robot_joints = JointNoise(
            encoder_noise_std_rad=robot.encoder_noise_std_rad,
            angle_process_std_rad_per_sqrt_s=VISION_ONLY_ANGLE_STD_RAD_PER_SQRT_S,
            bias_process_std_rad_per_sqrt_s=0.0, bias_decay_per_s=1.0, has_bias=False,
            initial_angle_std_rad=0.05, initial_bias_std_rad=0.0)
        params.initial_positions_rad = dict(initial_positions_rad or {})
    return params
