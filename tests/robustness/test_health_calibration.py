"""The health confusion table against counts made by hand, and a replay's health states
against the tracker's own, sample by sample."""

import math

import numpy as np
import pytest

from drake_tracker.core.robustness.health import HealthState
from drake_tracker.evaluation.health_calibration import (
    ImageStates,
    band,
    format_health_confusion,
    health_confusion,
    image_errors,
    image_health_csv_text,
)
from drake_tracker.io.replay import replay_run
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.metrics import pose_errors


def _row(state, error, time_s=6.0, method="full_fusion"):
    return {"method": method, "health": state, "translation_mm": str(error),
            "time_s": str(time_s)}


def test_bands_are_closed_above():
    assert [band(e) for e in (0.0, 10.0, 10.01, 50.0, 50.5, math.inf)] == [
        "<= 10 mm", "<= 10 mm", "10-50 mm", "10-50 mm", "> 50 mm", "> 50 mm"]


def test_the_confusion_table_counts_states_by_error_band():
    rows = ([_row("tracking", 2.0)] * 97 + [_row("tracking", 20.0)] * 2
            + [_row("tracking", 80.0)] + [_row("uncertain", 80.0)] * 3
            + [_row("lost", 300.0)] * 6
            + [_row("tracking", 500.0, time_s=1.0)]  # before the settling time
            + [_row("", 200.0, method="encoders_only")]  # no state
            + [_row("tracking", float("nan"))])  # no error
    table = health_confusion(rows, settle_s=5.0)
    assert set(table) == {"full_fusion"}
    t = table["full_fusion"]
    assert t["samples"] == 109
    assert t["counts"] == {("tracking", "<= 10 mm"): 97, ("tracking", "10-50 mm"): 2,
                           ("tracking", "> 50 mm"): 1, ("uncertain", "> 50 mm"): 3,
                           ("lost", "> 50 mm"): 6}
    assert t["tracking_within_10mm"] == pytest.approx(97 / 100)
    assert t["tracking_when_over_50mm"] == pytest.approx(1 / 10)
    text = format_health_confusion(table)
    assert "| tracking | 97 | 2 | 1 |" in text and "97.00 %" in text and "10.00 %" in text


def test_a_replay_reports_the_trackers_health_at_each_sample(apollo):
    # 1.5 s: the start-up search's images move the belief by more than its variance
    # allows, so the innovation test reports tracking from about 0.75 s on this run.
    run = synthetic_run(apollo, duration_s=1.5, encoder_rate_hz=200.0, seed=2)
    seen = {}

    def on_image(tracker, frame):
        seen[frame.arrival_time_s] = int(tracker.health.state)

    times = np.sort(np.concatenate([run.image_arrival_times_s + 1e-6,
                                    [run.reading_times_s[0] - 0.01]]))
    result = replay_run(run, None, apollo, sample_times_s=times, on_image=on_image)
    assert result.health[0] == -1  # before the first reading
    for k, t in enumerate(times[1:], 1):  # just after each image: its state
        arrival = t - 1e-6
        if arrival in seen:
            assert result.health[k] == seen[arrival]
    assert int(HealthState.TRACKING) in set(result.health.tolist())


def test_the_state_after_each_image_is_the_replays_sample_just_after_it(apollo):
    """``ImageStates`` against the replay's own sampler: a sample 1 us after each image's
    arrival holds the estimate and state the image left (readings stamped at or before
    an arrival come first), and the per-image error is the hand against the truth there."""
    run = synthetic_run(apollo, duration_s=1.5, encoder_rate_hz=200.0, seed=2)
    states, arrivals = ImageStates(), []

    def on_image(tracker, frame):
        before = len(states.times_s)
        states(tracker, frame)
        if len(states.times_s) > before:
            arrivals.append(frame.arrival_time_s)

    after = run.image_arrival_times_s + 1e-6
    sampled = replay_run(run, None, apollo, sample_times_s=after, on_image=on_image)
    rows = image_errors(run, states)
    k = np.searchsorted(after, np.asarray(arrivals) + 1e-6 - 1e-9)
    assert len(rows["times_s"]) == len(arrivals) > 5
    assert len(arrivals) == sampled.num_images_applied  # every image here is applied
    # A reading stamped a rounding error after an arrival (0.35000000000000003 against
    # 0.35) comes after the image, and the sample 1 us later holds it as well.
    alone = np.array([not np.any((run.reading_times_s > t) & (run.reading_times_s < a + 1e-6))
                      for t, a in zip(rows["times_s"], arrivals, strict=True)])
    assert alone.sum() >= len(arrivals) - 2
    np.testing.assert_allclose(np.stack(states.X_CE)[alone], sampled.X_CE[k[alone]])
    np.testing.assert_array_equal(rows["health"][alone], sampled.health[k[alone]])
    # The truth between its samples: a straight line, the hand's position at the
    # estimate's time; on a truth sample, pose_errors against that sample.
    t = rows["times_s"]
    i = np.clip(np.searchsorted(run.truth_times_s, t, side="right") - 1, 0,
                len(run.truth_times_s) - 2)
    t0, t1 = run.truth_times_s[i], run.truth_times_s[i + 1]
    w = ((t - t0) / (t1 - t0))[:, None]
    between = (1 - w) * run.truth_X_CE[i, :3, 3] + w * run.truth_X_CE[i + 1, :3, 3]
    np.testing.assert_allclose(rows["translation_mm"][alone], 1e3 * np.linalg.norm(
        sampled.X_CE[k[alone], :3, 3] - between[alone], axis=1), rtol=1e-9, atol=1e-9)
    on_grid = np.isclose(t, t0, rtol=0, atol=1e-12) & alone
    assert on_grid.sum() > 0
    np.testing.assert_allclose(rows["translation_mm"][on_grid], pose_errors(
        sampled.X_CE[k[on_grid]], run.truth_X_CE[i[on_grid]])[0], rtol=1e-9)
    assert np.all(rows["times_s"] <= np.asarray(arrivals) + 1e-12)  # its latest reading
    text = image_health_csv_text("s", "none", 3, {"full_fusion": {"images": rows},
                                                  "encoders_only": {}})
    lines = text.splitlines()
    assert lines[0] == "sequence,bias,method,seed,time_s,translation_mm,health"
    assert len(lines) == len(arrivals) + 1 and all(",full_fusion,3," in x for x in lines[1:])
    assert image_health_csv_text("s", "none", 3, {"encoders_only": {}}) == ""
