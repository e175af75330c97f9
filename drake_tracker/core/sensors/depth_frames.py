"""Time-stamped depth images as the tracker reads them, and the conversion from Drake's
depth pixel encodings."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from drake_tracker.core.resolved_params import ResolvedParams


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
        """The placeholder before the first image (``sequence`` -1)."""
        return DepthFrame(float("nan"), float("nan"), np.zeros((0, 0), np.float32), -1)

    @property
    def is_empty(self) -> bool:
        """Whether this is the placeholder, not an image."""
        return self.sequence < 0


#: Depth pixel encodings the tracker reads: Drake's ``ImageDepth32F`` (metres, +inf too
#: far, 0 too close) and ``ImageDepth16U`` (millimetres, 0 invalid or too close,
#: 65535 too far).
DEPTH_ENCODINGS = ("32F_m", "16U_mm")


def depth_to_metres(pixels: np.ndarray, encoding: str) -> np.ndarray:
    """(H, W) float32 depth in metres with NaN for every invalid pixel, from an (H, W) or
    (H, W, 1) array of depth pixels in ``encoding`` (one of ``DEPTH_ENCODINGS``)."""
    data = np.asarray(pixels)
    if data.ndim == 3 and data.shape[2] == 1:
        data = data[:, :, 0]
    if data.ndim != 2:
        raise ValueError(f"depth image: expected (H, W) or (H, W, 1) pixels, got {data.shape}")
    if encoding == "32F_m":
        depth = data.astype(np.float32, copy=True)
        invalid = ~np.isfinite(depth) | (depth <= 0)
    elif encoding == "16U_mm":
        depth = data.astype(np.float32) * np.float32(1e-3)
        invalid = (data == 0) | (data == np.iinfo(np.uint16).max)
    else:
        raise ValueError(f"depth image: unknown encoding '{encoding}'; known: "
                         f"{list(DEPTH_ENCODINGS)}")
    depth[invalid] = np.nan
    return depth


def in_metres(depth: np.ndarray) -> np.ndarray:
    """``depth`` as float metres: a 16-bit camera's millimetres converted
    (:func:`depth_to_metres`, ``16U_mm``), anything else as it is."""
    if np.asarray(depth).dtype == np.uint16:
        return depth_to_metres(depth, "16U_mm")
    return depth


def image_time(frame: DepthFrame, params: ResolvedParams) -> float:
    """The time t' (s) an image is applied at: its capture stamp minus the configured
    offset (``image.image_time_offset_s``)."""
    return float(frame.capture_time_s) - params.image.image_time_offset_s
