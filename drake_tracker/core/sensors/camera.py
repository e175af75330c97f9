"""Pinhole intrinsics of the depth camera (from Drake's CameraInfo or given) and plain
image subsampling."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pydrake.geometry import DepthRenderCamera, RenderCameraCore
    from pydrake.systems.sensors import CameraInfo


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics as Drake's CameraInfo: a point (x, y, z) in the camera frame
    (+z forward, +x right, +y down) projects to ``u = fx*x/z + cx``, ``v = fy*y/z + cy``,
    and pixel (i, j) looks along the ray through ``u = i + 0.5``, ``v = j + 0.5``, which
    is what RenderEngineVtk renders (measured with drake 1.51.1).

    Widths and heights are in pixels; focal lengths and centres in pixels too.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"CameraIntrinsics: width and height must be positive, got "
                             f"{self.width}x{self.height}")
        if not (self.fx > 0 and self.fy > 0):
            raise ValueError(f"CameraIntrinsics: fx, fy must be positive, got {self.fx}, {self.fy}")
        if not all(np.isfinite([self.cx, self.cy])):
            raise ValueError("CameraIntrinsics: cx, cy must be finite")

    @staticmethod
    def from_fov(width: int, height: int, fov_y_rad: float) -> CameraIntrinsics:
        """Square pixels, principal point at the image centre, as Drake's CameraInfo."""
        f = 0.5 * height / np.tan(0.5 * fov_y_rad)
        return CameraIntrinsics(width, height, f, f, width / 2.0 - 0.5, height / 2.0 - 0.5)

    @staticmethod
    def from_camera_info(info: CameraInfo) -> CameraIntrinsics:
        """From a ``pydrake.systems.sensors.CameraInfo``."""
        return CameraIntrinsics(info.width(), info.height(), info.focal_x(), info.focal_y(),
                                info.center_x(), info.center_y())

    def to_camera_info(self) -> CameraInfo:
        """The same intrinsics as a ``pydrake.systems.sensors.CameraInfo``."""
        from pydrake.systems.sensors import CameraInfo

        return CameraInfo(self.width, self.height, self.fx, self.fy, self.cx, self.cy)

    def subsampled(self, stride: int) -> CameraIntrinsics:
        """Intrinsics of ``subsample(image, stride)``: every ``stride``-th pixel from (0, 0).

        Kept pixel i is pixel ``i*stride``, whose ray passes through ``u = i*stride + 0.5``;
        so that it passes through ``i + 0.5`` in the subsampled image, the principal point
        moves to ``cx/stride + 0.5 - 0.5/stride``.
        """
        if stride < 1:
            raise ValueError(f"subsampling stride must be >= 1, got {stride}")
        shift = 0.5 - 0.5 / stride
        return CameraIntrinsics(
            width=-(-self.width // stride),
            height=-(-self.height // stride),
            fx=self.fx / stride,
            fy=self.fy / stride,
            cx=self.cx / stride + shift,
            cy=self.cy / stride + shift,
        )

    def as_array(self) -> np.ndarray:
        """[width, height, fx, fy, cx, cy] as floats (for storage)."""
        return np.array([self.width, self.height, self.fx, self.fy, self.cx, self.cy], float)

    @staticmethod
    def from_array(a: np.ndarray) -> CameraIntrinsics:
        """The inverse of ``as_array``."""
        w, h, fx, fy, cx, cy = (float(x) for x in a)
        return CameraIntrinsics(int(w), int(h), fx, fy, cx, cy)


def as_intrinsics(camera: CameraIntrinsics | CameraInfo | DepthRenderCamera
                  | RenderCameraCore) -> CameraIntrinsics:
    """CameraIntrinsics from Drake's ``CameraInfo``, a ``DepthRenderCamera`` or
    ``RenderCameraCore`` (e.g. ``sensor.default_depth_render_camera()``), or a
    CameraIntrinsics (returned as it is)."""
    if isinstance(camera, CameraIntrinsics):
        return camera
    if hasattr(camera, "core"):  # DepthRenderCamera / ColorRenderCamera
        camera = camera.core()
    if hasattr(camera, "intrinsics"):  # RenderCameraCore
        camera = camera.intrinsics()
    if all(hasattr(camera, name) for name in ("focal_x", "center_x", "width")):
        return CameraIntrinsics.from_camera_info(camera)
    raise TypeError(f"camera model: expected CameraInfo, DepthRenderCamera or "
                    f"CameraIntrinsics, got {type(camera).__name__}")


def subsample(image: np.ndarray, stride: int) -> np.ndarray:
    """Plain subsampling, as dbrt does: keeps pixels (i*stride, j*stride)."""
    if stride < 1:
        raise ValueError(f"subsampling stride must be >= 1, got {stride}")
    return image[::stride, ::stride]


def stride_for_width(width: int, target_width: int) -> int:
    """The integer stride that brings an image ``width`` px wide to about ``target_width``."""
    if target_width <= 0:
        raise ValueError(f"target image width must be positive, got {target_width}")
    return max(1, int(round(width / target_width)))
