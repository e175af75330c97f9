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

from dataclasses import dataclass, field

from drake_tracker.core.calibration.calibration_params import SelfCalibrationParams
from drake_tracker.core.cpf.image_params import ImageParams
from drake_tracker.core.robustness.health import HealthParams
from drake_tracker.core.sensors.stamp_params import TimestampParams


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
class TrackerParams:
    """Everything the tracker needs besides the robot model and the camera intrinsics."""

    kalman: KalmanConfig = field(default_factory=KalmanConfig)
    image: ImageParams = field(default_factory=ImageParams)
    #: When the tracker reports ``tracking``, ``uncertain`` or ``lost``.
    health: HealthParams = field(default_factory=HealthParams)
    #: Estimate the six virtual camera joints (False: the camera stays nominal, or at
    #: its ``camera_offsets``).
    estimate_camera_offset: bool = True
    #: Camera name -> its calibrated mounting error, [x, y, z] in m then [rx, ry, rz]
    #: in rad (its six virtual joints), e.g. from ``drake-tracker calibrate-cameras``.
    #: Those joints then read these values instead of 0 (the nominal mount): the
    #: estimate starts from the calibrated mount and every restart returns to it, and
    #: without ``estimate_camera_offset`` it stays there.
    camera_offsets: dict[str, list[float]] = field(default_factory=dict)
    #: With several cameras whose offsets are estimated and not given: once every camera
    #: has seen the arm for ``window_s``, fit their offsets to those images at once and
    #: hold them (``core/calibration/online.py``), as ``calibrate-cameras`` would.
    camera_calibration: SelfCalibrationParams = field(default_factory=SelfCalibrationParams)
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
