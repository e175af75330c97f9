"""Sphinx extension: the API reference pages, written from the package at build time.

``.. api-package:: drake_tracker.io`` documents the package's docstring and then every
module in it (``pkgutil``: a module added later is documented without editing a page),
each with autodoc's ``:members:``. Names exported at the top level
(``drake_tracker.__all__``) are documented once, on the top-level page, where autodoc
marks them ``:canonical:`` so that their defining module's name links there too; the
module pages leave them out. ``.. api-module:: NAME`` does the same for one module.
``.. pydrake_system::``, the block of ports that Drake's systems' docstrings hold, is
drawn as a table.
"""

from __future__ import annotations

import importlib
import pkgutil
from typing import Any

from docutils.parsers.rst import Directive

import drake_tracker


def top_level_names_in(module_name: str) -> list[str]:
    """The names under which ``module_name`` holds an object of ``drake_tracker.__all__``:
    those it defines, and those it imports and re-exports (e.g. ``robot.model`` the
    configuration classes of ``robot.config``), which autodoc would document again."""
    module = importlib.import_module(module_name)
    top = {id(getattr(drake_tracker, name)) for name in drake_tracker.__all__}
    return sorted(name for name, value in vars(module).items()
                  if not name.startswith("_") and id(value) in top
                  and (getattr(value, "__module__", None) == module_name
                       or name in getattr(module, "__all__", ())))


def package_modules(package_name: str) -> list[str]:
    """The public modules of a package (not its subpackages), sorted."""
    package = importlib.import_module(package_name)
    return sorted(f"{package_name}.{m.name}" for m in pkgutil.iter_modules(package.__path__)
                  if not m.name.startswith("_") and not m.ispkg)


def module_lines(module_name: str, title: bool = True) -> list[str]:
    """reStructuredText that documents ``module_name`` and its public members."""
    lines = [module_name, "-" * len(module_name), ""] if title else []
    lines += [f".. automodule:: {module_name}", "   :members:"]
    exclude = top_level_names_in(module_name)
    if exclude:
        lines.append(f"   :exclude-members: {', '.join(exclude)}")
    return lines + [""]


class ApiPackage(Directive):
    """``.. api-package:: PACKAGE``: the package's docstring, then each of its modules."""

    required_arguments = 1

    def run(self) -> list:
        name = self.arguments[0]
        lines = [f".. automodule:: {name}", ""]
        for module_name in package_modules(name):
            lines += module_lines(module_name)
        self.state_machine.insert_input(lines, f"<api-package {name}>")
        return []


class PydrakeSystem(Directive):
    """``.. pydrake_system::``, Drake's own block of a system's ports in a docstring (YAML:
    ``name``, ``input_ports``, ``output_ports``), drawn as a three-column table."""

    has_content = True

    def run(self) -> list:
        from pydrake.common.yaml import yaml_load

        spec = yaml_load(data="\n".join(self.content)) or {}
        inputs = spec.get("input_ports") or []
        outputs = spec.get("output_ports") or []
        rows = max(len(inputs), len(outputs), 1)
        lines = [".. list-table::", "   :header-rows: 1", "   :class: pydrake-system", "",
                 "   * - input ports", f"     - ``{spec.get('name', '')}``",
                 "     - output ports"]
        for k in range(rows):
            cell_in = f"``{inputs[k]}`` →" if k < len(inputs) else ""
            cell_out = f"→ ``{outputs[k]}``" if k < len(outputs) else ""
            lines += [f"   * - {cell_in}", "     -", f"     - {cell_out}"]
        self.state_machine.insert_input(lines + [""], "<pydrake_system>")
        return []


class ApiModule(Directive):
    """``.. api-module:: MODULE``: one module, without a title of its own."""

    required_arguments = 1

    def run(self) -> list:
        self.state_machine.insert_input(module_lines(self.arguments[0], title=False),
                                        f"<api-module {self.arguments[0]}>")
        return []


def setup(app: Any) -> dict[str, Any]:
    """Registers the directives."""
    app.add_directive("api-package", ApiPackage)
    app.add_directive("api-module", ApiModule)
    app.add_directive("pydrake_system", PydrakeSystem)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
