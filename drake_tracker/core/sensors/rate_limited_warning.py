"""A warning that repeats (a skipped sample, 1000 times a second) logged at its 1st,
10th, 100th, ... occurrence, with the count so far."""

from __future__ import annotations

import logging


class RateLimitedWarning:
    """Logs the 1st, 10th, 100th, ... warning of each ``kind``, with the count so far."""

    def __init__(self, logger: logging.Logger, enabled: bool = True):
        self.logger = logger
        self.enabled = enabled
        self.counts: dict[str, int] = {}

    def copy(self) -> RateLimitedWarning:
        """An independent copy that shares the logger."""
        clone = RateLimitedWarning(self.logger, self.enabled)
        clone.counts = dict(self.counts)
        return clone

    def __deepcopy__(self, memo) -> RateLimitedWarning:
        return self.copy()

    def warn(self, kind: str, message: str) -> None:
        """Counts one warning of ``kind`` and logs ``message`` at the 1st, 10th, 100th, ... of
        that kind (with the count so far after the first); only counts when not ``enabled``."""
        count = self.counts.get(kind, 0) + 1
        self.counts[kind] = count
        if self.enabled and _is_power_of_ten(count):
            suffix = "" if count == 1 else f" ({count} {kind} so far; logged at 1, 10, 100, ...)"
            self.logger.warning("%s%s", message, suffix)


    def count(self, kind: str) -> None:
        """Counts one event of ``kind`` without logging it (its caller logged it once)."""
        self.counts[kind] = self.counts.get(kind, 0) + 1


def _is_power_of_ten(count: int) -> bool:
    while count % 10 == 0:
        count //= 10
    return count == 1
