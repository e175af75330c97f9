"""The evaluation's figures: box plots of the settled errors, one figure per sequence
(the paper's layout: the methods side by side, here for each bias variant), and a time
series of every sample per case (bias changes dotted, occlusion and out-of-view
intervals shaded)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from drake_tracker.evaluation.methods import METHODS
from drake_tracker.evaluation.plot_style import mark_scenario_events, method_label
from drake_tracker.evaluation.summary import settled
from drake_tracker.evaluation.tasks import sequence_stem, task_name

#: One colour per method; the box plots draw their medians black over these.
METHOD_COLORS = dict(zip(METHODS, ("0.6", "tab:blue", "tab:orange", "tab:green")))
MEDIAN_LINE = {"color": "black", "linewidth": 1.6}
#: The bias variants in the order the box plots show them (others follow, sorted).
BIAS_ORDER = ("none", "constant", "time-varying", "ramp")


def plot_results(rows: list[dict], out_dir: Path, settle_s: float = 0.0,
                 scenarios: dict | None = None) -> list[Path]:
    """Box plots per sequence (``boxplot_<sequence>.png``: translation and rotation, one
    box per method and bias variant) of the samples from ``settle_s`` on, and time series
    of every sample. ``scenarios`` maps (sequence,
    bias) to the Scenario of the plotted seed (default: the stored run's, or the
    preset's)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    written = []
    late = settled(rows, settle_s)
    cases = sorted({(r["sequence"], r["bias"]) for r in rows})
    methods = [m for m in METHODS if any(r["method"] == m for r in rows)]
    if late:  # no box plots when no sample is settled
        for seq in sorted({s for s, _ in cases}):
            written.append(_plot_sequence_boxes(late, seq, methods, out_dir, plt, settle_s))
    for seq, bias in cases:
        scenario = (scenarios or {}).get((seq, bias))
        written.append(_plot_time_series(rows, seq, bias, methods, out_dir, plt, settle_s,
                                         scenario))
    return written


def _plot_sequence_boxes(late: list[dict], seq: str, methods: list[str], out_dir: Path,
                         plt, settle_s: float) -> Path:
    """``boxplot_<sequence>.png``: per metric, the bias variants side by side, one box per
    method (whiskers p1-p99 of all seeds' samples, log scale)."""
    rows = [r for r in late if r["sequence"] == seq]
    biases = sorted({r["bias"] for r in rows}, key=lambda b: (
        BIAS_ORDER.index(b) if b in BIAS_ORDER else len(BIAS_ORDER), b))
    seeds = len({r["seed"] for r in rows})
    fig, axes = plt.subplots(1, 2, figsize=(max(7.0, 2.4 * len(biases) + 2.0), 3.8))
    width = 0.8 / max(1, len(methods))
    for ax, (metric, unit) in zip(axes, (("translation_mm", "translation error (mm)"),
                                         ("rotation_deg", "rotation error (deg)"))):
        for i, method in enumerate(methods):
            data = []
            for bias in biases:
                v = np.array([float(r[metric]) for r in rows
                              if r["bias"] == bias and r["method"] == method])
                data.append(v[np.isfinite(v)])
            positions = np.arange(len(biases)) + (i - (len(methods) - 1) / 2) * width
            bp = ax.boxplot(data, positions=positions, widths=width * 0.9, whis=(1, 99),
                            showfliers=False, patch_artist=True, medianprops=MEDIAN_LINE)
            for patch in bp["boxes"]:
                patch.set_facecolor(METHOD_COLORS[method])
            ax.plot([], [], color=METHOD_COLORS[method], lw=6, label=method_label(method))
        ax.set_xticks(np.arange(len(biases)))
        ax.set_xticklabels(["no bias" if b == "none" else f"{b} bias" for b in biases],
                           fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel(unit + ", whiskers p1-p99", fontsize=8)
    axes[0].plot([], [], label="median", **MEDIAN_LINE)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{seq}: errors from t = {settle_s:g} s on, {seeds} seed(s)", fontsize=9)
    fig.tight_layout()
    path = out_dir / f"boxplot_{sequence_stem(seq)}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _stored_scenario(out_dir: Path, seq: str, bias: str, seed: int):
    """The scenario a stored run was simulated with (the preset if the run is gone)."""
    from pydrake.common.yaml import yaml_load_typed

    from drake_tracker.io.recording import RecordedRun
    from drake_tracker.sim.scenario.load import Scenario, load_scenario

    path = out_dir / "runs" / f"{task_name(seq, bias, seed)}.npz"
    if path.exists():
        text = RecordedRun.load(path).scenario_yaml
        if text:
            return yaml_load_typed(schema=Scenario, data=text)
    return load_scenario(f"{seq}/{bias}", validate=False)


def _plot_time_series(rows, seq, bias, methods, out_dir, plt, settle_s, scenario) -> Path:
    seed0 = min(int(r["seed"]) for r in rows if (r["sequence"], r["bias"]) == (seq, bias))
    if scenario is None:
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
        ax.plot(t, e, color=METHOD_COLORS[method], label=method_label(method), lw=1)
    mark_scenario_events(ax, scenario, t_end)
    if 0 < settle_s < t_end:
        ax.axvline(settle_s, color="tab:red", ls="--", lw=0.8, label="summary from here")
    ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("translation error (mm)")
    ax.set_title(f"{seq} / {bias} (seed {seed0})")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    path = out_dir / f"timeseries_{sequence_stem(seq)}_{bias}.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
