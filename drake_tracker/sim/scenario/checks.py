"""Validation of a :class:`~drake_tracker.sim.scenario.config.Scenario`: every error names its
field.
"""

from drake_tracker.sim.scenario.config import (
    BIAS_KINDS,
    BIAS_PROFILE_KINDS,
    CAMERA_CLOCKS,
    CAMERA_FRAME_NAME,
    MODES,
    OCCLUDER_MOTIONS,
    OCCLUDER_SHAPES,
    TRAJECTORY_KINDS,
    BiasProfile,
    CameraConfig,
    EncoderConfig,
    ModelMismatchConfig,
    OccluderSpec,
    Scenario,
    TrajectoryConfig,
    legacy_occluder_spec,
)
from drake_tracker.sim.scenario.validation import (
    is_number,
    require,
    require_length,
    require_non_negative,
    require_one_of,
    require_positive,
)

#: Number of size values of each occluder shape.
SHAPE_SIZES = {"box": 3, "cylinder": 2, "sphere": 1}


def validate_scenario(scenario: Scenario, check_model: bool = True) -> None:
    """Raises ValueError naming the offending field; with ``check_model`` also loads the
    robot to check joint and frame names."""
    s = scenario
    require_positive(s.duration_s, "Scenario.duration_s")
    require_one_of(s.mode, MODES, "Scenario.mode")
    require_positive(s.time_step_s, "Scenario.time_step_s")
    require(isinstance(s.seed, int) and s.seed >= 0, "Scenario.seed", s.seed,
            "must be a non-negative integer")
    _check_trajectory(s.trajectory)
    _check_encoders(s.encoders)
    _check_camera(s.camera)
    _check_cameras(s)
    if s.occluder.enabled:
        _check_occluder(legacy_occluder_spec(s.occluder), "occluder")
    for k, occluder in enumerate(s.occluders):
        _check_occluder(occluder, f"occluders[{k}]")
    _check_mismatch(s.model_mismatch)
    if check_model:
        _validate_against_model(s)


def _check_trajectory(t: TrajectoryConfig) -> None:
    require_one_of(t.kind, TRAJECTORY_KINDS, "trajectory.kind")
    require_non_negative(t.amplitude_deg, "trajectory.amplitude_deg")
    require_positive(t.period_s, "trajectory.period_s")
    require_positive(t.speed_scale, "trajectory.speed_scale")
    require_positive(t.sample_rate_hz, "trajectory.sample_rate_hz")
    require(t.num_components >= 1, "trajectory.num_components", t.num_components,
            "must be >= 1")
    require_non_negative(t.excursion_duration_s, "trajectory.excursion_duration_s")
    require_non_negative(t.excursion_ramp_s, "trajectory.excursion_ramp_s")
    require(t.kind != "in-out-in" or bool(t.excursion_joint), "trajectory.excursion_joint",
            t.excursion_joint, "must name a joint for kind 'in-out-in'")


def _check_encoders(e: EncoderConfig) -> None:
    require_positive(e.rate_hz, "encoders.rate_hz")
    require_one_of(e.bias, BIAS_KINDS, "encoders.bias")
    require(is_number(e.constant_bias_deg), "encoders.constant_bias_deg", e.constant_bias_deg,
            "must be a finite number")
    require_non_negative(e.step_amplitude_deg, "encoders.step_amplitude_deg")
    require_positive(e.step_period_s, "encoders.step_period_s")
    require_non_negative(e.step_transition_s, "encoders.step_transition_s")
    require(e.step_transition_s <= e.step_period_s, "encoders.step_transition_s",
            e.step_transition_s, "must not exceed encoders.step_period_s")
    require_non_negative(e.random_walk_sigma_deg_per_sqrt_s,
                         "encoders.random_walk_sigma_deg_per_sqrt_s")
    require_non_negative(e.ramp_start_s, "encoders.ramp_start_s")
    require_non_negative(e.ramp_duration_s, "encoders.ramp_duration_s")
    require_non_negative(e.noise_sigma_deg, "encoders.noise_sigma_deg")
    require_non_negative(e.quantization_deg, "encoders.quantization_deg")
    for joint, profile in e.bias_profiles.items():
        _check_bias_profile(profile, f"encoders.bias_profiles[{joint}]")


def _check_bias_profile(p: BiasProfile, where: str) -> None:
    require_one_of(p.kind, BIAS_PROFILE_KINDS, f"{where}.kind")
    for name in ("value_deg", "ramp_from_deg", "random_walk_drift_deg_per_s"):
        value = getattr(p, name)
        require(is_number(value), f"{where}.{name}", value, "must be a finite number")
    require_non_negative(p.ramp_start_s, f"{where}.ramp_start_s")
    require_non_negative(p.ramp_duration_s, f"{where}.ramp_duration_s")
    require_non_negative(p.step_transition_s, f"{where}.step_transition_s")
    require_non_negative(p.random_walk_sigma_deg_per_sqrt_s,
                         f"{where}.random_walk_sigma_deg_per_sqrt_s")
    times, values = p.step_times_s, p.step_values_deg
    require(len(times) == len(values), f"{where}.step_values_deg", values,
            f"needs one value per step time ({len(times)})")
    require_length(times, len(times), f"{where}.step_times_s")
    require_length(values, len(values), f"{where}.step_values_deg")
    gaps_ok = all(b - a >= p.step_transition_s for a, b in zip(times, times[1:]))
    require(gaps_ok, f"{where}.step_times_s", times,
            "must increase by at least step_transition_s")
    require(p.kind != "steps" or len(times) > 0, f"{where}.step_times_s", times,
            "must list at least one step for kind 'steps'")


def _check_cameras(s: Scenario) -> None:
    """``cameras``: each a valid camera, the names distinct, ``camera`` mirroring the
    first (``load.mirror_first_camera``)."""
    names = [c.name for c in s.cameras]
    for k, camera in enumerate(s.cameras):
        require(bool(camera.name) and camera.name.replace("_", "").isalnum(),
                f"cameras[{k}].name", camera.name, "must be a word (letters, digits, _)")
        require(names.count(camera.name) == 1, f"cameras[{k}].name", camera.name,
                "two cameras have this name; every camera needs its own")
        _check_camera(camera)
    require(not s.cameras or s.camera == s.cameras[0].sensor(), "camera", "",
            "differs from cameras[0]: with cameras, give the first camera there and leave "
            "camera out (load_scenario mirrors it)")


def _check_camera(c: CameraConfig) -> None:
    for name in ("width", "height"):
        value = getattr(c, name)
        require(isinstance(value, int) and value > 0, f"camera.{name}", value,
                "must be a positive integer")
    require_positive(c.fov_y_deg, "camera.fov_y_deg")
    require(c.fov_y_deg < 180, "camera.fov_y_deg", c.fov_y_deg, "must be < 180")
    require_positive(c.rate_hz, "camera.rate_hz")
    require_positive(c.near_m, "camera.near_m")
    require_positive(c.far_m, "camera.far_m")
    require(c.far_m > c.near_m, "camera.far_m", c.far_m,
            f"must exceed camera.near_m ({c.near_m})")
    require_non_negative(c.delay_s, "camera.delay_s")
    require_one_of(c.clock, CAMERA_CLOCKS, "camera.clock")
    require_non_negative(c.jitter_std_s, "camera.jitter_std_s")
    require(c.jitter_std_s <= 0.1 / c.rate_hz, "camera.jitter_std_s", c.jitter_std_s,
            "must be at most a tenth of the frame period 1/camera.rate_hz")
    require_non_negative(c.noise_sigma0_m, "camera.noise_sigma0_m")
    require_non_negative(c.noise_k_per_m, "camera.noise_k_per_m")
    require(0 <= c.dropout_probability < 1, "camera.dropout_probability",
            c.dropout_probability, "must be in [0, 1)")
    require_positive(c.silhouette_threshold_m, "camera.silhouette_threshold_m")
    require(isinstance(c.render_stride, int) and not isinstance(c.render_stride, bool)
            and 1 <= c.render_stride <= min(c.width, c.height), "camera.render_stride",
            c.render_stride, "must be an integer from 1 to the image's smaller side")
    require(0 <= c.curved_surface_tolerance_m < 0.01, "camera.curved_surface_tolerance_m",
            c.curved_surface_tolerance_m, "must be in [0, 0.01) m (0: Drake's own shapes)")
    require_length(c.offset, 6, "camera.offset", "numbers [x y z rx ry rz]")
    for joint, gains in c.offset_gain_per_rad.items():
        require_length(gains, 6, f"camera.offset_gain_per_rad[{joint}]")


def _check_occluder(o: OccluderSpec, where: str) -> None:
    require_one_of(o.shape, OCCLUDER_SHAPES, f"{where}.shape")
    require_one_of(o.motion, OCCLUDER_MOTIONS, f"{where}.motion")
    require(len(o.size_m) == SHAPE_SIZES[o.shape]
            and all(is_number(v) and v > 0 for v in o.size_m), f"{where}.size_m", o.size_m,
            f"a {o.shape} needs {SHAPE_SIZES[o.shape]} positive lengths")
    require_length(o.xyz_m, 3, f"{where}.xyz_m")
    require_length(o.rpy_deg, 3, f"{where}.rpy_deg")
    require_length(o.rgba, 4, f"{where}.rgba")
    require(o.motion != "frame" or bool(o.frame), f"{where}.frame", o.frame,
            f"must name a robot frame or '{CAMERA_FRAME_NAME}' for motion 'frame'")
    if o.motion == "path":
        times = o.waypoint_times_s
        require(len(times) >= 1 and len(times) == len(o.waypoints_m),
                f"{where}.waypoints_m", o.waypoints_m,
                f"needs one [x, y, z] per waypoint time ({len(times)}), at least one")
        require_length(times, len(times), f"{where}.waypoint_times_s")
        require(all(b > a for a, b in zip(times, times[1:])), f"{where}.waypoint_times_s",
                times, "must increase")
        for k, point in enumerate(o.waypoints_m):
            require_length(point, 3, f"{where}.waypoints_m[{k}]")
    if o.motion == "line-sweep":
        require(0 < o.line_fraction < 1, f"{where}.line_fraction", o.line_fraction,
                "must be in (0, 1)")
        require_non_negative(o.sweep_amplitude_m, f"{where}.sweep_amplitude_m")
        require_positive(o.sweep_period_s, f"{where}.sweep_period_s")
    require(is_number(o.enter_s), f"{where}.enter_s", o.enter_s, "must be a finite number")
    require(o.leave_s > o.enter_s, f"{where}.leave_s", o.leave_s,
            f"must be after enter_s ({o.enter_s}); .inf = until the end")
    require_non_negative(o.ramp_s, f"{where}.ramp_s")
    require(is_number(o.park_distance_m), f"{where}.park_distance_m", o.park_distance_m,
            "must be a finite number")


def _check_mismatch(m: ModelMismatchConfig) -> None:
    require_non_negative(m.joint_origin_mm, "model_mismatch.joint_origin_mm")
    require_non_negative(m.joint_origin_deg, "model_mismatch.joint_origin_deg")
    require_positive(m.cable_radius_m, "model_mismatch.cable_radius_m")
    require_non_negative(m.cable_offset_m, "model_mismatch.cable_offset_m")
    require(is_number(m.cable_angle_deg), "model_mismatch.cable_angle_deg", m.cable_angle_deg,
            "must be a finite number")
    require_positive(m.hand_scale, "model_mismatch.hand_scale")
    require(isinstance(m.seed, int) and m.seed >= 0, "model_mismatch.seed", m.seed,
            "must be a non-negative integer")


def _validate_against_model(s: Scenario) -> None:
    from drake_tracker.robot.model import build_tracker_model

    config = s.resolved_robot_config()
    try:
        model = build_tracker_model(config)
    except ValueError as err:
        raise ValueError(f"Scenario.robot_config: {err}") from err
    known = model.robot_joint_names

    def check(names, field_name):
        for n in names:
            require(n in known, field_name, n,
                    f"no such joint in {config.model_file}; joints: {known}")

    check(s.trajectory.joints, "trajectory.joints")
    check(s.trajectory.home_deg.keys(), "trajectory.home_deg")
    if s.trajectory.kind == "in-out-in":
        check([s.trajectory.excursion_joint], "trajectory.excursion_joint")
    check(s.encoders.biased_joints, "encoders.biased_joints")
    check(s.encoders.bias_profiles.keys(), "encoders.bias_profiles")
    check(s.camera.offset_gain_per_rad.keys(), "camera.offset_gain_per_rad")
    check(s.model_mismatch.joints, "model_mismatch.joints")
    plant, instance = model.plant, model.robot_instance
    for k, occluder in enumerate(s.occluders):
        if occluder.motion == "frame" and occluder.frame != CAMERA_FRAME_NAME:
            require(plant.HasFrameNamed(occluder.frame, instance), f"occluders[{k}].frame",
                    occluder.frame, f"no such frame in {config.model_file} (or use "
                    f"'{CAMERA_FRAME_NAME}')")
