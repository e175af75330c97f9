"""The shared plot pieces: event marks read from the scenario presets, readable method
names, and the demo's error plot on log axes from the first estimate on."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from drake_tracker.evaluation.plot_style import (  # noqa: E402
    mark_scenario_events,
    method_label,
    plot_error_time_series,
    scenario_events,
)
from drake_tracker.sim.scenario.load import load_scenario  # noqa: E402


def test_events_of_the_presets():
    # The presets' documented timings: steps every 10 s, the occluder in front from
    # 8 s to 52 s, the in-out-in excursion from 15 s for 4 + 25 + 4 s.
    steps = scenario_events(load_scenario("s-full-arm/time-varying"), t_end=30.0)
    assert steps == {"bias_steps": [10.0, 20.0, 30.0], "occluded": [], "out_of_view": []}
    occluded = scenario_events(load_scenario("occlusion/none"), t_end=60.0)
    assert occluded["occluded"] == [(8.0, 52.0)] and not occluded["bias_steps"]
    out = scenario_events(load_scenario("in-out-in/constant"), t_end=40.0)
    assert out["out_of_view"] == [(15.0, 40.0)]  # clipped to the plotted time
    assert scenario_events(load_scenario("in-out-in/constant"), t_end=10.0)["out_of_view"] == []


def test_marks_are_labelled_once():
    fig, ax = plt.subplots()
    mark_scenario_events(ax, load_scenario("occlusion/time-varying"), t_end=60.0)
    labels = [h.get_label() for h in ax.get_legend_handles_labels()[0]]
    plt.close(fig)
    assert sorted(labels) == ["bias step", "occluded"]


def test_method_labels_are_readable():
    assert method_label("full_fusion") == "full fusion (tracker)"
    assert method_label("encoders_only") == "encoders only"
    assert method_label("some_new_method") == "some new method"


def test_error_plot_uses_log_axes_and_skips_non_finite(tmp_path, monkeypatch):
    captured = {}
    real_savefig = matplotlib.figure.Figure.savefig

    def savefig(fig, path, **kwargs):
        captured["axes"] = fig.axes
        return real_savefig(fig, path, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    t = np.linspace(0.01, 3.0, 300)
    translation = np.where(t < 0.5, np.nan, 1000.0 * np.exp(-t))
    errors = {"full_fusion": (translation, np.exp(-t)),
              "encoders_only": (np.full_like(t, 150.0), np.full_like(t, 20.0))}
    path = plot_error_time_series(t, errors, load_scenario("s-full-arm/time-varying"),
                                  tmp_path / "errors.png", "title")
    assert path.stat().st_size > 0
    top, bottom = captured["axes"]
    assert top.get_yscale() == "log" and bottom.get_yscale() == "log"
    assert top.get_title() == "title"
    assert bottom.get_xlim() == pytest.approx((0.01, 3.0))
    lines = {line.get_label(): line for line in top.get_lines() if line.get_label()[0] != "_"}
    assert set(lines) == {"full fusion (tracker)", "encoders only"}
    assert np.all(lines["full fusion (tracker)"].get_xdata() >= 0.5)
