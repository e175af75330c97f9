"""The pixel likelihood against a direct scalar evaluation and numerical integration."""

import math

import numpy as np
import pytest

from drake_tracker.core.likelihood.pixel_model import (
    LikelihoodParams,
    log_likelihoods,
    prepare_observation,
)

PARAMS = LikelihoodParams(
    tail_weight=0.02,
    depth_noise_std_m=0.004,
    depth_noise_factor_per_m=0.002,
    max_depth_m=6.0,
    occluder_rate_per_m=math.log(2.0),
    occlusion_probability=0.2,
    occluder_depth="truncated",
)


def _normal_pdf(x, mu, s):
    return math.exp(-0.5 * ((x - mu) / s) ** 2) / (s * math.sqrt(2 * math.pi))


def _p_occ_by_integration(z, d, p):
    """Occluder depth y ~ truncated exponential on [0, d], blurred by N(0, sigma(z)^2)."""
    s = p.depth_noise_std_m + p.depth_noise_factor_per_m * z * z
    lam = p.occluder_rate_per_m
    y = np.linspace(0.0, d, 200001)
    prior = lam * np.exp(-lam * y) / (1 - math.exp(-lam * d))
    integrand = prior * np.exp(-0.5 * ((z - y) / s) ** 2) / (s * math.sqrt(2 * math.pi))
    dens = np.trapezoid(integrand, y)
    return p.tail_weight / p.max_depth_m + (1 - p.tail_weight) * dens


def _p_occ_inf(z, p):
    s = p.depth_noise_std_m + p.depth_noise_factor_per_m * z * z
    lam = p.occluder_rate_per_m
    return p.tail_weight / p.max_depth_m + (1 - p.tail_weight) * lam * math.exp(
        -lam * z + lam**2 * s**2 / 2
    )


def _scalar_log_ratio(z, d, p):
    """Direct transcription of SPEC §2 for one pixel (without the truncation's
    normaliser 1/(1 - e^{-λd}) for the independent occluder depth)."""
    if not (np.isfinite(z) and 0 < z <= p.max_depth_m) or not np.isfinite(d):
        return 0.0
    s = p.depth_noise_std_m + p.depth_noise_factor_per_m * z * z
    lam, w = p.occluder_rate_per_m, p.tail_weight
    p_vis = w / p.max_depth_m + (1 - w) * _normal_pdf(z, d, s)
    phi = 0.5 * (1 + math.erf((d - z + lam * s * s) / s / math.sqrt(2)))
    norm = 1 / (1 - math.exp(-lam * d)) if p.occluder_depth == "truncated" else 1.0
    p_occ = (
        w / p.max_depth_m
        + (1 - w) * lam * norm * math.exp(-lam * z + lam**2 * s**2 / 2) * phi
    )
    p_all = (1 - p.occlusion_probability) * p_vis + p.occlusion_probability * p_occ
    return math.log(p_all) - math.log(_p_occ_inf(z, p))


def test_vectorised_equals_scalar_formula():
    rng = np.random.default_rng(3)
    H, W, N = 6, 8, 5
    z = rng.uniform(0.3, 3.0, (H, W))
    z[0, 0], z[1, 1], z[2, 2], z[3, 3] = np.nan, 0.0, 7.0, -1.0  # invalid pixels
    rendered = z[None] + rng.normal(0, 0.05, (N, H, W))
    rendered[:, :, 0] = np.inf  # nothing rendered
    rendered[0, 4, 4] = z[4, 4] + 1.0  # robot behind the observed surface: occluded
    rendered[1, 4, 4] = z[4, 4] - 0.5  # robot in front: contradiction
    got = log_likelihoods(rendered, prepare_observation(z, PARAMS), PARAMS)
    expected = [
        sum(
            _scalar_log_ratio(z[i, j], rendered[n, i, j], PARAMS)
            for i in range(H)
            for j in range(W)
        )
        for n in range(N)
    ]
    np.testing.assert_allclose(got, expected, rtol=1e-10)


@pytest.mark.parametrize("z, d", [(1.0, 1.5), (0.8, 0.8), (2.0, 1.99), (1.2, 3.0), (0.5, 1.0)])
def test_occlusion_term_by_numerical_integration(z, d):
    s = PARAMS.depth_noise_std_m + PARAMS.depth_noise_factor_per_m * z * z
    lam, w = PARAMS.occluder_rate_per_m, PARAMS.tail_weight
    closed = w / PARAMS.max_depth_m + (1 - w) * lam / (1 - math.exp(-lam * d)) * math.exp(
        -lam * z + lam**2 * s**2 / 2
    ) * 0.5 * (1 + math.erf((d - z + lam * s * s) / s / math.sqrt(2)))
    assert closed == pytest.approx(_p_occ_by_integration(z, d, PARAMS), rel=1e-6)
    # The pixel score in the fully occluded case (o -> 1) is log(p_occ(z|d) / p_occ(z|inf)).
    p = LikelihoodParams(**{**PARAMS.__dict__, "occlusion_probability": 1 - 1e-12})
    score = log_likelihoods(np.full((1, 1, 1), d), prepare_observation(np.full((1, 1), z), p), p)
    assert score[0] == pytest.approx(math.log(closed / _p_occ_inf(z, p)), rel=1e-6, abs=1e-9)


def test_unrendered_and_invalid_pixels_score_zero():
    z = np.full((3, 4), np.nan)
    assert log_likelihoods(np.ones((2, 3, 4)), prepare_observation(z, PARAMS), PARAMS).tolist() == [
        0,
        0,
    ]
    z = np.ones((3, 4))
    assert log_likelihoods(
        np.full((2, 3, 4), np.inf), prepare_observation(z, PARAMS), PARAMS
    ).tolist() == [0, 0]


def test_bad_images_are_rejected():
    with pytest.raises(ValueError, match="2-D"):
        prepare_observation(np.ones(5), PARAMS)
    with pytest.raises(ValueError, match="dtype"):
        prepare_observation(np.ones((2, 2), np.uint16), PARAMS)
    with pytest.raises(ValueError, match="shape"):
        log_likelihoods(np.ones((2, 3, 3)), prepare_observation(np.ones((2, 2)), PARAMS), PARAMS)
    with pytest.raises(ValueError, match="occlusion_probability"):
        LikelihoodParams(occlusion_probability=1.0).validate()
    # the float32 mixture's floor, the uniform density, must be a normal float32
    with pytest.raises(ValueError, match="tail_weight / max_depth_m must be >= 1e-30"):
        LikelihoodParams(tail_weight=1e-32).validate()
    LikelihoodParams(tail_weight=1e-29).validate()


@pytest.mark.parametrize("occluder_depth", ["truncated", "independent"])
def test_lane_pixel_scores_equal_the_scalar_formula(occluder_depth):
    """The fused kernel's pixel term, 8 particles at a time (lane_pixel_scores: exp, log
    and erfc from polynomials), against the direct transcription, term by term, over
    depths that reach both ends of erfc's range (rendered far behind and far in front
    of the observation) and lanes with nothing rendered."""
    from numba import njit

    from drake_tracker.core.simd.lane_likelihood import (
        PIXELS_PER_CALL,
        TERM_ATOL_F32,
        TERM_RTOL_F32,
        lane_pixel_scores,
        lane_pixel_scores_truncated,
    )
    from drake_tracker.core.simd.lanes import LANES

    @njit
    def score(zb, offsets, pixels, acc, table, uniform, lam, occlusion, truncation):
        for k in range(0, offsets.shape[0] - PIXELS_PER_CALL + 1, PIXELS_PER_CALL):
            if truncation != 0.0:
                lane_pixel_scores_truncated(zb, offsets, pixels, k, acc, table, uniform, lam,
                                            occlusion, truncation)
            else:
                lane_pixel_scores(zb, offsets, pixels, k, acc, table, uniform, lam,
                                  occlusion, truncation)

    params = LikelihoodParams(**{**PARAMS.__dict__, "occluder_depth": occluder_depth})
    rng = np.random.default_rng(5)
    z = np.concatenate([rng.uniform(0.2, 5.9, 300), [0.3, 5.9, 1.0, 1.0]])
    observation = prepare_observation(z[None, :].astype(np.float64), params)
    pixels = np.arange(len(z))
    spread = rng.choice([1e-3, 1e-2, 0.1, 3.0], size=(len(z), LANES))
    d = np.clip(z[:, None] + spread * rng.normal(size=(len(z), LANES)), 0.1, 6.0)
    d[-4:, 0] = [0.1, 6.0, 1.0 + 1e-12, 0.1]  # the ends of the range, an exact hit
    inverse = np.where(rng.random(d.shape) < 0.15, 0.0, 1.0 / d)  # 0: nothing rendered
    zb = np.concatenate([inverse.ravel(), np.zeros(LANES)])
    # the kernel scores the rendered image's float32 depth
    depth = np.full(inverse.shape, np.inf)
    np.divide(1.0, inverse, out=depth, where=inverse > 0)
    depth = np.where(inverse > 0, depth.astype(np.float32).astype(np.float64), np.inf)
    terms = np.array([[_scalar_log_ratio(z[p], depth[p, lane], params)
                       for lane in range(LANES)] for p in pixels])
    assert np.ptp(terms) > 5.0
    o = observation
    # Term by term: each pixel scored alone, beside the LANES zeros past the image
    # (nothing rendered there: a term of 0).
    padding = len(z) * LANES
    each = np.zeros((len(z), LANES))
    for p in pixels:
        offsets = np.full(PIXELS_PER_CALL, padding)
        offsets[0] = p * LANES
        zb_p = zb.copy()
        score(zb_p, offsets, np.array([p] + [0] * (PIXELS_PER_CALL - 1)), each[p],
              o.pixel_table, o.uniform, o.occluder_rate_per_m, o.occlusion_probability,
              o.truncation)
    # Stated tolerance: the mixture is evaluated in float32 (module docstring).
    np.testing.assert_allclose(each, terms, rtol=TERM_RTOL_F32, atol=TERM_ATOL_F32)
    assert np.all(each[inverse == 0] == 0.0)
    # All pixels in one pass: the sums of those terms (summed in double).
    acc = np.zeros(LANES)
    score(zb, np.arange(len(z)) * LANES, pixels, acc, o.pixel_table, o.uniform,
          o.occluder_rate_per_m, o.occlusion_probability, o.truncation)
    np.testing.assert_allclose(acc, each.sum(axis=0), rtol=1e-12)
    assert not zb.any()  # the scored pixels are cleared for the next batch


def test_independent_occluder_depth_by_numerical_integration():
    """The default occluder model: the occluder's depth is exponential whatever the robot
    does, and it occludes when nearer: o * p_occ(z|d) has no 1/(1-e^{-λd}) normaliser, so
    an occluded pixel's score does not change with how far behind the occluder the robot
    is (the truncated form prefers the robot just behind it)."""
    p = LikelihoodParams(**{**PARAMS.__dict__, "occluder_depth": "independent",
                            "occlusion_probability": 1 - 1e-12})
    z = 0.6
    s = p.depth_noise_std_m + p.depth_noise_factor_per_m * z * z
    lam = p.occluder_rate_per_m
    observation = prepare_observation(np.full((1, 1), z), p)
    scores = []
    for d in (0.9, 1.5, 3.0):
        y = np.linspace(0.0, d, 200001)
        integrand = lam * np.exp(-lam * y) * np.exp(-0.5 * ((z - y) / s) ** 2) / (
            s * math.sqrt(2 * math.pi))
        expected = p.tail_weight / p.max_depth_m + (1 - p.tail_weight) * np.trapezoid(
            integrand, y)
        score = log_likelihoods(np.full((1, 1, 1), d), observation, p)[0]
        assert score == pytest.approx(math.log(expected / _p_occ_inf(z, p)), abs=1e-6)
        scores.append(score)
    assert np.ptp(scores) < 1e-6
    truncated = [log_likelihoods(np.full((1, 1, 1), d), prepare_observation(
        np.full((1, 1), z), PARAMS), PARAMS)[0] for d in (0.9, 3.0)]
    assert truncated[0] > truncated[1] + 0.1
