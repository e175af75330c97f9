"""The bias noise matched to the images' innovations (core/filter/bias_noise.py): the
rate it settles at against the true rate of a simulated random-walk bias, its bounds,
and the images it must not learn from."""

import numpy as np
import pytest

from drake_tracker.core.filter.angle_observation import AngleObservation, Restart
from drake_tracker.core.filter.belief_buffer import BeliefBuffer
from drake_tracker.core.filter.bias_noise import (
    INNOVATION_CLIP_VARIANCES,
    MATCHING_IMAGES,
    BiasNoiseMatch,
)
from drake_tracker.core.filter.kalman import (
    MEAN_A,
    VAR_A,
    JointKalmanBank,
    KalmanBankParams,
    initial_moments,
)

MIN_VAR = 0.02 ** 2  # the default σb², rad²/s
MAX_VAR = 0.1 ** 2


def _track(true_rate_var: float, seed: int, duration_s: float = 60.0,
           reading_hz: float = 250.0, image_interval_s: float = 0.1,
           image_std: float = 0.002, match: bool = True
           ) -> tuple[BeliefBuffer, float, float]:
    """One joint whose encoder reads angle + bias (a random walk of ``true_rate_var``)
    and whose angle an image observes every ``image_interval_s`` with ``image_std``;
    returns the buffer, the bias error at the end and the mean matched rate from the
    run's second third on."""
    rng = np.random.default_rng(seed)
    bank = JointKalmanBank(KalmanBankParams(
        encoder_noise_std=np.array([1e-4]), angle_process_std=np.array([10.0]),
        bias_process_std=np.array([np.sqrt(MIN_VAR)]), bias_decay_per_s=np.array([1.0]),
        has_bias=np.array([True])))
    start = BiasNoiseMatch.start(np.array([MIN_VAR]), np.array([MAX_VAR]), np.array([True]))
    buffer = BeliefBuffer(bank, initial_moments(np.zeros(1), np.array([0.03]),
                                                np.array([0.1]), np.array([True])),
                          0.0, horizon_s=1.0, bias_noise=start if match else None)
    dt = 1.0 / reading_hz
    bias, next_image, rates = 0.0, image_interval_s, []
    for k in range(1, int(duration_s * reading_hz) + 1):
        t = k * dt
        bias += np.sqrt(true_rate_var * dt) * rng.standard_normal()
        angle = 0.5 * np.sin(0.7 * t)
        buffer.add_reading(t, np.array([angle + bias + 1e-4 * rng.standard_normal()]))
        if t >= next_image - 1e-12:
            next_image += image_interval_s
            z = angle + image_std * rng.standard_normal()
            anchor = buffer.image_anchor(t)
            buffer.add_image_observation(anchor, AngleObservation(
                np.array([image_std ** -2]), np.array([z * image_std ** -2])))
            if t > duration_s / 3 and match:
                rates.append(buffer.bias_noise.rate_var[0])
    _, belief = buffer.present()
    return buffer, float(belief[1, 0] - bias), float(np.mean(rates)) if rates else np.nan


@pytest.mark.parametrize("true_sigma", [0.04, 0.07])
def test_the_rate_settles_at_the_true_random_walk_rate(true_sigma):
    """Between the bounds, the matched σb² is the true rate: its mean over the last 40 s
    is within 10 % of it (median over 5 seeds), every seed's within 20 %; and
    the bank runs with it."""
    rates = []
    for seed in range(5):
        buffer, _, mean_rate = _track(true_sigma ** 2, seed)
        assert buffer.bank.bias_process_var[0] == pytest.approx(buffer.bias_noise.rate_var[0])
        rates.append(mean_rate)
    ratio = np.array(rates) / true_sigma ** 2
    assert 0.9 < np.median(ratio) < 1.1, ratio
    assert (ratio > 0.8).all() and (ratio < 1.2).all(), ratio


def test_a_bias_slower_than_the_model_keeps_the_configured_rate():
    """The model never trusts the bias more than it was told to: a true rate below σb²
    leaves the rate at σb² (its lower bound) or within 30 % of it."""
    for seed in range(3):
        buffer, _, mean_rate = _track(0.005 ** 2, seed, duration_s=20.0)
        assert MIN_VAR <= buffer.bias_noise.rate_var[0] < 1.3 * MIN_VAR
        assert mean_rate < 1.3 * MIN_VAR


def test_a_fast_bias_is_followed_better_with_the_match():
    """A 4 deg/sqrt(s) walk: the bias error at the end, RMS over 5 seeds, is smaller with
    the matched rate than with the configured one."""
    with_match, without = [], []
    for seed in range(5):
        with_match.append(_track(0.07 ** 2, seed, duration_s=20.0)[1])
        without.append(_track(0.07 ** 2, seed, duration_s=20.0, match=False)[1])
    assert np.sqrt(np.mean(np.square(with_match))) < 0.8 * np.sqrt(np.mean(np.square(without)))


def _prior(mean: float, var: float) -> np.ndarray:
    prior = np.zeros((5, 1))
    prior[MEAN_A], prior[VAR_A] = mean, var
    return prior


def _observation(z: float, var: float, restart: Restart | None = None) -> AngleObservation:
    return AngleObservation(np.array([1.0 / var]), np.array([z / var]), restart)


def test_one_wrong_image_moves_the_rate_by_at_most_its_clip():
    match = BiasNoiseMatch.start(np.array([MIN_VAR]), np.array([1.0]), np.array([True]))
    match = match.after_image(0.0, _prior(0.0, 1e-4), _observation(0.0, 1e-4))
    after = match.after_image(0.1, _prior(0.0, 1e-4), _observation(5.0, 1e-4))  # 350 sigma
    S = 2e-4
    assert after.rate_var[0] == pytest.approx(
        MIN_VAR + (INNOVATION_CLIP_VARIANCES - 1) * S / 0.1 / MATCHING_IMAGES)


def test_images_it_must_not_learn_from():
    """The first image, an image before the previous one, a restart, a joint that does
    not adapt and a joint the image did not observe leave the rates as they were."""
    match = BiasNoiseMatch.start(np.full(2, MIN_VAR), np.full(2, 1.0), np.array([True, False]))
    prior = np.zeros((5, 2))
    prior[VAR_A] = 1e-4
    far = AngleObservation(np.full(2, 1e4), np.full(2, 1e4))  # z = 1 rad: far off
    first = match.after_image(1.0, prior, far)
    assert np.array_equal(first.rate_var, match.rate_var) and first.last_image_s == 1.0
    assert np.array_equal(first.after_image(0.5, prior, far).rate_var, match.rate_var)
    restart = AngleObservation(far.precision, far.information, Restart(np.ones(2), np.ones(2)))
    assert np.array_equal(first.after_image(1.1, prior, restart).rate_var, match.rate_var)
    unseen = AngleObservation(np.zeros(2), np.zeros(2))
    assert np.array_equal(first.after_image(1.1, prior, unseen).rate_var, match.rate_var)
    moved = first.after_image(1.1, prior, far)
    assert moved.rate_var[0] > MIN_VAR and moved.rate_var[1] == MIN_VAR


def test_a_copy_of_the_buffer_keeps_its_own_rate():
    """The buffer copies that the image update's hypotheses use do not share the
    match: an image applied to a copy leaves the original's bank as it was."""
    buffer, _, _ = _track(0.07 ** 2, 0, duration_s=2.0)
    before = buffer.bank.bias_process_var.copy()
    clone = buffer.copy()
    t = clone.now_s + 0.1
    clone.add_reading(t, np.array([0.0]))
    anchor = clone.image_anchor(t)
    clone.add_image_observation(anchor, _observation(float(anchor.prior[MEAN_A, 0]) + 0.2, 1e-6))
    assert clone.bias_noise.rate_var[0] > before[0]
    assert np.array_equal(buffer.bank.bias_process_var, before)


def test_only_an_image_that_confirms_a_tracked_belief_informs_the_rate():
    """``confirms_tracking``: tracked before (``images_in_a_row`` agreeing images in a
    row), and this image agrees (one more, none disagreeing); an observation marked
    otherwise moves no rate. The reported state does not decide: it says ``uncertain``
    when the innovations outgrow the model, the very images the match learns from."""
    from dataclasses import replace

    from drake_tracker.core.image_step import confirms_tracking
    from drake_tracker.core.robustness.health import HealthParams, HealthState, TrackerHealth

    params = HealthParams()  # images_in_a_row 2
    tracked = TrackerHealth(HealthState.TRACKING, agreeing_in_a_row=3)
    agreeing = replace(tracked, agreeing_in_a_row=4)
    assert confirms_tracking(tracked, agreeing, params)
    assert confirms_tracking(tracked, replace(agreeing, state=HealthState.UNCERTAIN), params)
    # reported uncertain (inconsistent innovations), but tracked: it counts
    assert confirms_tracking(replace(tracked, state=HealthState.UNCERTAIN), agreeing, params)
    assert not confirms_tracking(tracked, replace(agreeing, agreeing_in_a_row=0,
                                                  disagreeing_in_a_row=1), params)
    # one agreeing image before this one is not yet tracking
    once = TrackerHealth(HealthState.UNCERTAIN, agreeing_in_a_row=1)
    assert not confirms_tracking(once, replace(once, agreeing_in_a_row=2), params)
    match = BiasNoiseMatch.start(np.array([MIN_VAR]), np.array([1.0]), np.array([True]))
    match = match.after_image(0.0, _prior(0.0, 1e-4), _observation(0.0, 1e-4))
    far = replace(_observation(1.0, 1e-4), informs_bias_noise=False)
    assert match.after_image(0.1, _prior(0.0, 1e-4), far).rate_var[0] == MIN_VAR
    assert replace(far, informs_bias_noise=False).shifted(np.ones(1)).informs_bias_noise is False
