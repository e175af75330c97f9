"""From a window of images of every camera to each camera's offsets: the fit of
``window_fit`` started at the tracker's belief, then the joints that move only cameras
(a pan-tilt head) folded into those cameras' offsets, with Drake's kinematics.

Shared by ``drake-tracker calibrate-cameras`` (``io/calibrate_run.py``) and the
tracker's own calibration while it runs (``online.py``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from pydrake.math import RollPitchYaw

from drake_tracker.core.calibration.window_fit import (
    WindowFit,
    WindowImage,
    WindowLayout,
    fit_window,
)
from drake_tracker.core.filter.kalman import MEAN_A, MEAN_B

if TYPE_CHECKING:
    from drake_tracker.core.resolved_params import ResolvedParams
    from drake_tracker.robot.model import TrackerModel

#: The fit's initial spreads: a bias (rad), an offset's translation (m) and rotation (rad).
BIAS_SCALE_RAD, OFFSET_SCALE_M, OFFSET_SCALE_RAD = np.radians(1.0), 0.005, np.radians(0.5)


def calibration_layout(model: TrackerModel, params: ResolvedParams) -> WindowLayout:
    """Every robot joint with a bias (the camera chains' included: folded afterwards)."""
    has_bias = params.joints.has_bias[model.robot_joint_indices]
    return WindowLayout(model.num_joints, np.asarray(model.robot_joint_indices),
                        np.flatnonzero(has_bias),
                        {name: model.camera_joint_indices(name) for name in model.camera_names})


def fit_cameras(model: TrackerModel, params: ResolvedParams, images: list[WindowImage],
                belief: np.ndarray, mean_reading: np.ndarray, *, evaluations: int = 8000,
                seed: int = 0) -> tuple[dict[str, np.ndarray], WindowFit]:
    """Each camera's offsets (x, y, z in m; rx, ry, rz in rad) with the joints that move
    only cameras folded in at ``mean_reading`` (the robot joints' readings), and the fit:
    CMA-ES over ``images`` from the (5, n) ``belief`` (its robot biases and camera
    offsets), at most ``evaluations`` of the window's log-likelihood."""
    layout = calibration_layout(model, params)
    start = belief_theta(model, layout, belief)
    scale = np.concatenate([np.full(len(layout.bias_joints), BIAS_SCALE_RAD)]
                           + [np.array([OFFSET_SCALE_M] * 3 + [OFFSET_SCALE_RAD] * 3)]
                           * len(layout.camera_joints))
    fit = fit_window(layout, images, start, scale, evaluations=evaluations, seed=seed)
    offsets = folded_offsets(model, layout, fit, mean_reading, camera_only_joints(model))
    return offsets, fit


def belief_theta(model: TrackerModel, layout: WindowLayout, belief: np.ndarray) -> np.ndarray:
    """θ at the (5, n) ``belief``: its robot biases and each camera's offsets."""
    return np.concatenate([belief[MEAN_B][model.robot_joint_indices][layout.bias_joints]]
                          + [belief[MEAN_A][j] for j in layout.camera_joints.values()])


def camera_only_joints(model: TrackerModel) -> list[str]:
    """The robot joints that move a camera and not the hand (a pan-tilt head): their
    constant error and a mount's are one rigid transform, folded into the offsets."""
    plant = model.plant
    hand = model.end_effector_frame.body().index()
    cameras = {model.camera(name).frame.body().index() for name in model.camera_names}
    out = []
    for name in model.robot_joint_names:
        moved = set(plant.GetBodiesKinematicallyAffectedBy([plant.GetJointByName(name).index()]))
        if moved & cameras and hand not in moved:
            out.append(name)
    return out


def folded_offsets(model: TrackerModel, layout: WindowLayout, fit: WindowFit,
                   reading: np.ndarray, camera_only: list[str]) -> dict[str, np.ndarray]:
    """Each camera's offsets that put it, with the joints that move only cameras
    (``camera_only``: :func:`camera_only_joints`) at ``reading`` (no bias; they are
    trusted from now on), where the fit puts it (its biases and offsets) at that
    reading. Every other joint keeps the fit's angle: a camera on the arm keeps its
    offsets relative to its link, the arm's biases being the tracker's to follow."""
    q_fit = layout.configurations(fit.theta, reading)[0]
    q_plain = q_fit.copy()
    only = [model.joint_names.index(n) for n in camera_only]
    q_plain[only] = reading[[list(layout.robot_indices).index(j) for j in only]]
    return {name: equivalent_offsets(model, name, q_fit, q_plain)
            for name in model.camera_names}


def equivalent_offsets(model: TrackerModel, camera: str, q_target: np.ndarray,
                       q: np.ndarray) -> np.ndarray:
    """(6,) the offsets of camera ``camera`` that put it, at configuration ``q`` (its
    own offsets replaced), where it is at ``q_target``: Gauss-Newton on the pose error
    (translation, roll-pitch-yaw), from ``q_target``'s offsets, with Drake's kinematics.
    """
    plant = model.plant
    context = plant.CreateDefaultContext()
    frame, joints = model.camera(camera).frame, model.camera_joint_indices(camera)
    plant.SetPositions(context, q_target)
    target = plant.CalcRelativeTransform(context, plant.world_frame(), frame)
    q = np.array(q, float)

    def residual(o: np.ndarray) -> np.ndarray:
        q[joints] = o
        plant.SetPositions(context, q)
        error = plant.CalcRelativeTransform(context, plant.world_frame(), frame).inverse() \
            @ target
        return np.concatenate([error.translation(), RollPitchYaw(error.rotation()).vector()])

    o = np.array(q_target[joints], float)
    for _ in range(10):  # the map is nearly linear over degrees: a few steps
        r = residual(o)
        jacobian = np.column_stack([(residual(o + 1e-6 * e) - r) / 1e-6 for e in np.eye(6)])
        step = np.linalg.lstsq(jacobian, -r, rcond=None)[0]
        o = o + step
        if np.max(np.abs(step)) < 1e-10:
            break
    return o
