"""What the long commands show on stderr, so stdout keeps the results: progress bars
(tqdm) and one-line notes."""

from __future__ import annotations

import sys

from tqdm import tqdm


class SimulatedSecondsBar:
    """A bar in simulated seconds: ``advance_to(t)`` after each ``Simulator.AdvanceTo``.

    Disabled (``enabled=False``) it does nothing, so library calls stay silent.
    """

    def __init__(self, duration_s: float, description: str = "simulating",
                 enabled: bool = True):
        self._bar = tqdm(total=round(float(duration_s), 2), desc=description, unit="s",
                         disable=not enabled, mininterval=0.5, dynamic_ncols=True,
                         bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s "
                                    "simulated [{elapsed}<{remaining}]")
        self._last_s = 0.0

    def advance_to(self, time_s: float) -> None:
        """Moves the bar to ``time_s`` simulated seconds (clipped to the total)."""
        time_s = min(float(time_s), float(self._bar.total))
        if time_s > self._last_s:
            self._bar.update(time_s - self._last_s)
            self._last_s = time_s

    def close(self) -> None:
        """Closes the bar (also done on leaving a ``with`` block)."""
        self._bar.close()

    def __enter__(self) -> SimulatedSecondsBar:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def count_bar(total: int, unit: str, description: str, enabled: bool = True) -> tqdm:
    """A bar over ``total`` items (images, readings); ``update(k)`` as they are done."""
    return tqdm(total=int(total), desc=description, unit=unit, disable=not enabled,
                mininterval=0.5, dynamic_ncols=True)


def note(message: str) -> None:
    """A one-line note for the user on stderr (stdout keeps the results)."""
    print(f"note: {message}", file=sys.stderr)
