"""Replaying a recorded run through the offline tracker, and ``drake-tracker track``.

Events are fed in the order a live tracker receives them: each reading at its stamp,
each image at its arrival time (readings stamped at or before an image's arrival come
first). Bad samples are skipped with a warning that names their time, and the replay
finishes: readings by the tracker's time-stamp policy (``core/sensors/timestamps.py``), images
that raise (malformed, or not in metres) here. Estimates are sampled after the last
reading at or before each ground-truth time.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.filter.estimate import PoseReadout
from drake_tracker.core.filter.start import full_reading
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.io.recording import RecordedRun
from drake_tracker.io.stream import track_stream
from drake_tracker.metrics import method_report
from drake_tracker.params.loading import load_tracker_params
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import (
    RobotConfig,
    TrackerModel,
    build_tracker_model,
    load_robot_config,
)
from drake_tracker.tracker import Tracker

if TYPE_CHECKING:
    import argparse

log = logging.getLogger(__name__)


@dataclass
class ReplayResult:
    """Estimates sampled at ``times_s`` (the run's ground-truth times)."""

    times_s: np.ndarray
    positions: np.ndarray  # (T, n) all model joints
    position_variances: np.ndarray
    biases: np.ndarray
    camera_offsets: np.ndarray  # (T, 6 per camera), the model's camera order
    X_CE: np.ndarray  # (T, 4, 4)
    joint_names: list[str]
    num_images_applied: int
    #: Frames not processed (not due at ``min_image_interval_s``, or unusable).
    num_images_skipped: int
    image_update_s: list[float]
    wall_time_s: float
    #: (T,) the health state reported at each sample (``HealthState`` value; -1 before
    #: the tracker started).
    health: np.ndarray | None = None
    #: The image processors' ``DecisionTimes`` summed over the cameras: ``images``,
    #: ``update_s`` and ``decision_s`` (``core/image_processor.py``).
    decision_times: dict | None = None


def robot_config_from_yaml(text: str) -> RobotConfig:
    """The RobotConfig stored in a recorded run."""
    return load_robot_config(text)


def model_for_run(run: RecordedRun) -> TrackerModel:
    """The TrackerModel of the robot ``run`` was recorded with (its stored RobotConfig)."""
    return build_tracker_model(robot_config_from_yaml(run.robot_config_yaml))


class _Sampler:
    """The tracker's estimate at each sample time: the one after every event before it
    (``StreamObserver``)."""

    def __init__(self, times_s: np.ndarray, n: int) -> None:
        self.times_s = times_s
        self.next = 0
        self.q = np.full((len(times_s), n), np.nan)
        self.var = np.full((len(times_s), n), np.nan)
        self.b = np.full((len(times_s), n), np.nan)
        self.X = np.full((len(times_s), 4, 4), np.nan)
        self.health = np.full(len(times_s), -1, int)

    def before(self, time_s: float, tracker: Tracker) -> None:
        while self.next < len(self.times_s) and self.times_s[self.next] < time_s:
            if tracker.started:
                e, k = tracker.estimate(), self.next
                self.q[k], self.var[k], self.b[k] = e.positions, e.position_variances, e.biases
                self.X[k], self.health[k] = e.X_CE, int(e.health.state)
            self.next += 1


def replay_run(run: RecordedRun, params: TrackerParams | None = None,
               model: TrackerModel | None = None,
               sample_times_s: np.ndarray | None = None,
               progress: bool = False,
               on_image: Callable[[Tracker, DepthFrame], None] | None = None
               ) -> ReplayResult:
    """Replays ``run`` through a fresh :class:`Tracker` and samples its estimates;
    ``progress`` shows a bar of the images fed (stderr); ``on_image(tracker, frame)`` is
    called after each image the tracker accepted (to trace it; an exception it raises
    ends the replay and reaches the caller). The events go through
    ``io/stream.py:track_stream``, the path of ``drake-tracker track``."""
    from drake_tracker.io.track_files import run_events

    model = model if model is not None else model_for_run(run)
    if list(run.joint_names) != list(model.robot_joint_names):
        raise ValueError(f"the run's joints {run.joint_names} differ from the model's "
                         f"{model.robot_joint_names}")
    if run.other_cameras:
        tracker = Tracker(model, params=params, cameras=run.intrinsics_by_camera)
    else:
        tracker = Tracker(model, run.camera_intrinsics, params)
    times = run.truth_times_s if sample_times_s is None else np.asarray(sample_times_s)
    sampler = _Sampler(times, model.num_joints)
    t_start = time.perf_counter()
    counts = track_stream(run_events(run), tracker, total_images=len(
        run.image_capture_times_s), progress=progress, observer=sampler, on_image=on_image)
    virtual = model.virtual_joint_indices
    return ReplayResult(
        times_s=np.asarray(times), positions=sampler.q, position_variances=sampler.var,
        biases=sampler.b, camera_offsets=sampler.q[:, virtual], X_CE=sampler.X,
        health=sampler.health, joint_names=list(model.joint_names),
        num_images_applied=tracker.num_images_applied,
        num_images_skipped=tracker.num_images_skipped + sum(counts.source_skipped.values()),
        image_update_s=list(tracker.images.update.times.per_update) if tracker.images else [],
        wall_time_s=time.perf_counter() - t_start,
        decision_times=summed_decision_times(tracker),
    )


def summed_decision_times(tracker: Tracker) -> dict:
    """``images``, ``update_s`` and ``decision_s`` of ``tracker``'s image processors
    (``ImageProcessor.times``), summed over its cameras."""
    processors = [c.images for c in tracker.channels.values() if c.images is not None]
    return {"images": sum(p.times.images for p in processors),
            "update_s": sum(p.times.update_s for p in processors),
            "decision_s": sum(p.times.decision_s for p in processors)}


def readings_at(run: RecordedRun, times_s: np.ndarray) -> np.ndarray:
    """(T, n) the latest reading stamped at or before each time (NaN before the first)."""
    k = np.searchsorted(run.reading_times_s, np.asarray(times_s) + 1e-9, side="right") - 1
    out = np.full((len(k), len(run.joint_names)), np.nan)
    out[k >= 0] = run.readings_rad[k[k >= 0]]
    return out


def encoders_only_X_CE(run: RecordedRun, model: TrackerModel | None = None) -> np.ndarray:
    """The baseline: forward kinematics of the latest raw reading at each truth time,
    with the nominal camera (virtual joints at 0). (T, 4, 4); NaN before any reading."""
    model = model if model is not None else model_for_run(run)
    readings = readings_at(run, run.truth_times_s)
    out = np.full((len(readings), 4, 4), np.nan)
    ok = np.all(np.isfinite(readings), axis=1)
    if ok.any():
        q = np.array([full_reading(model, r) for r in readings[ok]])
        out[ok] = PoseReadout(model).poses(q)[0]
    return out


def run_report(run: RecordedRun, estimates: dict[str, np.ndarray]) -> dict:
    """``{"methods": {name: {"translation_mm": {...}, "rotation_deg": {...}}}}``, comparing
    each method's X_CE with the ground truth at the samples where both are defined."""
    report = {"methods": {}}
    for name, X in estimates.items():
        ok = np.all(np.isfinite(X.reshape(len(X), -1)), axis=1)
        report["methods"][name] = method_report(X[ok], run.truth_X_CE[ok])
    return report


def run_track(args: argparse.Namespace, run: RecordedRun | None = None,
              params: TrackerParams | None = None, model: TrackerModel | None = None) -> int:
    """``drake-tracker track --run FILE [--params YAML] [--out DIR]``; ``run``,
    ``params`` and ``model``, when given, were already loaded from those arguments. The
    run goes through ``io/track_files.py`` (the path a bag takes), and the encoders
    alone are reported beside it."""
    from drake_tracker.io.track_files import print_report, track_run

    run = run if run is not None else RecordedRun.load(args.run)
    params = params if params is not None else load_tracker_params(args.params)
    model = model if model is not None else model_for_run(run)
    out = Path(args.out) if args.out else None
    report = track_run(run, model, params, out)
    report["methods"] = {
        "encoders_only": run_report(run, {"e": encoders_only_X_CE(run, model)})["methods"]["e"],
        **report["methods"]}
    print_report(report)
    print(f"tracked {run.duration_s:.1f} s of data in {report['wall_time_s']:.1f} s")
    if out is not None:
        (out / "report.json").write_text(json.dumps(report, indent=2))
        print(f"wrote {out}/: " + ", ".join(report["files"] + ["report.json"]))
    return 0
