"""Sphinx configuration of the PioneeR docs site (``make docs``; built with warnings as errors).

The guide pages are the Markdown files of this folder (MyST); the API reference is generated
at build time by walking the ``pioneer`` package (autosummary, recursive) and rendering each
module's docstrings with autodoc, whose reST roles (``:func:``, ``:class:``, ``:mod:``) it
resolves; the CLI reference is generated at build time from each command's own ``--help``
(``_ext/pioneer_cli.py``).
"""

from __future__ import annotations

import re
import shutil
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))

import pioneer  # noqa: E402  (after the path: the extension folder)

project = "PioneeR"
author = "the PioneeR authors"
copyright = "the PioneeR authors, MIT License"
version = release = pioneer.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "pioneer_cli",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_templates", "**/README.md"]
templates_path = ["_templates"]

# Markdown: anchors for `page.md#a-heading` links, $…$ maths, ::: fences.
myst_heading_anchors = 4
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]

# The API reference: every module of the package, found by walking it when the site builds
# (the pages of a module since renamed or removed are dropped first).
shutil.rmtree(HERE / "reference" / "_api", ignore_errors=True)
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {
    "members": True,
    "show-inheritance": True,
    "member-order": "bysource",
    # A package's page documents what it defines; what it re-exports has its module's page.
    "ignore-module-all": True,
}
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
add_module_names = False
python_use_unqualified_type_names = True

# Moved research notes keep their own heading levels.
suppress_warnings = ["myst.header"]

# The docstrings write |x| for an absolute value or a norm, which reST reads as a
# substitution: escape a |…| whose bars touch their text (a table's bars stand apart).
_RST_SPECIAL = re.compile(r"([*_`|\\])")
_ABS = re.compile(r"(?<![\\|])\|(?=[^\s|])([^|\n`]*?[^\s|\\])\|(?!\|)")


def _escape_bars(app: Any, what: str, name: str, obj: Any, options: Any, lines: list[str]) -> None:
    if what == "attribute" and name.startswith("pioneer.cli."):
        # A command's option: its docstring is tyro's plain-text help (`general-*`), not reST.
        lines[:] = [_RST_SPECIAL.sub(r"\\\1", line) for line in lines]
        return
    literal_indent: int | None = None  # inside a literal block (after "::"): left as it is
    in_code = False  # inside an inline literal (``…``), which may run over lines
    for i, line in enumerate(lines):
        indent = len(line) - len(line.lstrip())
        if literal_indent is not None and line.strip() and indent <= literal_indent:
            literal_indent = None
        if literal_indent is None:
            parts = line.split("``")
            for k in range(len(parts)):
                if not in_code:
                    parts[k] = _ABS.sub(r"\\|\1\\|", parts[k])
                if k < len(parts) - 1:
                    in_code = not in_code
            lines[i] = "``".join(parts)
            if line.rstrip().endswith("::"):
                literal_indent = indent


def setup(app: Any) -> None:
    app.connect("autodoc-process-docstring", _escape_bars)


html_theme = "furo"
html_title = f"PioneeR {release}"
html_static_path: list[str] = []
html_show_sourcelink = False
pygments_style = "sphinx"
