"""The real-time part of ``drake-tracker bench``: the demo's Diagram and the tracker's
Diagram alone on recorded sensors, timed in simulated seconds per wall-clock second
(the keys ``demo`` and ``tracker_alone`` of ``bench.json``: ``bench/run.py``'s
docstring says what each holds)."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.bench.readings import record_demo_sensors
from drake_tracker.robot.model import build_tracker_model

if TYPE_CHECKING:
    from pydrake.systems.framework import DiagramBuilder

    from drake_tracker.io.recording import RecordedRun
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.sim.scenario.load import Scenario


def add_second_marks(builder: DiagramBuilder, marks: list) -> None:
    """Adds ``bench_clock``, which appends (simulated s, wall s, the Simulator thread's
    CPU s, the process's CPU s) to ``marks`` at every simulated second."""
    from pydrake.systems.framework import LeafSystem

    clock = builder.AddNamedSystem("bench_clock", LeafSystem())
    clock.DeclarePeriodicPublishEvent(1.0, 0.0, lambda context: marks.append(
        (context.get_time(), time.perf_counter(), time.thread_time(), time.process_time())))


def max_lag_behind_real_time_s(marks: list, end: tuple[float, float]) -> float:
    """The largest lag of the simulated clock behind the wall clock (s): over the
    ``marks`` of :func:`add_second_marks` (the first at simulated time 0) and ``end``
    (simulated s, wall s), the most wall time elapsed beyond the simulated time
    elapsed. A Simulator held to real time never runs ahead (about 0 while it keeps
    up); one that fell behind shows by how much, which its real-time factor hides once
    it has caught up (it then runs faster than real time: a 1 s stall at 0.95 s read
    as a factor of 1.9 from 1 s to 3 s). 0 when it never fell behind the first mark's
    pace, or ran ahead of real time (an unpaced one)."""
    points = [(t, wall) for t, wall, *_ in marks] + [tuple(end)]
    t0, wall0 = points[0]
    return max((wall - wall0) - (t - t0) for t, wall in points)


def bench_demo(params: TrackerParams, duration_s: float) -> dict:
    """The demo's real-time factor on its first ``duration_s`` (see the module doc)."""
    from drake_tracker.demo.run import (
        DEFAULT_SCENARIO,
        demo_hook,
        render_what_the_tracker_reads,
        start_meshcat,
    )
    from drake_tracker.sim.record import simulate_and_record
    from drake_tracker.sim.scenario.load import load_scenario

    scenario = render_what_the_tracker_reads(load_scenario(DEFAULT_SCENARIO), params)
    hook = demo_hook(start_meshcat(), params)
    marks = []  # filled by add_second_marks

    def add_systems(builder, world):
        add_second_marks(builder, marks)
        return hook(builder, world)

    run = simulate_and_record(scenario, duration_s=duration_s,
                              image_stride=scenario.camera.render_stride,
                              add_systems=add_systems, validate=False)
    wall_end, cpu_end = time.perf_counter(), time.process_time()
    after = [(t, wall) for t, wall, *_ in marks if t == 1.0]
    return {"scenario": DEFAULT_SCENARIO, "duration_s": run.duration_s,
            "render_stride": scenario.camera.render_stride,
            # the same figure as the demo's report.json
            "real_time_factor": run.duration_s / run.extra["wall_time_s"],
            "real_time_factor_after_1s": ((run.duration_s - 1.0) / (wall_end - after[0][1])
                                          if after and run.duration_s > 1.5 else None),
            "real_time_factor_cpu": run.duration_s / (cpu_end - marks[0][3])}


def bench_tracker_alone(params: TrackerParams, duration_s: float,
                        recording: tuple[Scenario, RecordedRun] | None = None,
                        paced: bool = False) -> dict:
    """The tracker's Diagram alone on the demo's recorded sensors (see the module doc);
    ``recording``: :func:`record_demo_sensors`'s, else made here. ``paced``: the
    Simulator is held to real time (``set_target_realtime_rate(1)``), as on a robot,
    where the sensors' clock is the wall clock: an update late at its deadline
    (``image.update_latency_s`` after its image) then took longer than that in wall time;
    unpaced, the Simulator runs ahead as fast as it can and waits at every deadline."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder

    from drake_tracker.demo.run import DEFAULT_SCENARIO
    from drake_tracker.systems.add_tracker import AddTracker
    from drake_tracker.systems.recorded_run_source import RecordedRunSource

    scenario, run = recording or record_demo_sensors(params, duration_s)
    model = build_tracker_model(scenario.resolved_robot_config())
    builder = DiagramBuilder()
    source = builder.AddSystem(RecordedRunSource(run))
    tracker = AddTracker(builder, model=model, camera=run.camera_intrinsics, params=params,
                         measured_position=source.GetOutputPort("measured_position"),
                         measurement_time=source.GetOutputPort("measurement_time"),
                         depth=source.GetOutputPort("depth_frame"),
                         encoder_period_s=1.0 / scenario.encoders.rate_hz)
    marks = []  # filled by add_second_marks
    add_second_marks(builder, marks)
    simulator = Simulator(builder.Build())
    if paced:
        simulator.set_target_realtime_rate(1.0)
    simulator.AdvanceTo(run.duration_s)
    end = (time.perf_counter(), time.thread_time(), time.process_time())
    start = next(m for m in marks if m[0] == 1.0)
    span = run.duration_s - 1.0
    cpf = tracker.image_update
    state = cpf.state(cpf.GetMyContextFromRoot(simulator.get_context()))
    updates = list(cpf.processor.update.times.per_update)
    main_cpu = (end[1] - start[2]) / span
    waits = cpf.deadline_waits
    return {"scenario": DEFAULT_SCENARIO, "duration_s": run.duration_s, "paced": paced,
            "min_image_interval_s": params.image.min_image_interval_s,
            "real_time_factor_after_1s": span / (end[0] - start[1]),
            "max_lag_behind_real_time_s": max_lag_behind_real_time_s(
                marks, (run.duration_s, end[0])),
            "main_thread_cpu_s_per_s": main_cpu,
            "other_threads_cpu_s_per_s": (end[2] - start[3]) / span - main_cpu,
            "images_applied_per_s": state.images_applied / run.duration_s,
            "update_wall_ms_median": 1e3 * float(np.median(updates)) if updates else None,
            "updates_late": waits.late, "updates_on_time": waits.on_time,
            "updates_late_searches": waits.late_searches,
            "deadline_wait_s_per_s": waits.waited_s / run.duration_s}


def format_demo(demo: dict) -> str:
    """One line: the demo's real-time factors of :func:`bench_demo`."""
    after = demo["real_time_factor_after_1s"]
    after = "" if after is None else f", {after:.2f} after the first second"
    return (f"demo real-time factor ({demo['scenario']}, first {demo['duration_s']:g} s "
            f"simulated): {demo['real_time_factor']:.2f} wall-clock{after}, "
            f"{demo['real_time_factor_cpu']:.2f} per second of CPU time   (target >= 1.0)")


def format_tracker_alone(alone: dict) -> str:
    """Two lines: the tracker alone on recorded sensors (:func:`bench_tracker_alone`)."""
    update = alone["update_wall_ms_median"]
    update = "no update" if update is None else f"{update:.0f} ms of wall time each"
    return (f"tracker alone on the demo's recorded sensors (first {alone['duration_s']:g} s): "
            f"real-time factor {alone['real_time_factor_after_1s']:.2f} after the first "
            f"second, at most {alone['max_lag_behind_real_time_s']:.2f} s behind real time"
            f"\n  CPU s per s: the Simulator's thread "
            f"{alone['main_thread_cpu_s_per_s']:.2f}, the other threads (the image "
            f"update's worker) {alone['other_threads_cpu_s_per_s']:.2f}; "
            f"{alone['images_applied_per_s']:.1f} images applied per s, {update}; "
            f"{alone['updates_late']} of {alone['updates_late'] + alone['updates_on_time']} "
            f"late at their deadline ({alone['updates_late_searches']} of them "
            f"searches), {alone['deadline_wait_s_per_s']:.2f} s waited per s")
