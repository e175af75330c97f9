"""The vectorisable exp and log against numpy's (libm), over the likelihood's domain."""

import numpy as np

from drake_tracker.core.vector_math import exp_inplace, log_inplace


def test_exp_equals_numpy_within_two_ulps():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-700.0, 700.0, 50_000), rng.uniform(-3.0, 3.0, 50_000),
                        [0.0, -700.0, 700.0, 1e-300, -1e-300, np.log(2.0)], [-800.0, 800.0]])
    got = x.copy()
    exp_inplace(got, len(got), np.empty_like(got))
    expected = np.exp(np.clip(x, -700.0, 700.0))  # documented clamp
    np.testing.assert_allclose(got, expected, rtol=4.5e-16, atol=0.0)


def test_log_equals_numpy_within_two_ulps():
    rng = np.random.default_rng(1)
    y = np.concatenate([np.exp(rng.uniform(-700.0, 700.0, 50_000)),
                        rng.uniform(0.5, 2.0, 50_000),
                        [1.0, 2.0, np.sqrt(0.5), np.sqrt(2.0), 1e-300, 1.7e-3]])
    got = y.copy()
    log_inplace(got, len(got), np.empty_like(got))
    expected = np.log(y)
    np.testing.assert_allclose(got, expected, rtol=4.5e-16, atol=2.3e-16)


def test_only_the_first_count_elements_change():
    x = np.array([0.0, 1.0, 2.0])
    exp_inplace(x, 2, np.empty(3))
    assert x[2] == 2.0 and x[0] == 1.0
