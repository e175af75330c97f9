"""The one place the tracker's parameters are checked: every error names its field.

:func:`validate_tracker_params` runs when a file is loaded (``load_tracker_params``) and
when parameters are resolved for a model (``resolve_tracker_params``): after that the
core receives a ``ResolvedParams`` and checks nothing again.
"""

import math

from drake_tracker.core.cpf.image_params import check_field as _check
from drake_tracker.core.cpf.image_params import validate_image_params
from drake_tracker.params.tracker_params import JointNoise, TrackerParams

#: Largest standard deviation accepted (rad, rad/√s): above it variances overflow.
MAX_STD = 1e6


def validate_joint_noise(noise: JointNoise, where: str) -> None:
    """A ValueError naming ``<where>.<field>`` for the first field of ``noise`` out of range."""
    for name in ("encoder_noise_std_rad", "angle_process_std_rad_per_sqrt_s",
                 "initial_angle_std_rad"):
        value = getattr(noise, name)
        _check(math.isfinite(value) and value > 0, f"{where}.{name}", value, "must be > 0")
    for name in ("bias_process_std_rad_per_sqrt_s", "initial_bias_std_rad"):
        value = getattr(noise, name)
        ok = math.isfinite(value) and (value > 0 if noise.has_bias else value >= 0)
        _check(ok, f"{where}.{name}", value, "must be > 0 for a joint with bias")
    c = noise.bias_decay_per_s
    _check(0 < c <= 1, f"{where}.bias_decay_per_s", c, "c must be in (0, 1]")
    for name in ("bias_jump_rate_per_s", "bias_jump_std_rad"):
        value = getattr(noise, name)
        _check(math.isfinite(value) and value >= 0, f"{where}.{name}", value,
               "must be finite and >= 0")
    for name in ("encoder_noise_std_rad", "angle_process_std_rad_per_sqrt_s",
                 "initial_angle_std_rad", "bias_process_std_rad_per_sqrt_s",
                 "initial_bias_std_rad", "bias_jump_std_rad"):
        value = getattr(noise, name)
        _check(value < MAX_STD, f"{where}.{name}", value,
               f"must be below {MAX_STD:g} (a larger one overflows the filter's variances)")


def validate_tracker_params(params: TrackerParams) -> None:
    """Model-independent checks; raises ValueError naming the field."""
    k = params.kalman
    validate_joint_noise(k.robot_joints, "kalman.robot_joints")
    validate_joint_noise(k.prismatic_joints, "kalman.prismatic_joints")
    validate_joint_noise(k.virtual_joints, "kalman.virtual_joints")
    for name, noise in k.overrides.items():
        validate_joint_noise(noise, f"kalman.overrides[{name}]")
    validate_image_params(params.image)
    params.health.validate()
    params.camera_calibration.validate()
    for name, value in params.initial_positions_rad.items():
        _check(math.isfinite(value), f"initial_positions_rad[{name}]", value, "must be finite")
    for name, offsets in params.camera_offsets.items():
        _check(len(offsets) == 6 and all(math.isfinite(v) for v in offsets),
               f"camera_offsets[{name}]", offsets,
               "must be 6 finite values: x, y, z (m), rx, ry, rz (rad)")
    _check(math.isfinite(params.buffer_horizon_s), "buffer_horizon_s",
           params.buffer_horizon_s, "must be finite (the buffer is pruned to it)")
    _check(params.buffer_horizon_s > 0, "buffer_horizon_s", params.buffer_horizon_s,
           "must be > 0")
    _check(math.isfinite(params.max_interpolation_gap_s)
           and params.max_interpolation_gap_s >= 0, "max_interpolation_gap_s",
           params.max_interpolation_gap_s, "must be finite and >= 0")
    ts = params.timestamps
    _check(math.isfinite(ts.max_future_jump_periods) and ts.max_future_jump_periods > 0,
           "timestamps.max_future_jump_periods", ts.max_future_jump_periods,
           "must be finite and > 0")
    _check(math.isfinite(ts.min_future_jump_s) and ts.min_future_jump_s > 0,
           "timestamps.min_future_jump_s", ts.min_future_jump_s, "must be finite and > 0")
    _check(isinstance(ts.reanchor_after_samples, int) and ts.reanchor_after_samples >= 2,
           "timestamps.reanchor_after_samples", ts.reanchor_after_samples,
           "must be an integer >= 2")
