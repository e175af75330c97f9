"""The time-stamp policy: which stamps of a sensor stream the tracker accepts.

One :class:`StreamClock` per stream (the joint readings, the depth images) maps each
raw stamp to the tracker's time base, or rejects it with a reason:

* a stamp that is not finite;
* a stamp far in the future: more than ``max(min_future_jump_s,
  max_future_jump_periods x the stream's recent sample period)`` after the latest
  accepted one (a glitched stamp, e.g. +1000 s);
* a stamp behind the latest accepted one (by more than ``max_behind_s``: 0 for the
  readings, which must come in order; the buffer horizon for images, which may come in
  any order).

A rejected stamp changes nothing, so one glitch never poisons later data. A clock that
steps back or forward *and stays there* is different: ``reanchor_after_samples``
consecutive rejected stamps that follow each other at the stream's normal pace are
taken as the clock's new time base, and the stream is re-anchored: from then on its
stamps are shifted so that they continue one recent period after the latest accepted
stamp. The tracker keeps its belief and its buffer; the samples of the run before the
re-anchoring one are lost. (Taking every re-anchored clock to continue where it was keeps
a camera whose clock did not step aligned with encoders whose clock did.)

:class:`RateLimitedWarning` (``core/sensors/rate_limited_warning.py``) logs each kind of problem
at its 1st, 10th, 100th, ... occurrence, with the count; the joint readings' gate
(``core/sensors/reading_gate.py``) adds the values' check: a run of non-finite readings (an
encoder gap) gets one warning when it starts and one info line when it ends.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drake_tracker.core.sensors.stamp_params import TimestampParams

if TYPE_CHECKING:
    from drake_tracker.core.filter.belief_buffer import BeliefBuffer

_log = logging.getLogger(__name__)

#: Accepted gaps kept to estimate a stream's recent sample period (their median).
RECENT_GAPS = 16


def median(values: Iterable[float]) -> float:
    """``float(np.median(values))`` of a few floats (the middle one, or the mean of the
    two middle ones; NaN if any is NaN), without numpy's overhead: a stream's recent
    period is taken at every sample, 1000 times a simulated second."""
    ordered = sorted(values)
    n = len(ordered)
    if n == 0 or any(v != v for v in ordered):
        return float("nan")
    m = n // 2
    return float(ordered[m]) if n % 2 else (ordered[m - 1] + ordered[m]) / 2


def _appended(recent: tuple[float, ...], value: float) -> tuple[float, ...]:
    """``recent`` with ``value`` appended, the oldest dropped past ``RECENT_GAPS``: a
    tuple, which a copy of the clock shares until it appends."""
    return (*recent[1 - RECENT_GAPS:], value)


@dataclass(frozen=True)
class StampDecision:
    """What :meth:`StreamClock.check` made of a raw stamp."""

    #: The stamp in the tracker's time base (s), or None when rejected.
    time_s: float | None
    #: Why it was rejected ("" when accepted).
    problem: str = ""
    #: Short name of the problem (the rate limiter's key).
    kind: str = ""
    #: The shift (s) added to this stream's stamps from now on, when this stamp
    #: re-anchored the stream; else None.
    reanchored_by_s: float | None = None
    #: True when this stamp restarted the stream's time base: the few stamps accepted
    #: before it (fewer than ``reanchor_after_samples``, e.g. a glitched first stamp)
    #: were the outliers, and what was built on them should restart too.
    restarted: bool = False


class StreamClock:
    """The time-stamp policy of one stream (see the module docstring).

    Args:
        name: the stream's name in messages ("joint reading", "image").
        params: thresholds.
        max_behind_s: how far behind the latest accepted stamp a stamp may be (s);
            0 demands strictly increasing stamps.
    """

    def __init__(self, name: str, params: TimestampParams, max_behind_s: float = 0.0):
        self.name = name
        self.params = params
        self.max_behind_s = float(max_behind_s)
        self.offset_s = 0.0
        #: The shift of the latest re-anchoring (s; 0 before any).
        self.last_shift_s = 0.0
        self.latest_s: float | None = None
        #: The latest accepted gaps and lags (at most ``RECENT_GAPS``; tuples, shared
        #: by copies: a new one at each append).
        self._gaps: tuple[float, ...] = ()
        self._run_count = 0
        self._run_first_raw = 0.0
        self._run_last_raw = 0.0
        self._lags: tuple[float, ...] = ()
        self._accepted = 0
        self._lag_run_count = 0
        self._lag_run_first = 0.0

    def copy(self) -> StreamClock:
        """An independent copy that shares the (immutable) parameters, name and recent
        gaps and lags (tuples): the tracker's systems copy their clocks at every sample,
        1000 times a simulated second."""
        clone = object.__new__(StreamClock)
        clone.__dict__.update(self.__dict__)
        return clone

    def __deepcopy__(self, memo) -> StreamClock:
        return self.copy()

    @property
    def recent_period_s(self) -> float:
        """Median of the latest accepted gaps (0 before two stamps)."""
        return median(self._gaps) if self._gaps else 0.0

    @property
    def typical_lag_s(self) -> float | None:
        """Median lag behind the reference of the latest accepted samples (s; see
        :meth:`follow_reference`), or None before ``reanchor_after_samples`` of them."""
        if len(self._lags) < self.params.reanchor_after_samples:
            return None
        return median(self._lags)

    def future_limit_s(self) -> float:
        """How far after the latest accepted stamp a stamp may be (s)."""
        p = self.params
        return max(p.min_future_jump_s, p.max_future_jump_periods * self.recent_period_s)

    def peek(self, raw_s: float) -> StampDecision:
        """What :meth:`check` would decide, without changing anything."""
        return self.copy().check(raw_s)

    def check(self, raw_s: float) -> StampDecision:
        """Maps ``raw_s`` to the tracker's time base, or rejects it (see the module)."""
        raw = float(raw_s)
        if not math.isfinite(raw):
            return StampDecision(None, f"its time stamp {raw} is not finite", "non-finite stamps")
        if self.latest_s is None:
            return self._accept(raw)
        t = self.accept_usual(raw)
        return self._checked(raw) if t is None else StampDecision(t)

    def accept_usual(self, raw_s: float) -> float | None:
        """The usual sample: a stamp after the latest accepted one and within the least
        future limit (``future_limit_s`` is never below it), which :meth:`check` accepts
        without the median of the recent gaps; accepts it as :meth:`check` would and
        returns its time. None, with nothing changed, for any other stamp (then
        :meth:`check` decides): the readings' gate takes this first at every sample,
        1000 times a simulated second."""
        latest = self.latest_s
        if latest is None:
            return None
        t = raw_s + self.offset_s
        if not 0 < t - latest <= self.params.min_future_jump_s:  # NaN too
            return None
        self._gaps = _appended(self._gaps, t - latest)
        self.latest_s = t
        self._run_count = 0
        self._accepted += 1
        return t

    def _checked(self, raw: float) -> StampDecision:
        """:meth:`check`'s decision for a finite stamp after the first, in full."""
        t = raw + self.offset_s
        gap = t - self.latest_s
        if gap > self.future_limit_s():
            problem = (f"stamped {raw:.4f} s, it is {gap:.3f} s after the latest accepted "
                       f"{self.name} ({self.latest_s - self.offset_s:.4f} s): far in the "
                       f"future (limit {self.future_limit_s():.3f} s)")
            kind = "stamps far in the future"
        elif gap < -self.max_behind_s or (self.max_behind_s == 0 and gap <= 0):
            latest = f"the latest accepted {self.name} ({self.latest_s - self.offset_s:.4f} s)"
            problem = (f"stamped {raw:.4f} s, it is older than {latest} by more than "
                       f"{self.max_behind_s:.3f} s" if self.max_behind_s > 0 else
                       f"stamped {raw:.4f} s, it is not after {latest}")
            kind = "stamps behind the latest"
        else:
            return self._accept(raw)
        return self._rejected(raw, problem, kind)

    def follow_reference(self, time_s: float, reference_s: float, rejected: bool,
                         reference_shift_s: float = 0.0) -> float | None:
        """Keeps this stream aligned with a reference clock (the images with the joint
        readings: ``reference_s`` is the buffer's present, ``rejected`` whether the buffer
        refused ``time_s`` as too old or from the future). After
        ``reanchor_after_samples`` refusals in a row at the same lag (within half a
        period: a stall of the reference makes the lag grow instead), the stream is
        shifted back to its typical lag; returns that shift, else None. A clock step
        shared by the encoders and the camera needs it: the readings are re-anchored, and
        the images, still in order among themselves, would be refused for good; when
        the shift is within half a period of ``reference_shift_s`` (the reference's own
        latest re-anchoring, or the jump of its clock over a gap, see ``follow_buffer``),
        it is taken to be the same step and that shift is used: the same in every shell,
        whatever the phase at which the lags were measured."""
        lag = time_s - reference_s
        if not rejected:
            self._lags = _appended(self._lags, lag)
            self._lag_run_count = 0
            return None
        if self.typical_lag_s is None:
            return None  # no typical lag yet (e.g. the first images after the start)
        if self._lag_run_count and abs(lag - self._lag_run_first) <= 0.5 * self.recent_period_s:
            self._lag_run_count += 1
        else:
            self._lag_run_count, self._lag_run_first = 1, lag
        if self._lag_run_count < self.params.reanchor_after_samples:
            return None
        shift = self.typical_lag_s - lag
        if reference_shift_s and abs(shift - reference_shift_s) <= 0.5 * self.recent_period_s:
            shift = reference_shift_s
        self.offset_s += shift
        self.latest_s += shift
        self.last_shift_s = shift
        self._lag_run_count = 0
        return shift

    def _accept(self, raw: float, reanchored_by: float | None = None) -> StampDecision:
        t = raw + self.offset_s
        if self.latest_s is not None and t > self.latest_s:
            self._gaps = _appended(self._gaps, t - self.latest_s)
        self.latest_s = t if self.latest_s is None else max(self.latest_s, t)
        self._run_count = 0
        self._accepted += 1
        return StampDecision(t, reanchored_by_s=reanchored_by)

    def _rejected(self, raw: float, problem: str, kind: str) -> StampDecision:
        """Counts a run of rejected stamps at the stream's pace; re-anchors after enough."""
        limit = max(self.future_limit_s(), 0.0)
        follows = self._run_count > 0 and 0 < raw - self._run_last_raw <= limit
        if follows:
            self._run_count += 1
        else:
            self._run_count, self._run_first_raw = 1, raw
        self._run_last_raw = raw
        if self._run_count < self.params.reanchor_after_samples:
            return StampDecision(None, problem, kind)
        if self._accepted < self.params.reanchor_after_samples:
            # Fewer stamps than this run were accepted before it: they were the outliers.
            self.latest_s, self._accepted, self._gaps = None, 0, ()
            return StampDecision(self._accept(raw).time_s, restarted=True)
        new_offset = self.latest_s + self.recent_period_s - self._run_first_raw
        shift = new_offset - self.offset_s
        self.offset_s, self.last_shift_s = new_offset, shift
        return self._accept(raw, reanchored_by=shift)


def log_reanchor(logger: logging.Logger, name: str, decision: StampDecision, raw_s: float,
                 clock: StreamClock) -> None:
    """The one message of a re-anchored stream."""
    logger.warning("%s clock re-anchored: its stamps stepped and stayed there for %d "
                   "samples (now %.4f s); from now on they are shifted by %+.4f s; the "
                   "belief is kept", name, clock.params.reanchor_after_samples, raw_s,
                   decision.reanchored_by_s)


def problem_kind(problem: str) -> str:
    """A short, stable name for a buffer's or image's problem (the rate limiter's key)."""
    for words in ("not finite", "future", "older than", "gap", "no valid depth pixel",
                  "no arm where one must be"):
        if words in problem:
            return f"images: {words}"
    return "images: other problems"


def follow_buffer(clock: StreamClock, buffer: BeliefBuffer, image_time_s: float,
                  logger: logging.Logger, readings_clock: StreamClock) -> None:
    """Runs an accepted image time through ``clock.follow_reference`` against the belief
    buffer's present.

    An image in a gap of the readings is evidence about the clocks only when the gap
    looks like a step of the readings' clock: a later reading has closed the gap, and
    the image lags the present by more than its typical lag plus half the gap (readings
    that jumped 1 s ahead leave a 1 s "gap" which the camera's next images fall into,
    1 s behind). An image in an open gap, or one that arrives at its usual lag (a real
    encoder gap: the readings stopped, or were not finite), says nothing about them."""
    problem = buffer.image_time_problem(image_time_s)
    gap = buffer.reading_gap(image_time_s) if problem is None else None
    step_s = readings_clock.last_shift_s
    if gap is not None:
        start_s, end_s, closed = gap
        lag = image_time_s - buffer.now_s
        if not (closed and clock.typical_lag_s is not None
                and lag < clock.typical_lag_s - 0.5 * (end_s - start_s)):
            return
        problem = "in a gap of the readings that the readings' clock stepped over"
        step_s = end_s - start_s - readings_clock.recent_period_s  # the readings' jump
    shift = clock.follow_reference(image_time_s, buffer.now_s, problem is not None, step_s)
    if shift is not None:
        reason = ("from the future" if "future" in problem else "in a gap of the readings"
                  if "gap" in problem else "too old")
        logger.warning("image clock re-aligned with the joint readings: %d images in a row "
                       "were %s at the same lag; from now on their stamps are shifted by "
                       "%+.4f s", clock.params.reanchor_after_samples, reason, shift)
