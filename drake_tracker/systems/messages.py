"""Values passed between the tracker's systems on abstract-valued ports.

Each carries an ``id`` that grows by one per new message, so a receiver that remembers
the last id it used can tell a new message from the same one seen again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_tracker.core.filter.angle_observation import AngleObservation
from drake_tracker.core.filter.belief_buffer import ImageAnchor


@dataclass
class BeliefCorrection:
    """The delay buffer's present belief after it applied an image (id 0: none yet)."""

    id: int = 0
    time_s: float = float("nan")
    #: Stamp of the latest joint reading the belief includes.
    last_reading_time_s: float = float("-inf")
    belief: np.ndarray | None = None


@dataclass
class ImagePrior:
    """Where the image on the depth port enters the buffer, with the angles' prior at its
    time (``anchor``), or why it cannot (``problem``)."""

    sequence: int = -1
    image_time_s: float = float("nan")
    anchor: ImageAnchor | None = None
    problem: str = "no image"
    #: The id of the last image observation the buffer has taken in (it is in ``anchor``).
    observation_id: int = 0


@dataclass
class ImageObservationMessage:
    """An image's pseudo-observation of the joint angles at its time, relative to
    ``anchor.prior``."""

    id: int = 0
    sequence: int = -1
    image_time_s: float = float("nan")
    observation: AngleObservation | None = None
    anchor: ImageAnchor | None = None


@dataclass
class AdmittedReading:
    """The latest joint reading the delay buffer's gate admitted (id 0: none yet): its
    time in the tracker's time base and its values; ``restarted`` when the readings'
    clock restarted at it (the estimate starts again from it). The Kalman bank filters
    each new one, so the readings pass one gate.

    ``correction_id`` is the id of the buffer's latest :class:`BeliefCorrection` (on its
    ``correction`` port) when it published this, kept up to date when it applies an
    image: the bank reads its correction port only when that is newer than the
    correction it holds, or None (no word of it: it reads the port every time)."""

    id: int = 0
    time_s: float = float("nan")
    values: np.ndarray | None = None
    restarted: bool = False
    correction_id: int | None = None
