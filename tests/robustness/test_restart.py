"""Never lost for good: a belief that the images show wrong restarts from the encoders.

The estimate below puts the arm out of the camera's view (a 100 deg bias on the shoulder)
while the encoders, and the image, show it in view. The out-of-view estimate explains
nothing and contradicts nothing, so no image update can move it; the restart is what
brings it back.
"""

from dataclasses import replace

import numpy as np
import pytest

from drake_tracker.core.filter.angle_observation import AngleObservation, Restart
from drake_tracker.core.filter.estimate import PoseReadout
from drake_tracker.core.filter.kalman import COV_AB, MEAN_A, MEAN_B, VAR_A, VAR_B
from drake_tracker.core.filter.start import full_reading, new_bank_and_belief
from drake_tracker.core.image_processor import ImageProcessor
from drake_tracker.core.likelihood.occlusion import observed_image
from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.render.configurations import default_view_configuration
from drake_tracker.core.robustness.health import (
    HealthParams,
    ImageConsistency,
    TrackerHealth,
    confirms_more,
    image_consistency,
    is_misplaced,
    next_health,
    restart_due,
)
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.metrics import pose_errors
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import build_tracker_model, robot_preset

CAMERA = CameraIntrinsics.from_fov(80, 60, np.radians(45.0))
SHOULDER_BIAS_RAD = np.radians(100.0)


def test_a_restart_that_keeps_the_bias_is_a_bias_step_the_readings_hold():
    """``Restart.kept()``: every mean stays (biases, camera offset); the reading's sum
    a + b keeps its variance, so the next reading's innovation is unchanged, while the
    angle marginal widens by the step's variance; commutes with an angle shift."""
    from drake_tracker.core.filter.kalman import JointKalmanBank, KalmanBankParams

    rng = np.random.default_rng(3)
    prior = np.abs(rng.normal(size=(5, 4))) * 0.01
    prior[COV_AB] = -0.5 * np.sqrt(prior[VAR_A] * prior[VAR_B])
    prior[MEAN_B] = [0.3, -0.2, 0.0, 0.1]
    step = np.array([0.1, 0.1, 0.0, 0.1]) ** 2
    kept = Restart(np.full(4, 0.02**2), step).kept()
    out = kept.apply(prior)
    np.testing.assert_array_equal(out[[MEAN_A, MEAN_B]], prior[[MEAN_A, MEAN_B]])
    np.testing.assert_allclose(out[VAR_A], prior[VAR_A] + step)
    np.testing.assert_allclose(out[VAR_A] + 2 * out[COV_AB] + out[VAR_B],
                               prior[VAR_A] + 2 * prior[COV_AB] + prior[VAR_B], atol=1e-15)
    cov = np.array([[out[VAR_A], out[COV_AB]], [out[COV_AB], out[VAR_B]]]).transpose(2, 0, 1)
    assert np.all(np.linalg.eigvalsh(cov) >= -1e-15)
    # The same reading after either belief: the same prediction of a + b.
    bank = JointKalmanBank(KalmanBankParams(np.full(4, 1e-3), np.full(4, 1.0),
                                            np.array([0.02, 0.02, 0.0, 0.02]),
                                            np.ones(4), np.array([1, 1, 0, 1], bool)))
    reading = prior[MEAN_A] + prior[MEAN_B] + 0.01
    a, b = bank.update(prior, reading), bank.update(out, reading)
    np.testing.assert_allclose(a[MEAN_A] + a[MEAN_B], b[MEAN_A] + b[MEAN_B], atol=1e-12)
    shift = rng.normal(size=4) * 0.05
    shifted = prior.copy()
    shifted[MEAN_A] += shift
    np.testing.assert_allclose(kept.apply(shifted)[MEAN_A] - shift, out[MEAN_A], atol=1e-15)


def test_restart_forgets_the_bias_and_commutes_with_an_angle_shift():
    rng = np.random.default_rng(0)
    prior = np.abs(rng.normal(size=(5, 4))) * 0.1
    prior[MEAN_B] = [0.3, -0.2, 0.0, 0.1]
    restart = Restart(np.full(4, 0.02**2), np.array([0.1, 0.1, 0.0, 0.1]) ** 2,
                      reading_var=np.full(4, 1e-3**2))
    out = restart.apply(prior)
    np.testing.assert_array_equal(out[MEAN_A], prior[MEAN_A] + prior[MEAN_B])
    np.testing.assert_array_equal(out[MEAN_B], 0.0)
    # The angle within the start's A of the reading, the bias forgotten (a flat prior)
    # and so given the reading: the limit B -> inf of the independent N(0, A) and
    # N(0, B) conditioned on a + b (the Gaussian conditional: the covariance
    # [[A, 0], [0, B]] less k k^T / S, k = [A, B], S = A + B + R). A joint without
    # bias (B = 0) keeps it at 0: the same conditional at B = 0.
    A, B, R = restart.angle_var, restart.bias_var, restart.reading_var
    for big in (1e3, 1e5):  # the limit, approached
        Bb = np.where(B > 0, big, 0.0)
        S = A + Bb + R
        np.testing.assert_allclose(out[VAR_A], A - A * A / S, rtol=10 * A.max() / big)
        np.testing.assert_allclose(out[COV_AB], -A * Bb / S, rtol=10 * A.max() / big)
        np.testing.assert_allclose(out[VAR_B], Bb - Bb * Bb / S, rtol=1e-6,
                                   atol=10 * A.max() ** 2 / big)
    # What the readings measure, a + b, has the reading's variance.
    np.testing.assert_allclose(out[VAR_A] + 2 * out[COV_AB] + out[VAR_B],
                               np.where(B > 0, R, A * R / (A + R)), rtol=1e-9)
    # An observation stored at an anchor, of the angles there plus a shift, gives the
    # same posterior as the observation applied at the image time.
    shift = rng.normal(size=4) * 0.05
    observation = AngleObservation(np.full(4, 50.0), rng.normal(size=4), restart)
    at_image = prior.copy()
    at_image[MEAN_A] += shift
    via_anchor = observation.shifted(shift).apply(prior)
    direct = observation.apply(at_image)
    np.testing.assert_allclose(via_anchor[MEAN_A] + shift, direct[MEAN_A], atol=1e-12)
    np.testing.assert_allclose(via_anchor[1:], direct[1:], atol=1e-12)


def test_an_image_applied_after_a_restart_survives_the_next_reading():
    """The restart's belief holds the reading it restarts from, so an image's answer
    after it moves the bias as well as the angle, and the next reading (the angle's
    random walk is wide: it follows its encoder) keeps the image's angle. Reference:
    the same joint filtered from the start through the bank, the image's angle being
    what the start's prior and the readings make of it."""
    from drake_tracker.core.filter.kalman import JointKalmanBank, KalmanBankParams

    sq, A, B = 2e-4, 0.035**2, 0.1**2
    bank = JointKalmanBank(KalmanBankParams(np.full(2, sq), np.full(2, 10.0),
                                            np.full(2, 0.02), np.full(2, 0.98),
                                            np.ones(2, bool)))
    restart = Restart(np.full(2, A), np.full(2, B), reading_var=np.full(2, sq**2))
    # A tracked belief at zero bias error, and the truth: the bias is really 0.07 rad.
    reading, true_bias = np.array([0.5, -0.3]), 0.07
    prior = np.zeros((5, 2))
    prior[MEAN_A], prior[VAR_A], prior[VAR_B] = reading - 0.02, 1e-4, 1e-4
    prior[MEAN_B], prior[COV_AB] = 0.02, -1e-4
    z = reading - true_bias  # what the image shows, 0.3 deg precise
    image = AngleObservation(np.full(2, 1 / 0.005**2), z / 0.005**2, restart)
    after = image.apply(prior)
    np.testing.assert_allclose(after[MEAN_B], true_bias, atol=2e-3)
    later = bank.step(after, 0.004, reading)
    np.testing.assert_allclose(later[MEAN_A], z, atol=2e-3)
    # The same restart without the reading's condition (independent angle and bias)
    # loses the image at the next reading: the angle goes back to the zero-bias arm.
    loose = prior.copy()
    loose[MEAN_A], loose[MEAN_B] = reading, 0.0
    loose[VAR_A], loose[COV_AB], loose[VAR_B] = A, 0.0, B
    lost = bank.step(AngleObservation(image.precision, image.information).apply(loose),
                     0.004, reading)
    assert np.all(np.abs(lost[MEAN_A] - reading) < 0.1 * true_bias)


def test_health_counts_misplaced_time_and_a_restart_resets_it():
    params = HealthParams(max_unconfirmed_s=1.0)
    unseen = ImageConsistency(0.0, 0, 0.0, 0.0)
    health = TrackerHealth()
    for t in (0.0, 0.5, 0.9):
        health = next_health(health, replace(unseen, time_s=t), params, misplaced=True)
    assert health.misplaced_since_s == 0.0
    assert not restart_due(health, 0.99, params) and restart_due(health, 1.0, params)
    restarted = next_health(health, replace(unseen, time_s=1.0), params, restarted=True)
    assert restarted.restarts == 1 and restarted.misplaced_since_s == np.inf
    assert not restarted.acquired
    # One image that is not misplaced ends the count.
    assert next_health(health, unseen, params).misplaced_since_s == np.inf


def test_an_estimate_that_renders_under_half_the_encoders_arm_is_misplaced():
    """Unless the image shows the estimate's arm more than the encoders' (``confirms_more``):
    a rendered size is not evidence."""
    params = HealthParams()  # min_robot_pixels 30
    seen = [ImageConsistency(0.0, n, 1.0, 0.0) for n in (0, 29, 343, 390, 391, 600)]
    encoders = ImageConsistency(0.0, 782, 0.9, 0.05)  # 704 pixels agree
    # A vote: 391 of 782 (half) is a tie, not misplaced.
    assert [is_misplaced(e, encoders, params) for e in seen] == [True] * 4 + [False] * 2
    few = ImageConsistency(0.0, 40, 0.9, 0.05)  # the encoders' arm barely in view
    assert [is_misplaced(e, few, params) for e in seen] == [True, True] + [False] * 4
    none = ImageConsistency(0.0, 29, 0.9, 0.05)  # out of view: nothing to compare with
    assert not any(is_misplaced(e, none, params) for e in seen)
    # The encoders' arm seen through: only an estimate the image shows less of (fewer
    # than min_robot_pixels agreeing) is misplaced.
    refuted = ImageConsistency(0.0, 782, 0.0, 1.0)
    assert [is_misplaced(e, refuted, params) for e in seen] == [True, True] + [False] * 4


def test_a_belief_never_confirmed_and_hidden_where_the_encoders_arm_shows_is_misplaced():
    """A belief no image has confirmed since the start or a restart counts its unhidden
    pixels: the start-up search put the arm behind the real one (560 pixels rendered, all
    hidden). An arm once confirmed and then hidden is an occlusion, and keeps its rendered
    count; an encoders' arm hidden as well says nothing."""
    params = HealthParams()  # min_robot_pixels 30
    behind = ImageConsistency(0.0, 560, 0.0, 0.0, occluded=1.0)
    encoders = ImageConsistency(0.0, 1046, 0.03, 0.42, occluded=0.53)  # 492 unhidden
    assert is_misplaced(behind, encoders, params, health=TrackerHealth())
    assert not is_misplaced(behind, encoders, params)  # no health: rendered pixels
    confirmed = TrackerHealth(confirmed_s=0.5)  # once confirmed, hidden: an occlusion
    assert not is_misplaced(behind, encoders, params, health=confirmed)
    hidden_too = replace(encoders, occluded=0.98)  # 21 unhidden: both behind something
    assert not is_misplaced(behind, hidden_too, params, health=TrackerHealth())
    # Half of the encoders' rendered arm, unhidden, is enough; and an image that shows
    # the belief's arm more than the encoders' keeps it.
    half = replace(behind, robot_pixels=1046, occluded=0.5)
    assert not is_misplaced(half, encoders, params, health=TrackerHealth())
    shown = ImageConsistency(0.0, 560, 0.09, 0.0, occluded=0.9)  # 50 of 56 unhidden agree
    assert not is_misplaced(shown, encoders, params, health=TrackerHealth())


def test_an_image_confirms_one_arm_more_only_with_enough_agreeing_pixels():
    """``confirms_more``: at least ``min_robot_pixels`` agreeing pixels, and more than
    the other arm's; two arms the image shows nothing of (an estimate out of view, an
    encoders' arm seen through) confirm neither, so the restart for a misplaced estimate
    still brings it back into view."""
    params = HealthParams()  # min_robot_pixels 30
    seen_through = ImageConsistency(0.0, 2212, 0.0, 1.0)
    out_of_view = ImageConsistency(0.0, 0, 0.0, 0.0)
    assert confirms_more(ImageConsistency(0.0, 840, 0.87, 0.05), seen_through, params)
    assert not confirms_more(out_of_view, seen_through, params)
    assert not confirms_more(seen_through, out_of_view, params)
    assert not confirms_more(ImageConsistency(0.0, 29, 1.0, 0.0), out_of_view, params)
    assert confirms_more(ImageConsistency(0.0, 30, 1.0, 0.0), out_of_view, params)
    half = ImageConsistency(0.0, 800, 0.5, 0.1)  # 400 agreeing
    assert not confirms_more(ImageConsistency(0.0, 400, 1.0, 0.0), half, params)
    assert confirms_more(ImageConsistency(0.0, 401, 1.0, 0.0), half, params)


def apollo_in_view(noise_seed: int) -> tuple:
    """Apollo at its default view configuration, and its depth image (2 mm of noise, the
    background at 2.5 m) as frame 7 captured at 5 s."""
    model = build_tracker_model(robot_preset("apollo"))
    truth = default_view_configuration(model)
    rendered = make_renderer(model, CAMERA).render(truth[None])[0].astype(float)
    noise = np.random.default_rng(noise_seed).normal(0, 0.002, rendered.shape)
    image = (np.where(np.isfinite(rendered), rendered, 2.5) + noise).astype(np.float32)
    return model, truth, DepthFrame(5.0, 5.05, image, 7)


@pytest.fixture(scope="module")
def scene():
    """Apollo in view and its depth image."""
    return apollo_in_view(noise_seed=5)


def out_of_view_prior(model, truth, encoder_bias_rad: np.ndarray) -> np.ndarray:
    """A belief whose arm is out of view (100 deg more on the shoulder, explained as bias)
    while the encoders read ``truth + encoder_bias_rad`` (robot joints)."""
    robot = [model.joint_names.index(n) for n in model.robot_joint_names]
    reading = truth[robot] + encoder_bias_rad
    _, prior = new_bank_and_belief(resolve_tracker_params(TrackerParams(), model), reading)
    prior[MEAN_A] = full_reading(model, reading)
    shoulder = model.joint_names.index("arm_joint_1")
    prior[MEAN_A, shoulder] += SHOULDER_BIAS_RAD
    prior[MEAN_B, shoulder] -= SHOULDER_BIAS_RAD
    prior[VAR_A] = np.radians(1.0) ** 2
    return prior


def hand_error_mm(model, truth, q) -> float:
    X_CE = PoseReadout(model).poses(np.array([truth, q]))[0]
    return float(pose_errors(X_CE[1:], X_CE[:1])[0][0])


def test_an_image_that_agrees_with_the_encoders_and_not_the_estimate_restarts_it(scene):
    model, truth, frame = scene
    prior = out_of_view_prior(model, truth, np.zeros(len(model.robot_joint_names)))
    assert hand_error_mm(model, truth, prior[MEAN_A]) > 300.0
    processor = ImageProcessor(model, CAMERA, resolve_tracker_params(TrackerParams(), model))
    outcome = processor.observe(frame, prior, 0.1, TrackerHealth(acquired=True))
    assert outcome.restarted and outcome.observation.restart is processor.restart
    post = outcome.observation.apply(prior)
    assert hand_error_mm(model, truth, post[MEAN_A]) < 10.0
    # The bias was forgotten, then explained by the image: what the readings measure,
    # a + b, is held, so the next reading keeps the image's angles.
    np.testing.assert_allclose(post[MEAN_A] + post[MEAN_B], prior[MEAN_A] + prior[MEAN_B],
                               atol=1e-5)  # within a tenth of an encoder's sigma
    health = next_health(TrackerHealth(acquired=True), outcome.consistency,
                         TrackerParams().health, outcome.restarted, outcome.misplaced)
    assert health.restarts == 1 and not health.acquired


def test_an_estimate_out_of_view_restarts_once_it_has_been_misplaced_long_enough(scene,
                                                                                no_challenger):
    """The encoders are -6 deg off on arm joints 2 and 4 (the image sees through 42 % of
    their arm): the out-of-view estimate stays until ``max_unconfirmed_s``. (Its
    100 deg shoulder bias is implausible: at the defaults the challenger belief restarts
    it at the first image, ``tests/robustness/test_challenger.py``; off here, to see this rule.)"""
    model, truth, frame = scene
    bias = np.zeros(len(model.robot_joint_names))
    bias[[model.robot_joint_names.index(n) for n in ("arm_joint_2", "arm_joint_4")]] = \
        np.radians(-6.0)
    prior = out_of_view_prior(model, truth, bias)
    params = TrackerParams()
    processor = ImageProcessor(model, CAMERA, resolve_tracker_params(params, model))
    encoders = processor.restart.apply(prior)[MEAN_A]
    before = hand_error_mm(model, truth, encoders)
    assert before > 30.0
    # Not due yet: the image cannot move the estimate, and says it is misplaced.
    fresh = processor.observe(frame, prior, 0.1, TrackerHealth(acquired=True))
    assert fresh.misplaced and not fresh.restarted
    assert fresh.consistency.robot_pixels < TrackerParams().health.min_robot_pixels
    stuck = hand_error_mm(model, truth, fresh.observation.apply(prior)[MEAN_A])
    assert stuck > 300.0
    # Misplaced since 1 s before this image: the update starts from the encoders (one
    # image from there is not an acquisition: here it ends 51 mm off, from 42).
    due = TrackerHealth(acquired=True, misplaced_since_s=frame.capture_time_s - 1.0)
    outcome = processor.observe(frame, prior, 0.1, due)
    assert outcome.restarted and not outcome.misplaced
    assert not processor.consistent(outcome.consistency)  # the encoders' arm disagreed
    post = outcome.observation.apply(prior)
    assert hand_error_mm(model, truth, post[MEAN_A]) < 1.5 * before < 0.25 * stuck
    np.testing.assert_allclose(post[MEAN_A] + post[MEAN_B], prior[MEAN_A] + prior[MEAN_B],
                               atol=1e-5)  # within a tenth of an encoder's sigma


def test_an_estimate_the_image_confirms_does_not_restart_to_an_encoders_arm_it_refutes(
        scene, no_challenger):
    """A bias that drifted far (the shoulder 30 deg, the upper arm -40) swings the
    encoders' arm towards the camera: it renders more than twice the estimate's pixels,
    so by its size the estimate would count as misplaced, while the image sees behind
    all of the encoders' arm and confirms the estimate's: it is not misplaced, and does
    not restart when a second of misplaced images is up. (Measured on a 30 s random walk
    of 3 deg/sqrt(s), the restart threw 29 deg of bias away each second from 17.9 s, the
    hand 100-750 mm off for most of 12 s, the estimate 2-57 mm before.)"""
    model, truth, frame = scene
    robot = [model.joint_names.index(n) for n in model.robot_joint_names]
    bias = np.zeros(len(robot))
    for name, deg in (("arm_joint_1", 30.0), ("arm_joint_2", -40.0)):
        bias[model.robot_joint_names.index(name)] = np.radians(deg)
    reading = truth[robot] + bias
    _, prior = new_bank_and_belief(resolve_tracker_params(TrackerParams(), model), reading)
    prior[MEAN_A] = truth
    prior[MEAN_B] = full_reading(model, reading) - truth  # a + b = the reading
    prior[VAR_A] = np.radians(1.0) ** 2
    processor = ImageProcessor(model, CAMERA, resolve_tracker_params(TrackerParams(), model))
    due = TrackerHealth(acquired=True, misplaced_since_s=frame.capture_time_s - 1.0)
    outcome = processor.observe(frame, prior, 0.1, due)
    encoders = processor.restart.apply(prior)[MEAN_A]
    assert hand_error_mm(model, truth, encoders) > 300.0
    # The encoders' arm against the same image, as the processor compares it.
    observed = observed_image(processor.update.prepare(frame.depth_m))
    seen = image_consistency(outcome.consistency.time_s,
                             processor.update.renderer.render(encoders[None])[0], observed,
                             processor.params.image.likelihood)
    assert seen.see_through > 0.95  # the image sees behind the encoders' arm
    assert outcome.consistency.robot_pixels < 0.5 * seen.robot_pixels  # by size, misplaced
    assert not outcome.misplaced and not outcome.restarted
    assert hand_error_mm(model, truth, outcome.observation.apply(prior)[MEAN_A]) < 15.0
    assert processor.restart_reason(outcome.consistency, seen, due) == ""


def test_an_image_that_scores_every_particle_the_same_leaves_the_belief(scene):
    """The arm out of view for every particle (the shoulder 180 deg round, 0.2 deg of
    spread) and an image of the background only: each particle scores 0, so the belief
    stays as it was, not moved by the particles' Monte-Carlo noise."""
    model, truth, frame = scene
    prior = out_of_view_prior(model, truth, np.zeros(len(model.robot_joint_names)))
    prior[MEAN_A, model.joint_names.index("arm_joint_1")] += np.radians(80.0)
    prior[VAR_A] = np.radians(0.2) ** 2
    background = replace(frame, depth_m=np.full_like(frame.depth_m, 2.5))
    outcome = ImageProcessor(model, CAMERA, resolve_tracker_params(TrackerParams(), model)).observe(
        background, prior, 0.1, TrackerHealth(acquired=True))
    assert outcome.consistency.robot_pixels == 0 and not outcome.restarted
    assert outcome.result.flat_likelihood
    assert not np.any(outcome.observation.precision)
    assert not np.any(outcome.observation.information)
    np.testing.assert_allclose(outcome.observation.apply(prior), prior, rtol=1e-12, atol=0)




def test_a_restart_keeps_the_joints_it_leaves_untouched():
    """With several cameras a camera's restart leaves the other cameras' joints as the
    prior has them (means, variances and covariances), in each kind of restart."""

    rng = np.random.default_rng(3)
    prior = rng.normal(size=(5, 6))
    prior[2:5:2] = np.abs(prior[2:5:2]) + 0.1
    untouched = np.array([4, 5])
    base = Restart(np.full(6, 0.01), np.full(6, 0.02), untouched=untouched)
    for restart in (base, base.kept(), base.pinned(np.full(6, 0.3))):
        after = restart.apply(prior)
        np.testing.assert_array_equal(after[:, untouched], prior[:, untouched])
        plain = Restart(restart.angle_var, restart.bias_var, restart.pinned_angle,
                        restart.keep_bias).apply(prior)
        np.testing.assert_array_equal(after[:, :4], plain[:, :4])
