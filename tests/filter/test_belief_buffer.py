"""Delayed images plus replay give exactly the in-time-order result (linear-Gaussian stand-in)."""

import logging

import numpy as np
import pytest

from drake_tracker.core.filter.belief_buffer import BeliefBuffer, StaleReadingError
from drake_tracker.core.filter.kalman import (
    MEAN_A,
    MEAN_B,
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
    """Reference without any buffer: one pass over readings and images in time order, each
    image applied at the reading nearest to its stamp, to the angles moved by the readings'
    linear interpolation to the image time (the buffer's anchor rule)."""
    bank = _bank()
    m = initial_moments(np.zeros(N), np.ones(N), np.full(N, 0.2), bank.params.has_bias)
    events = [(t, 0, 0.0, q) for t, q in zip(times, readings)]
    for t, y, r in images:
        k = int(np.searchsorted(times, t, side="right"))
        t0, t1 = times[k - 1], times[k]
        q_image = readings[k - 1] + (t - t0) / (t1 - t0) * (readings[k] - readings[k - 1])
        anchor = k - 1 if t - t0 <= t1 - t else k
        events.append((times[anchor], 1, t, (y, r, q_image - readings[anchor])))
    t_prev = 0.0
    for t, kind, _, data in sorted(events, key=lambda e: (e[0], e[1], e[2])):
        if kind == 0:
            m = bank.step(m, t - t_prev, data)
            t_prev = t
        else:
            y, r, shift = data
            prior = m.copy()
            prior[MEAN_A] += shift
            mean, var = _linear_image_update(y, r)(prior)
            m = recombine_with_bias(m, mean - shift, var)
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


def _bias_after_images(phase: float, num_images: int = 30) -> float:
    """Issue 10's case: 1 kHz readings of a joint at angle 0 with a 0.15 rad bias, and
    ideal images (angle 0, std 0.005 rad) at 10 Hz, ``phase`` encoder periods off the grid,
    each arriving 20 ms late; default tracker parameters."""
    from drake_tracker.params.resolve import joint_noise_for, resolve_kalman_params
    from drake_tracker.params.tracker_params import TrackerParams

    params = TrackerParams()
    bank = JointKalmanBank(resolve_kalman_params(params, ["j"]))
    noise = joint_noise_for(params, ["j"])[0]
    bias, r = 0.15, 0.005**2
    prior = initial_moments(np.array([bias]), np.array([noise.initial_angle_std_rad]),
                            np.array([noise.initial_bias_std_rad]), np.array([True]))
    buf = BeliefBuffer(bank, prior, 0.0, horizon_s=1.0)
    k = 0
    for image in range(num_images):
        t_image = 0.1 * (image + 1) + phase * 1e-3
        while (k + 1) * 1e-3 <= t_image + 0.02:
            k += 1
            buf.add_reading(k * 1e-3, np.array([bias]))
        assert buf.add_image(t_image, _linear_image_update(np.zeros(1), np.full(1, r)))
    return float(buf.present()[1][MEAN_B][0])


def test_an_image_carries_the_same_bias_information_at_any_phase_between_readings():
    on_grid = _bias_after_images(0.0)
    assert on_grid == pytest.approx(0.15, rel=0.02)
    for phase in (0.1, 0.5, 0.9):
        assert _bias_after_images(phase) == pytest.approx(on_grid, rel=0.02), phase


def test_image_anchor_interpolates_the_readings_and_falls_back_across_a_gap():
    bank = _bank()
    buf = BeliefBuffer(bank, initial_moments(np.zeros(N), np.ones(N), np.ones(N),
                                             bank.params.has_bias), 0.0, horizon_s=1.0,
                       max_interpolation_gap_s=0.05)
    buf.add_reading(0.010, np.full(N, 1.0))
    buf.add_reading(0.012, np.full(N, 2.0))
    anchor = buf.image_anchor(0.0115)  # nearer the second reading
    assert anchor.anchor_time_s == 0.012
    np.testing.assert_allclose(anchor.angle_shift, -0.25)
    np.testing.assert_allclose(anchor.prior[MEAN_A], buf.belief_at(0.012)[MEAN_A] - 0.25)
    buf.add_reading(0.200, np.full(N, 3.0))  # an encoder gap of 188 ms
    gap = buf.image_anchor(0.1)
    assert gap.anchor_time_s == 0.1 and not np.any(gap.angle_shift)
    assert np.all(gap.prior[VAR_A] > buf.belief_at(0.012)[VAR_A])


def test_a_copied_buffer_goes_on_alone_and_steps_as_the_bank_does():
    """``copy()`` (the delay buffer system's copy per reading) shares the stored events:
    each copy goes on on its own; a reading is the bank's checked step."""
    bank = _bank()
    start = initial_moments(np.zeros(N), np.full(N, 0.1), np.full(N, 0.05),
                            np.array([True, True, True, False]))
    buf = BeliefBuffer(bank, start, 0.0, horizon_s=0.05)
    expected, rng = start, np.random.default_rng(2)
    for k in range(1, 30):
        reading = rng.normal(0.0, 0.1, N)
        copy, before = buf.copy(), (len(buf), buf.now_s)
        belief = copy.add_reading(0.01 * k, reading)
        np.testing.assert_array_equal(belief, bank.step(expected, 0.01 * k - 0.01 * (k - 1),
                                                        reading))
        assert (len(buf), buf.now_s) == before and copy.now_s == 0.01 * k
        buf, expected = copy, belief


def _state(buf):
    """What a buffer holds, as plain values: its present, its anchor and every stored
    belief at its event times."""
    times = [e.time_s for e in buf._log.events[buf._start:buf._end]]
    return (buf.now_s, buf.oldest_time_s, buf.present()[1].tolist(), times,
            [buf.belief_at(t).tolist() for t in times])


@pytest.mark.parametrize("seed", [0, 1])
def test_copies_that_share_their_log_go_on_as_buffers_fed_alone(seed):
    """Copies share one log (appends in place, copy on any other change, compaction of
    the pruned events): whatever the order in which copies are made, fed readings and
    images, each holds exactly what a buffer fed its own events alone holds (the copies
    take their readings as the delay buffer system gives them, ``checked``; the buffers
    alone check theirs)."""
    rng = np.random.default_rng(seed)
    bank = _bank()
    start = initial_moments(np.zeros(N), np.full(N, 0.1), np.full(N, 0.05),
                            np.array([True, True, True, False]))
    times = np.cumsum(rng.uniform(0.0008, 0.0012, 3000))  # 3 s: compacts at 1024 events
    readings = rng.normal(0.3, 0.05, (3000, N))
    # Three lineages from one buffer, each with its own images; the fed-alone reference
    # of each replays its history from scratch.
    lineages = [BeliefBuffer(bank, start, 0.0, horizon_s=0.5)]
    histories = [[]]
    for k, (t, q) in enumerate(zip(times, readings)):
        if k in (700, 1500):  # a new lineage branches off from a random one
            j = int(rng.integers(len(lineages)))
            lineages.append(lineages[j].copy())
            histories.append(list(histories[j]))
        for j, buf in enumerate(lineages):
            copy = buf.copy()  # as the delay buffer system does at every reading
            if rng.random() < 0.02 and k > 50:  # an image, somewhere in the last 0.05 s
                t_image = t - rng.uniform(0.0, 0.05)
                y = rng.normal(0.25, 0.02, N)
                copy.add_image(t_image, _linear_image_update(y, 1e-4))
                histories[j].append(("image", t_image, y))
            copy.add_reading(t, q.copy(), checked=True)  # as the system gives it
            histories[j].append(("reading", t, q))
            lineages[j] = copy
        if k % 250 == 249 or k == 2999:
            for buf, history in zip(lineages, histories):
                alone = BeliefBuffer(bank, start, 0.0, horizon_s=0.5)
                for kind, t_event, value in history:
                    if kind == "reading":
                        alone.add_reading(t_event, value)
                    else:
                        alone.add_image(t_event, _linear_image_update(value, 1e-4))
                assert _state(buf) == _state(alone)
    assert len(lineages) == 3 and all(buf._start < 1024 for buf in lineages)
