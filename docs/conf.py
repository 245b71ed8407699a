"""Sphinx configuration of gyroarray's documentation site (``make docs``).

The guides are the Markdown pages of this folder (MyST); the API reference
is generated from the numpydoc docstrings (autodoc + autosummary + numpydoc).
"""

project = "gyroarray"
author = "the gyroarray developers"
extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.autosummary", "numpydoc",
              "sphinx.ext.mathjax"]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 3
exclude_patterns = ["_build"]
autosummary_generate = True
autodoc_default_options = {"members": True, "undoc-members": False}
autodoc_mock_imports = ["mujoco"]
numpydoc_show_class_members = False
numpydoc_validation_checks: set = set()
suppress_warnings = ["myst.xref_missing", "myst.header", "autosummary", "docutils"]
html_theme = "alabaster"
html_title = "gyroarray"
