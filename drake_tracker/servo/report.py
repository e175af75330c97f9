"""``drake-tracker servo``: run the three closed-loop runs and report them.

Writes to ``--out`` (default ``out/servo``):

* ``report.json``: per run (``encoders``, ``tracker``, ``truth``) the final true error at
  each target (translation mm, rotation deg), the time to settle within
  ``settle_threshold_m``, the simulation's wall time and real-time factor; the study's
  configuration as YAML and the scenario;
* ``servo_errors.png``: the true hand error (translation and rotation, log axes) over
  time for the three runs, the targets' windows marked;
* ``meshcat.html``: one Meshcat recording of the three runs with the targets as triads
  (``drake_tracker.servo.meshcat_view``);
* ``errors.csv``: every sample of the three runs' true errors.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.demo.run import start_meshcat
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.servo.config import (
    FEEDBACK_LABELS,
    FEEDBACKS,
    ServoStudyConfig,
    servo_config_to_yaml,
)
from drake_tracker.servo.outcomes import format_outcome_table, target_outcomes, true_errors
from drake_tracker.servo.study import ServoRun, run_servo, servo_scenario

if TYPE_CHECKING:
    import argparse

RUN_COLORS = {"encoders": "tab:blue", "tracker": "tab:green", "truth": "0.3"}


def plot_servo_errors(runs: dict[str, ServoRun], config: ServoStudyConfig, path: Path,
                      title: str) -> Path:
    """PNG of each run's true translation (mm) and rotation (deg) error over time, log
    axes, with the hold and each target's window marked and the settle threshold."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for feedback, run in runs.items():
        for ax, values in zip(axes, true_errors(run, config), strict=True):
            ok = np.isfinite(values) & (values > 0)
            ax.plot(run.times_s[ok], values[ok], lw=1.2, color=RUN_COLORS[feedback],
                    label=FEEDBACK_LABELS[feedback])
    for ax in axes:
        ax.axvspan(0.0, config.hold_s, color="0.9", lw=0)
        for k, (start, _) in enumerate(config.target_windows()):
            ax.axvline(start, color="0.5", lw=0.8, ls=":")
            if ax is axes[0]:
                ax.text(start, 1.02, f" target {k + 1}", transform=ax.get_xaxis_transform(),
                        fontsize=8, color="0.3")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.25)
    axes[0].axhline(1000 * config.settle_threshold_m, color="tab:red", lw=0.8, ls="--",
                    label=f"{1000 * config.settle_threshold_m:g} mm")
    axes[0].set_ylabel("true translation error (mm)")
    axes[1].set_ylabel("true rotation error (deg)")
    axes[1].set_xlabel("time (s); grey: the robot holds its home pose")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_error_csv(runs: dict[str, ServoRun], config: ServoStudyConfig, path: Path) -> Path:
    """Every sample: time, target index, and each run's true errors (mm, deg)."""
    first = next(iter(runs.values()))
    columns = [first.times_s, first.target_index]
    header = ["time_s", "target_index"]
    for feedback, run in runs.items():
        translation, rotation = true_errors(run, config)
        columns += [translation, rotation]
        header += [f"{feedback}_translation_mm", f"{feedback}_rotation_deg"]
    n = min(len(c) for c in columns)
    table = np.column_stack([np.asarray(c, float)[:n] for c in columns])
    np.savetxt(path, table, delimiter=",", header=",".join(header), comments="", fmt="%.6g")
    return path


def run_servo_study(config: ServoStudyConfig, out: Path, params: TrackerParams | None = None,
                    feedbacks: tuple[str, ...] = FEEDBACKS, duration_s: float | None = None,
                    with_meshcat: bool = True, progress: bool = True) -> dict:
    """Runs the study's runs one after the other and writes the report files to
    ``out``; returns the report (``report.json``'s content)."""
    from drake_tracker.servo.meshcat_view import ServoMeshcatView

    out.mkdir(parents=True, exist_ok=True)
    scenario = servo_scenario(config)
    view = None
    if with_meshcat:
        view = ServoMeshcatView(start_meshcat(), config)
        print(f"live view: {view.meshcat.web_url()} ({out}/meshcat.html keeps the "
              "recording)", flush=True)
        view.start_recording()
    runs: dict[str, ServoRun] = {}
    for feedback in feedbacks:
        runs[feedback] = run_servo(config, feedback, scenario, params, duration_s,
                                   view.visualize if view else None, progress)
    outcomes = {f: target_outcomes(run, config) for f, run in runs.items()}
    report = {
        "scenario": scenario.name,
        "camera_px": [scenario.camera.width, scenario.camera.height],
        "config_yaml": servo_config_to_yaml(config),
        "settle_threshold_mm": 1000 * config.settle_threshold_m,
        "runs": {f: {"label": FEEDBACK_LABELS[f],
                     "targets": [o.as_dict() for o in outcomes[f]],
                     "simulated_s": float(run.times_s[-1]),
                     "wall_time_s": run.wall_time_s,
                     "real_time_factor": run.real_time_factor,
                     # Time the controller held the arm because the tracker was lost.
                     "feedback_unusable_s": float(
                         np.sum(~run.feedback_usable) * config.sample_period_s)}
                 for f, run in runs.items()},
    }
    title = (f"{scenario.name}, dynamic: true hand error in the camera frame while servoing "
             f"to {len(config.targets)} targets")
    plot_servo_errors(runs, config, out / "servo_errors.png", title)
    write_error_csv(runs, config, out / "errors.csv")
    (out / "report.json").write_text(json.dumps(report, indent=2))
    if view is not None:
        (out / "meshcat.html").write_text(view.finish())
    report["table"] = format_outcome_table(outcomes, FEEDBACK_LABELS,
                                           1000 * config.settle_threshold_m)
    return report


def run_servo_command(args: argparse.Namespace, config: ServoStudyConfig,
                      params: TrackerParams | None) -> int:
    """The ``drake-tracker servo`` command (its arguments already checked)."""
    start = time.perf_counter()
    out = Path(args.out)
    feedbacks = tuple(args.runs.split(",")) if args.runs else FEEDBACKS
    report = run_servo_study(config, out, params, feedbacks, args.duration,
                             with_meshcat=not args.no_meshcat)
    print(f"scenario {report['scenario']} (dynamic), {len(config.targets)} targets; true "
          "hand error in the camera frame at the end of each target's dwell")
    print(report["table"])
    for run in report["runs"].values():
        lost = (f"; held {run['feedback_unusable_s']:.2f} s while the tracker was lost"
                if run["feedback_unusable_s"] > 0 else "")
        print(f"{run['label']}: real-time factor {run['real_time_factor']:.2f} "
              f"({run['simulated_s']:.1f} s simulated in {run['wall_time_s']:.1f} s){lost}")
    written = ["report.json", "servo_errors.png", "errors.csv"]
    written += [] if args.no_meshcat else ["meshcat.html"]
    print(f"wrote to {out}/: {', '.join(written)}; wall time "
          f"{time.perf_counter() - start:.1f} s")
    return 0
