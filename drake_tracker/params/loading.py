"""Tracker parameters from and to YAML (Drake's ``yaml_load_typed`` / ``yaml_dump_typed``)."""

from pathlib import Path

from pydrake.common.yaml import yaml_dump_typed, yaml_load, yaml_load_typed

from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.params.validation import validate_tracker_params
from drake_tracker.params.yaml_fields import mismatched_field, retired_field


def load_tracker_params(path: str | Path | None = None) -> TrackerParams:
    """Defaults, overridden by a YAML file when ``path`` is given, checked field by field
    (an error names the file and the field); the joint names in it are checked against a
    model when it is resolved (``resolve_tracker_params``)."""
    params = TrackerParams()
    if path is None:
        return params
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"tracker parameter file '{path}' does not exist")
    raw = None
    try:
        raw = yaml_load(filename=str(path))
        retired = retired_field(raw)
        if retired:
            raise ValueError(retired)
        if raw is not None:  # an empty file: all defaults
            params = yaml_load_typed(filename=str(path), defaults=params)
    except Exception as err:  # YAML syntax (yaml.YAMLError) or a field of the wrong type
        raise ValueError(f"{path}: cannot read tracker parameters: "
                         f"{mismatched_field(raw, params) or err}") from err
    try:
        validate_tracker_params(params)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from err
    return params


def tracker_params_to_yaml(params: TrackerParams) -> str:
    """The YAML text of ``params`` (Drake's ``yaml_dump_typed``)."""
    return yaml_dump_typed(params)
