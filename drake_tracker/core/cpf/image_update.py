"""One depth image's update of the joint angles: render, score, Coordinate Particle Filter.

:class:`CpfImageUpdate` is built once per model and camera: it fixes the processing
resolution (plain subsampling to about ``image_width_px``, docs/method.md §4), the renderer backend
and the CPF blocks. Each call takes the prior belief at the image's time and a depth
image, and returns the moment-matched angle marginals (eqs. 13-15); the Kalman bank's
recombination with p(b | a) (eq. 16) happens in the belief buffer.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.cpf.compiled import CompiledLikelihood, compiled_sweep
from drake_tracker.core.cpf.particle_filter import CPFResult, annealed_coordinate_particle_filter
from drake_tracker.core.filter.kalman import MEAN_A, VAR_A
from drake_tracker.core.likelihood.pixel_model import (
    LikelihoodParams,
    PreparedObservation,
    coarser_observation,
    prepare_observation,
    widened_observation,
)
from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.render.batched import BatchedDepthRenderer
from drake_tracker.core.sensors.camera import CameraIntrinsics, stride_for_width, subsample

if TYPE_CHECKING:
    from collections.abc import Callable

    from drake_tracker.core.render.backends import RenderThenScore
    from drake_tracker.robot.model import TrackerModel

log = logging.getLogger(__name__)

#: How many per-update wall times ``StageTimes`` keeps.
RECENT_UPDATES = 10_000


@dataclass
class StageTimes:
    """Wall time spent per stage of image updates (s), accumulated."""

    render_s: float = 0.0
    likelihood_s: float = 0.0
    filter_s: float = 0.0
    evaluations: int = 0
    updates: int = 0
    #: Wall time of each of the latest ``RECENT_UPDATES`` updates (s): bounded, so a
    #: tracker that runs for hours does not grow (issue 14, finding 10).
    per_update: deque[float] = field(
        default_factory=lambda: deque(maxlen=RECENT_UPDATES))


def check_depth_image(depth: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Raises ValueError unless ``depth`` is a floating (H, W) image matching ``intrinsics``."""
    depth = np.asarray(depth)
    if depth.size == 0:
        raise ValueError("depth image is empty")
    if not np.issubdtype(depth.dtype, np.floating):
        raise ValueError(f"depth image must be floating point metres, got dtype {depth.dtype}")
    expected = (intrinsics.height, intrinsics.width)
    if depth.shape != expected:
        raise ValueError(f"depth image has shape {depth.shape}, expected {expected} "
                         f"(height, width) from the camera intrinsics")
    return depth


class CpfImageUpdate:
    """The image update for one model and camera.

    Args:
        model: the tracker's ``TrackerModel`` (robot + virtual camera joints).
        camera: intrinsics of the images that will be passed in (full resolution).
        blocks: CPF blocks, index arrays into ``model.joint_names``.
        num_particles: particles per block.
        likelihood: the pixel model's parameters.
        image_width_px: images are subsampled to about this width.
        max_kl: resampling threshold (nats).
        renderer: ``batched`` or ``drake``.
        annealing_betas: likelihood exponents of successive CPF sweeps, ending at 1
            (``(1,)``: the paper's single sweep); see
            :func:`~drake_tracker.core.cpf.particle_filter.annealed_coordinate_particle_filter`.
        sweep_image_widths_px: per annealing sweep (empty: all at ``image_width_px``),
            the width (px) its image is subsampled to, a whole multiple of the stride
            coarser; a coarser sweep's log-likelihoods are scaled by the ratio of valid
            pixels. The last sweep (beta = 1) must score the ``image_width_px`` image.
    """

    def __init__(self, model: TrackerModel, camera: CameraIntrinsics, blocks: list[np.ndarray],
                 num_particles: int, likelihood: LikelihoodParams, image_width_px: int = 80,
                 max_kl: float = 2.0, renderer: str = "batched", near_m: float = 0.1,
                 far_m: float = 6.0, annealing_betas: tuple[float, ...] = (1.0,),
                 sweep_image_widths_px: tuple[int, ...] = (),
                 search_depth_widening_m: float = 0.0) -> None:
        likelihood.validate()
        if num_particles < 1:
            raise ValueError(f"num_particles must be >= 1, got {num_particles}")
        n = model.num_joints
        for block in blocks:
            if len(block) == 0 or np.min(block) < 0 or np.max(block) >= n:
                raise ValueError(f"CPF block {list(block)} is empty or out of range 0..{n - 1}")
        self.model = model
        self.camera = camera
        self.stride = stride_for_width(camera.width, image_width_px)
        if image_width_px > camera.width:
            # Images are only ever subsampled: a camera narrower than the width asked for
            # is tracked at its own (a recording stores the images at its working size).
            log.warning("image.image_width_px = %d is wider than the camera's %d x %d "
                        "images: tracking at %d px", image_width_px, camera.width,
                        camera.height, camera.width)
        self.intrinsics = camera.subsampled(self.stride)
        self.blocks = [np.asarray(b, int) for b in blocks]
        self.num_particles = int(num_particles)
        self.likelihood = likelihood
        self.max_kl = float(max_kl)
        self.annealing_betas = tuple(float(b) for b in annealing_betas)
        self.renderer = make_renderer(model, self.intrinsics, renderer, near_m, far_m)
        widths = tuple(sweep_image_widths_px) or (image_width_px,) * len(annealing_betas)
        if len(widths) != len(self.annealing_betas) or min(widths) < 1:
            raise ValueError(f"sweep_image_widths_px {list(widths)}: one width >= 1 per "
                             f"annealing sweep ({len(self.annealing_betas)})")
        #: Per sweep, how many times coarser than the update's image it scores.
        self.sweep_factors = tuple(
            max(1, round(stride_for_width(camera.width, w) / self.stride)) for w in widths)
        if self.sweep_factors[-1] != 1:
            raise ValueError(f"sweep_image_widths_px {list(widths)}: the last sweep must "
                             f"score the {self.intrinsics.width} px image")
        self.sweep_renderers = {f: make_renderer(model, camera.subsampled(self.stride * f),
                                                 renderer, near_m, far_m)
                                for f in set(self.sweep_factors) if f > 1}
        self.sweep_renderers[1] = self.renderer
        if not (np.isfinite(search_depth_widening_m) and search_depth_widening_m >= 0):
            raise ValueError(f"search_depth_widening_m must be finite and >= 0, got "
                             f"{search_depth_widening_m}")
        #: Per sweep of the start-up search, the depth σ added to every pixel's (m):
        #: ``search_depth_widening_m`` (1 - β).
        self.search_widening_m = tuple(float(search_depth_widening_m) * (1.0 - b)
                                       for b in self.annealing_betas)
        self.times = StageTimes()

    @property
    def evaluations_per_image(self) -> int:
        """Likelihood evaluations per image update: particles x blocks x annealing sweeps."""
        return self.num_particles * len(self.blocks) * len(self.annealing_betas)

    def prepare(self, depth: np.ndarray) -> PreparedObservation:
        """Checks a full-resolution depth image, subsamples it and precomputes its pixels."""
        depth = check_depth_image(depth, self.camera)
        return prepare_observation(subsample(depth, self.stride), self.likelihood)

    def log_likelihood(self, q: np.ndarray, observation: PreparedObservation,
                       renderer: BatchedDepthRenderer | RenderThenScore | None = None
                       ) -> np.ndarray:
        """(N,) log-likelihoods of configurations q (N, n) for one observation (prepared
        at the size ``renderer`` renders, by default ``self.renderer``)."""
        t0 = time.perf_counter()
        renderer = renderer or self.renderer
        out = renderer.score(q, observation)  # FK + render + pixel likelihood
        self._count_evaluations(time.perf_counter() - t0, len(q))
        return out

    def _count_evaluations(self, seconds: float, count: int) -> None:
        self.times.render_s += seconds
        self.times.evaluations += count

    def _likelihood(self, observation: PreparedObservation,
                    renderer: BatchedDepthRenderer | RenderThenScore,
                    scale: float | None = None) -> Callable[[np.ndarray], np.ndarray]:
        """The log-likelihood of configurations for ``observation`` (times ``scale``): a
        :class:`CompiledLikelihood`, whose CPF sweeps run in numba, for the batched
        renderer; a Python function for any other."""
        factors = () if scale is None else (scale,)
        if isinstance(renderer, BatchedDepthRenderer):
            return CompiledLikelihood(renderer, observation, factors, self._count_evaluations)

        def scored(q):
            out = self.log_likelihood(q, observation, renderer)
            return out if scale is None else scale * out

        return scored

    def __call__(self, prior: np.ndarray, observation: PreparedObservation,
                 rng: np.random.Generator, jump_probability: np.ndarray | None = None,
                 jump_std: np.ndarray | None = None, num_particles: int | None = None,
                 coarse_sweeps: bool = True, widened: bool = False,
                 blocks: list[np.ndarray] | None = None) -> CPFResult | None:
        """Angle marginals after the image, or None for an image with no valid pixel.

        ``jump_probability``/``jump_std`` (n,) let the prior of each angle admit a jump
        (a bias step since the previous image; see ``core/cpf/particle_filter.py``);
        ``num_particles``
        overrides the particles per block for this image; ``coarse_sweeps`` False scores
        every sweep at full resolution (the tracker's start-up search); ``widened`` scores
        them widened by ``search_widening_m`` (the search for an arm never held yet);
        ``blocks`` searches those of the blocks only (the others keep their prior)."""
        if observation.num_valid == 0:
            return None
        t0 = time.perf_counter()
        eval_before = self.times.render_s + self.times.likelihood_s
        result = annealed_coordinate_particle_filter(
            prior[MEAN_A], np.sqrt(np.maximum(prior[VAR_A], 0.0)),
            self.blocks if blocks is None else blocks,
            num_particles or self.num_particles, self._likelihood(observation, self.renderer),
            rng, self.max_kl, self.annealing_betas, jump_probability=jump_probability,
            jump_std=jump_std,
            sweep_log_likelihoods=(self._search_scores(observation) if widened else
                                   self._sweep_scores(observation) if coarse_sweeps else ()),
            sweep=compiled_sweep)
        total = time.perf_counter() - t0
        self.times.filter_s += total - (self.times.render_s + self.times.likelihood_s
                                        - eval_before)
        self.times.updates += 1
        self.times.per_update.append(total)
        return result

    def _search_scores(self, observation: PreparedObservation) -> list:
        """Per sweep of the start-up search, its likelihood on ``observation`` widened by
        ``search_widening_m`` (None: the observation as it is)."""
        return [None if extra == 0 else
                self._likelihood(widened_observation(observation, extra), self.renderer)
                for extra in self.search_widening_m]

    def _sweep_scores(self, observation: PreparedObservation) -> list:
        """Per sweep, the log-likelihood of its coarser image scaled to the valid pixels
        of ``observation``, or None where it scores ``observation`` itself."""
        scores = []
        coarse_by_factor = {}
        for factor in self.sweep_factors:
            if factor not in coarse_by_factor:
                coarse = coarser_observation(observation, factor)
                coarse_by_factor[factor] = coarse if coarse.num_valid else None
            coarse = coarse_by_factor[factor]
            if factor == 1 or coarse is None:
                scores.append(None)
                continue
            scale = observation.num_valid / coarse.num_valid
            scores.append(self._likelihood(coarse, self.sweep_renderers[factor], scale))
        return scores
