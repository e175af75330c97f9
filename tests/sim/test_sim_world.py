"""The simulated world: camera offset, delayed images, reproducibility, second robot,
dynamic mode, occluder, encoders-only baseline."""

import numpy as np
import pytest
from pydrake.geometry import SceneGraph
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_tracker.io.replay import encoders_only_X_CE, readings_at
from drake_tracker.metrics import pose_errors
from drake_tracker.robot.model import add_robot, camera_offset_transform
from drake_tracker.sim.depth_camera import depth_render_camera, ensure_vtk_renderer
from drake_tracker.sim.record import simulate_and_record
from drake_tracker.sim.scenario.load import Scenario, load_scenario
from drake_tracker.sim.world import build_simulated_world


def small(name: str = "s-full-arm/constant", **camera) -> Scenario:
    s = load_scenario(name)
    s.camera.width, s.camera.height = 160, 120
    s.encoders.rate_hz = 100.0
    for key, value in camera.items():
        setattr(s.camera, key, value)
    return s


class ReferenceRenderer:
    """An independent scene: the robot alone (no virtual joints, no environment) and a
    camera placed by hand at a given world pose."""

    def __init__(self, scenario: Scenario):
        builder = DiagramBuilder()
        plant, self.scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        ensure_vtk_renderer(self.scene_graph)
        config = scenario.resolved_robot_config()
        instance = add_robot(plant, config)
        plant.Finalize()
        self.plant = plant
        self.camera_frame = plant.GetFrameByName(config.camera_frame, instance)
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.plant_context = plant.GetMyContextFromRoot(self.context)
        self.camera = depth_render_camera(scenario.camera)

    def nominal_pose(self, q: np.ndarray) -> np.ndarray:
        self.plant.SetPositions(self.plant_context, q)
        return self.camera_frame.CalcPoseInWorld(self.plant_context).GetAsMatrix4()

    def render(self, q: np.ndarray, X_WC: np.ndarray) -> np.ndarray:
        self.plant.SetPositions(self.plant_context, q)
        query = self.scene_graph.get_query_output_port().Eval(
            self.scene_graph.GetMyContextFromRoot(self.context))
        image = query.RenderDepthImage(self.camera, SceneGraph.world_frame_id(),
                                       RigidTransform(X_WC))
        z = np.array(image.data[:, :, 0], np.float64)
        z[~np.isfinite(z)] = np.nan
        return z


def mismatch(a: np.ndarray, b: np.ndarray, tol_m: float = 0.01) -> float:
    """Fraction of pixels valid in ``a`` that are invalid in ``b`` or differ by > tol."""
    valid = np.isfinite(a)
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(a - b) <= tol_m)
    return float(np.mean(bad[valid]))


@pytest.fixture(scope="module")
def offset_run():
    """A noise-free run without environment, a large camera offset, a long delay."""
    s = small(noise_sigma0_m=0.0, noise_k_per_m=0.0, dropout_probability=0.0, delay_s=0.1,
              clock="encoder-grid")
    s.environment = False
    s.camera.offset = [0.06, -0.05, 0.04, 0.06, -0.05, 0.04]
    s.camera.offset_gain_per_rad = {"head_tilt": [0.0, 0.0, 0.02, 0.03, 0.0, 0.0]}
    s.encoders.bias = "none"
    return s, simulate_and_record(s, duration_s=0.6, image_stride=1)


def test_images_show_the_true_camera_pose_at_capture_time(offset_run):
    s, run = offset_run
    ref = ReferenceRenderer(s)
    q_tilt = np.radians(load_scenario("s-full-arm/none").trajectory.home_deg.get(
        "head_tilt", 32.0))
    offset = np.array(s.camera.offset) + q_tilt * np.array([0.0, 0.0, 0.02, 0.03, 0.0, 0.0])
    world_names = run.joint_names
    k = 12  # captured at 0.4 s, arrived at 0.5 s
    t_capture = run.image_capture_times_s[k]
    assert t_capture == pytest.approx(0.4)
    j = int(np.argmin(np.abs(run.truth_times_s - t_capture)))
    q = run.truth_positions_rad[j]
    np.testing.assert_allclose(run.truth_camera_offset[j], offset, atol=1e-12)
    assert world_names[-1] == "head_tilt"
    X_nominal = ref.nominal_pose(q)
    X_true = X_nominal @ camera_offset_transform(offset)
    image = run.depth_images_m[k]
    at_true = ref.render(q, X_true)
    at_nominal = ref.render(q, X_nominal)
    assert np.isfinite(image).mean() > 0.05  # the arm is in view
    assert mismatch(image, at_true) < 0.02
    assert mismatch(image, at_nominal) > 0.3
    # The image was taken at capture time, not at arrival: the arm has moved by then.
    j_arrival = int(np.argmin(np.abs(run.truth_times_s - run.image_arrival_times_s[k])))
    q_late = run.truth_positions_rad[j_arrival]
    X_late = ref.nominal_pose(q_late) @ camera_offset_transform(offset)
    assert mismatch(image, ref.render(q_late, X_late)) > 3 * mismatch(image, at_true)


def test_images_arrive_late_with_their_capture_times(offset_run):
    s, run = offset_run
    n = len(run.image_capture_times_s)
    h = 1.0 / s.encoders.rate_hz  # encoder-grid clock: the nearest encoder tick
    np.testing.assert_allclose(run.image_capture_times_s,
                               np.round(np.arange(n) / s.camera.rate_hz / h) * h, atol=1e-12)
    np.testing.assert_allclose(run.image_arrival_times_s - run.image_capture_times_s, 0.1,
                               atol=1e-12)
    # Everything that arrived by 0.6 s (+ the final half step) and nothing later.
    assert run.image_arrival_times_s[-1] <= 0.6 + 1.0 / 60
    assert n == int(np.floor((0.6 - 0.1) * s.camera.rate_hz + 1e-9)) + 1


def test_depth_frame_port_changes_only_at_arrival():
    s = small(delay_s=0.05, clock="encoder-grid")  # 100 Hz encoders: captures 0, 0.03, ...
    diagram, _ = build_simulated_world(s)
    sim = Simulator(diagram)
    ctx = sim.get_mutable_context()
    port = diagram.GetOutputPort("depth_frame")
    sim.AdvanceTo(0.049)
    assert port.Eval(ctx).is_empty
    sim.AdvanceTo(0.051)
    first = port.Eval(ctx)
    assert (first.sequence, first.capture_time_s, first.arrival_time_s) == (0, 0.0, 0.05)
    assert first.depth_m.shape == (120, 160) and first.depth_m.dtype == np.float32
    sim.AdvanceTo(0.05 + 0.03 - 0.002)
    assert port.Eval(ctx).sequence == 0
    sim.AdvanceTo(0.05 + 0.03 + 0.002)
    second = port.Eval(ctx)
    assert second.sequence == 1
    assert second.capture_time_s == pytest.approx(0.03)


def test_free_running_camera_clock_falls_between_encoder_readings():
    """The default camera runs on its own clock: a random phase, 1/30 s periods with 1 ms
    of Gaussian jitter, each frame stamped with its capture time and arriving delay_s
    later; encoders keep their own 1 kHz grid."""
    s = load_scenario("s-full-arm/constant")
    assert s.camera.clock == "free-running" and s.camera.jitter_std_s == 0.001
    from drake_tracker.sim.depth_camera import capture_schedule

    h = 1.0 / s.encoders.rate_hz
    offsets, cycle = capture_schedule(s.camera, seed=3, encoder_period_s=h)
    phase_on_grid = np.abs(offsets / h - np.round(offsets / h)) * h
    # Off the encoder grid: the distance to the nearest tick is uniform in [0, h/2].
    assert np.mean(phase_on_grid > 1e-5) > 0.95
    assert 0.2 * h < np.mean(phase_on_grid) < 0.3 * h
    gaps = np.diff(offsets)
    assert abs(np.mean(gaps) - 1 / 30) < 2e-4
    assert 0.0011 < np.std(gaps) < 0.0017  # two independent 1 ms jitters: sqrt(2) ms
    other, _ = capture_schedule(s.camera, seed=4, encoder_period_s=h)
    assert abs(other[0] - offsets[0]) > 1e-6  # the phase depends on the seed
    small_s = small(delay_s=0.04)
    run = simulate_and_record(small_s, duration_s=0.5, image_stride=8)
    captures = run.image_capture_times_s
    grid = 1.0 / small_s.encoders.rate_hz
    assert np.all(np.abs(captures / grid - np.round(captures / grid)) > 1e-6)
    np.testing.assert_allclose(run.image_arrival_times_s - captures, 0.04, atol=1e-9)
    assert np.all(np.diff(captures) > 0.02) and len(captures) >= 13


def test_depth_noise_and_dropout_statistics():
    # Static scene: the only differences between frames are the sensor model's.
    s = small("static/none", noise_sigma0_m=0.002, noise_k_per_m=0.003,
              dropout_probability=0.05)
    run = simulate_and_record(s, duration_s=0.2, image_stride=1)
    a, b = run.depth_images_m[0].astype(float), run.depth_images_m[1].astype(float)
    both = np.isfinite(a) & np.isfinite(b)
    z = 0.5 * (a + b)[both]
    diff = (a - b)[both]
    # The difference of two frames has sd sqrt(2) sigma(z); normalised it is N(0, 1),
    # in the near and in the far half of the scene alike.
    r = diff / (np.sqrt(2) * (0.002 + 0.003 * z**2))
    near = z < np.median(z)
    for sel in (near, ~near):
        assert np.std(r[sel]) == pytest.approx(1.0, abs=0.05)
        assert abs(np.mean(r[sel])) < 0.05
    # Dropout: invalid pixels beyond the shared silhouettes/no-hits ~ 5% per frame.
    only_a = np.mean(np.isnan(a) & np.isfinite(b))
    assert only_a == pytest.approx(0.05 * (1 - 0.05), abs=0.01)


def test_same_seed_same_run_and_different_seed_differs():
    s = small(dropout_probability=0.01)
    s.encoders.rate_hz = 200.0
    s.encoders.bias = "random-walk"
    r1 = simulate_and_record(s, duration_s=0.3, image_stride=2)
    r2 = simulate_and_record(s, duration_s=0.3, image_stride=2)
    for key in ("reading_times_s", "readings_rad", "depth_images_m", "truth_bias_rad",
                "truth_X_CE", "image_capture_times_s"):
        np.testing.assert_array_equal(getattr(r1, key), getattr(r2, key), err_msg=key)
    s.seed = 1
    r3 = simulate_and_record(s, duration_s=0.3, image_stride=2)
    assert not np.array_equal(r1.readings_rad, r3.readings_rad)
    assert not np.array_equal(np.nan_to_num(r1.depth_images_m),
                              np.nan_to_num(r3.depth_images_m))


def test_recorded_readings_and_truth_grids():
    s = small()
    s.encoders.rate_hz = 250.0
    run = simulate_and_record(s, duration_s=0.2, image_stride=4)
    np.testing.assert_allclose(run.reading_times_s, np.arange(51) / 250.0, atol=1e-12)
    np.testing.assert_allclose(run.truth_times_s, np.arange(21) / 100.0, atol=1e-12)
    assert run.depth_images_m.shape[1:] == (30, 40)
    assert run.camera_intrinsics.width == 40
    # Constant 8.6 deg bias on the arm joints, none on the head.
    np.testing.assert_allclose(np.degrees(run.truth_bias_rad[:, :7]), 8.6, atol=1e-9)
    np.testing.assert_allclose(run.truth_bias_rad[:, 7:], 0.0, atol=1e-12)
    err = np.degrees(readings_at(run, run.truth_times_s) - run.truth_positions_rad
                     - run.truth_bias_rad)
    assert np.abs(err).max() < 6 * s.encoders.noise_sigma_deg


def test_second_robot_simulates_and_encoders_only_is_exact_without_errors():
    s = Scenario(robot="arm6", duration_s=0.5)
    s.camera.width, s.camera.height = 160, 120
    s.camera.offset = [0.0] * 6
    s.encoders.rate_hz = 100.0
    s.encoders.noise_sigma_deg = 0.0
    s.camera.clock = "encoder-grid"
    run = simulate_and_record(s, duration_s=0.5, image_stride=1)
    assert run.joint_names == ["shoulder_pan", "shoulder_lift", "elbow", "wrist_1",
                               "wrist_2", "wrist_3"]
    assert len(run.image_capture_times_s) == 14
    assert np.isfinite(run.depth_images_m[-1]).mean() > 0.5
    t_err, r_err = pose_errors(encoders_only_X_CE(run), run.truth_X_CE)
    assert t_err.max() < 1e-6 and r_err.max() < 1e-4
    # With a bias the baseline is off.
    s.encoders.bias = "constant"
    biased = simulate_and_record(s, duration_s=0.1, image_stride=8)
    assert pose_errors(encoders_only_X_CE(biased), biased.truth_X_CE)[0].min() > 50.0


def test_dynamic_mode_tracks_the_trajectory():
    s = small(clock="encoder-grid")
    s.mode = "dynamic"
    s.time_step_s = 0.002
    run = simulate_and_record(s, duration_s=0.3, image_stride=8)
    _, world = build_simulated_world(small())
    reference = world.trajectory.positions(run.truth_times_s)
    np.testing.assert_allclose(run.truth_positions_rad[0], reference[0], atol=1e-12)
    assert np.abs(run.truth_positions_rad - reference).max() < np.radians(0.05)
    assert len(run.image_capture_times_s) == 8


def test_occluder_is_between_camera_and_hand_only_while_active():
    def scene(enabled: bool):
        s = small("occlusion/none")
        s.occluder.enabled = enabled
        s.occluder.start_s, s.occluder.end_s = 1.0, 8.0
        diagram, world = build_simulated_world(s)
        sensor = diagram.GetSubsystemByName("world_depth_camera_rgbd")
        ctx = diagram.CreateDefaultContext()

        def render(t):
            ctx.SetTime(t)
            port = sensor.depth_image_32F_output_port()
            image = np.array(port.Eval(sensor.GetMyContextFromRoot(ctx)).data[:, :, 0])
            return image, diagram.GetOutputPort("true_X_CE").Eval(ctx).translation()

        return render, world.intrinsics

    with_box, f = scene(True)
    without_box, _ = scene(False)
    parked, _ = with_box(0.0)  # parked out of view: the image is the one without box
    np.testing.assert_array_equal(parked, without_box(0.0)[0])
    image, (x, y, z) = with_box(5.0)  # in front of the hand
    u, v = int(round(f.fx * x / z + f.cx)), int(round(f.fy * y / z + f.cy))
    reference, _ = without_box(5.0)
    assert image[v, u] < 0.7 * z < reference[v, u]
    assert 0.05 < np.mean(image < reference - 0.1) < 0.6


@pytest.mark.parametrize("mutate, field", [
    (lambda s: setattr(s.encoders, "rate_hz", -5.0), "encoders.rate_hz"),
    (lambda s: setattr(s.camera, "rate_hz", 0.0), "camera.rate_hz"),
    (lambda s: setattr(s.trajectory, "joints", ["arm_joint_9"]), "trajectory.joints"),
    (lambda s: setattr(s.encoders, "biased_joints", ["elbow"]), "encoders.biased_joints"),
    (lambda s: setattr(s, "robot", "nope"), "Scenario.robot"),
])
def test_bad_scenario_values_name_the_field(mutate, field):
    from drake_tracker.sim.scenario.load import validate_scenario

    s = load_scenario("s-full-arm/constant")
    mutate(s)
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        validate_scenario(s)


def test_unknown_preset_and_camera_frame_are_rejected():
    from drake_tracker.robot.model import RobotConfig
    from drake_tracker.sim.scenario.load import validate_scenario

    with pytest.raises(ValueError, match="unknown scenario preset 's-nothing/constant'"):
        load_scenario("s-nothing/constant")
    s = load_scenario("static/none")
    s.robot_config = RobotConfig(camera_frame="no_such_camera")
    with pytest.raises(ValueError, match="camera_frame.*no_such_camera"):
        validate_scenario(s)


def test_scenario_yaml_file_overrides_a_preset(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text("preset: s-head/time-varying\nduration_s: 5.0\nencoders:\n  rate_hz: 500.0\n")
    s = load_scenario(path)
    assert (s.duration_s, s.encoders.rate_hz, s.encoders.bias) == (5.0, 500.0, "steps")
    assert s.trajectory.joints == ["head_pan", "head_tilt"]
    path.write_text("preset: static/none\nencoders:\n  rate_hz: -1.0\n")
    with pytest.raises(ValueError, match="encoders.rate_hz"):
        load_scenario(path)


def test_robot_config_is_read_from_scenario_yaml(tmp_path):
    path = tmp_path / "arm6.yaml"
    path.write_text(
        "trajectory: {kind: static}\n"
        "robot_config:\n"
        "  model_file: arm6_on_stand.urdf\n"
        "  end_effector_frame: tip\n"
        "  added_frames: {tip: {parent: tool_center, xyz_m: [0, 0, 0.1]}}\n")
    s = load_scenario(path)
    config = s.resolved_robot_config()
    assert (config.model_file, config.end_effector_frame) == ("arm6_on_stand.urdf", "tip")
    assert config.added_frames["tip"].xyz_m == [0.0, 0.0, 0.1]
    path.write_text("preset: static/none\nrobot_config: {end_effector_frame: nowhere}\n")
    with pytest.raises(ValueError, match="Scenario.robot_config.*nowhere"):
        load_scenario(path)
