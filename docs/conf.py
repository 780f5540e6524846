"""Sphinx configuration of the fem_squeal user guide (built by scripts/docs.sh with -W).

The scene reference (reference/scene.md) is generated here, before the build, from the schema in
code (fem_squeal.app.schema_reference), so it cannot drift from what the scene loader accepts.
"""
from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))      # the package and `geometry`, also without the editable install

from fem_squeal import __version__  # noqa: E402
from fem_squeal.app.schema_reference import write as write_scene_reference  # noqa: E402

write_scene_reference(HERE / "reference" / "scene.md")

project = "fem_squeal"
author = "fem_squeal contributors"
copyright = "fem_squeal contributors, MIT licence"
version = release = __version__

extensions = ["myst_parser", "sphinx.ext.autodoc"]
source_suffix = {".md": "markdown"}
master_doc = root_doc = "index"
exclude_patterns = ["_build", ".gitignore"]
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
html_theme = "alabaster"
html_static_path = ["_static"]
html_theme_options = {"page_width": "1320px", "sidebar_width": "260px", "body_max_width": "none",
                      "fixed_sidebar": True}
html_css_files = ["custom.css"]
html_show_sourcelink = False
pygments_style = "sphinx"
highlight_language = "none"        # literal blocks (docstrings, indented blocks) are not code

# The code's docstrings are plain text with unicode math (not reStructuredText): each is rendered
# as a literal block (see _literal_docstring), so markup-looking text never breaks the build.
autodoc_docstring_signature = True
autodoc_default_options = {"members": True, "member-order": "bysource", "show-inheritance": True}
autodoc_typehints = "signature"
autodoc_class_signature = "mixed"
autodoc_inherit_docstrings = False
autodoc_preserve_defaults = True
autoclass_content = "class"


def _literal_docstring(app, what, name, obj, options, lines):
    """A docstring verbatim, as a literal block (its indentation and unicode math kept)."""
    if not any(line.strip() for line in lines):
        lines[:] = []
        return
    body = [("    " + line) if line.strip() else "" for line in lines]
    lines[:] = ["::", ""] + body + [""]


def setup(app):
    app.connect("autodoc-process-docstring", _literal_docstring)
