"""The design card's rules that a test can hold: no Python file over 400 lines, no
folder with more than 15 modules (in the package, ``tests/`` and ``examples/``, at any
depth), no import cycle between the package's modules (every import that runs: at module
level or inside a function; only ``if TYPE_CHECKING:`` blocks, which never run, are left
out), and the layers: the core never imports the package's upper layers."""

import ast
from pathlib import Path

from repo_root import ROOT

PACKAGE = ROOT / "drake_tracker"
MAX_LINES = 400


def test_no_python_file_is_over_400_lines():
    long = {}
    for folder in ("drake_tracker", "tests", "examples", "models"):
        for path in (ROOT / folder).rglob("*.py"):
            lines = len(path.read_text().splitlines())
            if lines > MAX_LINES:
                long[str(path.relative_to(ROOT))] = lines
    assert not long, f"files over {MAX_LINES} lines: {long}"


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _is_type_checking_block(node: ast.stmt) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def _runtime_nodes(tree: ast.AST):
    """Every node of ``tree`` outside ``if TYPE_CHECKING:`` blocks."""
    for node in ast.iter_child_nodes(tree):
        if _is_type_checking_block(node):
            continue
        yield node
        yield from _runtime_nodes(node)


def _module_level_imports(path: Path, modules: set[str]) -> set[str]:
    """The package modules ``path`` imports when it runs, at module level or inside a
    function (``from a import b`` counts as a.b where that is a module, else as a)."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in _runtime_nodes(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{anchor}.{base}" if base else anchor
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base
                       for a in node.names]
        else:
            continue
        found |= {t for t in targets if t in modules and t != name}
    return found


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The cycles a depth-first search meets in ``graph`` (module -> imported modules)."""
    cycles = []
    state: dict[str, int] = {}  # 1: on the path, 2: done

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(path[path.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, path + [nxt])
        state[node] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    return cycles


def test_the_cycle_search_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c", "a"]]
    assert _cycles({"a": {"b"}, "b": set(), "c": {"a", "b"}}) == []


def test_no_import_cycle_between_the_package_modules():
    paths = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    modules = set(paths)
    graph = {m: _module_level_imports(p, modules) for m, p in paths.items()}
    # A package's __init__ importing its own submodules is how packages re-export;
    # a submodule importing its package's __init__ back would be the cycle.
    for m in graph:
        graph[m] = {t for t in graph[m] if not t.startswith(m + ".")}
    assert sum(len(v) for v in graph.values()) > 100  # the imports were read
    cycles = _cycles(graph)
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles[:5])


def test_the_import_reader_sees_imports_inside_functions(tmp_path):
    package = tmp_path / "pkg"
    package.mkdir()
    path = package / "a.py"
    path.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.c\n"
                    "def f():\n    from pkg.b import thing\n    return thing\n")
    global ROOT
    saved, ROOT = ROOT, tmp_path
    try:
        assert _module_level_imports(path, {"pkg.a", "pkg.b", "pkg.c"}) == {"pkg.b"}
    finally:
        ROOT = saved


#: The layers, lowest first: a module imports only from its own layer and those below.
#: ``robot`` is the model (a MultibodyPlant), the core's input; ``params`` resolves the
#: user's parameters into the core's ``ResolvedParams``.
LAYERS = (
    ("robot",),
    ("core",),
    ("params",),
    ("tracker", "systems", "io", "metrics", "progress", "kernel_warm_up", "models"),
    ("sim",),
    ("evaluation", "demo", "bench", "servo", "cli"),
)


def _layer(module: str) -> int:
    parts = module.split(".")
    if len(parts) == 1:  # the package's own __init__: the public API, above its layers
        return len(LAYERS) - 1
    for k, names in enumerate(LAYERS):
        if parts[1] in names:
            return k
    raise AssertionError(f"{module}: no layer for '{parts[1]}' (add it to LAYERS)")


def test_no_module_imports_a_layer_above_its_own():
    paths = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    modules = set(paths)
    upward = []
    for m, p in paths.items():
        for t in _module_level_imports(p, modules):
            if t != "drake_tracker" and _layer(t) > _layer(m):
                upward.append(f"{m} -> {t}")
    assert not upward, "imports of an upper layer: " + "; ".join(sorted(upward))


#: The top folders whose every folder, at any depth, holds at most ``MAX_MODULES`` modules.
CROWDING_CHECKED = ("drake_tracker", "tests", "examples")
MAX_MODULES = 15


def _modules_per_folder(top: Path) -> dict[str, int]:
    """Folder (from the repository root) -> its ``.py`` files other than ``__init__.py``,
    for ``top`` and every folder below it."""
    folders = [top, *sorted(p for p in top.rglob("*")
                            if p.is_dir() and "__pycache__" not in p.parts)]
    return {str(folder.relative_to(ROOT)):
            len([p for p in folder.glob("*.py") if p.name != "__init__.py"])
            for folder in folders}


def test_no_folder_has_more_than_15_modules():
    """The package, ``tests/`` and ``examples/``: no folder at any depth (the top folder
    included) has more than 15 modules, ``__init__.py`` not counted; a crowded folder is
    split into subfolders named for their job."""
    counts = {}
    for top in CROWDING_CHECKED:
        counts |= _modules_per_folder(ROOT / top)
    assert sum(counts.values()) > 100  # the folders were read
    crowded = {folder: n for folder, n in counts.items() if n > MAX_MODULES}
    assert not crowded, f"folders over {MAX_MODULES} modules: {crowded}"
