"""The encoder-rate part of ``drake-tracker bench``: what each joint reading costs the
Simulator's thread in a Diagram.

Every reading (1000 a second at the demo's encoder rate) runs two LeafSystems: the
:class:`~drake_tracker.systems.delay_buffer_system.DelayBufferSystem` (the readings' one
gate, then the reading filtered into the buffer) and the
:class:`~drake_tracker.systems.kalman_bank_system.JointKalmanBankSystem` (the admitted
reading filtered into the present estimate). Their core is a few microseconds (``kf_step_us``);
this measures the whole of it, Drake's event handling and the Python shells included,
as a user's Diagram pays it. The image update is left out: its worker runs on another
thread, and the buffer's ``image_observation`` input holds no observation.

Figures: ``us_per_reading`` (CPU time of the Simulator's thread per reading, both
systems, least of ``repeats``), the buffer alone (``buffer_us_per_reading``), the
bank's share (``bank_us_per_reading``: both less the buffer, the median over the turns
of the difference within each; the bank reads the buffer's admitted reading, so it
does not run alone), and ``source_us_per_reading``: the
:class:`~drake_tracker.systems.recorded_run_source.RecordedRunSource` that plays the
readings, its three ports evaluated by a system that does nothing else. Less the same
system reading nothing (the Simulator's step and one event), that is
``source_ports_us_per_reading``, the source's port calculations: a hardware driver has
a cost of its own, and this share of the figures above is not the tracker's (the
median over the turns, as the bank's share).
``tracker_us_per_reading``: both systems less the source's ports (the Simulator's step
to the event counted as the tracker's).
``last_reading_filtered_s``: the stamp of the bank's latest filtered reading at the end
(the run's last reading before its end: every reading went through).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, EventStatus, LeafSystem

from drake_tracker.robot.model import build_tracker_model
from drake_tracker.systems.delay_buffer_system import DelayBufferSystem
from drake_tracker.systems.kalman_bank_system import JointKalmanBankSystem
from drake_tracker.systems.messages import ImageObservationMessage
from drake_tracker.systems.recorded_run_source import RecordedRunSource

if TYPE_CHECKING:
    from drake_tracker.io.recording import RecordedRun
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.robot.model import TrackerModel
    from drake_tracker.sim.scenario.load import Scenario

#: Simulated seconds before the timing starts (the first readings build the belief).
WARM_UP_S = 0.5


class _SourceReader(LeafSystem):
    """Reads the source's three ports at the encoder rate (``read`` False: reads
    nothing, an event's cost alone) and does nothing else."""

    def __init__(self, num_joints: int, period_s: float, read: bool = True):
        super().__init__()
        self._ports = (self.DeclareVectorInputPort("measured_position", num_joints),
                       self.DeclareVectorInputPort("measurement_time", 1),
                       self.DeclareAbstractInputPort("depth_frame",
                                                     AbstractValue.Make(object())))
        self._reads = read
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, 0.0, self._read)

    def _read(self, context, state) -> EventStatus:
        if self._reads:
            for port in self._ports:
                port.Eval(context)
        return EventStatus.DidNothing()


def _cpu_us_per_reading(run: RecordedRun, model: TrackerModel, params: TrackerParams,
                        period_s: float, which: str) -> tuple[float, float | None]:
    """CPU µs of this thread per reading after WARM_UP_S, for ``which`` of "both",
    "buffer", "source", "idle" (a system whose event reads nothing); and the stamp of
    the bank's latest filtered reading."""
    builder = DiagramBuilder()
    source = builder.AddSystem(RecordedRunSource(run))
    if which in ("source", "idle"):
        sink = builder.AddSystem(_SourceReader(len(run.joint_names), period_s,
                                               read=which == "source"))
    else:
        sink = buffer = builder.AddSystem(DelayBufferSystem(model=model, params=params,
                                                            period_s=period_s))
    for name in ("measured_position", "measurement_time", "depth_frame"):
        builder.Connect(source.GetOutputPort(name), sink.GetInputPort(name))
    if which == "both":
        bank = builder.AddSystem(JointKalmanBankSystem(model=model, params=params,
                                                       period_s=period_s))
        builder.Connect(buffer.get_correction_output_port(), bank.get_correction_input_port())
        builder.Connect(buffer.get_reading_output_port(), bank.get_reading_input_port())
    simulator = Simulator(builder.Build())
    root = simulator.get_mutable_context()
    if which in ("both", "buffer"):
        buffer.get_image_observation_input_port().FixValue(
            buffer.GetMyMutableContextFromRoot(root), ImageObservationMessage())
    simulator.AdvanceTo(WARM_UP_S)
    start = time.thread_time()
    simulator.AdvanceTo(run.duration_s)
    readings = (run.duration_s - WARM_UP_S) / period_s
    cpu_us = 1e6 * (time.thread_time() - start) / readings
    if which != "both":
        return cpu_us, None
    return cpu_us, bank.bookkeeping(bank.GetMyContextFromRoot(root)).last_reading_s


def bench_reading_path(run: RecordedRun, model: TrackerModel, params: TrackerParams,
                       period_s: float, repeats: int = 3) -> dict:
    """The figures of the module docstring on the readings of ``run`` (recorded at
    ``period_s``), the variants taking turns ``repeats`` times (least of each)."""
    if not run.duration_s > WARM_UP_S + 0.5:
        raise ValueError(f"bench_reading_path needs a run longer than {WARM_UP_S + 0.5} s, "
                         f"got {run.duration_s} s")
    kinds = ("both", "buffer", "source", "idle")
    timed = {kind: [] for kind in kinds}
    for _ in range(max(1, repeats)):
        for kind in kinds:
            cpu_us, last_reading_s = _cpu_us_per_reading(run, model, params, period_s, kind)
            timed[kind].append(cpu_us)
            if kind == "both":
                latest = last_reading_s
    best = {kind: min(values) for kind, values in timed.items()}
    # A share is the median over the turns of its two variants' difference within the
    # turn (the least of each, subtracted, went to 0 or below in a slow spell).
    ports = float(np.median(np.subtract(timed["source"], timed["idle"])))
    bank = float(np.median(np.subtract(timed["both"], timed["buffer"])))
    return {"us_per_reading": best["both"],
            "bank_us_per_reading": bank,
            "buffer_us_per_reading": best["buffer"],
            "source_us_per_reading": best["source"],
            "source_ports_us_per_reading": ports,
            "tracker_us_per_reading": best["both"] - ports,
            "last_reading_filtered_s": latest,
            "duration_s": run.duration_s, "repeats": max(1, repeats)}


def record_demo_sensors(params: TrackerParams, duration_s: float) -> tuple[Scenario,
                                                                         RecordedRun]:
    """The demo's scenario (camera rendering what the tracker reads) and its sensors
    recorded over the first ``duration_s``, for the benches that replay them."""
    from drake_tracker.demo.run import DEFAULT_SCENARIO, render_what_the_tracker_reads
    from drake_tracker.sim.record import simulate_and_record
    from drake_tracker.sim.scenario.load import load_scenario

    scenario = render_what_the_tracker_reads(load_scenario(DEFAULT_SCENARIO), params)
    return scenario, simulate_and_record(scenario, duration_s=duration_s,
                                         image_stride=scenario.camera.render_stride,
                                         validate=False)


def bench_recorded_reading_path(params: TrackerParams,
                                recording: tuple[Scenario, RecordedRun],
                                quick: bool = False) -> dict:
    """:func:`bench_reading_path` on :func:`record_demo_sensors`'s recording, as
    ``drake-tracker bench`` runs it (3 repeats with ``quick``, else 9: on the shared VM
    the figure doubled for spells of about ten seconds, 44 against 60-94 µs in six runs
    of one process, and the least of turns spread over longer finds the idle core)."""
    scenario, run = recording
    return bench_reading_path(run, build_tracker_model(scenario.resolved_robot_config()),
                              params, 1.0 / scenario.encoders.rate_hz, 3 if quick else 9)


def format_reading_path(result: dict) -> str:
    """One line: :func:`bench_reading_path`'s figures."""
    return (f"each joint reading in a Diagram (bank and buffer systems, Drake's events "
            f"included): {result['us_per_reading']:.0f} us of CPU (bank's share "
            f"{result['bank_us_per_reading']:.0f}, buffer alone "
            f"{result['buffer_us_per_reading']:.0f}; of each, the recorded source's ports "
            f"{result['source_ports_us_per_reading']:.0f}, so the tracker's systems "
            f"{result['tracker_us_per_reading']:.0f}; a system that reads the ports and "
            f"does nothing else {result['source_us_per_reading']:.0f})")
