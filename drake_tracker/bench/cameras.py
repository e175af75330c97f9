"""The bench's figure of issue 46: what an image costs with one camera and with two.

One recording of the two-camera preset (both cameras at 30 Hz) is tracked twice by the
offline tracker with the given parameters, on the same two-camera model: with the first
camera's images alone (one camera at 30 Hz), and with every other image of each camera
(two cameras at 15 Hz: as many images per second). The image update's wall time per
image (each camera's own update, ``CpfImageUpdate.times``) and per second of data
compare the two: an image should cost the same whichever camera took it.
"""

from __future__ import annotations

import dataclasses
import time
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from drake_tracker.io.recording import RecordedRun
    from drake_tracker.params.tracker_params import TrackerParams

#: The recording both figures track.
TWO_CAMERA_SCENARIO = "occlusion-lasting-2cam/constant"


def every_other_image(run: RecordedRun, cameras: int) -> RecordedRun:
    """``run`` with the first ``cameras`` cameras (1 or all) and, with more than one,
    every other image of each (half their rate)."""
    if cameras == 1:
        return dataclasses.replace(run, other_cameras=[])
    half = slice(None, None, 2)
    return dataclasses.replace(
        run, image_capture_times_s=run.image_capture_times_s[half],
        image_arrival_times_s=run.image_arrival_times_s[half],
        depth_images_m=run.depth_images_m[half],
        other_cameras=[dataclasses.replace(
            c, capture_times_s=c.capture_times_s[half], arrival_times_s=c.arrival_times_s[half],
            depth_images_m=c.depth_images_m[half]) for c in run.other_cameras])


def image_update_cost(run: RecordedRun, params: TrackerParams) -> dict:
    """Tracks ``run`` (all its cameras) and times its image updates."""
    from drake_tracker.io.replay import model_for_run
    from drake_tracker.io.stream import track_stream
    from drake_tracker.io.track_files import run_events
    from drake_tracker.tracker import Tracker

    model = model_for_run(run)
    tracker = Tracker(model, params=params, cameras=run.intrinsics_by_camera)
    start = time.perf_counter()
    track_stream(run_events(run), tracker)
    wall = time.perf_counter() - start
    per_camera = {name: list(channel.images.update.times.per_update)
                  for name, channel in tracker.channels.items()}
    updates = [t for times in per_camera.values() for t in times]
    images = len(run.image_capture_times_s) + sum(len(c.capture_times_s)
                                                  for c in run.other_cameras)
    return {"cameras": run.camera_names, "images_per_s": images / run.duration_s,
            "updates": len(updates),
            "updates_per_camera": {name: len(t) for name, t in per_camera.items()},
            "update_ms_median": 1e3 * float(np.median(updates)),
            "update_ms_mean": 1e3 * float(np.mean(updates)),
            "update_s_per_s": float(np.sum(updates)) / run.duration_s,
            "tracking_wall_s_per_s": wall / run.duration_s,
            # The cameras' calibration (core/calibration/online.py): once, on one image.
            "calibration_fit_s": None if tracker.held is None else tracker.held.fit_wall_s}


def bench_camera_count(params: TrackerParams, duration_s: float) -> dict:
    """One camera at 30 Hz against two at 15 Hz (see the module)."""
    from drake_tracker.sim.record import simulate_and_record
    from drake_tracker.sim.scenario.load import load_scenario

    run = simulate_and_record(load_scenario(TWO_CAMERA_SCENARIO), duration_s=duration_s)
    one = image_update_cost(every_other_image(run, 1), params)
    two = image_update_cost(every_other_image(run, 2), params)
    return {"scenario": TWO_CAMERA_SCENARIO, "duration_s": run.duration_s,
            "one_camera_30hz": one, "two_cameras_15hz": two,
            "two_over_one_per_image": two["update_ms_mean"] / one["update_ms_mean"],
            "two_over_one_per_s": two["update_s_per_s"] / one["update_s_per_s"]}


def format_camera_count(result: dict) -> str:
    """Two lines: :func:`bench_camera_count`'s figures."""
    one, two = result["one_camera_30hz"], result["two_cameras_15hz"]
    return (f"image update per image ({result['scenario']}, {result['duration_s']:g} s): "
            f"one camera at 30 Hz {one['update_ms_mean']:.1f} ms mean "
            f"({one['update_ms_median']:.1f} median, {one['updates']} updates), two "
            f"cameras at 15 Hz {two['update_ms_mean']:.1f} ms mean "
            f"({two['update_ms_median']:.1f} median, {two['updates']} updates)\n"
            f"  two cameras / one camera: {result['two_over_one_per_image']:.2f} per image "
            f"(target ~1); {result['two_over_one_per_s']:.2f} per second of data (each "
            f"camera is paced at image.min_image_interval_s: {two['updates']} updates "
            f"against {one['updates']})"
            + ("" if two["calibration_fit_s"] is None else
               f"\n  the cameras' calibration: {two['calibration_fit_s']:.1f} s once, on the "
               "image that completed its window (not in the figures above)"))
