"""The delay buffer with late observations, on a linear-Gaussian system: applying an image
at its capture time when it arrives late, then filtering the later readings again, gives
the posterior of processing everything in time order, and is consistent (NEES).

Each of the 2000 joints of one buffer is an independent seeded run of the bank's own
model (angle random walk, decaying bias random walk, noisy readings at 100 Hz) with a
direct Gaussian observation of the angle (the CPF's stand-in) captured every 0.1 s on a
reading's stamp and delivered 50-90 ms later, some out of order.
"""

import numpy as np

from drake_tracker.core.filter.belief_buffer import BeliefBuffer
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

N, DT, STEPS = 2000, 0.01, 150
SIGMA_Q, SIGMA_A, SIGMA_B, DECAY = 0.01, 0.5, 0.05, 0.9
ANGLE_STD0, BIAS_STD0 = 0.2, 0.1
OBSERVATION_STD = 0.02
#: (capture step, arrival step): every 10th reading is observed; the delays are 5-9
#: readings, so the image of step 40 arrives after that of step 50 (out of order).
IMAGES = [(10 * j, 10 * j + d) for j, d in zip(range(1, 14), [5, 7, 9, 17, 6, 8, 5, 9, 7,
                                                               6, 8, 5, 9])]


def _bank() -> JointKalmanBank:
    return JointKalmanBank(KalmanBankParams(
        np.full(N, SIGMA_Q), np.full(N, SIGMA_A), np.full(N, SIGMA_B), np.full(N, DECAY),
        np.ones(N, bool)))


def _prior() -> np.ndarray:
    return initial_moments(np.zeros(N), np.full(N, ANGLE_STD0), np.full(N, BIAS_STD0),
                           np.ones(N, bool))


def _simulate(seed: int):
    """True angles and biases at each step, the readings, and the observations."""
    rng = np.random.default_rng(seed)
    a = rng.normal(0.0, ANGLE_STD0, N)
    b = rng.normal(0.0, BIAS_STD0, N)
    angles, biases, readings = [], [], []
    for k in range(STEPS):
        if k > 0:
            a = a + rng.normal(0.0, SIGMA_A * np.sqrt(DT), N)
            b = DECAY ** DT * b + rng.normal(0.0, SIGMA_B * np.sqrt(DT), N)
        angles.append(a)
        biases.append(b)
        readings.append(a + b + rng.normal(0.0, SIGMA_Q, N))
    observed = {k: angles[k] + rng.normal(0.0, OBSERVATION_STD, N) for k, _ in IMAGES}
    return np.array(angles), np.array(biases), np.array(readings), observed


def _observe(y: np.ndarray):
    """The exact posterior marginals of the angle after y = a + N(0, r)."""
    r = OBSERVATION_STD ** 2

    def update(prior):
        s = 1.0 / (1.0 / prior[VAR_A] + 1.0 / r)
        return s * (prior[MEAN_A] / prior[VAR_A] + y / r), s

    return update


def _nees(belief: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ea, eb = a - belief[MEAN_A], b - belief[MEAN_B]
    saa, sab, sbb = belief[VAR_A], belief[COV_AB], belief[VAR_B]
    return (sbb * ea * ea - 2.0 * sab * ea * eb + saa * eb * eb) / (saa * sbb - sab * sab)


def _run_buffer(readings, observed, at_arrival: bool = False):
    """The buffer fed in arrival order; the present belief after each reading. With
    ``at_arrival`` the observations are wrongly stamped with their arrival time."""
    buffer = BeliefBuffer(_bank(), _prior(), 0.0, horizon_s=0.5)
    arriving = {}
    for capture, arrival in IMAGES:
        arriving.setdefault(arrival, []).append(capture)
    beliefs = []
    for k in range(STEPS):
        buffer.add_reading(k * DT, readings[k])
        for capture in arriving.get(k, []):
            stamp = (k if at_arrival else capture) * DT
            assert buffer.add_image(stamp, _observe(observed[capture]))
        beliefs.append(buffer.present()[1])
    return beliefs


def _in_time_order(readings, observed) -> np.ndarray:
    """No buffer: each reading, then that step's observation if any, in time order."""
    bank = _bank()
    belief = _prior()
    for k in range(STEPS):
        belief = bank.step(belief, DT if k else 0.0, readings[k])
        if k in observed:
            mean, var = _observe(observed[k])(belief)
            belief = recombine_with_bias(belief, mean, var)
    return belief


def test_late_observations_give_the_in_time_order_posterior():
    _, _, readings, observed = _simulate(3)
    final = _run_buffer(readings, observed)[-1]
    np.testing.assert_allclose(final, _in_time_order(readings, observed), rtol=1e-9,
                               atol=1e-12)


def test_late_observations_keep_the_nees_within_the_chi2_bounds():
    """The (angle, bias) NEES of the present belief after every reading, over 2000
    joints, is chi-square(2): 95 % under its 95 % quantile (5.991), mean 2 (binomial std
    of the fraction 0.005, of the mean 0.045). The same observations applied at their
    arrival time instead (the delay ignored) are far outside."""
    angles, biases, readings, observed = _simulate(21)
    steps = range(10, STEPS)
    for at_arrival in (False, True):
        beliefs = _run_buffer(readings, observed, at_arrival)
        nees = np.array([_nees(beliefs[k], angles[k], biases[k]) for k in steps])
        inside, mean = np.mean(nees <= 5.991), np.mean(nees)
        if at_arrival:
            assert inside < 0.85 and mean > 3.0, (inside, mean)
        else:
            assert 0.94 <= inside <= 0.96, inside
            assert np.min(np.mean(nees <= 5.991, axis=1)) >= 0.92
            assert 1.9 <= mean <= 2.1, mean
