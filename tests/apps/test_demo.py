"""The demo end to end on one short run through the command line: progress on stderr,
report keys, the Meshcat recording (bound to localhost on a free port) with the truth,
the encoders-only robot and the estimate in distinct paths and colours, the plot and
the Diagram's graph."""

import base64
import contextlib
import io
import json
import re
import struct

import pytest

from drake_tracker.cli.main import main
from drake_tracker.demo.meshcat_views import ENCODERS_RGBA, ESTIMATE_RGBA

ROBOT_PATHS = ("/drake/truth", "/drake/encoders_only", "/drake/estimate")


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(["demo", "--scenario", "s-full-arm", "--duration", "1.0",
                     "--out", str(out)])
    return code, out, stdout.getvalue(), stderr.getvalue()


def meshcat_materials(html: str) -> dict[str, dict[str, set]]:
    """Per top-level /drake path: the material colours (0xRRGGBB) and opacities of the
    objects the recording sets there (its commands are base64 msgpack blobs)."""
    found = {}
    for blob in re.findall(r'base64,([A-Za-z0-9+/=]+)"\)', html):
        data = base64.b64decode(blob)
        paths = {m.decode() for m in re.findall(rb"/drake/[a-z_]+", data)}
        if len(paths) != 1:
            continue
        entry = found.setdefault(paths.pop(), {"colors": set(), "opacities": set()})
        # msgpack: "color" then a uint32 (0xce), "opacity" then a float64 (0xcb).
        entry["colors"] |= {int.from_bytes(c, "big")
                            for c in re.findall(rb"\xa5color\xce(.{4})", data, re.S)}
        entry["opacities"] |= {struct.unpack(">d", o)[0]
                               for o in re.findall(rb"\xa7opacity\xcb(.{8})", data, re.S)}
    return found


def rgb_int(rgba) -> int:
    # Meshcat's colour channels are 255 * c truncated (apollo.sdf's 0.45 -> 0x72).
    r, g, b = (int(255 * c) for c in (rgba.r(), rgba.g(), rgba.b()))
    return (r << 16) | (g << 8) | b


def test_demo_writes_report_with_both_methods(demo_run):
    code, out, stdout, _ = demo_run
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    assert report["scenario"] == "s-full-arm/constant"  # the bare sequence's default
    for method in ("encoders_only", "full_fusion"):
        for metric in ("translation_mm", "rotation_deg"):
            summary = report["methods"][method][metric]
            assert set(summary) == {"p1", "p25", "p50", "p75", "p99"}
            assert all(v == v for v in summary.values())  # no NaN
    assert report["real_time_factor"] > 0
    assert report["kernel_warm_up_s"] > 0  # loaded before the simulation, not in it
    # Every update ran on the worker (image.update_latency_s 0.08 by default), and was
    # either done at its deadline or waited for.
    assert report["image_updates_late"] + report["image_updates_on_time"] >= 1
    assert report["image_update_wait_s"] >= 0
    assert (report["image_update_wait_s"] > 0) == (report["image_updates_late"] > 0)
    assert "late at their deadline" in stdout
    assert 0 <= report["image_updates_late_searches"] <= report["image_updates_late"]
    assert f"{report['image_updates_late_searches']} of them searches" in stdout
    assert (out / "errors.png").stat().st_size > 0
    assert "tracker_kalman_bank" in (out / "diagram.dot").read_text()
    assert "meshcat.html" in stdout and "ends with the run" in stdout


def test_demo_prints_progress_in_simulated_seconds(demo_run):
    _, _, _, stderr = demo_run
    assert "s simulated" in stderr
    assert re.search(r"1\.0/1\.0 s simulated", stderr), stderr[-500:]
    assert "WARNING" not in stderr and "Traceback" not in stderr


def test_meshcat_shows_truth_encoders_and_estimate_distinctly(demo_run):
    _, out, _, _ = demo_run
    html = (out / "meshcat.html").read_text()
    materials = meshcat_materials(html)
    assert set(ROBOT_PATHS) | {"/drake/camera_points", "/drake/true_camera",
                               "/drake/estimated_camera"} <= set(materials), materials.keys()
    truth, encoders, estimate = (materials[p] for p in ROBOT_PATHS)
    # The truth keeps the model's own colours (apollo.sdf's orange links), opaque.
    assert 0xFF720C in truth["colors"] and truth["opacities"] == {1.0}
    # Each ghost is one translucent colour of its own, none of the truth's.
    assert encoders["colors"] == {rgb_int(ENCODERS_RGBA)}
    assert estimate["colors"] == {rgb_int(ESTIMATE_RGBA)}
    assert not (encoders["colors"] | estimate["colors"]) & truth["colors"]
    for ghost, rgba in ((encoders, ENCODERS_RGBA), (estimate, ESTIMATE_RGBA)):
        assert len(ghost["opacities"]) == 1
        assert ghost["opacities"].pop() == pytest.approx(rgba.a()) and rgba.a() < 0.8
    # The legend names each of them.
    legend = html[html.index('id="drake-tracker-legend"'):]
    for name in ("truth", "encoders only", "estimate", "camera"):
        assert name in legend
