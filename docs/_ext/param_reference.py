"""Sphinx extension: the parameter reference page, generated at build time.

``docs/reference/parameters.md`` holds the line ``<!-- tracker-parameters -->``; on
``source-read`` it is replaced by :func:`parameters_markdown`: one section per dataclass
of ``TrackerParams`` (its YAML path, the class, its docstring) with a table of its fields
(name, unit, default, meaning) read from the dataclasses themselves
(``drake_tracker.params.reference``). Nothing here is written by hand, so the page
cannot drift from the code.
"""

from __future__ import annotations

from typing import Any

from drake_tracker.params.reference import nested_groups, parameter_rows

MARKER = "<!-- tracker-parameters -->"
PAGE = "reference/parameters"


def _cell(text: str) -> str:
    """Text for a Markdown table cell: pipes escaped, line breaks joined."""
    return " ".join(text.split()).replace("|", "\\|")


def parameters_markdown() -> str:
    """The reference as MyST Markdown: a section per nested dataclass, a table row per
    field, in declaration order."""
    rows = parameter_rows()
    out = []
    for path, cls_name, doc in nested_groups():
        own = [r for r in rows if r.path.rpartition(".")[0] == path]
        if not own:
            continue
        title = f"`{path}`" if path else "top level"
        out += [f"## {title} ({cls_name})", "", _cell(doc), "",
                "| name | unit | default | meaning |", "|---|---|---|---|"]
        for r in own:
            name = r.path.rpartition(".")[2]
            unit = _cell(r.unit) if r.unit else "–"
            out.append(f"| `{name}` | {unit} | `{_cell(r.default)}` | {_cell(r.meaning)} |")
        out.append("")
    return "\n".join(out)


def _source_read(app: Any, docname: str, source: list[str]) -> None:
    if docname == PAGE:
        if MARKER not in source[0]:
            raise RuntimeError(f"{PAGE}.md lost its marker line {MARKER}")
        source[0] = source[0].replace(MARKER, parameters_markdown())


def setup(app: Any) -> dict[str, Any]:
    """Registers the page generator."""
    app.connect("source-read", _source_read)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
