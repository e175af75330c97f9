"""The repository's root folder, for the tests that read its files (pyproject.toml, the
package's sources, ``docs/``, ``examples/``, ``.ci/``) from any folder of ``tests/``."""

from pathlib import Path


def _folder_with_pyproject(start: Path) -> Path:
    """The nearest folder above ``start`` that holds pyproject.toml."""
    for folder in start.parents:
        if (folder / "pyproject.toml").is_file():
            return folder
    raise RuntimeError(f"no pyproject.toml in any folder above {start}")


#: The repository's root: the folder of pyproject.toml.
ROOT = _folder_with_pyproject(Path(__file__).resolve())
