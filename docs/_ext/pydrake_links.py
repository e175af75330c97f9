"""Sphinx extension and script: pydrake's types in the API reference link to pydrake's
documentation, without the network.

The build reads ``docs/_inventories/pydrake.inv`` (a Sphinx inventory, version 2, of the
pydrake names the API mentions, each pointing at https://drake.mit.edu/pydrake/) through
intersphinx. A bare name (``OutputPort``, from an annotation imported only for type
checking) links to the one pydrake name of the inventory it ends. A ``pydrake.`` name
that the inventory lacks is a warning (an error with ``-W``): regenerate the inventory
with ``python docs/_ext/pydrake_links.py``, which builds the site once, collects the
names, checks that each is importable from pydrake, and adds them to the file. The file
keeps the names it had: run under each drake the package supports (Python 3.11 gets
drake 1.51, 3.12 a newer one, whose signatures name more types, such as
``SystemScalarConverter``), it lets the site build under each.
"""

from __future__ import annotations

import ast
import importlib
import os
import subprocess
import sys
import tempfile
import zlib
from importlib import metadata
from pathlib import Path
from typing import Any

DOCS = Path(__file__).resolve().parents[1]
INVENTORY = DOCS / "_inventories" / "pydrake.inv"
PYDRAKE_URL = "https://drake.mit.edu/pydrake/"
#: When set, the build appends the pydrake names it meets to this file (the script).
COLLECT_ENV = "DRAKE_TRACKER_COLLECT_PYDRAKE"


def _inventory_names(env: Any) -> list[str]:
    named = getattr(env, "intersphinx_named_inventory", {}).get("pydrake", {})
    return sorted(named.get("py:class", {}))


def _missing_reference(app: Any, env: Any, node: Any, contnode: Any) -> Any:
    from sphinx.ext.intersphinx import missing_reference
    from sphinx.util import logging

    target = node.get("reftarget", "")
    if node.get("refdomain") != "py" or not target:
        return None
    collect = os.environ.get(COLLECT_ENV)
    if target.startswith("pydrake."):
        resolved = missing_reference(app, env, node, contnode)
        if resolved is not None:
            return resolved
        if collect:
            with open(collect, "a") as f:
                f.write(target + "\n")
        else:
            logging.getLogger(__name__).warning(
                "pydrake name %s (%s) is not in %s: run python docs/_ext/pydrake_links.py",
                target, node.get("reftype"), INVENTORY.relative_to(DOCS.parent), location=node)
        return None
    if "." in target:
        return None
    if collect:
        with open(collect, "a") as f:
            f.write(target + "\n")
    matches = [name for name in _inventory_names(env) if name.endswith("." + target)]
    if len(matches) != 1:
        return None
    full = node.deepcopy()
    full["reftarget"] = matches[0]
    return missing_reference(app, env, full, contnode)


def setup(app: Any) -> dict[str, Any]:
    """Links unresolved pydrake names through the shipped inventory."""
    app.connect("missing-reference", _missing_reference, priority=600)
    return {"parallel_read_safe": True, "parallel_write_safe": True}


def pydrake_imports(package: Path = DOCS.parent / "drake_tracker") -> dict[str, str]:
    """Name -> full pydrake name, for every ``from pydrake.X import Name`` in the package
    (type-checking imports included: those are the bare names of annotations)."""
    found: dict[str, str] = {}
    for path in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("pydrake"):
                for alias in node.names:
                    found.setdefault(alias.asname or alias.name, f"{node.module}.{alias.name}")
    return found


def pydrake_name(name: str, imports: dict[str, str]) -> str | None:
    """``name`` as an importable pydrake name: a full name as it is, a bare one as the
    package imports it (``imports``); None when it is not pydrake's."""
    full = name if name.startswith("pydrake.") else imports.get(name)
    if full is None:
        return None
    module, _, attr = full.rpartition(".")
    try:
        return full if hasattr(importlib.import_module(module), attr) else None
    except ImportError:
        return None


def inventory_bytes(names: list[str], version: str) -> bytes:
    """A Sphinx inventory (version 2) of pydrake classes at their pages on the site."""
    header = ("# Sphinx inventory version 2\n# Project: Drake\n"
              f"# Version: {version}\n"
              "# The remainder of this file is compressed using zlib.\n").encode()
    body = "".join(f"{name} py:class 1 {name.rpartition('.')[0]}.html#$ -\n"
                   for name in sorted(set(names)))
    return header + zlib.compress(body.encode())


def inventory_contents(path: Path = INVENTORY) -> tuple[list[str], str]:
    """The names and the version line of an inventory :func:`inventory_bytes` wrote
    (none and "" when there is no file)."""
    if not path.exists():
        return [], ""
    data = path.read_bytes()
    lines = data.split(b"\n", 4)
    version = lines[2].decode().removeprefix("# Version: ")
    body = zlib.decompress(lines[4]).decode()
    return [line.split(" ", 1)[0] for line in body.splitlines() if line], version


def main() -> None:
    """Builds the site once, collecting names, and adds them to ``INVENTORY``."""
    import pydrake

    with tempfile.TemporaryDirectory() as out:
        collected = Path(out) / "names.txt"
        collected.write_text("")
        env = dict(os.environ, **{COLLECT_ENV: str(collected)})
        subprocess.run([sys.executable, "-m", "sphinx", "-E", "-q", "-b", "html", str(DOCS),
                        str(Path(out) / "html")], env=env, check=True)
        seen = set(collected.read_text().split())
    imports = pydrake_imports()
    names = sorted({p for n in seen if (p := pydrake_name(n, imports))})
    kept, versions = inventory_contents()
    try:
        version = metadata.version("drake")
    except metadata.PackageNotFoundError:  # a source build of drake
        version = getattr(pydrake, "__version__", "")
    versions = ", ".join(sorted({v for v in (*versions.split(", "), version) if v}))
    added = sorted(set(names) - set(kept))
    names = sorted(set(names) | set(kept))
    INVENTORY.parent.mkdir(exist_ok=True)
    INVENTORY.write_bytes(inventory_bytes(names, versions))
    print(f"wrote {INVENTORY}: {len(names)} names ({len(added)} new), drake {versions}")
    for name in names:
        print(" ", name)


if __name__ == "__main__":
    main()
