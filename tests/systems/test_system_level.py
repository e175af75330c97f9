"""System level: the default scenario (s-full-arm, 8.6 deg constant bias on every arm
joint, 2 cm / 2.6 deg camera error) simulated for 30 s with the tracker inside the
Diagram, then the same recording replayed through the offline tracker."""

import numpy as np
import pytest

from drake_tracker.io.replay import encoders_only_X_CE, replay_run
from drake_tracker.metrics import pose_errors
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.sim.record import simulate_and_record
from drake_tracker.sim.scenario.load import load_scenario
from drake_tracker.systems.add_tracker import AddTracker


@pytest.fixture(scope="module")
def simulated():
    params = TrackerParams()
    scenario = load_scenario("s-full-arm/constant")

    def add_tracker(builder, world):
        tracker = AddTracker(builder, model=world.model, camera=world.intrinsics, params=params,
                             measured_position=world.port("measured_position"),
                             measurement_time=world.port("measurement_time"),
                             depth=world.port("depth_frame"),
                             encoder_period_s=world.encoder_period_s)
        return {"X_CE": tracker.X_CE,
                "estimated_position": tracker.estimated_position}

    run = simulate_and_record(scenario, add_systems=add_tracker)
    return run, params


def median_translation_mm(X, run) -> float:
    ok = run.truth_times_s > 0  # before the first reading there is no estimate
    return float(np.median(pose_errors(X[ok], run.truth_X_CE[ok])[0]))


def test_full_fusion_in_the_diagram_beats_encoders_only_tenfold(simulated):
    run, _ = simulated
    encoders = median_translation_mm(encoders_only_X_CE(run), run)
    fusion = median_translation_mm(run.extra["X_CE"], run)
    assert encoders > 100.0  # the bias really hurts the baseline
    assert fusion * 10.0 <= encoders, (fusion, encoders)


def test_offline_replay_of_the_recording_equals_the_diagram(simulated):
    run, params = simulated
    h = 1e-3
    # At a truth time t = k h the Diagram's bank has filtered the readings before t (it
    # updates at k h + h/2); the offline tracker's estimate "at t" includes the reading
    # stamped t, so sample it just before.
    applied = []  # arrival times of the images the offline tracker applied

    def on_image(tracker, frame):
        if tracker.num_images_applied > len(applied):
            applied.append(frame.arrival_time_s)

    replay = replay_run(run, params, sample_times_s=run.truth_times_s - 0.5 * h,
                        on_image=on_image)
    # The Diagram applies an image's update ``update_latency_s`` after its first tick
    # after arrival (the offline tracker at once); compare where no applied image
    # arrived within that and the last 3 encoder periods.
    arrivals, latency = np.array(applied), params.image.update_latency_s
    assert latency > 0 and len(arrivals) > 250  # the worker thread at 10 images/s
    settled = np.array([t > 0 and not np.any((arrivals > t - latency - 3 * h)
                                             & (arrivals <= t)) for t in run.truth_times_s])
    assert settled.sum() > 0.1 * len(settled)
    difference = np.abs(replay.positions[settled] - run.extra["estimated_position"][settled])
    assert difference.max() <= 1e-9, difference.max()
    encoders = median_translation_mm(encoders_only_X_CE(run), run)
    assert median_translation_mm(replay.X_CE, run) * 10.0 <= encoders
