"""How far to trust the health state: the tracker's state against the hand's error.

Every error sample of a tracker method carries the health state the tracker reported
then (``errors.csv``'s ``health``: ``tracking``, ``uncertain``, ``lost``; empty before
the first reading and for the encoders alone). :func:`health_confusion` counts the
samples from ``settle_s`` on by state and by the hand's translation error in bands
(<= 10 mm, 10-50, > 50), and two rates state what the state is worth to a controller:

* ``tracking_within_10mm``: of the samples that say ``tracking``, the fraction within
  10 mm (target: at least 99 %);
* ``tracking_when_over_50mm``: of the samples more than 50 mm off, the fraction that say
  ``tracking`` (target: under 1 %).

The samples come every 0.05 s, whether an image came or not; issue 43 states its targets
per image. :class:`ImageStates` records what the tracker says just after each image it
takes (its state and its estimate, at its latest reading), and the same count over those
rows (``image_health.csv``) gives the figures per image.
"""

from __future__ import annotations

import csv
import io
import math
from collections import Counter
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.robustness.health import HealthState

if TYPE_CHECKING:
    from drake_tracker.core.sensors.depth_frames import DepthFrame
    from drake_tracker.io.recording import RecordedRun
    from drake_tracker.tracker import Tracker

#: Error bands of the hand's translation (mm): upper bounds, the last open.
BANDS = ((10.0, "<= 10 mm"), (50.0, "10-50 mm"), (math.inf, "> 50 mm"))
STATES = ("tracking", "uncertain", "lost")


#: Columns of a task's per-image health rows (``results/images/<task>.csv.gz``).
IMAGE_COLUMNS = ("sequence", "bias", "method", "seed", "time_s", "translation_mm",
                 "health")


class ImageStates:
    """``replay_run``'s ``on_image``: after each image the tracker takes (its image
    update observes it: ``DecisionTimes.images``; a frame not due at
    ``image.min_image_interval_s``, or refused before, is not taken), its latest
    reading's time, the hand it then reports (``X_CE``) and its health state."""

    def __init__(self) -> None:
        self.times_s: list[float] = []
        self.X_CE: list[np.ndarray] = []
        self.states: list[int] = []
        self._observed = 0

    def __call__(self, tracker: Tracker, frame: DepthFrame) -> None:
        observed = sum(c.images.times.images for c in tracker.channels.values()
                       if c.images is not None)
        taken, self._observed = observed > self._observed, observed
        if not taken:
            return
        estimate = tracker.estimate()
        self.times_s.append(float(estimate.time_s))
        self.X_CE.append(np.asarray(estimate.X_CE, float))
        self.states.append(int(estimate.health.state))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(K,) times, (K, 4, 4) hands, (K,) ``HealthState`` values."""
        return (np.asarray(self.times_s, float),
                np.asarray(self.X_CE, float).reshape(-1, 4, 4),
                np.asarray(self.states, int))


def image_errors(run: RecordedRun, states: ImageStates) -> dict[str, np.ndarray]:
    """The hand's translation error just after each image that ``states`` recorded:
    {"times_s", "translation_mm", "health"}. The truth is interpolated linearly to the
    estimate's time (its latest reading): the images fall between the truth's samples
    (every 10 ms in a simulated run), and the hand crosses the camera's view at up to
    2 m/s, so the next sample would add up to 20 mm that is not the tracker's."""
    times_s, X_CE, health = states.arrays()
    truth = run.truth_X_CE[:, :3, 3]
    p_true = np.stack([np.interp(times_s, run.truth_times_s, truth[:, i])
                       for i in range(3)], axis=-1).reshape(-1, 3)
    error = 1e3 * np.linalg.norm(X_CE[:, :3, 3] - p_true, axis=-1)
    return {"times_s": times_s, "translation_mm": error, "health": health}


def image_health_csv_text(sequence: str, bias: str, seed: int, errors: dict[str, dict]
                          ) -> str:
    """The per-image rows (columns :data:`IMAGE_COLUMNS`) of one task's ``errors``
    (``evaluate_run``'s, whose tracking methods carry ``"images"``); "" if none."""
    rows = [(method, e["images"]) for method, e in errors.items() if "images" in e]
    if not rows:
        return ""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(IMAGE_COLUMNS)
    for method, im in rows:
        for t, tr, h in zip(im["times_s"], im["translation_mm"], im["health"], strict=True):
            writer.writerow([sequence, bias, method, seed, f"{t:.4f}", f"{tr:.4f}",
                             HealthState(int(h)).name.lower()])
    return buffer.getvalue()


def band(translation_mm: float) -> str:
    """The band of an error (mm)."""
    for upper, name in BANDS:
        if translation_mm <= upper:
            return name
    return BANDS[-1][1]


def health_confusion(rows: Iterable[dict], settle_s: float = 0.0) -> dict[str, dict]:
    """{method: {"counts": {(state, band): samples}, "samples": n,
    "tracking_within_10mm": fraction or NaN, "tracking_when_over_50mm": fraction or NaN}}
    over the rows (``errors.csv``'s dicts) from ``settle_s`` on that have a health state
    and a finite error."""
    counts: dict[str, Counter] = {}
    for row in rows:
        state = row.get("health", "")
        error = float(row["translation_mm"])
        if not state or float(row["time_s"]) < settle_s or not math.isfinite(error):
            continue
        counts.setdefault(row["method"], Counter())[(state, band(error))] += 1
    out = {}
    for method, c in counts.items():
        tracking = sum(c[("tracking", b)] for _, b in BANDS)
        over = sum(c[(s, BANDS[-1][1])] for s in STATES)
        out[method] = {
            "counts": dict(c), "samples": sum(c.values()),
            "tracking_within_10mm": c[("tracking", BANDS[0][1])] / tracking
            if tracking else math.nan,
            "tracking_when_over_50mm": c[("tracking", BANDS[-1][1])] / over
            if over else math.nan,
        }
    return out


def format_health_confusion(table: dict[str, dict], unit: str = "samples") -> str:
    """Markdown: per method, ``unit`` (samples, or images) by state (rows) and error band
    (columns), then the two rates."""
    lines = []
    for method, t in sorted(table.items()):
        lines += [f"**{method}** ({t['samples']} {unit})", "",
                  "| state | " + " | ".join(name for _, name in BANDS) + " |",
                  "|---|" + "---|" * len(BANDS)]
        for state in STATES:
            cells = [str(t["counts"].get((state, name), 0)) for _, name in BANDS]
            lines.append(f"| {state} | " + " | ".join(cells) + " |")
        lines += ["", f"- says tracking: within 10 mm on "
                      f"{100 * t['tracking_within_10mm']:.2f} % (target >= 99 %)",
                  f"- more than 50 mm off: says tracking on "
                  f"{100 * t['tracking_when_over_50mm']:.2f} % (target < 1 %)", ""]
    return "\n".join(lines)
