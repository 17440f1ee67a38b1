"""Sphinx configuration of the gpr3d documentation (``sphinx-build -W -b html docs build/docs``)."""

import os
import sys

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "src")))
os.environ.setdefault("MPLBACKEND", "Agg")

from gpr3d import __version__  # noqa: E402

project = "gpr3d"
author = "gpr3d developers"
copyright = "2026, gpr3d developers (GPL-3.0-or-later)"
version = release = __version__

extensions = ["sphinx.ext.autodoc", "sphinx.ext.mathjax", "sphinx.ext.viewcode", "numpydoc", "myst_parser"]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "figures/README.md"]
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]

# numpydoc: the sections of the public API's docstrings; class members are listed by autodoc, not numpydoc
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_typehints = "none"
# Open3D is optional (and needs a system library): its module documents without it
autodoc_mock_imports = ["open3d"]

nitpicky = True  # every cross-reference must resolve (the build runs with -W)
# torchvision has no intersphinx inventory here: the base class of gpr3d.detection.kindheads.KindRoIHeads
nitpick_ignore = [("py:class", "torchvision.models.detection.roi_heads.RoIHeads")]

html_theme = "alabaster"
html_title = f"gpr3d {version}"
html_static_path = []
