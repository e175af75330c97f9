"""Calibrated cameras: ``drake-tracker calibrate-cameras`` (``io/calibrate_run.py``) on a
simulated two-camera run, and the tracker parameters it writes (``camera_offsets``)."""

import numpy as np
import pytest
from fast_params import seeded_params
from two_cameras import in_out_in_recording, two_camera_config

from drake_tracker.core.calibration.fold import equivalent_offsets
from drake_tracker.core.filter.kalman import MEAN_A
from drake_tracker.io.calibrate_run import calibrate_run
from drake_tracker.io.replay import model_for_run, readings_at
from drake_tracker.params.loading import load_tracker_params
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.params.tracker_params import JointNoise, TrackerParams
from drake_tracker.robot.model import build_tracker_model
from drake_tracker.tracker import Tracker


@pytest.fixture(scope="module")
def two_cameras():
    return build_tracker_model(two_camera_config())


@pytest.fixture(scope="module")
def recorded():
    """1.5 s of in-out-in-2cam/none (``two_cameras.in_out_in_recording``)."""
    return in_out_in_recording(1.5)


def camera_world_pose(model, name, q):
    plant = model.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    return plant.CalcRelativeTransform(context, plant.world_frame(), model.camera(name).frame)


def test_a_head_bias_folds_into_the_camera_offsets_exactly_as_drake_places_the_camera(
        two_cameras):
    model = two_cameras
    rng = np.random.default_rng(4)
    q = np.zeros(model.num_joints)
    q[model.robot_joint_indices] = rng.normal(0.0, 0.3, len(model.robot_joint_indices))
    for name in model.camera_names:
        q[model.camera_joint_indices(name)] = rng.normal(0.0, [0.02] * 3 + [0.03] * 3)
    target = q.copy()
    head = [model.joint_names.index(n) for n in ("head_pan", "head_tilt")]
    target[head] += np.radians([1.5, -2.0])  # what a head bias of the fit does
    for name in model.camera_names:
        o = equivalent_offsets(model, name, target, q)
        moved = q.copy()
        moved[model.camera_joint_indices(name)] = o
        np.testing.assert_allclose(camera_world_pose(model, name, moved).GetAsMatrix4(),
                                   camera_world_pose(model, name, target).GetAsMatrix4(),
                                   atol=1e-9)
    # The post is not on the head: its offsets are what they were.
    np.testing.assert_allclose(equivalent_offsets(model, "post", target, q),
                               q[model.camera_joint_indices("post")], atol=1e-12)


def test_the_joints_that_move_only_a_camera_are_the_heads(two_cameras, apollo):
    """Drake's kinematics: a head joint moves the head camera and not the hand; an arm
    joint moves the hand; nothing moves the post."""
    from drake_tracker.core.calibration.fold import camera_only_joints

    assert camera_only_joints(two_cameras) == ["head_pan", "head_tilt"]
    assert camera_only_joints(apollo) == ["head_pan", "head_tilt"]


def test_camera_offsets_are_checked_and_name_the_models_cameras(two_cameras):
    params = TrackerParams()
    params.camera_offsets = {"camera": [0.0] * 5}
    with pytest.raises(ValueError, match=r"camera_offsets\[camera\].*6 finite values"):
        resolve_tracker_params(params, two_cameras)
    params.camera_offsets = {"camera": [0.0, 0.0, float("nan"), 0.0, 0.0, 0.0]}
    with pytest.raises(ValueError, match=r"camera_offsets\[camera\]"):
        resolve_tracker_params(params, two_cameras)
    params.camera_offsets = {"side": [0.0] * 6}
    with pytest.raises(ValueError, match=r"unknown cameras \['side'\].*\['camera', 'post'\]"):
        resolve_tracker_params(params, two_cameras)


def test_a_calibrated_camera_is_read_held_and_restarted_to(two_cameras):
    """With ``camera_offsets`` the virtual joints read the calibrated values: the
    estimate starts there, and without ``estimate_camera_offset`` it stays there through
    readings and images; Drake's kinematics place each camera there."""
    model = two_cameras
    calibrated = {"camera": [0.02, -0.015, 0.018, 0.046, -0.026, 0.017],
                  "post": [-0.015, 0.02, -0.01, -0.026, 0.017, 0.035]}
    params = seeded_params(0)
    params.estimate_camera_offset = False
    params.camera_offsets = calibrated
    resolved = resolve_tracker_params(params, model)
    for name, o in calibrated.items():
        joints = model.camera_joint_indices(name)
        np.testing.assert_array_equal(resolved.joints.virtual_reading[joints], o)
        np.testing.assert_array_equal(resolved.joints.initial_mean[joints], o)
    tracker = Tracker(model, params=params, cameras={n: _camera() for n in calibrated})
    reading = np.zeros(len(model.robot_joint_indices))
    for k in range(20):
        tracker.add_reading(0.01 * k, reading)
    _, belief = tracker.buffer.present()
    for name, o in calibrated.items():
        np.testing.assert_allclose(belief[MEAN_A][model.camera_joint_indices(name)], o,
                                   atol=1e-9)
        q = np.zeros(model.num_joints)
        q[model.camera_joint_indices(name)] = o
        X = tracker.estimate().X_WC_by_camera[name]
        np.testing.assert_allclose(np.asarray(X), camera_world_pose(
            model, name, q).GetAsMatrix4(), atol=1e-6)
    # A restart from the encoders returns each camera to its calibrated mount, not to
    # the nominal one.
    restart = tracker.channel("camera").images.restart
    restarted = restart.apply(belief)
    for name, o in calibrated.items():
        np.testing.assert_allclose(restarted[MEAN_A][model.camera_joint_indices(name)], o,
                                   atol=1e-9)


def _camera():
    from two_cameras import CAMERA

    return CAMERA


def test_calibrate_cameras_finds_each_mount_better_than_the_tracker_did(recorded):
    run = recorded
    model = model_for_run(run)
    params = seeded_params(0)
    params.image.min_image_interval_s = 0.1
    result = calibrate_run(run, params, start_s=0.3, end_s=1.5, images_per_camera=6,
                               evaluations=3000)
    assert result.fit.log_likelihood > result.fit.log_likelihood_start
    assert result.images == {name: 6 for name in model.camera_names}
    # Each camera's world pose, the calibrated offsets at the true head angles against
    # the true mount, and the tracker's own estimate at 1.5 s against the same truth.
    truth_index = np.searchsorted(run.truth_times_s, 1.5)
    q_true = np.zeros(model.num_joints)
    q_true[model.robot_joint_indices] = run.truth_positions_rad[truth_index]
    for name, o in run.truth_offsets_by_camera.items():
        q_true[model.camera_joint_indices(name)] = o[truth_index]
    reading = readings_at(run, np.array([1.5]))[0]
    q_start = result.fit.layout.configurations(result.fit.theta_start, reading)[0]

    def pose_error(name, q):
        error = camera_world_pose(model, name, q).inverse() @ camera_world_pose(
            model, name, q_true)
        return np.linalg.norm(error.translation()), error.rotation().ToAngleAxis().angle()

    for name in model.camera_names:
        q = q_true.copy()
        q[model.camera_joint_indices(name)] = result.offsets[name]
        (mm, rad), (mm_start, rad_start) = pose_error(name, q), pose_error(name, q_start)
        # Within the 5 mm and 0.5 deg, and nearer than the tracker's estimate.
        assert mm < 0.005 and rad < np.radians(0.5), (name, mm, np.degrees(rad))
        # (Measured: 2.5 mm, 0.34 deg and 3.5 mm, 0.09 deg against the tracker's 7.3 mm,
        # 0.99 deg and 11.4 mm, 0.36 deg.)
        assert mm < mm_start and rad < rad_start, (name, mm, mm_start, rad, rad_start)
    text = result.params_yaml()
    assert "camera_offsets:" in text
    # The head that carries a camera is trusted from now on: its error is in the offsets.
    assert sorted(result.trusted) == ["head_pan", "head_tilt"]
    assert not any(noise.has_bias for noise in result.trusted.values())


def test_the_written_parameters_load_as_tracker_parameters(tmp_path):
    from drake_tracker.io.calibrate_run import CameraCalibration

    fit = type("Fit", (), {"log_likelihood_start": 1.0, "log_likelihood": 2.0})()
    offsets = {"camera": np.array([0.01, 0.0, -0.02, 0.001, 0.0, 0.03]),
               "post": np.arange(6) / 100.0}
    path = tmp_path / "cameras.yaml"
    head = JointNoise(encoder_noise_std_rad=3e-4, has_bias=False)
    path.write_text(CameraCalibration(offsets, fit, (0.5, 2.5), {"camera": 3, "post": 3},
                                      {"head_pan": head}).params_yaml())
    loaded = load_tracker_params(path)
    assert loaded.estimate_camera_offset is False  # held where the fit put them
    assert loaded.kalman.overrides == {"head_pan": head}
    for name, o in offsets.items():
        np.testing.assert_allclose(loaded.camera_offsets[name], o, rtol=1e-5)


def test_a_run_of_one_camera_cannot_be_calibrated():
    from drake_tracker.io.synthetic import synthetic_run
    from drake_tracker.robot.model import robot_preset

    run = synthetic_run(build_tracker_model(robot_preset("apollo")), duration_s=0.3)
    with pytest.raises(ValueError, match="needs several cameras"):
        calibrate_run(run)


def test_the_command_writes_parameters_that_track_uses(recorded, tmp_path, capsys):
    """``calibrate-cameras`` on a two-camera run writes the held ``camera_offsets``, and
    ``track --params`` of the same run takes them; a one-camera run is a one-line error."""
    from cli_runs import assert_one_line_error, run_cli

    from drake_tracker.io.synthetic import synthetic_run
    from drake_tracker.robot.model import robot_preset

    run_path = tmp_path / "run.npz"
    recorded.save(run_path)
    out = tmp_path / "cal" / "cameras.yaml"
    code, stdout, err = run_cli(["calibrate-cameras", "--run", str(run_path), "--out",
                                 str(out), "--from", "0.3", "--to", "1.5",
                                 "--images-per-camera", "3", "--evaluations", "300"], capsys)
    assert code == 0, err
    assert f"wrote {out}" in stdout
    loaded = load_tracker_params(out)
    assert sorted(loaded.camera_offsets) == ["camera", "post_camera"]
    code, stdout, err = run_cli(["track", "--run", str(run_path), "--params", str(out),
                                 "--out", str(tmp_path / "tracked")], capsys)
    assert code == 0, err
    single = tmp_path / "single.npz"
    synthetic_run(build_tracker_model(robot_preset("apollo")), duration_s=0.3).save(single)
    code, _, err = run_cli(["calibrate-cameras", "--run", str(single), "--out",
                            str(tmp_path / "x.yaml")], capsys)
    assert_one_line_error(code, err, "single.npz", "needs several cameras")


def test_a_window_in_which_a_camera_sees_no_arm_is_refused(recorded):
    """A camera whose images show no arm cannot be placed: a clear error, no fit."""
    run = recorded
    model = model_for_run(run)
    params = seeded_params(0)
    # Turned away from the arm: at the tracker's estimate it renders none of it.
    params.camera_offsets = {"post_camera": [0.0, 0.0, 0.0, np.pi / 2, 0.0, 0.0]}
    params.estimate_camera_offset = False
    with pytest.raises(ValueError, match="camera 'post_camera' sees at most 0 pixels"):
        calibrate_run(run, params, start_s=0.3, end_s=1.5, images_per_camera=3,
                      evaluations=200, model=model)


def test_without_bounds_the_window_is_the_first_in_which_every_camera_sees_the_arm(
        recorded):
    """The window found lasts ``window_s`` inside the run, with images of both cameras;
    a window longer than the run is a clear error, and so is half a window given."""
    params = seeded_params(0)
    params.image.min_image_interval_s = 0.1
    result = calibrate_run(recorded, params, window_s=0.6, images_per_camera=3,
                           evaluations=300)
    start, end = result.window_s
    assert end - start == pytest.approx(0.6)
    assert 0.0 < start and end <= recorded.truth_times_s[-1]
    assert result.images == {"camera": 3, "post_camera": 3}
    with pytest.raises(ValueError, match="no 5 s in which 3 images of every camera"):
        calibrate_run(recorded, params, window_s=5.0, evaluations=300)
    with pytest.raises(ValueError, match="start and end together"):
        calibrate_run(recorded, params, start_s=0.3, evaluations=300)


def test_a_camera_on_the_arm_keeps_its_offsets_and_the_heads_takes_the_heads_error():
    """Folding takes only the joints that move a camera and not the hand (the head): a
    camera on the arm's last link keeps the fit's offsets (the arm's biases are the
    tracker's to follow), and the head camera, with the head at its readings, lands
    where the fit's head bias put it (Drake's kinematics)."""
    from drake_tracker.core.calibration.fold import camera_only_joints, folded_offsets
    from drake_tracker.core.calibration.window_fit import WindowFit, WindowLayout
    from drake_tracker.robot.model import CameraMount, FrameOffset, robot_preset

    config = robot_preset("apollo")
    config.added_frames = {"wrist_nominal": FrameOffset(
        parent="arm_link_7", xyz_m=[0.0, 0.05, 0.1], rpy_deg=[0.0, -90.0, 0.0])}
    config.cameras = [CameraMount("camera", "camera_optical"),
                      CameraMount("wrist", "wrist_nominal")]
    model = build_tracker_model(config)
    assert camera_only_joints(model) == ["head_pan", "head_tilt"]
    robot = np.asarray(model.robot_joint_indices)
    layout = WindowLayout(model.num_joints, robot, np.arange(len(robot)),
                          {n: model.camera_joint_indices(n) for n in model.camera_names})
    rng = np.random.default_rng(9)
    theta = np.concatenate([rng.normal(0.0, 0.03, len(robot))]
                           + [rng.normal(0.0, [0.01] * 3 + [0.02] * 3) for _ in range(2)])
    fit = WindowFit(layout, theta, theta, 0.0, 0.0, 1)
    reading = rng.normal(0.0, 0.3, len(robot))
    folded = folded_offsets(model, layout, fit, reading, camera_only_joints(model))
    np.testing.assert_allclose(folded["wrist"], layout.offsets(theta, "wrist"), atol=1e-9)
    q_fit = layout.configurations(theta, reading)[0]
    q = q_fit.copy()
    head = [model.joint_names.index(n) for n in ("head_pan", "head_tilt")]
    q[head] = reading[[list(robot).index(j) for j in head]]
    q[model.camera_joint_indices("camera")] = folded["camera"]
    np.testing.assert_allclose(camera_world_pose(model, "camera", q).GetAsMatrix4(),
                               camera_world_pose(model, "camera", q_fit).GetAsMatrix4(),
                               atol=1e-9)
    assert np.max(np.abs(folded["camera"] - layout.offsets(theta, "camera"))) > 1e-3
