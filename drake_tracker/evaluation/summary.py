"""Summaries of the evaluation's error samples: per (sequence, bias, method, metric),
percentiles of all seeds' samples pooled, and the spread over seeds (the median over
seeds of each seed's median, and the worst seed)."""

from __future__ import annotations

import csv
import gzip
import io
from pathlib import Path

import numpy as np

from drake_tracker.metrics import PERCENTILES, percentile_summary

#: summary.csv's columns.
SUMMARY_COLUMNS = (["sequence", "bias", "method", "metric"] + [f"p{p}" for p in PERCENTILES]
                   + ["seeds", "median_over_seeds", "worst_seed_median", "worst_seed"])
METRICS = ("translation_mm", "rotation_deg")


def read_errors_csv(path: Path) -> list[dict]:
    """The rows of an errors CSV (``errors.csv``, or a task's gzip-compressed one)."""
    raw = Path(path).read_bytes()
    text = gzip.decompress(raw).decode() if str(path).endswith(".gz") else raw.decode()
    return list(csv.DictReader(io.StringIO(text)))


def is_settled(row: dict, settle_s: float) -> bool:
    """Whether ``row`` was sampled at or after ``settle_s`` (s from the start of its run;
    the CSV's rounding of the time allowed for)."""
    return float(row["time_s"]) >= settle_s - 1e-9


def settled(rows: list[dict], settle_s: float) -> list[dict]:
    """The rows sampled at or after ``settle_s`` (s from the start of their run)."""
    return [r for r in rows if is_settled(r, settle_s)]


def summarize(rows: list[dict], settle_s: float = 0.0) -> list[dict]:
    """One row per (sequence, bias, method, metric) over the samples from ``settle_s``
    on: ``p1``..``p99`` of all seeds' samples together; ``seeds``; ``median_over_seeds``
    (the median of the per-seed medians); ``worst_seed_median`` and ``worst_seed`` (the
    seed with the largest median)."""
    groups: dict[tuple, dict[int, list[tuple[float, float]]]] = {}
    for r in settled(rows, settle_s):
        key = (r["sequence"], r["bias"], r["method"])
        groups.setdefault(key, {}).setdefault(int(r["seed"]), []).append(
            (float(r["translation_mm"]), float(r["rotation_deg"])))
    summary = []
    for (seq, bias, method), by_seed in sorted(groups.items()):
        seeds = sorted(by_seed)
        pooled = np.array([v for s in seeds for v in by_seed[s]])
        for k, metric in enumerate(METRICS):
            per_seed = np.array([percentile_summary(np.array(by_seed[s])[:, k])["p50"]
                                 for s in seeds])
            finite = np.isfinite(per_seed)
            worst = int(np.argmax(np.where(finite, per_seed, np.inf)))
            summary.append({
                "sequence": seq, "bias": bias, "method": method, "metric": metric,
                **percentile_summary(pooled[:, k]), "seeds": len(seeds),
                "median_over_seeds": float(np.median(per_seed)),
                "worst_seed_median": float(per_seed[worst]), "worst_seed": seeds[worst]})
    return summary


def format_summary(summary: list[dict], failures: dict[str, str] | None = None) -> str:
    """summary.txt: a fixed-width table, then the failed tasks if any."""
    header = (f"{'sequence':<12} {'bias':<13} {'method':<19} {'metric':<15}"
              + "".join(f"{'p' + str(p):>9}" for p in PERCENTILES)
              + f"{'seeds':>6}{'med/seed':>10}{'worst':>9}{'seed':>5}")
    lines = [header, "-" * len(header)]
    for row in summary:
        lines.append(f"{row['sequence']:<12} {row['bias']:<13} {row['method']:<19} "
                     f"{row['metric']:<15}"
                     + "".join(f"{row[f'p{p}']:>9.2f}" for p in PERCENTILES)
                     + f"{row['seeds']:>6}{row['median_over_seeds']:>10.2f}"
                     f"{row['worst_seed_median']:>9.2f}{row['worst_seed']:>5}")
    if failures:
        lines += ["", f"{len(failures)} task(s) failed twice and are not in the table "
                      "(failures.json has the errors):"]
        for name, error in sorted(failures.items()):
            last = error.strip().splitlines()[-1] if error.strip() else "?"
            lines.append(f"  {name}: {last}")
    return "\n".join(lines)


def write_summary(summary: list[dict], out_dir: Path,
                  failures: dict[str, str] | None = None) -> str:
    """Writes ``summary.csv`` (columns :data:`SUMMARY_COLUMNS`) and ``summary.txt``;
    returns the text."""
    out_dir = Path(out_dir)
    with (out_dir / "summary.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=SUMMARY_COLUMNS)
        writer.writeheader()
        for row in summary:
            writer.writerow({k: (f"{v:.3f}" if isinstance(v, float) else v)
                             for k, v in row.items()})
    text = format_summary(summary, failures)
    (out_dir / "summary.txt").write_text(text + "\n")
    return text
