"""An ``lcm-logger`` file as the tracker's input, read with ``lcm.EventLog`` (the ``lcm``
extra) and decoded with Drake's own message classes (``io/lcm_messages.py``).

* Channels: the status on ``status_channel`` (default: whichever of Drake's
  ``IIWA_STATUS`` and ``PANDA_STATUS`` the log holds), ``lcmt_iiwa_status`` or
  ``lcmt_panda_status`` (told apart by fingerprint, or forced with ``status_type``); the
  depth on ``image_channel`` (default ``DRAKE_RGBD_CAMERA_IMAGES``), an
  ``lcmt_image_array``. A channel the log lacks is an error listing the channels it has.
  Other channels are ignored.
* Several depth cameras (a sequence of :class:`LcmCamera`): each the model's camera by
  name, with its own channel (Drake's ``ApplyCameraConfig`` publishes camera NAME on
  ``DRAKE_RGBD_CAMERA_IMAGES_NAME``) and intrinsics; its images are named by it
  (``ImageEvent.camera``) and numbered on their own.
* Joints: a status message has no joint names, so its positions are taken in the
  model's ``robot_joint_names`` order, and their number must be the model's: an error
  at the first message, a skipped and counted message later on.
* Depth: the array's first depth image, uint16 mm or float32 m, raw or zlib, at the
  resolution of the given intrinsics (an ``lcmt_image`` has none: see
  ``camera_from_text``). Anything else is skipped and counted, by reason.
* Times: each message's ``utime`` (a status's, an image's ``header.utime``: the
  capture), relative to the earliest first stamp of the channels, in integer
  microseconds until then, then the nearest float to their count over 1e6. An image's
  arrival is its log time when that is on the stamps' clock (``io/stream.py:logged_arrival``).
* The log is checked as it is read: ``lcm.EventLog`` stops at an event that is cut
  short or not followed by another event's header, as if the log ended there; a log
  it stops reading before its end, or an event that does not start where the previous
  one ended, is an error naming the file and the byte offset.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drake import lcmt_image_array

from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.io.camera_sources import check_camera_sources
from drake_tracker.io.lcm_messages import (
    DRAKE_RGBD_CAMERA_IMAGES,
    IIWA_STATUS,
    PANDA_STATUS,
    STATUS_TYPES,
    decode,
    decode_status,
    depth_from_image_array,
    require_lcm,
    status_type_of,
)
from drake_tracker.io.stream import (
    Event,
    ImageEvent,
    ReadingEvent,
    SkippedMessage,
    logged_arrival,
)

#: An event's header in an lcm-logger file: magic, event number, time, two lengths.
EVENT_HEADER_BYTES = 4 + 8 + 8 + 4 + 4


def read_log(path: str | Path) -> Iterator[Any]:
    """The events (``lcm.Event``: ``timestamp``, ``channel``, ``data``) of the log at
    ``path``, checked: raises ValueError naming the file when it is missing or empty, has
    bytes between events, or has an event that cannot be read (truncated, damaged)."""
    require_lcm()
    import lcm

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"LCM log {path} does not exist")
    log = lcm.EventLog(str(path), "r")
    try:
        end, count = 0, 0
        while True:
            event = log.read_next_event()
            if event is None:
                break
            start = log.tell() - EVENT_HEADER_BYTES - len(event.channel.encode()) - len(
                event.data)
            if start != end:
                raise ValueError(f"LCM log {path} is corrupt: {start - end} bytes that are "
                                 f"not an event at byte {end} (after {count} events)")
            end, count = log.tell(), count + 1
            yield event
        if end != log.size() or count == 0:
            what = ("is empty" if log.size() == 0 else
                    f"is truncated or corrupt: no event can be read at byte {end} of "
                    f"{log.size()} (after {count} events; not an lcm-logger file, or "
                    f"damaged there)")
            raise ValueError(f"LCM log {path} {what}")
    finally:
        log.close()


@dataclass(frozen=True)
class LcmCamera:
    """One depth camera of an LCM log: the model's camera ``name``, the
    ``lcmt_image_array`` ``channel`` of its images (e.g. ``camera_channel(name)``) and its
    ``intrinsics`` (an ``lcmt_image`` carries none)."""

    name: str | None
    channel: str
    intrinsics: CameraIntrinsics


def check_lcm_cameras(cameras: Sequence[LcmCamera],
                      model_cameras: list[str] | None = None) -> None:
    """ValueError for no camera, a camera the model does not have (with
    ``model_cameras``, its camera names), two cameras of one name, or one channel for
    two cameras."""
    if not cameras:
        raise ValueError("no depth camera: give at least one")
    check_camera_sources([c.name for c in cameras], [c.channel for c in cameras],
                         "image channel", model_cameras)


class LcmLogSource:
    """The events of an LCM log (``io/stream.py``) for a model's robot joints.

    Args:
        path: the ``lcm-logger`` file.
        joint_names: the model's robot joints, in its order (the status's order).
        camera: the depth camera's intrinsics (one camera, on ``image_channel``; an
            ``lcmt_image`` carries none), or the cameras, each an :class:`LcmCamera`
            with its own channel (one named None: the model's one camera).
        status_channel: the status channel (None: ``IIWA_STATUS`` or ``PANDA_STATUS``,
            whichever the log holds).
        image_channel: the one camera's ``lcmt_image_array`` channel.
        status_type: ``"iiwa"``, ``"panda"`` or ``"auto"`` (by fingerprint).
    """

    def __init__(self, path: str | Path, joint_names: list[str],
                 camera: CameraIntrinsics | Sequence[LcmCamera],
                 status_channel: str | None = None,
                 image_channel: str = DRAKE_RGBD_CAMERA_IMAGES,
                 status_type: str = "auto") -> None:
        self.path = Path(path)
        self.joint_names = list(joint_names)
        if isinstance(camera, CameraIntrinsics):
            #: The cameras read (one camera: named None, as a recorded run's first).
            self.cameras: tuple[LcmCamera, ...] = (LcmCamera(None, image_channel, camera),)
        else:
            self.cameras = tuple(camera)
            check_lcm_cameras(self.cameras)
        if status_type not in ("auto", *STATUS_TYPES):
            raise ValueError(f"status type '{status_type}' is not one of "
                             f"{['auto', *STATUS_TYPES]}")
        counts: Counter[str] = Counter()
        first: dict[str, Any] = {}
        for event in read_log(self.path):
            counts[event.channel] += 1
            first.setdefault(event.channel, event)
        present = ", ".join(f"{c} ({n})" for c, n in sorted(counts.items()))
        if status_channel is None:
            known = [c for c in (IIWA_STATUS, PANDA_STATUS) if c in counts]
            if len(known) != 1:
                raise ValueError(f"LCM log {self.path} has {len(known)} of the channels "
                                 f"{IIWA_STATUS}, {PANDA_STATUS}: name the status channel "
                                 f"(--status-channel); its channels: {present}")
            status_channel = known[0]
        for channel, flag in ((status_channel, "--status-channel"),
                              *((c.channel, "--image-channel") for c in self.cameras)):
            if channel not in counts:
                raise ValueError(f"LCM log {self.path} has no channel '{channel}' ({flag}); "
                                 f"its channels (messages): {present}")
        self.status_channel = status_channel
        self._by_channel = {c.channel: c for c in self.cameras}
        data = first[status_channel].data
        found = status_type_of(data)
        if found is None or status_type not in ("auto", found):
            expected = ("lcmt_iiwa_status or lcmt_panda_status" if status_type == "auto"
                        else f"lcmt_{status_type}_status")
            seen = "" if found is None else f": lcmt_{found}_status"
            raise ValueError(f"LCM log {self.path}: the messages on {status_channel} are not "
                             f"{expected} (fingerprint {bytes(data[:8]).hex()}{seen})")
        self.status_type = found
        try:
            utime, positions = decode_status(data, found)
        except ValueError as err:
            raise ValueError(f"LCM log {self.path}: the first message on {status_channel} "
                             f"cannot be decoded: {err}") from None
        if positions.size != len(self.joint_names):
            raise ValueError(f"LCM log {self.path}: the status messages on {status_channel} "
                             f"hold {positions.size} joints, the model has "
                             f"{len(self.joint_names)} robot joints ({self.joint_names}); "
                             f"the status has no joint names, so the counts must match")
        stamps = [utime]
        for c in self.cameras:
            try:
                first_image = decode(lcmt_image_array, first[c.channel].data)
                stamps.append(depth_from_image_array(first_image)[0])
            except ValueError:
                pass  # the first image is skipped and counted by events()
        #: The time base (integer µs): the first status or depth message's stamp.
        self.base_us = min(stamps)
        #: The time base in integer ns (the estimates files' stamps).
        self.base_ns = self.base_us * 1000
        self.num_images = sum(counts[c.channel] for c in self.cameras)

    @property
    def image_channel(self) -> str:
        """The first camera's image channel (the only one's, for one camera)."""
        return self.cameras[0].channel

    @property
    def intrinsics(self) -> CameraIntrinsics:
        """The first camera's intrinsics (the only one's, for one camera)."""
        return self.cameras[0].intrinsics

    def camera_models(self) -> CameraIntrinsics | dict[str, CameraIntrinsics]:
        """The one camera's intrinsics, or several cameras' by name
        (``Tracker(cameras=...)``)."""
        if self.cameras[0].name is None:
            return self.intrinsics
        return {c.name: c.intrinsics for c in self.cameras}

    def events(self) -> Iterator[Event]:
        """The readings and depth images in the log's order (see the module)."""
        sequence = {c.channel: 0 for c in self.cameras}
        n = len(self.joint_names)
        for event in read_log(self.path):
            if event.channel == self.status_channel:
                if status_type_of(event.data) != self.status_type:
                    yield SkippedMessage("undecodable messages", f"a message on "
                                         f"{event.channel} is not lcmt_{self.status_type}"
                                         f"_status (log time {event.timestamp} µs)")
                    continue
                try:
                    utime, positions = decode_status(event.data, self.status_type)
                except ValueError as err:
                    yield SkippedMessage("undecodable messages", f"a message on "
                                         f"{event.channel} cannot be decoded: {err}")
                    continue
                t = (utime - self.base_us) / 10**6
                if positions.size != n:
                    yield SkippedMessage("status messages with another joint count",
                                         f"status at {t:.6f} s skipped: {positions.size} "
                                         f"joints, the model has {n}")
                    continue
                yield ReadingEvent(t, positions)
            elif event.channel in self._by_channel:
                camera = self._by_channel[event.channel]
                try:
                    utime, depth = depth_from_image_array(decode(lcmt_image_array, event.data))
                except ValueError as err:
                    yield SkippedMessage("depth images not usable", f"image array on "
                                         f"{event.channel} logged at {event.timestamp} µs "
                                         f"skipped: {err}")
                    continue
                t = (utime - self.base_us) / 10**6
                size = (camera.intrinsics.height, camera.intrinsics.width)
                if depth.shape != size:
                    yield SkippedMessage("depth images of another size", f"depth image on "
                                         f"{event.channel} at {t:.6f} s skipped: "
                                         f"{depth.shape[1]}x{depth.shape[0]}, the camera is "
                                         f"{size[1]}x{size[0]}")
                    continue
                arrival = logged_arrival(t, (int(event.timestamp) - self.base_us) / 10**6)
                yield ImageEvent(t, depth, sequence[event.channel], arrival, camera.name)
                sequence[event.channel] += 1

    def close(self) -> None:
        """Nothing to close: each pass opens the log anew (for the ``BagSource`` API)."""
