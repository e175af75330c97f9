"""Endurance benchmark (issue 14): the tracker inside the simulation Diagram for a long
run of the default scenario, its resident memory (RSS) sampled every simulated
``--sample-every-s``; prints whether RSS is flat after ``--warmup-s`` (the slope of a
least-squares line through the later samples, MB per simulated minute).

    python examples/endurance.py                      # 10 simulated minutes
    python examples/endurance.py --duration-s 60 --warmup-s 20 --sample-every-s 5

The Diagram (``AddTracker`` on the simulated world's ports, as ``drake-tracker demo``
wires it) is the path that runs for hours in a robot's process: Drake contexts, the
systems' abstract state, the delay buffer, the warning counters and the timing records
all live there. Nothing is recorded (``simulate_and_record`` would keep every image), so
what grows is the tracker's. The camera renders only the pixels the tracker reads, as in
the demo. It costs about 5 s of CPU per simulated second on one core.
"""

from __future__ import annotations

import argparse
import copy
import gc
import resource
import time
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_tracker.demo.run import DEFAULT_SCENARIO, render_what_the_tracker_reads
from drake_tracker.metrics import pose_errors
from drake_tracker.params.loading import load_tracker_params
from drake_tracker.sim.scenario.load import load_scenario
from drake_tracker.sim.world import AddSimulatedWorld
from drake_tracker.systems.add_tracker import AddTracker


def rss_mb() -> float:
    """Current resident set size (MB) from /proc, else the peak from getrusage."""
    status = Path("/proc/self/status")
    if status.is_file():
        for line in status.read_text().splitlines():
            if line.startswith("VmRSS:"):
                return float(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def slope_mb_per_min(times_s: np.ndarray, rss: np.ndarray) -> float:
    """Least-squares slope of RSS over simulated time (MB per minute)."""
    if len(times_s) < 2:
        return float("nan")
    return float(np.polyfit(times_s / 60.0, rss, 1)[0])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration-s", type=float, default=600.0,
                        help="simulated seconds (default 600)")
    parser.add_argument("--sample-every-s", type=float, default=10.0,
                        help="RSS sample period in simulated seconds (default 10)")
    parser.add_argument("--warmup-s", type=float, default=60.0,
                        help="samples before this are left out of the slope (default 60)")
    parser.add_argument("--scenario", default=DEFAULT_SCENARIO)
    parser.add_argument("--params", default=None, help="tracker parameters (YAML)")
    parser.add_argument("--flat-mb-per-min", type=float, default=0.5,
                        help="slope below which RSS is called flat (default 0.5)")
    args = parser.parse_args()

    params = load_tracker_params(args.params)
    scenario = copy.deepcopy(load_scenario(args.scenario))
    scenario.duration_s = max(scenario.duration_s, args.duration_s)
    scenario = render_what_the_tracker_reads(scenario, params)
    builder = DiagramBuilder()
    world = AddSimulatedWorld(builder, scenario)
    tracker = AddTracker(builder, model=world.model, camera=world.intrinsics, params=params,
                         measured_position=world.port("measured_position"),
                         measurement_time=world.port("measurement_time"),
                         depth=world.port("depth_frame"), encoder_period_s=world.encoder_period_s)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    world.set_initial_state(context)
    bank_context = tracker.kalman_bank.GetMyContextFromRoot(context)
    truth_port = world.port("true_X_CE")
    truth_context = truth_port.get_system().GetMyContextFromRoot(context)

    print(f"{scenario.name}: {args.duration_s:.0f} simulated s through the Diagram, RSS "
          f"every {args.sample_every_s:g} s")
    print(f"{'sim s':>7} {'RSS MB':>8} {'error mm':>9} {'wall s':>8} {'CPU s':>8}")
    wall0, cpu0 = time.perf_counter(), time.process_time()
    samples = []
    t = 0.0
    while t < args.duration_s - 1e-9:
        t = min(t + args.sample_every_s, args.duration_s)
        simulator.AdvanceTo(t)
        gc.collect()
        X = tracker.X_CE.Eval(bank_context).GetAsMatrix4()
        error = pose_errors(X, truth_port.Eval(truth_context).GetAsMatrix4())[0][0]
        samples.append((t, rss_mb(), error))
        print(f"{t:7.1f} {samples[-1][1]:8.1f} {error:9.1f} "
              f"{time.perf_counter() - wall0:8.1f} {time.process_time() - cpu0:8.1f}",
              flush=True)
    times, rss, _ = (np.array(c) for c in zip(*samples))
    late = times >= args.warmup_s
    slope = slope_mb_per_min(times[late], rss[late])
    flat = bool(np.isfinite(slope) and abs(slope) < args.flat_mb_per_min)
    print(f"RSS {rss[0]:.1f} MB at {times[0]:.0f} s, {rss[-1]:.1f} MB at {times[-1]:.0f} s; "
          f"slope after {args.warmup_s:g} s: {slope:+.3f} MB/min over {late.sum()} samples "
          f"-> {'flat' if flat else 'NOT flat'} (threshold {args.flat_mb_per_min:g} MB/min)")
    print(f"wall {time.perf_counter() - wall0:.0f} s, CPU {time.process_time() - cpu0:.0f} s")
    return 0 if flat else 1


if __name__ == "__main__":
    raise SystemExit(main())
