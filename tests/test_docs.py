"""The documentation site: it builds with warnings as errors, its API reference covers
every module of the package and its tutorials are the notebooks."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _modules() -> set[str]:
    out = set()
    for p in (ROOT / "ehm_drake").rglob("*.py"):
        parts = p.relative_to(ROOT).with_suffix("").parts
        out.add(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return out


def test_the_api_reference_covers_every_module():
    listed = set(re.findall(r"automodule:: (\S+)", (ROOT / "docs" / "api.md").read_text()))
    assert listed == _modules(), (sorted(_modules() - listed), sorted(listed - _modules()))


def test_every_notebook_is_a_tutorial_of_the_site():
    index = (ROOT / "docs" / "index.md").read_text()
    listed = set(re.findall(r"^tutorials/(\S+)$", index, re.M))
    assert listed == {p.stem for p in (ROOT / "notebooks").glob("*.ipynb")}


@pytest.mark.slow
def test_the_documentation_builds_without_a_warning(tmp_path):
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_nb")
    r = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                        "-d", str(tmp_path / "doctrees"), str(ROOT / "docs"),
                        str(tmp_path / "html")], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    html = (tmp_path / "html" / "api.html").read_text()
    # The docstrings are there, not only the headings.
    index = (tmp_path / "html" / "index.html").read_text()
    assert "static_equilibrium" in html and "Desai" in index
    # Each notebook is a page with its narrative and its code.
    for nb in (ROOT / "notebooks").glob("*.ipynb"):
        page = (tmp_path / "html" / "tutorials" / f"{nb.stem}.html").read_text()
        assert re.search(r"highlight-(ipython3|python3?)\b", page) and "ehm_drake" in page, \
            nb.name
