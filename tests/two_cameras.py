"""Apollo with a second depth camera on a post, and the camera model of both (shared by
the tests of several cameras: ``systems/``, ``robustness/test_camera_remount.py``,
``io/test_estimates_bag.py``)."""

import numpy as np

from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.model import CameraMount, FrameOffset, robot_preset

CAMERA = CameraIntrinsics.from_fov(80, 60, np.radians(45.0))
POST = FrameOffset(parent="torso", xyz_m=[1.2, -1.45, 1.45], rpy_deg=[-114.44, 0.0, 38.29])


def two_camera_config():
    config = robot_preset("apollo")
    config.added_frames = {"post_nominal": POST}
    config.cameras = [CameraMount("camera", "camera_optical"),
                      CameraMount("post", "post_nominal")]
    return config
