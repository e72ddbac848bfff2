"""Sphinx configuration of musclemetab's API reference, built from the docstrings.

Build it with ``python -m sphinx -W -b html docs/api OUT`` (warnings are errors;
``tests/test_api_docs.py`` does so). The reference documents the public modules listed in
``index.rst``; the method itself is in the Markdown documents of ``docs/``.
"""

import os
import sys

# the checkout's package, ahead of an installed copy
sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", "src")))

project = "musclemetab"
author = "the musclemetab authors"
copyright = "musclemetab authors, Apache-2.0"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
]

autosummary_generate = False  # the module pages are written out beside index.rst: nothing is generated into the sources
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": False}
autodoc_member_order = "bysource"
autodoc_typehints = "none"  # the signatures stay short; the docstrings say what each argument is
numpydoc_show_class_members = False  # autodoc's members: each documented once
numpydoc_class_members_toctree = False
numpydoc_validation_checks = set()  # the docstrings' own style (prose first), not numpydoc's checklist
suppress_warnings = ["autosummary.import_cycle"]

templates_path = []
exclude_patterns = ["_build"]
html_theme = "alabaster"
html_static_path = []
html_copy_source = False
html_show_sourcelink = False
