"""The cameras calibrated by the tracker itself while it runs (``core/calibration/online.py``):
the window it waits for, what it holds (exact algebra of the pinned observation), and on a
simulated two-camera run, each mount against the truth."""

import numpy as np
import pytest
from fast_params import seeded_params
from two_cameras import in_out_in_recording

from drake_tracker.core.calibration.calibration_params import SelfCalibrationParams
from drake_tracker.core.calibration.online import PIN_STD, HeldCameras, found_window
from drake_tracker.core.filter.angle_observation import AngleObservation, Restart
from drake_tracker.core.filter.kalman import COV_AB, MEAN_A, MEAN_B, VAR_A, VAR_B
from drake_tracker.io.replay import model_for_run
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.tracker import Tracker


def test_the_window_waits_for_every_camera_to_track_and_to_see_the_arm():
    seen = {"a": [(0.1 * k, True) for k in range(30)], "b": [(0.1 * k + 0.05, True)
                                                           for k in range(30)]}
    since = {"a": 0.3, "b": 0.6}
    assert found_window(seen, since, ["a", "b"], 2.55, 2.0) is None  # b tracks since 0.6
    assert found_window(seen, since, ["a", "b"], 2.65, 2.0) == pytest.approx(0.65)
    assert found_window(seen, {"a": 0.3}, ["a", "b"], 2.9, 2.0) is None  # b never tracked
    # An image that hides the arm is left out; three that show it are enough.
    hidden = {"a": seen["a"], "b": [(t, t < 0.9 or t > 2.7) for t, _ in seen["b"]]}
    assert found_window(hidden, since, ["a", "b"], 2.8, 2.0) is None  # b: 0.85, 2.75
    assert found_window(hidden, since, ["a", "b"], 2.85, 2.0) == pytest.approx(0.85)
    # At least three images of each camera.
    sparse = {"a": seen["a"], "b": [(1.0, True), (2.9, True)]}
    assert found_window(sparse, since, ["a", "b"], 2.9, 2.0) is None


def _belief(rng, n, reading_var=1e-8):
    """A belief after a reading: a + b known within ``reading_var``."""
    belief = np.zeros((5, n))
    belief[MEAN_A] = rng.normal(0.0, 0.3, n)
    belief[MEAN_B] = rng.normal(0.0, 0.05, n)
    belief[VAR_A] = rng.uniform(1e-5, 1e-3, n)
    belief[VAR_B] = belief[VAR_A] + reading_var
    belief[COV_AB] = -belief[VAR_A]
    return belief


def _held(n=8):
    offsets = np.full(n, np.nan)
    offsets[5:] = [0.01, -0.02, 0.03]  # a camera's offsets (three of them here)
    trusted = np.zeros(n, bool)
    trusted[1] = True  # a head joint: held at its reading
    return HeldCameras(offsets, trusted, (0.0, 2.0), (0.0, 1.0))


def test_the_held_prior_and_blocks():
    rng = np.random.default_rng(3)
    held, prior = _held(), _belief(rng, 8)
    out = held.prior(prior)
    # Every joint's a + b (what its readings measure) is kept.
    np.testing.assert_allclose(out[MEAN_A] + out[MEAN_B], prior[MEAN_A] + prior[MEAN_B])
    np.testing.assert_allclose(out[MEAN_A, 5:], held.offsets[5:])
    assert out[MEAN_B, 1] == pytest.approx(0.0, abs=1e-15)  # trusted: bias 0
    free = ~held.held
    np.testing.assert_array_equal(out[:, free], prior[:, free])
    blocks = held.blocks([np.array([0]), np.array([1]), np.array([2, 5]), np.array([6, 7])])
    assert [b.tolist() for b in blocks] == [[0], [2]]


def test_a_pinned_observation_puts_the_held_joints_at_their_targets_and_no_other():
    """Against the exact Gaussian product: the free joints' posterior is the unpinned
    observation's, each held joint's angle is its target within PIN_STD."""
    rng = np.random.default_rng(4)
    n = 8
    held, prior = _held(n), _belief(rng, n)
    observation = AngleObservation(rng.uniform(1e3, 1e5, n), rng.normal(0.0, 100.0, n))
    plain, pinned = observation.apply(prior), held.pin(observation, prior).apply(prior)
    free = ~held.held
    np.testing.assert_allclose(pinned[:, free], plain[:, free], rtol=1e-12)
    target = held.targets(prior)
    np.testing.assert_allclose(pinned[MEAN_A, held.held], target[held.held], atol=1e-8)
    assert np.all(pinned[VAR_A, held.held] <= PIN_STD ** 2)
    # The trusted joint's bias is then 0 (eq. 16: the reading's a + b is kept): its
    # angle is its reading.
    assert abs(pinned[MEAN_B, 1]) < 1e-8
    np.testing.assert_allclose(pinned[MEAN_A] + pinned[MEAN_B], prior[MEAN_A] + prior[MEAN_B],
                               atol=1e-8)
    # Its target is the prior's a + b, the reading.
    assert target[1] == pytest.approx(prior[MEAN_A, 1] + prior[MEAN_B, 1])


def test_a_restart_returns_the_held_cameras_to_their_calibration():
    rng = np.random.default_rng(5)
    n = 8
    held, prior = _held(n), _belief(rng, n)
    restart = Restart(np.full(n, 1e-3), np.full(n, 1e-2), reading_var=np.full(n, 1e-8))
    restarted = held.restart(restart).apply(prior)
    np.testing.assert_allclose(restarted[MEAN_A, 5:], held.offsets[5:])
    # Without the calibration, a restart puts the camera at a + b (its nominal mount
    # for a virtual joint, whose reading is 0).
    np.testing.assert_allclose(restart.apply(prior)[MEAN_A, 5:],
                               prior[MEAN_A, 5:] + prior[MEAN_B, 5:])
    # A kept restart keeps every mean: the pin of the image's observation holds them.
    kept = restart.kept()
    assert held.restart(kept) is kept


def test_the_parameters_are_checked_and_switch_it_off():
    with pytest.raises(ValueError, match="window_s"):
        SelfCalibrationParams(window_s=-1.0).validate()
    with pytest.raises(ValueError, match="max_evaluations"):
        SelfCalibrationParams(max_evaluations=3).validate()


@pytest.fixture(scope="module")
def recorded():
    """2 s of in-out-in-2cam/none (``two_cameras.in_out_in_recording``)."""
    return in_out_in_recording(2.0)


def _tracked(run, params):
    from drake_tracker.io.stream import track_stream
    from drake_tracker.io.track_files import run_events

    tracker = Tracker(model_for_run(run), params=params, cameras=run.intrinsics_by_camera)
    track_stream(run_events(run), tracker)
    return tracker


def test_the_tracker_calibrates_its_cameras_and_holds_them(recorded):
    """The first second in which both cameras see the arm is fitted, once; each mount
    (with the head at its true angles) ends within the issue's 5 mm and 0.5 deg and
    nearer than where the tracker alone puts it, and the estimate holds it there."""
    run = recorded
    params = seeded_params(0)
    params.image.min_image_interval_s = 0.1
    params.camera_calibration = SelfCalibrationParams(window_s=1.0)
    tracker = _tracked(run, params)
    held = tracker.held
    assert held is not None, "no window found"
    start_s, end_s = held.window_s
    assert end_s - start_s == pytest.approx(1.0) and end_s <= 2.0
    assert held.log_likelihood[1] > held.log_likelihood[0]
    model = tracker.model
    # The head is trusted: the hand's chain is not held.
    assert [model.joint_names[j] for j in np.flatnonzero(held.trusted)] == [
        "head_pan", "head_tilt"]
    params.camera_calibration = SelfCalibrationParams(window_s=0.0)
    alone = _tracked(run, params).estimate()
    estimate = tracker.estimate()
    for name in model.camera_names:
        joints = model.camera_joint_indices(name)
        np.testing.assert_allclose(estimate.camera_offsets[name], held.offsets[joints],
                                   atol=1e-5)
    # Each camera's world pose: the estimate's (its robot angles and offsets) against
    # the truth's, the calibrated tracker's and the tracker's alone.
    for name in model.camera_names:
        mm, rad = _camera_world_error(run, model, name, estimate)
        mm_alone, rad_alone = _camera_world_error(run, model, name, alone)
        assert mm < 0.005 and rad < np.radians(0.5), (name, mm, np.degrees(rad))
        assert mm < mm_alone and rad < rad_alone, (name, mm, mm_alone, rad, rad_alone)


def _camera_world_error(run, model, name, estimate):
    """The estimated camera's world pose against the true one at the estimate's time."""
    from pydrake.math import RigidTransform

    plant = model.plant
    context = plant.CreateDefaultContext()
    k = min(int(np.searchsorted(run.truth_times_s, estimate.time_s)),
            len(run.truth_times_s) - 1)
    q = np.zeros(model.num_joints)
    q[model.robot_joint_indices] = run.truth_positions_rad[k]
    for camera, o in run.truth_offsets_by_camera.items():
        q[model.camera_joint_indices(camera)] = o[k]
    plant.SetPositions(context, q)
    truth = plant.CalcRelativeTransform(context, plant.world_frame(), model.camera(name).frame)
    error = RigidTransform(np.asarray(estimate.X_WC_by_camera[name])).inverse() @ truth
    return np.linalg.norm(error.translation()), error.rotation().ToAngleAxis().angle()


def test_a_camera_without_images_switches_it_off(recorded):
    """The fit needs every camera's images: with one of the model's cameras given no
    images, the tracker does not calibrate (the camera's offset stays at its prior)."""
    run = recorded
    model = model_for_run(run)
    params = resolve_tracker_params(seeded_params(0), model)
    assert params.camera_calibration is not None
    tracker = Tracker(model, params=params,
                      cameras={run.camera_name: run.camera_intrinsics})
    assert tracker.calibration is None


def test_the_searches_leave_the_held_joints_alone():
    """Held, the second opinion's, the kept search's and the challenger's searches cover
    every block but the held joints, and their restarts return the offsets to the
    calibration; the tracker's own searches are as they were."""
    from two_cameras import CAMERA, two_camera_config

    from drake_tracker.robot.model import build_tracker_model

    model = build_tracker_model(two_camera_config())
    tracker = Tracker(model, params=seeded_params(0), cameras={"camera": CAMERA,
                                                               "post": CAMERA})
    processor = tracker.channel("camera").images
    n = model.num_joints
    offsets = np.full(n, np.nan)
    offsets[model.camera_joint_indices("camera")] = 0.01
    offsets[model.camera_joint_indices("post")] = -0.01
    trusted = np.isin(model.joint_names, ["head_pan", "head_tilt"])
    held = HeldCameras(offsets, trusted, (0.0, 1.0), (0.0, 1.0))
    search = processor.search.held_by(held)
    covered = set(np.concatenate(search._blocks).tolist())
    before = set(np.concatenate(processor.update.blocks).tolist())
    assert covered == {j for j in before if not held.held[j]} and covered < before
    assert not any(held.held[b].any() for b in search._drift_blocks)
    prior = _belief(np.random.default_rng(6), n)
    mine = model.camera_joint_indices("camera")
    np.testing.assert_allclose(search.restart.apply(prior)[MEAN_A][mine], 0.01)
    # The tracker's own search is untouched: its restart still goes to a + b.
    assert processor.search._blocks is None
    np.testing.assert_allclose(processor.search.restart.apply(prior)[MEAN_A][mine],
                               prior[MEAN_A][mine] + prior[MEAN_B][mine])
