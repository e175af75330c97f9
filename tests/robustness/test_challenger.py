"""The challenger belief: a search from the encoders' arm kept over images while the
estimate's biases are implausible (``core/robustness/second_opinion.py``).

Measured on the protocol's occlusion/time-varying seed 0: the estimate held joints 3-4
at biases of 30-55 deg (the bias model's spread is 10.3 deg), 100-570 mm off, and no
image contradicted it enough for the one-image second opinion.
"""

import dataclasses
import logging
import time

import numpy as np
import pytest
from test_restart import CAMERA, hand_error_mm
from test_second_opinion import prior_at, scene  # noqa: F401  (the fixture)

from drake_tracker.core.filter.kalman import MEAN_A, MEAN_B, VAR_A
from drake_tracker.core.filter.start import full_reading
from drake_tracker.core.image_processor import ImageProcessor
from drake_tracker.core.robustness.health import (
    Challenger,
    TrackerHealth,
    next_health,
)
from drake_tracker.core.robustness.second_opinion import (
    IMPLAUSIBLE_BIAS_SIGMAS,
    challenger_prior,
    implausible_biases,
    plausible_bias_std,
)
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.params.tracker_params import TrackerParams

#: A bend far beyond the bias model (29 deg is the default's trigger).
BEND_DEG = {"arm_joint_4": 40.0}


def test_the_plausible_spread_is_the_bias_models():
    # Defaults: sigma_b 0.02 rad/sqrt(s), c 0.98/s, initial 0.1 rad, jumps of 0.15 rad.
    stationary = 0.02 ** 2 / (-2.0 * np.log(0.98))  # 0.0099 rad^2: below the initial 0.01
    expected = np.sqrt(max(stationary, 0.1 ** 2) + 0.15 ** 2)
    got = plausible_bias_std(np.array([0.02, 0.05, 0.02]), np.array([0.98, 0.98, 1.0]),
                             np.array([0.1, 0.1, 0.1]), np.array([0.15, 0.15, 0.15]),
                             np.array([0.1, 0.1, 0.0]))
    np.testing.assert_allclose(got[0], expected, rtol=1e-12)
    assert np.degrees(got[0]) == pytest.approx(10.3, abs=0.05)
    # A larger random walk widens it; a pure random walk (c = 1) without jumps keeps the
    # initial spread.
    np.testing.assert_allclose(got[1], np.sqrt(0.05 ** 2 / (-2 * np.log(0.98)) + 0.15 ** 2))
    np.testing.assert_allclose(got[2], 0.1)


def test_implausible_biases_lie_beyond_the_threshold():
    prior = np.zeros((5, 3))
    prior[MEAN_B] = [0.40, -0.42, 5.0]
    spread = np.array([0.18, 0.18, np.inf])  # inf: a joint without a bias
    np.testing.assert_array_equal(implausible_biases(prior, spread, 2.25),
                                  [False, True, False])
    assert not implausible_biases(prior, spread, 0.0).any()  # 0: never


def test_the_challengers_prior_is_the_restart_shifted_by_its_offset():
    candidate = np.zeros((5, 2))
    candidate[MEAN_A], candidate[VAR_A] = [1.0, 2.0], [0.01, 0.01]
    assert challenger_prior(candidate, None, 3.0, np.ones(2)) is candidate
    held = Challenger(np.array([0.1, -0.2]), np.array([1e-4, 0.0099]), time_s=2.0, images=3)
    prior = challenger_prior(candidate, held, 2.5, np.array([4e-4, 4e-4]))
    np.testing.assert_allclose(prior[MEAN_A], [1.1, 1.8])
    # Grown by the bias random walk over 0.5 s, never above the restart's variance.
    np.testing.assert_allclose(prior[VAR_A], [1e-4 + 2e-4, 0.01])
    np.testing.assert_array_equal(candidate[MEAN_A], [1.0, 2.0])  # not modified


def test_an_implausible_bias_fails_the_innovation_tests_false_alarm_probability():
    """The threshold is the two-sided normal quantile of the innovation test's
    false-alarm probability: a bias at it has that tail probability (erfc)."""
    import math

    from drake_tracker.core.robustness.innovation import FALSE_ALARM_PROBABILITY

    tail = math.erfc(IMPLAUSIBLE_BIAS_SIGMAS / math.sqrt(2.0))
    assert tail == pytest.approx(FALSE_ALARM_PROBABILITY, rel=1e-9)


def run_images(processor, frame, prior, count, elapsed_s=0.1, period_s=0.0):
    """Feeds the same image ``count`` times against the same prior, the health carried
    from image to image, image k stamped ``k * period_s`` after ``frame``; returns the
    outcomes."""
    health, outcomes = TrackerHealth(acquired=True), []
    for k in range(count):
        image = dataclasses.replace(frame, capture_time_s=frame.capture_time_s + k * period_s)
        outcome = processor.observe(image, prior, elapsed_s, health)
        outcomes.append(outcome)
        health = next_health(health, outcome.consistency, processor.params.health,
                             outcome.restarted, outcome.misplaced, outcome.challenger)
        if outcome.restarted:
            break
    return outcomes


def test_a_challenger_replaces_an_implausible_belief_the_update_cannot_leave(
        scene, caplog, request, no_second_opinion):  # noqa: F811
    """A confident belief (0.05 deg) with the elbow bent 40 deg, and no bias jump admitted
    (images 0 s apart): the update cannot leave it, as the protocol's fold could not. The
    one-image second opinion is off; the challenger, started because the elbow's bias
    is implausible, finds the arm and restarts the belief there."""
    model, truth, reading, frame = scene
    q = truth.copy()
    for name, deg in BEND_DEG.items():
        q[model.joint_names.index(name)] += np.radians(deg)
    prior = prior_at(model, reading, q)
    prior[VAR_A] = np.radians(0.05) ** 2
    params = TrackerParams()
    processor = ImageProcessor(model, CAMERA, resolve_tracker_params(params, model))
    assert implausible_biases(prior, processor.search.plausible_std,
                              IMPLAUSIBLE_BIAS_SIGMAS).any()
    encoders = hand_error_mm(model, truth, full_reading(model, reading))
    start = hand_error_mm(model, truth, prior[MEAN_A])
    with caplog.at_level(logging.WARNING):
        outcomes = run_images(processor, frame, prior, 20, 0.0)
    assert outcomes[-1].restarted and "a challenger searched from the encoders' arm" \
        in caplog.text
    assert outcomes[-1].challenger is None  # it won: none is left
    after = hand_error_mm(model, truth, outcomes[-1].observation.apply(prior)[MEAN_A])
    request.getfixturevalue("no_challenger")
    alone = run_images(ImageProcessor(model, CAMERA, resolve_tracker_params(params, model)), frame,
    prior, len(outcomes),
                       0.0)
    assert not any(o.restarted for o in alone) and all(o.challenger is None for o in alone)
    stuck = hand_error_mm(model, truth, alone[-1].observation.apply(prior)[MEAN_A])
    print(f"bend {start:.0f} mm, encoders {encoders:.1f}, update alone {stuck:.0f}; the "
          f"challenger won at image {len(outcomes)}: {after:.1f} mm")
    assert after < 0.5 * encoders and after < 0.1 * stuck


def test_a_plausible_estimate_starts_no_challenger(scene):  # noqa: F811
    model, truth, reading, frame = scene
    prior = prior_at(model, reading, truth)  # biases of 3 deg
    outcome = ImageProcessor(model, CAMERA, resolve_tracker_params(TrackerParams(), model)).observe(
        frame, prior, 0.1, TrackerHealth(acquired=True))
    assert outcome.challenger is None and not outcome.restarted


def test_a_challenger_rests_as_long_as_it_searched(scene, no_second_opinion):  # noqa: F811
    """A robot whose bias really is that large: the challenger never wins (margin out of
    reach), searches for ``max_unconfirmed_s`` (two images 0.1 s apart), rests as long,
    then starts afresh."""
    model, truth, reading, frame = scene
    prior = prior_at(model, reading, truth)
    prior[MEAN_B][model.joint_names.index("arm_joint_3")] = np.radians(40.0)
    params = TrackerParams()
    params.health.second_opinion_margin_nats_per_pixel = 1e2
    params.health.max_unconfirmed_s = 0.2
    params.image.acquisition_num_particles = 10
    outcomes = run_images(ImageProcessor(model, CAMERA, resolve_tracker_params(params, model)),
                          frame, prior, 6, period_s=0.1)
    images = [o.challenger.images for o in outcomes]
    assert images == [1, 2, 3, 4, 1, 2]
    searched = [o.challenger.offset_mean for o in outcomes]
    assert not np.array_equal(searched[0], searched[1])  # searching: it moves
    np.testing.assert_array_equal(searched[1], searched[2])  # resting: it stays
    np.testing.assert_array_equal(searched[2], searched[3])


def test_an_estimate_out_of_view_is_challenged_at_the_first_image(apollo_out_of_view):
    """The restart's own scene (``tests/robustness/test_restart.py``): 100 deg of shoulder bias put
    the estimate's arm out of view; the misplaced-restart rule waits a second, the
    challenger does not (the bias is implausible), and brings the hand back near the
    encoders' at once (one image from there is not an acquisition, as in the restart's
    test)."""
    model, truth, frame, prior = apollo_out_of_view
    processor = ImageProcessor(model, CAMERA, resolve_tracker_params(TrackerParams(), model))
    outcome = processor.observe(frame, prior, 0.1, TrackerHealth(acquired=True))
    assert outcome.restarted and outcome.challenger is None
    encoders = hand_error_mm(model, truth, processor.restart.apply(prior)[MEAN_A])
    after = hand_error_mm(model, truth, outcome.observation.apply(prior)[MEAN_A])
    start = hand_error_mm(model, truth, prior[MEAN_A])
    print(f"out of view {start:.0f} mm, encoders {encoders:.1f}, after the challenger's "
          f"first image {after:.1f}")
    assert after < 2.0 * encoders < 0.5 * start


@pytest.fixture(scope="module")
def apollo_out_of_view():
    from test_restart import apollo_in_view, out_of_view_prior

    model, truth, frame = apollo_in_view(noise_seed=5)  # test_restart.scene
    bias = np.zeros(len(model.robot_joint_names))
    bias[[model.robot_joint_names.index(n) for n in ("arm_joint_2", "arm_joint_4")]] = \
        np.radians(-6.0)
    return model, truth, frame, out_of_view_prior(model, truth, bias)


def test_the_decision_times_hold_the_searches_beside_the_update(
        scene, no_second_opinion):  # noqa: F811
    """``ImageProcessor.times`` splits each image's time: the tracked belief's update
    (the CPF's own clock, ``StageTimes.per_update``, holds its first call of the image)
    counts as the update, the challenger's search (the image's other CPF calls) as the
    decision, and together they are the image's time (intervals nested in one clock)."""
    model, truth, reading, frame = scene
    prior = prior_at(model, reading, truth)
    prior[MEAN_B][model.joint_names.index("arm_joint_3")] = np.radians(40.0)
    params = TrackerParams()
    params.health.second_opinion_margin_nats_per_pixel = 1e2  # it never wins
    processor = ImageProcessor(model, CAMERA, resolve_tracker_params(params, model))
    times, challenger = processor.times, None
    for image in range(1, 3):
        before = (times.update_s, times.decision_s, len(processor.update.times.per_update))
        start = time.perf_counter()
        outcome = processor.observe(frame, prior, 0.0,
                                    TrackerHealth(acquired=True, challenger=challenger))
        wall = time.perf_counter() - start
        challenger = outcome.challenger
        main, *searches = list(processor.update.times.per_update)[before[2]:]
        update, decision = times.update_s - before[0], times.decision_s - before[1]
        assert times.images == image and len(searches) >= 1
        assert main <= update and sum(searches) <= decision
        assert update + decision <= wall
    assert 0 < times.decision_share == times.decision_s / times.update_s
