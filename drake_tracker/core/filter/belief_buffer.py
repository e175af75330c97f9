"""The delay buffer: joint readings, image corrections and the belief after each (paper §IV-C).

An image stamped ``t'`` is applied at the joint reading nearest to ``t'`` (its *anchor*),
as an observation of the angles at ``t'`` carried to the anchor by the encoders' own
measurement of the motion in between (linear interpolation of the two readings around
``t'``); then every later event is filtered again to reach the present. Predicting the
belief to ``t'`` with the angle process instead would widen the angle prior by
``σa²·|t' - t_k|`` (σa = 10 rad/√s: 0.23 rad after 0.5 ms), and the next reading would
erase most of what the image said about the bias; with the anchor, an image carries the
same information wherever it falls between two readings. Without readings around ``t'``
(vision only, or an encoder gap longer than ``max_interpolation_gap_s``) the belief is
predicted to ``t'``. (dbrt takes the first belief *after* ``t'`` and applies that
reading twice; this does neither.)

An image update is kept in the buffer as a per-joint Gaussian pseudo-observation of the
angles in information form (``precision``, ``information``), the likelihood implied by
the CPF's moment-matched marginals relative to the prior they came from. Applying it to
that same prior gives back exactly eq. (16); replaying it after an earlier delayed image
(out-of-order images) stays linear-Gaussian and cheap, with no second CPF run
(``core/filter/angle_observation.py``).
"""

from __future__ import annotations

import bisect
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drake_tracker.core.filter.angle_observation import AngleObservation
from drake_tracker.core.filter.kalman import MEAN_A, JointKalmanBank

log = logging.getLogger(__name__)


class StaleReadingError(ValueError):
    """A joint reading whose time stamp is not after the previous reading's."""


@dataclass(slots=True)
class _Event:
    time_s: float
    reading: np.ndarray | None = None
    observation: AngleObservation | None = None


#: A buffer's log is compacted (its live events copied to a new one) once this many
#: pruned events, and at least as many as are live, sit before them.
COMPACT_AFTER = 1024


class _Log:
    """Events, their times and the belief after each, in time order: the storage that
    copies of a buffer share. Each buffer sees the slice [start, end) of it; one whose
    end is the log's end appends in place (the others' slices do not change), and any
    other change goes to a private log first (copy on write)."""

    __slots__ = ("events", "beliefs", "times")

    def __init__(self, events: list[_Event], beliefs: list[np.ndarray], times: list[float]):
        self.events, self.beliefs, self.times = events, beliefs, times


#: An image update: given the angles' prior (5, n) at the image time, their posterior
#: marginals (mean, variance).
ImageUpdate = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class ImageAnchor:
    """Where an image stamped ``image_time_s`` enters the buffer.

    ``prior`` is the belief at ``anchor_time_s`` with the angle means moved by
    ``angle_shift``, the encoder-measured motion from the anchor to the image time: the
    prior of the angles at the image time. The image's observation of those angles is
    stored at the anchor as an observation of ``a(anchor) + angle_shift``.
    """

    image_time_s: float
    anchor_time_s: float
    prior: np.ndarray
    angle_shift: np.ndarray


class BeliefBuffer:
    """Readings and image corrections over a bounded horizon, with the belief after each.

    ``anchor`` is the belief just before the oldest stored event; events older than
    ``now - horizon_s`` are folded into it.
    """

    def __init__(self, bank: JointKalmanBank, initial_moments: np.ndarray, initial_time_s: float,
                 horizon_s: float, max_interpolation_gap_s: float = 0.05):
        if not horizon_s > 0:
            raise ValueError(f"delay buffer horizon_s must be > 0, got {horizon_s}")
        if not max_interpolation_gap_s >= 0:
            raise ValueError(f"max_interpolation_gap_s must be >= 0, got "
                             f"{max_interpolation_gap_s}")
        self.max_interpolation_gap_s = float(max_interpolation_gap_s)
        if initial_moments.shape != (5, bank.num_joints):
            raise ValueError(f"initial moments have shape {initial_moments.shape}, "
                             f"expected (5, {bank.num_joints})")
        self.bank = bank
        self.horizon_s = float(horizon_s)
        self._anchor_time = float(initial_time_s)
        self._anchor = initial_moments.copy()
        self._log = _Log([], [], [])
        self._start = 0
        self._end = 0
        #: Whether no copy shares ``_log`` (then it may be changed in place).
        self._private = True
        self._last_reading_time = -np.inf
        self._now = float(initial_time_s)

    def copy(self) -> BeliefBuffer:
        """An independent copy that shares the stored events and arrays: the buffer never
        modifies an array in place (every update stores a new one), and the two append
        to their shared log in turn or copy it before any other change (``_Log``), so a
        copy costs the same whatever the buffer holds (the delay buffer's LeafSystem
        copies it at every reading, 1000 times a simulated second)."""
        clone = object.__new__(BeliefBuffer)
        clone.__dict__.update(self.__dict__)
        self._private = clone._private = False
        return clone

    def __deepcopy__(self, memo) -> BeliefBuffer:
        return self.copy()

    # ----------------------------------------------------------------- queries
    @property
    def now_s(self) -> float:
        """The latest time the buffer knows of (a reading, or ``advance_to``)."""
        return self._now

    @property
    def oldest_time_s(self) -> float:
        """Images stamped before this are older than the horizon."""
        return self._anchor_time

    def __len__(self) -> int:
        return self._end - self._start

    def _latest_at_or_before(self, t: float) -> tuple[int, float, np.ndarray]:
        """(log index of the first event after t, time and belief of the latest at or
        before t)."""
        log = self._log
        k = bisect.bisect_right(log.times, t, self._start, self._end)
        if k == self._start:
            return k, self._anchor_time, self._anchor
        return k, log.times[k - 1], log.beliefs[k - 1]

    def belief_at(self, t: float) -> np.ndarray:
        """The latest belief at or before ``t``, predicted to ``t``."""
        if t < self._anchor_time:
            raise ValueError(f"time {t} s is older than the buffer ({self._anchor_time} s)")
        _, t0, belief = self._latest_at_or_before(t)
        return self.bank.predict(belief, t - t0)

    def present(self) -> tuple[float, np.ndarray]:
        """The current belief, at ``now_s``."""
        return self._now, self.belief_at(self._now)

    # ----------------------------------------------------------------- updates
    def advance_to(self, t: float) -> None:
        """Moves ``now`` forward without a reading (e.g. vision-only tracking)."""
        if t > self._now:
            self._now = float(t)
            self._prune()

    def add_reading(self, t: float, reading: np.ndarray, *, checked: bool = False
                    ) -> np.ndarray:
        """Filters a reading stamped ``t`` (after every earlier one); returns the new belief.
        ``checked``: ``reading`` is a float (n,) array that passed the readings' gate
        (``ReadingGate.admit``: NaN for a joint without a value, no infinity, some value)
        and is the buffer's to keep (e.g. ``full_reading``'s new array): it is stored as
        it is, where any other is checked (``JointKalmanBank.check_reading``) and copied."""
        if not math.isfinite(t):
            raise ValueError(f"joint reading time stamp is not finite: {t}")
        if t <= self._last_reading_time:
            raise StaleReadingError(
                f"joint reading stamped {t} s is not after the previous one "
                f"({self._last_reading_time} s)")
        t = float(t)
        if not checked:
            reading = self.bank.check_reading(reading).copy()
        self._last_reading_time = t
        log, end = self._log, self._end
        if self._start < end == len(log.times) and log.times[end - 1] <= t:
            # The usual reading, after every event: appended to the log in place, as
            # ``_insert`` would, without the searches (1000 times a second).
            belief = self.bank.step_unchecked(log.beliefs[end - 1],
                                              float(t - log.times[end - 1]), reading)
            log.events.append(_Event(t, reading=reading))
            log.beliefs.append(belief)
            log.times.append(t)
            self._end = end + 1
        else:
            k, t0, belief = self._latest_at_or_before(t)  # t0 <= t: checked, as ``step`` would
            k = self._insert(k, _Event(t, reading=reading),
                             self.bank.step_unchecked(belief, float(t - t0), reading))
            if k < self._end - 1:
                self._replay_from(k + 1)
        self._now = max(self._now, t)
        self._prune()
        return self._log.beliefs[self._end - 1]

    def image_time_problem(self, t: float) -> str | None:
        """Why an image stamped ``t`` cannot be applied (too old, from the future, not
        finite), or None when it can."""
        if not np.isfinite(t):
            return f"its time stamp {t} is not finite"
        if t < self._anchor_time:
            return (f"stamped {t:.4f} s, it is older than the {self.horizon_s:.3f} s buffer "
                    f"horizon (oldest belief {self._anchor_time:.4f} s)")
        if t > self._now + 1e-9:
            return f"stamped {t:.4f} s, it is from the future (now {self._now:.4f} s)"
        return None

    def reading_gap_problem(self, t: float) -> str | None:
        """Why an image stamped ``t`` inside the buffer should not be applied although it
        could be: it falls in a gap of the joint readings longer than
        ``max_interpolation_gap_s`` (e.g. a run of non-finite readings), where its prior
        would be the angle process's prediction, radians wide. None without readings
        (vision only) or when readings around ``t`` carry it (see ``image_anchor``)."""
        gap = self.reading_gap(t)
        if gap is None:
            return None
        t0, t1, _ = gap
        return (f"stamped {t:.4f} s, it falls in a {t1 - t0:.3f} s gap of the joint readings "
                f"({t0:.4f} s to {t1:.4f} s; max_interpolation_gap_s is "
                f"{self.max_interpolation_gap_s:.3f} s)")

    def reading_gap(self, t: float) -> tuple[float, float, bool] | None:
        """The gap of the joint readings longer than ``max_interpolation_gap_s`` that
        ``t`` falls in: its start and end (s; the end is the present while no reading has
        closed it) and whether a later reading closed it; None when there is none (see
        ``reading_gap_problem``)."""
        if self._last_reading_time == -np.inf or not np.isfinite(t):
            return None
        times = self._log.times
        k = bisect.bisect_right(times, t, self._start, self._end)
        before, after = self._reading_around(k - 1, -1), self._reading_around(k, 1)
        t0 = times[before] if before is not None else self._anchor_time
        if t0 == t:
            return None
        t1 = times[after] if after is not None else self._now
        if t1 - t0 <= self.max_interpolation_gap_s:
            return None
        return t0, t1, after is not None

    def _reading_around(self, k: int, step: int) -> int | None:
        """Log index of the nearest reading event from log index ``k`` on, walking by
        ``step``."""
        events = self._log.events
        while self._start <= k < self._end:
            if events[k].reading is not None:
                return k
            k += step
        return None

    def image_anchor(self, t: float) -> ImageAnchor:
        """Where an image stamped ``t`` is applied, and the angles' prior at ``t``.

        Raises ValueError when ``t`` is outside the buffer (see ``image_time_problem``).
        """
        problem = self.image_time_problem(t)
        if problem is not None:
            raise ValueError(f"image cannot be placed: {problem}")
        times, events = self._log.times, self._log.events
        k = bisect.bisect_right(times, t, self._start, self._end)
        before, after = self._reading_around(k - 1, -1), self._reading_around(k, 1)
        if before is not None and times[before] == t:
            after = before
        usable = (before is not None and after is not None
                  and times[after] - times[before] <= self.max_interpolation_gap_s)
        if not usable:
            zero = np.zeros(self.bank.num_joints)
            return ImageAnchor(float(t), float(t), self.belief_at(t), zero)
        t0, t1 = times[before], times[after]
        q0, q1 = events[before].reading, events[after].reading
        fraction = 0.0 if t1 == t0 else (t - t0) / (t1 - t0)
        q_at_image = q0 + fraction * (q1 - q0)
        anchor = before if t - t0 <= t1 - t else after
        # A joint without a value at either reading (NaN) is held where the anchor's
        # belief has it.
        shift = np.nan_to_num(q_at_image - events[anchor].reading, nan=0.0)
        # The latest belief at the anchor's time (after any observation stored there).
        prior = self.belief_at(times[anchor]).copy()
        prior[MEAN_A] = prior[MEAN_A] + shift
        return ImageAnchor(float(t), times[anchor], prior, shift)

    def add_image(self, t: float, update: ImageUpdate) -> bool:
        """Applies an image stamped ``t`` (see ``image_anchor``) and replays what came after.

        ``update`` maps the angles' prior (5, n) at ``t`` to their posterior marginals
        (mean, variance). Returns False (with a logged warning, nothing changed) for an
        image older than the horizon or from the future.
        """
        problem = self.image_time_problem(t)
        if problem is not None:
            log.warning("image skipped: %s", problem)
            return False
        anchor = self.image_anchor(t)
        mean_post, var_post = update(anchor.prior)
        self.add_image_observation(
            anchor, AngleObservation.from_posterior(anchor.prior, mean_post, var_post))
        return True

    def add_image_observation(self, anchor: ImageAnchor, observation: AngleObservation) -> None:
        """Stores an image's observation of the angles at ``anchor.image_time_s`` (relative
        to ``anchor.prior``) at the anchor, and replays what came after."""
        self.add_observation(anchor.anchor_time_s, observation.shifted(anchor.angle_shift))

    def add_observation(self, t: float, observation: AngleObservation) -> None:
        """Inserts an image's pseudo-observation at ``t`` and replays what came after.
        Raises ValueError when ``t`` is outside the buffer (see ``image_time_problem``)."""
        problem = self.image_time_problem(t)
        if problem is not None:
            raise ValueError(f"image observation rejected: {problem}")
        k, t0, belief = self._latest_at_or_before(t)
        prior = self.bank.predict(belief, t - t0)
        k = self._insert(k, _Event(float(t), observation=observation), observation.apply(prior))
        self._replay_from(k + 1)

    # ----------------------------------------------------------------- internals
    def _own(self) -> int:
        """Gives this buffer a private log of its events (when it shares one); returns
        by how much the log indices moved down."""
        return 0 if self._private else self._new_log()

    def _new_log(self) -> int:
        """Moves this buffer's events to a new log of its own (the old one is left to any
        copy that shares it); returns by how much the log indices moved down."""
        log, start, end = self._log, self._start, self._end
        self._log = _Log(log.events[start:end], log.beliefs[start:end], log.times[start:end])
        self._start, self._end, self._private = 0, end - start, True
        return start

    def _insert(self, k: int, event: _Event, belief: np.ndarray) -> int:
        """Inserts ``event`` at log index k; returns its log index."""
        log = self._log
        if not (k == self._end == len(log.times)):  # not an append at the log's end
            k -= self._own()
            log = self._log
        log.events.insert(k, event)
        log.beliefs.insert(k, belief)
        log.times.insert(k, event.time_s)
        self._end += 1
        return k

    def _replay_from(self, k: int) -> None:
        """Filters the events from log index k on again."""
        if k >= self._end:
            return
        k -= self._own()
        log = self._log
        for i in range(k, self._end):
            t0, previous = (log.times[i - 1], log.beliefs[i - 1]) if i > self._start else (
                self._anchor_time, self._anchor)
            event = log.events[i]
            dt = event.time_s - t0
            if event.reading is not None:
                log.beliefs[i] = self.bank.step_unchecked(previous, dt, event.reading)
            else:
                log.beliefs[i] = event.observation.apply(self.bank.predict(previous, dt))

    def _prune(self) -> None:
        log, start = self._log, self._start
        cutoff = self._now - self.horizon_s
        if start + 1 < self._end and log.times[start] < cutoff <= log.times[start + 1]:
            drop = 1  # the usual: one reading in, the oldest out (no search)
        else:
            drop = bisect.bisect_left(log.times, cutoff, start, self._end) - start
        # Keep at least the newest event so the present belief stays stored.
        drop = min(drop, self._end - self._start - 1)
        if drop > 0:
            self._anchor_time = log.times[self._start + drop - 1]
            self._anchor = log.beliefs[self._start + drop - 1]
            self._start += drop
            if self._start >= max(COMPACT_AFTER, self._end - self._start):
                self._new_log()  # compact: drop the pruned events
