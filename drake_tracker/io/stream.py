"""Tracking a stream of time-stamped messages: a bag, an LCM log, a recorded run.

A source yields :class:`ReadingEvent` and :class:`ImageEvent` in the order they arrived
(a log's order), with times in seconds relative to the stream's time base (its first
message, so that Unix stamps of 1.7e9 s lose no precision in the filter).
:func:`track_stream` feeds them to a :class:`~drake_tracker.tracker.Tracker` and hands
the estimate after every reading the tracker used to a sink (``io/estimates_out.py``).
It holds only the images that wait for the reading after their capture (see
``track_stream``): a 10-minute bag streams in flat memory.

An image without an arrival stamp (``ImageEvent.arrival_s`` None) arrives when it is
fed: its arrival is its capture stamp or the latest reading's, whichever is later.
"""

from __future__ import annotations

import heapq
import logging
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import numpy as np

from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.core.sensors.rate_limited_warning import RateLimitedWarning
from drake_tracker.progress import count_bar

if TYPE_CHECKING:
    from drake_tracker.core.filter.estimate import TrackerEstimate
    from drake_tracker.tracker import Tracker

log = logging.getLogger(__name__)

#: The reading gate's count of readings used without some joints (not skipped).
PARTIAL = "readings with missing joints"
#: An image logged later than this after its capture stamp is taken to be logged on
#: another clock than its stamps (s).
MAX_LOG_DELAY_S = 1.0


def logged_arrival(capture_s: float, logged_s: float) -> float | None:
    """An image's arrival from a log: its log time ``logged_s`` (stream time), when that
    is on the stamps' clock (at or after the capture, by at most ``MAX_LOG_DELAY_S``);
    else None (``ImageEvent.arrival_s``: the stream's rule, the latest reading's stamp)."""
    return logged_s if 0.0 <= logged_s - capture_s <= MAX_LOG_DELAY_S else None


@dataclass(frozen=True)
class ReadingEvent:
    """The robot joints' encoder reading (``model.robot_joint_names`` order) at
    ``time_s`` (s, stream time)."""

    time_s: float
    positions: np.ndarray


@dataclass(frozen=True)
class ImageEvent:
    """A depth image captured at ``capture_s`` (s, stream time): float metres, or uint16
    millimetres (0: no return), at the camera's full resolution."""

    capture_s: float
    depth: np.ndarray
    sequence: int
    #: When it arrived (s, stream time); None: when the source yields it (see above).
    arrival_s: float | None = None
    #: Which camera took it (``Tracker.add_image``'s ``camera``); None: the only one.
    camera: str | None = None


@dataclass(frozen=True)
class SkippedMessage:
    """A message the source could not turn into an event (``why`` says what was wrong
    with it): counted under ``kind`` and tracking goes on."""

    kind: str
    why: str


Event = ReadingEvent | ImageEvent | SkippedMessage


class EstimateSink(Protocol):
    """Where :func:`track_stream` puts each estimate (``io/estimates_out.py``)."""

    def write(self, estimate: TrackerEstimate) -> None:
        """Takes the estimate after one reading."""


class StreamObserver(Protocol):
    """Sees the tracker between events (``io/replay.py`` samples its estimate there)."""

    def before(self, time_s: float, tracker: Tracker) -> None:
        """Called before an event at ``time_s`` (a reading's stamp, an image's arrival)
        is fed, and once at the end with ``inf``."""


@dataclass
class StreamCounts:
    """What a stream gave and what the tracker made of it (``report.json``)."""

    readings: int = 0
    images: int = 0
    images_applied: int = 0
    estimates: int = 0
    #: Messages the source skipped, by kind (``SkippedMessage``).
    source_skipped: dict[str, int] = field(default_factory=dict)
    #: Readings the tracker skipped, by kind (its time-stamp policy, non-finite values).
    readings_skipped: dict[str, int] = field(default_factory=dict)
    #: Readings used although some joints had no value (those joints were predicted).
    readings_with_missing_joints: int = 0
    #: Images the tracker skipped, by kind; ``not due`` are the ones its pacing
    #: (``image.min_image_interval_s``) left out.
    images_skipped: dict[str, int] = field(default_factory=dict)
    #: With named cameras: each camera's ``images``, ``applied`` and ``skipped`` (the
    #: tracker's skips and the unusable images) by name.
    cameras: dict[str, dict[str, int]] = field(default_factory=dict)

    def as_dict(self) -> dict:
        """The counts as plain JSON types."""
        return {"readings": self.readings, "images": self.images,
                "images_applied": self.images_applied, "estimates": self.estimates,
                "source_skipped": dict(self.source_skipped),
                "readings_skipped": dict(self.readings_skipped),
                "readings_with_missing_joints": self.readings_with_missing_joints,
                "images_skipped": dict(self.images_skipped),
                **({"cameras": {k: dict(v) for k, v in self.cameras.items()}}
                   if self.cameras else {})}


def track_stream(events: Iterable[Event], tracker: Tracker,
                 sink: EstimateSink | None = None, total_images: int | None = None,
                 progress: bool = False, observer: StreamObserver | None = None,
                 on_image: Callable[[Tracker, DepthFrame], None] | None = None
                 ) -> StreamCounts:
    """Feeds ``events`` (arrival order) to ``tracker``; after each reading it used, the
    estimate goes to ``sink``. An image captured after the latest reading (a log that
    records it as it comes, before the reading that follows its capture) waits for that
    reading: the tracker places an image between readings, and would call it "from the
    future". An image the tracker cannot use (malformed, not in metres) is skipped with
    a rate-limited warning and counted, as is every message the source skipped.
    ``observer.before(t, tracker)`` runs before each event at time t; ``on_image(tracker,
    frame)`` after each image the tracker took (applied or skipped; not one it raised
    on); an exception it raises ends the stream and reaches the caller. Returns the
    counts."""
    counts = StreamCounts()
    warnings = RateLimitedWarning(log)
    latest_reading_s = -np.inf
    waiting: deque[ImageEvent] = deque()
    bar = count_bar(total_images or 0, "image", "tracking", enabled=progress)

    def feed(image: ImageEvent, waited: bool = False) -> None:
        bar.update(1)
        arrival = (max(image.capture_s, latest_reading_s)
                   if image.arrival_s is None or waited else image.arrival_s)
        frame = DepthFrame(float(image.capture_s), float(arrival), image.depth,
                           int(image.sequence))
        if observer is not None:
            observer.before(frame.arrival_time_s, tracker)
        applied = tracker.num_images_applied
        mine = (counts.cameras.setdefault(image.camera, dict.fromkeys(
            ("images", "applied", "skipped"), 0)) if image.camera is not None else None)
        try:
            tracker.add_image(frame, camera=image.camera)
        except ValueError as err:
            _count(counts.source_skipped, "unusable images")
            warnings.warn("unusable images", f"image {image.sequence} captured at "
                          f"{image.capture_s:.4f} s skipped: {err}")
        else:
            if on_image is not None:
                on_image(tracker, frame)
        if mine is not None:
            mine["images"] += 1
            done = tracker.num_images_applied > applied
            mine["applied" if done else "skipped"] += 1

    try:
        for event in events:
            if isinstance(event, ReadingEvent):
                counts.readings += 1
                if observer is not None:
                    observer.before(event.time_s, tracker)
                if tracker.add_reading(event.time_s, event.positions):
                    latest_reading_s = max(latest_reading_s, event.time_s)
                    while waiting and waiting[0].capture_s <= latest_reading_s:
                        feed(waiting.popleft(), waited=True)
                    if sink is not None:
                        sink.write(tracker.estimate())
                        counts.estimates += 1
            elif isinstance(event, ImageEvent):
                counts.images += 1
                if waiting or event.capture_s > latest_reading_s:
                    waiting.append(event)
                else:
                    feed(event)
            else:
                _count(counts.source_skipped, event.kind)
                warnings.warn(event.kind, event.why)
        while waiting:  # no reading came after them: the tracker says why it skips them
            feed(waiting.popleft(), waited=True)
        if observer is not None:
            observer.before(np.inf, tracker)
    finally:
        bar.close()
    counts.images_applied = tracker.num_images_applied
    skipped = dict(tracker.readings.warnings.counts)
    counts.readings_with_missing_joints = skipped.pop(PARTIAL, 0)
    counts.readings_skipped = skipped
    counts.images_skipped = dict(tracker.warnings.counts)
    unexplained = tracker.num_images_skipped - sum(tracker.warnings.counts.values())
    if unexplained > 0:
        counts.images_skipped["not due"] = unexplained
    return counts


def _count(counts: dict[str, int], kind: str) -> None:
    counts[kind] = counts.get(kind, 0) + 1


def merge_by_time(*streams: Iterable[tuple[float, Event]]) -> Iterator[Event]:
    """The events of several (time, event) streams, each in time order, in one time
    order; equal times keep the order of ``streams`` (lazy: nothing is loaded whole)."""
    tagged = [((t, k, e) for t, e in stream) for k, stream in enumerate(streams)]
    for _, _, event in heapq.merge(*tagged, key=lambda item: (item[0], item[1])):
        yield event
