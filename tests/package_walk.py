"""The package's sources, walked once for the rule tests that read them with ``ast``
(type hints, docstrings)."""

import ast
from collections.abc import Callable

from repo_root import ROOT

PACKAGE = ROOT / "drake_tracker"


def walk_package(count: Callable[[ast.Module], int],
                 offenders_in: Callable[[str, str], list[str]]) -> tuple[int, int, list[str]]:
    """Over every module of the package: (modules read, ``count`` of each parsed module
    summed, the ``offenders_in(source, label)`` lines, label the path from the repository
    root)."""
    files = sorted(PACKAGE.rglob("*.py"))
    checked = 0
    offenders = []
    for path in files:
        source = path.read_text(encoding="utf-8")
        checked += count(ast.parse(source))
        offenders += offenders_in(source, str(path.relative_to(PACKAGE.parent)))
    return len(files), checked, offenders
