"""The tempered CPF sweeps on a coarser image (``image.sweep_image_widths_px``).

The sweeps with beta < 1 only place the last sweep's proposal. Scoring them on the image
subsampled twice as coarsely must leave the answer an estimate of prior x likelihood
(importance sampling against the prior in the last sweep), and the coarse observation
must be exactly the coarser subsampling of the image, per-pixel occlusion included.
"""

import numpy as np
import pytest

from drake_tracker.core.cpf.image_update import CpfImageUpdate
from drake_tracker.core.cpf.particle_filter import annealed_coordinate_particle_filter
from drake_tracker.core.filter.kalman import initial_moments
from drake_tracker.core.likelihood.occlusion import with_pixel_occlusion
from drake_tracker.core.likelihood.pixel_model import (
    LikelihoodParams,
    coarser_observation,
    prepare_observation,
)
from drake_tracker.core.render.configurations import default_view_configuration
from drake_tracker.core.sensors.camera import CameraIntrinsics, subsample
from drake_tracker.params.loading import load_tracker_params
from drake_tracker.params.tracker_params import TrackerParams

BETAS = (0.003, 0.03, 0.3, 1.0)
PER_PIXEL = ("z", "sigma", "gauss_coeff", "occ_coeff", "log_p_occ_inf", "inv_sigma",
             "lam_sigma2")


def _awkward_depth(shape, seed):
    """A depth image with every kind of invalid pixel: NaN, 0, negative, beyond Z_max."""
    rng = np.random.default_rng(seed)
    depth = rng.uniform(0.5, 3.0, shape)
    kinds = rng.integers(0, 8, shape)
    depth[kinds == 0] = np.nan
    depth[kinds == 1] = 0.0
    depth[kinds == 2] = -1.0
    depth[kinds == 3] = 7.0
    return depth.astype(np.float32)


@pytest.mark.parametrize("shape, stride, factor", [((96, 128), 4, 2), ((95, 129), 4, 2),
                                                   ((60, 80), 1, 3)])
def test_coarser_observation_is_the_coarser_subsampling(shape, stride, factor):
    params = LikelihoodParams()
    depth = _awkward_depth(shape, 1)
    fine = prepare_observation(subsample(depth, stride), params)
    expected = prepare_observation(subsample(depth, stride * factor), params)
    got = coarser_observation(fine, factor)
    assert got.shape == expected.shape
    np.testing.assert_array_equal(got.pixel_index, expected.pixel_index)
    np.testing.assert_array_equal(got.pixel_slot, expected.pixel_slot)
    for name in PER_PIXEL:
        np.testing.assert_array_equal(getattr(got, name), getattr(expected, name), name)
    assert 0 < got.num_valid < fine.num_valid
    assert coarser_observation(fine, 1) is fine
    with pytest.raises(ValueError, match="factor"):
        coarser_observation(fine, 0)


def test_coarser_observation_keeps_the_per_pixel_occlusion():
    params = LikelihoodParams()
    depth = _awkward_depth((60, 80), 2)
    fine = prepare_observation(depth, params)
    occlusion = np.random.default_rng(3).uniform(0.0, 0.9, fine.num_valid)
    rows, cols = np.divmod(fine.pixel_index, 80)
    kept = (rows % 2 == 0) & (cols % 2 == 0)
    got = coarser_observation(with_pixel_occlusion(fine, occlusion), 2)
    expected = with_pixel_occlusion(coarser_observation(fine, 2), occlusion[kept])
    for name in PER_PIXEL + ("pixel_index",):
        np.testing.assert_array_equal(getattr(got, name), getattr(expected, name), name)
    assert got.occlusion_probability == expected.occlusion_probability == 0.5


def _shifted(loglik, shift):
    return lambda q: loglik(q - shift)


@pytest.mark.parametrize("shift", [0.15, -0.3])
def test_a_wrong_tempered_likelihood_still_gives_the_exact_posterior(shift):
    """Prior N(0, 1), likelihood N(1, 0.25): posterior N(0.8, 0.2). The tempered sweeps
    score a likelihood whose peak is ``shift`` off; only the proposal moves, so over 40
    seeds the result matches the exact posterior. The same likelihood in every sweep
    would move the mean by 0.8 * shift (0.12-0.24, over 20 standard errors)."""
    def loglik(q):
        return -0.5 * (q[:, 0] - 1.0) ** 2 / 0.25

    runs = [annealed_coordinate_particle_filter(
        np.zeros(1), np.ones(1), [np.array([0])], 400, loglik, np.random.default_rng([s, 3]),
        2.0, BETAS, sweep_log_likelihoods=[_shifted(loglik, shift)] * 3 + [None])
        for s in range(40)]
    means = np.array([r.mean[0] for r in runs])
    variances = np.array([r.variance[0] for r in runs])
    se = means.std(ddof=1) / np.sqrt(len(means))
    assert abs(means.mean() - 0.8) < 4 * se + 0.005, (means.mean(), se)
    assert abs(variances.mean() - 0.2) < 0.03 * 0.2 + 4 * variances.std(ddof=1) / np.sqrt(40)
    wrong = [annealed_coordinate_particle_filter(
        np.zeros(1), np.ones(1), [np.array([0])], 400, _shifted(loglik, shift),
        np.random.default_rng([s, 3]), 2.0, BETAS).mean[0] for s in range(10)]
    assert abs(np.mean(wrong) - 0.8) > 20 * se


def test_the_tempered_sweeps_render_the_coarser_image(apollo):
    """At 80x60 with sweeps at 40 px, the coarse sweeps' renderer draws Apollo at
    40x30 as the 80x60 renderer's image subsampled (its own level of detail: the same
    robot label on >= 98 % of the pixels either marks, depth within 2 mm at the median),
    and an update with it moves towards the truth like the full-resolution one."""
    camera = CameraIntrinsics.from_fov(640, 480, np.radians(45.0))
    params = TrackerParams().image
    blocks = [np.array([i]) for i in range(apollo.num_joints)]
    update = CpfImageUpdate(apollo, camera, blocks, 20, params.likelihood, 80,
                            annealing_betas=BETAS, sweep_image_widths_px=(40, 40, 80, 80))
    assert update.sweep_factors == (2, 2, 1, 1)
    coarse_renderer = update.sweep_renderers[2]
    assert (coarse_renderer.intrinsics.width, coarse_renderer.intrinsics.height) == (40, 30)
    q = default_view_configuration(apollo)
    fine = update.renderer.render(q[None])[0][::2, ::2]
    coarse = coarse_renderer.render(q[None])[0]
    fine_robot, coarse_robot = np.isfinite(fine), np.isfinite(coarse)
    either = fine_robot | coarse_robot
    assert either.sum() > 100
    assert np.mean(fine_robot[either] == coarse_robot[either]) >= 0.98
    both = fine_robot & coarse_robot
    assert np.median(np.abs(fine[both] - coarse[both])) < 0.002
    same = CpfImageUpdate(apollo, camera, blocks, 20, params.likelihood, 80,
                          annealing_betas=BETAS)
    assert same.sweep_factors == (1, 1, 1, 1) and same.sweep_renderers == {1: same.renderer}
    with pytest.raises(ValueError, match="last sweep"):
        CpfImageUpdate(apollo, camera, blocks, 20, params.likelihood, 80,
                       annealing_betas=BETAS, sweep_image_widths_px=(40, 40, 80, 40))
    with pytest.raises(ValueError, match="one width"):
        CpfImageUpdate(apollo, camera, blocks, 20, params.likelihood, 80,
                       annealing_betas=BETAS, sweep_image_widths_px=(40, 80))


@pytest.mark.parametrize("widths", ["[40, 40, 40, 40]", "[40, 80]", "[0, 40, 40, 80]"])
def test_sweep_widths_are_validated_at_load(tmp_path, widths):
    path = tmp_path / "params.yaml"
    path.write_text(f"image: {{sweep_image_widths_px: {widths}}}\n")
    with pytest.raises(ValueError, match="image.sweep_image_widths_px"):
        load_tracker_params(path)
    path.write_text("image: {sweep_image_widths_px: [20, 20, 80, 80]}\n")
    assert load_tracker_params(path).image.sweep_image_widths_px == [20, 20, 80, 80]
    assert TrackerParams().image.sweep_image_widths_px == []


class _CountingRenderer:
    """Wraps a renderer and counts the configurations it scores."""

    def __init__(self, renderer):
        self.renderer, self.scored = renderer, 0

    def score(self, q, observation):
        self.scored += len(q)
        return self.renderer.score(q, observation)


def test_only_the_coarse_sweeps_score_the_coarse_image_and_not_while_acquiring(apollo):
    camera = CameraIntrinsics.from_fov(320, 240, np.radians(45.0))
    likelihood = TrackerParams().image.likelihood
    blocks = [np.array([apollo.joint_names.index(n)]) for n in apollo.robot_joint_names]
    update = CpfImageUpdate(apollo, camera, blocks, 8, likelihood, 40, annealing_betas=BETAS,
                            sweep_image_widths_px=(20, 20, 20, 40))
    q = default_view_configuration(apollo)
    image = update.renderer.render(q[None])[0]
    full = np.repeat(np.repeat(np.where(np.isfinite(image), image, 2.5), 8, 0), 8, 1)
    observation = update.prepare(full.astype(np.float32))
    std = np.full(apollo.num_joints, 0.02)
    prior = initial_moments(q, std, std, np.ones(apollo.num_joints, bool))
    update.renderer = fine = _CountingRenderer(update.renderer)
    update.sweep_renderers[2] = coarse = _CountingRenderer(update.sweep_renderers[2])
    update(prior, observation, np.random.default_rng(0))
    per_sweep = 8 * len(blocks)
    assert (fine.scored, coarse.scored) == (per_sweep, 3 * per_sweep)
    update(prior, observation, np.random.default_rng(0), coarse_sweeps=False)
    assert (fine.scored, coarse.scored) == (5 * per_sweep, 3 * per_sweep)


def test_a_width_wider_than_the_camera_is_warned_and_the_camera_kept(apollo, caplog):
    """Images are only subsampled: asked for 160 px of an 80 x 60 camera (a recording
    stores its working size), the update tracks at 80 px and says so."""
    camera = CameraIntrinsics.from_fov(80, 60, np.radians(45.0))
    blocks = [np.array([i]) for i in range(apollo.num_joints)]
    with caplog.at_level("WARNING", logger="drake_tracker.core.cpf.image_update"):
        update = CpfImageUpdate(apollo, camera, blocks, 4, TrackerParams().image.likelihood,
                                160)
    assert (update.intrinsics.width, update.intrinsics.height) == (80, 60)
    assert "image_width_px = 160 is wider than the camera's 80 x 60" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING", logger="drake_tracker.core.cpf.image_update"):
        CpfImageUpdate(apollo, camera, blocks, 4, TrackerParams().image.likelihood, 80)
    assert "wider" not in caplog.text
