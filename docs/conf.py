"""Sphinx configuration of gainlink's documentation site (``make docs``; the test suite builds it with ``-W``).

It builds offline: no intersphinx inventory and no theme asset is fetched (furo ships its assets in its wheel);
other projects' documentation is linked by plain URL. Markdown through myst-parser, docstrings through autodoc and
numpydoc, the command line from its own argparse parser (sphinx-argparse).
"""

from __future__ import annotations

from gainlink.version import __version__

project = "gainlink"
author = "the gainlink authors"
copyright = "the gainlink authors, Apache-2.0"
release = version = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "numpydoc",
    "sphinxarg.ext",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build"]

myst_enable_extensions = ["colon_fence"]
myst_heading_anchors = 3

autodoc_member_order = "bysource"
autodoc_typehints = "none"  # numpydoc's Parameters sections say the types in words
numpydoc_show_class_members = False
numpydoc_validation_checks: set[str] = set()

html_theme = "furo"
html_title = f"gainlink {release}"
html_static_path: list[str] = []
