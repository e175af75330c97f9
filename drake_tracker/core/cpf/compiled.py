"""The CPF's block loop in numba, for a log-likelihood that is itself a numba kernel.

One image update makes 60 block calls (15 blocks x 4 sweeps); in Python each costs a
few hundred microseconds of numpy calls around the scoring kernel, a tenth of the
update or more. :func:`compiled_sweep` runs a whole sweep of
:func:`~drake_tracker.core.cpf.particle_filter.coordinate_particle_filter` in one numba call: the
same
steps in the same order, the same random draws from the same ``numpy.random.Generator``
(numba draws from its bit generator exactly as numpy does), so it returns the Python
sweep's result (tested, to rounding: numpy's and libm's exp and log may differ in the
last bit). The moment matching at the end is the Python sweep's own
(:func:`~drake_tracker.core.cpf.particle_filter.finish_sweep`).

A :class:`CompiledLikelihood` is the fused render-and-score kernel of a
:class:`~drake_tracker.core.render.batched.BatchedDepthRenderer` for one observation,
times constant factors (the tempered sweeps' beta, a coarse image's scale); called from
Python it scores like ``renderer.score``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from drake_tracker.core.cpf.particle_filter import (
    CoordinateMixture,
    CPFResult,
    checked_sweep,
    coordinate_particle_filter,
    finish_sweep,
)
from drake_tracker.core.render.fused_score import _score_parallel, _score_serial, num_batch_chunks

if TYPE_CHECKING:
    from drake_tracker.core.likelihood.pixel_model import PreparedObservation
    from drake_tracker.core.render.batched import BatchedDepthRenderer

#: Rows of a mixture's per-coordinate terms (see :func:`mixture_terms`).
MEAN, STD, P_JUMP, JUMP_STD, VAR, LOG_NORM, LOG_STAY, LOG_JUMP, JUMP_VAR, JUMP_LOG_NORM, \
    SPREAD = range(11)


class CompiledLikelihood:
    """``factors[-1] * (... * (factors[0] * renderer.score(q, observation)))``: the log-
    likelihood of configurations q (N, nq), which :func:`compiled_sweep` evaluates inside
    numba. ``on_evaluation(seconds, count)`` (optional) is told of each call's wall time
    and number of evaluations (the image update's stage times)."""

    def __init__(self, renderer: BatchedDepthRenderer, observation: PreparedObservation,
                 factors: tuple[float, ...] = (),
                 on_evaluation: Callable[[float, int], None] | None = None) -> None:
        self.renderer = renderer
        self.observation = observation
        self.factors = tuple(float(f) for f in factors)
        self.on_evaluation = on_evaluation

    def scaled(self, factor: float) -> CompiledLikelihood:
        """This log-likelihood times ``factor`` (applied after the present factors)."""
        return CompiledLikelihood(self.renderer, self.observation, (*self.factors, factor),
                                  self.on_evaluation)

    def __call__(self, q: np.ndarray) -> np.ndarray:
        t0 = time.perf_counter()
        out = self.renderer.score(q, self.observation)
        for factor in self.factors:
            out = factor * out
        if self.on_evaluation is not None:
            self.on_evaluation(time.perf_counter() - t0, len(q))
        return out

    def kernel_arguments(self, num_particles: int) -> tuple[tuple, tuple]:
        """The scoring kernel's arguments between q and chunks, and between chunks and
        out (``render_likelihood._score_particles``), for ``num_particles`` at a time."""
        r, o = self.renderer, self.observation
        k = r.intrinsics
        if tuple(o.shape) != (k.height, k.width):
            raise ValueError(f"observation has shape {tuple(o.shape)}, the renderer renders "
                             f"({k.height}, {k.width})")
        return ((*r._frame_tables, *r._lane_tables, r._planes, r._fx, r._fy, r._cx, r._cy,
                 r.near_m, r.far_m),
                (k.height, k.width, o.pixel_slot, o.pixel_table, o.uniform,
                 o.occluder_rate_per_m, o.occlusion_probability, o.truncation,
                 r.workspace(num_batch_chunks(num_particles))))


def mixture_terms(mixture: CoordinateMixture) -> np.ndarray:
    """(11, n) per coordinate: mean, std, jump probability and std, and the log-density
    constants of :meth:`CoordinateMixture.log_density` (spread as 1.0 / 0.0)."""
    spread, var, log_norm, log_stay, log_jump, jump_var, jump_log_norm = (
        mixture._log_density_terms)
    return np.ascontiguousarray(np.vstack([
        mixture.mean, mixture.std, mixture.jump_probability, mixture.jump_std, var, log_norm,
        log_stay, log_jump, jump_var, jump_log_norm, spread.astype(float)]))


@njit(cache=True, nogil=True)
def _log_density(x, block, terms, out):
    """out[i] = CoordinateMixture.log_density(x, block)[i] for the mixture ``terms``."""
    with_jumps = False
    for c in block:
        with_jumps = with_jumps or terms[P_JUMP, c] > 0
    for i in range(x.shape[0]):
        total = 0.0
        for j in range(block.shape[0]):
            c = block[j]
            deviation2 = (x[i, j] - terms[MEAN, c]) ** 2
            log_p = -0.5 * (deviation2 / terms[VAR, c] + terms[LOG_NORM, c])
            if with_jumps:
                log_p = np.logaddexp(terms[LOG_STAY, c] + log_p, terms[LOG_JUMP, c] + -0.5 * (
                    deviation2 / terms[JUMP_VAR, c] + terms[JUMP_LOG_NORM, c]))
            total += log_p if terms[SPREAD, c] != 0.0 else 0.0
        out[i] = total


@njit(cache=True, nogil=True)
def _resample_if_degenerate(rng, samples, previous, log_weights, max_kl):
    """cpf.kl_from_uniform and cpf.systematic_resample: resamples (children inherit
    their parent's values and likelihood) when KL(w || uniform) > max_kl."""
    n = log_weights.shape[0]
    w = np.exp(log_weights - np.max(log_weights))
    w /= w.sum()
    entropy = 0.0
    for v in w:
        if v > 0:
            entropy -= v * np.log(v)
    if np.log(n) - entropy <= max_kl:
        return False
    positions = (rng.random() + np.arange(n)) / n
    cumulative = np.cumsum(w)
    cumulative[-1] = 1.0
    children = np.minimum(np.searchsorted(cumulative, positions, side="right"), n - 1)
    samples[:, :] = samples[children].copy()
    previous[:] = previous[children].copy()
    log_weights[:] = 0.0
    return True


@njit(cache=True, nogil=True)
def _sweep(rng, samples, block_index, block_start, prior, proposal, proposal_jumps,
           importance, max_kl, factors, parallel, chunks, head, tail, log_weights, previous,
           block_max):
    """The block loop of cpf.coordinate_particle_filter, step for step. Returns
    (resamples, flat, ok); ok False: a log-likelihood was not finite."""
    n = samples.shape[0]
    current = np.zeros(n)
    ordered = np.empty_like(samples)
    scores = np.zeros(n)
    density = np.zeros(n)
    other = np.zeros(n)
    resamples = 0
    flat = n >= 2
    for b in range(block_start.shape[0] - 1):
        block = block_index[block_start[b]:block_start[b + 1]]
        k = block.shape[0]
        noise = rng.standard_normal((n, k))  # CoordinateMixture.sample
        jumped = rng.random((n, k)) if proposal_jumps else np.ones((n, k))
        values = np.empty((n, k))
        for i in range(n):
            for j in range(k):
                c = block[j]
                sd = proposal[STD, c]
                if jumped[i, j] < proposal[P_JUMP, c]:
                    sd = np.sqrt(sd ** 2 + proposal[JUMP_STD, c] ** 2)
                values[i, j] = proposal[MEAN, c] + sd * noise[i, j]
                samples[i, c] = values[i, j]
        # The kernel scores LANES particles in one pass over the pixels their triangles
        # cover together: one far off (a bias-jump draw, a wide search) widens the pass
        # of its whole batch. Batched in the order of the block's first value, near ones
        # share batches. Each particle's score is its own whatever its batch (tested), so
        # the result is the one of the particles' own order, bit for bit.
        order = np.argsort(values[:, 0], kind="mergesort")
        for i in range(n):
            ordered[i, :] = samples[order[i], :]
        if parallel:
            _score_parallel(ordered, *head, chunks, *tail, scores)
        else:
            _score_serial(ordered, *head, 1, *tail, scores)
        for i in range(n):
            current[order[i]] = scores[i]
        for f in factors:
            current[:] = f * current
        if not np.all(np.isfinite(current)):
            return resamples, flat, False
        log_weights += current - previous
        if importance:
            _log_density(values, block, prior, density)
            _log_density(values, block, proposal, other)
            log_weights += density - other
        previous[:] = current
        block_max[b] = current.max()
        flat = flat and current.max() == current.min()
        resamples += _resample_if_degenerate(rng, samples, previous, log_weights, max_kl)
    return resamples, flat, True


def compiled_sweep(prior_mean: np.ndarray, prior_std: np.ndarray,
                   blocks: Sequence[np.ndarray], num_particles: int,
                   log_likelihood: Callable[[np.ndarray], np.ndarray],
                   rng: np.random.Generator, max_kl: float = 2.0,
                   prior: CoordinateMixture | None = None,
                   proposal: CoordinateMixture | None = None) -> CPFResult:
    """:func:`~drake_tracker.core.cpf.particle_filter.coordinate_particle_filter`, its block loop
    in numba
    when ``log_likelihood`` is a :class:`CompiledLikelihood` (otherwise that function
    itself). Same arguments, same result."""
    if not isinstance(log_likelihood, CompiledLikelihood):
        return coordinate_particle_filter(prior_mean, prior_std, blocks, num_particles,
                                          log_likelihood, rng, max_kl, prior, proposal)
    prior_mean, prior_std, prior, proposal, importance = checked_sweep(
        prior_mean, prior_std, num_particles, prior, proposal)
    head, tail = log_likelihood.kernel_arguments(num_particles)
    blocks = [np.asarray(block, np.int64).reshape(-1) for block in blocks]
    block_start = np.cumsum([0] + [len(block) for block in blocks]).astype(np.int64)
    block_index = np.concatenate(blocks) if blocks else np.zeros(0, np.int64)
    samples = np.tile(proposal.mean, (num_particles, 1))
    log_weights = np.zeros(num_particles)
    previous = np.zeros(num_particles)
    block_max = np.zeros(len(blocks))
    policy = log_likelihood.renderer._policy
    parallel = policy.use_parallel() and num_batch_chunks(num_particles) > 1
    t0 = time.perf_counter()
    resamples, flat, ok = _sweep(
        rng, samples, block_index, block_start, mixture_terms(prior), mixture_terms(proposal),
        proposal.has_jumps, importance, float(max_kl), np.array(log_likelihood.factors),
        parallel, num_batch_chunks(num_particles), head, tail, log_weights, previous,
        block_max)
    seconds = time.perf_counter() - t0
    evaluations = num_particles * len(blocks)
    policy.record(parallel, seconds, evaluations)
    if log_likelihood.on_evaluation is not None:
        log_likelihood.on_evaluation(seconds, evaluations)
    if not ok:
        raise FloatingPointError("image log-likelihoods must be finite, one per particle")
    return finish_sweep(samples, log_weights, previous, blocks, prior_mean, prior_std,
                        int(resamples), evaluations, [float(m) for m in block_max], bool(flat))
