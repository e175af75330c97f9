"""Shared pieces of the error plots: readable method names, one colour per method, and
marks for a scenario's events (bias steps, occlusion, the arm out of view)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from drake_tracker.sim.scenario.load import Scenario

#: Method identifier -> the name a plot's legend shows.
METHOD_LABELS: dict[str, str] = {
    "encoders_only": "encoders only",
    "camera_offset_only": "camera offset only",
    "full_fusion": "full fusion (tracker)",
    "vision_only": "vision only",
}

#: Method identifier -> line colour (those of the evaluation's figures).
METHOD_COLORS: dict[str, str] = {
    "encoders_only": "0.45",
    "camera_offset_only": "tab:blue",
    "full_fusion": "tab:orange",
    "vision_only": "tab:green",
}


def method_label(method: str) -> str:
    """The readable name of ``method`` (the identifier itself if unknown)."""
    return METHOD_LABELS.get(method, method.replace("_", " "))


def scenario_events(scenario: Scenario, t_end: float) -> dict[str, list]:
    """The times a plot of ``scenario`` up to ``t_end`` should mark:
    ``{"bias_steps": [t, ...], "occluded": [(t0, t1)], "out_of_view": [(t0, t1)]}``."""
    events = {"bias_steps": [], "occluded": [], "out_of_view": []}
    encoders = scenario.encoders
    if encoders.bias == "steps" and encoders.step_period_s > 0:
        count = int(np.floor(t_end / encoders.step_period_s + 1e-9))
        events["bias_steps"] = [k * encoders.step_period_s for k in range(1, count + 1)]
    from drake_tracker.sim.scenario.config import occlusion_windows

    events["occluded"] = occlusion_windows(scenario, t_end)
    t = scenario.trajectory
    if t.kind == "in-out-in" and t.excursion_start_s < t_end:
        back = t.excursion_start_s + 2 * t.excursion_ramp_s + t.excursion_duration_s
        events["out_of_view"].append((t.excursion_start_s, min(back, t_end)))
    return events


def mark_scenario_events(ax: Axes, scenario: Scenario, t_end: float) -> None:
    """Dotted lines at the bias steps, grey spans while occluded or out of view, each
    labelled once for the legend."""
    events = scenario_events(scenario, t_end)
    for k, t in enumerate(events["bias_steps"]):
        ax.axvline(t, color="k", ls=":", lw=0.8, label="bias step" if k == 0 else None)
    for k, (t0, t1) in enumerate(events["occluded"]):
        ax.axvspan(t0, t1, color="0.85", label="occluded" if k == 0 else None)
    for k, (t0, t1) in enumerate(events["out_of_view"]):
        ax.axvspan(t0, t1, color="0.9", hatch="//", label="leaving / out of view"
                   if k == 0 else None)


def plot_error_time_series(times_s: np.ndarray, errors: dict[str, tuple], scenario: Scenario,
                           path: Path, title: str) -> Path:
    """PNG of translation (mm) and rotation (deg) errors over time on log axes, one line
    per method (``errors[method] = (translation_mm, rotation_deg)``), with the
    scenario's events marked. Non-finite samples are left out."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import ticker

    times_s = np.asarray(times_s, float)
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for method, values in errors.items():
        for ax, value in zip(axes, values):
            value = np.asarray(value, float)
            ok = np.isfinite(value) & (value > 0)
            ax.plot(times_s[ok], value[ok], lw=1, label=method_label(method),
                    color=METHOD_COLORS.get(method))
    t_end = float(times_s[-1]) if len(times_s) else 0.0
    for ax in axes:
        mark_scenario_events(ax, scenario, t_end)
        ax.set_yscale("log")
        ax.yaxis.set_major_locator(ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
        ax.yaxis.set_minor_formatter(ticker.NullFormatter())
        ax.grid(True, which="both", alpha=0.25)
    if len(times_s):
        axes[1].set_xlim(times_s[0], t_end)
    axes[0].set_ylabel("translation error (mm)")
    axes[1].set_ylabel("rotation error (deg)")
    axes[1].set_xlabel("time (s)")
    axes[0].set_title(title, fontsize=10)
    axes[0].legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)
