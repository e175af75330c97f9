"""The world is not the model: perturb the WORLD plant's robot (never the tracker's).

Applied to the world plant after ``add_robot`` and before ``Finalize``
(:func:`apply_model_mismatch`):

* joint origins: each perturbed joint is removed and added again, with the same name,
  axis, limits and damping, on a new frame ``X_FF' = [R(axis_j, deg), mm * dir_j]`` of
  its old frame on the parent; ``dir_j`` and ``axis_j`` are seeded random unit vectors
  (``model_mismatch.seed``, drawn for every single-DoF joint of the robot in joint
  index order, so a joint's error does not depend on which others are perturbed);
* a cable: one cylinder per moving link along the chain to the end effector, from the
  link's joint to the next joint, ``cable_offset_m`` beside that segment;
* a larger hand: the end effector body's visual geometry again, scaled by
  ``hand_scale`` about the body's origin.

Joints keep their names, so positions map by name as in the nominal robot.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.geometry import (
    Box,
    Capsule,
    Convex,
    Cylinder,
    Ellipsoid,
    Mesh,
    Role,
    SceneGraph,
    Shape,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    ModelInstanceIndex,
    PrismaticJoint,
    RevoluteJoint,
    RigidBody,
)

from drake_tracker.sim.scenario.config import ModelMismatchConfig
from drake_tracker.sim.scenario.validation import require
from drake_tracker.sim.streams import counter_generator

#: Random stream of the world robot's perturbations.
MISMATCH_STREAM = 9
#: Colour of the unmodelled cable.
CABLE_RGBA = np.array([0.1, 0.1, 0.1, 1.0])


def robot_joints(plant: MultibodyPlant, instance: ModelInstanceIndex) -> list:
    """The single-DoF revolute and prismatic joints of ``instance``, by joint index."""
    joints = [plant.get_joint(j) for j in plant.GetJointIndices(instance)]
    return [j for j in joints if isinstance(j, (RevoluteJoint, PrismaticJoint))]


def joint_origin_errors(names: list[str], config: ModelMismatchConfig) -> dict:
    """Joint name -> ``X_FF'`` (RigidTransform): the seeded origin error of each joint of
    ``names`` (every joint of the robot, in joint index order)."""
    rng = counter_generator(config.seed, 0, MISMATCH_STREAM)
    errors = {}
    for name in names:
        direction, axis = rng.standard_normal(3), rng.standard_normal(3)
        direction /= np.linalg.norm(direction)
        axis /= np.linalg.norm(axis)
        rotation = RotationMatrix(AngleAxis(np.radians(config.joint_origin_deg), axis))
        errors[name] = RigidTransform(rotation, 1e-3 * config.joint_origin_mm * direction)
    return errors


def _move_joint_origin(plant: MultibodyPlant, joint, X_FF: RigidTransform) -> None:
    instance, name = joint.model_instance(), joint.name()
    for index in plant.GetJointActuatorIndices():  # (the per-instance list is empty here)
        if plant.get_joint_actuator(index).joint().index() == joint.index():
            plant.RemoveJointActuator(plant.get_joint_actuator(index))
    parent, child = joint.frame_on_parent(), joint.frame_on_child()
    lower, upper = joint.position_lower_limits()[0], joint.position_upper_limits()[0]
    velocity = (joint.velocity_lower_limits()[0], joint.velocity_upper_limits()[0])
    if isinstance(joint, RevoluteJoint):
        axis, damping = joint.revolute_axis(), joint.default_damping()
        plant.RemoveJoint(joint)
        frame = plant.AddFrame(FixedOffsetFrame(f"{name}_world_origin", parent, X_FF, instance))
        new = plant.AddJoint(RevoluteJoint(name, frame, child, axis, lower, upper, damping))
    else:
        axis, damping = joint.translation_axis(), joint.default_damping()
        plant.RemoveJoint(joint)
        frame = plant.AddFrame(FixedOffsetFrame(f"{name}_world_origin", parent, X_FF, instance))
        new = plant.AddJoint(PrismaticJoint(name, frame, child, axis, lower, upper, damping))
    new.set_velocity_limits([velocity[0]], [velocity[1]])


def _inboard_joint(plant: MultibodyPlant, body):
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        if joint.child_body().index() == body.index():
            return joint
    return None


def cable_segments(plant: MultibodyPlant, end_effector_body: RigidBody) -> list:
    """(body, start, end) in the body's frame: from each moving link's joint to the next
    joint of the chain world -> end effector (segments shorter than 1 cm skipped)."""
    segments = []
    body = end_effector_body
    while True:
        joint = _inboard_joint(plant, body)
        if joint is None:
            return segments
        parent = joint.parent_body()
        parent_joint = _inboard_joint(plant, parent)
        if parent_joint is not None and parent_joint.num_positions() == 1:
            start = parent_joint.frame_on_child().GetFixedPoseInBodyFrame().translation()
            end = joint.frame_on_parent().GetFixedPoseInBodyFrame().translation()
            if np.linalg.norm(end - start) >= 0.01:
                segments.append((parent, start, end))
        body = parent


def _cylinder_between(start: np.ndarray, end: np.ndarray, offset_m: float,
                      angle_deg: float) -> RigidTransform:
    """Pose of a cylinder (axis z) from ``start`` to ``end``, moved ``offset_m`` sideways:
    along the body's x axis made perpendicular to the segment (else its y axis), turned
    ``angle_deg`` about the segment."""
    axis = (end - start) / np.linalg.norm(end - start)
    for guess in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        side = guess - axis * (guess @ axis)
        if np.linalg.norm(side) > 0.3:
            break
    side /= np.linalg.norm(side)
    angle = np.radians(angle_deg)
    side = np.cos(angle) * side + np.sin(angle) * np.cross(axis, side)
    rotation = np.column_stack([side, np.cross(axis, side), axis])
    return RigidTransform(RotationMatrix(rotation), 0.5 * (start + end) + offset_m * side)


def scaled_shape(shape: Shape, scale: float) -> Shape:
    """``shape`` scaled by ``scale`` about its own frame's origin."""
    if isinstance(shape, Box):
        return Box(scale * shape.width(), scale * shape.depth(), scale * shape.height())
    if isinstance(shape, Cylinder):
        return Cylinder(scale * shape.radius(), scale * shape.length())
    if isinstance(shape, Sphere):
        return Sphere(scale * shape.radius())
    if isinstance(shape, Capsule):
        return Capsule(scale * shape.radius(), scale * shape.length())
    if isinstance(shape, Ellipsoid):
        return Ellipsoid(scale * shape.a(), scale * shape.b(), scale * shape.c())
    if isinstance(shape, (Mesh, Convex)):
        return type(shape)(shape.source().path(), scale * np.asarray(shape.scale3()))
    require(False, "model_mismatch.hand_scale", scale,
            f"cannot scale a {type(shape).__name__} of the hand")
    return shape


def _diffuse(scene_graph: SceneGraph, geometry_id) -> np.ndarray:
    properties = scene_graph.model_inspector().GetIllustrationProperties(geometry_id)
    if properties is not None and properties.HasProperty("phong", "diffuse"):
        rgba = properties.GetProperty("phong", "diffuse")
        return np.array([rgba.r(), rgba.g(), rgba.b(), rgba.a()])
    return np.array([0.6, 0.6, 0.6, 1.0])


def _scale_hand(plant: MultibodyPlant, scene_graph: SceneGraph, body, scale: float) -> None:
    inspector = scene_graph.model_inspector()
    frame_id = plant.GetBodyFrameIdOrThrow(body.index())
    for k, geometry_id in enumerate(inspector.GetGeometries(frame_id, Role.kIllustration)):
        X_BG = inspector.GetPoseInFrame(geometry_id)
        shape = scaled_shape(inspector.GetShape(geometry_id), scale)
        X_scaled = RigidTransform(X_BG.rotation(), scale * X_BG.translation())
        plant.RegisterVisualGeometry(body, X_scaled, shape, f"mismatch_hand_{k}",
                                     _diffuse(scene_graph, geometry_id))


def apply_model_mismatch(plant: MultibodyPlant, scene_graph: SceneGraph,
                         instance: ModelInstanceIndex, end_effector_frame: str,
                         config: ModelMismatchConfig) -> None:
    """Makes the (not finalized) world plant's robot differ from its model (module doc)."""
    if not config.enabled:
        return
    end_effector_body = plant.GetFrameByName(end_effector_frame, instance).body()
    if config.cable:
        for k, (body, start, end) in enumerate(cable_segments(plant, end_effector_body)):
            plant.RegisterVisualGeometry(
                body, _cylinder_between(start, end, config.cable_offset_m, config.cable_angle_deg),
                Cylinder(config.cable_radius_m, float(np.linalg.norm(end - start))),
                f"mismatch_cable_{k}", CABLE_RGBA)
    if config.hand_scale != 1.0:
        _scale_hand(plant, scene_graph, end_effector_body, config.hand_scale)
    joints = robot_joints(plant, instance)
    names = [j.name() for j in joints]
    for name in config.joints:
        require(name in names, "model_mismatch.joints", name,
                f"no such joint in the robot; joints: {names}")
    errors = joint_origin_errors(names, config)
    chosen = set(config.joints or names)
    if config.joint_origin_mm == 0 and config.joint_origin_deg == 0:
        return
    for joint in joints:
        if joint.name() in chosen:
            _move_joint_origin(plant, joint, errors[joint.name()])
