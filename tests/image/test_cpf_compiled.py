"""The CPF's block loop in numba (core/cpf/compiled.py) against the Python sweep it
replaces: the same random draws, the same particles, the same result."""

import numpy as np
import pytest

from drake_tracker.bench.likelihood import make_update, tracking_prior
from drake_tracker.bench.likelihood import test_observation as bench_observation
from drake_tracker.core.cpf.compiled import CompiledLikelihood, compiled_sweep
from drake_tracker.core.cpf.particle_filter import annealed_coordinate_particle_filter
from drake_tracker.core.filter.kalman import MEAN_A, VAR_A
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import build_tracker_model, robot_preset

CAMERA = CameraIntrinsics.from_fov(640, 480, np.radians(45.0))


@pytest.fixture(scope="module")
def update():
    return make_update(build_tracker_model(robot_preset("apollo")), CAMERA, TrackerParams(),
                       evaluations=600)


def _assert_same(python, compiled):
    np.testing.assert_allclose(compiled.mean, python.mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(compiled.variance, python.variance, rtol=1e-9, atol=1e-18)
    assert compiled.num_resamples == python.num_resamples
    assert compiled.num_evaluations == python.num_evaluations
    assert compiled.flat_likelihood == python.flat_likelihood
    np.testing.assert_allclose(compiled.block_log_likelihood_max,
                               python.block_log_likelihood_max, rtol=1e-12)
    assert compiled.effective_sample_size == pytest.approx(python.effective_sample_size,
                                                           rel=1e-9)


@pytest.mark.parametrize("jumps", [False, True], ids=["gaussian prior", "jump mixture"])
def test_compiled_sweeps_give_the_python_sweeps_result(update, jumps):
    """Annealed sweeps (a Gaussian first sweep, then importance-weighted proposals; with
    jumps, mixtures in both), compiled and in Python, from the same seed."""
    observation = bench_observation(update)
    prior = tracking_prior(update.model)
    # off the truth, so that the particles are weighted and resampled
    mean = prior[MEAN_A] + np.random.default_rng(4).normal(0, 0.01, prior[MEAN_A].shape)
    std = np.sqrt(prior[VAR_A])
    n = len(mean)
    jump = dict(jump_probability=np.full(n, 0.05), jump_std=np.full(n, 0.1)) if jumps else {}
    likelihood = CompiledLikelihood(update.renderer, observation)
    results = [annealed_coordinate_particle_filter(
        mean, std, update.blocks, update.num_particles, scored, np.random.default_rng(1), 2.0,
        update.annealing_betas, sweep=compiled_sweep, **jump)
        for scored in (lambda q: likelihood(q), likelihood)]  # Python, then compiled
    assert results[0].num_resamples > 10
    assert np.abs(results[0].mean - mean).max() > 1e-3  # the image moved the estimate
    _assert_same(*results)


def test_the_image_update_runs_compiled_sweeps_with_the_python_result(update):
    """CpfImageUpdate with its batched renderer (compiled sweeps) against the same
    update through a wrapper renderer (the Python sweeps), coarse sweeps included."""
    from drake_tracker.core.cpf.image_update import CpfImageUpdate

    params = TrackerParams().image
    coarse = CpfImageUpdate(update.model, CAMERA, update.blocks, 10, params.likelihood, 80,
                            annealing_betas=update.annealing_betas,
                            sweep_image_widths_px=(40, 40, 40, 80))
    observation = bench_observation(coarse)
    prior = tracking_prior(update.model)

    class Wrapped:
        def __init__(self, renderer):
            self.renderer = renderer

        def score(self, q, o):
            return self.renderer.score(q, o)

    compiled = coarse(prior, observation, np.random.default_rng(2))
    evaluations = coarse.times.evaluations
    assert evaluations == coarse.evaluations_per_image
    coarse.renderer = Wrapped(coarse.renderer)
    coarse.sweep_renderers = {f: Wrapped(r) for f, r in coarse.sweep_renderers.items()}
    python = coarse(prior, observation, np.random.default_rng(2))
    assert coarse.times.evaluations == 2 * evaluations
    _assert_same(python, compiled)


def test_a_particles_score_does_not_depend_on_its_batch_mates(update):
    """The compiled sweep batches a block's particles in the order of the block's value
    (near ones share a pass over the pixels); that changes no result only because each
    particle's score is its own, bit for bit, whichever particles share its batch."""
    from drake_tracker.core.render.fused_score import _score_serial

    observation = bench_observation(update)
    prior = tracking_prior(update.model)
    rng = np.random.default_rng(3)
    q = prior[MEAN_A] + rng.normal(0.0, 0.05, (37, len(prior[MEAN_A])))
    q[::4] += rng.normal(0.0, 0.3, q[::4].shape)  # far-off draws, as a jump component's
    head, tail = CompiledLikelihood(update.renderer, observation).kernel_arguments(len(q))
    plain = np.zeros(len(q))
    _score_serial(np.ascontiguousarray(q), *head, 1, *tail, plain)
    for seed in range(3):
        order = np.random.default_rng(seed).permutation(len(q))
        permuted = np.zeros(len(q))
        _score_serial(np.ascontiguousarray(q[order]), *head, 1, *tail, permuted)
        assert np.array_equal(permuted, plain[order])
    assert np.ptp(plain) > 100.0  # the particles score differently
