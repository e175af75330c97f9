"""The parameter reference, read from the dataclasses themselves: every field of
:class:`~drake_tracker.params.tracker_params.TrackerParams` and of the dataclasses it
nests, with its YAML path, unit, default and meaning.

The meaning is the ``#:`` comment above the field (the convention autodoc reads too); a
field written directly below another without a comment of its own shares that one
(``near_m`` / ``far_m``). The unit comes from the name's suffix (``_s``, ``_m``,
``_rad``, ``_px``, ...), as ``tracker_params.py`` states; the defaults are those of a
default-constructed ``TrackerParams``, so a group's own defaults (the prismatic and the
virtual joints' noise) are shown where they differ from the class's. The site's
parameter page is generated from :func:`parameter_rows` at build time
(``docs/_ext/param_reference.py``).
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import math
import re
import textwrap
import typing
from dataclasses import dataclass
from functools import cache

from drake_tracker.params.tracker_params import TrackerParams

#: Name suffix -> unit, longest first (the first that matches wins).
UNIT_SUFFIXES: tuple[tuple[str, str], ...] = (
    ("_rad_per_sqrt_s", "rad/√s"),
    ("_nats_per_pixel", "nats/pixel"),
    ("_per_sqrt_s", "1/√s"),
    ("_per_s", "1/s"),
    ("_per_m", "1/m"),
    ("_rad", "rad"),
    ("_deg", "deg"),
    ("_px", "px"),
    ("_m", "m"),
    ("_s", "s"),
    ("_pixels", "pixels"),
    ("_images", "images"),
    ("_samples", "samples"),
    ("_periods", "sample periods"),
)



def group_unit(group: str, unit: str) -> str:
    """A unit in radians as it reads in ``group``: ``tracker_params.py`` states that the
    ``_rad`` fields are metres for the robot's prismatic joints and for the virtual
    camera joints' x, y, z."""
    if not unit.startswith("rad"):
        return unit
    if group == "kalman.prismatic_joints":
        return "m" + unit[3:]
    if group == "kalman.virtual_joints":
        return f"{unit} (x, y, z: m{unit[3:]})"
    return unit


@dataclass(frozen=True)
class ParamRow:
    """One field of the parameters."""

    #: The field's YAML path, e.g. ``image.likelihood.max_depth_m``.
    path: str
    #: The dataclass that declares it, e.g. ``LikelihoodParams``.
    owner: str
    #: The field's type as written in the dataclass.
    type: str
    #: The unit its name states ("" for a count, a flag or a ratio).
    unit: str
    #: Its default in ``TrackerParams()``, as YAML would write it.
    default: str
    #: The ``#:`` comment that documents it.
    meaning: str


def unit_of(name: str) -> str:
    """The unit that a field name's suffix states, or "" when it states none."""
    for suffix, unit in UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    return ""


@cache
def field_comments(cls: type) -> dict[str, str]:
    """Field name -> the ``#:`` comment lines above it in ``cls``'s source, joined; a
    field directly below another, without a comment of its own, shares that one."""
    source_lines, _ = inspect.getsourcelines(cls)
    tree = ast.parse(textwrap.dedent("".join(source_lines)))
    node = next(n for n in tree.body if isinstance(n, ast.ClassDef))
    lines = [line.strip() for line in source_lines]
    comments: dict[str, str] = {}
    previous_name, previous_end = None, -10
    for item in node.body:
        if not (isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name)):
            continue
        name, row = item.target.id, item.lineno - 1
        block = []
        k = row - 1
        while k >= 0 and lines[k].startswith("#:"):
            block.insert(0, lines[k][2:].strip())
            k -= 1
        if block:
            comments[name] = " ".join(block)
        elif previous_name in comments and row == previous_end + 1:
            comments[name] = comments[previous_name]
        previous_name, previous_end = name, (item.end_lineno or item.lineno) - 1
    return comments


def format_default(value: object) -> str:
    """A default as YAML writes it: ``true``, ``0.02``, ``[0.003, 0.03]``, ``{}``."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return ".inf" if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return value if value else '""'
    if isinstance(value, list):
        return "[" + ", ".join(format_default(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {format_default(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _type_name(annotation: object) -> str:
    """``float``, ``list[int]``, ``dict[str, JointNoise]``: without module prefixes."""
    if isinstance(annotation, type) and typing.get_origin(annotation) is None:
        return annotation.__name__
    return re.sub(r"\b[\w.]+\.(\w+)", r"\1", str(annotation))


def parameter_rows(params: TrackerParams | None = None, prefix: str = "") -> list[ParamRow]:
    """Every leaf field of ``params`` (default: ``TrackerParams()``), depth first in
    declaration order; a nested dataclass contributes its fields, not a row of its own."""
    params = TrackerParams() if params is None else params
    owner = type(params)
    comments = field_comments(owner)
    rows: list[ParamRow] = []
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        path = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            rows += parameter_rows(value, prefix=f"{path}.")
            continue
        unit = group_unit(prefix.rstrip("."), unit_of(f.name))
        rows.append(ParamRow(path=path, owner=owner.__name__, type=_type_name(f.type),
                             unit=unit, default=format_default(value),
                             meaning=comments.get(f.name, "")))
    return rows


def nested_groups(params: TrackerParams | None = None, prefix: str = ""
                  ) -> list[tuple[str, str, str]]:
    """(YAML path, dataclass name, its docstring's first paragraph) of ``params`` and of
    every dataclass nested in it, depth first; the root's path is ""."""
    params = TrackerParams() if params is None else params
    doc = inspect.getdoc(type(params)) or ""
    groups = [(prefix.rstrip("."), type(params).__name__, doc.split("\n\n")[0])]
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            groups += nested_groups(value, prefix=f"{prefix}{f.name}.")
    return groups
