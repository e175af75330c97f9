"""drake_tracker: probabilistic articulated tracking of a robot arm on Drake.

Implements Garcia Cifuentes et al., "Probabilistic Articulated Real-Time Tracking
for Robot Manipulation" (RA-L 2017): a per-joint Kalman bank on (angle, bias), a
Coordinate Particle Filter depth-image update, six virtual camera joints, and a
delay buffer for late images.

The layers, each importing only those before it: ``robot`` (the model, one source of
truth), ``core`` (the functional core: plain functions and small classes over numpy,
numba kernels), ``params`` (YAML dataclasses, checked and resolved once into the
core's ``ResolvedParams``), then the shells over one per-image step
(``core/image_step.py``): the offline ``Tracker`` and the Drake ``systems``; ``io``
(recorded runs); and the applications ``sim``, ``cli``, ``demo``, ``bench``,
``evaluation``, ``servo``. The public API::

    from drake_tracker import AddTracker, RobotConfig, TrackerParams, build_tracker_model
"""

from drake_tracker.core.resolved_params import ResolvedParams
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.params import load_tracker_params, resolve_tracker_params
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import (
    FrameOffset,
    RobotConfig,
    TrackerModel,
    build_tracker_model,
    default_home_positions,
    load_robot_config,
)
from drake_tracker.systems import (
    AddImageStamper,
    AddTracker,
    CpfImageUpdateSystem,
    DelayBufferSystem,
    DepthFrameToPointCloud,
    DepthImageToFrame,
    ImageStamper,
    JointKalmanBankSystem,
    TrackerCamera,
    TrackerSystems,
)
from drake_tracker.tracker import Tracker

#: The package's version, as the wheel states it.
__version__ = "0.1.0"

__all__ = ["__version__", "AddImageStamper", "AddTracker", "CameraIntrinsics",
           "CpfImageUpdateSystem", "DelayBufferSystem", "DepthFrame",
           "DepthFrameToPointCloud", "DepthImageToFrame", "FrameOffset", "ImageStamper",
           "JointKalmanBankSystem", "ResolvedParams", "RobotConfig", "Tracker",
           "TrackerCamera", "TrackerModel", "TrackerParams", "TrackerSystems",
           "build_tracker_model",
           "default_home_positions", "load_robot_config", "load_tracker_params",
           "resolve_tracker_params"]
