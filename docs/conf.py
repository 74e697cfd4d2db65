"""Sphinx configuration of the ehm_drake documentation (`sphinx-build -W docs docs/_build`).

The pages are Markdown (MyST); the API reference is generated from the docstrings; the
tutorials are the notebooks of `notebooks/`, copied into `tutorials/` when the build starts
(shown as stored, without running them: the test suite runs each one in its test mode)."""

import shutil
from pathlib import Path

_HERE = Path(__file__).resolve().parent
_TUTORIALS = _HERE / "tutorials"
shutil.rmtree(_TUTORIALS, ignore_errors=True)
_TUTORIALS.mkdir()
for _nb in sorted((_HERE.parent / "notebooks").glob("*.ipynb")):
    shutil.copy2(_nb, _TUTORIALS / _nb.name)

project = "ehm_drake"
author = "the ehm_drake developers"
# myst_nb reads the Markdown pages (it includes myst_parser) and the notebooks.
extensions = ["sphinx.ext.autodoc", "sphinx.ext.napoleon", "sphinx.ext.mathjax", "myst_nb"]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
nb_execution_mode = "off"
root_doc = "index"
exclude_patterns = ["_build", "make_figures.py"]
autodoc_member_order = "bysource"
autodoc_typehints = "none"  # the signatures carry them; Drake's types do not resolve
# Short attribute names (`label`, `mass`, `seat`) exist on several classes; an
# unqualified reference to one is left unlinked rather than guessed.
suppress_warnings = ["ref.python"]
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]
html_theme = "alabaster"


def _escape_bars(app, what, name, obj, options, lines):
    """The docstrings write absolute values and norms as |x| (plain text, readable in
    `help()`); reStructuredText would read them as substitutions. Escape every bar outside
    ``literals`` and literal blocks."""
    import re

    literal_indent = None
    for i, line in enumerate(lines):
        indent = len(line) - len(line.lstrip())
        if literal_indent is not None:
            if line.strip() and indent <= literal_indent:
                literal_indent = None
            else:
                continue
        parts = re.split(r"(``.*?``)", line)
        lines[i] = "".join(p if p.startswith("``") else p.replace("|", r"\|") for p in parts)
        if line.rstrip().endswith("::"):
            literal_indent = indent


def setup(app):
    app.connect("autodoc-process-docstring", _escape_bars)
