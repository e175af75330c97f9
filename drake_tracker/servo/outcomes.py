"""What a servo run achieved at each target: final error and time to settle.

All errors are of the TRUE hand pose in the TRUE camera frame against the target (what
the robot actually did), whatever the controller was fed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from drake_tracker.metrics import pose_errors
from drake_tracker.servo.config import ServoStudyConfig
from drake_tracker.servo.study import ServoRun


@dataclass
class TargetOutcome:
    """One run at one target."""

    target: int
    #: True error at the end of the target's dwell (mm, deg).
    final_translation_mm: float
    final_rotation_deg: float
    #: From the target's start until the true position error stays below the settle
    #: threshold to the end of the dwell (s); None when it never does.
    settle_time_s: float | None

    def as_dict(self) -> dict:
        """JSON-ready fields."""
        return asdict(self)


def true_errors(run: ServoRun, config: ServoStudyConfig) -> tuple[np.ndarray, np.ndarray]:
    """(T,) true translation (mm) and rotation (deg) errors of the hand against the target
    of each sample (the first target during the hold)."""
    targets = np.array([t.X_CT().GetAsMatrix4() for t in config.targets])
    return pose_errors(run.true_X_CE, targets[np.maximum(run.target_index, 0)])


def settle_time(times_s: np.ndarray, error_m: np.ndarray, start_s: float,
                threshold_m: float) -> float | None:
    """Time after ``start_s`` from which every sample of ``error_m`` is below
    ``threshold_m`` (samples at and after ``start_s``); None when the last is not."""
    keep = times_s >= start_s - 1e-9
    t, e = times_s[keep], error_m[keep]
    if len(e) == 0 or e[-1] >= threshold_m:
        return None
    above = np.flatnonzero(e >= threshold_m)
    first_good = 0 if len(above) == 0 else above[-1] + 1
    return float(t[first_good] - start_s)


def target_outcomes(run: ServoRun, config: ServoStudyConfig) -> list[TargetOutcome]:
    """Each target's final error and settle time in ``run`` (targets the run did not
    reach in time are left out)."""
    translation_mm, rotation_deg = true_errors(run, config)
    outcomes = []
    for k, (start, end) in enumerate(config.target_windows()):
        inside = (run.times_s > start + 1e-9) & (run.times_s <= end + 1e-9) & (
            run.target_index == k)
        if not inside.any():
            continue
        t, e = run.times_s[inside], translation_mm[inside] / 1000.0
        last = np.flatnonzero(inside)[-1]
        outcomes.append(TargetOutcome(
            k, float(translation_mm[last]), float(rotation_deg[last]),
            settle_time(t, e, start, config.settle_threshold_m)))
    return outcomes


def format_outcome_table(outcomes: dict[str, list[TargetOutcome]], labels: dict[str, str],
                         threshold_mm: float) -> str:
    """A Markdown table: one row per run and target."""
    lines = [f"| run | target | final translation (mm) | final rotation (deg) | "
             f"settle within {threshold_mm:g} mm (s) |", "|---|---|---|---|---|"]
    for feedback, rows in outcomes.items():
        for o in rows:
            settle = "never" if o.settle_time_s is None else f"{o.settle_time_s:.2f}"
            lines.append(f"| {labels[feedback]} | {o.target + 1} | "
                         f"{o.final_translation_mm:.1f} | {o.final_rotation_deg:.2f} | "
                         f"{settle} |")
    return "\n".join(lines)
