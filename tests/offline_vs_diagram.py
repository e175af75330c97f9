"""Running the same recorded data through the offline ``Tracker`` and through the
Diagram (``AddTracker``), with faulty stamps, sequence numbers, arrivals or readings;
shared by the parametrised equality test and the fault tests."""

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.systems.add_tracker import AddTracker
from drake_tracker.systems.recorded_run_source import RecordedRunSource
from drake_tracker.tracker import Tracker

H = 1.0 / 200.0  # the synthetic runs' encoder period (s)


def feed(tracker: Tracker, run, stamps=None, sequences=None, arrivals=None,
         readings=None, sample_times=None):
    """Feeds ``run`` in arrival order, with faulty reading stamps, image sequence numbers,
    image arrival times or reading values; returns the estimates after each sample time
    (default: after each reading) and whether each image was applied."""
    stamps = run.reading_times_s if stamps is None else stamps
    sequences = np.arange(len(run.image_capture_times_s)) if sequences is None else sequences
    arrivals = run.image_arrival_times_s if arrivals is None else arrivals
    readings = run.readings_rad if readings is None else readings
    times = run.reading_times_s + 0.6 * H if sample_times is None else sample_times
    order = np.argsort(arrivals, kind="stable")
    estimates, applied, i, s = [], {}, 0, 0

    def sample_until(limit):
        nonlocal s
        while s < len(times) and times[s] < limit:
            estimates.append(tracker.estimate().positions if tracker.started else None)
            s += 1

    for k, t in enumerate(run.reading_times_s):
        while i < len(order) and arrivals[order[i]] < t:
            j = order[i]
            sample_until(arrivals[j])
            applied[j] = tracker.add_image(DepthFrame(
                float(run.image_capture_times_s[j]), float(arrivals[j]),
                run.depth_images_m[j], int(sequences[j])))
            i += 1
        sample_until(t)
        tracker.add_reading(float(stamps[k]), readings[k])
    sample_until(np.inf)
    return estimates, applied


class FaultySource(RecordedRunSource):
    """A RecordedRunSource whose reading stamps and image sequence numbers are given."""

    def __init__(self, run, stamps, sequences):
        super().__init__(run)
        self.stamps, self.sequences = stamps, sequences

    def _calc_time(self, context, output):
        k = self._latest_reading(context.get_time())
        output.SetAtIndex(0, self.stamps[k] if k >= 0 else -1.0)

    def _calc_frame(self, context, output):
        super()._calc_frame(context, output)
        frame = output.get_value()
        if not frame.is_empty:
            output.set_value(DepthFrame(frame.capture_time_s, frame.arrival_time_s,
                                        frame.depth_m, int(self.sequences[frame.sequence])))


def simulate(model, run, p, stamps=None, sequences=None):
    """The Diagram on ``run`` (with faulty stamps or sequence numbers): the estimate
    right after each reading's bank update, and the number of images applied (an update
    still on the worker thread counted)."""
    stamps = run.reading_times_s if stamps is None else stamps
    sequences = np.arange(len(run.image_capture_times_s)) if sequences is None else sequences
    builder = DiagramBuilder()
    source = builder.AddSystem(FaultySource(run, stamps, sequences))
    tracker = AddTracker(builder, model=model, camera=run.camera_intrinsics, params=p,
                         measured_position=source.GetOutputPort("measured_position"),
                         measurement_time=source.GetOutputPort("measurement_time"),
                         depth=source.GetOutputPort("depth_frame"), encoder_period_s=H)
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    bank_context = tracker.kalman_bank.GetMyContextFromRoot(context)
    estimates = []
    for t in run.reading_times_s + 0.6 * H:
        simulator.AdvanceTo(t)
        estimates.append(tracker.estimated_position.Eval(bank_context).copy())
    cpf = tracker.image_update.state(tracker.image_update.GetMyContextFromRoot(context))
    return estimates, cpf.images_applied + (cpf.in_flight is not None)


def assert_same_when_settled(run, diagram, offline, first=0, latency_s=0.0, h=H,
                             arrivals=None):
    """The Diagram applies an image at the first CPF tick after it arrives (<= h later)
    plus ``latency_s``, the offline tracker at once: compare where no image (of
    ``arrivals``: default, the run's first camera's) arrived in that time and the last 2
    ticks (samples from the ``first`` reading on)."""
    arrivals = run.image_arrival_times_s if arrivals is None else arrivals
    settled = np.array([not np.any((arrivals > t - latency_s - 2.5 * h) & (arrivals <= t))
                        for t in run.reading_times_s[first:] + 0.6 * h])
    assert settled.sum() > (0.5 if latency_s == 0 else 0.25) * len(settled)
    difference = np.abs(np.array(diagram[first:])[settled] - np.array(offline[first:])[settled])
    assert np.max(difference) <= 1e-9, np.max(difference)


def feed_cameras(tracker: Tracker, run, times):
    """Feeds a run of several cameras as ``feed`` does (arrival order; a reading before
    an image at the same time, the cameras in the run's order at a tie), each image
    named by its camera; returns the estimate after each of ``times`` and the number of
    images each camera had applied."""
    from drake_tracker.io.stream import ImageEvent
    from drake_tracker.io.track_files import run_events

    estimates, applied, s = [], dict.fromkeys(run.camera_names, 0), 0

    def sample_until(limit):
        nonlocal s
        while s < len(times) and times[s] < limit:
            estimates.append(tracker.estimate() if tracker.started else None)
            s += 1

    for event in run_events(run):
        if isinstance(event, ImageEvent):
            sample_until(event.arrival_s)
            applied[event.camera] += tracker.add_image(DepthFrame(
                event.capture_s, event.arrival_s, event.depth, event.sequence),
                camera=event.camera)
        else:
            sample_until(event.time_s)
            tracker.add_reading(event.time_s, event.positions)
    sample_until(np.inf)
    return estimates, applied


def simulate_cameras(model, run, p, h, times, system=False):
    """The Diagram with a depth port per camera of ``run`` (``AddTracker(cameras=...)``):
    the estimated positions and each camera's offset port at each of ``times``, and the
    image-update system's state at the end (and, with ``system``, the system)."""
    from drake_tracker.systems.add_tracker import TrackerCamera

    builder = DiagramBuilder()
    source = builder.AddSystem(RecordedRunSource(run))
    intrinsics = {run.camera_name: run.camera_intrinsics} | {
        c.name: c.intrinsics for c in run.other_cameras}
    tracker = AddTracker(
        builder, model=model, params=p, encoder_period_s=h,
        measured_position=source.GetOutputPort("measured_position"),
        measurement_time=source.GetOutputPort("measurement_time"),
        cameras=[TrackerCamera(name, camera, source.get_depth_frame_output_port(name))
                 for name, camera in intrinsics.items()])
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    bank_context = tracker.kalman_bank.GetMyContextFromRoot(context)
    positions, offsets = [], []
    for t in times:
        simulator.AdvanceTo(t)
        positions.append(tracker.estimated_position.Eval(bank_context).copy())
        offsets.append({name: port.Eval(bank_context).copy()
                        for name, port in tracker.camera_offsets.items()})
    cpf = tracker.image_update.state(tracker.image_update.GetMyContextFromRoot(context))
    if system:
        return positions, offsets, cpf, tracker.image_update
    return positions, offsets, cpf
