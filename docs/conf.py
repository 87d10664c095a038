"""Sphinx configuration: the Markdown pages of docs/ (MyST) and an API reference built from wpctrl's docstrings."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the checkout's wpctrl, also without an editable install

project = "wpctrl"
author = "the wpctrl authors"
copyright = "the wpctrl authors, Apache License 2.0"

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon"]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "**/.ipynb_checkpoints", "**/__pycache__"]

myst_heading_anchors = 3  # [text](page.md#a-heading) links resolve to the page's headings

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
napoleon_google_docstring = True
napoleon_numpy_docstring = False

html_theme = "alabaster"
html_title = "wpctrl"
