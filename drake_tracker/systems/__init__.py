"""Thin Drake LeafSystems around the functional core, and ``AddTracker`` to wire them."""

from drake_tracker.systems.add_tracker import AddTracker, TrackerCamera, TrackerSystems
from drake_tracker.systems.cpf_system import CpfImageUpdateSystem
from drake_tracker.systems.delay_buffer_system import DelayBufferSystem
from drake_tracker.systems.depth_image_adapter import (
    AddImageStamper,
    DepthImageToFrame,
    ImageStamper,
)
from drake_tracker.systems.kalman_bank_system import JointKalmanBankSystem
from drake_tracker.systems.point_cloud import DepthFrameToPointCloud

__all__ = ["AddImageStamper", "AddTracker", "CpfImageUpdateSystem", "DelayBufferSystem",
           "DepthFrameToPointCloud", "DepthImageToFrame", "ImageStamper",
           "JointKalmanBankSystem", "TrackerCamera", "TrackerSystems"]
