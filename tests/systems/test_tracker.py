"""The offline tracker: bad input, uninformative images, the CPF on a Drake-rendered
image, and accuracy against the encoders-only baseline on synthetic runs."""

import logging

import numpy as np
import pytest
from fast_params import seeded_params

from drake_tracker.core.cpf.image_update import CpfImageUpdate
from drake_tracker.core.filter.kalman import initial_moments
from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.render.configurations import default_view_configuration
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.io.replay import encoders_only_X_CE, replay_run, run_report
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.params.loading import load_tracker_params
from drake_tracker.params.resolve import (
    camera_chain_joints,
    resolve_kalman_params,
    resolve_tracker_params,
)
from drake_tracker.params.tracker_params import JointNoise, TrackerParams
from drake_tracker.robot.model import build_tracker_model, robot_preset
from drake_tracker.tracker import Tracker

CAMERA = CameraIntrinsics.from_fov(80, 60, np.radians(45.0))


@pytest.fixture(scope="module")
def arm6():
    return build_tracker_model(robot_preset("arm6"))


def test_bad_readings_are_rejected_by_name(apollo, caplog):
    tracker = Tracker(apollo, CAMERA, seeded_params())
    n = len(apollo.robot_joint_names)
    with pytest.raises(ValueError, match="shape"):
        tracker.add_reading(0.0, np.zeros(n + 1))
    # Unusable values and stamps are skipped with a warning (core/sensors/timestamps.py).
    with caplog.at_level(logging.WARNING):
        tracker.add_reading(0.0, np.full(n, np.nan))
        assert not tracker.started and "not finite" in caplog.text
        tracker.add_reading(0.0, np.zeros(n))
        bad = np.zeros(n)
        bad[2] = np.nan
        caplog.clear()
        tracker.add_reading(0.01, bad)
        assert "arm_joint_3" in caplog.text
        tracker.add_reading(0.0, np.zeros(n))
        assert "not after" in caplog.text
    assert np.all(np.isfinite(tracker.estimate().positions))


def test_bad_images_are_rejected(apollo):
    tracker = Tracker(apollo, CAMERA, seeded_params())
    tracker.add_reading(0.0, np.zeros(len(apollo.robot_joint_names)))
    with pytest.raises(ValueError, match="shape"):
        tracker.add_image(DepthFrame(0.0, 0.0, np.ones((60, 81), np.float32), 0))
    with pytest.raises(ValueError, match="dtype"):  # uint16 is millimetres (issue 14)
        tracker.add_image(DepthFrame(0.0, 0.0, np.ones((60, 80), np.int32), 0))
    with pytest.raises(ValueError, match="empty"):
        tracker.add_image(DepthFrame(0.0, 0.0, np.ones((0, 0), np.float32), 0))


def test_future_and_too_old_images_are_skipped_with_warning(apollo, caplog):
    tracker = Tracker(apollo, CAMERA, seeded_params())
    n = len(apollo.robot_joint_names)
    for k in range(30):
        tracker.add_reading(0.1 * k, np.zeros(n))
    before = tracker.estimate().positions.copy()
    image = np.full((60, 80), 2.0, np.float32)
    with caplog.at_level(logging.WARNING):
        assert not tracker.add_image(DepthFrame(5.0, 5.0, image, 0))
        assert not tracker.add_image(DepthFrame(0.2, 2.9, image, 1))
    assert "future" in caplog.text and "older than" in caplog.text
    np.testing.assert_array_equal(tracker.estimate().positions, before)


def test_all_nan_image_changes_nothing(apollo):
    tracker = Tracker(apollo, CAMERA, seeded_params())
    n = len(apollo.robot_joint_names)
    tracker.add_reading(0.0, np.zeros(n))
    tracker.add_reading(0.05, np.zeros(n))
    before = tracker.estimate()
    assert not tracker.add_image(
        DepthFrame(0.02, 0.05, np.full((60, 80), np.nan, np.float32), 0))
    after = tracker.estimate()
    np.testing.assert_array_equal(after.positions, before.positions)
    np.testing.assert_array_equal(after.position_variances, before.position_variances)
    assert np.all(np.isfinite(after.X_CE))


def test_bad_parameters_name_the_problem(apollo, tmp_path):
    """Checked once, when resolved for the model (the Tracker and AddTracker do that),
    or when a file is loaded; each error names its field."""
    params = TrackerParams()
    params.kalman.overrides["no_such_joint"] = JointNoise()
    with pytest.raises(ValueError, match="no_such_joint"):
        resolve_tracker_params(params, apollo)
    params = TrackerParams()
    params.kalman.robot_joints.encoder_noise_std_rad = 0.0
    with pytest.raises(ValueError, match="encoder_noise_std_rad"):
        Tracker(apollo, CAMERA, params)
    params = TrackerParams()
    params.kalman.robot_joints.bias_decay_per_s = 1.5
    with pytest.raises(ValueError, match=r"c must be in \(0, 1\]"):
        resolve_tracker_params(params, apollo)
    params = TrackerParams()
    params.initial_positions_rad["no_such_joint"] = 0.0
    with pytest.raises(ValueError, match="initial_positions_rad"):
        resolve_tracker_params(params, apollo)
    path = tmp_path / "bad.yaml"
    path.write_text("image:\n  num_particles: 0\n")
    with pytest.raises(ValueError, match="image.num_particles"):
        load_tracker_params(path)
    path.write_text("image:\n  no_such_field: 3\n")
    with pytest.raises(ValueError, match="no_such_field"):
        load_tracker_params(path)


def test_yaml_overrides_reach_the_bank(apollo, tmp_path):
    path = tmp_path / "params.yaml"
    path.write_text("kalman:\n  overrides:\n    head_pan:\n      has_bias: false\n"
                    "      bias_process_std_rad_per_sqrt_s: 0.0\n"
                    "      initial_bias_std_rad: 0.0\n")
    bank = resolve_kalman_params(load_tracker_params(path), apollo.joint_names)
    k = apollo.joint_names.index("head_pan")
    assert not bank.has_bias[k] and bank.has_bias[0]


def test_camera_chain_is_read_from_the_plant(apollo, arm6):
    assert camera_chain_joints(apollo) == ["head_pan", "head_tilt"]
    assert camera_chain_joints(arm6) == []


def test_cpf_moves_each_joint_toward_the_truth_on_a_drake_rendered_image(apollo):
    """The image is rendered by Drake's RenderEngineVtk (independent of the batched
    renderer the filter uses) at a known configuration; each joint's prior is 5 deg off
    with a 5 deg std, the others at the truth."""
    q_true = default_view_configuration(apollo)
    q_true[apollo.joint_names.index("arm_joint_1")] = 0.3
    q_true[apollo.joint_names.index("arm_joint_6")] = 0.4
    image = make_renderer(apollo, CAMERA, "drake").render(q_true[None])[0]
    image = np.where(np.isfinite(image), image, 2.5)
    update = CpfImageUpdate(apollo, CAMERA, [np.array([i]) for i in range(apollo.num_joints)],
                            150, TrackerParams().image.likelihood)
    observation = update.prepare(image.astype(np.float32))
    errors = []
    for j, name in enumerate(apollo.robot_joint_names):
        k = apollo.joint_names.index(name)
        mean = q_true.copy()
        mean[k] += np.radians(5.0)
        std = np.full(apollo.num_joints, 1e-6)
        std[k] = np.radians(5.0)
        prior = initial_moments(mean, std, std, np.ones(apollo.num_joints, bool))
        result = update(prior, observation, np.random.default_rng(j))
        error = np.degrees(abs(result.mean[k] - q_true[k]))
        # Toward the truth: well inside the 5 deg start for every joint (the flange roll
        # is the least visible at 80x60).
        assert error < 3.0, (name, error)
        assert np.all(np.isfinite(result.variance))
        errors.append(error)
    assert np.median(errors) < 0.5, errors


def test_fusion_beats_encoders_only_on_synthetic_runs_over_seeds(apollo):
    """3 deg of bias on every joint and a 1 cm / 1 deg camera offset; 2 s of data, three
    seeds (data and filter): the median over seeds of the median error."""
    ratios = []
    for seed in range(3):
        run = synthetic_run(apollo, duration_s=2.0, bias_rad=np.radians(3.0), seed=seed)
        result = replay_run(run, seeded_params(seed), apollo)
        report = run_report(run, {"encoders_only": encoders_only_X_CE(run, apollo),
                                  "full_fusion": result.X_CE})
        encoders = report["methods"]["encoders_only"]["translation_mm"]["p50"]
        fusion = report["methods"]["full_fusion"]["translation_mm"]["p50"]
        ratios.append(encoders / fusion)
        assert np.all(np.isfinite(result.positions[np.isfinite(result.positions[:, 0])]))
    assert np.median(ratios) > 5.0, ratios


def test_second_robot_tracks(arm6):
    run = synthetic_run(arm6, duration_s=1.5, bias_rad=np.radians(3.0), seed=0)
    result = replay_run(run, seeded_params(), arm6)
    report = run_report(run, {"encoders_only": encoders_only_X_CE(run, arm6),
                              "full_fusion": result.X_CE})
    assert (report["methods"]["full_fusion"]["translation_mm"]["p50"]
            < report["methods"]["encoders_only"]["translation_mm"]["p50"] / 2.0)
