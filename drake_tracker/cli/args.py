"""Checking the command line's arguments before any work starts.

Each function turns one argument into the object the command needs, or raises
:class:`UsageError` with one line that names the problem and what is valid.
``drake-tracker`` prints that line and exits with code 2 (``--debug`` shows the
traceback).
"""

from __future__ import annotations

import argparse
import difflib
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from drake_tracker.io.recording import RecordedRun
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.robot.model import TrackerModel
    from drake_tracker.servo.config import ServoStudyConfig
    from drake_tracker.sim.scenario.config import Scenario

#: The bias variant a bare sequence name (``--scenario s-full-arm``) stands for.
DEFAULT_BIAS_VARIANT = "constant"


SCENARIO_HELP = ("a preset SEQUENCE/BIAS, e.g. occlusion/time-varying (a bare SEQUENCE "
                 "means SEQUENCE/constant; 'drake-tracker scenarios' lists them), or a "
                 "scenario YAML file (default: %(default)s)")
PARAMS_HELP = ("tracker parameters YAML ('drake-tracker params --defaults' prints every "
               "field; examples/params.yaml is a commented sample); default: the defaults")


class UsageError(Exception):
    """A mistake in the command line: the message is one line for the user."""


def positive_seconds(text: str) -> float:
    """argparse type of a duration: a finite number of seconds > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number of seconds") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a number of seconds > 0, got {text}")
    return value


def positive_int(text: str) -> int:
    """argparse type of a count: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return value


def _is_file_name(text: str) -> bool:
    return Path(text).suffix in (".yaml", ".yml") or Path(text).expanduser().is_file()


def scenario_name(text: str) -> str:
    """The preset ``SEQUENCE/BIAS`` (or YAML path) that ``--scenario text`` stands for.

    A bare sequence name stands for ``SEQUENCE/constant`` (``DEFAULT_BIAS_VARIANT``).
    """
    from drake_tracker.sim.scenario.load import ALL_SEQUENCES as SEQUENCES
    from drake_tracker.sim.scenario.load import BIAS_VARIANTS, list_presets

    if _is_file_name(text) or text in list_presets():
        return text
    if text in SEQUENCES:
        return f"{text}/{DEFAULT_BIAS_VARIANT}"
    sequence, slash, bias = text.partition("/")
    if slash and sequence in SEQUENCES:
        raise UsageError(f"unknown bias variant '{bias}' for {sequence}; valid: "
                         f"{', '.join(BIAS_VARIANTS)}")
    close = difflib.get_close_matches(text, list(SEQUENCES) + list_presets(), n=3,
                                      cutoff=0.6)
    hint = f"did you mean {' or '.join(close)}? " if close else ""
    raise UsageError(f"unknown scenario '{text}'; {hint}give SEQUENCE/BIAS (bias: "
                     f"{', '.join(BIAS_VARIANTS)}) or a YAML file; "
                     "'drake-tracker scenarios' lists the presets")


def resolve_scenario(text: str) -> Scenario:
    """The :class:`~drake_tracker.sim.scenario.load.Scenario` of ``--scenario text``."""
    from drake_tracker.sim.scenario.load import load_scenario

    name = scenario_name(text)
    try:
        return load_scenario(name)
    except FileNotFoundError:
        raise UsageError(f"scenario file '{text}' does not exist") from None
    except (ValueError, RuntimeError, KeyError) as err:
        raise UsageError(f"scenario '{text}': {_one_line(err, named=name)}") from None


def load_params_arg(path: str | None) -> TrackerParams:
    """The :class:`~drake_tracker.params.tracker_params.TrackerParams` of ``--params path``
    (defaults
    when None); a missing or invalid file is a UsageError."""
    from drake_tracker.params.loading import load_tracker_params

    if path is not None and not Path(path).is_file():
        raise UsageError(f"parameter file '{path}' does not exist ('drake-tracker params "
                         "--defaults' prints a valid one)")
    try:
        return load_tracker_params(path)
    except (ValueError, RuntimeError, TypeError, KeyError) as err:
        raise UsageError(f"parameter file '{path}': {_one_line(err, named=path)}") from None


def check_params_for_model(params: TrackerParams, model: TrackerModel, where: str) -> None:
    """Names in ``params`` (overrides, blocks) must be joints of ``model``."""
    from drake_tracker.params.resolve import resolve_blocks, resolve_kalman_params

    try:
        resolve_kalman_params(params, list(model.joint_names),
                              model.prismatic_joint_names)
        resolve_blocks(params, list(model.joint_names))
    except ValueError as err:
        raise UsageError(f"{where}: {_one_line(err)}") from None


def load_servo_config_arg(path: str | None, scenario: str | None = None
                          ) -> ServoStudyConfig:
    """The :class:`~drake_tracker.servo.config.ServoStudyConfig` of ``--config path``
    (default: the defaults), with ``--scenario`` over its ``scenario``; checked."""
    from drake_tracker.servo.config import load_servo_config, validate_servo_config
    from drake_tracker.servo.study import servo_scenario

    if path and not Path(path).is_file():
        raise UsageError(f"servo config '{path}' does not exist ('drake-tracker servo "
                         "--print-config' prints the defaults as YAML)")
    try:
        config = load_servo_config(path)
        if scenario:
            config.scenario = scenario_name(scenario)
            validate_servo_config(config)
        resolve_scenario(config.scenario)
        servo_scenario(config)
    except ValueError as err:
        raise UsageError(f"servo config: {_one_line(err)}") from None
    return config


def load_run_arg(path: str) -> RecordedRun:
    """The :class:`~drake_tracker.io.recording.RecordedRun` of ``--run path``."""
    import zipfile

    from drake_tracker.io.recording import RecordedRun

    if not Path(path).is_file():
        raise UsageError(f"recorded run '{path}' does not exist ('drake-tracker record "
                         "--scenario NAME --out FILE.npz' writes one)")
    try:
        return RecordedRun.load(path)
    except (ValueError, KeyError, OSError, EOFError, zipfile.BadZipFile) as err:
        raise UsageError(f"'{path}' is not a recorded run (.npz from 'drake-tracker "
                         f"record'): {_one_line(err)}") from None


def check_new_file(path: str, suffix: str) -> Path:
    """An output file path with the given suffix whose folder can be created."""
    out = Path(path)
    if out.suffix != suffix:
        raise UsageError(f"output file '{path}' must end with {suffix}")
    if out.is_dir():
        raise UsageError(f"output file '{path}' is a folder")
    return out


def check_new_log(path: str, what: str, require: Callable[[], None],
                  suffix: str | None = None) -> Path:
    """A log file to write (``what``: "bag", "LCM log"): not a folder, not an existing
    file (never overwritten), with ``suffix`` if given, and its extra installed
    (``require`` raises ImportError naming it)."""
    out = check_new_file(path, suffix) if suffix else Path(path)
    if out.is_dir():
        raise UsageError(f"output file '{path}' is a folder")
    if out.exists():
        raise UsageError(f"{what} '{path}' exists: not overwritten")
    try:
        require()
    except ImportError as err:
        raise UsageError(str(err)) from None
    return out


def check_out_dir(path: str) -> Path:
    """An output folder: it may exist, but not as a file."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise UsageError(f"output folder '{path}' is an existing file")
    return out


def named_flags(primary: list[str], secondary: list[str], flags: tuple[str, str],
                value: str) -> tuple[list[tuple[str, str]], dict[str, str]] | None:
    """The cameras of a repeated ``--A [NAME=]VALUE`` (``primary``) and its companion
    ``--B [NAME=]VALUE`` (``secondary``), ``flags`` their names: None for one camera (no
    NAME, each flag at most once), else ``primary``'s (NAME, VALUE) pairs and
    ``secondary``'s values by NAME. ValueError naming what is wrong (``value``: the form
    of ``--A``'s value, for the message)."""
    a, b = flags
    named = [v for v in primary + secondary if "=" in v]
    if not named:
        if len(primary) > 1 or len(secondary) > 1:
            raise ValueError(f"several {a} or {b}: name each camera, {a} NAME={value} "
                             f"(RobotConfig.cameras)")
        return None
    if len(named) != len(primary) + len(secondary):
        raise ValueError(f"{a} and {b} are either all {value} (one camera) or all "
                         f"NAME={value} (several)")
    pairs = [(name, text) for name, text in (v.split("=", 1) for v in primary)]
    given = dict(v.split("=", 1) for v in secondary)
    unknown = sorted(set(given) - {name for name, _ in pairs})
    if unknown:
        raise ValueError(f"{b} {unknown[0]}=...: no {a} {unknown[0]}={value}")
    return pairs, given


def _one_line(err: BaseException, named: str | Path | None = None) -> str:
    """``err``'s message on one line, at most 300 characters; without the leading
    ``"<named>: "`` of a loader that names its file, when the caller names it already."""
    text = " ".join(str(err).split())
    if named is not None:
        text = text.removeprefix(f"{Path(named)}: ")
    return text if len(text) <= 300 else text[:297] + "..."
