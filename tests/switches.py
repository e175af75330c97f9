"""Parts of the per-image decision switched off in a test, where they have no parameter
to (docs/method.md section 7)."""

from collections.abc import Iterator
from contextlib import contextmanager

import pytest


def switch_second_opinion_off(patch: pytest.MonkeyPatch) -> None:
    """No search from the encoders' arm on a surprising image (H2 and H1'), after an
    inconsistent innovation (H2), nor of a camera's own pose (H4), while ``patch``
    lasts: an image is surprising by a vote (``health.contradicts``), with no fraction
    to set to 0."""
    from drake_tracker.core.robustness.second_opinion import EncoderSearch

    for name in ("second_opinion", "kept_search", "remount_search"):
        patch.setattr(EncoderSearch, name, lambda self, *args: None)


@contextmanager
def second_opinion_off() -> Iterator[None]:
    """``switch_second_opinion_off`` for a ``with`` block."""
    with pytest.MonkeyPatch.context() as patch:
        switch_second_opinion_off(patch)
        yield
