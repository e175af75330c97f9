"""Resolving the tracker's parameters against a model, once: ``TrackerParams`` (per
joint group, as a YAML file has them) in, the core's ``ResolvedParams`` (per joint, as
arrays in the model's position order) out."""

from __future__ import annotations

from collections.abc import Collection
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.filter.kalman import KalmanBankParams
from drake_tracker.core.resolved_params import JointArrays, ResolvedParams
from drake_tracker.params.tracker_params import JointNoise, TrackerParams
from drake_tracker.params.validation import validate_tracker_params
from drake_tracker.robot.model import VIRTUAL_JOINT_NAMES

if TYPE_CHECKING:
    from drake_tracker.robot.model import TrackerModel


def resolve_tracker_params(params: TrackerParams | ResolvedParams | None,
                           model: TrackerModel) -> ResolvedParams:
    """``params`` (None: the defaults) checked (:func:`validate_tracker_params`) and
    resolved for ``model``'s joints; ValueError naming the field or the unknown joint.
    A ``ResolvedParams`` is returned as it is."""
    if isinstance(params, ResolvedParams):
        if params.joints.names != tuple(model.joint_names):
            raise ValueError(f"parameters resolved for joints {list(params.joints.names)}, "
                             f"not this model's {model.joint_names}")
        return params
    params = TrackerParams() if params is None else params
    validate_tracker_params(params)
    names = list(model.joint_names)
    virtual = model.virtual_joint_names
    camera_chains = {c.name: camera_chain_joints(model.for_camera(c.name))
                     for c in model.cameras}
    per_camera = []  # each camera's blocks (see other_cameras_joints)
    left_joints = []
    for camera in model.cameras:
        own = camera.virtual_joint_names
        left = other_cameras_joints(model, camera.name, camera_chains)
        per_camera.append((camera.name, tuple(resolve_blocks(
            params, names, camera_chains[camera.name], own, left))))
        left_joints.append((camera.name, np.array([names.index(n) for n in left], np.int64)))
    chains = {n for c in camera_chains.values() for n in c}
    chain = [n for n in names if n in chains]
    noise = joint_noise_for(params, names, model.prismatic_joint_names, virtual)
    unknown = sorted(set(params.initial_positions_rad) - set(names))
    if unknown:
        raise ValueError(f"initial_positions_rad: unknown joint names {unknown}")
    reading = camera_offset_readings(params, model)
    mean = reading.copy()
    for name, value in params.initial_positions_rad.items():
        mean[names.index(name)] = value

    def column(field: str) -> np.ndarray:
        return np.array([getattr(j, field) for j in noise], float)

    has_bias = np.array([j.has_bias for j in noise], bool)
    # No bias jumps on the joints that move a camera (a pan-tilt head): a jump there
    # turns the whole view, and on s-head-arm with a time-varying arm bias it let the
    # filter "explain" a misaligned arm by looking away from it (an unrendered robot
    # scores 0 per pixel, a misaligned one less): 300 mm from then on. (The switch
    # ``image.bias_jumps_in_camera_chain`` that allowed them is gone.)
    jumps = has_bias & np.array([name not in chain for name in names])
    declared_jumps = column("bias_jump_rate_per_s")
    joints = JointArrays(
        names=tuple(names),
        kalman=kalman_params(noise, names),
        bias_process_std=column("bias_process_std_rad_per_sqrt_s"),
        bias_decay_per_s=column("bias_decay_per_s"),
        has_bias=has_bias,
        jump_rate_per_s=np.where(jumps, declared_jumps, 0.0),
        declared_jump_rate_per_s=declared_jumps,
        jump_std=column("bias_jump_std_rad"),
        initial_mean=mean,
        initial_angle_std=column("initial_angle_std_rad"),
        initial_bias_std=column("initial_bias_std_rad"),
        robot=np.isin(names, model.robot_joint_names),
        robot_indices=model.robot_joint_indices,
        virtual_reading=reading,
    )
    return ResolvedParams(
        joints=joints,
        blocks=per_camera[0][1],
        camera_chain=tuple(chain),
        camera_blocks=tuple(per_camera),
        camera_left_joints=tuple(left_joints) if len(model.cameras) > 1 else (),
        image=params.image,
        health=params.health,
        timestamps=params.timestamps,
        use_joint_readings=bool(params.use_joint_readings),
        estimate_camera_offset=bool(params.estimate_camera_offset),
        buffer_horizon_s=float(params.buffer_horizon_s),
        max_interpolation_gap_s=float(params.max_interpolation_gap_s),
        camera_calibration=params.camera_calibration if (
            params.camera_calibration.window_s > 0 and len(model.cameras) > 1
            and params.estimate_camera_offset and not params.camera_offsets
            and params.use_joint_readings) else None,
    )


def camera_offset_readings(params: TrackerParams, model: TrackerModel) -> np.ndarray:
    """(n,) each joint's reading besides the encoders': ``params.camera_offsets`` on each
    calibrated camera's six virtual joints, 0 elsewhere. ValueError for a camera the
    model does not have."""
    cameras = [c.name for c in model.cameras]
    unknown = sorted(set(params.camera_offsets) - set(cameras))
    if unknown:
        raise ValueError(f"camera_offsets: unknown cameras {unknown}; the model's cameras "
                         f"are {cameras}")
    reading = np.zeros(model.num_joints)
    for name, offsets in params.camera_offsets.items():
        reading[model.camera_joint_indices(name)] = np.asarray(offsets, float)
    return reading


def kalman_params(noise: list[JointNoise], names: list[str]) -> KalmanBankParams:
    """The bank's per-joint arrays (σb is 0 for a joint without bias)."""
    has_bias = np.array([j.has_bias for j in noise], bool)
    return KalmanBankParams(
        encoder_noise_std=np.array([j.encoder_noise_std_rad for j in noise]),
        angle_process_std=np.array([j.angle_process_std_rad_per_sqrt_s for j in noise]),
        bias_process_std=np.where(
            has_bias, [j.bias_process_std_rad_per_sqrt_s for j in noise], 0.0),
        bias_decay_per_s=np.array([j.bias_decay_per_s for j in noise]),
        has_bias=has_bias,
        names=tuple(names),
    )


def other_cameras_joints(model: TrackerModel, camera: str,
                         camera_chains: dict[str, list[str]]) -> list[str]:
    """The joints that camera ``camera``'s images leave as they are: every other camera's
    six offset joints, and the robot joints that move another camera and not this one
    (``camera_chains``: each camera's ``camera_chain_joints``; e.g. a pan-tilt head's
    joints, for a camera on a post). Those joints are the other camera's frame: from
    this camera they are seen on a few pixels (a head across the room), and what its
    images make of them lands on the other camera's frame with nothing to correct it
    while that camera cannot see the arm. Measured on in-out-in-2cam/none seed 0, the
    post camera's images walked the head's pan 4 deg (true 0) in 3 s with the hand out
    of the head camera's view: the hand in the head camera's frame went 60-100 mm off."""
    own = set(model.camera(camera).virtual_joint_names) | set(camera_chains[camera])
    others = [n for c in model.cameras if c.name != camera
              for n in (*camera_chains[c.name], *c.virtual_joint_names)]
    return [n for n in model.joint_names if n in set(others) - own]


def camera_chain_joints(model: TrackerModel) -> list[str]:
    """The robot joints that move the (active: ``TrackerModel.for_camera``) camera (e.g.
    a pan-tilt head), base first."""
    plant = model.plant
    camera_body = model.nominal_camera_frame.body().index()
    chain = []
    for name in model.robot_joint_names:
        joint = plant.GetJointByName(name)
        if camera_body in plant.GetBodiesKinematicallyAffectedBy([joint.index()]):
            chain.append(name)
    return chain


def joint_noise_for(params: TrackerParams, joint_names: list[str],
                    prismatic: Collection[str] = (),
                    virtual: Collection[str] = VIRTUAL_JOINT_NAMES) -> list[JointNoise]:
    """The JointNoise of each joint: its override, else the virtual joints' (``virtual``:
    every camera's, ``TrackerModel.virtual_joint_names``), the
    prismatic joints' (``prismatic``: the robot's, ``TrackerModel.prismatic_joint_names``)
    or the robot joints' default; unknown override names raise ValueError."""
    unknown = sorted(set(params.kalman.overrides) - set(joint_names))
    if unknown:
        raise ValueError(f"kalman.overrides: unknown joint names {unknown}; the model's "
                         f"joints are {joint_names}")
    out = []
    for name in joint_names:
        if name in params.kalman.overrides:
            out.append(params.kalman.overrides[name])
        elif name in virtual:
            out.append(params.kalman.virtual_joints)
        elif name in prismatic:
            out.append(params.kalman.prismatic_joints)
        else:
            out.append(params.kalman.robot_joints)
    return out


def resolve_blocks(params: TrackerParams, joint_names: list[str],
                   camera_chain: list[str] = (),
                   virtual: Collection[str] = VIRTUAL_JOINT_NAMES,
                   excluded: Collection[str] = ()) -> list[np.ndarray]:
    """Index arrays of the CPF blocks of one camera's images: ``virtual`` are its six
    virtual joints, ``excluded`` the other cameras' (in no block: an image leaves the
    other cameras' offsets as they are). Without ``estimate_camera_offset`` the virtual
    joints are left out of every block (they stay at their prior, 0).

    ``per-joint`` samples the camera first: the robot joints that move the camera
    (``camera_chain``, e.g. a pan-tilt head), then the virtual joints, then the other
    joints from base to tip. Measured on Apollo, sampling the arm before the camera lets
    the arm's base joints absorb the camera's error, and the estimate drifts.
    """
    im = params.image
    excluded = set(excluded)
    own = set(virtual)
    virtual = [n for n in joint_names if n in own]
    robot = [n for n in joint_names if n not in own and n not in excluded]
    if im.blocks == "per-joint":
        chain = [n for n in robot if n in camera_chain]
        rest = [n for n in robot if n not in camera_chain]
        groups = [[n] for n in chain] + [[n] for n in virtual] + [[n] for n in rest]
    elif im.blocks == "arm-camera":
        groups = [robot, virtual]
    elif im.blocks == "single":
        groups = [robot + virtual]
    elif im.blocks == "camera":
        groups = [[n] for n in virtual]
    else:
        groups = [list(b) for b in im.block_joints]
        for block in groups:
            for name in block:
                if name not in joint_names:
                    raise ValueError(f"image.block_joints: unknown joint '{name}'; the "
                                     f"model's joints are {joint_names}")
    if not params.estimate_camera_offset:
        groups = [[n for n in b if n not in own] for b in groups]
    groups = [b for b in groups if b]
    return [np.array([joint_names.index(n) for n in b], int) for b in groups]


def resolve_kalman_params(params: TrackerParams, joint_names: list[str],
                          prismatic: Collection[str] = ()) -> KalmanBankParams:
    """The Kalman bank's per-joint arrays for ``joint_names`` alone (no model: e.g. a
    bank of named joints in a test or a benchmark); ``prismatic`` as in
    :func:`joint_noise_for`. The bank checks the arrays; ``params`` are not checked
    again (``resolve_tracker_params`` does, for a model)."""
    return kalman_params(joint_noise_for(params, list(joint_names), prismatic),
                         list(joint_names))
