"""drake_tracker: probabilistic articulated tracking of a robot arm on Drake.

Implements Garcia Cifuentes et al., "Probabilistic Articulated Real-Time Tracking
for Robot Manipulation" (RA-L 2017): a per-joint Kalman bank on (angle, bias), a
Coordinate Particle Filter depth-image update, six virtual camera joints, and a
delay buffer for late images.

The public API (imported lazily, so ``import drake_tracker`` stays cheap)::

    from drake_tracker import AddTracker, RobotConfig, TrackerParams, build_tracker_model
"""

import importlib

from drake_tracker.systems import _PUBLIC as _SYSTEMS

__version__ = "0.1.0"

#: Public name -> module that defines it: the systems, and the rest of the API.
_PUBLIC = {
    **_SYSTEMS,
    "Tracker": "drake_tracker.tracker",
    "TrackerParams": "drake_tracker.params.tracker_params",
    "load_tracker_params": "drake_tracker.params.tracker_params",
    "RobotConfig": "drake_tracker.robot.model",
    "FrameOffset": "drake_tracker.robot.model",
    "TrackerModel": "drake_tracker.robot.model",
    "build_tracker_model": "drake_tracker.robot.model",
    "load_robot_config": "drake_tracker.robot.model",
    "default_home_positions": "drake_tracker.robot.model",
    "CameraIntrinsics": "drake_tracker.core.sensors.camera",
    "DepthFrame": "drake_tracker.core.sensors.depth_frames",
}

__all__ = ["__version__", *_PUBLIC]


def __getattr__(name: str):
    """Imports a public name from its module on first use."""
    if name not in _PUBLIC:
        raise AttributeError(f"module 'drake_tracker' has no attribute '{name}'")
    value = getattr(importlib.import_module(_PUBLIC[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_PUBLIC))
