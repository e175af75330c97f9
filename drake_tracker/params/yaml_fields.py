"""Which field of a YAML file does not fit its dataclass schema.

``pydrake.common.yaml.yaml_load_typed`` names the field for most type errors, but not
for a scalar where a list is expected (``annealing_betas: 0.5`` gives "'float' object
is not iterable") nor for a string where a float is expected (``duration_s: long``
gives "could not convert string to float"). :func:`mismatched_field` walks the raw
YAML against the defaults to name it. :func:`retired_field` names a field that an
earlier version had and what replaced it.
"""

from __future__ import annotations

import dataclasses
from typing import Any

#: Fields of earlier versions (YAML path) and what became of them.
RETIRED_FIELDS = {
    "health.lost_after_images": "replaced by health.images_in_a_row (one count for "
                                "both ways)",
    "health.recovered_after_images": "replaced by health.images_in_a_row (one count for "
                                     "both ways)",
    "health.reacquire_after_s": "replaced by health.max_unconfirmed_s (one duration for "
                                "holding the arm and for restarting a misplaced estimate)",
    "health.restart_after_misplaced_s": "replaced by health.max_unconfirmed_s (one "
                                        "duration for holding the arm and for restarting "
                                        "a misplaced estimate)",
    "image.estimate_occlusion": "removed: the occlusion probability is always estimated "
                                "(image.occlusion_prior_pixels)",
    "image.bias_jumps_in_camera_chain": "removed: the joints that move a camera never "
                                        "have bias jumps",
    "health.challenger_bias_sigmas": "removed: a bias is implausible where the bias "
                                     "model's own test rejects it, at the innovation "
                                     "test's false-alarm probability (2.81 of its "
                                     "spread)",
    "health.challenger_images": "removed: a challenger searches for "
                                "health.max_unconfirmed_s, then rests as long",
    "health.second_opinion_agreement": "removed: an image is surprising when more of "
                                       "the estimate's unhidden arm disagrees with it "
                                       "than agrees (the same rule as 0.5)",
    "health.misplaced_fraction": "removed: an estimate is misplaced when it renders "
                                 "fewer robot pixels than half the encoders' arm (the "
                                 "same rule as 0.5)",
    "health.no_arm_see_through": "removed: an image shows no arm when it sees behind "
                                 "all but fewer than health.min_robot_pixels of both the "
                                 "estimate's and the encoders' rendered arm",
}

#: Fields of a joint group's noise model (``JointNoise``) of earlier versions.
RETIRED_JOINT_NOISE_FIELDS = {
    "match_bias_noise_to_images": "removed: the images' innovations no longer set the "
                                  "bias random walk's rate (it made occlusions worse); a "
                                  "drifting bias is followed by the kept search",
}


def retired_field(raw: Any) -> str | None:
    """``"path: why"`` for the first field of ``raw`` (the YAML mapping of a
    ``TrackerParams``) that :data:`RETIRED_FIELDS` lists, or None."""
    if not isinstance(raw, dict):
        return None
    for path, why in RETIRED_FIELDS.items():
        group, name = path.split(".")
        if isinstance(raw.get(group), dict) and name in raw[group]:
            return f"{path}: {why}"
    kalman = raw.get("kalman")
    if isinstance(kalman, dict):  # a joint group's field, or an override's
        overrides = kalman.get("overrides")
        groups = {f"kalman.{k}": v for k, v in kalman.items() if k != "overrides"}
        if isinstance(overrides, dict):
            groups.update({f"kalman.overrides.{k}": v for k, v in overrides.items()})
        for where, fields in groups.items():
            for name, why in RETIRED_JOINT_NOISE_FIELDS.items():
                if isinstance(fields, dict) and name in fields:
                    return f"{where}.{name}: {why}"
    return None


def _mismatch(value: Any, default: Any) -> str | None:
    """Why ``value`` (raw YAML) cannot replace ``default``, or None when it may."""
    if isinstance(default, bool):
        return None if isinstance(value, bool) else "expected true or false"
    if isinstance(default, (int, float)):
        numeric = isinstance(value, (int, float)) and not isinstance(value, bool)
        return None if numeric else "expected a number"
    if isinstance(default, str):
        return None if isinstance(value, str) else "expected a string"
    if isinstance(default, (list, tuple)):
        return None if isinstance(value, list) else "expected a list"
    if isinstance(default, dict) or dataclasses.is_dataclass(default):
        return None if isinstance(value, dict) else "expected a mapping"
    return None


def mismatched_field(raw: Any, defaults: Any, prefix: str = "") -> str | None:
    """``"field.path: value (why)"`` for the first field of ``raw`` (a YAML mapping) whose
    value does not fit the matching field of ``defaults`` (a dataclass instance), or
    None when none is found (unknown fields are left to ``yaml_load_typed``)."""
    if not isinstance(raw, dict) or not dataclasses.is_dataclass(defaults):
        return None
    for key, value in raw.items():
        if not hasattr(defaults, str(key)):
            continue
        default = getattr(defaults, str(key))
        where = f"{prefix}{key}"
        why = _mismatch(value, default)
        if why is not None:
            return f"{where}: {value!r} ({why})"
        if dataclasses.is_dataclass(default):
            found = mismatched_field(value, default, f"{where}.")
            if found:
                return found
    return None
