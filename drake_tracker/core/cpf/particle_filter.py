"""The Coordinate Particle Filter image update and moment matching (paper §IV-B).

Particles start at the prior mean. For each block of coordinates in turn, that block
alone is sampled afresh (earlier blocks keep their values), all particles are scored
together, and the change of log-likelihood since the previous block is added to the log
weights. When the weights degenerate, ``KL(w || uniform) = log N - H(w) > max_kl``, the
particles are resampled (systematic resampling); children inherit their parent's values
and likelihood. Finally a Gaussian per joint is moment-matched to the weighted particles.

Each coordinate's prior may admit a *jump*: with probability ``jump_probability`` it is
``N(mean, std² + jump_std²)`` instead of ``N(mean, std²)`` (a bias that stepped since the
last image). Sampling from a proposal that is not the prior (a jump-heavy mixture, or a
Gaussian placed by an earlier annealing sweep) adds the importance ratio
``prior(x) / proposal(x)`` of each sampled block to the weights, so the weighted particles
always estimate prior x likelihood.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np


@dataclass
class CPFResult:
    """Moment-matched angle marginals and diagnostics of one image update."""

    mean: np.ndarray  # (n,)
    variance: np.ndarray  # (n,)
    num_resamples: int
    effective_sample_size: float
    num_evaluations: int
    log_likelihood_spread: float = 0.0
    block_log_likelihood_max: list[float] = field(default_factory=list)
    #: Every particle of every block scored the same log-likelihood (at least two
    #: particles): the image says nothing about these configurations, the posterior is
    #: the prior, and ``mean`` and ``variance`` are the prior's exactly.
    flat_likelihood: bool = False


def kl_from_uniform(log_weights: np.ndarray) -> float:
    """KL(w || uniform) = log N - entropy(w) for normalised weights exp(log_weights)."""
    w = normalized_weights(log_weights)
    nz = w > 0
    entropy = -np.sum(w[nz] * np.log(w[nz]))
    return float(np.log(len(w)) - entropy)


def normalized_weights(log_weights: np.ndarray) -> np.ndarray:
    """Weights ``exp(log_weights)`` scaled to sum to 1 (the largest log weight is
    subtracted first, so nothing overflows)."""
    shifted = np.exp(log_weights - np.max(log_weights))
    return shifted / shifted.sum()


def systematic_resample(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices of N children drawn by systematic resampling."""
    n = len(weights)
    positions = (rng.random() + np.arange(n)) / n
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0
    return np.searchsorted(cumulative, positions, side="right").clip(0, n - 1)


def weighted_moments(samples: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-coordinate weighted mean and variance (eqs. 14-15)."""
    mean = weights @ samples
    variance = weights @ np.square(samples - mean)
    return mean, variance


@dataclass(frozen=True)
class CoordinateMixture:
    """Per coordinate: ``(1 - p) N(mean, std²) + p N(mean, std² + jump_std²)``, all (n,)."""

    mean: np.ndarray
    std: np.ndarray
    jump_probability: np.ndarray
    jump_std: np.ndarray

    @staticmethod
    def gaussian(mean: np.ndarray, std: np.ndarray) -> CoordinateMixture:
        """A plain Gaussian (no jump component)."""
        zero = np.zeros_like(np.asarray(mean, float))
        return CoordinateMixture(np.asarray(mean, float), np.asarray(std, float), zero, zero)

    @cached_property
    def has_jumps(self) -> bool:
        """Whether any coordinate has a jump component (``jump_probability > 0`` and
        ``jump_std > 0``)."""
        return bool(np.any((self.jump_probability > 0) & (self.jump_std > 0)))

    @cached_property
    def _log_density_terms(self) -> tuple[np.ndarray, ...]:
        """Per coordinate, computed once (the mixture is immutable): whether it has spread,
        its variance (1 where none), log(2 pi var), and the jump component's
        log(1 - p), log(p) (-inf where p = 0), variance and log(2 pi var)."""
        spread = self.std > 0
        var = np.where(spread, self.std**2, 1.0)
        jump_var = var + self.jump_std**2
        with np.errstate(divide="ignore"):
            log_p = np.log(self.jump_probability)
        return (spread, var, np.log(2.0 * np.pi * var), np.log1p(-self.jump_probability),
                log_p, jump_var, np.log(2.0 * np.pi * jump_var))

    def sample(self, block: np.ndarray, num: int, rng: np.random.Generator) -> np.ndarray:
        """(num, len(block)) draws of the block's coordinates."""
        noise = rng.standard_normal((num, len(block)))
        std = self.std[block]
        if self.has_jumps:
            jumped = rng.random((num, len(block))) < self.jump_probability[block]
            std = np.where(jumped, np.sqrt(std**2 + self.jump_std[block] ** 2), std)
        return self.mean[block] + std * noise

    def log_density(self, x: np.ndarray, block: np.ndarray) -> np.ndarray:
        """(num,) log density of the block's values x (num, len(block)), summed over it;
        coordinates without spread contribute 0 (the same numbers as
        ``-0.5 ((x - mean)^2 / var + log(2 pi var))`` mixed with the jump component by
        logaddexp, from constants computed once per mixture)."""
        spread, var, log_norm, log_stay, log_jump, jump_var, jump_log_norm = (
            t[block] for t in self._log_density_terms)
        deviation2 = np.square(x - self.mean[block])
        log_p = -0.5 * (deviation2 / var + log_norm)
        if np.any(self.jump_probability[block] > 0):
            log_p = np.logaddexp(log_stay + log_p,
                                 log_jump + -0.5 * (deviation2 / jump_var + jump_log_norm))
        return np.sum(np.where(spread, log_p, 0.0), axis=1)

    def check(self, n: int, what: str) -> None:
        """Raises ValueError, prefixed with ``what``, unless all four arrays are finite with
        shape (n,), ``std`` and ``jump_std`` >= 0 and ``jump_probability`` in [0, 1)."""
        for name in ("mean", "std", "jump_probability", "jump_std"):
            value = np.asarray(getattr(self, name), float)
            if value.shape != (n,) or not np.all(np.isfinite(value)):
                raise ValueError(f"{what} {name} must be finite with shape ({n},)")
        if np.any(self.std < 0) or np.any(self.jump_std < 0) or np.any(
                (self.jump_probability < 0) | (self.jump_probability >= 1)):
            raise ValueError(f"{what}: std >= 0, jump_std >= 0, jump_probability in [0, 1)")


def coordinate_particle_filter(
    prior_mean: np.ndarray,
    prior_std: np.ndarray,
    blocks: Sequence[np.ndarray],
    num_particles: int,
    log_likelihood: Callable[[np.ndarray], np.ndarray],
    rng: np.random.Generator,
    max_kl: float = 2.0,
    prior: CoordinateMixture | None = None,
    proposal: CoordinateMixture | None = None,
) -> CPFResult:
    """Runs the CPF; ``log_likelihood`` maps (N, n) configurations to (N,) log-likelihoods.

    The particles target prior x likelihood, the prior being ``N(prior_mean, prior_std²)``
    or, when given, the mixture ``prior`` (whose mean and std must be ``prior_mean`` and
    ``prior_std``). They are drawn from the prior itself (the paper's CPF) unless a
    ``proposal`` is given; then each block's weights gain ``prior(x_block) /
    proposal(x_block)``, and the result still estimates prior x likelihood (importance
    sampling) wherever the proposal covers the posterior. Coordinates not yet sampled sit
    at the proposal's mean. Coordinates in no block keep their prior marginal.
    """
    prior_mean, prior_std, prior, proposal, importance = checked_sweep(
        prior_mean, prior_std, num_particles, prior, proposal)
    samples = np.tile(proposal.mean, (num_particles, 1))
    log_weights = np.zeros(num_particles)
    previous = np.zeros(num_particles)
    resamples = 0
    evaluations = 0
    block_max = []
    flat = num_particles >= 2
    for block in blocks:
        values = proposal.sample(block, num_particles, rng)
        samples[:, block] = values
        current = np.asarray(log_likelihood(samples), float)
        evaluations += num_particles
        if current.shape != (num_particles,) or not np.all(np.isfinite(current)):
            raise FloatingPointError("image log-likelihoods must be finite, one per particle")
        log_weights += current - previous
        if importance:
            log_weights += prior.log_density(values, block) - proposal.log_density(values, block)
        previous = current
        block_max.append(float(current.max()))
        flat = flat and bool(current.max() == current.min())
        if kl_from_uniform(log_weights) > max_kl:
            children = systematic_resample(normalized_weights(log_weights), rng)
            samples = samples[children]
            previous = previous[children]
            log_weights = np.zeros(num_particles)
            resamples += 1
    return finish_sweep(samples, log_weights, previous, blocks, prior_mean, prior_std,
                        resamples, evaluations, block_max, flat)


def checked_sweep(prior_mean: np.ndarray, prior_std: np.ndarray, num_particles: int,
                  prior: CoordinateMixture | None, proposal: CoordinateMixture | None
                  ) -> tuple[np.ndarray, np.ndarray, CoordinateMixture, CoordinateMixture,
                             bool]:
    """The arguments of a CPF sweep checked (ValueError naming the problem) and completed:
    (prior_mean, prior_std, prior, proposal, importance), the prior a mixture, the
    proposal the prior when none is given, and whether importance weights are needed."""
    prior_mean = np.asarray(prior_mean, float)
    prior_std = np.asarray(prior_std, float)
    n = prior_mean.shape[0]
    if prior_std.shape != (n,) or not np.all(np.isfinite(prior_std)) or np.any(prior_std < 0):
        raise ValueError("prior_std must be finite, non-negative and match prior_mean")
    if num_particles < 1:
        raise ValueError(f"num_particles must be >= 1, got {num_particles}")
    prior = prior if prior is not None else CoordinateMixture.gaussian(prior_mean, prior_std)
    prior.check(n, "CPF prior")
    if not (np.array_equal(prior.mean, prior_mean) and np.array_equal(prior.std, prior_std)):
        raise ValueError("the CPF prior mixture's mean and std must be prior_mean, prior_std")
    importance = proposal is not None or prior.has_jumps
    proposal = proposal if proposal is not None else prior
    proposal.check(n, "CPF proposal")
    return prior_mean, prior_std, prior, proposal, importance


def finish_sweep(samples: np.ndarray, log_weights: np.ndarray, previous: np.ndarray,
                 blocks: Sequence[np.ndarray], prior_mean: np.ndarray, prior_std: np.ndarray,
                 resamples: int, evaluations: int, block_max: list[float],
                 flat: bool) -> CPFResult:
    """The end of a CPF sweep: moment matching of the weighted particles (eqs. 14-15),
    the prior kept for coordinates in no block, and for a flat likelihood (``flat``)."""
    n = prior_mean.shape[0]
    weights = normalized_weights(log_weights)
    mean, variance = weighted_moments(samples, weights)
    in_blocks = np.zeros(n, bool)
    for block in blocks:
        in_blocks[block] = True
    mean = np.where(in_blocks, mean, prior_mean)
    variance = np.where(in_blocks, variance, prior_std**2)
    if flat:
        # Prior x constant is the prior. Its sample moments differ from it only by
        # Monte-Carlo noise, which, applied image after image (an arm out of view scores
        # 0 everywhere), walked the estimate: in-out-in, the camera offset 13-35 mm off.
        mean, variance = prior_mean.copy(), prior_std**2
    return CPFResult(
        mean=mean,
        variance=variance,
        num_resamples=resamples,
        effective_sample_size=float(1.0 / np.sum(weights**2)),
        num_evaluations=evaluations,
        log_likelihood_spread=float(previous.max() - previous.min()),
        block_log_likelihood_max=list(block_max),
        flat_likelihood=flat,
    )


def tempered_by(log_likelihood: Callable[[np.ndarray], np.ndarray],
                beta: float) -> Callable[[np.ndarray], np.ndarray]:
    """beta x ``log_likelihood``: its own ``scaled(beta)`` where it has one (a compiled
    likelihood stays compiled), else a wrapper."""
    if hasattr(log_likelihood, "scaled"):
        return log_likelihood.scaled(beta)

    def scored(q):
        return beta * np.asarray(log_likelihood(q), float)

    return scored


def annealed_coordinate_particle_filter(
    prior_mean: np.ndarray,
    prior_std: np.ndarray,
    blocks: Sequence[np.ndarray],
    num_particles: int,
    log_likelihood: Callable[[np.ndarray], np.ndarray],
    rng: np.random.Generator,
    max_kl: float = 2.0,
    betas: Sequence[float] = (1.0,),
    keep_std_fraction: float = 0.5,
    jump_probability: np.ndarray | None = None,
    jump_std: np.ndarray | None = None,
    proposal_jump_fraction: float = 0.25,
    sweep_log_likelihoods: Sequence[Callable[[np.ndarray], np.ndarray] | None] = (),
    sweep: Callable[..., CPFResult] | None = None,
) -> CPFResult:
    """CPF sweeps towards prior x likelihood^beta, for ``betas`` increasing to 1.

    ``betas == (1,)`` without jumps is the paper's single sweep. With more, sweep k
    targets ``prior x likelihood^beta_k`` by importance sampling (see
    :func:`coordinate_particle_filter`): the first sweep draws from the prior, each later
    one from a Gaussian at the previous sweep's moment-matched mean, with each
    coordinate's std the larger of its matched std and ``keep_std_fraction`` times the
    previous proposal's. Every sweep is weighted against the *prior*, never against the
    previous sweep's result, so the likelihood enters the answer exactly once, as
    likelihood^1 in the last sweep; the tempered sweeps only place its particles. (Weighting
    each sweep's ``likelihood^beta_k`` on top of the previous sweep's result would count
    the image sum(betas) times: 1.33 for the default schedule.)

    With ``jump_probability``/``jump_std`` (n,), the prior admits a jump per coordinate
    (see :class:`CoordinateMixture`), and every sweep's proposal draws the jump component
    for ``max(jump_probability, proposal_jump_fraction)`` of the particles (where the
    prior has one), so that a jump the image supports is found; importance weights keep
    the answer that of the prior.

    ``sweep_log_likelihoods`` (empty, or one per beta) may replace ``log_likelihood`` in
    the sweeps with beta < 1 by a cheaper approximation (e.g. a coarser image); None
    entries keep it. Those sweeps only place the last sweep's proposal, which is weighted
    against the prior with ``log_likelihood`` itself (its entry must be None), so the
    answer still estimates prior x likelihood. A log-likelihood with a ``scaled(factor)``
    method (a compiled one) is tempered through it rather than wrapped.

    ``sweep``: runs one sweep, with the arguments of :func:`coordinate_particle_filter`
    (default: that function; ``cpf_compiled.compiled_sweep`` runs the block loop of a
    compiled log-likelihood in numba, with the same random draws and results).

    Why sweep more than once: the pixel likelihood is so peaked that one sweep, sampling
    block after block while the later blocks sit at a prior mean several degrees off,
    lets the early blocks absorb the later blocks' error; tempered sweeps first find the
    basin (annealed particle filtering). Measured on Apollo with 8.6 deg of bias on every
    arm joint: a single sweep diverges, annealed sweeps converge to a few millimetres.
    """
    betas = [float(b) for b in betas]
    if not betas or betas[-1] != 1.0 or any(not 0 < b <= 1 for b in betas) or any(
            b1 > b2 for b1, b2 in zip(betas, betas[1:])):
        raise ValueError(f"annealing betas must increase within (0, 1] and end at 1, "
                         f"got {betas}")
    if not 0 < keep_std_fraction <= 1:
        raise ValueError(f"keep_std_fraction must be in (0, 1], got {keep_std_fraction}")
    if not 0 <= proposal_jump_fraction < 1:
        raise ValueError(f"proposal_jump_fraction must be in [0, 1), got "
                         f"{proposal_jump_fraction}")
    sweeps = list(sweep_log_likelihoods) or [None] * len(betas)
    if len(sweeps) != len(betas) or sweeps[-1] is not None:
        raise ValueError("sweep_log_likelihoods: one per beta, the last None (the exact "
                         "likelihood scores the last sweep)")
    prior_mean = np.asarray(prior_mean, float)
    prior_std = np.asarray(prior_std, float)
    zero = np.zeros_like(prior_mean)
    p_jump = zero if jump_probability is None else np.asarray(jump_probability, float)
    s_jump = zero if jump_std is None else np.asarray(jump_std, float)
    prior = CoordinateMixture(prior_mean, prior_std, p_jump, s_jump)
    p_proposal = np.where((p_jump > 0) & (s_jump > 0),
                          np.maximum(p_jump, proposal_jump_fraction), 0.0)
    proposal = CoordinateMixture(prior_mean, prior_std, p_proposal, s_jump)
    resamples = evaluations = 0
    result = None
    flat = True
    sweep = sweep or coordinate_particle_filter
    for layer, beta in enumerate(betas):
        scored = log_likelihood if beta == 1.0 else tempered_by(sweeps[layer] or log_likelihood,
                                                                 beta)
        is_prior = layer == 0 and not prior.has_jumps
        result = sweep(prior_mean, prior_std, blocks, num_particles, scored, rng, max_kl, prior,
                       None if is_prior else proposal)
        resamples += result.num_resamples
        evaluations += result.num_evaluations
        flat = flat and result.flat_likelihood
        if layer < len(betas) - 1:
            std = np.maximum(np.sqrt(result.variance), keep_std_fraction * proposal.std)
            proposal = CoordinateMixture(result.mean, std, p_proposal, s_jump)
    result.num_resamples = resamples
    result.num_evaluations = evaluations
    # Every sweep flat: the last sweep already returned the prior's moments exactly.
    result.flat_likelihood = flat
    return result
