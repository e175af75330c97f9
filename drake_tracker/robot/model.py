"""Robot models: where they live, how they load, and the six virtual camera joints.

The robot is always a URDF/SDF file (or Drake model directives) loaded into a
MultibodyPlant; nothing downstream (kinematics, rendering, encoders) is written by hand
for a particular robot. A vendor's package loads as it ships: ``package://`` URIs
resolve through Drake's PackageMap, STL/DAE meshes are converted once to OBJ
(:mod:`drake_tracker.robot.vendor`), and the camera and end-effector frames can be declared
in the :class:`RobotConfig` as a parent frame plus an offset.

The configuration (``RobotConfig``, ``CameraMount``, the presets) is
:mod:`drake_tracker.robot.config`, re-exported here.
"""

import dataclasses
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import PackageMap, Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    Frame,
    JointIndex,
    ModelInstanceIndex,
    PrismaticJoint,
    RevoluteJoint,
    SpatialInertia,
    UnitInertia,
)
from pydrake.systems.framework import DiagramBuilder

from drake_tracker.robot.config import (
    DEFAULT_CAMERA_NAME,
    ESTIMATED_CAMERA_BODY_NAME,
    OFFSET_AXES,
    ROBOT_PRESETS,
    VIRTUAL_JOINT_NAMES,
    VIRTUAL_MODEL_INSTANCE_NAME,
    CameraMount,
    FrameOffset,
    RobotConfig,
    load_robot_config,
    robot_preset,
    virtual_joint_names_of,
)
from drake_tracker.robot.vendor import (
    PACKAGE_SCHEMES,
    drake_loadable_model,
    populate_package_map,
    resolve_uri,
)

#: Package name under which the shipped models are known (``package://drake_tracker_models``).
SHIPPED_MODELS_PACKAGE = "drake_tracker_models"


def models_dir() -> Path:
    """The folder of robot models shipped with drake_tracker (top-level ``models/``)."""
    return Path(str(resources.files("drake_tracker.models")))


def resolve_model_path(model_file: str, package_map: PackageMap | None = None) -> Path:
    """Resolves ``model_file``: a ``package://`` URI (through ``package_map``), an existing
    path as given, else a file under ``models_dir()``."""
    if model_file.startswith(PACKAGE_SCHEMES):
        path = resolve_uri(model_file, package_map or PackageMap.MakeEmpty(), Path.cwd())
        if not path.is_file():
            raise FileNotFoundError(f"robot model_file '{model_file}' resolves to {path}, "
                                    "which does not exist")
        return path
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



def add_robot(plant: MultibodyPlant, config: RobotConfig) -> ModelInstanceIndex:
    """Parses the robot model into ``plant`` (not finalized), adds ``config.added_frames``
    to the robot's model instance, welds a floating root link to the world, and checks
    that the camera and end-effector frames exist in the returned (robot) instance."""
    parser = Parser(plant)
    package_map = parser.package_map()
    package_map.Add(SHIPPED_MODELS_PACKAGE, str(models_dir()))
    populate_package_map(package_map, config.package_paths, config.package_folders, None)
    path = resolve_model_path(config.model_file, package_map)
    populate_package_map(package_map, {}, [], path)
    loadable = drake_loadable_model(path, package_map, config.mesh_cache_dir or None)
    instances = parser.AddModels(str(loadable))
    instance = _robot_instance(plant, instances, config, path)
    _weld_floating_roots(plant, instance)
    for name, offset in config.added_frames.items():
        if plant.HasFrameNamed(name, instance):
            raise ValueError(f"RobotConfig.added_frames: frame '{name}' already exists in "
                             f"{path.name}")
        parent = _find_frame(plant, instances, offset.parent, f"added_frames[{name}].parent",
                             path)
        plant.AddFrame(FixedOffsetFrame(name, parent, offset.transform(), instance))
    required = [("camera_frame", config.camera_frame),
                ("end_effector_frame", config.end_effector_frame)]
    required += [(f"cameras[{m.name}].frame", m.frame) for m in config.camera_mounts()]
    for field_name, name in required:
        if not plant.HasFrameNamed(name, instance):
            # A frame of another instance (directives): alias it in the robot's instance.
            frame = _find_frame(plant, instances, name, field_name, path)
            plant.AddFrame(FixedOffsetFrame(name, frame, RigidTransform(), instance))
    return instance


def _robot_instance(plant: MultibodyPlant, instances: list, config: RobotConfig,
                    path: Path) -> ModelInstanceIndex:
    names = [plant.GetModelInstanceName(i) for i in instances]
    if config.model_instance:
        if config.model_instance not in names:
            raise ValueError(f"RobotConfig.model_instance: '{config.model_instance}' is not "
                             f"one of the models of {path.name}: {names}")
        return instances[names.index(config.model_instance)]
    if len(instances) == 1:
        return instances[0]
    moving = [i for i in instances if any(plant.get_joint(j).num_positions() > 0
                                          for j in plant.GetJointIndices(i))]
    if len(moving) != 1:
        raise ValueError(f"{path.name} defines the models {names}; name the robot's in "
                         "RobotConfig.model_instance")
    return moving[0]


def _find_frame(plant: MultibodyPlant, instances: list, name: str, field_name: str,
                path: Path) -> Frame:
    found = [plant.GetFrameByName(name, i) for i in instances if plant.HasFrameNamed(name, i)]
    if len(found) == 1:
        return found[0]
    frames = sorted({plant.get_frame(f).name() for i in instances
                     for f in plant.GetFrameIndices(i)})
    problem = "does not exist" if not found else "exists in several models"
    raise ValueError(f"RobotConfig.{field_name}: frame '{name}' {problem} in {path.name}; "
                     f"frames: {frames} (or declare it in RobotConfig.added_frames)")


def _weld_floating_roots(plant: MultibodyPlant, instance: ModelInstanceIndex) -> None:
    """Welds each body of ``instance`` that no joint moves to the world at its origin
    (a URDF's root link would otherwise float)."""
    children = {plant.get_joint(j).child_body().index()
                for j in plant.GetJointIndices(instance)}
    children |= {plant.get_joint(JointIndex(j)).child_body().index()
                 for j in range(plant.num_joints())}
    for index in plant.GetBodyIndices(instance):
        if index not in children:
            plant.WeldFrames(plant.world_frame(), plant.get_body(index).body_frame())


def add_virtual_camera_joints(
    plant: MultibodyPlant, camera_frame: Frame, mass_kg: float = 1e-3,
    camera: str = DEFAULT_CAMERA_NAME,
) -> tuple[list[str], Frame]:
    """Inserts six virtual joints between ``camera_frame`` and a new camera body.

    The chain is prismatic x, y, z, then revolute about x, y, z, all with axes in the
    nominal camera frame, so at zero positions the new body's frame coincides with
    ``camera_frame``, and in general ``X_nominal_true = p(x,y,z) * Rx * Ry * Rz``.
    Returns the joint names (``virtual_joint_names_of(camera)``: ``VIRTUAL_JOINT_NAMES``
    for the default camera) and the new camera body frame, of the body
    ``<camera>_offset_estimated_camera`` in the model instance ``<camera>_offset``.
    The tiny bodies have a small mass only so that a continuous plant stays regular.
    """
    names = virtual_joint_names_of(camera)
    instance = plant.AddModelInstance(f"{camera}_offset")
    inertia = SpatialInertia(
        mass=mass_kg, p_PScm_E=np.zeros(3), G_SP_E=UnitInertia.SolidSphere(0.01)
    )
    parent = camera_frame
    axes = np.eye(3)
    for k, name in enumerate(names):
        body_name = f"{camera}_offset_estimated_camera" if k == 5 else f"{name}_body"
        body = plant.AddRigidBody(body_name, instance, inertia)
        axis = axes[k % 3]
        if k < 3:
            joint = PrismaticJoint(name, parent, body.body_frame(), axis)
        else:
            joint = RevoluteJoint(name, parent, body.body_frame(), axis)
        plant.AddJoint(joint)
        parent = body.body_frame()
    return list(names), parent


def add_camera_chains(plant: MultibodyPlant, instance: ModelInstanceIndex,
                      config: RobotConfig) -> list[tuple[CameraMount, Frame, Frame]]:
    """The virtual joints of each of ``config``'s cameras (``add_virtual_camera_joints``),
    in order: (mount, nominal frame, estimated frame) of each."""
    chains = []
    for mount in config.camera_mounts():
        nominal = plant.GetFrameByName(mount.frame, instance)
        _, frame = add_virtual_camera_joints(plant, nominal, camera=mount.name)
        chains.append((mount, nominal, frame))
    return chains


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


def default_home_positions(plant: MultibodyPlant,
                           names: list[str] | None = None) -> np.ndarray:
    """A home pose from the joint limits of a finalized ``plant``: the middle of each
    joint's range; 0 where a limit is infinite, moved inside a finite one (rad or m).

    ``names`` (default: ``joint_names(plant)``) picks the joints and their order.
    """
    names = joint_names(plant) if names is None else list(names)
    home = np.zeros(len(names))
    for k, name in enumerate(names):
        joint = plant.GetJointByName(name)
        if joint.num_positions() != 1:
            raise ValueError(f"joint '{name}' is not a single-DoF joint")
        lower = float(joint.position_lower_limits()[0])
        upper = float(joint.position_upper_limits()[0])
        if np.isfinite(lower) and np.isfinite(upper):
            home[k] = 0.5 * (lower + upper)
        else:
            home[k] = float(np.clip(0.0, lower, upper))
    return home


@dataclass(frozen=True)
class ModelCamera:
    """One depth camera of a :class:`TrackerModel`: its nominal frame (from the robot
    model), its estimated frame (after its six virtual joints) and those joints."""

    name: str
    nominal_frame: Frame
    frame: Frame
    #: ``<name>_offset_x`` ... ``<name>_offset_rz``.
    virtual_joint_names: tuple[str, ...]


@dataclass
class TrackerModel:
    """The tracker's model: the robot plus six virtual joints per camera, finalized.

    ``diagram`` holds ``plant`` and ``scene_graph`` so that geometry can be queried.
    ``camera_frame`` and ``nominal_camera_frame`` are those of the model's active camera:
    the first (the camera of the output) unless the model is one camera's view
    (:meth:`for_camera`, what renders that camera's images).
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
    #: Every camera, in ``RobotConfig.camera_mounts()`` order (empty: the one camera of
    #: ``camera_frame``, named ``camera``).
    cameras: tuple[ModelCamera, ...] = ()

    def __post_init__(self) -> None:
        if not self.cameras:
            self.cameras = (ModelCamera(DEFAULT_CAMERA_NAME, self.nominal_camera_frame,
                                        self.camera_frame, VIRTUAL_JOINT_NAMES),)

    @property
    def camera_names(self) -> list[str]:
        """The cameras' names, the first being the camera of the output."""
        return [c.name for c in self.cameras]

    def camera(self, name: str) -> ModelCamera:
        """The camera ``name``; ValueError naming the model's cameras for another."""
        for camera in self.cameras:
            if camera.name == name:
                return camera
        raise ValueError(f"unknown camera '{name}': the model's cameras are "
                         f"{self.camera_names} (RobotConfig.cameras)")

    def for_camera(self, name: str) -> "TrackerModel":
        """This model seen from camera ``name``: ``camera_frame`` and
        ``nominal_camera_frame`` are that camera's (the plant and joints are shared)."""
        camera = self.camera(name)
        return dataclasses.replace(self, nominal_camera_frame=camera.nominal_frame,
                                   camera_frame=camera.frame)

    def camera_joint_indices(self, name: str) -> np.ndarray:
        """Indices of camera ``name``'s six virtual joints in ``joint_names``."""
        return np.array([self.joint_names.index(n)
                         for n in self.camera(name).virtual_joint_names])

    @property
    def num_joints(self) -> int:
        """Number of joints the tracker estimates (robot and virtual)."""
        return len(self.joint_names)

    @property
    def virtual_joint_names(self) -> list[str]:
        """Every camera's six virtual joints, camera after camera."""
        return [n for c in self.cameras for n in c.virtual_joint_names]

    @property
    def virtual_joint_indices(self) -> np.ndarray:
        """Indices of the virtual camera joints in ``joint_names`` (six per camera, camera
        after camera: with one camera, its six)."""
        return np.array([self.joint_names.index(n) for n in self.virtual_joint_names])

    @property
    def robot_joint_indices(self) -> np.ndarray:
        """Indices of the robot (measured) joints within ``joint_names``."""
        return np.array([self.joint_names.index(n) for n in self.robot_joint_names], int)

    @property
    def robot_joint_names(self) -> list[str]:
        """The robot's own joints in position order: the order of the encoder readings."""
        virtual = set(self.virtual_joint_names)
        return [n for n in self.joint_names if n not in virtual]

    @property
    def prismatic_joint_names(self) -> list[str]:
        """The robot's own joints that translate (their positions in m, not rad): their
        filters default to ``kalman.prismatic_joints``."""
        robot = set(self.robot_joint_names)
        joints = (self.plant.get_joint(i) for i in self.plant.GetJointIndices())
        return [j.name() for j in joints
                if j.name() in robot and j.type_name() == "prismatic"]


def build_tracker_model(config: RobotConfig) -> TrackerModel:
    """Loads ``config``'s robot, adds each camera's virtual joints, and finalizes."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    instance = add_robot(plant, config)
    chains = add_camera_chains(plant, instance, config)
    plant.Finalize()
    diagram = builder.Build()
    cameras = tuple(ModelCamera(m.name, nominal, frame, virtual_joint_names_of(m.name))
                    for m, nominal, frame in chains)
    return TrackerModel(
        config=config,
        diagram=diagram,
        plant=plant,
        scene_graph=scene_graph,
        robot_instance=instance,
        joint_names=joint_names(plant),
        nominal_camera_frame=cameras[0].nominal_frame,
        camera_frame=cameras[0].frame,
        end_effector_frame=plant.GetFrameByName(config.end_effector_frame, instance),
        cameras=cameras,
    )


__all__ = ["DEFAULT_CAMERA_NAME", "ESTIMATED_CAMERA_BODY_NAME", "OFFSET_AXES", "ROBOT_PRESETS",
           "VIRTUAL_JOINT_NAMES", "VIRTUAL_MODEL_INSTANCE_NAME", "CameraMount", "FrameOffset",
           "ModelCamera", "RobotConfig", "TrackerModel", "add_camera_chains", "add_robot",
           "add_virtual_camera_joints", "build_tracker_model", "camera_offset_transform",
           "default_home_positions", "joint_names", "load_robot_config", "models_dir",
           "resolve_model_path", "robot_preset", "virtual_joint_names_of"]
