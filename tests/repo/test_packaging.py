"""The wheel ships every package: checked on the source tree and pyproject.toml, without
building (``.ci/run`` builds and installs the wheel)."""

from __future__ import annotations

import tomllib
import warnings
from pathlib import Path

import pytest
import setuptools
from repo_root import ROOT

PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
SETUPTOOLS = PYPROJECT["tool"]["setuptools"]


def _package_folders() -> dict[str, Path]:
    """Package name -> folder, for every folder below each package-dir root (the package
    itself included) with .py files in it or below it, mapped through package-dir
    (``models/`` -> ``drake_tracker.models``)."""
    found = {}
    for package, folder in SETUPTOOLS["package-dir"].items():
        base = ROOT / folder
        for path in [base, *sorted(p for p in base.rglob("*") if p.is_dir())]:
            relative = path.relative_to(base)
            if "__pycache__" in relative.parts or not any(
                    "__pycache__" not in f.parts for f in path.rglob("*.py")):
                continue
            found[".".join((package, *relative.parts))] = path
    return found


def _disk_packages() -> set[str]:
    return set(_package_folders())


def test_package_dir_covers_the_package_and_the_models():
    assert SETUPTOOLS["package-dir"] == {"drake_tracker": "drake_tracker",
                                         "drake_tracker.models": "models"}
    # A folder of drake_tracker that is not below a package-dir root would not ship.
    assert (ROOT / "drake_tracker" / "__init__.py").is_file()
    assert "drake_tracker.core.filter" in _disk_packages()


def test_every_folder_with_python_files_has_an_init():
    missing = sorted(str(path.relative_to(ROOT)) for path in _package_folders().values()
                     if not (path / "__init__.py").is_file())
    assert not missing, f"folders with .py files but no __init__.py: {missing}"


def _discovered_by_config() -> set[str]:
    """The packages the pyproject configuration ships, by setuptools' public discovery
    API: an explicit ``packages`` list as given; else (automatic discovery with
    package-dir, setuptools' "explicit layout") each package-dir entry and every folder
    below it (``find_namespace_packages``)."""
    packages = SETUPTOOLS.get("packages")
    if isinstance(packages, list):
        return set(packages)
    assert packages is None, "packages.find is not set up for the models/ mapping"
    found = set()
    for package, folder in SETUPTOOLS["package-dir"].items():
        found.add(package)
        found.update(f"{package}.{name}"
                     for name in setuptools.find_namespace_packages(str(ROOT / folder)))
    return found


def test_configured_discovery_finds_every_package():
    missing = sorted(_disk_packages() - _discovered_by_config())
    assert not missing, f"packages on disk that the wheel would not ship: {missing}"


def test_setuptools_resolves_every_package(monkeypatch):
    """The same, by setuptools' own reading of pyproject.toml (what the build runs)."""
    major = int(setuptools.__version__.split(".")[0])
    if major < 77:
        pytest.skip(f"setuptools {setuptools.__version__} < 77 cannot read this pyproject "
                    "(pip install 'setuptools>=77', in the test extra)")
    from setuptools.dist import Distribution

    monkeypatch.chdir(ROOT)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dist = Distribution()
        dist.parse_config_files()
        dist.set_defaults()
    shipped = set(dist.packages)
    missing = sorted(_disk_packages() - shipped)
    assert not missing, f"packages on disk that the wheel would not ship: {missing}"
    assert dist.package_dir.get("drake_tracker.models") == "models"


def test_model_files_are_package_data():
    """Every non-Python file of models/ matches a package-data pattern (globbed in the
    folder of drake_tracker.models, as setuptools does)."""
    patterns = SETUPTOOLS["package-data"]["drake_tracker.models"]
    models = ROOT / SETUPTOOLS["package-dir"]["drake_tracker.models"]
    files = {p for p in models.rglob("*")
             if p.is_file() and p.suffix not in (".py", ".pyc") and "__pycache__" not in p.parts}
    assert files
    shipped = {p for pattern in patterns for p in models.glob(pattern)}
    unmatched = sorted(str(p.relative_to(ROOT)) for p in files - shipped)
    assert not unmatched, f"model files that would not ship: {unmatched}"


def test_py_typed_and_license_ship():
    assert (ROOT / "drake_tracker" / "py.typed").is_file()
    assert "py.typed" in SETUPTOOLS["package-data"]["drake_tracker"]
    license_text = (ROOT / "LICENSE").read_text()
    assert "BSD 3-Clause" in license_text and "The drake_tracker developers" in license_text
    assert PYPROJECT["project"]["license"] == "BSD-3-Clause"
    assert "LICENSE" in PYPROJECT["project"]["license-files"]
