"""``drake-tracker bench``: throughput of the tracker's hot paths on this machine.

All figures come from one process and one run, so ratios (CAD robot vs bench robot,
batched vs Drake's RenderEngineVtk) compare the same frames under the same load. Times
are the least of several repetitions after a warm-up (numba compilation excluded).

Keys of ``bench.json``:

* ``machine``: the processor, the CPU numba compiles for (``llvm_cpu``, ``avx512f``),
  Python, numba's threading layer;
* ``robots``: per robot, the bench robot ``apollo`` (Drake primitives) and ``apollo_cad``
  (the same robot with CAD-like OBJ meshes, 54,720 triangles, generated on the fly), the
  figures of :mod:`drake_tracker.bench.likelihood`: image updates/s at about 2000
  evaluations with 1 and 2 numba threads, µs per evaluation by stage, the CPF's Python
  time per block call, Drake RenderEngineVtk's time per image and its ratios, agreement
  with it, triangle counts, and ``level_of_detail`` (the measured level of detail's
  agreement on its calibration images and each body's cell; None where nothing is
  simplified);
* ``image_updates_per_s_2000_1_thread`` / ``..._2_threads``: the bench robot's;
* ``cad_over_bench_cost_per_evaluation``: the scoring kernel's time per evaluation, CAD
  robot / bench robot, the two robots' updates taking turns (``kernel_us_per_evaluation``
  has both); ``cad_over_bench_stage_score``: the same from the stage figures, timed
  robot after robot;
* ``image_updates_per_s_default``: the bench robot with the default parameters;
* ``image_updates_per_s_coarse_sweeps``: the same with ``image.sweep_image_widths_px``
  set to ``COARSE_SWEEP_WIDTHS_PX`` (the three tempered sweeps on a 2x coarser image:
  faster, less robust; see the README);
* ``kf_step_us``: one predict+update of the whole bank (15 joints);
* ``replay_us_per_reading``: re-filtering one buffered reading after a delayed image;
* ``demo``: the demo's real-time factor (simulated seconds per wall-clock second) on the
  first ``duration_s`` of its default scenario, with its Diagram as ``drake-tracker
  demo`` builds it (tracker, Meshcat views and recording, the camera rendering what the
  tracker reads): ``real_time_factor`` over the whole slice (the first second includes
  the start-up acquisition, 150 particles per block), ``real_time_factor_after_1s``,
  and ``real_time_factor_cpu`` (simulated seconds per second of the process's CPU
  time, which a loaded machine does not inflate);
* ``tracker_alone``: the tracker's Diagram alone (``AddTracker`` with the defaults) fed
  by the demo's sensors recorded beforehand (``RecordedRunSource``), as on a robot whose
  sensors come from hardware: its real-time factor after the first second, CPU seconds
  per simulated second in the Simulator's thread and in the other threads (the image
  update's worker), images applied per second, the median wall time of an update, and
  how many updates were not done at their deadline (``CpfImageUpdateSystem.
  deadline_waits``; ``updates_late_searches`` of them started as searches, the arm not
  yet acquired) with the Simulator's wait per simulated second;
* ``tracker_alone_paced``: the same held to real time, as on a robot (``defaults``, and
  ``every_frame`` with ``image.min_image_interval_s`` 0: every frame of the camera, at
  ``demo_camera_rate_hz``): its late updates took longer than ``image.update_latency_s``
  of wall time. Its real-time factor after the first second reads above 1 when the
  Simulator fell behind in that second and caught up; ``max_lag_behind_real_time_s``
  (also in ``tracker_alone``) is the most the simulated clock ever was behind the wall
  clock, which catching up does not hide;
* ``reading_path``: what each joint reading costs the Simulator's thread in a Diagram,
  on the same recorded sensors (:mod:`drake_tracker.bench.readings`);
* ``cameras``: an image update's cost, one camera at 30 Hz vs two at 15 Hz (``bench/cameras.py``);
* ``decision``: the per-image decision's time beside the image update's, per case and
  pooled (``bench/decision.py``).
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.bench.cameras import bench_camera_count, format_camera_count
from drake_tracker.bench.decision import bench_decision, format_decision
from drake_tracker.bench.readings import (
    bench_recorded_reading_path,
    format_reading_path,
    record_demo_sensors,
)
from drake_tracker.bench.realtime import (
    bench_demo,
    bench_tracker_alone,
    format_demo,
    format_tracker_alone,
)
from drake_tracker.core.cpf.image_update import CpfImageUpdate
from drake_tracker.core.filter.angle_observation import AngleObservation
from drake_tracker.core.filter.belief_buffer import BeliefBuffer
from drake_tracker.core.filter.kalman import VAR_A, JointKalmanBank, initial_moments
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.params.resolve import camera_chain_joints, resolve_blocks, resolve_kalman_params
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import TrackerModel, build_tracker_model, robot_preset

if TYPE_CHECKING:
    import argparse

#: The ``image.sweep_image_widths_px`` the bench times beside the defaults.
COARSE_SWEEP_WIDTHS_PX = [40, 40, 40, 80]


def bench_image_update(model: TrackerModel, camera: CameraIntrinsics, params: TrackerParams,
                       num_particles: int, repeats: int) -> dict:
    """Times whole CPF image updates with ``num_particles`` per block."""
    from drake_tracker.bench.likelihood import test_observation, time_updates, tracking_prior

    blocks = resolve_blocks(params, model.joint_names, camera_chain_joints(model))
    update = CpfImageUpdate(model, camera, blocks, num_particles, params.image.likelihood,
                            params.image.image_width_px, params.image.max_kl,
                            annealing_betas=tuple(params.image.annealing_betas),
                            sweep_image_widths_px=tuple(params.image.sweep_image_widths_px))
    timed = time_updates(update, test_observation(update), tracking_prior(model), repeats)
    return {"evaluations": update.evaluations_per_image, **timed}


def bench_kalman(model: TrackerModel, params: TrackerParams, repeats: int = 20000) -> dict:
    """Times the joint Kalman bank: ``kf_step_us``, one predict+update of all joints (µs,
    mean over ``repeats``), and ``replay_us_per_reading``, re-filtering one buffered reading
    after an image is inserted about 0.1 s back (µs); ``bank_variance_check`` is the largest
    angle variance afterwards."""
    bank = JointKalmanBank(resolve_kalman_params(params, model.joint_names,
                                                   model.prismatic_joint_names))
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
    """All figures of ``bench.json`` (see the module docstring)."""
    from drake_tracker.bench.likelihood import bench_robot, kernel_us_per_evaluation_in_turns
    from drake_tracker.robot.hires import BENCH_TESSELLATION, hires_apollo_model

    camera = CameraIntrinsics.from_fov(640, 480, np.radians(45.0))
    params = TrackerParams()
    repeats = 3 if quick else 7
    num_drake = 10 if quick else 50
    apollo = build_tracker_model(robot_preset("apollo"))
    robots = {"apollo": apollo, "apollo_cad": hires_apollo_model(**BENCH_TESSELLATION)}
    results = {name: bench_robot(model, camera, params, repeats, num_drake)
               for name, model in robots.items()}
    in_turns = kernel_us_per_evaluation_in_turns(robots, camera, params, 2 * repeats)
    default = bench_image_update(apollo, camera, params, params.image.num_particles,
                                 repeats)
    coarse_params = TrackerParams()
    coarse_params.image.sweep_image_widths_px = list(COARSE_SWEEP_WIDTHS_PX)
    coarse = bench_image_update(apollo, camera, coarse_params, params.image.num_particles,
                                repeats)
    kalman = bench_kalman(apollo, params)
    demo = bench_demo(params, 2.0 if quick else 4.0)
    recording = record_demo_sensors(params, 3.0 if quick else 6.0)
    alone = bench_tracker_alone(params, recording[1].duration_s, recording)
    every_frame = TrackerParams()
    every_frame.image.min_image_interval_s = 0.0
    paced = {name: bench_tracker_alone(p, recording[1].duration_s, recording, paced=True)
             for name, p in (("defaults", params), ("every_frame", every_frame))}
    readings = bench_recorded_reading_path(params, recording, quick)
    cameras = bench_camera_count(params, 2.0 if quick else 4.0)
    decision = bench_decision(3.0 if quick else 10.0)
    bench, cad = results["apollo"], results["apollo_cad"]
    size = camera.subsampled(bench_stride(camera, params))
    return {
        "machine": {"processor": platform.processor() or platform.machine(),
                    **_compile_target(),
                    "python": platform.python_version(),
                    "numba_threading_layer": _threading_layer()},
        "image_size": [size.width, size.height],
        "robots": results,
        "image_updates_per_s_2000_1_thread": bench["threads"]["1"]["updates_per_s"],
        "image_updates_per_s_2000_2_threads": bench["threads"]["2"]["updates_per_s"],
        "kernel_us_per_evaluation": in_turns,
        "cad_over_bench_cost_per_evaluation": in_turns["apollo_cad"] / in_turns["apollo"],
        "cad_over_bench_stage_score": (cad["stage_us_per_evaluation"]["score"]
                                       / bench["stage_us_per_evaluation"]["score"]),
        "image_updates_per_s_default": default["updates_per_s"],
        "evaluations_default": default["evaluations"],
        "image_updates_per_s_coarse_sweeps": coarse["updates_per_s"],
        "kf_step_us": kalman["kf_step_us"],
        "replay_us_per_reading": kalman["replay_us_per_reading"],
        "demo": demo,
        "tracker_alone": alone,
        "tracker_alone_paced": paced,
        "demo_camera_rate_hz": recording[0].camera.rate_hz,
        "reading_path": readings,
        "cameras": cameras,
        "decision": decision,
    }


def bench_stride(camera: CameraIntrinsics, params: TrackerParams) -> int:
    """The subsampling stride of the image update at the default image width."""
    from drake_tracker.core.sensors.camera import stride_for_width

    return stride_for_width(camera.width, params.image.image_width_px)


def _compile_target() -> dict:
    """The CPU numba compiles the kernels for (its name in LLVM, e.g. znver3, and
    whether it has AVX-512): the bench's figures depend on it (the same kernels ran
    1.8-2.0x faster per evaluation on a Zen 5 with AVX-512 than on a Zen 3)."""
    import llvmlite.binding as llvm
    import numba

    name = numba.config.CPU_NAME or llvm.get_host_cpu_name()
    features = numba.config.CPU_FEATURES
    if features is None:
        features = llvm.get_host_cpu_features().flatten()
    return {"llvm_cpu": name, "avx512f": "+avx512f" in features.split(",")}


def _threading_layer() -> str:
    import numba

    try:
        return str(numba.threading_layer())
    except ValueError:  # no parallel kernel has run yet
        return str(numba.config.THREADING_LAYER)


def _python_share(robot: dict) -> float:
    one = robot["threads"]["1"]
    return 100.0 * one["python_us_per_block"] * robot["block_calls_per_update"] * 1e-6 / (
        one["seconds"])


def format_bench(result: dict) -> str:
    """A human-readable summary of ``bench.json``."""
    w, h = result["image_size"]
    machine = result["machine"]
    lines = [f"image {w}x{h}, kernels compiled for {machine['llvm_cpu']} "
             f"({'with' if machine['avx512f'] else 'without'} AVX-512), numba threading "
             f"layer {machine['numba_threading_layer']}"]
    for name, r in result["robots"].items():
        stages = r["stage_us_per_evaluation"]
        threads = ", ".join(f"{t} thread{'s' if t != '1' else ''} {v['updates_per_s']:.1f}"
                            for t, v in r["threads"].items())
        lines += [
            f"{name}: {r['triangles_source']} triangles ({r['triangles_rendered']} rendered)",
            f"  image updates/s at {r['evaluations']} evaluations: {threads}"
            "   (target >= 30 on one thread)",
            f"  per second of CPU time, 1 thread: {r['threads']['1']['updates_per_cpu_s']:.1f}",
            "  us per evaluation (1 thread): " + ", ".join(
                f"{k} {v:.1f}" for k, v in stages.items()),
            f"  Python outside the compiled sweeps: "
            f"{r['threads']['1']['python_us_per_block']:.0f}"
            f" us per block call x {r['block_calls_per_update']} = "
            f"{_python_share(r):.0f} % of an update (1 thread)",
            f"  Drake RenderEngineVtk {r['drake_us_per_image']:.0f} us per image: "
            f"{r['drake_over_score']:.0f}x a fused evaluation, "
            f"{r['drake_over_render']:.0f}x a batched render; agreement: labels "
            f"{100 * r['label_agreement_vs_drake']:.2f} %, depth median "
            f"{r['depth_median_mm_vs_drake']:.2f} mm, p95 {r['depth_p95_mm_vs_drake']:.2f} mm",
        ]
    lines += [
        f"CAD robot / bench robot cost per evaluation: "
        f"{result['cad_over_bench_cost_per_evaluation']:.2f}, timed in turns (kernel "
        f"{result['kernel_us_per_evaluation']['apollo_cad']:.1f} / "
        f"{result['kernel_us_per_evaluation']['apollo']:.1f} us); from the stages above "
        f"{result['cad_over_bench_stage_score']:.2f}   (target <= 2)",
        f"image updates/s, defaults ({result['evaluations_default']} evaluations): "
        f"{result['image_updates_per_s_default']:.2f}; tempered sweeps at 40 px: "
        f"{result['image_updates_per_s_coarse_sweeps']:.2f}",
        f"Kalman bank step: {result['kf_step_us']:.2f} us   (target <= 20)",
        f"replay: {result['replay_us_per_reading']:.2f} us per re-filtered reading",
    ]
    lines.append(format_demo(result["demo"]))
    lines.append(format_tracker_alone(result["tracker_alone"]))
    for name, paced in result["tracker_alone_paced"].items():
        lines.append(f"held to real time, {name.replace('_', ' ')} "
                     f"(camera {result['demo_camera_rate_hz']:g} Hz): "
                     + format_tracker_alone(paced))
    lines += [format_reading_path(result["reading_path"]), format_camera_count(result["cameras"]),
              format_decision(result["decision"])]
    return "\n".join(lines)


def run_bench(args: argparse.Namespace) -> int:
    """``drake-tracker bench``: runs :func:`run_benchmarks` (fewer repetitions with
    ``--quick``; with ``--only readings``, ``cameras`` or ``decision`` that figure alone,
    ``bench.json`` then holding ``reading_path``, ``cameras`` or ``decision`` only),
    prints the figures and writes them to ``OUT/bench.json``; returns 0."""
    quick = getattr(args, "quick", False)
    if getattr(args, "only", None) == "readings":
        params = TrackerParams()
        result = {"reading_path": bench_recorded_reading_path(
            params, record_demo_sensors(params, 3.0 if quick else 6.0), quick)}
        print(format_reading_path(result["reading_path"]))
    elif getattr(args, "only", None) == "cameras":
        result = {"cameras": bench_camera_count(TrackerParams(), 2.0 if quick else 4.0)}
        print(format_camera_count(result["cameras"]))
    elif getattr(args, "only", None) == "decision":
        result = {"decision": bench_decision(3.0 if quick else 10.0)}
        print(format_decision(result["decision"]))
    else:
        result = run_benchmarks(quick=quick)
        print(format_bench(result))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {out / 'bench.json'}")
    return 0
