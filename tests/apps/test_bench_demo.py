"""The demo slice of ``drake-tracker bench`` reports what it documents (no timing
assertions: the figures themselves go in the README)."""

import math

import pytest

from drake_tracker.bench.readings import bench_reading_path, format_reading_path
from drake_tracker.bench.realtime import (
    bench_demo,
    bench_tracker_alone,
    format_demo,
    format_tracker_alone,
    max_lag_behind_real_time_s,
    record_demo_sensors,
)
from drake_tracker.core.sensors.camera import stride_for_width
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import build_tracker_model


def test_bench_demo_reports_its_real_time_factors():
    params = TrackerParams()
    result = bench_demo(params, duration_s=0.3)
    assert result["scenario"] == "s-full-arm/constant"
    assert result["duration_s"] == 0.3
    # The demo's camera renders the pixels the tracker reads: 640 px at its stride.
    assert result["render_stride"] == stride_for_width(640, params.image.image_width_px) > 1
    for key in ("real_time_factor", "real_time_factor_cpu"):
        assert math.isfinite(result[key]) and result[key] > 0, key
    assert result["real_time_factor_after_1s"] is None  # the slice is under 1.5 s
    line = format_demo(result)
    assert "demo real-time factor" in line and "target >= 1.0" in line


def test_bench_tracker_alone_reports_the_tracker_on_recorded_sensors():
    params = TrackerParams()
    result = bench_tracker_alone(params, duration_s=1.6)
    assert result["scenario"] == "s-full-arm/constant" and result["duration_s"] == 1.6
    for key in ("real_time_factor_after_1s", "main_thread_cpu_s_per_s",
                "other_threads_cpu_s_per_s", "update_wall_ms_median"):
        assert math.isfinite(result[key]) and result[key] > 0, key
    # Images are taken up at most every image.min_image_interval_s (0.1 s: 10 a second),
    # and the recorded camera's do reach the tracker.
    rate = result["images_applied_per_s"]
    assert 0 < rate <= 1.0 / params.image.min_image_interval_s + 1.0 / result["duration_s"]
    assert result["updates_late"] + result["updates_on_time"] >= 1  # on the worker
    assert 0 <= result["updates_late_searches"] <= result["updates_late"]
    assert result["deadline_wait_s_per_s"] >= 0
    text = format_tracker_alone(result)
    assert "tracker alone" in text and "images applied per s" in text
    assert f"({result['updates_late_searches']} of them searches)" in text
    # The largest lag over its simulated seconds and its end, from its first mark (0 s).
    assert math.isfinite(result["max_lag_behind_real_time_s"])
    assert result["max_lag_behind_real_time_s"] >= 0.0
    assert "behind real time" in text


def _marks(walls: list[float]) -> list[tuple]:
    """``add_second_marks``'s marks at simulated 0, 1, 2, ... s with these wall times."""
    return [(float(t), wall, 0.0, 0.0) for t, wall in enumerate(walls)]


def test_the_lag_behind_real_time_keeps_a_stall_the_real_time_factor_hides():
    """A paced Simulator that stalls for 1 s in its first second and then catches up
    (wall times 10, 12, 13, 14, end at 4 s simulated at 14.5 s): its real-time factor
    after the first second reads 1.2, faster than real time, while it was 1 s behind
    real time at its first second. The lag is measured from the first mark."""
    marks = _marks([10.0, 12.0, 13.0, 14.0])
    end = (4.0, 14.5)
    factor_after_1s = (end[0] - 1.0) / (end[1] - marks[1][1])
    assert factor_after_1s == pytest.approx(1.2)
    assert max_lag_behind_real_time_s(marks, end) == pytest.approx(1.0)
    # On time throughout, or ahead of real time (unpaced): no lag.
    assert max_lag_behind_real_time_s(_marks([0.0, 1.0, 2.0]), (2.5, 2.5)) == 0.0
    assert max_lag_behind_real_time_s(_marks([0.0, 0.5, 1.0]), (2.0, 1.5)) == 0.0
    # Behind only at the end: the end counts.
    assert max_lag_behind_real_time_s(_marks([0.0, 1.0, 2.0]), (2.5, 3.25)) == \
        pytest.approx(0.75)


def test_bench_reading_path_reports_what_each_joint_reading_costs():
    params = TrackerParams()
    scenario, run = record_demo_sensors(params, 1.2)
    model = build_tracker_model(scenario.resolved_robot_config())
    period_s = 1.0 / scenario.encoders.rate_hz
    result = bench_reading_path(run, model, params, period_s, repeats=1)
    for key in ("us_per_reading", "bank_us_per_reading", "buffer_us_per_reading",
                "source_us_per_reading", "source_ports_us_per_reading",
                "tracker_us_per_reading"):
        assert math.isfinite(result[key]), key
    assert result["us_per_reading"] > 0 and result["source_us_per_reading"] > 0
    # The parts add up: the tracker's share is the whole less the source's port calcs.
    assert math.isclose(result["tracker_us_per_reading"] + result["source_ports_us_per_reading"],
                        result["us_per_reading"])
    assert result["duration_s"] == 1.2 and result["repeats"] == 1
    # The timed Diagram did filter the readings, up to the last one before the end
    # (AdvanceTo(t) leaves the updates at t pending).
    before_end = run.reading_times_s[run.reading_times_s < run.duration_s]
    assert result["last_reading_filtered_s"] == before_end[-1]
    assert "each joint reading in a Diagram" in format_reading_path(result)
    short = record_demo_sensors(params, 0.8)[1]
    with pytest.raises(ValueError, match="longer than"):
        bench_reading_path(short, model, params, period_s)
