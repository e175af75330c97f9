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
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable

#: Error bands of the hand's translation (mm): upper bounds, the last open.
BANDS = ((10.0, "<= 10 mm"), (50.0, "10-50 mm"), (math.inf, "> 50 mm"))
STATES = ("tracking", "uncertain", "lost")


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


def format_health_confusion(table: dict[str, dict]) -> str:
    """Markdown: per method, samples by state (rows) and error band (columns), then the
    two rates."""
    lines = []
    for method, t in sorted(table.items()):
        lines += [f"**{method}** ({t['samples']} samples)", "",
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
