"""Sphinx configuration of the kfpga manual (``make docs``: HTML under build/docs, warnings as errors)."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

project = "kfpga"
author = "the kfpga authors"
copyright = "2026, the kfpga authors"

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon", "sphinxarg.ext"]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
myst_heading_anchors = 4
myst_enable_extensions = ["colon_fence"]
exclude_patterns = ["_build"]
root_doc = "index"
html_theme = "alabaster"
html_title = "kfpga"

autodoc_member_order = "bysource"
autodoc_typehints = "none"
napoleon_google_docstring = False
napoleon_numpy_docstring = True
# the docstrings name classes and modules all over the package: a name Sphinx cannot resolve is
# plain text, not a warning (nitpicky stays off)
suppress_warnings = ["myst.xref_ambiguous"]
