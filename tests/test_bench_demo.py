"""The demo slice of ``drake-tracker bench`` reports what it documents (no timing
assertions: the figures themselves go in the README)."""

import math

from drake_tracker.bench import bench_demo, format_demo
from drake_tracker.core.camera import stride_for_width
from drake_tracker.params import TrackerParams


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
