"""What a robot model is made of, as configured: the robot's file, its frames, and its
depth cameras (each with six virtual offset joints, named after it)."""

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw

#: The name of the one camera of a model that declares no ``RobotConfig.cameras``.
DEFAULT_CAMERA_NAME = "camera"
#: Axes of a camera's six virtual joints, in chain order: prismatic x, y, z, then
#: revolute about x, y, z, all expressed in the camera's nominal frame.
OFFSET_AXES: tuple[str, ...] = ("x", "y", "z", "rx", "ry", "rz")


def virtual_joint_names_of(camera: str) -> tuple[str, ...]:
    """The six virtual joints of the camera named ``camera``: ``<camera>_offset_x`` ...
    ``<camera>_offset_rz``."""
    return tuple(f"{camera}_offset_{axis}" for axis in OFFSET_AXES)


#: Names of the six virtual joints of the one (default) camera.
VIRTUAL_JOINT_NAMES: tuple[str, ...] = virtual_joint_names_of(DEFAULT_CAMERA_NAME)
#: Model instance that holds the default camera's virtual joints and their bodies.
VIRTUAL_MODEL_INSTANCE_NAME = f"{DEFAULT_CAMERA_NAME}_offset"
#: Body whose frame is the default camera's estimated (in simulation: true) frame.
ESTIMATED_CAMERA_BODY_NAME = f"{DEFAULT_CAMERA_NAME}_offset_estimated_camera"
#: Package name under which the shipped models are known (``package://drake_tracker_models``).

@dataclass
class FrameOffset:
    """A frame added to the robot model: a fixed pose relative to one of its frames."""

    #: Name of an existing frame of the model (a link, or a frame the file declares).
    parent: str = ""
    #: Position of the new frame's origin in the parent frame (m).
    xyz_m: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    #: Orientation relative to the parent: roll, pitch, yaw about the parent's fixed
    #: x, y, z axes (deg), as URDF's ``rpy``.
    rpy_deg: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])

    def transform(self) -> RigidTransform:
        """``X_parent_frame``."""
        if len(self.xyz_m) != 3 or len(self.rpy_deg) != 3:
            raise ValueError(f"FrameOffset: xyz_m and rpy_deg need 3 values each, got "
                             f"{self.xyz_m} and {self.rpy_deg}")
        if not np.all(np.isfinite(self.xyz_m + self.rpy_deg)):
            raise ValueError(f"FrameOffset: values must be finite, got {self.xyz_m}, "
                             f"{self.rpy_deg}")
        return RigidTransform(RollPitchYaw(np.radians(self.rpy_deg)), np.array(self.xyz_m))


@dataclass
class CameraMount:
    """A depth camera of a model with several: its name (its virtual joints are
    ``<name>_offset_x`` ...) and the name of its nominal frame (a frame of the model or
    one of ``RobotConfig.added_frames``; Drake's camera convention, as
    ``RobotConfig.camera_frame``)."""

    name: str = DEFAULT_CAMERA_NAME
    frame: str = "camera_optical"


@dataclass
class RobotConfig:
    """Which robot to load and which of its frames matter to the tracker.

    Loadable from YAML with ``pydrake.common.yaml.yaml_load_typed`` (or
    :func:`load_robot_config`).
    """

    #: URDF, SDF or Drake model directives (``.dmd.yaml``) file: a path, a
    #: ``package://`` URI, or the name of a model under ``models/``.
    model_file: str = "apollo.sdf"
    #: Name of the depth camera's frame (Drake camera convention: +z along the optical
    #: axis, +x right, +y down): a frame of the model or one of ``added_frames``. Its
    #: pose is the *nominal* one.
    camera_frame: str = "camera_optical"
    #: Name of the end-effector frame whose pose in the camera frame is the output.
    end_effector_frame: str = "end_effector"
    #: Frames to add to the model by name, so that the vendor's file is never edited.
    added_frames: dict[str, FrameOffset] = field(default_factory=dict)
    #: ``package://NAME`` -> folder, for packages the model refers to.
    package_paths: dict[str, str] = field(default_factory=dict)
    #: Folders searched (recursively) for ``package.xml`` files. The package that holds
    #: ``model_file`` is found without this.
    package_folders: list[str] = field(default_factory=list)
    #: The robot's model instance when the file adds several with joints (directives).
    model_instance: str = ""
    #: Where converted STL/DAE meshes go; empty: ``mesh_cache.default_cache_dir()``.
    mesh_cache_dir: str = ""
    #: Several depth cameras, each with its own six virtual joints (its own mounting
    #: error). Empty: one camera, named ``camera``, at ``camera_frame``. The first is the
    #: camera of the output (the hand's pose is in its estimated frame).
    cameras: list[CameraMount] = field(default_factory=list)

    def camera_mounts(self) -> list[CameraMount]:
        """The cameras (``cameras``, or the one at ``camera_frame``); ValueError for an
        empty or repeated name."""
        mounts = list(self.cameras) or [CameraMount(DEFAULT_CAMERA_NAME, self.camera_frame)]
        seen = set()
        for mount in mounts:
            if not mount.name or not mount.name.replace("_", "").isalnum():
                raise ValueError(f"RobotConfig.cameras: camera name '{mount.name}' must be "
                                 "a non-empty word (letters, digits, _)")
            if mount.name in seen:
                raise ValueError(f"RobotConfig.cameras: two cameras are named "
                                 f"'{mount.name}'; every camera needs its own name")
            seen.add(mount.name)
        return mounts


def load_robot_config(yaml_text: str) -> RobotConfig:
    """A RobotConfig from YAML text; unknown fields are an error naming them."""
    from pydrake.common.yaml import yaml_load_typed

    return yaml_load_typed(schema=RobotConfig, data=yaml_text)


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
