"""``drake-tracker demo``: simulate a scenario, estimate the hand pose, report the errors.

Writes to ``--out`` (default ``out/demo``):

* ``report.json``: ``{"methods": {METHOD: {"translation_mm": {"p1", "p25", "p50", "p75",
  "p99"}, "rotation_deg": {...}}}, "wall_time_s": .., "simulation_wall_time_s": ..,
  "scenario": .., "duration_s": .., "num_readings": .., "num_images": ..,
  "num_truth_samples": ..}``; errors are of the end effector pose in the camera frame
  against the truth (in the TRUE camera frame), sampled at 100 Hz from the first
  encoder reading on (before it there is no estimate);
* ``errors.png``: translation and rotation error of each method over time, log axes,
  with the scenario's bias steps, occlusion and out-of-view windows marked;
* ``meshcat.html``: a standalone Meshcat recording, all in one scene: the true robot in
  its colours, the robot where the raw (biased) encoders put it (translucent blue) and
  the tracker's estimate (translucent green), each placed so that its own camera is the
  real camera (so its hand shows the hand pose in the camera frame, what the errors
  measure), the camera's frustum at its true pose (black) and at the estimated one
  (green), the depth camera's points (magenta), and a legend;
* ``diagram.dot`` (and ``diagram.png`` where Graphviz's ``dot`` is installed, else a
  one-line note): the Diagram's structure.

A progress bar of simulated seconds goes to stderr, with the live Meshcat URL (the live
view ends with the run).

The simulated camera renders only the pixels the tracker reads
(:func:`render_what_the_tracker_reads`; the same pixels, silhouettes and noise law as
the full-resolution camera subsampled). ``encoders_only`` is computed from the recorded
readings; ``full_fusion`` is the
tracker running inside the simulation Diagram (``AddTracker`` wired to the world's
ports), its ``X_CE`` output sampled at the truth times. ``report.json`` also holds the
simulation's real-time factor (simulated seconds per wall-clock second).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.io.recording import RecordedRun
from drake_tracker.io.replay import encoders_only_X_CE
from drake_tracker.metrics import format_report_table, method_report, pose_errors
from drake_tracker.params.loading import load_tracker_params
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import build_tracker_model
from drake_tracker.sim.scenario.load import Scenario, load_scenario

if TYPE_CHECKING:
    import argparse

    from pydrake.geometry import Meshcat

DEFAULT_SCENARIO = "s-full-arm/constant"


#: Offline methods: name -> function(run, model) -> (T, 4, 4) X_CE at the truth times.
METHODS: dict[str, Callable[..., np.ndarray]] = {"encoders_only": encoders_only_X_CE}


def evaluate_methods(run: RecordedRun, estimates: dict[str, np.ndarray]) -> dict:
    """``{"methods": {name: method_report(...)}}`` of (T, 4, 4) estimates vs
    ``run.truth_X_CE`` (translation in mm, rotation in deg), from the first reading on."""
    report = {"methods": {}}
    for name, X in estimates.items():
        X = np.asarray(X, float)
        if X.shape != run.truth_X_CE.shape:
            raise ValueError(f"estimate '{name}' has shape {X.shape}, the truth "
                             f"{run.truth_X_CE.shape}")
        keep = first_estimate_mask(run)
        report["methods"][name] = method_report(X[keep], run.truth_X_CE[keep])
    return report


def first_estimate_mask(run: RecordedRun) -> np.ndarray:
    """Truth samples after the first encoder reading: before it there is no estimate."""
    if len(run.reading_times_s) == 0:
        return np.zeros(len(run.truth_times_s), bool)
    return run.truth_times_s > run.reading_times_s[0]


def plot_errors(run: RecordedRun, estimates: dict[str, np.ndarray], path: Path,
                scenario: Scenario | None = None) -> Path:
    """PNG of translation (mm) and rotation (deg) error over time on log axes, one line
    per method, from the first estimate on, with the scenario's events marked."""
    from pydrake.common.yaml import yaml_load_typed

    from drake_tracker.evaluation.plot_style import plot_error_time_series

    if scenario is None:
        scenario = yaml_load_typed(schema=Scenario, data=run.scenario_yaml)
    keep = first_estimate_mask(run)
    errors = {name: tuple(e[keep] for e in pose_errors(X, run.truth_X_CE))
              for name, X in estimates.items()}
    title = (f"{scenario.name}: hand pose error in the camera frame "
             f"({run.duration_s:.1f} s simulated)")
    return plot_error_time_series(run.truth_times_s[keep], errors, scenario, path, title)


def demo_hook(meshcat: Meshcat, params: TrackerParams) -> Callable:
    """An ``add_systems`` hook: the tracker on the world's ports (every camera of the
    scenario), and Meshcat views of the true world, the encoders-only robot and the
    estimate (each moved so that its camera is the real first camera), each camera's
    frustum at its true and estimated poses, and each camera's points."""
    from pydrake.geometry import MeshcatVisualizer, MeshcatVisualizerParams, Role
    from pydrake.systems.primitives import ConstantVectorSource, Multiplexer

    from drake_tracker.demo.meshcat_views import (
        ENCODERS_RGBA,
        ESTIMATE_RGBA,
        AddGhostRobot,
        frame_the_robot,
    )
    from drake_tracker.demo.world_tracker import (
        AddCameraViews,
        AddWorldTracker,
        first_camera_positions,
    )

    def hook(builder, world):
        tracker = AddWorldTracker(builder, world, params)
        period = 1.0 / 30.0
        MeshcatVisualizer.AddToBuilder(
            builder, world.scene_graph, meshcat,
            MeshcatVisualizerParams(role=Role.kIllustration, prefix="truth",
                                    publish_period=period))
        n = len(world.robot_joint_names)
        mux = builder.AddNamedSystem("encoders_ghost_positions", Multiplexer([n, 6]))
        zeros = builder.AddNamedSystem("nominal_camera_offset",
                                       ConstantVectorSource(np.zeros(6)))
        builder.Connect(world.port("measured_position"), mux.get_input_port(0))
        builder.Connect(zeros.get_output_port(), mux.get_input_port(1))
        true_pose = next(iter(AddCameraViews(builder, world, meshcat, tracker,
                                             period).values()))
        AddGhostRobot(builder, world.robot_config, meshcat, mux.get_output_port(),
                      "encoders_only", ENCODERS_RGBA, camera_pose=true_pose,
                      publish_period_s=period)
        AddGhostRobot(builder, world.robot_config, meshcat,
                      first_camera_positions(builder, world.model, tracker.estimated_position),
                      "estimate", ESTIMATE_RGBA,
                      camera_pose=true_pose, publish_period_s=period)
        frame_the_robot(meshcat, world.plant, world.end_effector_frame.model_instance(),
                        world.reference.positions(0.0))
        meshcat.StartRecording(frames_per_second=30.0)
        hook.image_update = tracker.image_update  # its deadline_waits, for the report
        return {"full_fusion_X_CE": tracker.X_CE}

    return hook


def render_what_the_tracker_reads(scenario: Scenario, params: TrackerParams) -> Scenario:
    """``scenario`` with each camera rendering only the pixels the tracker reads
    (``render_stride`` = the tracker's subsampling stride) unless the scenario sets a
    ``render_stride`` other than 1 for it: the tracker sees the same pixels either way
    (``sim.depth_camera``), at a fraction of the rendering cost."""
    import copy

    from drake_tracker.core.sensors.camera import stride_for_width

    fast = copy.deepcopy(scenario)
    for camera in [fast.camera, *fast.cameras]:  # with ``cameras:``, each of them
        if camera.render_stride == 1:
            camera.render_stride = stride_for_width(camera.width,
                                                    params.image.image_width_px)
    return fast


def legend_entries() -> list:
    """The legend of the demo's Meshcat scene."""
    from drake_tracker.demo.meshcat_views import (
        ENCODERS_RGBA,
        ESTIMATE_RGBA,
        POINTS_RGBA,
        TRUE_CAMERA_RGBA,
        LegendEntry,
    )

    return [LegendEntry(None, "<b>truth</b>: the robot in its own colours"),
            LegendEntry(ENCODERS_RGBA, "<b>encoders only</b>: the raw readings"),
            LegendEntry(ESTIMATE_RGBA, "<b>estimate</b>: the tracker; green frustum: its "
                                       "camera pose"),
            LegendEntry(TRUE_CAMERA_RGBA, "the real camera; both ghosts hang from it, so "
                                          "their hand is the hand pose in the camera frame"),
            LegendEntry(POINTS_RGBA, "the camera's depth points")]


def write_diagram(graphviz: str, out: Path) -> Path | None:
    """Writes ``diagram.dot`` and, when Graphviz's ``dot`` is on the PATH, ``diagram.png``
    (a one-line note says when it is not)."""
    import shutil
    import subprocess

    from drake_tracker.progress import note

    (out / "diagram.dot").write_text(graphviz)
    if shutil.which("dot") is None:
        note("Graphviz's 'dot' is not installed: wrote diagram.dot, not diagram.png "
             "(install graphviz, or paste diagram.dot into any Graphviz viewer)")
        return None
    png = out / "diagram.png"
    subprocess.run(["dot", "-Tpng", "-Gdpi=60", str(out / "diagram.dot"), "-o", str(png)],
                   check=True)
    return png


def start_meshcat() -> Meshcat:
    """A Meshcat server on localhost at a free port, without Drake's own INFO line (the
    demo prints the URL with what it shows)."""
    import logging

    from pydrake.geometry import Meshcat, MeshcatParams

    meshcat_params = MeshcatParams()
    meshcat_params.host = "localhost"
    meshcat_params.port = 0  # a free port
    logger = logging.getLogger("drake")
    level = logger.level
    logger.setLevel(logging.WARNING)
    try:
        return Meshcat(meshcat_params)
    finally:
        logger.setLevel(level)


def run_demo(args: argparse.Namespace, scenario: Scenario | None = None,
             params: TrackerParams | None = None, progress: bool = True) -> int:
    """The ``drake-tracker demo`` command (``--scenario``, ``--out``, ``--duration``,
    ``--params``); ``scenario`` and ``params``, when given, were already loaded from
    them (the command line checks them before anything is written)."""
    from drake_tracker.demo.meshcat_views import add_legend
    from drake_tracker.kernel_warm_up import warm_up_tracker_kernels
    from drake_tracker.sim.depth_camera import rendered_intrinsics
    from drake_tracker.sim.record import simulate_and_record

    start = time.perf_counter()
    if scenario is None:
        scenario = load_scenario(getattr(args, "scenario", None) or DEFAULT_SCENARIO)
    if params is None:
        params = load_tracker_params(getattr(args, "params", None))
    out = Path(getattr(args, "out", None) or "out/demo")
    out.mkdir(parents=True, exist_ok=True)
    meshcat = start_meshcat()
    print(f"live view: {meshcat.web_url()} (open it now: it ends with the run; "
          f"{out}/meshcat.html keeps the recording)\n"
          "  truth: the robot's own colours; encoders only: translucent blue; estimate: "
          "translucent green", flush=True)
    simulated = render_what_the_tracker_reads(scenario, params)
    print("loading the tracker's compiled kernels (a machine's first run compiles them: "
          "about a minute)...", flush=True)
    model = build_tracker_model(scenario.resolved_robot_config())
    warm_up_s = warm_up_tracker_kernels(model, rendered_intrinsics(simulated.camera), params)
    print(f"  done in {warm_up_s:.1f} s", flush=True)
    hook = demo_hook(meshcat, params)
    run = simulate_and_record(simulated, duration_s=getattr(args, "duration", None),
                              image_stride=simulated.camera.render_stride,
                              add_systems=hook, validate=False, progress=progress)
    waits = hook.image_update.deadline_waits
    meshcat.StopRecording()
    meshcat.PublishRecording()
    (out / "meshcat.html").write_text(add_legend(meshcat.StaticHtml(), legend_entries()))

    estimates = {name: method(run, model) for name, method in METHODS.items()}
    estimates["full_fusion"] = run.extra["full_fusion_X_CE"]
    report = evaluate_methods(run, estimates)
    plot_errors(run, estimates, out / "errors.png", scenario)
    report.update({
        "scenario": scenario.name,
        "duration_s": run.duration_s,
        "num_readings": len(run.reading_times_s),
        "num_images": len(run.image_capture_times_s),
        "num_truth_samples": len(run.truth_times_s),
        "simulation_wall_time_s": run.extra["wall_time_s"],
        "real_time_factor": run.duration_s / run.extra["wall_time_s"],
        # Image updates the Simulator had to wait for at their deadline, and how long.
        "image_updates_late": waits.late,
        "image_updates_late_searches": waits.late_searches,
        "image_updates_on_time": waits.on_time,
        "image_update_wait_s": waits.waited_s,
        # Loading (a machine's first run: compiling) the kernels before the simulation.
        "kernel_warm_up_s": warm_up_s,
        "wall_time_s": time.perf_counter() - start,
    })
    png = write_diagram(run.extra["graphviz"], out)
    (out / "report.json").write_text(json.dumps(report, indent=2))
    print(f"scenario {scenario.name}, {run.duration_s:.1f} s simulated; errors from the "
          "first reading on")
    print(format_report_table(report))
    print(f"real-time factor {report['real_time_factor']:.2f} (simulation "
          f"{report['simulation_wall_time_s']:.1f} s); wall time {report['wall_time_s']:.1f} s; "
          f"{waits.late} of {waits.late + waits.on_time} image updates late at their "
          f"deadline, {waits.late_searches} of them searches ({waits.waited_s:.1f} s waited)")
    written = ["report.json", "errors.png", "meshcat.html (open it in a browser)",
               "diagram.dot"] + (["diagram.png"] if png else [])
    print(f"wrote to {out}/: {', '.join(written)}")
    return 0
