"""Delayed images plus replay give exactly the in-time-order result (linear-Gaussian stand-in)."""

import logging

import numpy as np
import pytest

from drake_tracker.core.belief_buffer import BeliefBuffer, StaleReadingError
from drake_tracker.core.kalman import (
    MEAN_A,
    VAR_A,
    JointKalmanBank,
    KalmanBankParams,
    initial_moments,
    recombine_with_bias,
)

N = 4


def _bank():
    return JointKalmanBank(
        KalmanBankParams(
            encoder_noise_std=np.full(N, 2e-3),
            angle_process_std=np.full(N, 3.0),
            bias_process_std=np.full(N, 5e-3),
            bias_decay_per_s=np.full(N, 0.8),
            has_bias=np.array([True, True, True, False]),
        )
    )


def _linear_image_update(y, r):
    """Stand-in for the CPF: exact posterior marginals for the observation y = a + N(0, r)."""

    def update(prior):
        s = 1.0 / (1.0 / prior[VAR_A] + 1.0 / r)
        return s * (prior[MEAN_A] / prior[VAR_A] + y / r), s

    return update


def _data(seed):
    rng = np.random.default_rng(seed)
    times = np.cumsum(rng.uniform(0.0008, 0.0012, 400))
    readings = rng.normal(0.3, 0.05, (400, N))
    images = [(t, rng.normal(0.25, 0.02, N), np.full(N, 1e-4)) for t in (0.05, 0.12, 0.2, 0.31)]
    return times, readings, images


def _in_time_order(times, readings, images):
    """Reference without any buffer: one pass over readings and images sorted by stamp."""
    bank = _bank()
    m = initial_moments(np.zeros(N), np.ones(N), np.full(N, 0.2), bank.params.has_bias)
    events = [(t, 0, q) for t, q in zip(times, readings)] + [(t, 1, (y, r)) for t, y, r in images]
    t_prev = 0.0
    for t, kind, data in sorted(events, key=lambda e: (e[0], e[1])):
        if kind == 0:
            m = bank.step(m, t - t_prev, data)
        else:
            m = bank.predict(m, t - t_prev)
            mean, var = _linear_image_update(*data)(m)
            m = recombine_with_bias(m, mean, var)
        t_prev = t
    return t_prev, m


@pytest.mark.parametrize("delay_s, reverse", [(0.03, False), (0.08, False), (0.08, True)])
def test_delayed_images_with_replay_equal_in_order_processing(delay_s, reverse):
    times, readings, images = _data(5)
    t_ref, m_ref = _in_time_order(times, readings, images)
    bank = _bank()
    buf = BeliefBuffer(
        bank,
        initial_moments(np.zeros(N), np.ones(N), np.full(N, 0.2), bank.params.has_bias),
        0.0,
        horizon_s=0.5,
    )
    arrivals = sorted(images, key=lambda im: im[0], reverse=reverse)
    pending = [(t + delay_s + (0.1 if reverse else 0.0), t, y, r) for t, y, r in arrivals]
    for t, q in zip(times, readings):
        buf.add_reading(t, q)
        for item in [p for p in pending if p[0] <= t]:
            assert buf.add_image(item[1], _linear_image_update(item[2], item[3]))
            pending.remove(item)
    for _, t_img, y, r in pending:
        assert buf.add_image(t_img, _linear_image_update(y, r))
    t_now, m_now = buf.present()
    assert t_now == t_ref
    np.testing.assert_allclose(m_now, m_ref, rtol=1e-9, atol=1e-12)


def test_old_and_future_images_are_rejected_with_a_warning(caplog):
    times, readings, _ = _data(6)
    bank = _bank()
    buf = BeliefBuffer(
        bank,
        initial_moments(np.zeros(N), np.ones(N), np.ones(N), bank.params.has_bias),
        0.0,
        horizon_s=0.1,
    )
    for t, q in zip(times, readings):
        buf.add_reading(t, q)
    before = buf.present()[1].copy()
    update = _linear_image_update(np.zeros(N), np.full(N, 1e-4))
    with caplog.at_level(logging.WARNING):
        assert not buf.add_image(times[-1] - 0.2, update)
        assert not buf.add_image(times[-1] + 0.01, update)
    assert "older than" in caplog.text and "future" in caplog.text
    np.testing.assert_array_equal(buf.present()[1], before)
    # Within the horizon it is accepted, and no reading was lost: only older ones were folded.
    assert buf.add_image(times[-1] - 0.05, update)
    assert buf.oldest_time_s <= times[-1] - 0.1 + 0.0015


def test_stale_and_bad_readings_raise():
    bank = _bank()
    buf = BeliefBuffer(
        bank,
        initial_moments(np.zeros(N), np.ones(N), np.ones(N), bank.params.has_bias),
        0.0,
        horizon_s=0.1,
    )
    buf.add_reading(0.01, np.zeros(N))
    with pytest.raises(StaleReadingError):
        buf.add_reading(0.01, np.zeros(N))
    with pytest.raises(ValueError, match="shape"):
        buf.add_reading(0.02, np.zeros(N + 1))
    with pytest.raises(ValueError, match="horizon"):
        BeliefBuffer(bank, np.zeros((5, N)), 0.0, horizon_s=0.0)
