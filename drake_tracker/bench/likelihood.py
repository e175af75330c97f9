"""The likelihood's part of ``drake-tracker bench``: one robot's image updates and stages.

For one robot, at the bench's image size and about 2000 likelihood evaluations per image
update (particles per block x blocks x annealing layers):

* ``updates_per_s``: whole CPF image updates per second, per numba thread count (wall
  clock; the counts take turns update by update, the quickest of each kept), and
  ``updates_per_cpu_s`` per second of this process's CPU time (summed over its
  threads): on a shared machine, the one-thread CPU figure is what an idle core gives;
* ``python_us_per_block``: the part of an update spent outside the compiled sweeps
  (scoring kernel and CPF block loop: :mod:`drake_tracker.core.cpf.compiled`), per
  block call;
* ``stage_us_per_evaluation``: ``fk``, ``raster``, ``likelihood``, ``score`` (what the
  filter runs: the three fused) and ``render`` (images written to memory), CPU time, one
  thread, on the configurations one image update scores (see :func:`_stages`);
* ``drake_us_per_image``: Drake's RenderEngineVtk on the same configurations (one
  ``RenderDepthImage`` each, scoring excluded), and its ratio to ``score``;
* agreement of the rendered images with Drake's (robot/background label, depth);
* ``triangles``: as read from SceneGraph, and as rendered (the level of detail).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numba
import numpy as np
from numba import njit

from drake_tracker.bench.renderers import best_wall_and_cpu_time
from drake_tracker.core.cpf.image_update import CpfImageUpdate
from drake_tracker.core.filter.kalman import initial_moments
from drake_tracker.core.likelihood.pixel_model import PreparedObservation
from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.render.configurations import (
    default_view_configuration,
    random_configurations,
)
from drake_tracker.core.render.fused_score import _score_serial
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.core.simd.lane_kinematics import lane_relative_poses
from drake_tracker.core.simd.lanes import LANES
from drake_tracker.params.resolve import camera_chain_joints, resolve_blocks
from drake_tracker.params.tracker_params import TrackerParams

if TYPE_CHECKING:
    from drake_tracker.robot.model import TrackerModel


def _test_image(renderer, q: np.ndarray) -> np.ndarray:
    """The robot at q in front of a wall at 2.5 m, 4 mm of noise (seeded)."""
    depth = renderer.render(q[None])[0].astype(np.float64)
    depth[~np.isfinite(depth)] = 2.5
    depth += np.random.default_rng(0).normal(0.0, 0.004, depth.shape)
    return depth.astype(np.float32)


def make_update(model: TrackerModel, camera: CameraIntrinsics, params: TrackerParams,
                evaluations: int = 2000) -> CpfImageUpdate:
    """The tracker's image update with particles per block set for ``evaluations``."""
    blocks = resolve_blocks(params, model.joint_names, camera_chain_joints(model))
    layers = len(params.image.annealing_betas)
    particles = int(np.ceil(evaluations / (len(blocks) * layers)))
    return CpfImageUpdate(model, camera, blocks, particles, params.image.likelihood,
                          params.image.image_width_px, params.image.max_kl,
                          annealing_betas=tuple(params.image.annealing_betas),
                          sweep_image_widths_px=tuple(params.image.sweep_image_widths_px))


def test_observation(update: CpfImageUpdate) -> PreparedObservation:
    """The update's prepared observation of the robot at its view configuration in front
    of a wall (rendered by the update's own renderer)."""
    image = _test_image(update.renderer, default_view_configuration(update.model))
    return update.prepare(_full_resolution(image, update.stride))


def tracking_prior(model: TrackerModel) -> np.ndarray:
    """A prior at the view configuration: 1 deg per joint, 5 mm / rad per virtual joint."""
    std = np.full(model.num_joints, np.radians(1.0))
    std[model.virtual_joint_indices] = 0.005
    return initial_moments(default_view_configuration(model), std, std,
                           np.ones(model.num_joints, bool))


def _timed_update(update: CpfImageUpdate, observation: PreparedObservation,
                  prior: np.ndarray, rng: np.random.Generator) -> tuple[float, float, float]:
    """One image update: (wall s, CPU s, s in the scoring kernel)."""
    before = update.times.render_s
    c0 = time.process_time()
    t0 = time.perf_counter()
    update(prior, observation, rng)
    return (time.perf_counter() - t0, time.process_time() - c0,
            update.times.render_s - before)


def _best(update: CpfImageUpdate, timed: list[tuple[float, float, float]]) -> dict:
    """The figures of :func:`time_updates` from its timed updates (the quickest one's)."""
    total, _, kernel = min(timed)
    calls = len(update.blocks) * len(update.annealing_betas)
    return {"updates_per_s": 1.0 / total, "seconds": total,
            "updates_per_cpu_s": 1.0 / min(cpu for _, cpu, _ in timed),
            "python_us_per_block": 1e6 * (total - kernel) / calls,
            "kernel_ms": 1e3 * kernel}


def time_updates(update: CpfImageUpdate, observation: PreparedObservation,
                 prior: np.ndarray, repeats: int) -> dict:
    """Best of ``repeats`` image updates: updates/s, and the time outside the kernel."""
    rng = np.random.default_rng(0)
    update(prior, observation, rng)  # warm-up (and compile)
    return _best(update, [_timed_update(update, observation, prior, rng)
                          for _ in range(max(1, repeats))])


def time_updates_by_threads(update: CpfImageUpdate, observation: PreparedObservation,
                            prior: np.ndarray, repeats: int,
                            threads: tuple[int, ...]) -> dict[str, dict]:
    """:func:`time_updates` for each numba thread count, the counts taking turns update
    by update (so that a change of the shared machine's speed hits all of them alike,
    and their ratio means what it says)."""
    rng = np.random.default_rng(0)
    timed: dict[int, list] = {t: [] for t in threads}
    for t in threads:  # warm-up (and compile) each
        numba.set_num_threads(min(t, numba.config.NUMBA_NUM_THREADS))
        update(prior, observation, rng)
    for _ in range(max(1, repeats)):
        for t in threads:
            numba.set_num_threads(min(t, numba.config.NUMBA_NUM_THREADS))
            timed[t].append(_timed_update(update, observation, prior, rng))
    return {str(t): _best(update, timed[t]) for t in threads}


def kernel_us_per_evaluation_in_turns(models: dict[str, TrackerModel],
                                      camera: CameraIntrinsics, params: TrackerParams,
                                      repeats: int) -> dict[str, float]:
    """µs in the scoring kernel per likelihood evaluation of each model's image update
    (1 thread, the least of ``repeats``), the models taking turns update by update, so
    that a ratio of two is not this shared machine's drift between two blocks of timing
    (the CAD ÷ bench ratio moved from 1.24 to 2.09 between separately timed runs)."""
    cases = {}
    for name, model in models.items():
        update = make_update(model, camera, params)
        cases[name] = (update, test_observation(update), tracking_prior(model))
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        rng = np.random.default_rng(0)
        for update, observation, prior in cases.values():
            update(prior, observation, rng)  # warm-up (and compile)
        kernel_s = {name: [] for name in cases}
        for _ in range(max(1, repeats)):
            for name, (update, observation, prior) in cases.items():
                kernel_s[name].append(_timed_update(update, observation, prior, rng)[2])
    finally:
        numba.set_num_threads(previous)
    return {name: 1e6 * min(kernel_s[name]) / cases[name][0].evaluations_per_image
            for name in cases}


def bench_robot(model: TrackerModel, camera: CameraIntrinsics, params: TrackerParams,
                repeats: int = 5, num_drake: int = 30, threads: tuple[int, ...] = (1, 2)) -> dict:
    """The figures of the module docstring for one robot (``camera``: full resolution)."""
    update = make_update(model, camera, params)
    renderer = update.renderer
    observation = test_observation(update)
    prior = tracking_prior(model)
    previous = numba.get_num_threads()
    try:
        per_threads = time_updates_by_threads(update, observation, prior, 2 * repeats,
                                              threads)
        numba.set_num_threads(1)
        stages = _stages(update, observation, prior, repeats)
    finally:
        numba.set_num_threads(previous)
    drake = _against_drake(model, renderer, num_drake)
    return {
        "evaluations": update.evaluations_per_image,
        "particles_per_block": update.num_particles,
        "block_calls_per_update": len(update.blocks) * len(update.annealing_betas),
        "threads": per_threads,
        "stage_us_per_evaluation": stages,
        "drake_us_per_image": drake["us_per_image"],
        "drake_over_score": drake["us_per_image"] / stages["score"],
        "drake_over_render": drake["us_per_image"] / stages["render"],
        "label_agreement_vs_drake": drake["label_agreement"],
        "depth_median_mm_vs_drake": drake["depth_median_mm"],
        "depth_p95_mm_vs_drake": drake["depth_p95_mm"],
        "triangles_source": renderer.source_meshes.num_triangles,
        "triangles_rendered": renderer.num_triangles,
        "level_of_detail": _detail_summary(renderer),
    }


def _detail_summary(renderer) -> dict | None:
    """The measured level of detail's calibration figures and per-body choices (None:
    the meshes are rendered at one cell, or as they are)."""
    measured = getattr(renderer, "measured_detail", None)
    if measured is None:
        return None
    return {"calibration_agreement": measured.agreement,
            "calibration_robot_px": measured.robot_px,
            "bodies": [{"body": int(o.body), "cell_px": o.cell_px, "culled": o.culled,
                        "triangles": o.triangles} for o in measured.options]}


def _full_resolution(image: np.ndarray, stride: int) -> np.ndarray:
    """An image that subsamples (every ``stride``-th pixel) back to ``image``."""
    return np.repeat(np.repeat(image, stride, axis=0), stride, axis=1)


class _Recorder:
    """A renderer stand-in that records the configurations the CPF scores (the Python
    sweeps: the same particles as the compiled ones, which cannot be watched)."""

    def __init__(self, renderer):
        self.renderer, self.calls = renderer, []

    def score(self, q, observation):
        self.calls.append(np.array(q))
        return self.renderer.score(q, observation)


def cpf_configurations(update: CpfImageUpdate, observation: PreparedObservation,
                       prior: np.ndarray) -> list[np.ndarray]:
    """The configurations one image update scores, block call by block call (particles
    of a CPF block are alike, which the batched kernel exploits: random configurations
    would misstate its cost)."""
    renderer = update.renderer
    update.renderer = recorder = _Recorder(renderer)
    try:
        update(prior, observation, np.random.default_rng(0))
    finally:
        update.renderer = renderer
    return recorder.calls


@njit(cache=True)
def _replay_scores(chunks, head, tail, out):
    """The scoring kernel on each chunk of configurations, as the compiled sweeps call
    it (from numba: no Python dispatch per call)."""
    for q in chunks:
        _score_serial(q, *head, 1, *tail, out[:q.shape[0]])


@njit(cache=True)
def _replay_kinematics(chunks, frame_tables, world, poses, work):
    """The scoring kernel's forward kinematics alone on each chunk, LANES at a time."""
    for q in chunks:
        for first in range(0, q.shape[0], LANES):
            lane_relative_poses(q, first, min(LANES, q.shape[0] - first), *frame_tables,
                                world, poses, work)


def _stages(update: CpfImageUpdate, observation: PreparedObservation, prior: np.ndarray,
            repeats: int) -> dict:
    """µs per evaluation of each stage, on the configurations one image update scores
    (block call by block call, called from numba as the compiled sweeps do), 1 thread,
    CPU time: ``fk`` (the kernel's forward kinematics alone), ``raster`` (the kernel
    against an image with a single valid pixel, away from the robot: FK, culling,
    rasterising and the pixel scan, minus ``fk``), ``likelihood`` (``score`` minus that),
    ``score`` (the kernel as the filter runs it), and ``render`` (the scalar rasteriser's
    images written to memory, FK excluded)."""
    from numba.typed import List

    from drake_tracker.core.cpf.compiled import CompiledLikelihood
    from drake_tracker.core.likelihood.pixel_model import prepare_observation

    renderer = update.renderer
    configurations = cpf_configurations(update, observation, prior)
    chunks = List(np.ascontiguousarray(c) for c in configurations)
    evaluations = sum(len(c) for c in configurations)
    one_pixel = np.full(observation.shape, np.nan, dtype=np.float32)
    one_pixel[0, 0] = 1.0
    nearly_empty = prepare_observation(one_pixel, update.likelihood)
    out = np.zeros(max(len(c) for c in configurations))
    nb = renderer.kinematics.num_bodies
    world, poses, work = np.zeros(nb * 12 * LANES), np.zeros((nb, 12, LANES)), np.zeros(
        3 * 12 * LANES)

    def kernel(o):
        head, tail = CompiledLikelihood(renderer, o).kernel_arguments(len(out))
        return lambda: _replay_scores(chunks, head, tail, out)

    frame = renderer.model.camera_frame
    camera_poses = [renderer.kinematics.relative_poses(c, frame) for c in configurations]
    runs = [lambda: _replay_kinematics(chunks, renderer._frame_tables, world, poses, work),
            kernel(nearly_empty), kernel(observation),
            lambda: [renderer.render_camera_poses(p) for p in camera_poses]]
    for fn in runs:
        fn()
    # The stages in turn, round after round, each the least of its rounds: the
    # differences below then compare runs made under the same load (timed one stage
    # after the other, a load change between them gave raster > score on the CAD robot).
    best = np.full(len(runs), np.inf)
    for _ in range(max(1, 2 * repeats)):
        for i, fn in enumerate(runs):
            best[i] = min(best[i], best_wall_and_cpu_time(fn, 1)[1])
    fk, fk_raster, score, render = (float(b) * 1e6 / evaluations for b in best)
    return {"fk": fk, "raster": max(0.0, fk_raster - fk),
            "likelihood": max(0.0, score - fk_raster), "score": score, "render": render}


def _against_drake(model, renderer, num: int) -> dict:
    """Drake's RenderEngineVtk per image on ``num`` configurations, and the agreement of
    the two renderings (robot/background label, depth on shared robot pixels)."""
    q = random_configurations(model, max(1, num), seed=3,
                              center=default_view_configuration(model))
    drake = make_renderer(model, renderer.intrinsics, "drake", renderer.near_m, renderer.far_m)
    drake.render(q[:1])  # create the render window
    t0 = time.perf_counter()
    ref = drake.render(q)
    us = 1e6 * (time.perf_counter() - t0) / len(q)
    ours = renderer.render(q)
    hit_ours, hit_ref = np.isfinite(ours), np.isfinite(ref)
    both = hit_ours & hit_ref
    diff = 1e3 * np.abs(ours[both].astype(float) - ref[both].astype(float))
    return {"us_per_image": us,
            "label_agreement": float(1.0 - (hit_ours ^ hit_ref).sum()
                                     / max(1, (hit_ours | hit_ref).sum())),
            "depth_median_mm": float(np.median(diff)) if diff.size else 0.0,
            "depth_p95_mm": float(np.percentile(diff, 95)) if diff.size else 0.0}
