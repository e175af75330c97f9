"""The renderers against each other: the batched rasteriser and Drake's
RenderEngineVtk on the same configurations (speed, agreement), and the fused scoring."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numba
import numpy as np

from drake_tracker.core.likelihood.pixel_model import (
    LikelihoodParams,
    log_likelihoods,
    prepare_observation,
)
from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.render.configurations import (
    default_view_configuration,
    random_configurations,
    synthetic_observation,
)

if TYPE_CHECKING:
    from drake_tracker.core.sensors.camera import CameraIntrinsics
    from drake_tracker.robot.model import TrackerModel


def best_wall_and_cpu_time(fn: Callable[[], object], repeats: int) -> tuple[float, float]:
    """(wall, cpu) seconds of ``fn()``, each the least of ``repeats`` runs (the least
    disturbed by other processes on the machine); cpu is this process's CPU time summed
    over its threads."""
    wall = cpu = np.inf
    for _ in range(max(1, repeats)):
        c0 = time.process_time()
        t0 = time.perf_counter()
        fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return float(wall), float(cpu)


def benchmark_renderers(model: TrackerModel, intrinsics: CameraIntrinsics,
                        num_particles: int = 2000, seed: int = 0, num_drake: int | None = None,
                        near_m: float = 0.1, far_m: float = 6.0, repeats: int = 3,
                        tracking_spread_rad: float = 0.05,
                        likelihood: LikelihoodParams | None = None) -> dict:
    """Renders the same random configurations with both backends in this process.

    The batched backend renders all ``num_particles`` in one call (after a warm-up that
    compiles the numba kernels), FK included; Drake renders the first ``num_drake`` of
    them (default min(num_particles, 100)) one call each. The batched timings are the
    best of ``repeats`` runs. Per-image times are in microseconds.

    Also timed: ``fused_us_per_evaluation``, one image update's likelihood evaluation
    (FK + render + pixel likelihood, ``BatchedDepthRenderer.score``) per
    particle, for ``num_particles`` particles spread by ``tracking_spread_rad`` around
    the view configuration, scored against a synthetic noisy image of that
    configuration (``likelihood``: a ``LikelihoodParams``, default its defaults); and
    ``separate_us_per_evaluation``, the same with ``render`` then ``log_likelihoods``.
    The ``*_cpu_us_*`` figures are CPU time summed over threads: with T threads and an
    otherwise idle machine, wall time is about cpu / T; unlike wall time they are hardly
    affected by other processes competing for the cores.
    """
    if num_particles < 1:
        raise ValueError(f"num_particles must be >= 1, got {num_particles}")
    num_drake = min(num_particles, 100) if num_drake is None else min(num_drake, num_particles)
    center = default_view_configuration(model)
    q = random_configurations(model, num_particles, seed, center=center)
    batched = make_renderer(model, intrinsics, "batched", near_m, far_m)
    drake = make_renderer(model, intrinsics, "drake", near_m, far_m)
    batched.render(q[:2])  # compile / load the cached kernel
    drake.render(q[:1])  # create the render window
    images_b = batched.render(q)
    t_batched, cpu_batched = best_wall_and_cpu_time(lambda: batched.render(q), repeats)
    t0 = time.perf_counter()
    images_d = drake.render(q[:num_drake])
    t_drake = time.perf_counter() - t0
    us_b = 1e6 * t_batched / num_particles
    us_d = 1e6 * t_drake / num_drake
    hit_b = np.isfinite(images_b[:num_drake])
    hit_d = np.isfinite(images_d)
    either = hit_b | hit_d

    params = LikelihoodParams() if likelihood is None else likelihood
    observation = prepare_observation(synthetic_observation(batched, center, seed), params)
    q_track = random_configurations(model, num_particles, seed + 1,
                                    spread_rad=tracking_spread_rad, center=center)
    batched.score(q_track[:2], observation)  # compile / load
    log_likelihoods(images_b[:2], observation, params)
    t_fused, cpu_fused = best_wall_and_cpu_time(
        lambda: batched.score(q_track, observation), repeats)
    t_separate, _ = best_wall_and_cpu_time(
        lambda: log_likelihoods(batched.render(q_track), observation, params), repeats)
    return {
        "width": intrinsics.width,
        "height": intrinsics.height,
        "num_particles": num_particles,
        "num_drake_particles": num_drake,
        "num_triangles": batched.num_triangles,
        "batched_us_per_image": us_b,
        "drake_us_per_image": us_d,
        "renderer_speedup_vs_drake": us_d / us_b,
        "hit_mismatch_fraction": float((hit_b ^ hit_d).sum() / max(1, either.sum())),
        "coverage_fraction": float(hit_b.mean()),
        "batched_cpu_us_per_image": 1e6 * cpu_batched / num_particles,
        "fused_us_per_evaluation": 1e6 * t_fused / num_particles,
        "fused_cpu_us_per_evaluation": 1e6 * cpu_fused / num_particles,
        "separate_us_per_evaluation": 1e6 * t_separate / num_particles,
        "numba_threads": _numba_threads(),
    }


def _numba_threads() -> int:
    return int(numba.get_num_threads())
