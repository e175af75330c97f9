"""The demo end to end on a short run: report keys, Meshcat recording (bound to
localhost on a free port), plot and Diagram graph."""

import argparse
import base64
import json
import re

from drake_tracker.demo import run_demo


def test_demo_writes_report_with_both_methods(tmp_path):
    args = argparse.Namespace(scenario="s-full-arm/constant", out=str(tmp_path),
                              duration=0.4, params=None)
    assert run_demo(args) == 0
    report = json.loads((tmp_path / "report.json").read_text())
    for method in ("encoders_only", "full_fusion"):
        for metric in ("translation_mm", "rotation_deg"):
            summary = report["methods"][method][metric]
            assert set(summary) == {"p1", "p25", "p50", "p75", "p99"}
            assert all(v == v for v in summary.values())  # no NaN
    assert report["real_time_factor"] > 0
    html = (tmp_path / "meshcat.html").read_text()
    # The recording embeds Meshcat's commands as base64 msgpack blobs.
    blobs = re.findall(r'base64,([A-Za-z0-9+/=]+)"\)', html)
    paths = {m.decode() for b in blobs for m in re.findall(rb"/drake/[a-z_]+",
                                                           base64.b64decode(b))}
    assert {"/drake/true", "/drake/encoders", "/drake/estimate",
            "/drake/camera_points"} <= paths, paths
    assert (tmp_path / "errors.png").stat().st_size > 0
    assert "tracker_kalman_bank" in (tmp_path / "diagram.dot").read_text()
