"""``drake-tracker evaluate``: the paper's protocol (SPEC §5) on the simulated suite.

Work is split into tasks, one per (sequence, bias variant, seed): a task simulates and
records the run once (cached as ``runs/<task>.npz``), replays it through every method,
and writes ``results/<task>.csv`` with the errors sampled at regular times. A task whose
result file exists is skipped, so a stopped evaluation resumes where it stopped. Tasks
run through an :class:`Executor` (default: a process pool); a cluster executor only has
to provide ``map_unordered(function, tasks)``.

Outputs in ``--out DIR``: ``errors.csv`` (all samples), ``summary.csv`` (columns
``sequence,bias,method,metric,p1,p25,p50,p75,p99``), ``summary.txt``, box plots
``boxplot_translation_mm.png`` / ``boxplot_rotation_deg.png`` and time series
``timeseries_<sequence>_<bias>.png`` (bias changes as dotted lines, occlusion and
out-of-view intervals shaded).
"""

from __future__ import annotations

import csv
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drake_tracker.methods import METHODS, method_params
from drake_tracker.metrics import PERCENTILES, percentile_summary, pose_errors

#: The quick suite: each kind of sequence (sinusoid, free, fast, out of view, occlusion)
#: with each bias variant, shortened.
QUICK_SEQUENCES = ("s-full-arm", "s-head-arm", "arm++", "in-out-in", "occlusion")
QUICK_DURATION_S = 10.0
QUICK_IMAGE_INTERVAL_S = 0.1
BIASES = ("none", "constant", "time-varying")
#: Errors are sampled every this many seconds.
SAMPLE_PERIOD_S = 0.05
#: The summary and box plots use the errors from this time on (s): the targets are
#: stated after the first 5 s of each sequence, once the tracker has converged from
#: its start. errors.csv and the time series keep every sample.
SETTLE_S = 5.0


def task_name(sequence: str, bias: str, seed: int) -> str:
    """The stem of a task's files in ``runs/`` and ``results/``."""
    return f"{sequence.replace('+', 'p')}__{bias}__seed{seed}"


@dataclass(frozen=True)
class Task:
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
        return task_name(self.sequence, self.bias, self.seed)

    def scenario(self):
        """The preset with this task's seed; a shortened run keeps its events in it (the
        hand leaves the view, the occluder passes) by compressing their timing."""
        from drake_tracker.sim.scenario import load_scenario

        scenario = load_scenario(f"{self.sequence}/{self.bias}")
        scenario.seed = self.seed
        if self.duration_s is not None and self.duration_s < scenario.duration_s:
            d = self.duration_s
            t = scenario.trajectory
            t.excursion_start_s, t.excursion_ramp_s = 0.2 * d, 0.1 * d
            t.excursion_duration_s = 0.4 * d
            o = scenario.occluder
            o.start_s, o.end_s = 0.25 * d, 0.85 * d
            e = scenario.encoders
            e.step_period_s = min(e.step_period_s, 0.3 * d)
            e.step_transition_s = min(e.step_transition_s, 0.5 * e.step_period_s)
            scenario.duration_s = d
        return scenario


class Executor:
    """Runs tasks; ``map_unordered`` yields each task's result as it finishes."""

    def map_unordered(self, function: Callable, tasks: list) -> Iterator:
        raise NotImplementedError


class SerialExecutor(Executor):
    def map_unordered(self, function, tasks):
        for task in tasks:
            yield function(task)


def _one_numba_thread() -> None:
    # Parallelism comes from the processes; numba threads on top would oversubscribe
    # the cores (measured: 3x slower per image with 2 workers x 2 threads on 2 cores).
    import numba

    numba.set_num_threads(1)


class ProcessExecutor(Executor):
    """A local process pool, one numba thread per process."""

    def __init__(self, workers: int):
        self.workers = workers

    def map_unordered(self, function, tasks):
        with ProcessPoolExecutor(max_workers=self.workers,
                                 initializer=_one_numba_thread) as pool:
            futures = [pool.submit(function, task) for task in tasks]
            for future in as_completed(futures):
                yield future.result()


def _sample_times(run, period_s: float) -> np.ndarray:
    start = run.truth_times_s[0]
    return np.arange(start, run.truth_times_s[-1] + 1e-9, period_s)


def evaluate_run(run, methods: Iterable[str], min_image_interval_s: float = 0.0,
                 sample_period_s: float = SAMPLE_PERIOD_S, base_params=None
                 ) -> dict[str, dict[str, np.ndarray]]:
    """Errors of each method on one recorded run, at regular sample times.

    Returns {method: {"times_s", "translation_mm", "rotation_deg"}}.
    """
    from drake_tracker.offline import encoders_only_X_CE, model_for_run, replay_run

    model = model_for_run(run)
    times = _sample_times(run, sample_period_s)
    truth_index = np.clip(np.searchsorted(run.truth_times_s, times), 0,
                          len(run.truth_times_s) - 1)
    X_true = run.truth_X_CE[truth_index]
    out = {}
    initial = {n: float(q) for n, q in zip(run.joint_names, run.truth_positions_rad[0])}
    for method in methods:
        if method == "encoders_only":
            X = encoders_only_X_CE(run, model)[truth_index]
        else:
            params = method_params(method, base_params, initial_positions_rad=initial)
            params.image.min_image_interval_s = min_image_interval_s
            X = replay_run(run, params, model, sample_times_s=times).X_CE
        ok = np.all(np.isfinite(X.reshape(len(X), -1)), axis=1)
        t_err = np.full(len(times), np.nan)
        r_err = np.full(len(times), np.nan)
        t_err[ok], r_err[ok] = pose_errors(X[ok], X_true[ok])
        out[method] = {"times_s": times, "translation_mm": t_err, "rotation_deg": r_err}
    return out


def task_base_params(task: Task):
    """The TrackerParams a task's methods start from (None: the defaults)."""
    if not task.params_yaml:
        return None
    from pydrake.common.yaml import yaml_load_typed

    from drake_tracker.params import TrackerParams, validate_tracker_params

    params = yaml_load_typed(schema=TrackerParams, data=task.params_yaml)
    validate_tracker_params(params)
    return params


def run_task(task: Task, out_dir: Path) -> str:
    """Simulates (or loads) the task's run, evaluates every method, writes its CSV."""
    from drake_tracker.recording import RecordedRun
    from drake_tracker.sim.record import simulate_and_record

    result_path = out_dir / "results" / f"{task.name}.csv"
    if result_path.exists():
        return task.name
    run_path = out_dir / "runs" / f"{task.name}.npz"
    if run_path.exists():
        run = RecordedRun.load(run_path)
    else:
        run = simulate_and_record(task.scenario())
        run.save(run_path)
    errors = evaluate_run(run, task.methods, task.min_image_interval_s,
                          base_params=task_base_params(task))
    tmp = result_path.with_suffix(".tmp")
    tmp.parent.mkdir(parents=True, exist_ok=True)
    with tmp.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["sequence", "bias", "method", "seed", "time_s", "translation_mm",
                         "rotation_deg"])
        for method, e in errors.items():
            for t, tr, rot in zip(e["times_s"], e["translation_mm"], e["rotation_deg"]):
                writer.writerow([task.sequence, task.bias, method, task.seed, f"{t:.4f}",
                                 f"{tr:.4f}", f"{rot:.5f}"])
    tmp.replace(result_path)  # atomic: a result file is always complete
    return task.name


class _TaskRunner:
    """Picklable ``function(task)`` for process executors."""

    def __init__(self, out_dir: Path):
        self.out_dir = out_dir

    def __call__(self, task: Task) -> str:
        return run_task(task, self.out_dir)


def make_tasks(quick: bool, seeds: int | None, methods: tuple[str, ...],
               params_yaml: str = "") -> list[Task]:
    from drake_tracker.sim.scenario import SEQUENCES

    if quick:
        sequences, duration, interval = QUICK_SEQUENCES, QUICK_DURATION_S, QUICK_IMAGE_INTERVAL_S
        num_seeds = seeds or 1
    else:
        sequences = SEQUENCES  # the 11 of the paper and `static`
        duration, interval, num_seeds = None, QUICK_IMAGE_INTERVAL_S, seeds or 10
    return [Task(seq, bias, seed, duration, interval, methods, params_yaml)
            for seq in sequences for bias in BIASES for seed in range(num_seeds)]


def load_errors(out_dir: Path) -> list[dict]:
    rows = []
    for path in sorted((out_dir / "results").glob("*.csv")):
        with path.open() as f:
            rows.extend(csv.DictReader(f))
    return rows


def settled(rows: list[dict], settle_s: float) -> list[dict]:
    """The rows sampled at or after ``settle_s`` (s from the start of their run)."""
    return [r for r in rows if float(r["time_s"]) >= settle_s - 1e-9]


def summarize(rows: list[dict], settle_s: float = 0.0) -> list[dict]:
    """Percentiles per (sequence, bias, method, metric) over all seeds and the samples
    from ``settle_s`` on."""
    groups: dict[tuple, list[tuple[float, float]]] = {}
    for r in settled(rows, settle_s):
        key = (r["sequence"], r["bias"], r["method"])
        groups.setdefault(key, []).append((float(r["translation_mm"]), float(r["rotation_deg"])))
    summary = []
    for (seq, bias, method), values in sorted(groups.items()):
        values = np.array(values)
        for k, metric in enumerate(("translation_mm", "rotation_deg")):
            s = percentile_summary(values[:, k])
            summary.append({"sequence": seq, "bias": bias, "method": method, "metric": metric,
                            **s})
    return summary


def write_summary(summary: list[dict], out_dir: Path) -> str:
    columns = ["sequence", "bias", "method", "metric"] + [f"p{p}" for p in PERCENTILES]
    with (out_dir / "summary.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        for row in summary:
            writer.writerow({k: (f"{v:.3f}" if isinstance(v, float) else v)
                             for k, v in row.items()})
    header = (f"{'sequence':<12} {'bias':<13} {'method':<19} {'metric':<15}"
              + "".join(f"{'p' + str(p):>9}" for p in PERCENTILES))
    lines = [header, "-" * len(header)]
    for row in summary:
        lines.append(f"{row['sequence']:<12} {row['bias']:<13} {row['method']:<19} "
                     f"{row['metric']:<15}" + "".join(f"{row[f'p{p}']:>9.2f}"
                                                      for p in PERCENTILES))
    text = "\n".join(lines)
    (out_dir / "summary.txt").write_text(text + "\n")
    return text


def plot_results(rows: list[dict], out_dir: Path, settle_s: float = 0.0) -> list[Path]:
    """Box plots per metric (one box per method and sequence/bias) of the samples from
    ``settle_s`` on, and time series of every sample."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    late = settled(rows, settle_s)
    cases = sorted({(r["sequence"], r["bias"]) for r in rows})
    methods = [m for m in METHODS if any(r["method"] == m for r in rows)]
    colors = dict(zip(METHODS, ("0.6", "tab:blue", "tab:orange", "tab:green")))
    for metric, unit in (("translation_mm", "translation error (mm)"),
                         ("rotation_deg", "rotation error (deg)")):
        fig, ax = plt.subplots(figsize=(max(8, 1.2 * len(cases)), 4.5))
        width = 0.8 / max(1, len(methods))
        for i, method in enumerate(methods):
            data = []
            for case in cases:
                v = np.array([float(r[metric]) for r in late
                              if (r["sequence"], r["bias"]) == case and r["method"] == method])
                data.append(v[np.isfinite(v)])
            positions = np.arange(len(cases)) + (i - (len(methods) - 1) / 2) * width
            bp = ax.boxplot(data, positions=positions, widths=width * 0.9, whis=(1, 99),
                            showfliers=False, patch_artist=True)
            for patch in bp["boxes"]:
                patch.set_facecolor(colors[method])
            ax.plot([], [], color=colors[method], lw=6, label=method)
        ax.set_xticks(np.arange(len(cases)))
        ax.set_xticklabels([f"{s}\n{b}" for s, b in cases], fontsize=7)
        ax.set_yscale("log")
        ax.set_ylabel(unit + ", whiskers p1-p99")
        if settle_s > 0:
            ax.set_title(f"errors from t = {settle_s:g} s on", fontsize=9)
        ax.legend(fontsize=8)
        fig.tight_layout()
        path = out_dir / f"boxplot_{metric}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    for seq, bias in cases:
        written.append(_plot_time_series(rows, seq, bias, methods, colors, out_dir, plt,
                                         settle_s))
    return written


def _stored_scenario(out_dir: Path, seq: str, bias: str, seed: int):
    """The scenario a stored run was simulated with (the preset if the run is gone)."""
    from pydrake.common.yaml import yaml_load_typed

    from drake_tracker.recording import RecordedRun
    from drake_tracker.sim.scenario import Scenario, load_scenario

    path = out_dir / "runs" / f"{task_name(seq, bias, seed)}.npz"
    if path.exists():
        text = RecordedRun.load(path).scenario_yaml
        if text:
            return yaml_load_typed(schema=Scenario, data=text)
    return load_scenario(f"{seq}/{bias}", validate=False)


def _plot_time_series(rows, seq, bias, methods, colors, out_dir, plt, settle_s) -> Path:
    seed0 = min(int(r["seed"]) for r in rows if (r["sequence"], r["bias"]) == (seq, bias))
    scenario = _stored_scenario(out_dir, seq, bias, seed0)
    fig, ax = plt.subplots(figsize=(9, 3.5))
    t_end = 0.0
    for method in methods:
        sel = [r for r in rows if (r["sequence"], r["bias"], r["method"], int(r["seed"]))
               == (seq, bias, method, seed0)]
        t = np.array([float(r["time_s"]) for r in sel])
        e = np.array([float(r["translation_mm"]) for r in sel])
        if len(t):
            t_end = max(t_end, t[-1])
        ax.plot(t, e, color=colors[method], label=method, lw=1)
    if scenario.encoders.bias == "steps":
        for k in range(1, int(t_end / scenario.encoders.step_period_s) + 1):
            ax.axvline(k * scenario.encoders.step_period_s, color="k", ls=":", lw=0.8)
    if scenario.occluder.enabled:
        ax.axvspan(scenario.occluder.start_s, min(scenario.occluder.end_s, t_end),
                   color="0.85", label="occluded")
    if scenario.trajectory.kind == "in-out-in":
        tr = scenario.trajectory
        ax.axvspan(tr.excursion_start_s, min(t_end, tr.excursion_start_s
                                             + 2 * tr.excursion_ramp_s + tr.excursion_duration_s),
                   color="0.9", label="leaving / out of view")
    if 0 < settle_s < t_end:
        ax.axvline(settle_s, color="tab:red", ls="--", lw=0.8, label="summary from here")
    ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("translation error (mm)")
    ax.set_title(f"{seq} / {bias} (seed {seed0})")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    path = out_dir / f"timeseries_{seq.replace('+', 'p')}_{bias}.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def evaluate(tasks: list[Task], out_dir: Path, executor: Executor | None = None,
             settle_s: float = SETTLE_S, progress: bool = True) -> list[dict]:
    """Runs the tasks not done yet in ``out_dir`` and writes errors.csv, the summary
    (summary.csv, summary.txt) and the figures there; returns the summary rows."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    _check_same_protocol(tasks, out_dir)
    executor = executor or SerialExecutor()
    todo = [t for t in tasks if not (out_dir / "results" / f"{t.name}.csv").exists()]
    if progress:
        print(f"{len(tasks)} tasks, {len(tasks) - len(todo)} already done, {len(todo)} to "
              f"run")
    start = time.perf_counter()
    for done, name in enumerate(executor.map_unordered(_TaskRunner(out_dir), todo), 1):
        if progress:
            elapsed = time.perf_counter() - start
            bar = "#" * int(30 * done / max(1, len(todo)))
            sys.stderr.write(f"\r[{bar:<30}] {done}/{len(todo)} {elapsed:6.0f} s  {name}    ")
            sys.stderr.flush()
    if todo and progress:
        sys.stderr.write("\n")
    names = {t.name for t in tasks}
    rows = [r for r in load_errors(out_dir)
            if task_name(r["sequence"], r["bias"], int(r["seed"])) in names]
    with (out_dir / "errors.csv").open("w", newline="") as f:
        if rows:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    summary = summarize(rows, settle_s)
    text = write_summary(summary, out_dir)
    plot_results(rows, out_dir, settle_s)
    if progress:
        print(text)
        print(f"wrote {out_dir}/summary.csv (errors from t = {settle_s:g} s on), errors.csv "
              f"and figures in {time.perf_counter() - start:.0f} s")
    return summary


def _check_same_protocol(tasks: list[Task], out_dir: Path) -> None:
    """Result files are named by sequence, bias and seed only; refuse to mix results of
    different durations, image rates, methods or parameters in one folder."""
    import json

    settings = sorted({json.dumps([t.duration_s, t.min_image_interval_s, list(t.methods),
                                   t.params_yaml])
                       for t in tasks})
    path = out_dir / "protocol.json"
    if path.exists():
        stored = json.loads(path.read_text())
        if stored != settings:
            raise ValueError(f"{out_dir} holds results of another protocol (duration, image "
                             f"interval, methods or parameters: {stored}); use a new --out folder")
    else:
        path.write_text(json.dumps(settings))


def run_evaluate(args) -> int:
    methods = tuple(args.methods.split(",")) if args.methods else METHODS
    for m in methods:
        if m not in METHODS:
            raise SystemExit(f"unknown method '{m}'; known: {list(METHODS)}")
    if args.settle_s < 0:
        raise SystemExit(f"--settle-s must be >= 0, got {args.settle_s}")
    params_yaml = ""
    if getattr(args, "params", None):
        from drake_tracker.params import load_tracker_params, tracker_params_to_yaml

        params_yaml = tracker_params_to_yaml(load_tracker_params(args.params))
    tasks = make_tasks(args.quick, args.seeds, methods, params_yaml)
    if getattr(args, "sequences", None):
        wanted = args.sequences.split(",")
        known = sorted({t.sequence for t in tasks})
        for name in wanted:
            if name not in known:
                raise SystemExit(f"unknown sequence '{name}' for this mode; known: {known}")
        tasks = [t for t in tasks if t.sequence in wanted]
    executor = SerialExecutor() if args.workers <= 1 else ProcessExecutor(args.workers)
    print(f"{args.workers} worker(s)")
    try:
        evaluate(tasks, Path(args.out), executor, args.settle_s)
    except ValueError as e:
        raise SystemExit(str(e)) from None
    return 0
