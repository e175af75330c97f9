"""The occlusion-robust depth-pixel likelihood (paper eqs. 1-2, docs/method.md §2).

For an observed depth ``z`` and the depth ``d`` the robot renders at that pixel:

* ``σ = σ_model + σ_factor z²``
* ``p_vis(z|d) = w/Z_max + (1-w) N(z; d, σ²)``
* ``p_occ(z|d) = w/Z_max + (1-w) λ/(1-e^{-λd}) exp(-λz + λ²σ²/2) Φ((d - z + λσ²)/σ)``
  (the paper's: the occluder's depth is exponential *truncated to [0, d]*), or, with
  ``occluder_depth = "independent"`` (the default), without the ``1/(1-e^{-λd})``
  normaliser: the occluder is an object of its own, exponential in depth whatever the
  robot does, and it occludes when it is nearer. The truncated form makes an observed
  occluder at z likelier the nearer the robot is put behind it (``1/(1-e^{-λd})`` grows
  as d falls): measured on an image hiding 78 % of the arm, it pulled the estimate
  towards the camera, many prior standard deviations (issue 17).
* ``p(z|d) = (1-o) p_vis + o p_occ``

Each pixel scores ``log(p(z|d) / p_occ(z|∞))``: pixels where nothing is rendered and
invalid pixels (NaN, <= 0, > Z_max) score 0. A particle's log-likelihood is the sum.
"""


import math
from dataclasses import dataclass, replace
from functools import cached_property

import numba
import numpy as np

from drake_tracker.core.jit.numba_threading import pick_kernel, serial_and_parallel

#: The least uniform density w / Z_max (1/m) allowed: the image update's float32 mixture
#: never falls below it, so its logarithm is that of a normal float32 number.
MIN_UNIFORM_DENSITY = 1e-30


@dataclass
class LikelihoodParams:
    """Parameters of the pixel model; loadable from YAML."""

    #: Tail weight w: probability of a uniformly random depth reading.
    tail_weight: float = 0.01
    #: σ_model (m): depth noise standard deviation at zero depth.
    depth_noise_std_m: float = 0.003
    #: σ_factor (1/m): growth of the noise standard deviation with depth squared.
    depth_noise_factor_per_m: float = 0.0014247
    #: Z_max (m): largest valid depth; the support of the uniform tail.
    max_depth_m: float = 6.0
    #: λ (1/m): rate of the exponential prior over an occluder's depth.
    occluder_rate_per_m: float = math.log(2.0)
    #: o: prior probability that a pixel is occluded.
    occlusion_probability: float = 0.1
    #: ``independent`` (an occluder's depth does not depend on the robot's) or
    #: ``truncated`` (the paper's: truncated to [0, d]); see the module docstring.
    occluder_depth: str = "independent"

    def validate(self, where: str = "LikelihoodParams") -> None:
        """Raises ValueError naming the field as ``where.field`` (e.g.
        ``image.likelihood.max_depth_m`` when loaded with the tracker's parameters)."""
        def need(cond: bool, field: str, why: str) -> None:
            if not cond:
                raise ValueError(f"{where}.{field} = {getattr(self, field)!r}: {why}")

        for field, value in vars(self).items():
            if isinstance(value, float):
                need(math.isfinite(value), field, "must be finite")
        need(0 < self.tail_weight < 1, "tail_weight", "must be in (0, 1)")
        # the image update evaluates the mixture in float32, whose floor is the uniform
        # density w / Z_max: it must be a normal float32 number (>= 1.2e-38), with room
        need(self.tail_weight / max(self.max_depth_m, 1e-300) >= MIN_UNIFORM_DENSITY,
             "tail_weight", f"tail_weight / max_depth_m must be >= {MIN_UNIFORM_DENSITY:g} "
             "(the uniform density is the float32 mixture's floor)")
        need(self.depth_noise_std_m > 0, "depth_noise_std_m", "must be > 0")
        need(self.depth_noise_factor_per_m >= 0, "depth_noise_factor_per_m", "must be >= 0")
        need(self.max_depth_m > 0, "max_depth_m", "must be > 0")
        need(self.occluder_rate_per_m > 0, "occluder_rate_per_m", "must be > 0")
        need(0 <= self.occlusion_probability < 1, "occlusion_probability", "must be in [0, 1)")
        need(self.occluder_depth in ("independent", "truncated"), "occluder_depth",
             "must be 'independent' or 'truncated'")

    @property
    def truncation(self) -> float:
        """1.0 for the truncated occluder depth, 0.0 for the independent one."""
        return 1.0 if self.occluder_depth == "truncated" else 0.0


def pixel_sigma(z: np.ndarray, params: LikelihoodParams) -> np.ndarray:
    """Per-pixel depth noise standard deviation (m) at depths ``z`` (m), same shape:
    ``depth_noise_std_m + depth_noise_factor_per_m * z²``."""
    return params.depth_noise_std_m + params.depth_noise_factor_per_m * np.square(z)


def valid_pixels(z: np.ndarray, params: LikelihoodParams) -> np.ndarray:
    """Boolean mask of usable observed depths."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(z) & (z > 0) & (z <= params.max_depth_m)


#: Columns of :attr:`PreparedObservation.pixel_table`.
(TABLE_Z, TABLE_INV_SIGMA, TABLE_GAUSS, TABLE_OCC, TABLE_LAM_SIGMA2,
 TABLE_LOG_P_OCC_INF) = range(6)
PIXEL_COLUMNS = 8


@dataclass
class PreparedObservation:
    """An observed image reduced to its valid pixels and their per-pixel constants.

    Built once per image by :func:`prepare_observation`, with everything a scorer needs
    (the fused render-and-score kernel reads these arrays as they are): per valid pixel
    p, contiguous float64 constants, and ``pixel_slot`` mapping each of the H*W pixels to
    its p (-1: invalid). The scalar parameters are those it was prepared with.
    """

    pixel_index: np.ndarray  # (P,) int64 flat indices into the H*W image
    z: np.ndarray  # (P,) observed depth
    sigma: np.ndarray
    gauss_coeff: np.ndarray  # (1-w)/(σ√(2π))
    occ_coeff: np.ndarray  # (1-w) λ exp(-λz + λ²σ²/2)
    log_p_occ_inf: np.ndarray  # log p_occ(z|∞)
    shape: tuple[int, int]
    pixel_slot: np.ndarray  # (H*W,) int64: index p of each pixel, -1 if invalid
    inv_sigma: np.ndarray  # 1/σ
    lam_sigma2: np.ndarray  # λσ²
    uniform: float  # w/Z_max
    occluder_rate_per_m: float  # λ
    occlusion_probability: float  # o
    truncation: float  # 1: occluder depth truncated to [0, d]; 0: independent

    @property
    def num_valid(self) -> int:
        """P, the number of valid pixels."""
        return len(self.z)

    @cached_property
    def pixel_table(self) -> np.ndarray:
        """(P, PIXEL_COLUMNS) float64: each valid pixel's constants in one row (columns
        TABLE_Z, TABLE_INV_SIGMA, TABLE_GAUSS, TABLE_OCC, TABLE_LAM_SIGMA2,
        TABLE_LOG_P_OCC_INF; the rest padding, so that a row is one cache line), as the
        fused kernel reads them; built once per observation (``dataclasses.replace``
        makes a new observation, with a table of its own)."""
        table = np.zeros((self.num_valid, PIXEL_COLUMNS))
        for column, values in ((TABLE_Z, self.z), (TABLE_INV_SIGMA, self.inv_sigma),
                               (TABLE_GAUSS, self.gauss_coeff), (TABLE_OCC, self.occ_coeff),
                               (TABLE_LAM_SIGMA2, self.lam_sigma2),
                               (TABLE_LOG_P_OCC_INF, self.log_p_occ_inf)):
            table[:, column] = values
        return table


def prepare_observation(depth: np.ndarray, params: LikelihoodParams) -> PreparedObservation:
    """Checks an observed (H, W) depth image and precomputes what depends only on it."""
    depth = np.asarray(depth)
    if depth.ndim != 2 or depth.size == 0:
        raise ValueError(f"depth image must be a non-empty 2-D array, got shape {depth.shape}")
    if not np.issubdtype(depth.dtype, np.floating):
        raise ValueError(f"depth image must be floating point metres, got dtype {depth.dtype}")
    flat = depth.astype(np.float64).ravel()
    index = np.flatnonzero(valid_pixels(flat, params))
    z = flat[index]
    sigma = pixel_sigma(z, params)
    w, lam = params.tail_weight, params.occluder_rate_per_m
    gauss_coeff = (1.0 - w) / (sigma * math.sqrt(2.0 * math.pi))
    occ_coeff = (1.0 - w) * lam * np.exp(-lam * z + 0.5 * lam**2 * sigma**2)
    log_p_occ_inf = np.log(w / params.max_depth_m + occ_coeff)
    slot = np.full(flat.size, -1, dtype=np.int64)
    slot[index] = np.arange(index.size)
    return PreparedObservation(
        pixel_index=index, z=z, sigma=sigma, gauss_coeff=gauss_coeff, occ_coeff=occ_coeff,
        log_p_occ_inf=log_p_occ_inf, shape=tuple(depth.shape), pixel_slot=slot,
        inv_sigma=1.0 / sigma, lam_sigma2=lam * np.square(sigma),
        uniform=w / params.max_depth_m, occluder_rate_per_m=float(lam),
        occlusion_probability=float(params.occlusion_probability),
        truncation=params.truncation)


def widened_observation(observation: PreparedObservation,
                        extra_std_m: float) -> PreparedObservation:
    """``observation`` with every pixel's depth noise σ widened by ``extra_std_m`` (m),
    its per-pixel occlusion estimate kept: what :func:`prepare_observation` gives with
    ``depth_noise_std_m + extra_std_m``, times the occlusion factors. A likelihood whose
    peaks are that much wider in depth: the start-up search's early sweeps (see
    ``image_update``)."""
    if not (math.isfinite(extra_std_m) and extra_std_m >= 0):
        raise ValueError(f"extra_std_m must be finite and >= 0, got {extra_std_m}")
    if extra_std_m == 0:
        return observation
    sigma = observation.sigma + extra_std_m
    lam = observation.occluder_rate_per_m
    # gauss ∝ 1/σ; occ ∝ exp(λ²σ²/2) (prepare_observation), so both scale per pixel.
    growth = np.exp(0.5 * lam**2 * (np.square(sigma) - np.square(observation.sigma)))
    occ_base = np.exp(observation.log_p_occ_inf) - observation.uniform
    return replace(
        observation, sigma=sigma, gauss_coeff=observation.gauss_coeff * observation.sigma / sigma,
        occ_coeff=observation.occ_coeff * growth, inv_sigma=1.0 / sigma,
        lam_sigma2=lam * np.square(sigma),
        log_p_occ_inf=np.log(observation.uniform + occ_base * growth))


def coarser_observation(observation: PreparedObservation,
                        factor: int) -> PreparedObservation:
    """``observation`` subsampled again: its pixels (factor*i, factor*j), with their
    per-pixel constants as they are (a per-pixel occlusion estimate included). Equal to
    preparing the image subsampled ``factor`` times more coarsely."""
    if factor < 1:
        raise ValueError(f"coarsening factor must be >= 1, got {factor}")
    if factor == 1:
        return observation
    height, width = observation.shape
    rows, cols = np.divmod(observation.pixel_index, width)
    kept = np.flatnonzero((rows % factor == 0) & (cols % factor == 0))
    shape = (-(-height // factor), -(-width // factor))
    index = (rows[kept] // factor) * shape[1] + cols[kept] // factor
    slot = np.full(shape[0] * shape[1], -1, dtype=np.int64)
    slot[index] = np.arange(index.size)
    per_pixel = {name: getattr(observation, name)[kept] for name in (
        "z", "sigma", "gauss_coeff", "occ_coeff", "log_p_occ_inf", "inv_sigma",
        "lam_sigma2")}
    return replace(observation, pixel_index=index, shape=shape,
                   pixel_slot=slot, **per_pixel)


def _sum_log_ratios_of(rendered, index, z, sigma, gauss_coeff, occ_coeff, log_p_occ_inf,
                    uniform, lam, occlusion, truncation):
    num = rendered.shape[0]
    out = np.zeros(num)
    inv_sqrt2 = 1.0 / math.sqrt(2.0)
    for n in numba.prange(num):
        total = 0.0
        for p in range(index.shape[0]):
            d = rendered[n, index[p]]
            if not np.isfinite(d):
                continue
            s = sigma[p]
            r = (z[p] - d) / s
            p_vis = uniform + gauss_coeff[p] * math.exp(-0.5 * r * r)
            phi = 0.5 * math.erfc(-(d - z[p] + lam * s * s) / s * inv_sqrt2)
            p_occ = uniform + occ_coeff[p] * phi / (1.0 - truncation * math.exp(-lam * d))
            total += math.log((1.0 - occlusion) * p_vis + occlusion * p_occ) - log_p_occ_inf[p]
        out[n] = total
    return out


_sum_serial, _sum_parallel = serial_and_parallel(_sum_log_ratios_of, nogil=True)


def log_likelihoods(rendered: np.ndarray, observation: PreparedObservation,
                    params: LikelihoodParams) -> np.ndarray:
    """Log-likelihood of each of N rendered (N, H, W) depth images (inf = not rendered):
    the plain reference implementation, one pixel after another."""
    return _score_rendered(rendered, observation, params.tail_weight / params.max_depth_m,
                           params.truncation,
                           params.occluder_rate_per_m, params.occlusion_probability)


def score_images(rendered: np.ndarray, observation: PreparedObservation) -> np.ndarray:
    """:func:`log_likelihoods` under the parameters the observation was prepared with."""
    return _score_rendered(rendered, observation, observation.uniform, observation.truncation,
                           observation.occluder_rate_per_m, observation.occlusion_probability)


def _score_rendered(rendered, observation: PreparedObservation, uniform: float,
                    truncation: float, lam: float, occlusion: float) -> np.ndarray:
    rendered = np.asarray(rendered)
    if rendered.ndim != 3 or rendered.shape[1:] != tuple(observation.shape):
        raise ValueError(f"rendered images have shape {rendered.shape}, expected "
                         f"(N, {observation.shape[0]}, {observation.shape[1]})")
    flat = rendered.reshape(rendered.shape[0], -1)
    if observation.num_valid == 0:
        return np.zeros(rendered.shape[0])
    return pick_kernel(_sum_serial, _sum_parallel)(
        flat, observation.pixel_index, observation.z, observation.sigma,
        observation.gauss_coeff, observation.occ_coeff, observation.log_p_occ_inf,
        uniform, lam, occlusion, truncation)
