"""Two evaluations compared cell by cell (``drake-tracker compare``).

Each side is one or more output folders of ``drake-tracker evaluate`` (their
``errors.csv``), pooled: the same sweep run with several random streams for the tracker
(``image.seed`` in ``--params``) gives each cell more runs. For each cell (sequence,
bias) and the chosen method, every run's median translation error from ``settle_s`` on
is taken; then, per side:

* the median over runs and the worst run, and whether ``after`` is worse or better than
  ``before`` beyond the issues' tolerance, :data:`RELATIVE_TOLERANCE` of the figure plus
  :data:`ABSOLUTE_TOLERANCE_MM`, on either;
* the change of the mean log run median, ``exp(mean_after - mean_before)``, averaged over
  the cells present on both sides, with a percentile bootstrap over each cell's runs.

Why both: at 5 seeds the tracker's random stream alone moves 7-10 cells of the quick
suite across the tolerance (docs/evaluation.md, "How far apart two runs of the same code
land"); the pooled ratio with its interval says whether a change moved the errors as a
whole.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drake_tracker.evaluation.summary import read_errors_csv, settled

#: The issues' tolerance: a cell is worse when a figure grew by more than this fraction
#: of it plus :data:`ABSOLUTE_TOLERANCE_MM`.
RELATIVE_TOLERANCE = 0.10
ABSOLUTE_TOLERANCE_MM = 0.5


@dataclass(frozen=True)
class CellChange:
    """One cell on both sides: run counts, median over runs and worst run (mm)."""

    sequence: str
    bias: str
    runs: tuple[int, int]
    median_mm: tuple[float, float]
    worst_mm: tuple[float, float]

    @property
    def worse(self) -> bool:
        """The median or the worst run grew beyond the tolerance of its figure before."""
        return any(a > b + _tolerance(b) for b, a in (self.median_mm, self.worst_mm))

    @property
    def better(self) -> bool:
        """The median or the worst run fell beyond the tolerance of its figure before."""
        return any(a < b - _tolerance(b) for b, a in (self.median_mm, self.worst_mm))


@dataclass(frozen=True)
class Comparison:
    """The cells on both sides, the cells on one side only, and the pooled ratio of run
    medians (after / before) with its 95 % bootstrap interval."""

    cells: list[CellChange]
    only_before: list[tuple[str, str]]
    only_after: list[tuple[str, str]]
    ratio: float
    ratio_interval: tuple[float, float]


def _tolerance(before_mm: float) -> float:
    return RELATIVE_TOLERANCE * before_mm + ABSOLUTE_TOLERANCE_MM


def _errors_rows(folder: Path) -> list[dict]:
    for name in ("errors.csv", "errors.csv.gz"):
        if (folder / name).exists():
            return read_errors_csv(folder / name)
    raise ValueError(f"{folder}: no errors.csv (the output folder of drake-tracker evaluate)")


def run_medians(folders: list[Path], method: str, settle_s: float
                ) -> dict[tuple[str, str], list[float]]:
    """Per cell (sequence, bias), the median translation error (mm) of each run of
    ``method`` from ``settle_s`` on, over every folder (a run: one seed of one folder).
    ValueError for a folder without ``errors.csv`` or without ``method``; a run without a
    finite sample after ``settle_s`` is left out."""
    cells: dict[tuple[str, str], list[float]] = {}
    for folder in folders:
        samples: dict[tuple[str, str, str], list[float]] = {}
        for row in settled(_errors_rows(Path(folder)), settle_s):
            if row["method"] == method:
                samples.setdefault((row["sequence"], row["bias"], row["seed"]), []).append(
                    float(row["translation_mm"]))
        if not samples:
            raise ValueError(f"{folder}: no samples of method '{method}' from "
                             f"{settle_s} s on in its errors.csv")
        for (sequence, bias, _), values in sorted(samples.items()):
            finite = np.asarray(values)[np.isfinite(values)]
            if finite.size:
                cells.setdefault((sequence, bias), []).append(float(np.median(finite)))
    return cells


def compare(before: list[Path], after: list[Path], method: str = "full_fusion",
            settle_s: float = 5.0, resamples: int = 2000, seed: int = 0) -> Comparison:
    """``after`` against ``before`` (each a list of evaluate output folders, pooled)."""
    a, b = run_medians(before, method, settle_s), run_medians(after, method, settle_s)
    keys = sorted(set(a) & set(b))
    if not keys:
        raise ValueError("the two sides share no cell (sequence, bias) of method "
                         f"'{method}'")
    cells = [CellChange(k[0], k[1], (len(a[k]), len(b[k])),
                        (float(np.median(a[k])), float(np.median(b[k]))),
                        (float(np.max(a[k])), float(np.max(b[k])))) for k in keys]
    logs_a = [np.log(np.maximum(a[k], 1e-9)) for k in keys]
    logs_b = [np.log(np.maximum(b[k], 1e-9)) for k in keys]
    change = np.mean([lb.mean() - la.mean() for la, lb in zip(logs_a, logs_b)])
    rng = np.random.default_rng(seed)
    boots = [np.mean([rng.choice(lb, lb.size).mean() - rng.choice(la, la.size).mean()
                      for la, lb in zip(logs_a, logs_b)]) for _ in range(resamples)]
    lo, hi = np.percentile(boots, [2.5, 97.5])
    return Comparison(cells, sorted(set(a) - set(b)), sorted(set(b) - set(a)),
                      float(np.exp(change)), (float(np.exp(lo)), float(np.exp(hi))))


def format_comparison(c: Comparison) -> str:
    """The comparison as text: a line per cell, then the counts and the pooled ratio."""
    lines = [f"{'sequence':<24} {'bias':<14} {'runs':>7}  median (worst run), mm: "
             "before -> after"]
    for cell in c.cells:
        verdict = " ".join(v for v, on in (("WORSE", cell.worse), ("better", cell.better))
                           if on)
        lines.append(f"{cell.sequence:<24} {cell.bias:<14} {cell.runs[0]:>3},{cell.runs[1]:<3}  "
                     f"{cell.median_mm[0]:8.2f} ({cell.worst_mm[0]:8.2f}) -> "
                     f"{cell.median_mm[1]:8.2f} ({cell.worst_mm[1]:8.2f})  {verdict}")
    for side, keys in (("before", c.only_before), ("after", c.only_after)):
        if keys:
            lines.append(f"only {side}: " + ", ".join(f"{s}/{b}" for s, b in keys))
    worse = sum(cell.worse for cell in c.cells)
    better = sum(cell.better for cell in c.cells)
    lines.append(f"cells worse {worse}, better {better} of {len(c.cells)} (beyond "
                 f"{RELATIVE_TOLERANCE:.0%} + {ABSOLUTE_TOLERANCE_MM} mm)")
    lines.append(f"run medians, after / before: x{c.ratio:.3f} (95 % bootstrap "
                 f"{c.ratio_interval[0]:.3f}-{c.ratio_interval[1]:.3f}), mean over "
                 f"{len(c.cells)} cells of the change of the mean log")
    return "\n".join(lines)
