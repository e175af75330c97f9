"""The scenario's dataclasses: what the robot does, how its sensors lie, what hides it.

A :class:`Scenario` is a tree of dataclasses that loads from YAML with
``pydrake.common.yaml.yaml_load_typed`` (see ``drake_tracker.sim.scenario.load``). Units are in
the field names (``_s``, ``_hz``, ``_deg``, ``_m``, ``_mm``) or stated in the comments.
Checks live in ``drake_tracker.sim.scenario.checks``; the named presets in
``drake_tracker.sim.scenario.presets``.
"""

import dataclasses
import math
from dataclasses import dataclass, field

from drake_tracker.robot.model import (
    DEFAULT_CAMERA_NAME,
    ROBOT_PRESETS,
    CameraMount,
    FrameOffset,
    RobotConfig,
    robot_preset,
)
from drake_tracker.sim.scenario.validation import require

MODES = ("kinematic", "dynamic")
TRAJECTORY_KINDS = ("sinusoid", "free", "in-out-in", "static")
CAMERA_CLOCKS = ("free-running", "encoder-grid")
#: Kinds of ``EncoderConfig.bias`` (the same model on every biased joint).
BIAS_KINDS = ("none", "constant", "steps", "random-walk", "ramp")
#: Kinds of a per-joint :class:`BiasProfile`.
BIAS_PROFILE_KINDS = ("none", "constant", "ramp", "steps", "random-walk")
OCCLUDER_SHAPES = ("box", "cylinder", "sphere")
#: How an occluder is placed: fixed in the world, fixed to a frame of the robot (or the
#: true camera), along timed waypoints, or swept across the line camera -> hand.
OCCLUDER_MOTIONS = ("world", "frame", "path", "line-sweep")
#: ``OccluderSpec.frame`` value that names the true camera frame.
CAMERA_FRAME_NAME = "camera"


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
class BiasProfile:
    """The encoder bias of one joint over time (see ``drake_tracker.sim.bias``)."""

    #: none | constant | ramp | steps | random-walk
    kind: str = "constant"
    #: constant: the bias; ramp: the value reached at the end of the ramp, then held (deg).
    value_deg: float = 8.6
    #: ramp: the value before ``ramp_start_s`` (deg), when the ramp starts (s) and how
    #: long it takes (s); linear in between.
    ramp_from_deg: float = 0.0
    ramp_start_s: float = 0.0
    ramp_duration_s: float = 10.0
    #: steps: the bias becomes ``step_values_deg[i]`` at ``step_times_s[i]`` (0 before
    #: the first), each change a half-cosine of ``step_transition_s`` centred on its time.
    step_times_s: list[float] = field(default_factory=list)
    step_values_deg: list[float] = field(default_factory=list)
    step_transition_s: float = 1.0
    #: random-walk: b(0) = 0, each sample adds N(drift dt, sigma^2 dt) (deg/sqrt(s), deg/s).
    random_walk_sigma_deg_per_sqrt_s: float = 1.0
    random_walk_drift_deg_per_s: float = 0.0


@dataclass
class EncoderConfig:
    """The joint encoders: rate, bias model, white noise, quantisation."""

    #: Sample rate (Hz).
    rate_hz: float = 1000.0
    #: The model of every biased joint: none | constant | steps (smooth steps of
    #: alternating sign) | random-walk | ramp (linear from 0 to constant_bias_deg).
    bias: str = "none"
    #: Joints that get a bias. Empty: the robot profile's arm joints.
    biased_joints: list[str] = field(default_factory=list)
    #: constant: the bias of every biased joint; ramp: its final value (deg).
    constant_bias_deg: float = 8.6
    #: steps: the bias is +-step_amplitude_deg, changing sign every step_period_s
    #: with a smooth (cosine) transition of step_transition_s; joint k starts with
    #: sign (-1)^k.
    step_amplitude_deg: float = 5.0
    step_period_s: float = 10.0
    step_transition_s: float = 1.0
    #: random-walk: standard deviation growth (deg / sqrt(s)); variance = sigma^2 t.
    random_walk_sigma_deg_per_sqrt_s: float = 1.0
    #: ramp: when the ramp from 0 starts and how long it takes to reach
    #: constant_bias_deg (s).
    ramp_start_s: float = 0.0
    ramp_duration_s: float = 10.0
    #: Per-joint profiles (joint name -> profile); they replace ``bias`` on their joints,
    #: biased or not.
    bias_profiles: dict[str, BiasProfile] = field(default_factory=dict)
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
    #: Render only every ``render_stride``-th pixel of the ``width`` x ``height`` camera,
    #: from pixel (0, 0): the delivered images are ``core.camera.subsample(full_image,
    #: render_stride)``, with the same pixel centres and intrinsics
    #: ``CameraIntrinsics.subsampled(render_stride)`` (``sim.depth_camera``). 1: full
    #: resolution. The demo sets it to the tracker's stride (it renders what is read).
    render_stride: int = 1
    #: The camera sees spheres, cylinders, capsules and ellipsoids as triangle meshes
    #: within this distance of their true surface (m; ``sim.curved_shapes``), for the
    #: renderer only. RenderEngineVtk's own sphere has about 5000 triangles, half of
    #: each render's time for Apollo's three. 0: Drake's own shapes.
    curved_surface_tolerance_m: float = 0.0003
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
class MountedCameraConfig(CameraConfig):
    """One of several depth cameras (``Scenario.cameras``): a ``CameraConfig`` (rate,
    delay, clock, noise, true offset from its nominal pose) with a name and a mount."""

    #: Its name: its virtual joints are ``<name>_offset_x`` ... (the first camera's
    #: offset and hand pose are the run's truth and output).
    name: str = DEFAULT_CAMERA_NAME
    #: Its nominal pose: ``mount.parent`` empty: the robot's ``camera_frame``; else this
    #: offset from a frame of the robot model (``added_frames`` as ``<name>_nominal``).
    mount: FrameOffset = field(default_factory=lambda: FrameOffset(parent=""))

    def sensor(self) -> CameraConfig:
        """The camera's ``CameraConfig`` fields alone."""
        return CameraConfig(**{f.name: getattr(self, f.name)
                               for f in dataclasses.fields(CameraConfig)})


@dataclass
class OccluderConfig:
    """The legacy single occluder: a box that moves between the camera and the hand.

    Kept for existing scenarios; the world converts it to an :class:`OccluderSpec`
    (``motion: line-sweep``, 2 s ramps) placed before ``Scenario.occluders``.
    """

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
class OccluderSpec:
    """One occluding object: its shape, where it is, and when it is in the scene.

    Outside ``[enter_s, leave_s]`` it is parked ``park_distance_m`` aside along the true
    camera's x axis (by default beyond the camera's far plane); with ``ramp_s > 0`` it
    slides in and out with cosine ramps inside the window.
    """

    #: box | cylinder | sphere
    shape: str = "box"
    #: box: edge lengths [x, y, z]; cylinder: [radius, length] (axis along its z);
    #: sphere: [radius] (m).
    size_m: list[float] = field(default_factory=lambda: [0.2, 0.2, 0.2])
    #: world (fixed at xyz_m / rpy_deg in the world) | frame (fixed at xyz_m / rpy_deg
    #: in ``frame``) | path (through timed waypoints, orientation rpy_deg in the world) |
    #: line-sweep (on the line true camera -> end effector, swept sideways).
    motion: str = "world"
    #: motion frame: a frame of the robot model, or ``camera`` (the true camera frame).
    frame: str = ""
    #: Position (m) and roll-pitch-yaw (deg) in the world or in ``frame``.
    xyz_m: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    rpy_deg: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    #: motion path: increasing times (s) and world positions [x, y, z] (m) of the
    #: centre; linear in between, held before the first and after the last.
    waypoint_times_s: list[float] = field(default_factory=list)
    waypoints_m: list[list[float]] = field(default_factory=list)
    #: motion line-sweep: where on the line camera -> end effector the centre sits
    #: (0..1), the sideways sweep along the camera's x axis (m) and its period (s).
    line_fraction: float = 0.45
    sweep_amplitude_m: float = 0.12
    sweep_period_s: float = 9.0
    #: In the scene during [enter_s, leave_s] (s); leave_s: .inf = until the end.
    enter_s: float = 0.0
    leave_s: float = math.inf
    #: Duration of the slide in and out (s), inside the window; 0 = appears at once.
    ramp_s: float = 0.0
    #: Where it waits outside its window: this far along the camera's x axis (m).
    park_distance_m: float = 20.0
    #: Colour (illustration and the camera's colour image), RGBA in [0, 1].
    rgba: list[float] = field(default_factory=lambda: [0.2, 0.5, 0.9, 1.0])


@dataclass
class ModelMismatchConfig:
    """A WORLD robot that differs from the tracker's nominal model.

    The world (images, encoders, truth) uses the perturbed robot; the tracker and the
    recorded run keep the nominal ``RobotConfig`` (see ``drake_tracker.sim.mismatch``).
    """

    #: Each perturbed joint's origin (its frame on the parent body) is moved by this
    #: distance (mm) in a seeded random direction ...
    joint_origin_mm: float = 0.0
    #: ... and rotated by this angle (deg) about a seeded random axis.
    joint_origin_deg: float = 0.0
    #: Joints to perturb; empty: every joint of the robot.
    joints: list[str] = field(default_factory=list)
    #: An unmodelled cable: a cylinder along each arm link, beside it.
    cable: bool = False
    #: Cable radius (m) and its distance from the link's axis (m).
    cable_radius_m: float = 0.01
    cable_offset_m: float = 0.075
    #: Which side of the link: this angle about the link's axis from its x axis (deg);
    #: 180 is the side of Apollo's arm links that its camera sees.
    cable_angle_deg: float = 180.0
    #: The end effector's body (the hand) is drawn this much larger (about its origin).
    hand_scale: float = 1.0
    #: Seed of the joint perturbations.
    seed: int = 0

    @property
    def enabled(self) -> bool:
        """True when the world robot differs from the model at all."""
        return (self.joint_origin_mm != 0 or self.joint_origin_deg != 0 or self.cable
                or self.hand_scale != 1.0)


@dataclass
class Scenario:
    """One simulated run."""

    #: Optional preset to start from; the other fields given in YAML override it.
    preset: str = ""
    name: str = "custom"
    #: Robot preset name (``apollo``, ``arm6``); ignored when robot_config is given.
    robot: str = "apollo"
    robot_config: RobotConfig | None = None
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
    #: Several depth cameras (the first is the camera of the truth and the output); empty:
    #: the one ``camera`` at the robot's ``camera_frame``. When given, ``camera`` mirrors
    #: the first (``load.mirror_first_camera``).
    cameras: list[MountedCameraConfig] = field(default_factory=list)
    #: The legacy single occluder (see OccluderConfig).
    occluder: OccluderConfig = field(default_factory=OccluderConfig)
    #: Any number of occluders.
    occluders: list[OccluderSpec] = field(default_factory=list)
    #: The world's robot against the tracker's model (nothing differs by default).
    model_mismatch: ModelMismatchConfig = field(default_factory=ModelMismatchConfig)

    def resolved_robot_config(self) -> RobotConfig:
        """``robot_config`` when given, else the robot preset named ``robot``; with
        ``cameras``, with their mounts (``RobotConfig.cameras``) added."""
        if self.robot_config is not None:
            config = self.robot_config
        else:
            require(self.robot in ROBOT_PRESETS, "Scenario.robot", self.robot,
                    f"unknown robot preset; known: {sorted(ROBOT_PRESETS)} (or give "
                    f"robot_config)")
            config = robot_preset(self.robot)
        if not self.cameras:
            return config
        config = dataclasses.replace(config, added_frames=dict(config.added_frames))
        mounts = []
        for camera in self.cameras:
            frame = config.camera_frame
            if camera.mount.parent:
                frame = f"{camera.name}_nominal"
                config.added_frames[frame] = camera.mount
            mounts.append(CameraMount(camera.name, frame))
        config.cameras = mounts
        return config

    def resolved_cameras(self) -> list[MountedCameraConfig]:
        """``cameras``, or the one ``camera`` (named ``camera``, at ``camera_frame``)."""
        if self.cameras:
            return list(self.cameras)
        return [MountedCameraConfig(**dataclasses.asdict(self.camera))]


#: Ramp time of the legacy occluder's moves in and out of view (s).
LEGACY_OCCLUDER_RAMP_S = 2.0


def legacy_occluder_spec(config: OccluderConfig) -> OccluderSpec:
    """The legacy box as an :class:`OccluderSpec` with the same motion and timing."""
    return OccluderSpec(
        shape="box", size_m=list(config.size_m), motion="line-sweep",
        line_fraction=config.line_fraction, sweep_amplitude_m=config.sweep_amplitude_m,
        sweep_period_s=config.sweep_period_s, enter_s=config.start_s, leave_s=config.end_s,
        ramp_s=LEGACY_OCCLUDER_RAMP_S, park_distance_m=config.park_distance_m)


def scenario_occluders(scenario: Scenario) -> list[OccluderSpec]:
    """Every occluder of ``scenario``: the legacy box (when enabled), then ``occluders``."""
    legacy = [legacy_occluder_spec(scenario.occluder)] if scenario.occluder.enabled else []
    return legacy + list(scenario.occluders)


def occlusion_windows(scenario: Scenario, t_end: float) -> list[tuple[float, float]]:
    """``(enter, leave)`` of every occluder that enters before ``t_end`` (leave clipped to
    ``t_end``), in order: the intervals a plot should mark as occluded."""
    return [(o.enter_s, min(o.leave_s, t_end)) for o in scenario_occluders(scenario)
            if o.enter_s < t_end]
