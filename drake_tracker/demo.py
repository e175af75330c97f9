"""``drake-tracker demo``: simulate a scenario, estimate the hand pose, report the errors.

Writes to ``--out`` (default ``out/demo``):

* ``report.json``: ``{"methods": {METHOD: {"translation_mm": {"p1", "p25", "p50", "p75",
  "p99"}, "rotation_deg": {...}}}, "wall_time_s": .., "simulation_wall_time_s": ..,
  "scenario": .., "duration_s": .., "num_readings": .., "num_images": ..,
  "num_truth_samples": ..}``; errors are of the end effector pose in the camera frame
  against the truth (in the TRUE camera frame), sampled at 100 Hz;
* ``errors.png``: translation and rotation error of each method over time;
* ``meshcat.html``: a standalone Meshcat recording: the true robot in its colours and,
  white and translucent, the robot where the raw (biased) encoders put it.

Methods are functions of the recorded run (``METHODS``); a method that runs inside the
simulation Diagram (the tracker) adds its systems through the ``add_systems`` hook of
:func:`~drake_tracker.sim.record.simulate_and_record` and returns its ``X_CE`` port,
whose samples at the truth times arrive in ``run.extra``; then pass them to
:func:`evaluate_methods` beside the offline ones.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from drake_tracker.metrics import format_report_table, method_report, pose_errors
from drake_tracker.recording import RecordedRun
from drake_tracker.robot import build_tracker_model
from drake_tracker.sim.scenario import load_scenario
from drake_tracker.sim.world import encoders_only_X_CE

DEFAULT_SCENARIO = "s-full-arm/constant"


def readings_at(run: RecordedRun, times_s: np.ndarray) -> np.ndarray:
    """(T, n) the latest encoder reading stamped at or before each time (the first
    reading for times before it)."""
    k = np.searchsorted(run.reading_times_s, np.asarray(times_s) + 1e-9, side="right") - 1
    return run.readings_rad[np.clip(k, 0, None)]


def encoders_only(run: RecordedRun, model=None) -> np.ndarray:
    """(T, 4, 4) X_CE at the truth times from the raw readings and the nominal camera."""
    if model is None:
        from drake_tracker.offline import model_for_run

        model = model_for_run(run)
    return encoders_only_X_CE(model, readings_at(run, run.truth_times_s))


#: Offline methods: name -> function(run, model) -> (T, 4, 4) X_CE at the truth times.
METHODS: dict[str, Callable[..., np.ndarray]] = {"encoders_only": encoders_only}


def evaluate_methods(run: RecordedRun, estimates: dict[str, np.ndarray]) -> dict:
    """``{"methods": {name: method_report(...)}}`` of (T, 4, 4) estimates vs
    ``run.truth_X_CE`` (translation in mm, rotation in deg)."""
    report = {"methods": {}}
    for name, X in estimates.items():
        X = np.asarray(X, float)
        if X.shape != run.truth_X_CE.shape:
            raise ValueError(f"estimate '{name}' has shape {X.shape}, the truth "
                             f"{run.truth_X_CE.shape}")
        report["methods"][name] = method_report(X, run.truth_X_CE)
    return report


def plot_errors(run: RecordedRun, estimates: dict[str, np.ndarray], path: Path) -> Path:
    """PNG of translation (mm) and rotation (deg) error over time, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for name, X in estimates.items():
        t_err, r_err = pose_errors(X, run.truth_X_CE)
        axes[0].plot(run.truth_times_s, t_err, label=name)
        axes[1].plot(run.truth_times_s, r_err, label=name)
    axes[0].set_ylabel("translation error (mm)")
    axes[1].set_ylabel("rotation error (deg)")
    axes[1].set_xlabel("time (s)")
    axes[0].legend()
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def meshcat_hook(meshcat):
    """An ``add_systems`` hook drawing the true world and the encoders-only robot."""
    from pydrake.geometry import MeshcatVisualizer, MeshcatVisualizerParams, Role
    from pydrake.systems.primitives import ConstantVectorSource, Multiplexer

    from drake_tracker.visualization import ENCODERS_RGBA, AddGhostRobot

    def hook(builder, world):
        period = 1.0 / 30.0
        MeshcatVisualizer.AddToBuilder(
            builder, world.scene_graph, meshcat,
            MeshcatVisualizerParams(role=Role.kIllustration, prefix="true",
                                    publish_period=period))
        n = len(world.robot_joint_names)
        mux = builder.AddNamedSystem("encoders_ghost_positions", Multiplexer([n, 6]))
        zeros = builder.AddNamedSystem("nominal_camera_offset",
                                       ConstantVectorSource(np.zeros(6)))
        builder.Connect(world.port("measured_position"), mux.get_input_port(0))
        builder.Connect(zeros.get_output_port(), mux.get_input_port(1))
        visualizer = AddGhostRobot(builder, world.robot_config, meshcat, mux.get_output_port(),
                                   "encoders", ENCODERS_RGBA, with_camera_joints=True)
        del visualizer
        meshcat.StartRecording(frames_per_second=30.0)
        return {}

    return hook


def run_demo(args) -> int:
    """The ``drake-tracker demo`` command (``--scenario``, ``--out``, ``--duration``)."""
    from pydrake.geometry import Meshcat

    from drake_tracker.sim.record import simulate_and_record

    start = time.perf_counter()
    scenario = load_scenario(getattr(args, "scenario", None) or DEFAULT_SCENARIO)
    out = Path(getattr(args, "out", None) or "out/demo")
    out.mkdir(parents=True, exist_ok=True)
    meshcat = Meshcat()
    run = simulate_and_record(scenario, duration_s=getattr(args, "duration", None),
                              add_systems=meshcat_hook(meshcat), validate=False)
    meshcat.StopRecording()
    meshcat.PublishRecording()
    (out / "meshcat.html").write_text(meshcat.StaticHtml())

    model = build_tracker_model(scenario.resolved_robot_config())
    estimates = {name: method(run, model) for name, method in METHODS.items()}
    report = evaluate_methods(run, estimates)
    plot_errors(run, estimates, out / "errors.png")
    report.update({
        "scenario": scenario.name,
        "duration_s": run.duration_s,
        "num_readings": len(run.reading_times_s),
        "num_images": len(run.image_capture_times_s),
        "num_truth_samples": len(run.truth_times_s),
        "simulation_wall_time_s": run.extra["wall_time_s"],
        "wall_time_s": time.perf_counter() - start,
    })
    (out / "report.json").write_text(json.dumps(report, indent=2))
    print(f"scenario {scenario.name}, {run.duration_s:.1f} s simulated")
    print(format_report_table(report))
    print(f"wall time {report['wall_time_s']:.1f} s; wrote {out}/report.json, errors.png, "
          f"meshcat.html")
    return 0
