"""Issue 14's time-stamp findings fed through the trackers: a glitched stamp, a clock that
steps back, a camera counter that restarts, an image out of order, a burst of non-finite
readings, each in the offline tracker and in the Diagram (the policy alone:
test_timestamp_policy.py)."""

import logging
from collections import Counter
from dataclasses import replace

import numpy as np
import pytest
from fast_params import small_params
from offline_vs_diagram import H, feed, simulate

from drake_tracker.core.filter.belief_buffer import BeliefBuffer
from drake_tracker.core.filter.kalman import VAR_A
from drake_tracker.core.filter.start import full_reading, new_belief_buffer
from drake_tracker.core.sensors.stamp_params import TimestampParams
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.tracker import Tracker


@pytest.fixture(scope="module")
def run(apollo):
    return synthetic_run(apollo, duration_s=0.5, encoder_rate_hz=200.0, seed=7)




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
    reference = new_belief_buffer(resolve_tracker_params(p, apollo), run.reading_times_s[0],
    run.readings_rad[0])
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
    burst[gap] = np.nan
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
    assert tracker.readings.warnings.counts["non-finite readings"] == gap.sum()


def test_one_joint_without_values_is_predicted_and_the_others_used(apollo, run, caplog):
    """Issue 44: one joint's encoder gives NaN for 0.15 s. The other joints' values are
    used, one warning names the joint, the images inside the burst are applied, and the
    joint's prior there is no wider than the start's angle prior (not the angle random
    walk's radians: ``JointKalmanBank.missing_angle_var``)."""
    burst = run.readings_rad.copy()
    gap = (run.reading_times_s >= 0.15) & (run.reading_times_s < 0.3)
    burst[gap, 1] = np.nan
    params = small_params()
    priors = []
    with caplog.at_level(logging.INFO):
        tracker = Tracker(apollo, run.camera_intrinsics, params)
        original = tracker.images.observe

        def observe(frame, prior, *args, **kwargs):
            priors.append((frame.capture_time_s, prior.copy()))
            return original(frame, prior, *args, **kwargs)

        tracker.images.observe = observe
        _, applied = feed(tracker, run, readings=burst)
    name = apollo.robot_joint_names[1]
    partial = [r for r in caplog.records if "no usable value" in r.getMessage()]
    assert len(partial) == 1 and name in partial[0].getMessage()
    assert "every joint again" in caplog.text and "not finite" not in caplog.text
    assert tracker.readings.warnings.counts["readings with missing joints"] == gap.sum()
    inside = [j for j in applied if 0.16 < run.image_capture_times_s[j] < 0.29]
    assert inside and all(applied[j] for j in inside)
    index = apollo.robot_joint_indices[1]
    start_std = tracker.params.joints.initial_angle_std[index]
    inside_priors = [p for t, p in priors if 0.16 < t < 0.29]
    assert inside_priors
    for prior in inside_priors:
        assert np.sqrt(prior[VAR_A, index]) <= start_std + 1e-12
        assert np.isfinite(prior).all()
    others = [i for i in apollo.robot_joint_indices if i != index]
    np.testing.assert_array_less(np.sqrt(inside_priors[-1][VAR_A, others]), start_std)
    assert np.all(np.isfinite(tracker.estimate().positions))


# ----------------------------------------------------------------- the same in the Diagram


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
        _, applied = feed(Tracker(apollo, run.camera_intrinsics, p), stepped,
                                stamps=stamps)
    assert "re-aligned" in caplog.text and caplog.text.count("re-anchored") == 1
    after = [j for j in applied if run.image_capture_times_s[j] >= 0.2]
    n = p.timestamps.reanchor_after_samples
    assert not any(applied[j] for j in after[:n]) and all(applied[j] for j in after[n:])
    assert len(after) > n + 1


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
        _, applied = feed(Tracker(apollo, run.camera_intrinsics, p), run, stamps=stamps)
    assert "re-aligned" in caplog.text and "in a gap of the readings at the same lag" \
        in caplog.text and "re-anchored" not in caplog.text
    after = [j for j in applied if run.image_capture_times_s[j] >= 0.22]
    n = p.timestamps.reanchor_after_samples
    assert len(after) > n + 1
    assert not any(applied[j] for j in after[:n]) and all(applied[j] for j in after[n:])
    assert all(applied[j] for j in applied if j not in after)


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


def test_the_usual_samples_fast_path_decides_as_the_full_check():
    """``StreamClock.check`` takes ``accept_usual`` for the usual sample; against the
    plain reference (every stamp after the first through ``_checked``, which the fast
    path skips), on seeded stamps with repeats, glitches, steps back and NaN: the same
    decisions and the same clock after each."""
    from drake_tracker.core.sensors.timestamps import StreamClock

    rng = np.random.default_rng(12)
    stamps = np.cumsum(rng.choice([0.001, 0.001, 0.002, 0.0, 0.0005], 3000))
    faults = rng.integers(0, len(stamps), 60)
    stamps[faults[:20]] += 1000.0
    stamps[faults[20:40]] -= 0.5
    stamps[faults[40:50]] = np.nan
    stamps[1500:1520] -= 2.0  # a step back that stays long enough to re-anchor
    stamps[2000:] += 5.0  # a step forward for good
    fast, plain = StreamClock("joint reading", TimestampParams()), StreamClock(
        "joint reading", TimestampParams())
    kinds = Counter()
    for raw in stamps.tolist():
        if plain.latest_s is None and raw == raw:
            expected = plain._accept(raw)
        elif raw != raw:
            expected = plain.check(raw)  # not finite: rejected before either path
        else:
            expected = plain._checked(raw)
        decision = fast.check(raw)
        assert decision == expected, raw
        assert fast.__dict__ == plain.__dict__, raw
        kinds[decision.kind or ("re-anchored" if decision.reanchored_by_s else "usual")] += 1
    assert kinds["usual"] > 2000 and kinds["re-anchored"] >= 1, kinds
    assert kinds["stamps far in the future"] and kinds["stamps behind the latest"], kinds


def test_the_gates_value_check_answers_as_its_plain_numpy_reference():
    """``ReadingGate.admit`` tells a usable reading by one sum of plain floats; against
    the plain numpy check joint by joint (usable: finite and within ±1e6), on seeded
    readings with NaN, ±inf, values beyond ±1e6 and usable ones whose sum is beyond it:
    the same admitted values (NaN where unusable), the same skips and counts."""
    from drake_tracker.core.sensors.reading_gate import MAX_READING_MAGNITUDE, ReadingGate

    rng = np.random.default_rng(45)
    names = [f"j{k}" for k in range(4)]
    gate = ReadingGate(TimestampParams(), names, logger=None)
    skipped = partial = 0
    for k in range(3000):
        values = rng.normal(0.0, 1.0, 4)
        kinds = rng.integers(0, 12, 4)
        values[kinds == 0] = np.nan
        values[kinds == 1] = np.inf * rng.choice([-1, 1])
        values[kinds == 2] = 2e6 * rng.choice([-1, 1])
        values[kinds == 3] = 0.9e6 * rng.choice([-1, 1])  # usable; the sum is beyond
        if rng.random() < 0.05:
            values[:] = np.nan
        usable = np.abs(values) <= MAX_READING_MAGNITUDE
        t = gate.admit(0.001 * k, values)
        if not usable.any():
            assert t is None
            skipped += 1
            continue
        assert t == pytest.approx(0.001 * k)
        np.testing.assert_array_equal(gate.values, np.where(usable, values, np.nan))
        partial += not usable.all()
    assert gate.warnings.counts["non-finite readings"] == skipped > 0
    assert gate.warnings.counts["readings with missing joints"] == partial > 0
