"""A recorded run written as an ``lcm-logger`` file (``drake-tracker record --lcm-log``),
so the LCM path can be tried end to end without a robot.

Channels (Drake's default names): ``IIWA_STATUS``, an ``lcmt_iiwa_status`` per reading
(``num_joints`` = the run's joints, whatever their number; the readings in
``joint_position_measured``, the other arrays zero), and ``DRAKE_RGBD_CAMERA_IMAGES``, an
``lcmt_image_array`` per image holding one depth ``lcmt_image`` (float32 metres, NaN: no
return; or uint16 millimetres, 0: no return; raw or zlib). A run of several cameras
writes each camera's images on ``DRAKE_RGBD_CAMERA_IMAGES_<name>``, the first camera's
too, as Drake's ``ApplyCameraConfig`` publishes named cameras (:func:`image_channels`).
Stamps are integer microseconds: the run's times plus ``base_us``, rounded (write a
``run.stamped_in_microseconds()`` to read its times back exactly). A reading is logged
at its stamp; an image at its arrival, with its capture time in ``header.utime``. The
truth is not written (LCM has no message for it); the camera's intrinsics neither (an
``lcmt_image`` has no field for them: ``drake-tracker record`` prints them as the
``--camera`` argument of ``track --lcm-log``).
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.io.lcm_messages import (
    DRAKE_RGBD_CAMERA_IMAGES,
    IIWA_STATUS,
    camera_channel,
    depth_image_message,
    image_array_message,
    require_lcm,
    status_message,
)

if TYPE_CHECKING:
    from drake_tracker.io.recording import RecordedRun

#: 2023-11-14T22:13:20Z: the default time base of a written log (µs).
DEFAULT_BASE_US = 1_700_000_000 * 10**6
#: Depth pixel types a log can be written with.
DEPTH_TYPES = ("float32", "uint16")


def _us(base_us: int, t: float) -> int:
    return int(base_us) + int(round(float(t) * 1e6))


def millimetres(depth_m: np.ndarray) -> np.ndarray:
    """Depth in metres as uint16 millimetres (rounded; NaN, <= 0 or beyond 65.534 m: 0,
    no return)."""
    depth = np.asarray(depth_m, float)
    ok = np.isfinite(depth) & (depth > 0) & (depth < 65.5345)
    return np.where(ok, np.round(np.where(ok, depth, 0.0) * 1000.0), 0).astype(np.uint16)


def write_run_lcm_log(run: RecordedRun, path: str | Path, base_us: int = DEFAULT_BASE_US,
                      depth_type: str = "float32", compress: bool = False) -> int:
    """Writes ``run`` to the new LCM log ``path`` (see the module); returns the number of
    messages written. Raises FileExistsError rather than overwrite a file."""
    require_lcm()
    import lcm

    if depth_type not in DEPTH_TYPES:
        raise ValueError(f"depth type '{depth_type}' is not one of {DEPTH_TYPES}")
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"{path} exists: not overwritten")
    log = lcm.EventLog(str(path), "w")
    count = 0
    try:
        for log_us, channel, data in run_messages(run, base_us, depth_type, compress):
            log.write_event(log_us, channel, data)
            count += 1
    finally:
        log.close()
    return count


def run_messages(run: RecordedRun, base_us: int = DEFAULT_BASE_US,
                 depth_type: str = "float32", compress: bool = False
                 ) -> Iterator[tuple[int, str, bytes]]:
    """(log time µs, channel, encoded message) of ``run`` in log order, built one at a
    time (see the module): what a log of it holds, or a live robot would publish."""
    def readings():
        for t, q in zip(run.reading_times_s, run.readings_rad):
            stamp = _us(base_us, t)
            yield stamp, 0, IIWA_STATUS, lambda s=stamp, q=q: status_message(s, q)

    def images(channel, camera):
        order, _ = camera.arrival_order()
        for i in order:
            stamp = _us(base_us, camera.capture_times_s[i])
            depth = np.asarray(camera.depth_images_m[i], np.float32)
            yield _us(base_us, camera.arrival_times_s[i]), 1, channel, (
                lambda s=stamp, d=depth: image_array_message(s, [depth_image_message(
                    s, d if depth_type == "float32" else millimetres(d), compress)]))

    run.warn_unplayable("LCM log")
    channels = image_channels(run)
    cameras = [images(channels[c.name], c) for c in run.cameras]
    for log_us, _, channel, build in heapq.merge(readings(), *cameras,
                                                 key=lambda e: (e[0], e[1])):
        yield log_us, channel, build()


def image_channels(run: RecordedRun) -> dict[str, str]:
    """Each camera's ``lcmt_image_array`` channel by name: ``DRAKE_RGBD_CAMERA_IMAGES``
    for a run of one camera, ``DRAKE_RGBD_CAMERA_IMAGES_<name>`` for each of several."""
    if not run.other_cameras:
        return {run.camera_name: DRAKE_RGBD_CAMERA_IMAGES}
    return {name: camera_channel(name) for name in run.camera_names}
