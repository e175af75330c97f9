"""The likelihood part of ``drake-tracker bench`` reports what it documents (no timing
assertions: only that the figures exist, are positive, and the renderings agree)."""

import numpy as np

from drake_tracker.bench.likelihood import bench_robot
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import build_tracker_model, robot_preset


def test_bench_robot_reports_its_figures():
    model = build_tracker_model(robot_preset("apollo"))
    camera = CameraIntrinsics.from_fov(640, 480, np.radians(45.0))
    result = bench_robot(model, camera, TrackerParams(), repeats=1, num_drake=3)
    assert result["evaluations"] >= 2000
    assert set(result["threads"]) == {"1", "2"}
    for figures in result["threads"].values():
        assert figures["updates_per_s"] > 0 and figures["python_us_per_block"] >= 0
    stages = result["stage_us_per_evaluation"]
    assert set(stages) == {"fk", "raster", "likelihood", "score", "render"}
    assert all(np.isfinite(v) and v >= 0 for v in stages.values())
    assert result["drake_us_per_image"] > 0
    assert result["label_agreement_vs_drake"] >= 0.98
    assert result["triangles_rendered"] == result["triangles_source"] == 1176


def test_kernel_cost_in_turns_is_per_evaluation_for_each_robot():
    """Both robots timed in turns, 1 thread: the kernel's µs per evaluation of each (the
    CAD ÷ bench ratio of ``bench.json``); the thread count is restored afterwards."""
    import numba

    from drake_tracker.bench.likelihood import kernel_us_per_evaluation_in_turns

    models = {name: build_tracker_model(robot_preset(name)) for name in ("apollo", "arm6")}
    camera = CameraIntrinsics.from_fov(640, 480, np.radians(45.0))
    threads = numba.get_num_threads()
    result = kernel_us_per_evaluation_in_turns(models, camera, TrackerParams(), repeats=1)
    assert set(result) == {"apollo", "arm6"}
    assert all(np.isfinite(v) and 0 < v < 1e4 for v in result.values())
    assert numba.get_num_threads() == threads
