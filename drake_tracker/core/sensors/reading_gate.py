"""The joint readings' gate: new-sample detection on a port, the time-stamp policy of
``core/sensors/timestamps.py`` for the readings' stamps, and the values' check (a run of
non-finite or absurd readings, an encoder gap, gets one warning when it starts and one
info line when it ends).

Each stream has one gate: in a Diagram the delay buffer system holds it, and the
Kalman bank system filters the readings it admitted.
"""

from __future__ import annotations

import copy
import logging
import math

import numpy as np

from drake_tracker.core.sensors.rate_limited_warning import RateLimitedWarning
from drake_tracker.core.sensors.stamp_params import TimestampParams
from drake_tracker.core.sensors.timestamps import StreamClock, log_reanchor

_log = logging.getLogger(__name__)

#: A reading value beyond this (rad, or m) is skipped like a non-finite one: squared in
#: the filter and the CPF, it would overflow (1e300 did, at the next image).
MAX_READING_MAGNITUDE = 1e6


def is_new_stamp(raw_s: float, last_raw_s: float) -> bool:
    """Whether a stamp held on a port is a new sample: it differs from the last one seen
    (NaN after NaN is the same sample)."""
    raw, last = float(raw_s), float(last_raw_s)
    return not (raw == last or (math.isnan(raw) and math.isnan(last)))


class ReadingGate:
    """The joint readings' policy: new-sample detection, the stamp's :class:`StreamClock`,
    and one warning per run of non-finite values (an encoder gap).

    ``admit`` returns the reading's time in the tracker's time base, or None when it is
    skipped (logged through ``warnings``; ``logger=None`` keeps it quiet).
    """

    def __init__(self, params: TimestampParams, joint_names: list[str],
                 logger: logging.Logger | None = _log):
        self.clock = StreamClock("joint reading", params)
        self.joint_names = list(joint_names)
        self._warnings = RateLimitedWarning(logger or _log, enabled=logger is not None)
        #: Whether a copy shares ``_warnings`` (then the first use copies them).
        self._shared_warnings = False
        self.logger = logger
        self.last_raw_s = float("nan")
        self.gap_start_s: float | None = None
        self.gap_readings = 0
        #: The latest admitted reading's values, with NaN for the joints that had none
        #: (non-finite, or beyond ``MAX_READING_MAGNITUDE``): the callers filter these.
        self.values: np.ndarray | None = None
        #: The joints missing from the current run of partial readings (warned once).
        self.missing: tuple[str, ...] = ()
        #: Whether the latest admitted reading restarted the time base
        #: (``StampDecision.restarted``): the caller restarts its belief from it.
        self.restarted = False

    @property
    def warnings(self) -> RateLimitedWarning:
        """The gate's rate-limited warnings and their counts (its own: the first use after
        a copy copies them)."""
        if self._shared_warnings:
            self._warnings, self._shared_warnings = self._warnings.copy(), False
        return self._warnings

    def copy(self) -> ReadingGate:
        """An independent copy that shares the logger and joint names (see StreamClock's),
        and its warnings until either uses them (they change only on a problem): the
        delay buffer's LeafSystem copies its gate at every reading."""
        clone = self._with(self.clock.copy(), self._warnings)
        self._shared_warnings = clone._shared_warnings = True
        return clone

    def __deepcopy__(self, memo) -> ReadingGate:
        return self._with(copy.deepcopy(self.clock, memo), copy.deepcopy(self.warnings, memo))

    def _with(self, clock: StreamClock, warnings: RateLimitedWarning) -> ReadingGate:
        clone = object.__new__(ReadingGate)
        clone.__dict__.update(self.__dict__)
        clone.clock, clone._warnings, clone._shared_warnings = clock, warnings, False
        return clone

    def is_new(self, raw_s: float) -> bool:
        """Whether a stamp held on a port is a new sample (differs from the last seen)."""
        return is_new_stamp(raw_s, self.last_raw_s)

    def admit(self, raw_s: float, values: np.ndarray) -> float | None:
        """The reading's time in the tracker's time base, or None (skipped, logged). A
        reading with some joints' values unusable (non-finite, or absurd) is admitted
        with NaN for them (``values``; those joints are predicted, the others filtered),
        with one warning per run of such readings; with none usable it is skipped (an
        encoder gap: one warning when it starts)."""
        raw_s = float(raw_s)
        self.last_raw_s = raw_s
        self.restarted = False
        self.values = values = np.asarray(values, float)
        partial: tuple[str, ...] = ()
        # NaN, ±inf, absurd values: the usual reading has none, which one sum of plain
        # floats tells (a NaN makes it NaN; a sum within the bound bounds each value, a
        # rounded sum of magnitudes being at least each); else, joint by joint.
        if not sum(map(abs, values.ravel().tolist())) <= MAX_READING_MAGNITUDE:
            with np.errstate(invalid="ignore"):
                bad = ~(np.abs(values) <= MAX_READING_MAGNITUDE)
            names = tuple(n for n, b in zip(self.joint_names, bad, strict=True) if b)
            if bad.all():
                if self.gap_start_s is None:
                    self.gap_start_s = float(raw_s)
                    if self.logger:
                        self.logger.warning(
                            "joint reading stamped %.4f s is not finite (%s; or beyond "
                            "±1e6, which overflows the filter): readings are skipped "
                            "until they are finite again (one warning per gap)",
                            raw_s, ", ".join(names))
                self.gap_readings += 1
                self.warnings.count("non-finite readings")
                return None
            if names:  # some joints have a value: those are used
                partial = names
                self.values = np.where(bad, np.nan, values)
        decision = None
        t = self.clock.accept_usual(raw_s)  # the usual sample: no StampDecision made
        if t is None:
            decision = self.clock.check(raw_s)
            if decision.time_s is None:
                self.warnings.warn(decision.kind, f"joint reading skipped: {decision.problem}")
                return None
            t, self.restarted = decision.time_s, decision.restarted
            if decision.restarted and self.logger:
                self.logger.warning("joint reading clock restarted at %.4f s: the few "
                                    "stamps accepted before were not followed by the "
                                    "stream; the estimate restarts from this reading", raw_s)
        if self.gap_start_s is not None:
            if self.logger:
                self.logger.info("joint readings finite again at %.4f s after %d skipped "
                                 "from %.4f s", raw_s, self.gap_readings, self.gap_start_s)
            self.gap_start_s, self.gap_readings = None, 0
        if decision is not None and decision.reanchored_by_s is not None and self.logger:
            log_reanchor(self.logger, "joint reading", decision, raw_s, self.clock)
        if partial != self.missing:
            if partial and self.logger:
                self.logger.warning(
                    "joint reading stamped %.4f s has no usable value for %s (non-finite, "
                    "or beyond ±1e6): %s predicted from the images until %s again, the "
                    "other joints filtered (one warning per run)", raw_s,
                    ", ".join(partial), "it is" if len(partial) == 1 else "they are",
                    "it reads" if len(partial) == 1 else "they read")
            elif self.logger:
                self.logger.info("joint reading stamped %.4f s has every joint again",
                                 raw_s)
            self.missing = partial
        if partial:
            self.warnings.count("readings with missing joints")
        return t
