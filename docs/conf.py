"""Sphinx configuration of the drake_tracker site.

Build: ``python -m sphinx -W -b html docs OUT`` (the ``docs`` extra). The build never
touches the network: pydrake's types are cross-linked through a small inventory shipped
in ``docs/_inventories/`` (``docs/_ext/pydrake_inventory.py`` writes it).
"""

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(DOCS.parent))

import drake_tracker  # noqa: E402

project = "drake_tracker"
author = "drake_tracker contributors"
copyright = "drake_tracker contributors"
release = drake_tracker.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.intersphinx",
    "param_reference",
    "api_pages",
    "pydrake_links",
]

# pydrake's documentation, from a shipped inventory: the build never uses the network.
intersphinx_mapping = {
    "pydrake": ("https://drake.mit.edu/pydrake/", str(DOCS / "_inventories" / "pydrake.inv")),
}

autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_class_signature = "separated"
napoleon_google_docstring = True
napoleon_numpy_docstring = False

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
# The evaluation folders hold data (CSV, JSON, results) and the plots that pages show;
# they are not pages themselves.
exclude_patterns = ["_build", "evaluation_full", "evaluation_quick",
                    "parameter_study.txt"]

myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence"]
myst_heading_anchors = 3

html_theme = "alabaster"
html_title = f"drake_tracker {release}"

