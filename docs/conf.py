"""Sphinx configuration for dyntarget's documentation site.

Build it (warnings are errors) with ``.ci/docs`` or::

    pip install -e ".[docs]"
    sphinx-build -W --keep-going -b html docs docs/_build/html
"""

from __future__ import annotations

import os
import sys
from importlib.metadata import version as _dist_version
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # _cli_reference.py beside this file
os.environ.setdefault("MPLBACKEND", "Agg")

project = "dyntarget"
author = "dyntarget developers"
copyright = "dyntarget developers, Apache-2.0"
release = _dist_version("dyntarget")  # one source: the installed package's metadata
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
templates_path = ["_templates"]
exclude_patterns = [
    "_build",
    "benchmarks/*.md",
    "**.ipynb_checkpoints",
    "auto_examples/*.ipynb",
    "auto_examples/*.py",
    "auto_examples/*.zip",
    "auto_examples/*.json",
]

# MyST: the Markdown pages (README-style) are part of the site.
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3  # [text](page.md#a-heading) links resolve

# API reference: autosummary generates one page per module from the package itself, so
# modules added later appear without editing the docs.
autosummary_generate = True
autosummary_imported_members = False
# type aliases (``Window = tuple[...]``) look like classes to autosummary: documented as data
autosummary_context = {"type_aliases": ["Window"]}
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_typehints = "none"  # numpydoc sections carry the types
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks: set[str] = set()

# sphinx-gallery: examples/ run at build time, each shows a figure.
sphinx_gallery_conf = {
    "examples_dirs": str(HERE.parent / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "within_subsection_order": "FileNameSortKey",
}

html_theme = "pydata_sphinx_theme"
html_title = f"dyntarget {release}"
html_static_path: list[str] = []
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
}
html_show_sourcelink = False

# intersphinx needs the network (numpy, rasterio, shapely, pysteps inventories): off by
# default; DYNTARGET_DOCS_INTERSPHINX=1 turns it on where the network is there.
if os.environ.get("DYNTARGET_DOCS_INTERSPHINX") == "1":
    extensions.append("sphinx.ext.intersphinx")
    intersphinx_mapping = {
        "python": ("https://docs.python.org/3", None),
        "numpy": ("https://numpy.org/doc/stable", None),
        "rasterio": ("https://rasterio.readthedocs.io/en/stable", None),
        "shapely": ("https://shapely.readthedocs.io/en/stable", None),
    }
