"""The closed-loop servo study's parameters: a YAML tree of dataclasses.

Loaded with ``pydrake.common.yaml.yaml_load_typed`` (:func:`load_servo_config`) and
checked at load (:func:`validate_servo_config`); every error names the field. Units are
in the field names. A sample: ``drake-tracker servo --print-config``.

The targets are poses of the end effector in the camera frame (x right, y down, z
forward, as Drake's cameras), as an object detector on that camera would report a grasp
pose: the hand must reach each one and stay ``dwell_s``.
"""

from dataclasses import dataclass, field

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw

from drake_tracker.sim.scenario.validation import (
    require,
    require_length,
    require_non_negative,
    require_positive,
)

#: What feeds the controller's pose feedback, and the study's labels for them.
FEEDBACKS = ("encoders", "tracker", "truth")
FEEDBACK_LABELS = {"encoders": "(a) encoders + nominal camera",
                   "tracker": "(b) drake_tracker X_CE",
                   "truth": "(c) ground truth"}


@dataclass
class ServoTarget:
    """One target pose of the end effector E in the camera frame C, and the stop there."""

    #: p_CE (m) and the roll-pitch-yaw of R_CE (deg).
    xyz_m: list[float] = field(default_factory=lambda: [-0.10, -0.15, 1.10])
    rpy_deg: list[float] = field(default_factory=lambda: [-20.0, -32.0, 90.0])
    #: How long the controller servos to this target before the next one (s).
    dwell_s: float = 4.0

    def X_CT(self) -> RigidTransform:
        """The target as a RigidTransform in the camera frame."""
        return RigidTransform(RollPitchYaw(np.radians(self.rpy_deg)), np.array(self.xyz_m))


def _default_targets() -> list[ServoTarget]:
    # Around Apollo's home pose (hand at [-0.095, -0.148, 1.109] m, rpy [-20, -32, 90]
    # deg in the camera frame): 5-8 cm and 10-15 deg away, all in the camera's view.
    return [
        ServoTarget([-0.03, -0.12, 1.06], [-10.0, -30.0, 90.0]),
        ServoTarget([-0.16, -0.08, 1.04], [-25.0, -22.0, 100.0]),
        ServoTarget([-0.06, -0.02, 1.12], [-30.0, -38.0, 82.0]),
        ServoTarget([-0.13, -0.17, 1.00], [-15.0, -40.0, 95.0]),
    ]


@dataclass
class ServoGains:
    """The Cartesian law and its differential IK (see ``drake_tracker.servo.controller``)."""

    #: Desired hand velocity = gain x pose error (1/s), translation and rotation.
    translation_gain_per_s: float = 2.0
    rotation_gain_per_s: float = 2.0
    #: Caps on the commanded hand speed (m/s, deg/s).
    max_speed_m_per_s: float = 0.15
    max_angular_speed_deg_per_s: float = 30.0
    #: Joint speed limit the differential IK respects (deg/s).
    max_joint_speed_deg_per_s: float = 60.0
    #: Pull of the redundant (null-space) motion towards the start pose (1/s).
    joint_centering_gain_per_s: float = 0.5
    #: The controller's update period (s).
    control_period_s: float = 0.01
    #: Natural frequency of the robot's joint servo (InverseDynamicsController) (rad/s).
    joint_servo_frequency_rad_per_s: float = 40.0


@dataclass
class ServoStudyConfig:
    """One closed-loop study: the world, the targets, the controller, the tracker."""

    #: The simulated world: a scenario preset or YAML (``drake-tracker scenarios``). Its
    #: robot, encoders (bias), camera (mounting error), seed and plant step are used; its
    #: trajectory only gives the home pose (the controller moves the arm) and the plant
    #: is always simulated (dynamic).
    scenario: str = "static/constant"
    #: The robot holds its home pose this long before servoing to the first target (s):
    #: the tracker acquires the arm meanwhile.
    hold_s: float = 1.0
    targets: list[ServoTarget] = field(default_factory=_default_targets)
    gains: ServoGains = field(default_factory=ServoGains)
    #: Tracker parameters YAML for run (b) (empty: the defaults).
    tracker_params: str = ""
    #: The true hand error is sampled this often for the report (s).
    sample_period_s: float = 0.01
    #: "Settled" means the hand's true position error stays below this (m).
    settle_threshold_m: float = 0.005

    @property
    def duration_s(self) -> float:
        """Hold plus every target's dwell (s)."""
        return self.hold_s + sum(t.dwell_s for t in self.targets)

    def target_windows(self) -> list[tuple[float, float]]:
        """``(start, end)`` of each target's dwell (s)."""
        windows, start = [], self.hold_s
        for target in self.targets:
            windows.append((start, start + target.dwell_s))
            start += target.dwell_s
        return windows

    def target_index(self, time_s: float) -> int:
        """The target being servoed to at ``time_s``; -1 during the hold."""
        for k, (_, end) in enumerate(self.target_windows()):
            if time_s >= self.hold_s and time_s < end:
                return k
        return -1 if time_s < self.hold_s else len(self.targets) - 1


def validate_servo_config(config: ServoStudyConfig) -> None:
    """Raises ValueError naming the first bad field of ``config``."""
    require(bool(config.scenario), "scenario", config.scenario, "must name a scenario")
    require_non_negative(config.hold_s, "hold_s")
    require(len(config.targets) >= 1, "targets", config.targets, "must list >= 1 target")
    for k, target in enumerate(config.targets):
        require_length(target.xyz_m, 3, f"targets[{k}].xyz_m")
        require_length(target.rpy_deg, 3, f"targets[{k}].rpy_deg")
        require(target.xyz_m[2] > 0, f"targets[{k}].xyz_m", target.xyz_m,
                "z must be > 0 (in front of the camera)")
        require_positive(target.dwell_s, f"targets[{k}].dwell_s")
    g = config.gains
    for name in ("translation_gain_per_s", "rotation_gain_per_s", "max_speed_m_per_s",
                 "max_angular_speed_deg_per_s", "max_joint_speed_deg_per_s",
                 "control_period_s", "joint_servo_frequency_rad_per_s"):
        require_positive(getattr(g, name), f"gains.{name}")
    require_non_negative(g.joint_centering_gain_per_s, "gains.joint_centering_gain_per_s")
    require_positive(config.sample_period_s, "sample_period_s")
    require_positive(config.settle_threshold_m, "settle_threshold_m")


def load_servo_config(path: str | None = None) -> ServoStudyConfig:
    """The defaults, or the YAML file ``path`` over them; checked."""
    from pydrake.common.yaml import yaml_load_typed

    config = ServoStudyConfig()
    if path:
        try:
            config = yaml_load_typed(filename=str(path), defaults=config)
        except RuntimeError as err:
            raise ValueError(f"{path}: {err}") from err
    validate_servo_config(config)
    return config


def servo_config_to_yaml(config: ServoStudyConfig) -> str:
    """``config`` as YAML that :func:`load_servo_config` reads back."""
    from pydrake.common.yaml import yaml_dump_typed

    return yaml_dump_typed(config)
