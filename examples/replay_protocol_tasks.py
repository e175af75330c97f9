"""Replays protocol tasks' recorded runs through full fusion at this checkout and prints
its translation error beside the stored protocol result of the same task.

For each task name (``<sequence>__<bias>__seed<N>``, e.g. ``arm__time-varying__seed8``):
p50 / p75 / p99 (mm) from 5 s and the seconds above 200 mm, before (the result file in
``--out``/results, written by ``drake-tracker evaluate``) and now (the run in
``--out``/runs replayed with the same tracker seed and image pacing)::

    python examples/replay_protocol_tasks.py arm__time-varying__seed8 \\
        occlusion__time-varying__seed8

It is how a tracker change is checked against the protocol without re-running it.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from drake_tracker.evaluation.results import ResultStore
from drake_tracker.evaluation.tasks import (
    QUICK_IMAGE_INTERVAL_S,
    SAMPLE_PERIOD_S,
    SETTLE_S,
    evaluate_run,
)
from drake_tracker.io.recording import RecordedRun

FAR_MM = 200.0


def figures(times_s: np.ndarray, error_mm: np.ndarray) -> str:
    """p50 / p75 / p99 from ``SETTLE_S`` on, and the time above ``FAR_MM``."""
    keep = (times_s >= SETTLE_S) & np.isfinite(error_mm)
    e = error_mm[keep]
    p50, p75, p99 = np.percentile(e, [50, 75, 99])
    return f"{p50:.1f} / {p75:.1f} / {p99:.1f} mm, {SAMPLE_PERIOD_S * np.sum(e > FAR_MM):.1f} s"


def stored_full_fusion(store: ResultStore, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(times, translation errors) of full fusion in task ``name``'s stored result."""
    rows = [r for r in store.read_errors(name) if r["method"] == "full_fusion"]
    return (np.array([float(r["time_s"]) for r in rows]),
            np.array([float(r["translation_mm"]) for r in rows]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("tasks", nargs="+", help="task names, e.g. arm__time-varying__seed8")
    parser.add_argument("--out", default="docs/evaluation_full",
                        help="the protocol's folder (results/ and runs/)")
    args = parser.parse_args()
    import numba

    numba.set_num_threads(1)
    root = Path(args.out)
    store = ResultStore(root)
    for name in args.tasks:
        seed = int(name.rsplit("seed", 1)[1])
        before = figures(*stored_full_fusion(store, name))
        start = time.perf_counter()
        run = RecordedRun.load(root / "runs" / f"{name}.npz")
        now = evaluate_run(run, ["full_fusion"], QUICK_IMAGE_INTERVAL_S,
                           tracker_seed=seed)["full_fusion"]
        print(f"{name}: stored {before} | now {figures(now['times_s'], now['translation_mm'])}"
              f"  ({time.perf_counter() - start:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
