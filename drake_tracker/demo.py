"""``drake-tracker demo``: simulate a scenario, estimate the hand pose, report the errors.

Writes to ``--out`` (default ``out/demo``):

* ``report.json``: ``{"methods": {METHOD: {"translation_mm": {"p1", "p25", "p50", "p75",
  "p99"}, "rotation_deg": {...}}}, "wall_time_s": .., "simulation_wall_time_s": ..,
  "scenario": .., "duration_s": .., "num_readings": .., "num_images": ..,
  "num_truth_samples": ..}``; errors are of the end effector pose in the camera frame
  against the truth (in the TRUE camera frame), sampled at 100 Hz;
* ``errors.png``: translation and rotation error of each method over time;
* ``meshcat.html``: a standalone Meshcat recording, all in one scene: the true robot in
  its colours, the robot where the raw (biased) encoders put it (white, translucent),
  the tracker's estimate (orange, translucent), and the depth camera's points placed
  with the estimated camera pose;
* ``diagram.dot`` (and ``diagram.png`` where Graphviz's ``dot`` is installed): the
  Diagram's structure.

``encoders_only`` is computed from the recorded readings; ``full_fusion`` is the
tracker running inside the simulation Diagram (``AddTracker`` wired to the world's
ports), its ``X_CE`` output sampled at the truth times. ``report.json`` also holds the
simulation's real-time factor (simulated seconds per wall-clock second).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from pydrake.geometry import Rgba

from drake_tracker.metrics import format_report_table, method_report, pose_errors
from drake_tracker.offline import encoders_only_X_CE
from drake_tracker.params import TrackerParams, load_tracker_params
from drake_tracker.recording import RecordedRun
from drake_tracker.robot import build_tracker_model
from drake_tracker.sim.scenario import load_scenario

DEFAULT_SCENARIO = "s-full-arm/constant"


#: Offline methods: name -> function(run, model) -> (T, 4, 4) X_CE at the truth times.
METHODS: dict[str, Callable[..., np.ndarray]] = {"encoders_only": encoders_only_X_CE}


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


def demo_hook(meshcat, params: TrackerParams):
    """An ``add_systems`` hook: the tracker on the world's ports, and Meshcat views of the
    true world, the encoders-only robot, the estimate and the camera's points."""
    from pydrake.geometry import (
        MeshcatPointCloudVisualizer,
        MeshcatVisualizer,
        MeshcatVisualizerParams,
        Role,
    )
    from pydrake.systems.primitives import ConstantVectorSource, Multiplexer

    from drake_tracker.systems.add_tracker import AddTracker
    from drake_tracker.systems.point_cloud import DepthFrameToPointCloud
    from drake_tracker.visualization import ENCODERS_RGBA, ESTIMATE_RGBA, AddGhostRobot

    def hook(builder, world):
        tracker = AddTracker(builder, world.model, world.intrinsics, params,
                             world.port("measured_position"), world.port("measurement_time"),
                             world.port("depth_frame"), world.encoder_period_s)
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
        AddGhostRobot(builder, world.robot_config, meshcat, mux.get_output_port(),
                      "encoders", ENCODERS_RGBA)
        AddGhostRobot(builder, world.robot_config, meshcat,
                      tracker.port("estimated_position"), "estimate", ESTIMATE_RGBA)
        cloud = builder.AddNamedSystem("point_cloud", DepthFrameToPointCloud(world.intrinsics))
        builder.Connect(world.port("depth_frame"), cloud.get_input_port())
        points = builder.AddNamedSystem(
            "point_cloud_visualizer",
            MeshcatPointCloudVisualizer(meshcat, "camera_points", publish_period=period))
        points.set_default_rgba(Rgba(0.1, 0.4, 1.0, 1.0))
        builder.Connect(cloud.get_output_port(), points.cloud_input_port())
        builder.Connect(tracker.port("X_WC"), points.pose_input_port())
        meshcat.StartRecording(frames_per_second=30.0)
        return {"full_fusion_X_CE": tracker.port("X_CE")}

    return hook


def write_diagram(graphviz: str, out: Path) -> Path | None:
    """Writes ``diagram.dot`` and, when Graphviz's ``dot`` is on the PATH, ``diagram.png``."""
    import shutil
    import subprocess

    (out / "diagram.dot").write_text(graphviz)
    if shutil.which("dot") is None:
        return None
    png = out / "diagram.png"
    subprocess.run(["dot", "-Tpng", "-Gdpi=60", str(out / "diagram.dot"), "-o", str(png)],
                   check=True)
    return png


def run_demo(args) -> int:
    """The ``drake-tracker demo`` command (``--scenario``, ``--out``, ``--duration``)."""
    from pydrake.geometry import Meshcat, MeshcatParams

    from drake_tracker.sim.record import simulate_and_record

    start = time.perf_counter()
    scenario = load_scenario(getattr(args, "scenario", None) or DEFAULT_SCENARIO)
    params = load_tracker_params(getattr(args, "params", None))
    out = Path(getattr(args, "out", None) or "out/demo")
    out.mkdir(parents=True, exist_ok=True)
    meshcat_params = MeshcatParams()
    meshcat_params.host = "localhost"
    meshcat_params.port = 0  # a free port
    meshcat = Meshcat(meshcat_params)
    run = simulate_and_record(scenario, duration_s=getattr(args, "duration", None),
                              add_systems=demo_hook(meshcat, params), validate=False)
    meshcat.StopRecording()
    meshcat.PublishRecording()
    (out / "meshcat.html").write_text(meshcat.StaticHtml())

    model = build_tracker_model(scenario.resolved_robot_config())
    estimates = {name: method(run, model) for name, method in METHODS.items()}
    estimates["full_fusion"] = run.extra["full_fusion_X_CE"]
    report = evaluate_methods(run, estimates)
    plot_errors(run, estimates, out / "errors.png")
    report.update({
        "scenario": scenario.name,
        "duration_s": run.duration_s,
        "num_readings": len(run.reading_times_s),
        "num_images": len(run.image_capture_times_s),
        "num_truth_samples": len(run.truth_times_s),
        "simulation_wall_time_s": run.extra["wall_time_s"],
        "real_time_factor": run.duration_s / run.extra["wall_time_s"],
        "wall_time_s": time.perf_counter() - start,
    })
    write_diagram(run.extra["graphviz"], out)
    (out / "report.json").write_text(json.dumps(report, indent=2))
    print(f"scenario {scenario.name}, {run.duration_s:.1f} s simulated")
    print(format_report_table(report))
    print(f"real-time factor {report['real_time_factor']:.2f} (simulation "
          f"{report['simulation_wall_time_s']:.1f} s); wall time {report['wall_time_s']:.1f} s")
    print(f"wrote {out}/report.json, errors.png, meshcat.html, diagram.dot")
    return 0
