"""The documentation site (``docs/``): the parameter reference is the dataclasses', the
site builds with no warning, and every public name is in its API reference.

The build test needs the ``docs`` extra (Sphinx, myst-parser); CI installs it."""

import dataclasses
import importlib
import inspect
import pkgutil
import sys
import warnings
from pathlib import Path

import pytest
from repo_root import ROOT

import drake_tracker
from drake_tracker.params.reference import field_comments, parameter_rows, unit_of
from drake_tracker.params.tracker_params import TrackerParams

DOCS = ROOT / "docs"
sys.path.insert(0, str(DOCS / "_ext"))
from param_reference import parameters_markdown  # noqa: E402

#: The subpackages whose every module the API reference documents.
API_PACKAGES = ("drake_tracker.systems", "drake_tracker.io", "drake_tracker.robot",
                "drake_tracker.params", "drake_tracker.sim.scenario")


def leaf_fields(params: object, prefix: str = "") -> dict[str, object]:
    """YAML path -> default of every non-dataclass field, walked independently of the
    reference's own walk."""
    out = {}
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if dataclasses.is_dataclass(value):
            out |= leaf_fields(value, f"{prefix}{f.name}.")
        else:
            out[prefix + f.name] = value
    return out


def test_every_parameter_is_in_the_reference_with_its_default_and_a_meaning():
    fields = leaf_fields(TrackerParams())
    rows = {row.path: row for row in parameter_rows()}
    assert set(rows) == set(fields)
    # the nested dataclasses were walked, three levels deep included
    assert {"health.min_robot_pixels", "kalman.robot_joints.bias_jump_std_rad",
            "image.likelihood.tail_weight"} <= set(rows)
    for path, row in rows.items():
        assert row.meaning, f"{path} has no #: comment"
        value = fields[path]
        if isinstance(value, float):
            assert float(row.default) == value, path
    # group defaults of their own are shown, not the class's
    assert rows["kalman.prismatic_joints.encoder_noise_std_rad"].default == "2e-05"
    assert rows["kalman.robot_joints.encoder_noise_std_rad"].default == "0.0002"
    assert rows["kalman.virtual_joints.bias_decay_per_s"].default == "1.0"
    assert rows["image.annealing_betas"].default == "[0.003, 0.03, 0.3, 1.0]"


def test_the_page_has_a_row_per_field_in_a_section_per_dataclass():
    page = parameters_markdown()
    for row in parameter_rows():
        section, _, name = row.path.rpartition(".")
        heading = f"## `{section}` (" if section else "## top level ("
        start = page.index(heading)
        end = page.find("\n## ", start + 1)
        section_text = page[start:end if end > 0 else None]
        line = next(s for s in section_text.splitlines() if s.startswith(f"| `{name}` | "))
        assert f"| `{row.default}` |" in line, row.path


def test_units_come_from_the_name_and_comments_from_the_source():
    assert unit_of("buffer_horizon_s") == "s"
    assert unit_of("bias_process_std_rad_per_sqrt_s") == "rad/√s"
    assert unit_of("depth_noise_factor_per_m") == "1/m"
    assert unit_of("num_particles") == ""
    rows = {row.path: row for row in parameter_rows()}
    assert rows["kalman.prismatic_joints.initial_bias_std_rad"].unit == "m"
    assert rows["image.likelihood.max_depth_m"].unit == "m"
    comments = field_comments(type(TrackerParams().timestamps))
    # a field right below another without a comment of its own shares that one
    assert comments["min_future_jump_s"] == comments["max_future_jump_periods"]
    assert "re-anchored" in comments["reanchor_after_samples"]


def public_definitions(module_name: str) -> list[str]:
    """Classes and functions defined in ``module_name`` whose names are public."""
    module = importlib.import_module(module_name)
    return sorted(name for name, obj in vars(module).items()
                  if not name.startswith("_") and (inspect.isclass(obj) or inspect.isfunction(obj))
                  and getattr(obj, "__module__", None) == module_name)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> tuple[Path, dict]:
    """The site, built with -W (warnings are errors), and its object inventory."""
    pytest.importorskip("sphinx", reason="the docs extra builds the site")
    pytest.importorskip("myst_parser", reason="the docs extra builds the site")
    from sphinx.cmd.build import build_main
    from sphinx.util.inventory import InventoryFile

    out = tmp_path_factory.mktemp("site")
    with warnings.catch_warnings():  # Sphinx's deprecation notices about its extensions
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        status = build_main(["-W", "-q", "-b", "html", str(DOCS), str(out)])
    assert status == 0, "the site does not build without warnings"
    with (out / "objects.inv").open("rb") as f:
        inventory = InventoryFile.load(f, "", lambda base, uri: uri)
    names = {name for entries in inventory.data.values() for name in entries} if hasattr(
        inventory, "data") else {name for entries in inventory.values() for name in entries}
    return out, names


def test_every_public_name_is_in_the_api_reference(site):
    _, names = site
    missing = [f"drake_tracker.{n}" for n in drake_tracker.__all__
               if f"drake_tracker.{n}" not in names]
    modules = 0
    for package_name in API_PACKAGES:
        package = importlib.import_module(package_name)
        for info in pkgutil.iter_modules(package.__path__):
            if info.name.startswith("_") or info.ispkg:
                continue
            modules += 1
            module_name = f"{package_name}.{info.name}"
            assert module_name in names, module_name
            for name in public_definitions(module_name):
                exported = getattr(drake_tracker, name, None) is getattr(
                    importlib.import_module(module_name), name)
                if f"{module_name}.{name}" not in names and not (
                        exported and f"drake_tracker.{name}" in names):
                    missing.append(f"{module_name}.{name}")
    assert modules > 30
    assert not missing, f"not in the API reference: {missing}"


def test_pydrake_types_link_to_pydrakes_documentation(site):
    out, _ = site
    page = (out / "reference" / "api" / "drake_tracker.html").read_text()
    assert ("https://drake.mit.edu/pydrake/pydrake.systems.framework.html"
            "#pydrake.systems.framework.DiagramBuilder") in page
    assert "pydrake.systems.framework.OutputPort" in page


def test_the_parameter_page_is_built_from_the_dataclasses(site):
    out, _ = site
    page = (out / "reference" / "parameters.html").read_text()
    for row in parameter_rows():
        name = row.path.rpartition(".")[2]
        assert f'<span class="pre">{name}</span>' in page, row.path
