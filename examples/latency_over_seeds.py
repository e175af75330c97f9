"""What the image update's latency costs: the default scenario over world seeds, the
tracker inside the Diagram with ``image.update_latency_s`` at each given value.

    python examples/latency_over_seeds.py [--seeds 1 2 3] [--latencies 0 0.08]
                                          [--duration 20]

Prints, per seed and latency, the hand's translation error in the camera frame
(p50 / p75 / p99, mm, after the first second) and the simulation's real-time factor,
then the median over seeds with the worst seed.
"""

from __future__ import annotations

import argparse
import copy

import numpy as np

from drake_tracker.demo.run import DEFAULT_SCENARIO, render_what_the_tracker_reads
from drake_tracker.metrics import pose_errors
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.sim.record import simulate_and_record
from drake_tracker.sim.scenario.load import load_scenario
from drake_tracker.systems.add_tracker import AddTracker

PERCENTILES = (50, 75, 99)


def run_one(seed: int, latency_s: float, duration_s: float) -> tuple[list[float], float]:
    """(p50, p75, p99 translation error in mm after 1 s, real-time factor)."""
    params = TrackerParams()
    params.image.update_latency_s = latency_s
    scenario = copy.deepcopy(load_scenario(DEFAULT_SCENARIO))
    scenario.seed = seed
    scenario = render_what_the_tracker_reads(scenario, params)

    def add_tracker(builder, world):
        tracker = AddTracker(builder, model=world.model, camera=world.intrinsics, params=params,
                             measured_position=world.port("measured_position"),
                             measurement_time=world.port("measurement_time"),
                             depth=world.port("depth_frame"),
                             encoder_period_s=world.encoder_period_s)
        return {"X_CE": tracker.X_CE}

    run = simulate_and_record(scenario, duration_s=duration_s,
                              image_stride=scenario.camera.render_stride,
                              add_systems=add_tracker, validate=False)
    keep = run.truth_times_s > 1.0
    errors_mm = pose_errors(run.extra["X_CE"][keep], run.truth_X_CE[keep])[0]
    return ([float(np.percentile(errors_mm, q)) for q in PERCENTILES],
            run.duration_s / run.extra["wall_time_s"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--latencies", type=float, nargs="+", default=[0.0, 0.08])
    parser.add_argument("--duration", type=float, default=20.0)
    args = parser.parse_args()
    for latency in args.latencies:
        rows = []
        for seed in args.seeds:
            percentiles, rtf = run_one(seed, latency, args.duration)
            rows.append(percentiles)
            print(f"latency {latency:g} s, seed {seed}: p50 / p75 / p99 "
                  f"{' / '.join(f'{p:.2f}' for p in percentiles)} mm, "
                  f"real-time factor {rtf:.2f}", flush=True)
        rows = np.array(rows)
        print(f"latency {latency:g} s: median over seeds "
              f"{' / '.join(f'{p:.2f}' for p in np.median(rows, axis=0))} mm, worst seed "
              f"{' / '.join(f'{p:.2f}' for p in rows.max(axis=0))} mm")


if __name__ == "__main__":
    main()
