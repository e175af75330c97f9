"""One way to reject a bad scenario value: ``require(condition, field, value, why)``.

Every check in ``drake_tracker.sim`` goes through :func:`require`, so each error names
the offending field, shows the value and says what was expected, e.g.
``ValueError: encoders.rate_hz = -5.0: must be a positive number``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable


def require(condition: bool, field: str, value: object, why: str) -> None:
    """Raises ``ValueError("FIELD = VALUE: WHY")`` unless ``condition`` holds."""
    if not condition:
        raise ValueError(f"{field} = {value!r}: {why}")


def is_number(value: object) -> bool:
    """True for a finite int or float (bools excluded)."""
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


def require_positive(value: float, field: str) -> None:
    """``value`` is a finite number > 0."""
    require(is_number(value) and value > 0, field, value, "must be a positive number")


def require_non_negative(value: float, field: str) -> None:
    """``value`` is a finite number >= 0."""
    require(is_number(value) and value >= 0, field, value, "must be a number >= 0")


def require_one_of(value: str, allowed: Iterable[str], field: str) -> None:
    """``value`` is one of ``allowed``."""
    allowed = list(allowed)
    require(value in allowed, field, value, f"must be one of {allowed}")


def require_length(values: list, length: int, field: str, what: str = "numbers") -> None:
    """``values`` has exactly ``length`` finite numbers."""
    require(len(values) == length and all(is_number(v) for v in values), field, values,
            f"must be {length} finite {what}")
