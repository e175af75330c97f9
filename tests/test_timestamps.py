"""Issue 14's time-stamp findings fed through the trackers: a glitched stamp, a clock that
steps back, a camera counter that restarts, an image out of order, a burst of non-finite
readings, each in the offline tracker and in the Diagram (the policy alone:
test_timestamp_policy.py)."""

import logging
from dataclasses import replace

import numpy as np
import pytest
from fast_params import small_params
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_tracker.core.filter.belief_buffer import BeliefBuffer
from drake_tracker.core.image_step import full_reading, new_belief_buffer
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.params.tracker_params import TimestampParams
from drake_tracker.systems.add_tracker import AddTracker
from drake_tracker.systems.recorded_run_source import RecordedRunSource
from drake_tracker.tracker import Tracker

H = 1.0 / 200.0  # the synthetic runs' encoder period (s)


@pytest.fixture(scope="module")
def run(apollo):
    return synthetic_run(apollo, duration_s=0.5, encoder_rate_hz=200.0, seed=7)


# ----------------------------------------------------------------- feeding runs with faults
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


def test_offline_tracker_survives_a_glitched_stamp_exactly(apollo, run, caplog):
    """Finding 1: a +1000 s stamp ended tracking for good ("not after the previous
    one" for every later reading). Now it is as if that one reading were missing."""
    glitched = run.reading_times_s.copy()
    glitched[30] += 1000.0
    with caplog.at_level(logging.WARNING):
        faulty, applied = feed(Tracker(apollo, run.camera_intrinsics, small_params()), run,
                               stamps=glitched)
    assert "far in the future" in caplog.text and "1000.1500" in caplog.text
    missing = run.readings_rad.copy()
    missing[30] = np.nan  # the same run without that reading (skipped as non-finite)
    clean, applied_clean = feed(Tracker(apollo, run.camera_intrinsics, small_params()), run,
                                readings=missing)
    assert applied == applied_clean and sum(applied.values()) >= 10
    for a, b in zip(faulty[1:], clean[1:], strict=True):
        np.testing.assert_array_equal(a, b)


def test_offline_tracker_reanchors_a_clock_that_steps_back(apollo, run, caplog):
    """Finding 2: after a 1 s step back, readings were ignored for 1 s and no image was
    applied. Now the clock is re-anchored after N samples and images keep coming: the
    same as the run without the N - 1 readings rejected before the re-anchoring."""
    p = small_params()
    n = p.timestamps.reanchor_after_samples
    step = np.searchsorted(run.reading_times_s, 0.2)
    stepped = run.reading_times_s - 1.0 * (np.arange(len(run.reading_times_s)) >= step)
    with caplog.at_level(logging.WARNING):
        tracker = Tracker(apollo, run.camera_intrinsics, p)
        estimates, applied = feed(tracker, run, stamps=stepped)
    assert caplog.text.count("re-anchored") == 1 and "not after" in caplog.text
    assert tracker.estimate().time_s == pytest.approx(run.reading_times_s[-1], abs=1e-9)
    late = [j for j in applied if run.image_capture_times_s[j] > 0.25]
    assert len(late) >= 4 and all(applied[j] for j in late)
    missing = run.readings_rad.copy()
    missing[step:step + n - 1] = np.nan
    clean, applied_clean = feed(Tracker(apollo, run.camera_intrinsics, p), run,
                                readings=missing)
    assert applied == applied_clean
    np.testing.assert_allclose(np.array(estimates[1:]), np.array(clean[1:]), rtol=0,
                               atol=1e-9)


def test_an_image_out_of_order_is_applied_at_its_time_exactly(apollo, run, monkeypatch):
    """Finding 4: an image older than the last applied one was dropped silently. Now it
    is applied at its capture time; the belief is the one of the same observations
    inserted in time order (the buffer is exact for out-of-order images)."""
    arrivals = run.image_arrival_times_s.copy()
    arrivals[6] = arrivals[7] + 2 * H  # image 6 arrives after image 7
    stored = []
    original = BeliefBuffer.add_image_observation

    def recording(buffer, anchor, observation):
        stored.append((anchor, observation))
        original(buffer, anchor, observation)

    monkeypatch.setattr(BeliefBuffer, "add_image_observation", recording)
    p = small_params()
    tracker = Tracker(apollo, run.camera_intrinsics, p)
    _, applied = feed(tracker, run, arrivals=arrivals)
    assert applied[6] and applied[7] and all(applied.values())
    times = [anchor.image_time_s for anchor, _ in stored]
    assert times != sorted(times)  # really applied out of order
    reference = new_belief_buffer(apollo, p, run.reading_times_s[0], run.readings_rad[0])
    for t, reading in zip(run.reading_times_s, run.readings_rad, strict=True):
        reference.add_reading(t, full_reading(apollo, reading))
    for anchor, observation in sorted(stored, key=lambda pair: pair[0].image_time_s):
        original(reference, anchor, observation)
    np.testing.assert_allclose(tracker.buffer.present()[1], reference.present()[1],
                               rtol=1e-12, atol=1e-14)


def test_a_nan_burst_gives_one_warning_and_no_wide_prior(apollo, run, caplog):
    """Finding 7: one warning per gap, not per reading; an image inside the gap is
    skipped (it would have a radians-wide prior), the others are applied."""
    burst = run.readings_rad.copy()
    gap = (run.reading_times_s >= 0.15) & (run.reading_times_s < 0.3)
    burst[gap, 1] = np.nan
    with caplog.at_level(logging.INFO):
        tracker = Tracker(apollo, run.camera_intrinsics, small_params())
        _, applied = feed(tracker, run, readings=burst)
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    nan_warnings = [r for r in warnings if "not finite" in r.getMessage()]
    assert len(nan_warnings) == 1 and apollo.robot_joint_names[1] in caplog.text
    assert "finite again" in caplog.text
    inside = [j for j in applied if 0.15 < run.image_capture_times_s[j] < 0.295]
    assert inside and not any(applied[j] for j in inside)
    assert "gap of the joint readings" in caplog.text
    outside = [j for j in applied if run.image_capture_times_s[j] > 0.3]
    assert outside and all(applied[j] for j in outside)
    assert np.all(np.sqrt(tracker.estimate().position_variances) < 0.1)
    assert "re-aligned" not in caplog.text  # a real gap says nothing about the clocks


# ----------------------------------------------------------------- the same in the Diagram
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


def test_diagram_survives_glitch_step_restart_and_order_like_the_offline_tracker(
        apollo, run, caplog):
    """Findings 1-4 inside the Diagram: a +1000 s stamp, a 1 s step back of the encoder
    clock, a camera counter restart and an image out of order. Before, the Diagram
    stopped taking readings at the glitch (439 mm from then on) and ignored the images
    after the restart; now it gives the offline tracker's estimates."""
    stamps = run.reading_times_s.copy()
    stamps[20] += 1000.0
    stamps[60:] -= 1.0
    sequences = np.arange(len(run.image_capture_times_s))
    sequences[8:] -= 8  # the counter restarts at image 8
    arrivals = run.image_arrival_times_s.copy()
    arrivals[4] = arrivals[5] + 2 * H  # image 4 arrives after image 5
    run = _with_arrivals(run, arrivals)
    p = small_params()
    offline, applied = feed(Tracker(apollo, run.camera_intrinsics, p), run, stamps=stamps,
                            sequences=sequences)
    assert all(applied.values())
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        diagram, images_applied = simulate(apollo, run, p, stamps, sequences)
    assert "restarted" in caplog.text and caplog.text.count("re-anchored") == 1
    assert "far in the future" in caplog.text
    assert_same_when_settled(run, diagram, offline)
    assert images_applied == len(applied)


def test_diagram_nan_burst_gives_one_warning_and_skips_the_image_inside(apollo, run, caplog):
    """Finding 7 in the Diagram: a 0.15 s burst of NaN readings gave a warning per reading
    per system, and an image inside it was applied with a 6.84 rad prior."""
    burst = run.readings_rad.copy()
    burst[(run.reading_times_s >= 0.15) & (run.reading_times_s < 0.3), 1] = np.nan
    run = replace(run, readings_rad=burst)
    p = small_params()
    offline, applied = feed(Tracker(apollo, run.camera_intrinsics, p), run)
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        diagram, images_applied = simulate(apollo, run, p)
    warnings = [r.getMessage() for r in caplog.records]
    assert sum("not finite" in w for w in warnings) == 1
    assert sum("gap of the joint readings" in w for w in warnings) >= 1
    assert images_applied == sum(applied.values()) < len(applied)
    assert_same_when_settled(run, diagram, offline)


def test_a_glitched_first_stamp_restarts_the_estimate_offline_and_in_the_diagram(
        apollo, run, caplog):
    """A finite glitch as the very first stamp (1e6 s) became the time base: the good
    readings after it were re-anchored to it and no image could be placed again. Now
    the stream outvotes it and the estimate restarts from the reading that does."""
    stamps = run.reading_times_s.copy()
    stamps[0] = 1e6
    p = small_params()
    with caplog.at_level(logging.WARNING):
        tracker = Tracker(apollo, run.camera_intrinsics, p)
        offline, applied = feed(tracker, run, stamps=stamps)
    assert "restarted at" in caplog.text
    assert tracker.estimate().time_s == pytest.approx(run.reading_times_s[-1])
    late = [j for j in applied if run.image_capture_times_s[j] > 0.1]
    assert late and all(applied[j] for j in late)
    diagram, images_applied = simulate(apollo, run, p, stamps)
    assert images_applied == sum(applied.values())
    assert_same_when_settled(run, diagram[10:], offline[10:], first=10)


def simulate(apollo, run, p, stamps=None, sequences=None):
    """The Diagram on ``run`` (with faulty stamps or sequence numbers): the estimate
    right after each reading's bank update, and the number of images applied."""
    stamps = run.reading_times_s if stamps is None else stamps
    sequences = np.arange(len(run.image_capture_times_s)) if sequences is None else sequences
    builder = DiagramBuilder()
    source = builder.AddSystem(FaultySource(run, stamps, sequences))
    tracker = AddTracker(builder, apollo, run.camera_intrinsics, p,
                         source.GetOutputPort("measured_position"),
                         source.GetOutputPort("measurement_time"),
                         source.GetOutputPort("depth_frame"), encoder_period_s=H)
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    bank_context = tracker.kalman_bank.GetMyContextFromRoot(context)
    estimates = []
    for t in run.reading_times_s + 0.6 * H:
        simulator.AdvanceTo(t)
        estimates.append(tracker.port("estimated_position").Eval(bank_context).copy())
    cpf = tracker.image_update.GetMyContextFromRoot(context).get_abstract_state(0)
    return estimates, cpf.get_value().images_applied


def assert_same_when_settled(run, diagram, offline, first=0):
    """The Diagram applies an image at the first CPF tick after it arrives (<= h later),
    the offline tracker at once: compare where no image arrived in the last 2 ticks
    (samples from the ``first`` reading on)."""
    arrivals = run.image_arrival_times_s
    settled = np.array([not np.any((arrivals > t - 2.5 * H) & (arrivals <= t))
                        for t in run.reading_times_s[first:] + 0.6 * H])
    assert settled.sum() > 0.5 * len(settled)
    difference = np.abs(np.array(diagram)[settled] - np.array(offline)[settled])
    assert np.max(difference) <= 1e-9, np.max(difference)


def _with_arrivals(run, arrivals):
    return replace(run, image_arrival_times_s=arrivals)


def test_a_clock_step_shared_by_encoders_and_camera_is_followed_by_both(apollo, run, caplog):
    """A host clock stepping back by 1 s moves both streams: the readings are re-anchored,
    and the images (in order among themselves) would then be older than the buffer for
    good; they are re-aligned after N in a row at the same lag, offline and in the
    Diagram alike."""
    stamps = run.reading_times_s - 1.0 * (run.reading_times_s >= 0.2)
    captures = run.image_capture_times_s - 1.0 * (run.image_capture_times_s >= 0.2)
    stepped = replace(run, image_capture_times_s=captures)
    p = small_params()
    with caplog.at_level(logging.WARNING):
        offline, applied = feed(Tracker(apollo, run.camera_intrinsics, p), stepped,
                                stamps=stamps)
    assert "re-aligned" in caplog.text and caplog.text.count("re-anchored") == 1
    after = [j for j in applied if run.image_capture_times_s[j] >= 0.2]
    n = p.timestamps.reanchor_after_samples
    assert not any(applied[j] for j in after[:n]) and all(applied[j] for j in after[n:])
    assert len(after) > n + 1
    diagram, images_applied = simulate(apollo, stepped, p, stamps)
    assert images_applied == sum(applied.values())
    assert_same_when_settled(stepped, diagram, offline)


@pytest.mark.parametrize("how", ["deepcopy", "copy"])
def test_a_copied_gate_is_independent_and_shares_only_what_never_changes(how):
    """The systems copy their gate at every sample: the copy (``copy()``, or a deep copy)
    must take the same decisions as the original from then on, and neither may see the
    other's later samples."""
    import copy

    from drake_tracker.core.sensors.reading_gate import ReadingGate

    gate = ReadingGate(TimestampParams(), ["a", "b"])
    for k in range(20):
        gate.admit(0.01 * k, np.zeros(2))
    gate.admit(float("nan"), np.zeros(2))
    clone = copy.deepcopy(gate) if how == "deepcopy" else gate.copy()
    assert clone.logger is gate.logger and clone.clock.params is gate.clock.params
    for later in (0.25, 0.26, 1000.0):
        assert clone.admit(later, np.zeros(2)) == gate.admit(later, np.zeros(2))
    assert clone.warnings.counts == gate.warnings.counts
    clone.admit(0.27, np.zeros(2))
    clone.admit(0.26, np.zeros(2))  # not after the latest: counted in the clone only
    assert clone.warnings.counts != gate.warnings.counts
    assert clone.clock.latest_s == 0.27 and gate.clock.latest_s == 0.26
    assert clone.clock._gaps is not gate.clock._gaps


def test_diagram_warns_of_frames_it_never_saw(apollo, run, caplog):
    """A camera that drops frames (or frames replaced on the port between two checks)
    shows as a gap in the sequence numbers: counted as skipped, and logged, where before
    it was only counted."""
    sequences = np.arange(len(run.image_capture_times_s))
    sequences[6:] += 3  # three frames after image 5 never reached the port
    with caplog.at_level(logging.WARNING):
        simulate(apollo, run, small_params(), run.reading_times_s, sequences)
    assert "3 frame(s) before image 9 were never on the depth port" in caplog.text


def test_an_encoder_clock_step_forward_is_told_from_a_gap_by_the_images(apollo, run, caplog):
    """Issue 14's last lost data: readings whose clock jumps 0.2 s ahead (within the
    30 s glitch limit) leave a 0.2 s "gap" that the camera's next images fall into,
    0.2 s behind their usual lag. They were skipped as in a gap of the readings for as
    long as the step (1 s of images for a 1 s step); now N of them re-align the images
    with the readings, offline and in the Diagram alike, and the rest are applied."""
    stamps = run.reading_times_s + 0.2 * (run.reading_times_s >= 0.22)
    p = small_params()
    with caplog.at_level(logging.WARNING):
        offline, applied = feed(Tracker(apollo, run.camera_intrinsics, p), run,
                                stamps=stamps)
    assert "re-aligned" in caplog.text and "in a gap of the readings at the same lag" \
        in caplog.text and "re-anchored" not in caplog.text
    after = [j for j in applied if run.image_capture_times_s[j] >= 0.22]
    n = p.timestamps.reanchor_after_samples
    assert len(after) > n + 1
    assert not any(applied[j] for j in after[:n]) and all(applied[j] for j in after[n:])
    assert all(applied[j] for j in applied if j not in after)
    diagram, images_applied = simulate(apollo, run, p, stamps)
    assert images_applied == sum(applied.values())
    assert_same_when_settled(run, diagram, offline)


def test_median_is_numpys_median_bit_for_bit():
    from collections import deque

    from drake_tracker.core.sensors.timestamps import RECENT_GAPS, median

    rng = np.random.default_rng(0)
    for n in range(1, RECENT_GAPS + 1):
        for values in (rng.uniform(0.0, 0.01, n), rng.normal(0.0, 1.0, n),
                       0.001 * rng.integers(1, 3, n), np.round(rng.uniform(0, 1e-3, n), 6)):
            window = deque(values.tolist(), maxlen=RECENT_GAPS)
            assert median(window) == float(np.median(window))
    assert np.isnan(median([1.0, float("nan"), 2.0]))
