"""The project rule "type hints on public functions", checked on the source with ``ast``.

Public: module-level functions and the methods of module-level classes whose names do
not start with ``_``, plus ``__init__`` and ``__call__``; nested functions and classes
are not public. Each must annotate every argument (``self`` / ``cls`` of a method
excepted, ``*args`` and ``**kwargs`` included) and, ``__init__`` excepted, its return.
"""

import ast

from package_walk import PACKAGE, walk_package

DUNDERS_PUBLIC = {"__init__", "__call__"}

FunctionNode = ast.FunctionDef | ast.AsyncFunctionDef


def _is_public(name: str) -> bool:
    return not name.startswith("_") or name in DUNDERS_PUBLIC


def _is_staticmethod(node: FunctionNode) -> bool:
    return any(isinstance(d, ast.Name) and d.id == "staticmethod"
               for d in node.decorator_list)


def missing_hints(node: FunctionNode, is_method: bool) -> list[str]:
    """What ``node`` leaves unannotated: argument names, and ``return``."""
    args = node.args
    positional = args.posonlyargs + args.args
    if is_method and not _is_staticmethod(node) and positional \
            and positional[0].arg in ("self", "cls"):
        positional = positional[1:]
    missing = [a.arg for a in positional + args.kwonlyargs if a.annotation is None]
    missing += [f"*{a.arg}" for a in (args.vararg,) if a is not None and a.annotation is None]
    missing += [f"**{a.arg}" for a in (args.kwarg,) if a is not None and a.annotation is None]
    if node.returns is None and node.name != "__init__":
        missing.append("return")
    return missing


def public_functions(tree: ast.Module) -> list[tuple[str, FunctionNode, bool]]:
    """(qualified name, node, is_method) of the module's public functions and methods."""
    found = []
    for node in tree.body:
        if isinstance(node, FunctionNode) and _is_public(node.name):
            found.append((node.name, node, False))
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            found += [(f"{node.name}.{item.name}", item, True) for item in node.body
                      if isinstance(item, FunctionNode) and _is_public(item.name)]
    return found


def offenders_in(source: str, label: str) -> list[str]:
    """One line per public function of ``source`` that lacks a hint."""
    out = []
    for name, node, is_method in public_functions(ast.parse(source)):
        missing = missing_hints(node, is_method)
        if missing:
            out.append(f"{label}:{node.lineno} {name}: no hint for {', '.join(missing)}")
    return out


def test_every_public_function_has_type_hints():
    modules, checked, offenders = walk_package(lambda tree: len(public_functions(tree)),
                                               offenders_in)
    assert modules > 50, f"found only {modules} modules under {PACKAGE}"
    assert checked > 300, f"only {checked} public functions found: is the walk broken?"
    assert not offenders, (f"{len(offenders)} public functions without full type "
                           "hints:\n" + "\n".join(offenders))


def test_the_check_finds_what_is_missing():
    source = '''
def f(a, b: int, *args, c, **kw): pass
def g(a: int) -> None: pass
def _private(a): pass
class Public:
    def __init__(self, x): pass
    def method(self, y: int): pass
    @staticmethod
    def static(self) -> None: pass
    @classmethod
    def build(cls) -> "Public": pass
    def _hidden(self, z): pass
    def __call__(self, w: int) -> int:
        def nested(v): pass
        return w
class _Private:
    def method(self, y): pass
'''
    assert offenders_in(source, "m") == [
        "m:2 f: no hint for a, c, *args, **kw, return",
        "m:6 Public.__init__: no hint for x",
        "m:7 Public.method: no hint for return",
        "m:9 Public.static: no hint for self",
    ]
