"""``drake-tracker bench``: throughput of the tracker's hot paths on this machine.

All figures come from one process and one run, so ratios (batched renderer vs Drake's
RenderEngine) compare the same frames under the same load. Timings are medians over
repetitions after a warm-up (numba compilation excluded).

Keys of ``bench.json``:

* ``image_updates_per_s_2000``: full CPF image updates per second at 2000 likelihood
  evaluations per image (particles x blocks, as dbrt counts ``sample_count``, times the
  annealing layers), 80x60, Apollo's 7 arm + 2 head joints + 6 virtual joints (15
  blocks);
* ``image_updates_per_s_default``: the same with the default parameters;
* ``stage_ms_2000``: per image update at 2000 evaluations: ``fk``, ``render`` and
  ``likelihood`` measured as separate passes, ``fused`` (what the filter runs: the three
  in one kernel), ``resampling`` and ``filter_other`` (the rest of the CPF);
* ``renderer_speedup_vs_drake``: Drake RenderEngineVtk per image / batched per image;
* ``kf_step_us``: one predict+update of the whole bank (15 joints);
* ``replay_us_per_reading``: re-filtering one buffered reading after a delayed image.
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import numpy as np

from drake_tracker.core.belief_buffer import AngleObservation, BeliefBuffer
from drake_tracker.core.camera import CameraIntrinsics
from drake_tracker.core.cpf import normalized_weights, systematic_resample
from drake_tracker.core.image_update import CpfImageUpdate
from drake_tracker.core.kalman import VAR_A, JointKalmanBank, initial_moments
from drake_tracker.core.likelihood import log_likelihoods
from drake_tracker.core.renderer import benchmark_renderers, default_view_configuration
from drake_tracker.params import TrackerParams, resolve_blocks, resolve_kalman_params
from drake_tracker.robot import build_tracker_model, robot_preset
from drake_tracker.tracker import camera_chain_joints


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def _test_image(model, camera: CameraIntrinsics) -> np.ndarray:
    from drake_tracker.core.renderer import make_renderer

    image = make_renderer(model, camera, "batched").render(
        default_view_configuration(model)[None])[0]
    return np.where(np.isfinite(image), image, 2.5).astype(np.float32)


def bench_image_update(model, camera: CameraIntrinsics, params: TrackerParams,
                       num_particles: int, repeats: int) -> dict:
    """Times whole CPF image updates with ``num_particles`` per block."""
    blocks = resolve_blocks(params, model.joint_names, camera_chain_joints(model))
    update = CpfImageUpdate(model, camera, blocks, num_particles, params.image.likelihood,
                            params.image.image_width_px, params.image.max_kl,
                            annealing_betas=tuple(params.image.annealing_betas))
    observation = update.prepare(_test_image(model, camera))
    std = np.full(model.num_joints, np.radians(1.0))
    std[model.virtual_joint_indices] = 0.005
    prior = initial_moments(default_view_configuration(model), std, std,
                            np.ones(model.num_joints, bool))
    rng = np.random.default_rng(0)
    update(prior, observation, rng)  # warm-up
    seconds = _median_time(lambda: update(prior, observation, rng), repeats)
    return {"evaluations": update.evaluations_per_image, "seconds": seconds,
            "updates_per_s": 1.0 / seconds, "update": update, "observation": observation}


def bench_stages(update: CpfImageUpdate, observation, repeats: int) -> dict:
    """Per-image-update stage times (ms) for the update's evaluation count."""
    model = update.model
    n_eval = update.evaluations_per_image
    rng = np.random.default_rng(1)
    q = default_view_configuration(model) + rng.normal(0, 0.01, (n_eval, model.num_joints))
    renderer = update.renderer
    kinematics = getattr(renderer, "kinematics", None)
    out = {}
    if kinematics is not None:
        out["fk"] = 1e3 * _median_time(lambda: kinematics.body_poses(q), repeats)
    rendered = renderer.render(q)
    out["render"] = 1e3 * _median_time(lambda: renderer.render(q), repeats)
    log_likelihoods(rendered, observation, update.likelihood)
    out["likelihood"] = 1e3 * _median_time(
        lambda: log_likelihoods(rendered, observation, update.likelihood), repeats)
    out["fused"] = 1e3 * _median_time(
        lambda: update.log_likelihood(q, observation), repeats)
    weights = normalized_weights(rng.normal(0, 5, update.num_particles))
    per_block = _median_time(lambda: systematic_resample(weights, rng), 20 * repeats)
    out["resampling"] = 1e3 * per_block * len(update.blocks) * len(update.annealing_betas)
    return out


def bench_kalman(model, params: TrackerParams, repeats: int = 20000) -> dict:
    bank = JointKalmanBank(resolve_kalman_params(params, model.joint_names))
    belief = initial_moments(np.zeros(model.num_joints), np.full(model.num_joints, 0.1),
                             np.full(model.num_joints, 0.1), np.ones(model.num_joints, bool))
    reading = np.zeros(model.num_joints)
    bank.step(belief, 0.001, reading)
    t0 = time.perf_counter()
    for _ in range(repeats):
        belief = bank.step(belief, 0.001, reading)
    kf_step_us = 1e6 * (time.perf_counter() - t0) / repeats
    # Replay: 1000 readings (1 s at 1 kHz) buffered, an image inserted 100 ms back.
    start = initial_moments(np.zeros(model.num_joints), np.full(model.num_joints, 0.1),
                            np.full(model.num_joints, 0.1), np.ones(model.num_joints, bool))
    buffer = BeliefBuffer(bank, start, 0.0, horizon_s=2.0)
    for k in range(1, 1001):
        buffer.add_reading(0.001 * k, reading)
    observation = AngleObservation(np.full(model.num_joints, 1e4),
                                   np.full(model.num_joints, 1.0))
    t0 = time.perf_counter()
    images = 20
    for i in range(images):
        buffer.add_observation(0.9 + 0.001 * i + 0.0005, observation)
    replayed = sum(1000 - (900 + i) for i in range(images))
    replay_us = 1e6 * (time.perf_counter() - t0) / replayed
    return {"kf_step_us": kf_step_us, "replay_us_per_reading": replay_us,
            "bank_variance_check": float(buffer.present()[1][VAR_A].max())}


def run_benchmarks(quick: bool = False) -> dict:
    model = build_tracker_model(robot_preset("apollo"))
    camera = CameraIntrinsics.from_fov(640, 480, np.radians(45.0))
    params = TrackerParams()
    repeats = 3 if quick else 7
    num_blocks = len(resolve_blocks(params, model.joint_names, camera_chain_joints(model)))
    layers = len(params.image.annealing_betas)
    particles_2000 = int(np.ceil(2000 / (num_blocks * layers)))
    at_2000 = bench_image_update(model, camera, params, particles_2000, repeats)
    default = bench_image_update(model, camera, params, params.image.num_particles, repeats)
    stages = bench_stages(at_2000["update"], at_2000["observation"], repeats)
    stages["filter_other"] = max(
        0.0, 1e3 * at_2000["seconds"] - stages["fused"] - stages["resampling"])
    small = camera.subsampled(at_2000["update"].stride)
    renderers = benchmark_renderers(model, small, num_particles=2000, seed=0,
                                    num_drake=30 if quick else 100)
    kalman = bench_kalman(model, params)
    return {
        "machine": {"processor": platform.processor() or platform.machine(),
                    "python": platform.python_version()},
        "image_size": [small.width, small.height],
        "num_joints": model.num_joints,
        "num_blocks": num_blocks,
        "annealing_layers": layers,
        "image_updates_per_s_2000": at_2000["updates_per_s"],
        "evaluations_2000": at_2000["evaluations"],
        "image_updates_per_s_default": default["updates_per_s"],
        "evaluations_default": default["evaluations"],
        "stage_ms_2000": stages,
        "renderer_speedup_vs_drake": renderers["renderer_speedup_vs_drake"],
        "batched_us_per_image": renderers["batched_us_per_image"],
        "drake_us_per_image": renderers["drake_us_per_image"],
        "kf_step_us": kalman["kf_step_us"],
        "replay_us_per_reading": kalman["replay_us_per_reading"],
    }


def format_bench(result: dict) -> str:
    lines = [
        f"image size {result['image_size'][0]}x{result['image_size'][1]}, "
        f"{result['num_joints']} joints, {result['num_blocks']} blocks",
        f"image updates/s at {result['evaluations_2000']} evaluations: "
        f"{result['image_updates_per_s_2000']:.2f}   (target >= 10)",
        f"image updates/s, defaults ({result['evaluations_default']} evaluations): "
        f"{result['image_updates_per_s_default']:.2f}",
        "stage ms per update at 2000 evaluations: " + ", ".join(
            f"{k} {v:.1f}" for k, v in result["stage_ms_2000"].items()),
        f"renderer: batched {result['batched_us_per_image']:.1f} us/image, Drake "
        f"{result['drake_us_per_image']:.0f} us/image, speedup "
        f"{result['renderer_speedup_vs_drake']:.1f}x   (target >= 50)",
        f"Kalman bank step: {result['kf_step_us']:.2f} us   (target <= 20)",
        f"replay: {result['replay_us_per_reading']:.2f} us per re-filtered reading",
    ]
    return "\n".join(lines)


def run_bench(args) -> int:
    result = run_benchmarks(quick=getattr(args, "quick", False))
    print(format_bench(result))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {out / 'bench.json'}")
    return 0
