"""The reading gate as numbers (``ReadingGate.to_vector``/``from_vector``, for the Kalman
bank system's discrete state): a gate rebuilt from its vector at every reading takes the
decisions of a gate that lives on, on awkward streams."""

import numpy as np
import pytest
from awkward_stamps import awkward_stamps

from drake_tracker.core.sensors.reading_gate import ReadingGate
from drake_tracker.params.tracker_params import TimestampParams

JOINTS = ["a", "b"]


def _readings(seed: int, count: int) -> np.ndarray:
    """Finite readings with runs of NaN and of absurd values (encoder gaps)."""
    rng = np.random.default_rng(100 + seed)
    values = rng.normal(0.0, 1.0, (count, len(JOINTS)))
    for start in rng.integers(0, count - 20, 12):
        values[start:start + rng.integers(1, 15), rng.integers(0, 2)] = rng.choice(
            [np.nan, np.inf, 1e9])
    return values


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_gate_rebuilt_from_its_vector_decides_as_the_original(seed):
    params = TimestampParams(reanchor_after_samples=4, min_future_jump_s=0.02,
                             max_future_jump_periods=10.0)
    # a glitched first stamp, so that the stream restarts once
    stamps = [1e6] + awkward_stamps(seed, 4000)
    values = _readings(seed, len(stamps))
    living = ReadingGate(params, JOINTS, logger=None)
    vector = ReadingGate(params, JOINTS, logger=None).to_vector()
    seen = {"restarted": 0, "gap": 0, "accepted": 0, "new": 0}
    for raw, reading in zip(stamps, values, strict=True):
        rebuilt = ReadingGate.from_vector(vector, params, JOINTS)
        assert rebuilt.is_new(raw) == living.is_new(raw)
        if living.is_new(raw):
            seen["new"] += 1
            t_living = living.admit(raw, reading)
            t_rebuilt = rebuilt.admit(raw, reading)
            assert t_rebuilt == t_living
            assert rebuilt.restarted == living.restarted
            seen["restarted"] += living.restarted
            seen["accepted"] += t_living is not None
        seen["gap"] += living.gap_start_s is not None
        vector = rebuilt.to_vector()
        np.testing.assert_array_equal(vector, living.to_vector())
        assert vector.shape == (ReadingGate.VECTOR_SIZE,)
    # the streams did go through every branch
    assert seen["restarted"] >= 1 and seen["gap"] >= 12
    assert 0 < seen["accepted"] < seen["new"] < len(stamps)


def test_a_vector_of_the_wrong_size_is_an_error():
    with pytest.raises(ValueError, match="reading gate's state has"):
        ReadingGate.from_vector(np.zeros(3), TimestampParams(), JOINTS)
