"""Robot models: where they live, how they load, and the six virtual camera joints.

The robot is always a URDF/SDF file loaded into a MultibodyPlant; nothing downstream
(kinematics, rendering, encoders) is written by hand for a particular robot.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import (
    Frame,
    JointIndex,
    ModelInstanceIndex,
    PrismaticJoint,
    RevoluteJoint,
    SpatialInertia,
    UnitInertia,
)
from pydrake.systems.framework import DiagramBuilder

#: Names of the six virtual joints, in chain order: prismatic x, y, z, then revolute
#: about x, y, z, all expressed in the nominal camera frame.
VIRTUAL_JOINT_NAMES: tuple[str, ...] = (
    "camera_offset_x",
    "camera_offset_y",
    "camera_offset_z",
    "camera_offset_rx",
    "camera_offset_ry",
    "camera_offset_rz",
)
#: Model instance that holds the virtual joints and their bodies.
VIRTUAL_MODEL_INSTANCE_NAME = "camera_offset"
#: Body whose frame is the estimated (or, in simulation, the true) camera frame.
ESTIMATED_CAMERA_BODY_NAME = "camera_offset_estimated_camera"


def models_dir() -> Path:
    """The folder of robot models shipped with drake_tracker (top-level ``models/``)."""
    return Path(str(resources.files("drake_tracker.models")))


def resolve_model_path(model_file: str) -> Path:
    """Resolves ``model_file``: an existing path as given, else a file under ``models_dir()``."""
    given = Path(model_file).expanduser()
    if given.is_file():
        return given.resolve()
    shipped = models_dir() / model_file
    if shipped.is_file():
        return shipped
    raise FileNotFoundError(
        f"robot model_file '{model_file}' is neither an existing file nor one of the shipped "
        f"models in {models_dir()} ({sorted(p.name for p in models_dir().glob('*.[su][dr]*'))})"
    )


@dataclass
class RobotConfig:
    """Which robot to load and which of its frames matter to the tracker.

    Loadable from YAML with ``pydrake.common.yaml.yaml_load_typed``.
    """

    #: URDF or SDF file: a path, or the name of a model under ``models/``.
    model_file: str = "apollo.sdf"
    #: Name of the depth camera's frame in the model (Drake camera convention:
    #: +z along the optical axis, +x right, +y down). Its pose is the *nominal* one.
    camera_frame: str = "camera_optical"
    #: Name of the end-effector frame whose pose in the camera frame is the output.
    end_effector_frame: str = "end_effector"


#: Robot presets shipped with the package.
ROBOT_PRESETS: dict[str, RobotConfig] = {
    "apollo": RobotConfig(),
    "arm6": RobotConfig(
        model_file="arm6_on_stand.urdf",
        camera_frame="camera_optical",
        end_effector_frame="tool_center",
    ),
}


def robot_preset(name: str) -> RobotConfig:
    """A copy of a named robot preset; unknown names raise a ValueError listing the known."""
    if name not in ROBOT_PRESETS:
        raise ValueError(f"unknown robot preset '{name}'; known: {sorted(ROBOT_PRESETS)}")
    return dataclasses.replace(ROBOT_PRESETS[name])


def add_robot(plant: MultibodyPlant, config: RobotConfig) -> ModelInstanceIndex:
    """Parses the robot model into ``plant`` (not finalized) and checks the named frames."""
    path = resolve_model_path(config.model_file)
    parser = Parser(plant)
    parser.package_map().Add("drake_tracker_models", str(models_dir()))
    instances = parser.AddModels(str(path))
    if len(instances) != 1:
        raise ValueError(f"{path} defines {len(instances)} models; expected exactly one")
    instance = instances[0]
    for field in ("camera_frame", "end_effector_frame"):
        name = getattr(config, field)
        if not plant.HasFrameNamed(name, instance):
            frames = [
                plant.get_frame(i).name()
                for i in plant.GetFrameIndices(instance)
            ]
            raise ValueError(
                f"RobotConfig.{field}: frame '{name}' does not exist in {path.name}; "
                f"frames: {sorted(frames)}"
            )
    return instance


def add_virtual_camera_joints(
    plant: MultibodyPlant, camera_frame: Frame, mass_kg: float = 1e-3
) -> tuple[list[str], Frame]:
    """Inserts six virtual joints between ``camera_frame`` and a new camera body.

    The chain is prismatic x, y, z, then revolute about x, y, z, all with axes in the
    nominal camera frame, so at zero positions the new body's frame coincides with
    ``camera_frame``, and in general ``X_nominal_true = p(x,y,z) * Rx * Ry * Rz``.
    Returns the joint names (``VIRTUAL_JOINT_NAMES``) and the new camera body frame.
    The tiny bodies have a small mass only so that a continuous plant stays regular.
    """
    instance = plant.AddModelInstance(VIRTUAL_MODEL_INSTANCE_NAME)
    inertia = SpatialInertia(
        mass=mass_kg, p_PScm_E=np.zeros(3), G_SP_E=UnitInertia.SolidSphere(0.01)
    )
    parent = camera_frame
    axes = np.eye(3)
    for k, name in enumerate(VIRTUAL_JOINT_NAMES):
        body_name = ESTIMATED_CAMERA_BODY_NAME if k == 5 else f"{name}_body"
        body = plant.AddRigidBody(body_name, instance, inertia)
        axis = axes[k % 3]
        if k < 3:
            joint = PrismaticJoint(name, parent, body.body_frame(), axis)
        else:
            joint = RevoluteJoint(name, parent, body.body_frame(), axis)
        plant.AddJoint(joint)
        parent = body.body_frame()
    return list(VIRTUAL_JOINT_NAMES), parent


def camera_offset_transform(offset: np.ndarray) -> np.ndarray:
    """4x4 ``X_nominal_true`` for virtual joint values [x, y, z, rx, ry, rz] (m, rad)."""
    x, y, z, rx, ry, rz = np.asarray(offset, dtype=float)
    cx, sx = np.cos(rx), np.sin(rx)
    cy, sy = np.cos(ry), np.sin(ry)
    cz, sz = np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    X = np.eye(4)
    X[:3, :3] = Rx @ Ry @ Rz
    X[:3, 3] = [x, y, z]
    return X


def joint_names(plant: MultibodyPlant) -> list[str]:
    """Names of the plant's single-DoF joints in position-vector order."""
    joints = [plant.get_joint(JointIndex(i)) for i in range(plant.num_joints())]
    joints = [j for j in joints if j.num_positions() == 1]
    joints.sort(key=lambda j: j.position_start())
    if len(joints) != plant.num_positions():
        raise ValueError("only single-DoF joints (revolute, prismatic) are supported")
    return [j.name() for j in joints]


@dataclass
class TrackerModel:
    """The tracker's model: the robot plus the six virtual camera joints, finalized.

    ``diagram`` holds ``plant`` and ``scene_graph`` so that geometry can be queried.
    """

    config: RobotConfig
    diagram: object
    plant: MultibodyPlant
    scene_graph: object
    robot_instance: ModelInstanceIndex
    #: All single-DoF joint names in position order; virtual joints included.
    joint_names: list[str]
    #: The nominal camera frame from the model, and the estimated one after the chain.
    nominal_camera_frame: Frame
    camera_frame: Frame
    end_effector_frame: Frame

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def virtual_joint_indices(self) -> np.ndarray:
        return np.array([self.joint_names.index(n) for n in VIRTUAL_JOINT_NAMES])

    @property
    def robot_joint_names(self) -> list[str]:
        return [n for n in self.joint_names if n not in VIRTUAL_JOINT_NAMES]


def build_tracker_model(config: RobotConfig) -> TrackerModel:
    """Loads ``config``'s robot, adds the virtual camera joints, and finalizes."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    instance = add_robot(plant, config)
    nominal = plant.GetFrameByName(config.camera_frame, instance)
    _, camera = add_virtual_camera_joints(plant, nominal)
    plant.Finalize()
    diagram = builder.Build()
    return TrackerModel(
        config=config,
        diagram=diagram,
        plant=plant,
        scene_graph=scene_graph,
        robot_instance=instance,
        joint_names=joint_names(plant),
        nominal_camera_frame=nominal,
        camera_frame=camera,
        end_effector_frame=plant.GetFrameByName(config.end_effector_frame, instance),
    )
