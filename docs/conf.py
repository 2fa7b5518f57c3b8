"""Sphinx configuration of tolsynth's documentation.

Build (from the repository root): ``pip install -e ".[docs]"`` then
``sphinx-build -W --keep-going -b html docs docs/_build/html`` (warnings fail the build).

- API reference: autosummary + autodoc of ``tolsynth.__all__``, docstrings in numpydoc style;
- notebooks: the jupytext ``py:percent`` files of ``notebooks/`` (linked into ``docs/notebooks/``),
  executed by myst-nb unless the tests have executed the same notebook on the same code, outputs
  and plots included;
- the model-file format with the table of every key from ``tolsynth.model.fields.FORMAT``; the
  command line: each sub-command's ``--help``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # _ext.py
# the notebook kernels inherit this environment: the inline backend puts every figure into the page
# (CI exports MPLBACKEND=Agg for the tests, under which plt.show() would show nothing)
os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"

from _ext import notebook_cache_dir  # noqa: E402

import tolsynth  # noqa: E402

project = "tolsynth"
author = "the tolsynth authors"
copyright = "2026, the tolsynth authors"
release = version = tolsynth.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_nb",
    "_ext",
]

# the notebooks are jupytext py:percent text; every other .py here is not a page
nb_custom_formats = {".py": ["jupytext.reads", {"fmt": "py:percent"}]}
exclude_patterns = ["_build", "_generated", "_templates", "conf.py", "_ext.py", "**/__pycache__", "jupyter_execute"]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".py": "myst-nb"}

# a notebook is executed once per content: its outputs are cached under a folder keyed by the
# package's source (_ext.notebook_cache_dir), where tests/test_notebooks.py also stores the notebooks
# it has executed; a page never shows numbers of other code, and CI never runs a notebook twice
nb_execution_mode = "cache"
nb_execution_cache_path = str(notebook_cache_dir())
nb_execution_timeout = 600  # seconds per cell
nb_execution_raise_on_error = True  # a failing cell fails the build
nb_execution_show_tb = True
nb_merge_streams = True
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 3

autosummary_generate = True
# a class page lists its own members only (not, say, the str methods of the str-valued Status enum)
templates_path = ["_templates"]
autodoc_typehints = "none"  # the numpydoc Parameters sections state the types
autodoc_default_options = {"members": True, "inherited-members": False}
numpydoc_show_class_members = False  # autosummary lists them; avoids duplicate entries
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

html_theme = "pydata_sphinx_theme"
html_title = f"tolsynth {release}"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": {"notebooks/*": []},
}
html_static_path = ["_static"]
html_css_files = ["wide.css"]
