"""Thin Drake LeafSystems around the functional core, and ``AddTracker`` to wire them.

Imported lazily: ``from drake_tracker.systems import AddTracker``.
"""

import importlib

_PUBLIC = {
    "AddTracker": "drake_tracker.systems.add_tracker",
    "TrackerSystems": "drake_tracker.systems.add_tracker",
    "JointKalmanBankSystem": "drake_tracker.systems.kalman_bank_system",
    "DelayBufferSystem": "drake_tracker.systems.delay_buffer_system",
    "CpfImageUpdateSystem": "drake_tracker.systems.cpf_system",
    "DepthImageToFrame": "drake_tracker.systems.depth_image_adapter",
    "ImageStamper": "drake_tracker.systems.depth_image_adapter",
    "AddImageStamper": "drake_tracker.systems.depth_image_adapter",
    "DepthFrameToPointCloud": "drake_tracker.systems.point_cloud",
}

__all__ = list(_PUBLIC)


def __getattr__(name: str):
    """Imports a public system from its module on first use."""
    if name not in _PUBLIC:
        raise AttributeError(f"module 'drake_tracker.systems' has no attribute '{name}'")
    return getattr(importlib.import_module(_PUBLIC[name]), name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_PUBLIC))
