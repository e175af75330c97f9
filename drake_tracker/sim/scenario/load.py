"""Simulation scenarios: load one by preset name or from a YAML file.

A :class:`Scenario` (``drake_tracker.sim.scenario.config``) is a tree of dataclasses loaded with
``pydrake.common.yaml.yaml_load_typed`` and checked by ``validate_scenario``
(``drake_tracker.sim.scenario.checks``); the named presets are in
``drake_tracker.sim.scenario.presets``
and the robot profiles in ``drake_tracker.sim.scenario.profiles``. This module gathers the
public names, so ``from drake_tracker.sim.scenario.load import Scenario, load_scenario``
keeps working.

A YAML file may start from a preset with ``preset: NAME`` and override any field. The
legacy single ``occluder:`` keeps working (the world converts it to the list form of
``occluders:``).
"""

from pathlib import Path

from drake_tracker.sim.scenario.checks import validate_scenario
from drake_tracker.sim.scenario.config import (
    BIAS_KINDS,
    BIAS_PROFILE_KINDS,
    CAMERA_CLOCKS,
    MODES,
    OCCLUDER_MOTIONS,
    OCCLUDER_SHAPES,
    TRAJECTORY_KINDS,
    BiasProfile,
    CameraConfig,
    EncoderConfig,
    ModelMismatchConfig,
    OccluderConfig,
    OccluderSpec,
    Scenario,
    TrajectoryConfig,
    occlusion_windows,
    scenario_occluders,
)
from drake_tracker.sim.scenario.presets import (
    ALL_SEQUENCES,
    BIAS_VARIANTS,
    EXTRA_SEQUENCES,
    MISMATCH_SUFFIX,
    SEQUENCES,
    list_presets,
    preset_scenario,
)
from drake_tracker.sim.scenario.profiles import ROBOT_PROFILES, RobotProfile, robot_profile

__all__ = [
    "ALL_SEQUENCES", "BIAS_KINDS", "BIAS_PROFILE_KINDS", "BIAS_VARIANTS", "CAMERA_CLOCKS",
    "EXTRA_SEQUENCES", "MISMATCH_SUFFIX", "MODES", "OCCLUDER_MOTIONS", "OCCLUDER_SHAPES",
    "ROBOT_PROFILES", "SEQUENCES",
    "TRAJECTORY_KINDS", "BiasProfile", "CameraConfig", "EncoderConfig",
    "ModelMismatchConfig", "OccluderConfig", "OccluderSpec", "RobotProfile", "Scenario",
    "TrajectoryConfig", "list_presets", "load_scenario", "mirror_first_camera", "occlusion_windows",
    "preset_scenario", "robot_profile", "scenario_occluders", "validate_scenario",
]


def mirror_first_camera(scenario: Scenario) -> None:
    """With ``cameras``, sets ``camera`` (what the one-camera code reads) to the first."""
    if scenario.cameras:
        scenario.camera = scenario.cameras[0].sensor()


def load_scenario(name_or_path: str | Path, validate: bool = True) -> Scenario:
    """A preset by name, or a YAML file (which may start from ``preset: NAME``)."""
    from pydrake.common.yaml import yaml_load, yaml_load_typed

    text = str(name_or_path)
    path = Path(text).expanduser()
    if path.suffix in (".yaml", ".yml") or path.is_file():
        if not path.is_file():
            raise FileNotFoundError(f"scenario file '{path}' does not exist")
        try:
            raw = yaml_load(filename=str(path)) or {}
        except Exception as err:  # YAML syntax (yaml.YAMLError)
            raise ValueError(f"{path}: not a readable YAML file: {err}") from err
        if not isinstance(raw, dict):
            raise ValueError(f"{path}: a scenario YAML must be a mapping")
        if raw.get("preset") is not None and not isinstance(raw["preset"], str):
            raise ValueError(f"{path}: preset: {raw['preset']!r} (expected a preset name, "
                             f"e.g. 's-full-arm/constant')")
        base = None
        try:
            base = preset_scenario(raw["preset"]) if raw.get("preset") else Scenario()
            # An empty file is the defaults (or its preset).
            scenario = yaml_load_typed(filename=str(path), defaults=base) if raw else base
        except (RuntimeError, AssertionError, TypeError, ValueError) as err:
            from drake_tracker.params.yaml_fields import mismatched_field

            raise ValueError(f"{path}: {mismatched_field(raw, base) or err}") from err
        if scenario.name == "custom" and not raw.get("name"):
            scenario.name = path.stem
        mirror_first_camera(scenario)
        if validate:
            try:
                validate_scenario(scenario)
            except ValueError as err:
                raise ValueError(f"{path}: {err}") from err
        return scenario
    scenario = preset_scenario(text)
    if validate:
        validate_scenario(scenario)
    return scenario
