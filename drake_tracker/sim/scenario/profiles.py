"""Robot profiles: per-model joint groups, a home pose in view, and the camera's
configuration-dependent offset, keyed by the model file's name."""

from dataclasses import dataclass, field
from pathlib import Path

from drake_tracker.robot.model import RobotConfig


@dataclass
class RobotProfile:
    """Per-model defaults the presets need: joint groups and a home pose in view."""

    upper_arm: list[str]
    lower_arm: list[str]
    head: list[str]
    home_deg: dict[str, float]
    #: Default configuration-dependent camera offset (see CameraConfig).
    offset_gain_per_rad: dict[str, list[float]] = field(default_factory=dict)

    @property
    def arm(self) -> list[str]:
        """The arm's joints, upper then lower."""
        return self.upper_arm + self.lower_arm


#: Profiles keyed by the model file's name.
ROBOT_PROFILES: dict[str, RobotProfile] = {
    "apollo.sdf": RobotProfile(
        upper_arm=["arm_joint_1", "arm_joint_2", "arm_joint_3"],
        lower_arm=["arm_joint_4", "arm_joint_5", "arm_joint_6", "arm_joint_7"],
        head=["head_pan", "head_tilt"],
        home_deg={"head_tilt": 32.0, "arm_joint_1": 20.0, "arm_joint_2": 60.0,
                  "arm_joint_4": -60.0, "arm_joint_6": -30.0},
        # Apollo's head kinematics are approximate: the error grows with the angles.
        offset_gain_per_rad={
            "head_pan": [0.0, 0.01, 0.0, 0.0, 0.02, 0.01],
            "head_tilt": [0.0, 0.0, 0.015, 0.02, 0.0, 0.0],
        },
    ),
    "arm6_on_stand.urdf": RobotProfile(
        upper_arm=["shoulder_pan", "shoulder_lift"],
        lower_arm=["elbow", "wrist_1", "wrist_2", "wrist_3"],
        head=[],
        home_deg={"shoulder_lift": 30.0, "elbow": 60.0, "wrist_1": 30.0},
    ),
}


def robot_profile(config: RobotConfig) -> "RobotProfile | None":
    """The profile of ``config``'s model, or None for a model without one."""
    return ROBOT_PROFILES.get(Path(config.model_file).name)
