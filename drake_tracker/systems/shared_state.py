"""Abstract state that Drake's copies share instead of duplicating.

Drake copies a system's abstract state twice at every discrete update (1000 times a
simulated second at encoder rate). The tracker's systems never modify a stored state:
an update takes ``copy()``, replaces the fields it changes (copying any part it changes
in place first) and stores that. Under that rule a deep copy is the object itself.
"""

from __future__ import annotations

from typing import Self


class SharedAbstractState:
    """Mixin for a system's state class that is never modified once stored."""

    def __deepcopy__(self, memo: dict) -> Self:
        return self

    def copy(self) -> Self:
        """A shallow copy: an update's own, whose fields it replaces before changing."""
        clone = object.__new__(type(self))
        clone.__dict__.update(self.__dict__)
        return clone
