"""Every example of the site's guides (``docs/guides/*.md``) runs here, so a broken
example fails CI.

A guide is run as one script: its ```` ```python ```` blocks in order, in one namespace,
each at its own line numbers (a traceback names the guide's line), in a fresh working
folder. Its ```` ```bash ```` blocks hold ``drake-tracker`` commands, run in the same
folder (the python blocks may read what they wrote; the commands of a page run before
its python blocks). Commands shown but not run (the installs) are ```` ```console ````
blocks: each must be a line of the README, whose test command is ``.ci/run``'s.
"""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from repo_root import ROOT

GUIDES = sorted((ROOT / "docs" / "guides").glob("*.md"))
FENCE = re.compile(r"^```(\w+)[^\n]*\n(.*?)^```\s*$", re.MULTILINE | re.DOTALL)


def fenced_blocks(text: str, language: str) -> list[tuple[int, str]]:
    """(first line number of the code, code) of each ```` ```language ```` block."""
    found = []
    for match in FENCE.finditer(text):
        if match.group(1) == language:
            first_line = text.count("\n", 0, match.start(2)) + 1
            found.append((first_line, match.group(2)))
    return found


def as_script(text: str) -> str:
    """The python blocks of ``text`` at their own line numbers, blank lines between."""
    lines: list[str] = []
    for first_line, code in fenced_blocks(text, "python"):
        lines += [""] * (first_line - 1 - len(lines))
        lines += code.splitlines()
    return "\n".join(lines) + "\n"


def test_the_block_reader_keeps_line_numbers():
    text = "# T\n\n```python\na = 1\n```\n\ntext\n```bash\nx\n```\n```python\nb = a\n```\n"
    script = as_script(text).splitlines()
    assert script[3] == "a = 1" and script[11] == "b = a"
    assert fenced_blocks(text, "bash") == [(9, "x\n")]


def test_there_are_guides_with_examples():
    names = {path.stem for path in GUIDES}
    assert {"getting_started", "tracker_in_your_diagram", "your_own_robot", "real_data",
            "closed_loop", "bad_input"} <= names
    for path in GUIDES:
        assert fenced_blocks(path.read_text(), "python"), f"{path.name} has no example"


def test_shown_commands_are_the_readmes():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    for path in GUIDES:
        for _, code in fenced_blocks(path.read_text(), "console"):
            for line in filter(None, (s.strip() for s in code.splitlines())):
                assert line in readme, f"{path.name}: {line!r} is not a README command"
    test_command = next(line for line in readme.splitlines() if "pytest" in line)
    assert test_command.split(" && ")[1] in ci  # the install line CI runs


def _command(line: str) -> list[str]:
    words = shlex.split(line)
    assert words[0] == "drake-tracker", f"a bash block may run drake-tracker only: {line}"
    return [sys.executable, "-m", "drake_tracker.cli.main", *words[1:]]


@pytest.mark.parametrize("guide", GUIDES, ids=[path.stem for path in GUIDES])
def test_guide_examples_run(guide: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    text = guide.read_text()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get("PYTHONPATH", "")])))
    for first_line, code in fenced_blocks(text, "bash"):
        for line in filter(None, (s.strip() for s in code.splitlines())):
            done = subprocess.run(_command(line), cwd=tmp_path, env=env, text=True,
                                  capture_output=True, timeout=600)
            assert done.returncode == 0, (f"{guide.name}:{first_line}: {line}\n"
                                          f"{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", [str(guide)])
    namespace = {"__name__": f"guide_{guide.stem}"}
    exec(compile(as_script(text), str(guide), "exec"), namespace)  # noqa: S102
