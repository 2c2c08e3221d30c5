"""Sphinx configuration of the flexctrl documentation (``make docs`` builds it)."""

import importlib.metadata
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent / "_ext"))

project = "flexctrl"
author = "the flexctrl developers"
release = importlib.metadata.version("flexctrl")
version = release

extensions = [
    "myst_nb",
    "numpydoc",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx_copybutton",
    "sphinx_design",
    "flexctrl_reference",
]

# numpydoc renders the docstrings; autosummary writes one page per public name
autosummary_generate = True
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

# Markdown pages (MyST) and notebooks (myst-nb, executed when the site is built)
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
myst_enable_extensions = ["colon_fence", "deflist", "dollarmath", "amsmath"]
myst_heading_anchors = 3
nb_execution_mode = os.environ.get("FLEXCTRL_DOCS_EXECUTE", "cache")
nb_execution_timeout = 1800
nb_execution_raise_on_error = True
nb_execution_show_tb = True

exclude_patterns = ["_build", "jupyter_execute", "**.ipynb_checkpoints"]
# generated fragments, included by the pages that show them
exclude_patterns += ["reproduction/table.md"]
# the contributors' page, read in the repository (CONTRIBUTING.md points to it)
exclude_patterns += ["architecture.md"]
templates_path = ["_templates"]
html_static_path = ["_static"]
html_theme = "pydata_sphinx_theme"
html_title = "flexctrl"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
}
html_sidebars = {"**": ["sidebar-nav-bs"]}
suppress_warnings = ["mystnb.unknown_mime_type"]

# The reference documents the public namespace (flexctrl.NAME). Docstrings also point into the
# toolkit's own modules (flexctrl.LAYER.MODULE...) and, unqualified, to names of the module they
# sit in; those are for readers of the source and have no page here, so they are not checked.
nitpick_ignore_regex = [
    (r"py:.*", r"flexctrl\.[a-z_]+\..+"),
    (r"py:.*", r"[A-Za-z_][A-Za-z0-9_]*"),
    (r"py:.*", r"abc\.ABC"),
]
