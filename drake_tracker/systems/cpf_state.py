"""The state of the CPF image-update system (``cpf_system.py``): each camera's images
between checks, and what all cameras share (the observation messages, the counts and
the one update in flight)."""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass, field

from drake_tracker.core.calibration.online import SelfCalibration
from drake_tracker.core.cameras import best_health
from drake_tracker.core.image_step import ImagePacing
from drake_tracker.core.robustness.health import TrackerHealth
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.systems.messages import ImageObservationMessage, ImagePrior
from drake_tracker.systems.shared_state import SharedAbstractState


@dataclass(frozen=True)
class CameraImageState:
    """One camera's images at the image-update system. Frozen: an update replaces it."""

    name: str
    last_sequence: int = -1
    #: (sequence, capture stamp) of the last frame seen: a new pair is a new frame.
    last_frame: tuple = ()
    #: Which images are due (``core/image_step.py``, step 2).
    pacing: ImagePacing = field(default_factory=ImagePacing)
    health: TrackerHealth = field(default_factory=TrackerHealth)
    #: A frame put off for a check, until its prior holds the latest update.
    deferred_frame: tuple = ()
    #: Arrival minus image time of the latest image taken up (s; NaN before): the
    #: cameras' clocks are compared with it (``core/cameras.clock_disagreement``).
    lag_s: float = float("nan")


@dataclass(frozen=True)
class ImageUpdateInFlight:
    """An image update of ``camera`` handed to the worker thread, applied at ``due_s``."""

    frame: DepthFrame
    prior: ImagePrior
    due_s: float
    outcome: Future
    camera: str = ""
    #: Started as a search (the camera's arm not acquired when it was taken up).
    search: bool = False


@dataclass
class CpfState(SharedAbstractState):
    """The system's abstract state. A stored one is never modified (``_update`` changes a
    ``copy()`` of it, replacing the dict of cameras before replacing an entry, and stores
    that), so Drake's copies of it, two at every update (1000 a simulated second), share
    it. ``health``, ``pacing``, ``last_sequence`` and ``last_frame`` read as the
    one-camera system's: the best camera's health, the first camera's others."""

    #: Each camera's state, in the model's camera order.
    cameras: dict[str, CameraImageState] = field(default_factory=dict)
    #: The latest observation of any camera; its id grows by one per applied image.
    message: ImageObservationMessage = field(default_factory=ImageObservationMessage)
    images_applied: int = 0
    #: Frames not processed: not due (paced at ``min_image_interval_s``), unplaceable,
    #: malformed, or replaced on the port before the system looked.
    images_skipped: int = 0
    #: The update running on the worker thread (``image.update_latency_s`` > 0).
    in_flight: ImageUpdateInFlight | None = None
    #: The cameras' calibration (several cameras; ``core/calibration/online.py``):
    #: ``calibration.held`` is what it holds once calibrated. None: not calibrating.
    calibration: SelfCalibration | None = None

    @property
    def health(self) -> TrackerHealth:
        """The health of the camera in the best state (``core/cameras.best_health``)."""
        return best_health(self.cameras)

    @property
    def first(self) -> CameraImageState:
        """The first camera's state."""
        return next(iter(self.cameras.values()))

    @property
    def pacing(self) -> ImagePacing:
        """The first camera's pacing."""
        return self.first.pacing

    @property
    def last_sequence(self) -> int:
        """The first camera's last sequence number."""
        return self.first.last_sequence

    @property
    def last_frame(self) -> tuple:
        """The first camera's last frame key."""
        return self.first.last_frame

    def count(self, applied: bool | None) -> None:
        """Counts an image applied (True) or skipped (False); None: started on the
        worker, counted when it is done."""
        if applied is not None:
            self.images_applied += int(applied)
            self.images_skipped += int(not applied)
