"""Robot configurations and images for tests and benchmarks: random poses around a
configuration, a pose with the arm in view, and a synthetic noisy depth image."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.robot.model import VIRTUAL_JOINT_NAMES

if TYPE_CHECKING:
    from drake_tracker.core.render.backends import RenderThenScore
    from drake_tracker.core.render.batched import BatchedDepthRenderer
    from drake_tracker.robot.model import TrackerModel


def random_configurations(model: TrackerModel, num: int, seed: int, spread_rad: float = 0.3,
                          center: np.ndarray | None = None) -> np.ndarray:
    """``num`` configurations around ``center`` (default: all zeros), robot joints
    perturbed by N(0, spread_rad^2) and clipped to the joint limits, virtual camera joints
    by small offsets (1 cm, 0.01 rad)."""
    rng = np.random.default_rng(seed)
    plant = model.plant
    nq = plant.num_positions()
    center = np.zeros(nq) if center is None else np.asarray(center, float)
    q = center + rng.normal(0.0, spread_rad, size=(num, nq))
    for name in VIRTUAL_JOINT_NAMES:
        k = model.joint_names.index(name)
        q[:, k] = center[k] + rng.normal(0.0, 0.01, size=num)
    return np.clip(q, plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits())


def default_view_configuration(model: TrackerModel) -> np.ndarray:
    """A configuration that puts the arm in the camera's view for the shipped robots:
    Apollo's head turned to the arm (pan -0.35, tilt 0.6) with the arm reaching
    forward; other robots at zero."""
    q = np.zeros(model.plant.num_positions())
    values = {"head_pan": -0.35, "head_tilt": 0.6, "arm_joint_2": 1.0, "arm_joint_4": -1.2}
    for name, value in values.items():
        if name in model.joint_names:
            q[model.joint_names.index(name)] = value
    return q


def synthetic_observation(renderer: BatchedDepthRenderer | RenderThenScore,
                          q_true: np.ndarray, seed: int = 0,
                          background_m: float = 2.5, noise_m: float = 0.004) -> np.ndarray:
    """A depth image (H, W) float32 for benchmarks: the robot at ``q_true`` rendered by
    ``renderer`` in front of a wall at ``background_m``, plus Gaussian noise."""
    depth = np.asarray(renderer.render(q_true)[0], dtype=np.float64)
    depth[~np.isfinite(depth)] = background_m
    depth += np.random.default_rng(seed).normal(0.0, noise_m, size=depth.shape)
    return depth.astype(np.float32)
