"""The Coordinate Particle Filter against a brute-force grid posterior."""

import numpy as np
import pytest

from drake_tracker.core.cpf.particle_filter import (
    annealed_coordinate_particle_filter,
    coordinate_particle_filter,
    kl_from_uniform,
)
from drake_tracker.core.filter.angle_observation import AngleObservation
from drake_tracker.core.filter.kalman import COV_AB, MEAN_A, MEAN_B, VAR_A, VAR_B
from drake_tracker.core.likelihood.pixel_model import (
    LikelihoodParams,
    log_likelihoods,
    prepare_observation,
)
from drake_tracker.params.tracker_params import TrackerParams

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


@pytest.mark.parametrize("betas", [(1.0,), (0.25, 1.0)])
def test_a_likelihood_the_same_for_every_particle_leaves_the_prior_exactly(betas):
    """Prior x constant is the prior: not its sample moments, whose Monte-Carlo noise,
    image after image, would walk the estimate (an arm out of view scores 0 for every
    particle). The rule needs every particle of every block and sweep to agree."""
    mu, sd = np.array([0.15, 0.0, -0.3]), np.array([0.12, 0.2, 0.05])
    blocks = [np.array([0]), np.array([1, 2])]
    flat = annealed_coordinate_particle_filter(
        mu, sd, blocks, 50, lambda q: np.full(len(q), -3.5), np.random.default_rng(4),
        betas=betas, jump_probability=np.array([0.1, 0.0, 0.0]),
        jump_std=np.array([0.3, 0.0, 0.0]))
    assert flat.flat_likelihood
    np.testing.assert_array_equal(flat.mean, mu)
    np.testing.assert_array_equal(flat.variance, sd**2)
    # One particle that differs anywhere, and the update is the ordinary one.
    def almost(q):
        out = np.zeros(len(q))
        out[0] = 1e-9
        return out
    ordinary = annealed_coordinate_particle_filter(
        mu, sd, blocks, 50, almost, np.random.default_rng(4), betas=betas)
    assert not ordinary.flat_likelihood and not np.array_equal(ordinary.mean, mu)
    # A single particle cannot tell: no rule.
    single = coordinate_particle_filter(mu, sd, blocks, 1, lambda q: np.zeros(len(q)),
                                        np.random.default_rng(4))
    assert not single.flat_likelihood


def test_kl_from_uniform():
    assert abs(kl_from_uniform(np.zeros(10))) < 1e-12
    lw = np.full(10, -np.inf)
    lw[3] = 0.0
    assert np.isclose(kl_from_uniform(lw), np.log(10))


DEFAULT_BETAS = tuple(TrackerParams().image.annealing_betas)


def _gaussian_case_2d():
    """A correlated Gaussian likelihood on two coordinates with an independent prior: the
    exact posterior is Gaussian, with precision prior + likelihood."""
    mu, sd = np.array([0.2, -0.1]), np.array([0.3, 0.5])
    y = np.array([0.1, 0.05])
    lam = np.array([[400.0, 300.0], [300.0, 400.0]])

    def loglik(q):
        d = q - y
        return -0.5 * np.einsum("ni,ij,nj->n", d, lam, d)

    precision = np.diag(1 / sd**2) + lam
    cov = np.linalg.inv(precision)
    return loglik, mu, sd, cov @ (mu / sd**2 + lam @ y), np.diag(cov)


def _gaussian_case_1d():
    def loglik(q):
        return -0.5 * (q[:, 0] - 1.0) ** 2 / 0.25

    # prior N(0, 1), likelihood N(1, 0.25): posterior mean 0.8, variance 0.2.
    return loglik, np.zeros(1), np.ones(1), np.array([0.8]), np.array([0.2])


@pytest.mark.parametrize("case", [_gaussian_case_1d, _gaussian_case_2d])
@pytest.mark.parametrize("betas", [DEFAULT_BETAS, (1.0,)])
def test_annealed_and_single_sweeps_match_the_exact_gaussian_posterior(case, betas):
    loglik, mu, sd, mean_ref, var_ref = case()
    blocks = [np.array([i]) for i in range(len(mu))]
    means, variances = [], []
    for seed in range(40):
        r = annealed_coordinate_particle_filter(mu, sd, blocks, 400, loglik,
                                                np.random.default_rng([seed, 7]), 2.0, betas)
        means.append(r.mean)
        variances.append(r.variance)
    means, variances = np.array(means), np.array(variances)
    se_mean = means.std(axis=0, ddof=1) / np.sqrt(len(means))
    se_var = variances.std(axis=0, ddof=1) / np.sqrt(len(variances))
    assert np.all(np.abs(means.mean(0) - mean_ref) < 4 * se_mean + 0.01 * np.sqrt(var_ref)), (
        means.mean(0), mean_ref)
    # A weighted variance from an effective sample of a few hundred is biased low by ~1/ESS.
    assert np.all(np.abs(variances.mean(0) - var_ref) < 4 * se_var + 0.03 * var_ref), (
        variances.mean(0), var_ref)


def test_the_default_schedule_does_not_count_the_image_more_than_once():
    """Regression: sweeps that each weighted likelihood^beta_k on top of the previous
    sweep's result gave the posterior of likelihood^sum(betas) (variance 0.43, not 0.5)."""
    def loglik(q):
        return -0.5 * (q[:, 0] - 1.0) ** 2

    variances = [annealed_coordinate_particle_filter(
        np.zeros(1), np.ones(1), [np.array([0])], 400, loglik, np.random.default_rng(s), 2.0,
        DEFAULT_BETAS).variance[0] for s in range(40)]
    overconfident = 1 / (1 + sum(DEFAULT_BETAS))
    assert abs(np.mean(variances) - 0.5) < abs(np.mean(variances) - overconfident) / 4


def test_cpf_image_update_with_a_correlated_angle_bias_prior_is_the_kalman_update():
    """One joint with a correlated (angle, bias) prior and a Gaussian image likelihood on
    the angle: the CPF's marginals, turned into a pseudo-observation and recombined with
    p(b | a) (eq. 16), give the exact Kalman posterior of (angle, bias)."""
    prior = np.zeros((5, 1))
    prior[MEAN_A], prior[MEAN_B] = 0.3, 0.1
    prior[VAR_A], prior[COV_AB], prior[VAR_B] = 0.04, -0.015, 0.01
    y, r = 0.2, 0.01**2

    def loglik(q):
        return -0.5 * (q[:, 0] - y) ** 2 / r

    H = np.array([[1.0, 0.0]])
    P = np.array([[0.04, -0.015], [-0.015, 0.01]])
    K = P @ H.T / (H @ P @ H.T + r)
    mean_ref = np.array([0.3, 0.1]) + (K * (y - 0.3)).ravel()
    cov_ref = (np.eye(2) - K @ H) @ P
    results = []
    for seed in range(30):
        cpf = annealed_coordinate_particle_filter(
            prior[MEAN_A], np.sqrt(prior[VAR_A]), [np.array([0])], 400, loglik,
            np.random.default_rng(seed), 2.0, DEFAULT_BETAS)
        post = AngleObservation.from_posterior(prior, cpf.mean, cpf.variance).apply(prior)
        results.append([post[MEAN_A, 0], post[MEAN_B, 0], post[VAR_A, 0], post[COV_AB, 0],
                        post[VAR_B, 0]])
    got = np.mean(results, axis=0)
    np.testing.assert_allclose(got[:2], mean_ref, atol=3e-4)
    np.testing.assert_allclose(got[2:], [cov_ref[0, 0], cov_ref[0, 1], cov_ref[1, 1]],
                               rtol=0.05)
