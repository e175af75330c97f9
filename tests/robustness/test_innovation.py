"""The chi-square test of the joint filter's innovations (core/robustness/innovation.py)
and the health it reports."""

import numpy as np
import pytest

from drake_tracker.core.filter.angle_observation import AngleObservation, Restart
from drake_tracker.core.filter.kalman import MEAN_A, VAR_A
from drake_tracker.core.robustness.health import (
    HealthParams,
    HealthState,
    ImageConsistency,
    TrackerHealth,
    drifts,
    next_health,
)
from drake_tracker.core.robustness.innovation import (
    FALSE_ALARM_PROBABILITY,
    NO_INNOVATION,
    WINDOW_IMAGES,
    chi2_quantile,
    image_inconsistent,
    image_innovation,
    innovations_consistent,
    with_innovation,
)

# Chi-square quantiles from the standard tables (dof, probability, value).
CHI2_TABLE = [(3, 0.995, 12.838), (5, 0.99, 15.086), (10, 0.995, 25.188),
              (21, 0.995, 41.401), (35, 0.995, 60.275), (30, 0.999, 59.703)]


@pytest.mark.parametrize("dof, probability, value", CHI2_TABLE)
def test_the_quantile_matches_the_tables(dof, probability, value):
    assert chi2_quantile(dof, probability) == pytest.approx(value, rel=0.01)


def test_the_quantile_rejects_bad_arguments():
    with pytest.raises(ValueError, match="dof"):
        chi2_quantile(0, 0.9)
    with pytest.raises(ValueError, match="probability"):
        chi2_quantile(3, 1.0)


def _prior(mean, var):
    prior = np.zeros((5, len(mean)))
    prior[MEAN_A], prior[VAR_A] = mean, var
    return prior


def test_one_images_innovation_by_hand():
    prior = _prior([0.1, -0.2, 0.3, 0.0], [4e-4, 1e-4, 1e-4, 1e-4])
    R = np.array([1e-4, 1e-4, 1e-3, 1e-5])  # joint 2 says less than its prior
    z = np.array([0.12, -0.19, 0.5, 0.01])
    observation = AngleObservation(1.0 / R, z / R)
    robot = np.array([True, True, True, False])  # joint 3: a virtual joint
    nis, dof = image_innovation(prior, observation, robot)
    expected = (0.02 ** 2) / (4e-4 + 1e-4) + (0.01 ** 2) / (1e-4 + 1e-4)
    assert dof == 2
    assert nis == pytest.approx(expected, rel=1e-12)
    restarted = AngleObservation(1.0 / R, z / R, Restart(np.ones(4), np.ones(4)))
    assert image_innovation(prior, restarted, robot) == NO_INNOVATION


def test_a_consistent_filter_is_called_inconsistent_at_the_stated_rate():
    """Truth drawn from the prior, the image's angles from the truth with the stated R:
    the model holds, and the pooled test must fire on about FALSE_ALARM_PROBABILITY of
    the windows (binomial bounds, 40,000 independent windows of 7 joints)."""
    rng = np.random.default_rng(7)
    n, windows = 7, 40_000
    robot = np.ones(n, bool)
    alarms = 0
    for _ in range(windows):
        window = ()
        for _ in range(WINDOW_IMAGES):
            s = rng.uniform(1e-5, 1e-3, n)
            R = s * rng.uniform(0.05, 1.0, n)
            mu = rng.normal(0.0, 0.5, n)
            a = mu + np.sqrt(s) * rng.standard_normal(n)
            z = a + np.sqrt(R) * rng.standard_normal(n)
            window = with_innovation(window, image_innovation(
                _prior(mu, s), AngleObservation(1.0 / R, z / R), robot))
        alarms += not innovations_consistent(window)
    expected = FALSE_ALARM_PROBABILITY * windows
    assert abs(alarms - expected) < 4 * np.sqrt(expected)


def test_a_bias_drifting_faster_than_its_model_is_caught():
    """Innovations two of their standard deviations off on every joint (a drift the
    prior does not hold): the window fails the test."""
    n = 7
    s, R = np.full(n, 1e-4), np.full(n, 5e-5)
    z = 2.0 * np.sqrt(s + R)
    window = ()
    for _ in range(WINDOW_IMAGES):
        window = with_innovation(window, image_innovation(
            _prior(np.zeros(n), s), AngleObservation(1.0 / R, z / R), np.ones(n, bool)))
    assert not innovations_consistent(window)
    assert len(window) == WINDOW_IMAGES
    assert not innovations_consistent(())  # nothing vouches for the filter
    assert not innovations_consistent((NO_INNOVATION,) * WINDOW_IMAGES)


def test_the_health_reports_an_inconsistent_filter_as_uncertain_without_forgetting_it():
    params = HealthParams()
    agree = [ImageConsistency(0.1 * k, 500, 0.98, 0.0) for k in range(20)]
    good, bad = (7.0, 7), (400.0, 7)
    h = TrackerHealth()
    for k in range(3):
        h = next_health(h, agree[k], params, innovation=good)
    assert h.state == HealthState.TRACKING
    h = next_health(h, agree[3], params, innovation=bad)
    assert h.state == HealthState.UNCERTAIN  # reported
    assert h.confirmed_s == agree[3].time_s and h.acquired  # the arm still counts as held
    states = []
    for k in range(4, 4 + WINDOW_IMAGES):
        h = next_health(h, agree[k], params, innovation=good)
        states.append(h.state)
    # Tracking again once the bad image has left the window (or the pooled sum allows it).
    assert states[-1] == HealthState.TRACKING
    assert HealthState.UNCERTAIN in states[:-1]
    # Without innovations (an image that was not applied) the state is the pixels' alone
    # (the image before confirmed the estimate too: one of two in a row).
    assert next_health(TrackerHealth(HealthState.TRACKING, agree[0], 0, 3,
                                     confirming_in_a_row=1), agree[1],
                       params).state == HealthState.TRACKING


def test_one_images_test_fires_at_the_stated_rate_and_on_a_drift():
    """One image's innovation alone (what asks the kept search): a consistent filter's
    NIS, a chi-square of k, fails on about FALSE_ALARM_PROBABILITY of the images
    (binomial bounds over 200,000 images of 1-7 joints; Wilson-Hilferty's quantile is
    least exact at 1-2 degrees of freedom); a chi-square quantile from the tables sits
    on the edge."""
    rng = np.random.default_rng(11)
    images = 200_000
    dof = rng.integers(1, 8, images)
    nis = np.array([np.sum(rng.standard_normal(k) ** 2) for k in dof])
    alarms = sum(image_inconsistent((float(x), int(k))) for x, k in zip(nis, dof))
    expected = FALSE_ALARM_PROBABILITY * images
    assert abs(alarms - expected) < 4 * np.sqrt(expected)
    assert image_inconsistent((12.838 * 1.02, 3)) and not image_inconsistent((12.838 * 0.98, 3))
    assert not image_inconsistent(NO_INNOVATION)
    assert not image_inconsistent((1e6, 0))


@pytest.mark.parametrize("last, agreement, visible, expected", [
    ((40.0, 3), 0.80, 900, True),   # an inconsistent image before, this one disagrees
    ((2.0, 3), 0.80, 900, False),   # the image before was consistent
    ((40.0, 3), 0.97, 900, False),  # this image confirms its unhidden arm
    ((40.0, 3), 0.50, 20, False),   # too little unhidden arm to say anything
    (NO_INNOVATION, 0.50, 900, False),  # a restart has no innovation
])
def test_the_kept_search_is_asked_after_an_inconsistent_image(last, agreement, visible,
                                                               expected):
    """``drifts``: the latest applied image's own innovation failed, and this image does
    not confirm ``tracking_agreement`` (0.95) of the arm it shows unhidden."""
    params = HealthParams()
    health = TrackerHealth(acquired=True, innovations=((1.0, 3), last))
    # Half of 2 * visible robot pixels hidden: agreement counts over all of them.
    image = ImageConsistency(1.0, 2 * visible, agreement / 2, 0.0, occluded=0.5)
    assert image.visible_robot_pixels == pytest.approx(visible)
    assert drifts(image, health, params) is expected
    assert not drifts(image, TrackerHealth(acquired=True), params)  # nothing applied yet
