"""The time-stamp policy of core/sensors/timestamps.py on its own: a glitch, a clock that steps and
stays, a glitched first stamp, images out of order, the images following the readings'
clock, rate-limited warnings and the parameters' validation (the faults fed through the
trackers are in test_timestamps.py)."""

import logging

import numpy as np
import pytest
from awkward_stamps import awkward_stamps

from drake_tracker.core.sensors.rate_limited_warning import RateLimitedWarning
from drake_tracker.core.sensors.stamp_params import TimestampParams
from drake_tracker.core.sensors.timestamps import StreamClock
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.params.validation import validate_tracker_params


def test_a_glitch_is_rejected_and_does_not_poison_later_stamps():
    clock = StreamClock("joint reading", TimestampParams())
    stamps = [0.0, 0.005, 0.010, 1000.015, 0.020, 1e6, 0.025, np.inf, np.nan, 0.030]
    times = [clock.check(t).time_s for t in stamps]
    assert times == [0.0, 0.005, 0.010, None, 0.020, None, 0.025, None, None, 0.030]
    assert "far in the future" in clock.check(500.0).problem
    assert "not after" in clock.check(0.030).problem
    assert "not finite" in clock.check(np.nan).problem


@pytest.mark.parametrize("step_s", [-1.0, 200.0])
def test_a_clock_that_steps_and_stays_is_reanchored_after_n_samples(step_s):
    p = TimestampParams(reanchor_after_samples=4)
    clock = StreamClock("joint reading", p)
    raw = [0.005 * k for k in range(20)] + [0.005 * k + step_s for k in range(20, 40)]
    decisions = [clock.check(t) for t in raw]
    rejected = [k for k, d in enumerate(decisions) if d.time_s is None]
    assert rejected == [20, 21, 22]  # the 4th consistent sample re-anchors
    assert decisions[23].reanchored_by_s == pytest.approx(-step_s, abs=1e-9)
    accepted = np.array([d.time_s for d in decisions if d.time_s is not None])
    assert np.all(np.diff(accepted) > 0)
    # The time base continues: the re-anchored stream goes on at its own pace.
    np.testing.assert_allclose(np.diff(accepted[20:]), 0.005, atol=1e-9)
    assert accepted[20] == pytest.approx(0.095 + 0.005 * 4)


def test_a_glitched_first_stamp_is_outvoted_by_the_stream():
    clock = StreamClock("joint reading", TimestampParams(reanchor_after_samples=4))
    decisions = [clock.check(t) for t in [1e6, 0.005, 0.010, 0.015, 0.020, 0.025]]
    assert [d.time_s for d in decisions] == [1e6, None, None, None, 0.020, 0.025]
    assert decisions[4].restarted and not decisions[5].restarted


class _FullCheckClock(StreamClock):
    """A StreamClock that takes every finite stamp after the first through the full
    policy (no fast path for the usual sample)."""

    def check(self, raw_s):
        raw = float(raw_s)
        if self.latest_s is None or not np.isfinite(raw):
            return super().check(raw)
        return self._checked(raw)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("max_behind_s", [0.0, 1.0])
def test_the_usual_sample_fast_path_decides_as_the_full_policy(seed, max_behind_s):
    # A tight min_future_jump_s, so that the future limit is the recent period's, not
    # the floor's.
    params = TimestampParams(reanchor_after_samples=4, min_future_jump_s=0.02,
                             max_future_jump_periods=10.0)
    raw = awkward_stamps(seed)
    fast = StreamClock("joint reading", params, max_behind_s)
    full = _FullCheckClock("joint reading", params, max_behind_s)
    decisions = [(fast.check(r), full.check(r)) for r in raw]
    assert all(a == b for a, b in decisions)
    assert fast.__dict__.keys() == full.__dict__.keys()
    for key, value in fast.__dict__.items():
        assert value == full.__dict__[key] or key == "params", key
    # The stream did go through every branch.
    kinds = {a.kind for a, _ in decisions}
    assert {"", "stamps far in the future", "stamps behind the latest",
            "non-finite stamps"} <= kinds
    assert sum(a.reanchored_by_s is not None for a, _ in decisions) >= 3


def test_images_may_come_out_of_order_within_the_window():
    clock = StreamClock("image", TimestampParams(), max_behind_s=1.0)
    assert [clock.check(t).time_s for t in (1.0, 1.1, 1.05, 0.5)] == [1.0, 1.1, 1.05, 0.5]
    assert "older than" in clock.check(0.05).problem


def test_images_follow_the_readings_clock_but_not_a_stall_of_the_readings():
    clock = StreamClock("image", TimestampParams(), max_behind_s=1.0)
    period, lag = 1 / 30, -0.05
    for k in range(10):  # accepted by the buffer, 50 ms behind its present
        t = clock.check(k * period).time_s
        assert clock.follow_reference(t, t - lag, rejected=False) is None
    # The readings stall at 0.3 s: the images are from the future, the lag grows.
    for k in range(10, 20):
        t = clock.check(k * period).time_s
        assert clock.follow_reference(t, 0.3, rejected=True) is None
    # The camera's clock jumps 1 s ahead of the readings' and stays there.
    shifts = [clock.follow_reference(clock.check(k * period + 1.0).time_s,
                                     k * period - lag, rejected=True) for k in range(20, 25)]
    assert shifts[:4] == [None] * 4 and shifts[4] == pytest.approx(-1.0, abs=1e-9)
    assert clock.check(25 * period + 1.0).time_s == pytest.approx(25 * period, abs=1e-9)


def test_warnings_are_rate_limited_per_kind(caplog):
    warnings = RateLimitedWarning(logging.getLogger("test"))
    with caplog.at_level(logging.WARNING):
        for _ in range(150):
            warnings.warn("a", "problem a")
        warnings.warn("b", "problem b")
    assert len(caplog.records) == 4  # a at 1, 10, 100; b at 1
    assert "100 a so far" in caplog.records[2].getMessage()


def test_timestamp_params_are_validated_by_name():
    p = TrackerParams()
    p.timestamps.reanchor_after_samples = 1
    with pytest.raises(ValueError, match="timestamps.reanchor_after_samples"):
        validate_tracker_params(p)
    p = TrackerParams()
    p.timestamps.min_future_jump_s = float("inf")
    with pytest.raises(ValueError, match="timestamps.min_future_jump_s"):
        validate_tracker_params(p)
