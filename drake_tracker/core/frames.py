"""Time-stamped measurements passed between the simulated world, the tracker and its ports."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class DepthFrame:
    """One depth image with its time stamps.

    ``depth_m`` is (H, W) float32 depth along the optical axis in metres; NaN marks an
    invalid pixel. ``sequence`` counts images from 0; -1 means "no image yet" (an
    empty placeholder that consumers must ignore).
    """

    capture_time_s: float
    arrival_time_s: float
    depth_m: np.ndarray
    sequence: int

    @staticmethod
    def empty() -> DepthFrame:
        return DepthFrame(float("nan"), float("nan"), np.zeros((0, 0), np.float32), -1)

    @property
    def is_empty(self) -> bool:
        return self.sequence < 0
