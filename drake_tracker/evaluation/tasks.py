"""The evaluation's unit of work: a task is one (sequence, bias variant, seed).

A task simulates its run (or loads it from a cache folder), replays it through every
method, and **returns** its result as a payload (the text of its per-task CSV, the
environment it ran in, and its wall times). It never writes its result itself: the
driver writes the payload atomically into ``results/``, so workers need no file system
in common with the driver (a Ray cluster without shared storage).
"""

from __future__ import annotations

import csv
import io
import os
import platform
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.robustness.health import HealthState
from drake_tracker.evaluation.camera_frames import (
    camera_errors_csv_text,
    camera_frame_errors,
    camera_poses,
    true_positions,
)
from drake_tracker.evaluation.health_calibration import (
    ImageStates,
    image_errors,
    image_health_csv_text,
)
from drake_tracker.evaluation.methods import method_params
from drake_tracker.metrics import pose_errors

if TYPE_CHECKING:
    from drake_tracker.io.recording import RecordedRun
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.sim.scenario.config import Scenario

#: The quick suite: each kind of sequence (sinusoid, free, fast, out of view, occlusion)
#: with each bias variant, shortened.
QUICK_SEQUENCES = ("s-full-arm", "s-head-arm", "arm++", "in-out-in", "occlusion")
#: Further quick cases (sequence, bias): heavy and lasting occlusion, a bias ramp, a
#: world robot that is not exactly the tracker's model, and biases that drift as random
#: walks of 1, 3 and 6 deg/sqrt(s); and the lasting occlusion and in-out-in with a second
#: camera that sees the arm when the first does not.
BIASES = ("none", "constant", "time-varying")
QUICK_EXTRA_CASES = (("occlusion-heavy", "constant"), ("occlusion-lasting", "constant"),
                     ("s-full-arm", "ramp"), ("s-full-arm-mismatch", "constant"),
                     ("s-full-arm", "random-walk-1"), ("s-full-arm", "random-walk-3"),
                     ("s-full-arm", "random-walk-6"), ("occlusion-lasting-2cam", "constant"),
                     *(("in-out-in-2cam", bias) for bias in BIASES))
QUICK_DURATION_S = 10.0
QUICK_IMAGE_INTERVAL_S = 0.1
#: Seeds per case by default (each seed varies the simulation and the tracker).
QUICK_SEEDS = 3
FULL_SEEDS = 10
#: Errors are sampled every this many seconds.
SAMPLE_PERIOD_S = 0.05
#: The summary and box plots use the errors from this time on (s): the targets are
#: stated after the first 5 s of each sequence, once the tracker has converged from
#: its start. errors.csv and the time series keep every sample.
SETTLE_S = 5.0
#: Columns of a task's result CSV (and of errors.csv).
ERROR_COLUMNS = ("sequence", "bias", "method", "seed", "time_s", "translation_mm",
                 "rotation_deg", "health")

#: ``report(message)``: a task's progress inside its run, e.g. "simulating 3/10 s".
Reporter = Callable[[str], None]


def sequence_stem(sequence: str) -> str:
    """``sequence`` as it appears in file names ('+' spelt 'p': arm++ -> armpp)."""
    return sequence.replace("+", "p")


def task_name(sequence: str, bias: str, seed: int) -> str:
    """The stem of a task's files in ``runs/`` and ``results/``."""
    return f"{sequence_stem(sequence)}__{bias}__seed{seed}"


@dataclass(frozen=True)
class Task:
    """One (sequence, bias variant, seed) run, evaluated with ``methods``.

    ``seed`` seeds both the simulation (scenario seed) and the tracker's particle
    filter (added to the parameters' ``image.seed``).
    """

    sequence: str
    bias: str
    seed: int
    duration_s: float | None
    min_image_interval_s: float
    methods: tuple[str, ...]
    #: Tracker parameters (YAML of TrackerParams) the methods start from; "" = defaults.
    params_yaml: str = ""

    @property
    def name(self) -> str:
        """The stem of this task's files in ``runs/`` and ``results/`` (:func:`task_name`)."""
        return task_name(self.sequence, self.bias, self.seed)

    def scenario(self) -> Scenario:
        """The preset with this task's seed; a shortened run keeps its events in it (the
        hand leaves the view, the occluder passes) by compressing their timing."""
        from drake_tracker.sim.scenario.load import load_scenario
        from drake_tracker.sim.scenario.timing import shorten_scenario

        scenario = load_scenario(f"{self.sequence}/{self.bias}")
        scenario.seed = self.seed
        if self.duration_s is not None:
            shorten_scenario(scenario, self.duration_s)
        return scenario


def make_tasks(quick: bool, seeds: int | None, methods: tuple[str, ...],
               params_yaml: str = "", duration_s: float | None = None,
               sequences: tuple[str, ...] | None = None) -> list[Task]:
    """The protocol's tasks: the quick suite (``QUICK_SEQUENCES``, 10 s, 3 seeds) or the
    full one (12 sequences at their preset durations, 10 seeds), × the bias variants.
    ``duration_s`` shortens every run (a slice for cost measurements and tests).
    ``sequences`` keeps only those; in the full mode it may also name the presets beyond
    the paper's (``EXTRA_SEQUENCES``: heavy and lasting occlusion, the mismatched world,
    the two-camera sequences), each run at its preset duration with the three biases.
    An unknown name raises ValueError listing the known ones."""
    from drake_tracker.sim.scenario.load import ALL_SEQUENCES, SEQUENCES

    if quick:
        sequences_run, duration, num_seeds = (QUICK_SEQUENCES, QUICK_DURATION_S,
                                              seeds or QUICK_SEEDS)
    else:
        sequences_run, duration, num_seeds = SEQUENCES, None, seeds or FULL_SEEDS
    if duration_s is not None:
        duration = duration_s
    cases = [(seq, bias) for seq in sequences_run for bias in BIASES]
    if quick:
        cases += list(QUICK_EXTRA_CASES)
    if sequences is not None:
        known = sorted({seq for seq, _ in cases} if quick else ALL_SEQUENCES)
        for name in sequences:
            if name not in known:
                raise ValueError(f"unknown sequence '{name}' for this mode; known: {known}")
        cases = [(seq, bias) for seq, bias in cases if seq in sequences]
        if not quick:
            cases += [(seq, bias) for seq in sequences if seq not in SEQUENCES
                      for bias in BIASES]
    return [Task(seq, bias, seed, duration, QUICK_IMAGE_INTERVAL_S, methods, params_yaml)
            for seq, bias in cases for seed in range(num_seeds)]


def task_base_params(task: Task) -> TrackerParams | None:
    """The TrackerParams a task's methods start from (None: the defaults); checked when
    the tracker resolves them (they come from ``load_tracker_params``, checked there)."""
    if not task.params_yaml:
        return None
    from pydrake.common.yaml import yaml_load_typed

    from drake_tracker.params.tracker_params import TrackerParams

    return yaml_load_typed(schema=TrackerParams, data=task.params_yaml)


def _sample_times(run, period_s: float) -> np.ndarray:
    start = run.truth_times_s[0]
    return np.arange(start, run.truth_times_s[-1] + 1e-9, period_s)


def protocol_params(run: RecordedRun, method: str, min_image_interval_s: float,
                    base_params: TrackerParams | None = None,
                    tracker_seed: int = 0) -> TrackerParams:
    """The parameters the protocol replays ``run`` with for ``method``: the method's
    (``methods.method_params``), started at the run's first true configuration, images
    paced at ``min_image_interval_s``, and ``tracker_seed`` added to ``image.seed``."""
    initial = {n: float(q) for n, q in zip(run.joint_names, run.truth_positions_rad[0])}
    params = method_params(method, base_params, initial_positions_rad=initial)
    params.image.min_image_interval_s = min_image_interval_s
    params.image.seed += int(tracker_seed)
    return params


def evaluate_run(run: RecordedRun, methods: Iterable[str], min_image_interval_s: float = 0.0,
                 sample_period_s: float = SAMPLE_PERIOD_S,
                 base_params: TrackerParams | None = None,
                 tracker_seed: int = 0, report: Reporter | None = None,
                 wall_s: dict[str, float] | None = None,
                 decision_times: dict[str, dict] | None = None
                 ) -> dict[str, dict[str, np.ndarray]]:
    """Errors of each method on one recorded run, at regular sample times.

    ``tracker_seed`` is added to the parameters' ``image.seed``. Returns
    {method: {"times_s", "translation_mm", "rotation_deg", "health"}}, and for a replayed
    method "cameras", each camera's frame against the truth
    (``camera_frames.camera_frame_errors``), and "images", the state and error just after
    each image (``health_calibration.image_errors``); each method's wall time
    goes into ``wall_s`` if given (and, before this process's first replay, the
    kernels' loading into ``wall_s["kernel_warm_up"]``), and each tracking method's
    image times (``ReplayResult.decision_times``) into ``decision_times``.
    """
    from drake_tracker.io.replay import encoders_only_X_CE, model_for_run, replay_run
    from drake_tracker.kernel_warm_up import warm_up_once

    model = model_for_run(run)
    times = _sample_times(run, sample_period_s)
    truth_index = np.clip(np.searchsorted(run.truth_times_s, times), 0,
                          len(run.truth_times_s) - 1)
    X_true = run.truth_X_CE[truth_index]
    try:
        truth_q = true_positions(run, model, truth_index)
        truth_poses = camera_poses(model, truth_q)  # once, for every replayed method
    except ValueError as error:  # e.g. a run that names its camera unlike the model
        warnings.warn(f"{error}: no per-camera errors for this run", stacklevel=2)
        truth_q = None
    out = {}
    methods = list(methods)
    for k, method in enumerate(methods, 1):
        if report:
            report(f"{method} ({k}/{len(methods)})")
        start = time.perf_counter()
        health, cameras, image_rows = np.full(len(times), -1, int), None, None
        if method == "encoders_only":
            X = encoders_only_X_CE(run, model)[truth_index]
        else:
            params = protocol_params(run, method, min_image_interval_s, base_params,
                                     tracker_seed)
            # the kernels loaded before this process's first replay, timed apart, so
            # that no replay's times include them (kernel_warm_up.warm_up_once)
            warm_up_s = warm_up_once(model, run.camera_intrinsics, params)
            if warm_up_s is not None and wall_s is not None:
                wall_s["kernel_warm_up"] = warm_up_s
            start = time.perf_counter()
            states = ImageStates()
            replay = replay_run(run, params, model, sample_times_s=times, on_image=states)
            X, health = replay.X_CE, replay.health
            image_rows = image_errors(run, states)
            if truth_q is not None:
                cameras = camera_frame_errors(model, replay.positions, truth_q, truth_poses)
            if decision_times is not None:
                decision_times[method] = replay.decision_times
        if wall_s is not None:
            wall_s[method] = time.perf_counter() - start
        ok = np.all(np.isfinite(X.reshape(len(X), -1)), axis=1)
        t_err = np.full(len(times), np.nan)
        r_err = np.full(len(times), np.nan)
        t_err[ok], r_err[ok] = pose_errors(X[ok], X_true[ok])
        out[method] = {"times_s": times, "translation_mm": t_err, "rotation_deg": r_err,
                       "health": health}
        if cameras is not None:
            out[method]["cameras"] = cameras
        if image_rows is not None:
            out[method]["images"] = image_rows
    return out


def errors_csv_text(task: Task, errors: dict[str, dict[str, np.ndarray]]) -> str:
    """The per-task result CSV (columns :data:`ERROR_COLUMNS`)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(ERROR_COLUMNS)
    for method, e in errors.items():
        health = e.get("health", np.full(len(e["times_s"]), -1))
        for t, tr, rot, h in zip(e["times_s"], e["translation_mm"], e["rotation_deg"],
                                 health, strict=True):
            state = HealthState(int(h)).name.lower() if h >= 0 else ""
            writer.writerow([task.sequence, task.bias, method, task.seed, f"{t:.4f}",
                             f"{tr:.4f}", f"{rot:.5f}", state])
    return buffer.getvalue()


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _compile_target() -> str:
    """The CPU that numba's kernels are compiled for (LLVM's name, e.g. znver4)."""
    import llvmlite.binding
    import numba

    return numba.config.CPU_NAME or llvmlite.binding.get_host_cpu_name()


def environment() -> dict:
    """What a result depends on besides its inputs: package versions, CPU, threads.

    ``cpu`` can name two CPU generations alike ("AMD EPYC": LLVM's znver3 and znver4
    here, in different sessions), so ``compile_target`` names the one the kernels were
    compiled for. Measured: the same sequence, seed and code simulated in two sessions
    gave different full-fusion errors (occlusion/time-varying seed 0: median 13.3 and
    47.3 mm), while a replay of one recorded run gives the same estimates bit for bit
    with kernels compiled for znver3 or znver4; so results across machines are samples
    of the same distribution, not bit-equal."""
    import numba

    versions = {}
    for package in ("drake", "numpy", "numba", "llvmlite"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = "not installed"
    versions["python"] = platform.python_version()
    return {"versions": versions, "cpu": _cpu_model(), "compile_target": _compile_target(),
            "cpu_count": os.cpu_count(),
            "platform": platform.platform(), "numba_threads": numba.get_num_threads(),
            "numba_threading_layer": str(numba.config.THREADING_LAYER),
            "NUMBA_NUM_THREADS": os.environ.get("NUMBA_NUM_THREADS", "")}


def _simulation_progress(report: Reporter, duration_s: float):
    """``add_systems`` hook of simulate_and_record: reports the simulated time once a
    simulated second (a publish event, which changes no state)."""
    from pydrake.systems.framework import LeafSystem

    def add(builder, world):
        probe = LeafSystem()
        probe.set_name("evaluation_progress")
        probe.DeclarePeriodicPublishEvent(
            1.0, 0.0, lambda context: report(f"simulating {context.get_time():.0f}/"
                                             f"{duration_s:g} s"))
        builder.AddSystem(probe)
        return {}

    return add


def _load_or_simulate(task: Task, cache_dir: Path | None, report: Reporter):
    from drake_tracker.io.recording import RecordedRun
    from drake_tracker.sim.record import simulate_and_record

    path = cache_dir / f"{task.name}.npz" if cache_dir is not None else None
    if path is not None and path.exists():
        report("loading the cached run")
        return RecordedRun.load(path)
    scenario = task.scenario()
    run = simulate_and_record(scenario,
                              add_systems=_simulation_progress(report, scenario.duration_s))
    if path is not None:
        partial = path.with_name(f"{task.name}.partial.npz")
        run.save(partial)
        os.replace(partial, path)  # atomic: a cached run is always complete
    return run


def compute_task(task: Task, cache_dir: Path | None = None,
                 report: Reporter | None = None) -> dict:
    """Runs one task and returns its payload: ``{"name", "csv", "cameras_csv", "images_csv"
    (the health just after each image), "environment",
    "simulated_s", "wall_s": {"simulate", <method>...}, "decision_times": {<method>:
    {"images", "update_s", "decision_s"}}}``.

    ``cache_dir``: where simulated runs are cached (``None`` when the worker shares no
    file system with the driver: the run is simulated and not kept).
    """
    report = report or (lambda message: None)
    start = time.perf_counter()
    run = _load_or_simulate(task, cache_dir, report)
    wall_s, decision_times = {"simulate": time.perf_counter() - start}, {}
    errors = evaluate_run(run, task.methods, task.min_image_interval_s,
                          base_params=task_base_params(task), tracker_seed=task.seed,
                          report=report, wall_s=wall_s, decision_times=decision_times)
    cameras = {m: e["cameras"] for m, e in errors.items() if "cameras" in e}
    times = next(iter(errors.values()))["times_s"]
    return {"name": task.name, "csv": errors_csv_text(task, errors),
            "cameras_csv": camera_errors_csv_text(task.sequence, task.bias, task.seed, times,
                                                  cameras) if cameras else "",
            "images_csv": image_health_csv_text(task.sequence, task.bias, task.seed, errors),
            "environment": environment(), "simulated_s": float(run.duration_s),
            "wall_s": wall_s, "decision_times": decision_times}


class TaskRunner:
    """Picklable ``function(task, report) -> payload`` that executors run."""

    def __init__(self, cache_dir: Path | None):
        self.cache_dir = cache_dir

    def __call__(self, task: Task, report: Reporter) -> dict:
        return compute_task(task, self.cache_dir, report)
