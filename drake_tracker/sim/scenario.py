"""Simulation scenarios: what the robot does, how its sensors lie, and for how long.

A :class:`Scenario` is a tree of dataclasses that loads from YAML with
``pydrake.common.yaml.yaml_load_typed``. Units are in the field names (``_s``, ``_hz``,
``_deg``, ``_m``) or stated in the comments.

Named presets mirror the paper's experiments (SPEC §5): ``SEQUENCE/BIAS`` with BIAS in
``none``, ``constant`` (8.6 deg on every arm joint) and ``time-varying`` (smooth steps of
alternating sign, 5 deg amplitude, so jumps reach 10 deg). Sequences, all on Apollo:

* 30 s sinusoids: ``s-lower-arm`` (elbow and wrist), ``s-upper-arm`` (shoulder),
  ``s-full-arm``, ``s-head``, ``s-head-arm``;
* 60 s smooth random motion: ``arm``, ``arm++`` (fast), ``both`` (arm and head),
  ``both++``, ``in-out-in`` (the hand leaves the view and comes back), ``occlusion`` (a
  box moves between the camera and the moving arm for most of the run);
* ``static``: 30 s, the robot holds its home pose (a sanity check: only the bias and
  the camera offset make errors).

A YAML file may start from a preset with ``preset: NAME`` and override any field.
"""

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path

from drake_tracker.robot import ROBOT_PRESETS, RobotConfig, robot_preset

MODES = ("kinematic", "dynamic")
TRAJECTORY_KINDS = ("sinusoid", "free", "in-out-in", "static")
CAMERA_CLOCKS = ("free-running", "encoder-grid")
BIAS_KINDS = ("none", "constant", "steps", "random-walk")
BIAS_VARIANTS = ("none", "constant", "time-varying")


@dataclass
class RobotModelConfig:
    """YAML-loadable mirror of ``drake_tracker.robot.RobotConfig`` (same fields).

    (``RobotConfig``'s module uses postponed annotations, which
    ``yaml_load_typed`` cannot read, so scenarios carry this copy.)
    """

    model_file: str = "apollo.sdf"
    camera_frame: str = "camera_optical"
    end_effector_frame: str = "end_effector"

    def to_robot_config(self) -> RobotConfig:
        return RobotConfig(model_file=self.model_file, camera_frame=self.camera_frame,
                           end_effector_frame=self.end_effector_frame)


@dataclass
class TrajectoryConfig:
    """The commanded joint motion (see ``drake_tracker.sim.trajectories``)."""

    #: sinusoid | free (smooth random: sums of sinusoids with seeded phases) |
    #: in-out-in (free motion plus an excursion of one joint) | static
    kind: str = "sinusoid"
    #: Joints that move. Empty: the robot profile's arm joints.
    joints: list[str] = field(default_factory=list)
    #: Home (mean) angles per joint name (deg); joints not listed use the robot
    #: profile's home pose, or 0.
    home_deg: dict[str, float] = field(default_factory=dict)
    #: Peak deviation from home of each moved joint (deg).
    amplitude_deg: float = 20.0
    #: Base period of the sinusoids (s); joint k uses period_s * (1 + 0.17 k).
    period_s: float = 8.0
    #: Time scaling of the free motion (2.5 for the fast ``++`` sequences).
    speed_scale: float = 1.0
    #: Number of sinusoid components per joint of the free motion.
    num_components: int = 3
    #: in-out-in: the joint that takes the hand out of view and back.
    excursion_joint: str = ""
    #: in-out-in: how far that joint moves away from its free motion (deg).
    excursion_deg: float = 0.0
    #: in-out-in: when the excursion starts, how long it stays out, its ramps (s).
    excursion_start_s: float = 15.0
    excursion_duration_s: float = 25.0
    excursion_ramp_s: float = 4.0
    #: Samples per second at which the world checks the joint limits (s^-1).
    sample_rate_hz: float = 200.0


@dataclass
class EncoderConfig:
    """The joint encoders: rate, bias model, white noise, quantisation."""

    #: Sample rate (Hz).
    rate_hz: float = 1000.0
    #: none | constant | steps (smooth steps of alternating sign) | random-walk
    bias: str = "none"
    #: Joints that get a bias. Empty: the robot profile's arm joints.
    biased_joints: list[str] = field(default_factory=list)
    #: constant: the bias of every biased joint (deg).
    constant_bias_deg: float = 8.6
    #: steps: the bias is +-step_amplitude_deg, changing sign every step_period_s
    #: with a smooth (cosine) transition of step_transition_s; joint k starts with
    #: sign (-1)^k.
    step_amplitude_deg: float = 5.0
    step_period_s: float = 10.0
    step_transition_s: float = 1.0
    #: random-walk: standard deviation growth (deg / sqrt(s)); variance = sigma^2 t.
    random_walk_sigma_deg_per_sqrt_s: float = 1.0
    #: White measurement noise (deg), on every measured joint.
    noise_sigma_deg: float = 0.01
    #: Quantisation step (deg); 0 = none.
    quantization_deg: float = 0.0


@dataclass
class CameraConfig:
    """The head-mounted depth camera."""

    width: int = 640
    height: int = 480
    fov_y_deg: float = 45.0
    rate_hz: float = 30.0
    near_m: float = 0.1
    far_m: float = 6.0
    #: ``free-running``: the camera's own clock (period 1/rate_hz from a random phase,
    #: plus per-frame Gaussian jitter), so frames fall between encoder readings, as real
    #: cameras' do. ``encoder-grid``: every capture is moved to the nearest encoder tick
    #: (to compare with the free-running camera on the same run).
    clock: str = "free-running"
    #: Standard deviation of each capture instant about the camera's period grid (s).
    jitter_std_s: float = 0.001
    #: Transport delay between capture and arrival (s).
    delay_s: float = 0.05
    #: Depth noise sigma(z) = noise_sigma0_m + noise_k_per_m * z^2 (m).
    noise_sigma0_m: float = 0.001
    noise_k_per_m: float = 0.0012
    #: Probability that a pixel is invalid (NaN) at random.
    dropout_probability: float = 0.005
    #: Pixels next to a depth jump larger than this are invalid (silhouettes) (m).
    silhouette_threshold_m: float = 0.05
    #: The TRUE camera pose relative to the nominal one: [x, y, z] (m) then
    #: [rx, ry, rz] (rad), the six virtual joints' values.
    offset: list[float] = field(
        default_factory=lambda: [0.02, -0.015, 0.01,
                                 math.radians(2.0), math.radians(-1.5), math.radians(1.0)]
    )
    #: Configuration-dependent part of the offset: joint name -> 6 gains per rad of
    #: that joint (m/rad for x,y,z; rad/rad for rx,ry,rz); offset = offset + sum(gain*q).
    offset_gain_per_rad: dict[str, list[float]] = field(default_factory=dict)


@dataclass
class OccluderConfig:
    """A box that moves between the camera and the hand (own model instance)."""

    enabled: bool = False
    #: Box edge lengths (m).
    size_m: list[float] = field(default_factory=lambda: [0.22, 0.22, 0.22])
    #: Where on the line camera -> end effector the box centre sits (0..1).
    line_fraction: float = 0.45
    #: Sideways sweep across that line (m) and its period (s).
    sweep_amplitude_m: float = 0.12
    sweep_period_s: float = 9.0
    #: The box is in front of the arm during [start_s, end_s] (with 2 s ramps),
    #: and parked out of view otherwise.
    start_s: float = 8.0
    end_s: float = 52.0
    #: How far aside it is parked (m), in the camera's horizontal direction.
    park_distance_m: float = 1.5


@dataclass
class Scenario:
    """One simulated run."""

    #: Optional preset to start from; the other fields given in YAML override it.
    preset: str = ""
    name: str = "custom"
    #: Robot preset name (``apollo``, ``arm6``); ignored when robot_config is given.
    robot: str = "apollo"
    robot_config: RobotModelConfig | None = None
    duration_s: float = 30.0
    seed: int = 0
    #: kinematic: the plant's positions are played back exactly (fast).
    #: dynamic: a discrete plant with an inverse-dynamics controller tracks them.
    mode: str = "kinematic"
    #: Discrete plant step of the dynamic mode (s).
    time_step_s: float = 0.001
    #: Add a floor, a table and a back wall to the world (valid background depth).
    environment: bool = True
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    encoders: EncoderConfig = field(default_factory=EncoderConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    occluder: OccluderConfig = field(default_factory=OccluderConfig)

    def resolved_robot_config(self) -> RobotConfig:
        if self.robot_config is not None:
            return self.robot_config.to_robot_config()
        if self.robot not in ROBOT_PRESETS:
            raise ValueError(
                f"Scenario.robot: unknown robot preset '{self.robot}'; known: "
                f"{sorted(ROBOT_PRESETS)} (or give robot_config)")
        return robot_preset(self.robot)


@dataclass
class RobotProfile:
    """Per-model defaults the presets need: joint groups and a home pose in view."""

    upper_arm: list[str]
    lower_arm: list[str]
    head: list[str]
    home_deg: dict[str, float]
    #: Default configuration-dependent camera offset (see CameraConfig).
    offset_gain_per_rad: dict[str, list[float]] = field(default_factory=dict)

    @property
    def arm(self) -> list[str]:
        return self.upper_arm + self.lower_arm


#: Profiles keyed by the model file's name.
ROBOT_PROFILES: dict[str, RobotProfile] = {
    "apollo.sdf": RobotProfile(
        upper_arm=["arm_joint_1", "arm_joint_2", "arm_joint_3"],
        lower_arm=["arm_joint_4", "arm_joint_5", "arm_joint_6", "arm_joint_7"],
        head=["head_pan", "head_tilt"],
        home_deg={"head_tilt": 32.0, "arm_joint_1": 20.0, "arm_joint_2": 60.0,
                  "arm_joint_4": -60.0, "arm_joint_6": -30.0},
        # Apollo's head kinematics are approximate: the error grows with the angles.
        offset_gain_per_rad={
            "head_pan": [0.0, 0.01, 0.0, 0.0, 0.02, 0.01],
            "head_tilt": [0.0, 0.0, 0.015, 0.02, 0.0, 0.0],
        },
    ),
    "arm6_on_stand.urdf": RobotProfile(
        upper_arm=["shoulder_pan", "shoulder_lift"],
        lower_arm=["elbow", "wrist_1", "wrist_2", "wrist_3"],
        head=[],
        home_deg={"shoulder_lift": 30.0, "elbow": 60.0, "wrist_1": 30.0},
    ),
}


def robot_profile(config: RobotConfig) -> "RobotProfile | None":
    """The profile of ``config``'s model, or None for a model without one."""
    return ROBOT_PROFILES.get(Path(config.model_file).name)


def _preset(sequence: str, bias: str) -> Scenario:
    p = ROBOT_PROFILES["apollo.sdf"]
    s = Scenario(name=f"{sequence}/{bias}", robot="apollo", duration_s=30.0)
    s.camera.offset_gain_per_rad = copy.deepcopy(p.offset_gain_per_rad)
    t = s.trajectory
    sinusoid_joints = {
        "s-lower-arm": p.lower_arm,
        "s-upper-arm": p.upper_arm,
        "s-full-arm": p.arm,
        "s-head": p.head,
        "s-head-arm": p.arm + p.head,
    }
    if sequence in sinusoid_joints:
        t.kind = "sinusoid"
        t.joints = list(sinusoid_joints[sequence])
        t.amplitude_deg = 10.0 if sequence == "s-head" else 15.0
    elif sequence == "static":
        t.kind = "static"
    else:
        s.duration_s = 60.0
        t.kind = "free"
        t.amplitude_deg = 15.0
        t.joints = list(p.arm + p.head) if sequence.startswith("both") else list(p.arm)
        if sequence.endswith("++"):
            t.speed_scale = 2.5
        if sequence == "in-out-in":
            t.kind = "in-out-in"
            t.excursion_joint = "arm_joint_1"
            t.excursion_deg = -100.0
        if sequence == "occlusion":
            s.occluder.enabled = True
    e = s.encoders
    e.bias = {"none": "none", "constant": "constant", "time-varying": "steps"}[bias]
    return s


SEQUENCES = ("s-lower-arm", "s-upper-arm", "s-full-arm", "s-head", "s-head-arm",
             "arm", "arm++", "both", "both++", "in-out-in", "occlusion", "static")


def list_presets() -> list[str]:
    """All preset names, ``SEQUENCE/BIAS``."""
    return [f"{q}/{b}" for q in SEQUENCES for b in BIAS_VARIANTS]


def preset_scenario(name: str) -> Scenario:
    """A fresh copy of a named preset; unknown names raise ValueError listing the known."""
    seq, _, bias = name.partition("/")
    if seq not in SEQUENCES or bias not in BIAS_VARIANTS:
        raise ValueError(f"unknown scenario preset '{name}'; known presets: {list_presets()}")
    return _preset(seq, bias)


def scenario_to_yaml(scenario: Scenario) -> str:
    from pydrake.common.yaml import yaml_dump_typed

    return yaml_dump_typed(scenario)


def load_scenario(name_or_path: str | Path, validate: bool = True) -> Scenario:
    """A preset by name, or a YAML file (which may start from ``preset: NAME``)."""
    from pydrake.common.yaml import yaml_load, yaml_load_typed

    text = str(name_or_path)
    path = Path(text).expanduser()
    if path.suffix in (".yaml", ".yml") or path.is_file():
        if not path.is_file():
            raise FileNotFoundError(f"scenario file '{path}' does not exist")
        raw = yaml_load(filename=str(path)) or {}
        if not isinstance(raw, dict):
            raise ValueError(f"{path}: a scenario YAML must be a mapping")
        base = preset_scenario(raw["preset"]) if raw.get("preset") else Scenario()
        try:
            scenario = yaml_load_typed(filename=str(path), defaults=base)
        except RuntimeError as err:
            raise ValueError(f"{path}: {err}") from err
        if scenario.name == "custom" and not raw.get("name"):
            scenario.name = path.stem
    else:
        scenario = preset_scenario(text)
    if validate:
        validate_scenario(scenario)
    return scenario


def _positive(value: float, field_name: str) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{field_name} must be a positive number, got {value!r}")


def _non_negative(value: float, field_name: str) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise ValueError(f"{field_name} must be >= 0, got {value!r}")


def _one_of(value: str, allowed: tuple[str, ...], field_name: str) -> None:
    if value not in allowed:
        raise ValueError(f"{field_name}: '{value}' is not one of {list(allowed)}")


def validate_scenario(scenario: Scenario, check_model: bool = True) -> None:
    """Raises ValueError naming the offending field; with ``check_model`` also loads the
    robot to check joint and frame names."""
    s = scenario
    _positive(s.duration_s, "Scenario.duration_s")
    _one_of(s.mode, MODES, "Scenario.mode")
    _positive(s.time_step_s, "Scenario.time_step_s")
    if not isinstance(s.seed, int) or s.seed < 0:
        raise ValueError(f"Scenario.seed must be a non-negative integer, got {s.seed!r}")
    t = s.trajectory
    _one_of(t.kind, TRAJECTORY_KINDS, "trajectory.kind")
    _non_negative(t.amplitude_deg, "trajectory.amplitude_deg")
    _positive(t.period_s, "trajectory.period_s")
    _positive(t.speed_scale, "trajectory.speed_scale")
    _positive(t.sample_rate_hz, "trajectory.sample_rate_hz")
    if t.num_components < 1:
        raise ValueError(f"trajectory.num_components must be >= 1, got {t.num_components}")
    _non_negative(t.excursion_duration_s, "trajectory.excursion_duration_s")
    _non_negative(t.excursion_ramp_s, "trajectory.excursion_ramp_s")
    if t.kind == "in-out-in" and not t.excursion_joint:
        raise ValueError("trajectory.excursion_joint must name a joint for kind 'in-out-in'")
    e = s.encoders
    _positive(e.rate_hz, "encoders.rate_hz")
    _one_of(e.bias, BIAS_KINDS, "encoders.bias")
    _non_negative(e.step_amplitude_deg, "encoders.step_amplitude_deg")
    _positive(e.step_period_s, "encoders.step_period_s")
    _non_negative(e.step_transition_s, "encoders.step_transition_s")
    if e.step_transition_s > e.step_period_s:
        raise ValueError("encoders.step_transition_s must not exceed encoders.step_period_s")
    _non_negative(e.random_walk_sigma_deg_per_sqrt_s, "encoders.random_walk_sigma_deg_per_sqrt_s")
    _non_negative(e.noise_sigma_deg, "encoders.noise_sigma_deg")
    _non_negative(e.quantization_deg, "encoders.quantization_deg")
    c = s.camera
    for name in ("width", "height"):
        if not isinstance(getattr(c, name), int) or getattr(c, name) <= 0:
            raise ValueError(f"camera.{name} must be a positive integer, got "
                             f"{getattr(c, name)!r}")
    _positive(c.fov_y_deg, "camera.fov_y_deg")
    if c.fov_y_deg >= 180:
        raise ValueError(f"camera.fov_y_deg must be < 180, got {c.fov_y_deg}")
    _positive(c.rate_hz, "camera.rate_hz")
    _positive(c.near_m, "camera.near_m")
    _positive(c.far_m, "camera.far_m")
    if c.far_m <= c.near_m:
        raise ValueError(f"camera.far_m ({c.far_m}) must exceed camera.near_m ({c.near_m})")
    _non_negative(c.delay_s, "camera.delay_s")
    _one_of(c.clock, CAMERA_CLOCKS, "camera.clock")
    _non_negative(c.jitter_std_s, "camera.jitter_std_s")
    if c.jitter_std_s > 0.1 / c.rate_hz:
        raise ValueError(f"camera.jitter_std_s = {c.jitter_std_s} s is more than a tenth of "
                         f"the frame period 1/camera.rate_hz")
    _non_negative(c.noise_sigma0_m, "camera.noise_sigma0_m")
    _non_negative(c.noise_k_per_m, "camera.noise_k_per_m")
    if not 0 <= c.dropout_probability < 1:
        raise ValueError(f"camera.dropout_probability must be in [0, 1), got "
                         f"{c.dropout_probability}")
    _positive(c.silhouette_threshold_m, "camera.silhouette_threshold_m")
    if len(c.offset) != 6:
        raise ValueError(f"camera.offset must have 6 entries [x y z rx ry rz], got "
                         f"{len(c.offset)}")
    for joint, gains in c.offset_gain_per_rad.items():
        if len(gains) != 6:
            raise ValueError(f"camera.offset_gain_per_rad[{joint}] must have 6 entries")
    o = s.occluder
    if len(o.size_m) != 3 or min(o.size_m) <= 0:
        raise ValueError(f"occluder.size_m must be 3 positive lengths, got {o.size_m}")
    _non_negative(o.sweep_amplitude_m, "occluder.sweep_amplitude_m")
    _positive(o.sweep_period_s, "occluder.sweep_period_s")
    if not 0 < o.line_fraction < 1:
        raise ValueError(f"occluder.line_fraction must be in (0, 1), got {o.line_fraction}")
    if check_model:
        _validate_against_model(s)


def _validate_against_model(s: Scenario) -> None:
    from drake_tracker.robot import build_tracker_model

    config = s.resolved_robot_config()
    try:
        model = build_tracker_model(config)
    except ValueError as err:
        raise ValueError(f"Scenario.robot_config: {err}") from err
    known = model.robot_joint_names

    def check(names, field_name):
        for n in names:
            if n not in known:
                raise ValueError(f"{field_name}: joint '{n}' does not exist in "
                                 f"{config.model_file}; joints: {known}")

    check(s.trajectory.joints, "trajectory.joints")
    check(s.trajectory.home_deg.keys(), "trajectory.home_deg")
    if s.trajectory.kind == "in-out-in":
        check([s.trajectory.excursion_joint], "trajectory.excursion_joint")
    check(s.encoders.biased_joints, "encoders.biased_joints")
    check(s.camera.offset_gain_per_rad.keys(), "camera.offset_gain_per_rad")
