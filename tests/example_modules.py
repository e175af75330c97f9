"""Loads a script of ``examples/`` as a module, for the tests that call its functions."""

import importlib.util
from types import ModuleType

from repo_root import ROOT

EXAMPLES = ROOT / "examples"


def load_example(file_name: str) -> ModuleType:
    """``examples/<file_name>`` imported under its stem, without running its main."""
    path = EXAMPLES / file_name
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
