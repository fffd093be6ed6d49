"""Sphinx configuration of the geovs_drake API reference (``make docs``)."""

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(DOCS.parent))  # this checkout's package, installed or not

import geovs_drake  # noqa: E402

project = "geovs_drake"
author = "the geovs_drake authors"
copyright = "the geovs_drake authors, BSD-3-Clause"
release = version = geovs_drake.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "myst_nb",  # MyST Markdown pages, and the notebooks with their outputs
    "pydrake_system",
    "geovs_docs",
    "notebook_pages",  # runs notebooks/*.ipynb into docs/notebooks/ before the read
]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
# notebook_pages has just executed them: render those outputs, do not run them again.
nb_execution_mode = "off"
# paper-notes.md is included by paper_notes.rst (when it exists), not a page of its own.
exclude_patterns = ["_build", "paper-notes.md", "images/*", "**/.ipynb_checkpoints"]
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]
# The Markdown pages are written to be read on a forge too (README, CHANGELOG, the
# paper notes): their heading levels and links to repository files are theirs.
suppress_warnings = ["myst.header", "myst.xref_missing"]

autodoc_default_options = {"members": True, "undoc-members": True, "member-order": "bysource"}
autodoc_typehints = "signature"
autodoc_preserve_defaults = True  # show DEFAULT_DOMAIN, not its repr
autodoc_class_signature = "mixed"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True  # Attributes: as a field list (no duplicate attribute entries)

html_theme = "furo"
html_title = f"geovs_drake {release}"
html_static_path = ["_static"]
html_show_sourcelink = False
