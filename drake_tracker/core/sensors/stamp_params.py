"""The time-stamp policy's parameters (``TrackerParams.timestamps``)."""

from dataclasses import dataclass


@dataclass
class TimestampParams:
    """The time-stamp policy of each sensor stream (``core/sensors/timestamps.py``)."""

    #: A stamp more than max(``min_future_jump_s``, this many of the stream's recent
    #: sample periods) after the latest accepted one is rejected as a glitch.
    max_future_jump_periods: float = 1000.0
    min_future_jump_s: float = 30.0
    #: A clock that stepped and stays there is re-anchored after this many consecutive
    #: rejected stamps at the stream's normal pace.
    reanchor_after_samples: int = 5
