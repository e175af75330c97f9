"""The tracker's parameters: dataclasses that load from YAML with ``yaml_load_typed``.

Units are in the field names: ``_rad`` (rad, or m for prismatic joints: the virtual
camera joints' x, y, z and the robot's own, ``kalman.prismatic_joints``),
``_per_sqrt_s`` (standard deviation growth per square root of a second), ``_per_s``,
``_m``, ``_s``, ``_px``. The paper's models (docs/method.md §2) are written per second; dbrt's
per-message values were converted and then chosen by measurement (see ``docs/``).

Example YAML (every field optional)::

    kalman:
      robot_joints: {bias_decay_per_s: 0.9}
      overrides:
        head_pan: {has_bias: false}
    image:
      num_particles: 150
      blocks: per-joint
"""

import math
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from drake_tracker.core.cpf.image_params import ImageParams, validate_image_params
from drake_tracker.core.cpf.image_params import check_field as _check
from drake_tracker.core.filter.kalman import KalmanBankParams
from drake_tracker.core.robustness.health import HealthParams
from drake_tracker.robot.model import VIRTUAL_JOINT_NAMES


@dataclass
class JointNoise:
    """Noise model of one joint's (angle, bias) Kalman filter (docs/method.md §2-3, eqs. 3-5)."""

    #: σq: encoder white noise (rad).
    encoder_noise_std_rad: float = 2e-4
    #: σa: angle random-walk growth (rad/√s). Large: the angle follows the encoder.
    angle_process_std_rad_per_sqrt_s: float = 10.0
    #: σb: bias random-walk growth (rad/√s). It sets how far each image may move the
    #: angle (σb·√0.1 ≈ 0.36 deg at 10 images/s) and how wide the prior grows while the
    #: arm is hidden.
    bias_process_std_rad_per_sqrt_s: float = 0.02
    #: c: fraction of the bias that remains after one second, in (0, 1]. Without images
    #: the bias relaxes to N(0, σb²/(-2 ln c)) (5.7 deg). 0.98 keeps 90 % of a learnt
    #: bias over a 5 s occlusion; 0.9 kept 59 % (occlusion-heavy 52.6 mm median while
    #: occluded, 22.9 now). With σb = 0.0088 as well (the "occlusion hold") arm++/constant
    #: lost a seed (README, "A bias that outlasts an occlusion").
    bias_decay_per_s: float = 0.98
    #: Expected bias jumps per second (a cable slipping, a gear skipping): the image
    #: update's prior admits a step of ``bias_jump_std_rad`` with probability
    #: 1 - exp(-rate * time since the previous image), so an image that shows one is
    #: followed at once instead of at the pace of σb. 0 = the paper's Gaussian bias.
    bias_jump_rate_per_s: float = 0.1
    #: Standard deviation of a bias jump (rad).
    bias_jump_std_rad: float = 0.15
    #: False: the joint is trusted (its bias is held at 0).
    has_bias: bool = True
    #: Prior standard deviations at the first reading (rad). The bias prior must cover
    #: the biases the tracker will meet: with 0.035 (2 deg), the protocol's constant 8.6
    #: deg was a 4.3-sigma start, and the start-up search found it on 2 of 3 seeds.
    initial_angle_std_rad: float = 0.035
    initial_bias_std_rad: float = 0.1


def _virtual_joint_noise() -> JointNoise:
    # The "reading" of a virtual joint is always 0, so its bias absorbs the offset: the
    # angle moves slowly (the camera offset is nearly constant) and starts wide enough
    # to cover a few centimetres and degrees of mounting error. The offset does not decay:
    # a camera mount does not relax to its nominal pose while the arm is out of view
    # (with 0.9/s the in-out-in estimate lost a third of the offset in 4 s out of view).
    return JointNoise(
        encoder_noise_std_rad=1e-4,
        angle_process_std_rad_per_sqrt_s=0.015,
        bias_process_std_rad_per_sqrt_s=0.01,
        bias_decay_per_s=1.0,
        has_bias=True,
        initial_angle_std_rad=0.01,
        initial_bias_std_rad=0.01,
        bias_jump_rate_per_s=0.0,
    )


def _prismatic_joint_noise() -> JointNoise:
    # A robot's sliding joints (a gripper's fingers): the revolute defaults' roles in
    # metres. A bias prior of 1 cm, not the 0.1 "rad" (10 cm) of a revolute joint,
    # which let the Panda's finger estimates drift 3 cm below their joint limit.
    return JointNoise(
        encoder_noise_std_rad=2e-5,
        bias_process_std_rad_per_sqrt_s=0.002,
        bias_jump_std_rad=0.01,
        initial_angle_std_rad=0.0035,
        initial_bias_std_rad=0.01,
    )


@dataclass
class KalmanConfig:
    """Per-joint filter parameters: defaults for the robot's revolute and prismatic
    joints and for the virtual joints, and overrides."""

    robot_joints: JointNoise = field(default_factory=JointNoise)
    #: The robot's prismatic joints (``TrackerModel.prismatic_joint_names``), in m.
    prismatic_joints: JointNoise = field(default_factory=_prismatic_joint_noise)
    virtual_joints: JointNoise = field(default_factory=_virtual_joint_noise)
    #: Joint name -> its own parameters (replacing the group default).
    overrides: dict[str, JointNoise] = field(default_factory=dict)


@dataclass
class TimestampParams:
    """The time-stamp policy of each sensor stream (``core/sensors/timestamps.py``)."""

    #: A stamp more than max(``min_future_jump_s``, this many of the stream's recent
    #: sample periods) after the latest accepted one is rejected as a glitch.
    max_future_jump_periods: float = 1000.0
    min_future_jump_s: float = 30.0
    #: A clock that stepped and stays there is re-anchored after this many consecutive
    #: rejected stamps at the stream's normal pace.
    reanchor_after_samples: int = 5


@dataclass
class TrackerParams:
    """Everything the tracker needs besides the robot model and the camera intrinsics."""

    kalman: KalmanConfig = field(default_factory=KalmanConfig)
    image: ImageParams = field(default_factory=ImageParams)
    #: When the tracker reports ``tracking``, ``uncertain`` or ``lost``.
    health: HealthParams = field(default_factory=HealthParams)
    #: Estimate the six virtual camera joints (False: the camera stays nominal).
    estimate_camera_offset: bool = True
    #: False: joint readings are ignored (the vision-only method); then the angles'
    #: prior comes from ``initial_positions_rad`` and the angle process noise.
    use_joint_readings: bool = True
    #: Vision-only start, joint name -> angle (rad); others start at 0.
    initial_positions_rad: dict[str, float] = field(default_factory=dict)
    #: The delay buffer keeps this much history (s); older images are rejected.
    buffer_horizon_s: float = 1.0
    #: An image between two joint readings at most this far apart (s) is applied at the
    #: nearer one, with the angles moved by the readings' interpolated motion (see
    #: ``core/filter/belief_buffer.py``); across a longer encoder gap the belief is predicted
    #: to the image time with the angle process.
    max_interpolation_gap_s: float = 0.05
    #: Which sensor time stamps are accepted, and when a stepped clock is re-anchored.
    timestamps: TimestampParams = field(default_factory=TimestampParams)


def load_tracker_params(path: str | Path | None = None) -> TrackerParams:
    """Defaults, overridden by a YAML file when ``path`` is given; validated later against
    a model by :func:`resolve_kalman_params`."""
    params = TrackerParams()
    if path is None:
        return params
    from pydrake.common.yaml import yaml_load, yaml_load_typed

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"tracker parameter file '{path}' does not exist")
    from drake_tracker.params.yaml_fields import mismatched_field

    raw = None
    try:
        raw = yaml_load(filename=str(path))
        if raw is not None:  # an empty file: all defaults
            params = yaml_load_typed(filename=str(path), defaults=params)
    except Exception as err:  # YAML syntax (yaml.YAMLError) or a field of the wrong type
        raise ValueError(f"{path}: cannot read tracker parameters: "
                         f"{mismatched_field(raw, params) or err}") from err
    try:
        validate_tracker_params(params)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from err
    return params


def tracker_params_to_yaml(params: TrackerParams) -> str:
    """The YAML text of ``params`` (Drake's ``yaml_dump_typed``)."""
    from pydrake.common.yaml import yaml_dump_typed

    return yaml_dump_typed(params)


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
    for name, value in params.initial_positions_rad.items():
        _check(math.isfinite(value), f"initial_positions_rad[{name}]", value, "must be finite")
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


def joint_noise_for(params: TrackerParams, joint_names: list[str],
                    prismatic: Collection[str] = ()) -> list[JointNoise]:
    """The JointNoise of each joint: its override, else the virtual joints', the
    prismatic joints' (``prismatic``: the robot's, ``TrackerModel.prismatic_joint_names``)
    or the robot joints' default; unknown override names raise ValueError."""
    unknown = sorted(set(params.kalman.overrides) - set(joint_names))
    if unknown:
        raise ValueError(f"kalman.overrides: unknown joint names {unknown}; the model's "
                         f"joints are {joint_names}")
    out = []
    for name in joint_names:
        if name in params.kalman.overrides:
            out.append(params.kalman.overrides[name])
        elif name in VIRTUAL_JOINT_NAMES:
            out.append(params.kalman.virtual_joints)
        elif name in prismatic:
            out.append(params.kalman.prismatic_joints)
        else:
            out.append(params.kalman.robot_joints)
    return out


def resolve_kalman_params(params: TrackerParams, joint_names: list[str],
                          prismatic: Collection[str] = ()) -> KalmanBankParams:
    """The bank's per-joint arrays for ``joint_names`` (virtual joints included;
    ``prismatic``: see :func:`joint_noise_for`)."""
    validate_tracker_params(params)
    noise = joint_noise_for(params, joint_names, prismatic)
    has_bias = np.array([j.has_bias for j in noise], bool)
    return KalmanBankParams(
        encoder_noise_std=np.array([j.encoder_noise_std_rad for j in noise]),
        angle_process_std=np.array([j.angle_process_std_rad_per_sqrt_s for j in noise]),
        bias_process_std=np.where(
            has_bias, [j.bias_process_std_rad_per_sqrt_s for j in noise], 0.0),
        bias_decay_per_s=np.array([j.bias_decay_per_s for j in noise]),
        has_bias=has_bias,
        names=tuple(joint_names),
    )


def resolve_blocks(params: TrackerParams, joint_names: list[str],
                   camera_chain: list[str] = ()) -> list[np.ndarray]:
    """Index arrays of the CPF blocks. Without ``estimate_camera_offset`` the virtual
    joints are left out of every block (they stay at their prior, 0).

    ``per-joint`` samples the camera first: the robot joints that move the camera
    (``camera_chain``, e.g. a pan-tilt head), then the virtual joints, then the other
    joints from base to tip. Measured on Apollo, sampling the arm before the camera lets
    the arm's base joints absorb the camera's error, and the estimate drifts.
    """
    im = params.image
    virtual = [n for n in joint_names if n in VIRTUAL_JOINT_NAMES]
    robot = [n for n in joint_names if n not in VIRTUAL_JOINT_NAMES]
    if im.blocks == "per-joint":
        chain = [n for n in robot if n in camera_chain]
        rest = [n for n in robot if n not in camera_chain]
        groups = [[n] for n in chain] + [[n] for n in virtual] + [[n] for n in rest]
    elif im.blocks == "arm-camera":
        groups = [robot, virtual]
    elif im.blocks == "single":
        groups = [robot + virtual]
    elif im.blocks == "camera":
        groups = [[n] for n in virtual]
    else:
        groups = [list(b) for b in im.block_joints]
        for block in groups:
            for name in block:
                if name not in joint_names:
                    raise ValueError(f"image.block_joints: unknown joint '{name}'; the "
                                     f"model's joints are {joint_names}")
    if not params.estimate_camera_offset:
        groups = [[n for n in b if n not in VIRTUAL_JOINT_NAMES] for b in groups]
    groups = [b for b in groups if b]
    return [np.array([joint_names.index(n) for n in b], int) for b in groups]
