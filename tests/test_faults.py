"""Issue 14's remaining faults: bounded timing records, depth images in the wrong units or
without a valid pixel, and replays of recordings with bad samples."""

from drake_tracker.core.image_update import RECENT_UPDATES, StageTimes


def test_the_per_update_timing_record_is_bounded():
    """Finding 10: the per-update timing list grew by one float per image, forever."""
    times = StageTimes()
    for k in range(RECENT_UPDATES + 500):
        times.per_update.append(float(k))
    assert len(times.per_update) == RECENT_UPDATES
    assert times.per_update[-1] == RECENT_UPDATES + 499  # the latest are kept
