"""The Kalman bank against an independent textbook filter on the stacked 2n-state system."""

import numpy as np
import pytest

from drake_tracker.core.filter.kalman import (
    COV_AB,
    MEAN_A,
    MEAN_B,
    VAR_A,
    VAR_B,
    JointKalmanBank,
    KalmanBankParams,
    initial_moments,
    recombine_with_bias,
)


def _params(n, rng):
    return KalmanBankParams(
        encoder_noise_std=rng.uniform(1e-3, 1e-2, n),
        angle_process_std=rng.uniform(0.1, 2.0, n),
        bias_process_std=rng.uniform(1e-3, 1e-2, n),
        bias_decay_per_s=rng.uniform(0.3, 1.0, n),
        has_bias=np.array([True] * (n - 1) + [False]),
    )


def _textbook(params, x, P, dt, q):
    """Dense Kalman filter on x = [a_1..a_n, b_1..b_n]."""
    n = params.num_joints
    c = params.bias_decay_per_s**dt
    F = np.block([[np.eye(n), np.zeros((n, n))], [np.zeros((n, n)), np.diag(c)]])
    sb = np.where(params.has_bias, params.bias_process_std, 0.0)
    Q = np.diag(np.concatenate([dt * params.angle_process_std**2, dt * sb**2]))
    H = np.hstack([np.eye(n), np.eye(n)])
    R = np.diag(params.encoder_noise_std**2)
    x = F @ x
    P = F @ P @ F.T + Q
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    x = x + K @ (q - H @ x)
    P = (np.eye(2 * n) - K @ H) @ P
    return x, P


def test_bank_matches_textbook_stacked_filter():
    rng = np.random.default_rng(0)
    n = 5
    params = _params(n, rng)
    bank = JointKalmanBank(params)
    m = initial_moments(rng.normal(size=n), np.full(n, 0.5), np.full(n, 0.1), params.has_bias)
    x = np.concatenate([m[MEAN_A], m[MEAN_B]])
    P = np.diag(np.concatenate([m[VAR_A], m[VAR_B]]))
    t = 0.0
    for _ in range(200):
        dt = rng.uniform(0.0005, 0.003)  # irregular time stamps
        t += dt
        q = rng.normal(size=n)
        m = bank.step(m, dt, q)
        x, P = _textbook(params, x, P, dt, q)
    np.testing.assert_allclose(m[MEAN_A], x[:n], atol=1e-9)
    np.testing.assert_allclose(m[MEAN_B], x[n:], atol=1e-9)
    np.testing.assert_allclose(m[VAR_A], np.diag(P)[:n], rtol=1e-7, atol=1e-14)
    np.testing.assert_allclose(m[COV_AB], np.diag(P, n), rtol=1e-7, atol=1e-14)
    np.testing.assert_allclose(m[VAR_B], np.diag(P)[n:], rtol=1e-7, atol=1e-14)
    # The joint without bias never acquires one.
    assert m[MEAN_B, -1] == 0.0 and m[VAR_B, -1] == 0.0


def test_bias_variance_converges_to_eq8_without_readings():
    rng = np.random.default_rng(1)
    params = _params(4, rng)
    bank = JointKalmanBank(params)
    m = initial_moments(np.zeros(4), np.ones(4), np.full(4, 0.3), params.has_bias)
    dt = 0.01
    for _ in range(20000):
        m = bank.predict(m, dt)
    expected = params.stationary_bias_variance(dt)
    np.testing.assert_allclose(m[VAR_B, :3], expected[:3], rtol=1e-6)
    assert m[VAR_B, 3] == 0.0


def test_recombination_equals_kalman_update_with_angle_observation():
    """Eq. (16) with the exact posterior of y = a + N(0, r) is the Kalman update."""
    rng = np.random.default_rng(2)
    n = 3
    m = initial_moments(rng.normal(size=n), np.full(n, 0.2), np.full(n, 0.1), np.ones(n, bool))
    m[COV_AB] = [-0.005, 0.002, -0.009]
    y, r = rng.normal(size=n), np.full(n, 0.01)
    s_post = 1 / (1 / m[VAR_A] + 1 / r)
    mu_post = s_post * (m[MEAN_A] / m[VAR_A] + y / r)
    out = recombine_with_bias(m, mu_post, s_post)
    for j in range(n):
        P = np.array([[m[VAR_A, j], m[COV_AB, j]], [m[COV_AB, j], m[VAR_B, j]]])
        H = np.array([[1.0, 0.0]])
        S = H @ P @ H.T + r[j]
        K = P @ H.T / S
        x = np.array([m[MEAN_A, j], m[MEAN_B, j]]) + (K * (y[j] - m[MEAN_A, j])).ravel()
        P = P - K @ H @ P
        np.testing.assert_allclose([out[MEAN_A, j], out[MEAN_B, j]], x, atol=1e-12)
        np.testing.assert_allclose(
            [out[VAR_A, j], out[COV_AB, j], out[VAR_B, j]], [P[0, 0], P[0, 1], P[1, 1]], atol=1e-12
        )


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("encoder_noise_std", 0.0, "encoder_noise_std of joint j1"),
        ("angle_process_std", -1.0, "angle_process_std of joint j1"),
        ("bias_decay_per_s", 1.5, "must be in \\(0, 1\\]"),
        ("bias_decay_per_s", 0.0, "must be in \\(0, 1\\]"),
    ],
)
def test_bad_parameters_are_named(field, value, message):
    good = dict(
        encoder_noise_std=np.full(2, 1e-3),
        angle_process_std=np.ones(2),
        bias_process_std=np.full(2, 1e-3),
        bias_decay_per_s=np.full(2, 0.9),
        has_bias=np.ones(2, bool),
        names=("j0", "j1"),
    )
    good[field] = np.array([good[field][0], value])
    with pytest.raises(ValueError, match=message):
        KalmanBankParams(**good)


def test_bad_readings_are_rejected():
    params = KalmanBankParams(
        np.full(2, 1e-3),
        np.ones(2),
        np.full(2, 1e-3),
        np.full(2, 0.9),
        np.ones(2, bool),
        names=("j0", "j1"),
    )
    bank = JointKalmanBank(params)
    m = initial_moments(np.zeros(2), np.ones(2), np.ones(2), np.ones(2, bool))
    with pytest.raises(ValueError, match="shape"):
        bank.step(m, 0.001, np.zeros(3))
    with pytest.raises(ValueError, match="j1"):
        bank.step(m, 0.001, np.array([0.0, np.inf]))
    with pytest.raises(ValueError, match="no value"):
        bank.step(m, 0.001, np.array([np.nan, np.nan]))


def test_a_joint_without_a_value_is_predicted_and_the_others_filtered():
    """NaN for one joint: that joint's moments are the prediction alone (angle variance
    capped at ``missing_angle_var``, its covariance kept within the Cauchy-Schwarz
    bound); every other joint's are exactly what a reading of it alone gives."""
    params = KalmanBankParams(np.full(3, 1e-3), np.full(3, 10.0), np.full(3, 0.02),
                              np.full(3, 0.98), np.ones(3, bool), names=("a", "b", "c"))
    cap = np.full(3, 0.035 ** 2)
    bank = JointKalmanBank(params, missing_angle_var=cap)
    m = initial_moments(np.array([0.1, 0.2, 0.3]), np.full(3, 0.01), np.full(3, 0.1),
                        np.ones(3, bool))
    m = bank.step(m, 0.001, np.array([0.1, 0.2, 0.3]))
    reading = np.array([0.11, np.nan, 0.29])
    out = bank.step(m, 0.01, reading)
    full = bank.step(m, 0.01, np.array([0.11, 0.2, 0.29]))
    np.testing.assert_array_equal(out[:, [0, 2]], full[:, [0, 2]])
    predicted = bank.predict(m, 0.01)
    np.testing.assert_array_equal(out[[MEAN_A, MEAN_B, VAR_B], 1],
                                  predicted[[MEAN_A, MEAN_B, VAR_B], 1])
    assert predicted[VAR_A, 1] > cap[1] and out[VAR_A, 1] == cap[1]
    assert out[COV_AB, 1] ** 2 <= out[VAR_A, 1] * out[VAR_B, 1] + 1e-18
    # Without a cap the angle variance is the prediction's: radians wide in 0.1 s.
    free = JointKalmanBank(params).step(m, 0.1, reading)
    assert np.sqrt(free[VAR_A, 1]) > 1.0


def test_the_bank_is_consistent_nees_within_the_chi2_bounds():
    """2000 independent joints simulated from the filter's own model (angle random walk,
    decaying bias random walk, noisy readings): the normalised estimation error squared
    e' P^-1 e of each joint's (angle, bias) is chi-square with 2 degrees of freedom, so 95 %
    of the joints fall under its 95 % quantile (5.991) at any step, and its mean is 2.
    Checked to fail when the simulated bias noise is doubled (90 % inside), the reading
    noise doubled (73 %) or the bias decay wrong (0.5/s: 97.5 %); with readings this
    precise, a wrong angle noise barely shows (the reading pins a + b)."""
    n, dt, steps = 2000, 0.01, 150
    sigma_q, sigma_a, sigma_b, c = 0.01, 0.5, 0.05, 0.9
    params = KalmanBankParams(np.full(n, sigma_q), np.full(n, sigma_a), np.full(n, sigma_b),
                              np.full(n, c), np.ones(n, bool))
    bank = JointKalmanBank(params)
    rng = np.random.default_rng(11)
    angle_std0, bias_std0 = 0.2, 0.1
    belief = initial_moments(np.zeros(n), np.full(n, angle_std0), np.full(n, bias_std0),
                             np.ones(n, bool))
    a = rng.normal(0.0, angle_std0, n)
    b = rng.normal(0.0, bias_std0, n)
    inside, means = [], []
    for k in range(steps):
        if k > 0:
            a = a + rng.normal(0.0, sigma_a * np.sqrt(dt), n)
            b = c ** dt * b + rng.normal(0.0, sigma_b * np.sqrt(dt), n)
        q = a + b + rng.normal(0.0, sigma_q, n)
        belief = bank.step(belief, dt if k > 0 else 0.0, q)
        ea, eb = a - belief[MEAN_A], b - belief[MEAN_B]
        saa, sab, sbb = belief[VAR_A], belief[COV_AB], belief[VAR_B]
        det = saa * sbb - sab * sab
        nees = (sbb * ea * ea - 2.0 * sab * ea * eb + saa * eb * eb) / det
        inside.append(np.mean(nees <= 5.991))
        means.append(np.mean(nees))
    # Binomial std of the fraction over 2000 joints: 0.005; of the mean NEES: 0.045.
    assert 0.93 <= np.mean(inside[10:]) <= 0.97, np.mean(inside[10:])
    assert min(inside[10:]) >= 0.92
    assert 1.9 <= np.mean(means[10:]) <= 2.1, np.mean(means[10:])


def test_check_reading_answers_as_its_plain_numpy_reference():
    """``check_reading`` takes one Python sum for an all-finite reading; against the plain
    numpy checks (no value at all, an infinite value; NaN allowed), on seeded readings
    with NaN, ±inf, huge values whose sum overflows, and lists."""
    rng = np.random.default_rng(21)
    n = 5
    params = KalmanBankParams(np.full(n, 1e-3), np.ones(n), np.full(n, 1e-3),
                              np.full(n, 0.9), np.ones(n, bool))
    bank = JointKalmanBank(params)

    def reference(reading):
        reading = np.asarray(reading, dtype=float)
        if np.isinf(reading).any():
            return "infinite"
        if np.isnan(reading).all() and reading.size:
            return "no value"
        return reading

    for _ in range(2000):
        reading = rng.normal(0.0, 1.0, n)
        kinds = rng.integers(0, 8, n)
        reading[kinds == 0] = np.nan
        reading[kinds == 1] = np.inf
        reading[kinds == 2] = -np.inf
        reading[kinds == 3] = 1e308
        if rng.random() < 0.1:
            reading[:] = np.nan
        given = reading.tolist() if rng.random() < 0.2 else reading
        expected = reference(given)
        if isinstance(expected, str):
            with pytest.raises(ValueError, match=expected):
                bank.check_reading(given)
        else:
            np.testing.assert_array_equal(bank.check_reading(given), expected)


def test_compiled_step_answers_as_its_plain_numpy_reference():
    """The compiled step (``step_unchecked``, and ``step_in_place`` on the Kalman bank
    system's own copy) against plain numpy: predict, cap the joints without a value,
    update the others; on seeded beliefs and readings with NaN and a zero time step."""
    rng = np.random.default_rng(45)
    n = 6
    params = _params(n, rng)
    cap = rng.uniform(0.01, 0.2, n)
    bank = JointKalmanBank(params, missing_angle_var=cap)
    sa2, sb2 = params.angle_process_std ** 2, bank.bias_process_var
    log_c, sq2 = np.log(params.bias_decay_per_s), params.encoder_noise_std ** 2

    def reference(m, dt, q):
        m = m.copy()
        if dt > 0:
            cd = np.exp(log_c * dt)
            m[MEAN_B] *= cd
            m[VAR_A] += dt * sa2
            m[COV_AB] *= cd
            m[VAR_B] = cd * cd * m[VAR_B] + dt * sb2
        missing = np.isnan(q) & (m[VAR_A] > cap)
        bound = np.sqrt(cap * m[VAR_B])
        m[VAR_A] = np.where(missing, cap, m[VAR_A])
        m[COV_AB] = np.where(missing, np.clip(m[COV_AB], -bound, bound), m[COV_AB])
        saa, sab, sbb = m[VAR_A].copy(), m[COV_AB].copy(), m[VAR_B].copy()
        s = saa + 2.0 * sab + sbb + sq2
        ka, kb = (saa + sab) / s, (sab + sbb) / s
        nu = q - m[MEAN_A] - m[MEAN_B]
        has = ~np.isnan(q)
        m[MEAN_A] = np.where(has, m[MEAN_A] + ka * nu, m[MEAN_A])
        m[MEAN_B] = np.where(has, m[MEAN_B] + kb * nu, m[MEAN_B])
        m[VAR_A] = np.where(has, np.maximum(saa - ka * ka * s, 0.0), m[VAR_A])
        m[COV_AB] = np.where(has, sab - ka * kb * s, m[COV_AB])
        m[VAR_B] = np.where(has, np.maximum(sbb - kb * kb * s, 0.0), m[VAR_B])
        return m

    m = initial_moments(rng.normal(size=n), np.full(n, 0.5), np.full(n, 0.1), params.has_bias)
    for k in range(300):
        dt = 0.0 if k % 50 == 0 else float(rng.uniform(0.0005, 0.05))
        q = rng.normal(size=n)
        q[rng.random(n) < 0.2] = np.nan
        expected = reference(m, dt, q)
        stepped = bank.step_unchecked(m, dt, q)
        np.testing.assert_allclose(stepped, expected, rtol=1e-12, atol=1e-15)
        in_place = m.copy()
        bank.step_in_place(in_place, dt, q)
        np.testing.assert_array_equal(in_place, stepped)
        m = stepped
