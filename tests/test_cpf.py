"""The Coordinate Particle Filter against a brute-force grid posterior."""

import numpy as np

from drake_tracker.core.cpf import coordinate_particle_filter, kl_from_uniform
from drake_tracker.core.likelihood import LikelihoodParams, log_likelihoods, prepare_observation

PARAMS = LikelihoodParams(
    depth_noise_std_m=0.05, depth_noise_factor_per_m=0.0, occlusion_probability=0.2
)
NUM_PIXELS = 12


def _render(q):
    """A 2-joint 'scene': 12 pixels whose depths depend non-linearly on both joints."""
    q = np.atleast_2d(q)
    p = np.arange(NUM_PIXELS)
    d = 1.5 + 0.25 * np.sin(q[:, :1] + 0.3 * p) + 0.6 * q[:, 1:2] * np.cos(0.5 * p)
    d[:, 10:] = np.where(q[:, :1] > 0.2, d[:, 10:], np.inf)  # pixels that appear and vanish
    return d[:, None, :]


def _setup():
    truth = np.array([0.25, -0.1])
    rng = np.random.default_rng(11)
    z = _render(truth)[0] + rng.normal(0, 0.05, (1, NUM_PIXELS))
    z[0, 3] = 1.0  # an occluder in front of the robot
    obs = prepare_observation(z, PARAMS)
    return (
        (lambda q: log_likelihoods(_render(q), obs, PARAMS)),
        np.array([0.15, 0.0]),
        np.array([0.12, 0.2]),
    )


def _grid_posterior(loglik, mu, sd):
    g0 = np.linspace(mu[0] - 6 * sd[0], mu[0] + 6 * sd[0], 301)
    g1 = np.linspace(mu[1] - 6 * sd[1], mu[1] + 6 * sd[1], 301)
    Q = np.stack(np.meshgrid(g0, g1, indexing="ij"), -1).reshape(-1, 2)
    logp = loglik(Q) - 0.5 * np.sum(((Q - mu) / sd) ** 2, axis=1)
    w = np.exp(logp - logp.max())
    w /= w.sum()
    mean = w @ Q
    return mean, w @ (Q - mean) ** 2


def test_cpf_matches_brute_force_posterior_within_monte_carlo_error():
    loglik, mu, sd = _setup()
    mean_ref, var_ref = _grid_posterior(loglik, mu, sd)
    assert np.all(np.abs(mean_ref - mu) > 0.02)  # the image is informative
    means, variances = [], []
    for seed in range(12):
        r = coordinate_particle_filter(
            mu,
            sd,
            [np.array([0]), np.array([1])],
            3000,
            loglik,
            np.random.default_rng(seed),
            max_kl=2.0,
        )
        means.append(r.mean)
        variances.append(r.variance)
    means, variances = np.array(means), np.array(variances)
    se_mean = means.std(axis=0, ddof=1) / np.sqrt(len(means))
    se_var = variances.std(axis=0, ddof=1) / np.sqrt(len(variances))
    # Across seeds, the estimates scatter around the grid posterior (4 standard errors) ...
    assert np.all(np.abs(means.mean(axis=0) - mean_ref) < 4 * se_mean + 1e-4), (
        means.mean(0),
        mean_ref,
    )
    assert np.all(np.abs(variances.mean(axis=0) - var_ref) < 4 * se_var + 0.05 * var_ref)
    # ... and each single run is close to it.
    assert np.all(np.abs(means - mean_ref) < 4 * np.sqrt(var_ref / 100))


def test_coordinates_outside_blocks_keep_their_prior():
    loglik, mu, sd = _setup()
    r = coordinate_particle_filter(mu, sd, [np.array([0])], 500, loglik, np.random.default_rng(0))
    assert r.mean[1] == mu[1] and r.variance[1] == sd[1] ** 2


def test_kl_from_uniform():
    assert abs(kl_from_uniform(np.zeros(10))) < 1e-12
    lw = np.full(10, -np.inf)
    lw[3] = 0.0
    assert np.isclose(kl_from_uniform(lw), np.log(10))
