"""The depth image the tracker sees, as a point cloud for Meshcat."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.perception import BaseField, Fields, PointCloud
from pydrake.systems.framework import LeafSystem

from drake_tracker.core.sensors.camera import (
    CameraIntrinsics,
    as_intrinsics,
    stride_for_width,
    subsample,
)
from drake_tracker.core.sensors.depth_frames import DepthFrame


class DepthFrameToPointCloud(LeafSystem):
    """Back-projects the latest depth frame, subsampled to about ``width_px`` wide, into
    a point cloud in the camera frame (+z forward); invalid pixels are dropped.
    ``camera``: the frames' intrinsics, or Drake's ``CameraInfo`` / ``DepthRenderCamera``.

    .. pydrake_system::

        name: DepthFrameToPointCloud
        input_ports:
        - depth_frame
        output_ports:
        - point_cloud
    """

    def __init__(self, camera: CameraIntrinsics, width_px: int = 160):
        super().__init__()
        camera = as_intrinsics(camera)
        self._stride = stride_for_width(camera.width, width_px)
        small = camera.subsampled(self._stride)
        v, u = np.mgrid[0:small.height, 0:small.width]
        # Pixel (i, j) looks through u = i + 0.5, v = j + 0.5 (see CameraIntrinsics).
        self._ray_x = (u + 0.5 - small.cx) / small.fx
        self._ray_y = (v + 0.5 - small.cy) / small.fy
        self._frame_port = self.DeclareAbstractInputPort(
            "depth_frame", AbstractValue.Make(DepthFrame.empty()))
        self.DeclareAbstractOutputPort("point_cloud",
                                       lambda: AbstractValue.Make(PointCloud(0)),
                                       self._calc, {self._frame_port.ticket()})

    def _calc(self, context, output):
        frame: DepthFrame = self._frame_port.Eval(context)
        if frame.is_empty:
            output.set_value(PointCloud(0))
            return
        z = subsample(np.asarray(frame.depth_m, float), self._stride)
        ok = np.isfinite(z) & (z > 0)
        xyz = np.stack([self._ray_x[ok] * z[ok], self._ray_y[ok] * z[ok], z[ok]])
        cloud = PointCloud(xyz.shape[1], Fields(BaseField.kXYZs))
        cloud.mutable_xyzs()[:] = xyz
        output.set_value(cloud)
