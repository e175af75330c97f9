"""The project rule "docstrings on public classes/functions", checked on the source with ``ast``.

Every module needs a docstring. Public: module-level functions and classes whose names
do not start with ``_``, and the methods (properties included) of those classes whose
names do not start with ``_``; nested functions and classes, and dunder methods, are
not public. Each public item needs a docstring (``ast.get_docstring``).
"""

import ast

from package_walk import PACKAGE, walk_package

FunctionNode = ast.FunctionDef | ast.AsyncFunctionDef
DefinitionNode = FunctionNode | ast.ClassDef


def _is_public(name: str) -> bool:
    return not name.startswith("_")


def public_definitions(tree: ast.Module) -> list[tuple[str, DefinitionNode]]:
    """(qualified name, node) of the module's public classes, functions and methods."""
    found = []
    for node in tree.body:
        if isinstance(node, FunctionNode) and _is_public(node.name):
            found.append((node.name, node))
        elif isinstance(node, ast.ClassDef) and _is_public(node.name):
            found.append((node.name, node))
            found += [(f"{node.name}.{item.name}", item) for item in node.body
                      if isinstance(item, FunctionNode) and _is_public(item.name)]
    return found


def offenders_in(source: str, label: str) -> list[str]:
    """One line per public definition of ``source`` without a docstring (and one for the
    module itself when it has none)."""
    tree = ast.parse(source)
    out = [] if ast.get_docstring(tree) is not None else [f"{label}:1 module"]
    for name, node in public_definitions(tree):
        if ast.get_docstring(node) is None:
            kind = "class" if isinstance(node, ast.ClassDef) else "def"
            out.append(f"{label}:{node.lineno} {kind} {name}")
    return out


def test_every_module_and_public_definition_has_a_docstring():
    modules, checked, offenders = walk_package(lambda tree: len(public_definitions(tree)),
                                               offenders_in)
    assert modules > 50, f"found only {modules} modules under {PACKAGE}"
    assert checked > 400, f"only {checked} public definitions found: is the walk broken?"
    assert not offenders, (f"{len(offenders)} modules or public definitions without a "
                           "docstring:\n" + "\n".join(offenders))


def test_the_check_finds_what_is_missing():
    source = '''
import math

def f(a): return a
def g():
    """Documented."""
    def nested(): pass
def _private(): pass
class Public:
    x: int = 1
    def __init__(self): pass
    def method(self): pass
    @property
    def size(self) -> int:
        return 1
    @staticmethod
    def documented():
        """Documented."""
    def _hidden(self): pass
    class Inner:
        def method(self): pass
class Documented:
    """Documented."""
    async def fetch(self): pass
class _Private:
    def method(self): pass
'''
    assert offenders_in(source, "m") == [
        "m:1 module",
        "m:4 def f",
        "m:9 class Public",
        "m:12 def Public.method",
        "m:14 def Public.size",
        "m:24 def Documented.fetch",
    ]
    documented = '"""A module."""\n' + source.replace(
        "def f(a): return a", "def f(a):\n    'Documented.'\n    return a")
    assert offenders_in(documented, "m") == [
        "m:12 class Public",
        "m:15 def Public.method",
        "m:17 def Public.size",
        "m:27 def Documented.fetch",
    ]
