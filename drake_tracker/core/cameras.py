"""The per-camera state of a tracker with one or several depth cameras.

Each camera has its own image update (rendered through its own estimated frame, its
images sampling the robot joints and its own six virtual joints:
``ImageProcessor(camera_name=...)``), its own clock (``StreamClock``), pacing
(``ImagePacing``) and health (``TrackerHealth``). Its images go through the one per-image
step (``core/image_step.py``) into the one delay buffer, at their own times.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.image_processor import ImageProcessor
from drake_tracker.core.image_step import ImagePacing
from drake_tracker.core.robustness.health import HealthState, TrackerHealth
from drake_tracker.core.sensors.camera import CameraIntrinsics, as_intrinsics
from drake_tracker.core.sensors.timestamps import StreamClock

if TYPE_CHECKING:
    from drake_tracker.core.resolved_params import ResolvedParams
    from drake_tracker.robot.model import TrackerModel


@dataclass
class CameraChannel:
    """One camera's images: what they are scored with and the state between them."""

    name: str
    intrinsics: CameraIntrinsics
    #: The image update (None when the parameters disable images).
    images: ImageProcessor | None
    clock: StreamClock
    pacing: ImagePacing = field(default_factory=ImagePacing)
    health: TrackerHealth = field(default_factory=TrackerHealth)
    #: Arrival minus image time of this camera's latest placed image (s; NaN before).
    lag_s: float = float("nan")


def camera_channels(model: TrackerModel, cameras: dict, params: ResolvedParams
                    ) -> dict[str, CameraChannel]:
    """A channel per entry of ``cameras`` (camera name -> intrinsics or Drake
    ``CameraInfo``), in the model's camera order. ValueError for no camera, or a name
    the model does not have (naming the model's cameras). With one camera its clock is
    named ``image``, as the one-camera tracker's; with several ``image (NAME)``."""
    if not cameras:
        raise ValueError(f"no camera given: name at least one of the model's cameras "
                         f"{model.camera_names}")
    for name in cameras:
        model.camera(name)  # ValueError for a camera the model does not have
    several = len(model.cameras) > 1
    channels = {}
    for name in model.camera_names:
        if name not in cameras:
            continue
        intrinsics = as_intrinsics(cameras[name])
        images = ImageProcessor(model, intrinsics, params, camera_name=name) \
            if params.image.enabled else None
        clock = StreamClock(f"image ({name})" if several else "image", params.timestamps,
                            params.buffer_horizon_s)
        channels[name] = CameraChannel(name, intrinsics, images, clock)
    return channels


def camera_named(camera: str | None, names: list[str], owner: str,
                 how_to_name: str = "name one") -> str:
    """The camera ``camera`` among ``names`` (None: the only one), as the offline tracker
    and the Drake systems resolve an image's camera: a ValueError naming ``owner``'s
    cameras for an unknown name, or for None with several (``how_to_name`` says how to
    name one)."""
    if camera is None:
        if len(names) > 1:
            raise ValueError(f"the {owner} has the cameras {names}: {how_to_name}")
        return names[0]
    if camera not in names:
        raise ValueError(f"unknown camera '{camera}': the {owner}'s cameras are {names}")
    return camera


def clock_disagreement(channel: CameraChannel, channels: dict[str, CameraChannel],
                       lag_s: float, horizon_s: float) -> str:
    """Why ``channel``'s image, which arrives ``lag_s`` after its time, says that its
    camera's clock disagrees with another's by more than the buffer horizon ("" when it
    does not, or when no other camera has placed an image)."""
    if not np.isfinite(lag_s):
        return ""
    for other in channels.values():
        if other is channel or not np.isfinite(other.lag_s):
            continue
        if abs(lag_s - other.lag_s) > horizon_s:
            return (f"camera '{channel.name}''s clock disagrees with camera "
                    f"'{other.name}''s by {lag_s - other.lag_s:+.3f} s, more than the "
                    f"buffer horizon ({horizon_s:g} s): its images cannot be placed")
    return ""


def best_health(channels: dict[str, CameraChannel]) -> TrackerHealth:
    """The tracker's health, which describes its output ``X_CE``, the hand in the first
    camera's estimated frame: the first camera's health while it says ``tracking``;
    otherwise that of the camera in the best state, at best ``uncertain``. Another
    camera that tracks the arm confirms the hand, not the first camera's pose (its
    offset, and the joints that carry it), which only its own images observe: measured
    on the quick suite's in-out-in-2cam/constant seed 3 at b598ba4, the first camera saw no arm
    while the other tracked it, and the hand was 85-119 mm off in the first camera's
    frame with the best camera's health saying ``tracking``. One camera: its health."""
    first = next(iter(channels.values()))
    if first.health.state == HealthState.TRACKING:
        return first.health
    best = min(channels.values(), key=lambda c: int(c.health.state)).health
    return replace(best, state=max(best.state, HealthState.UNCERTAIN))


def another_camera_tracks(healths: Mapping[str, TrackerHealth], name: str) -> bool:
    """Whether a camera other than ``name`` says ``tracking`` (its images confirm the
    arm), given each camera's health by name: an image of camera ``name`` that shows
    most of the arm hidden is then not applied (``ImageProcessor.observe``'s
    ``others_track``)."""
    return any(health.state == HealthState.TRACKING
               for other, health in healths.items() if other != name)
