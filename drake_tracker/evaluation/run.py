"""The evaluation's driver: runs the tasks not done yet through an executor (retrying
a failed task once), writes each result as it comes back, shows progress, and writes
the summary and figures. Also the ``drake-tracker evaluate`` command."""

from __future__ import annotations

import csv
import json
import signal
import time
from collections.abc import Callable
from contextlib import closing
from pathlib import Path
from typing import TYPE_CHECKING

from drake_tracker.evaluation.camera_frames import camera_summary
from drake_tracker.evaluation.executor_choice import make_executor
from drake_tracker.evaluation.executors import Executor, SerialExecutor
from drake_tracker.evaluation.health_calibration import (
    format_health_confusion,
    health_confusion,
)
from drake_tracker.evaluation.methods import METHODS
from drake_tracker.evaluation.paper_comparison import format_paper_comparison, paper_comparison
from drake_tracker.evaluation.plots import plot_results
from drake_tracker.evaluation.results import (
    ResultStore,
    check_same_protocol,
    record_environments,
)
from drake_tracker.evaluation.summary import summarize, write_summary
from drake_tracker.evaluation.tasks import (
    SAMPLE_PERIOD_S,
    SETTLE_S,
    Task,
    TaskRunner,
    make_tasks,
)

if TYPE_CHECKING:
    import argparse

#: How many times a task is tried before it is reported as failed.
ATTEMPTS = 2


def run_tasks(executor: Executor, function: Callable, tasks: list[Task],
              on_result: Callable[[dict], None], progress: bool = True) -> dict[str, str]:
    """Runs ``function(task, report)`` on every task through ``executor``; each payload
    goes to ``on_result`` as it arrives. A failed task is run once more after the
    others; returns {task name: error} of those that failed every attempt."""
    from tqdm import tqdm

    failures: dict[str, str] = {}
    running: dict[str, str] = {}
    bar = tqdm(total=len(tasks), unit="task", disable=not progress or not tasks,
               dynamic_ncols=True, mininterval=0.5)

    def on_progress(name: str, message: str) -> None:
        running[name] = message
        bar.set_postfix_str(" | ".join(f"{n}: {m}" for n, m in running.items()),
                            refresh=False)
        bar.refresh()

    todo = list(tasks)
    try:
        for attempt in range(1, ATTEMPTS + 1):
            again = []
            with closing(executor.map_unordered(function, todo, on_progress)) as outcomes:
                for outcome in outcomes:
                    name = outcome.task.name
                    running.pop(name, None)
                    if outcome.payload is not None:
                        on_result(outcome.payload)
                        failures.pop(name, None)
                        bar.update(1)
                        continue
                    failures[name] = outcome.error or "unknown error"
                    last = failures[name].strip().splitlines()[-1:] or ["?"]
                    if attempt < ATTEMPTS:
                        again.append(outcome.task)
                        bar.write(f"task {name} failed ({last[0]}); it runs again at the end")
                    else:
                        bar.write(f"task {name} failed again ({last[0]}); reported in "
                                  f"failures.json")
                        bar.update(1)
            todo = again
            if not todo:
                break
    finally:
        bar.close()
    return failures


def evaluate(tasks: list[Task], out_dir: Path, executor: Executor | None = None,
             settle_s: float = SETTLE_S, progress: bool = True) -> list[dict]:
    """Runs the tasks not done yet in ``out_dir`` and writes errors.csv, the summary
    (summary.csv, summary.txt), paper_comparison.md, health_confusion.md (the health
    state against the error: ``health_calibration.py``), cameras.csv and cameras.md
    (each camera's frame against the truth: ``camera_frames.py``), failures.json and the
    figures there; returns the summary rows."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    check_same_protocol(tasks, out_dir)
    executor = executor or SerialExecutor()
    store = ResultStore(out_dir)
    todo = [t for t in tasks if not store.is_done(t)]
    if progress:
        print(f"{len(tasks)} tasks, {len(tasks) - len(todo)} already done, {len(todo)} to "
              f"run ({executor.describe()})", flush=True)
    start = time.perf_counter()
    runner = TaskRunner(out_dir / "runs" if executor.shares_files else None)
    failures = run_tasks(executor, runner, todo, store.write, progress)
    store.write_failures(failures)
    rows = store.load_rows(tasks)
    _write_rows(out_dir / "errors.csv", rows)
    metas = store.load_metas(tasks)
    record_environments(out_dir, metas)
    summary = summarize(rows, settle_s)
    if rows and not summary and progress:
        print(f"no samples from --settle-s {settle_s:g} s on: the runs are shorter; the "
              f"summary is empty", flush=True)
    text = write_summary(summary, out_dir, failures)
    (out_dir / "paper_comparison.md").write_text(
        format_paper_comparison(paper_comparison(summary)) + "\n")
    health = _write_health(rows, store.load_image_rows(tasks), out_dir, settle_s)
    _write_camera_frames(store.load_camera_rows(tasks), out_dir, settle_s)
    if rows:
        first_seed = {}
        for t in tasks:
            key = (t.sequence, t.bias)
            if store.is_done(t) and (key not in first_seed or t.seed < first_seed[key].seed):
                first_seed[key] = t
        plot_results(rows, out_dir, settle_s,
                     {key: t.scenario() for key, t in first_seed.items()})
    if progress:
        print(text)
        print(health)
        print(cost_line(metas, time.perf_counter() - start, len(todo)))
        print(f"wrote {out_dir}/summary.csv (errors from t = {settle_s:g} s on), errors.csv, "
              f"protocol.json and figures")
    return summary


def _write_rows(path: Path, rows: list[dict]) -> None:
    """``rows`` (dicts with the same keys) as a CSV with a header (empty: no rows)."""
    with path.open("w", newline="") as f:
        if rows:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


def _write_health(rows: list[dict], image_rows: list[dict], out_dir: Path,
                  settle_s: float) -> str:
    """``health_confusion.md``: the health state against the hand's error at the error
    samples and, when the tasks stored them, just after each image (``image_health.csv``);
    returns its text."""
    text = (f"## At the error samples (every {SAMPLE_PERIOD_S:g} s)\n\n"
            + format_health_confusion(health_confusion(rows, settle_s)))
    if image_rows:
        _write_rows(out_dir / "image_health.csv", image_rows)
        text += ("\n## Just after each image (the state it left, the hand then)\n\n"
                 + format_health_confusion(health_confusion(image_rows, settle_s), "images"))
    (out_dir / "health_confusion.md").write_text(
        f"# The health state against the hand's error, from {settle_s:g} s on\n\n"
        + text + "\n")
    return text


def _write_camera_frames(rows: list[dict], out_dir: Path, settle_s: float) -> None:
    """``cameras.csv`` and ``cameras.md``: each camera's frame against the truth
    (``camera_frames.py``), when some task has them."""
    if not rows:
        return
    _write_rows(out_dir / "cameras.csv", rows)
    (out_dir / "cameras.md").write_text(
        "# Each camera's frame against the truth, over the whole run\n\n"
        + camera_summary(rows, settle_s) + "\n")


def cost_line(metas: list[dict], wall_s: float, tasks_run: int) -> str:
    """Wall time per simulated task-second, summed over the workers' tasks."""
    timed = [m for m in metas if "wall_s" in m and m.get("simulated_s")]
    if not timed:
        return f"{tasks_run} task(s) run in {wall_s:.0f} s"
    task_wall = sum(sum(m["wall_s"].values()) for m in timed)
    simulated = sum(m["simulated_s"] for m in timed)
    line = (f"{tasks_run} task(s) run in {wall_s:.0f} s; stored tasks: "
            f"{task_wall / simulated:.2f} s of worker time per simulated task-second "
            f"({len(timed)} tasks, {simulated:.0f} task-seconds)")
    times = [t for m in timed for t in m.get("decision_times", {}).values()]
    update_s = sum(t["update_s"] for t in times)
    if update_s > 0:  # tasks stored before the decision was timed have none
        share = 100 * sum(t["decision_s"] for t in times) / update_s
        images = sum(t["images"] for t in times)
        line += (f"; the per-image decision took {share:.1f} % of the image updates' time "
                 f"({images} images of {len(times)} replays)")
    return line


class TerminatedError(BaseException):
    """SIGTERM, turned into an exception so that executors stop their workers. A stop
    request, not an error: like KeyboardInterrupt it is no ``Exception``, so a task's
    guard (``executors.run_guarded``) does not take it for the task's failure. Measured
    with ``Exception``: SIGTERM to a serial evaluation (``--workers 1``) failed the
    running task, and the sweep went on to the end."""


def _raise_stopped(signum, frame):
    raise TerminatedError(signal.Signals(signum).name)


def _stop_signal(error: BaseException) -> BaseException | None:
    """The KeyboardInterrupt or TerminatedError behind ``error``, if any (a signal that
    arrives inside Ray's compiled code comes back wrapped in a SystemError)."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt | TerminatedError):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return None


def _parse(args) -> list[Task]:
    methods = tuple(args.methods.split(",")) if args.methods else METHODS
    for m in methods:
        if m not in METHODS:
            raise SystemExit(f"unknown method '{m}'; known: {list(METHODS)}")
    if args.settle_s < 0:
        raise SystemExit(f"--settle-s must be >= 0, got {args.settle_s}")
    if args.workers < 1:
        raise SystemExit(f"--workers must be >= 1, got {args.workers}")
    if args.seeds is not None and args.seeds < 1:
        raise SystemExit(f"--seeds must be >= 1, got {args.seeds}")
    if args.duration is not None and not args.duration > 0:
        raise SystemExit(f"--duration must be > 0, got {args.duration}")
    if args.address and args.executor != "ray":
        raise SystemExit("--address is for --executor ray")
    params_yaml = ""
    if args.params:
        from drake_tracker.params.loading import load_tracker_params, tracker_params_to_yaml

        params_yaml = tracker_params_to_yaml(load_tracker_params(args.params))
    wanted = tuple(args.sequences.split(",")) if args.sequences else None
    try:
        tasks = make_tasks(args.quick, args.seeds, methods, params_yaml, args.duration,
                           sequences=wanted)
    except ValueError as e:
        raise SystemExit(str(e)) from None
    return tasks


def run_evaluate(args: argparse.Namespace) -> int:
    """``drake-tracker evaluate``: 0 when every task has a result, 1 when some failed,
    130 / 143 when stopped by Ctrl-C / SIGTERM (finished tasks are kept)."""
    tasks = _parse(args)
    try:
        executor = make_executor(args.executor, args.workers, args.address)
    except ImportError as e:
        raise SystemExit(str(e)) from None
    previous = signal.signal(signal.SIGTERM, _raise_stopped)
    try:
        with executor:
            signal.signal(signal.SIGTERM, _raise_stopped)  # Ray's init sets its own
            evaluate(tasks, Path(args.out), executor, args.settle_s)
    except ValueError as e:
        raise SystemExit(str(e)) from None
    except BaseException as e:
        stop = _stop_signal(e)
        if stop is None:
            raise
        done = sum(ResultStore(Path(args.out)).is_done(t) for t in tasks)
        print(f"\nstopped ({str(stop) or 'Ctrl-C'}): {done} of {len(tasks)} tasks have results in "
              f"{args.out}; the same command resumes", flush=True)
        return 143 if isinstance(stop, TerminatedError) else 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    failures = json.loads((Path(args.out) / "failures.json").read_text())
    return 1 if failures else 0
