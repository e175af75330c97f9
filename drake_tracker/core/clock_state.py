"""The joint readings' time-stamp policy as a vector of numbers: discrete state.

A Drake discrete update can change only numeric state. The Kalman bank system keeps its
reading gate (:class:`~drake_tracker.core.timestamps.ReadingGate`: the stream's clock,
its recent gaps and lags, the encoder-gap bookkeeping) in a discrete state group through
:func:`gate_to_vector` and :func:`gate_from_vector`. A gate rebuilt from its vector takes
the same decisions as the gate it came from (tested on streams with jitter, repeats,
glitches, restarts and non-finite values). What is not carried is the count of its
warnings: a gate rebuilt here is silent (the delay buffer, which runs the same policy on
the same stream, logs).

Layout (:data:`GATE_VECTOR_SIZE` numbers; NaN stands for None):

* the gate: last raw stamp, whether in an encoder gap, the gap's first stamp, readings
  skipped in it, whether the latest reading restarted the stream;
* the clock: offset, last shift, latest stamp, accepted count, the run of rejected
  stamps (count, first, last), the run of lags (count, first), then the recent gaps and
  the recent lags, each as a count followed by RECENT_GAPS slots.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from drake_tracker.core.timestamps import RECENT_GAPS, ReadingGate, StreamClock
from drake_tracker.params import TimestampParams

_GATE_FIELDS = 5
_CLOCK_SCALARS = ("offset_s", "last_shift_s", "latest_s", "_accepted", "_run_count",
                  "_run_first_raw", "_run_last_raw", "_lag_run_count", "_lag_run_first")
_CLOCK_SIZE = len(_CLOCK_SCALARS) + 2 * (1 + RECENT_GAPS)
#: Numbers in a gate's vector.
GATE_VECTOR_SIZE = _GATE_FIELDS + _CLOCK_SIZE


def _number(value: float | None) -> float:
    return float("nan") if value is None else float(value)


def _optional(value: float) -> float | None:
    return None if math.isnan(value) else float(value)


def _history(values: deque) -> list[float]:
    padded = list(values) + [float("nan")] * (RECENT_GAPS - len(values))
    return [float(len(values)), *padded]


def gate_to_vector(gate: ReadingGate) -> np.ndarray:
    """The numbers of ``gate``'s state (:data:`GATE_VECTOR_SIZE`, the module's layout)."""
    clock = gate.clock
    in_gap = gate.gap_start_s is not None
    head = [gate.last_raw_s, float(in_gap), gate.gap_start_s if in_gap else float("nan"),
            float(gate.gap_readings), float(gate.restarted)]
    scalars = [_number(getattr(clock, name)) for name in _CLOCK_SCALARS]
    return np.array(head + scalars + _history(clock._gaps) + _history(clock._lags))


def last_raw_stamp(vector: np.ndarray) -> float:
    """The last raw stamp the gate of ``vector`` saw (NaN before any)."""
    return float(vector[0])


def gate_from_vector(vector: np.ndarray, params: TimestampParams,
                     joint_names: list[str]) -> ReadingGate:
    """A silent :class:`ReadingGate` (no logger) in the state that ``vector`` (from
    :func:`gate_to_vector`) holds. Raises ValueError for a vector of the wrong size."""
    x = np.asarray(vector, dtype=float).ravel()
    if x.shape != (GATE_VECTOR_SIZE,):
        raise ValueError(f"a reading gate's vector has {GATE_VECTOR_SIZE} numbers, got "
                         f"{x.shape}")
    values = x.tolist()
    gate = ReadingGate(params, joint_names, logger=None)
    gate.last_raw_s = values[0]
    gate.gap_start_s = values[2] if values[1] else None
    gate.gap_readings = int(values[3])
    gate.restarted = bool(values[4])
    clock: StreamClock = gate.clock
    scalars = values[_GATE_FIELDS:_GATE_FIELDS + len(_CLOCK_SCALARS)]
    for name, value in zip(_CLOCK_SCALARS, scalars, strict=True):
        setattr(clock, name, value)
    clock.latest_s = _optional(clock.latest_s)
    clock._accepted, clock._run_count = int(clock._accepted), int(clock._run_count)
    clock._lag_run_count = int(clock._lag_run_count)
    at = _GATE_FIELDS + len(_CLOCK_SCALARS)
    for history in (clock._gaps, clock._lags):
        count = int(values[at])
        history.extend(values[at + 1:at + 1 + count])
        at += 1 + RECENT_GAPS
    return gate
