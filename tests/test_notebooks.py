"""The tutorial notebooks in ``notebooks/``: executed, saved clean, public API only.

Every ``notebooks/*.ipynb`` (a notebook added later is picked up automatically) is

* executed with nbclient in its short *test mode*: the first code cell reads
  ``test_mode = os.environ.get("EHM_NOTEBOOK_TEST_MODE") == "1"`` and shortens every run;
  the kernel gets ``EHM_NOTEBOOK_TEST_MODE=1`` and ``MPLBACKEND=Agg`` and runs in a scratch
  folder, so the files a notebook writes land there and not in the repository;
* checked to be saved with its outputs cleared (no outputs, no execution counts);
* checked to use only the public API: no ``from ehm_drake... import _name``, no import of a
  private module, and no ``._name`` attribute (private attributes of ehm_drake objects, or
  of any other library, are not something a tutorial should teach).
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import nbformat
import pytest

NOTEBOOK_DIR = Path(__file__).resolve().parent.parent / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
#: Per-cell time limit of the test-mode execution (s).
CELL_TIMEOUT_S = 300
KERNEL_NAME = "python3"
TEST_MODE_LINE = re.compile(
    r"""test_mode\s*=\s*os\.environ\.get\(\s*["']EHM_NOTEBOOK_TEST_MODE["']\s*\)"""
    r"""\s*==\s*["']1["']"""
)


def _read(path: Path):
    return nbformat.read(path, as_version=nbformat.NO_CONVERT)


def _code_cells(nb) -> list:
    return [c for c in nb.cells if c.cell_type == "code"]


def _python_source(source: str) -> str:
    """Cell source with IPython magics and shell escapes replaced by `pass` (same indent)."""
    lines = []
    for line in source.splitlines():
        stripped = line.lstrip()
        if stripped.startswith(("%", "!")):
            line = line[: len(line) - len(stripped)] + "pass"
        lines.append(line)
    return "\n".join(lines)


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_uses(source: str) -> list[str]:
    """Private names a code cell uses: imports from ehm_drake and ``._name`` attributes."""
    found = []
    for node in ast.walk(ast.parse(_python_source(source))):
        if isinstance(node, ast.ImportFrom) and node.module and (
                node.module.split(".")[0] == "ehm_drake"):
            if any(_is_private(part) for part in node.module.split(".")):
                found.append(f"line {node.lineno}: from {node.module} import ...")
            found += [f"line {node.lineno}: from {node.module} import {alias.name}"
                      for alias in node.names if _is_private(alias.name)]
        elif isinstance(node, ast.Import):
            found += [f"line {node.lineno}: import {alias.name}" for alias in node.names
                      if alias.name.split(".")[0] == "ehm_drake"
                      and any(_is_private(part) for part in alias.name.split("."))]
        elif isinstance(node, ast.Attribute) and _is_private(node.attr):
            found.append(f"line {node.lineno}: attribute .{node.attr}")
    return found


def test_notebooks_present():
    assert NOTEBOOKS, f"no notebooks found in {NOTEBOOK_DIR}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_saved_clean(path):
    nb = _read(path)
    assert nb.nbformat == 4, f"{path.name}: nbformat {nb.nbformat}, expected 4"
    nbformat.validate(nb)
    dirty = [i for i, cell in enumerate(nb.cells) if cell.cell_type == "code"
             and (cell.get("outputs") or cell.get("execution_count") is not None)]
    assert not dirty, (f"{path.name}: cells {dirty} have outputs or execution counts; clear "
                       "them before saving (e.g. jupyter nbconvert --clear-output --inplace)")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_reads_test_mode_first(path):
    cells = _code_cells(_read(path))
    assert cells, f"{path.name}: no code cell"
    assert TEST_MODE_LINE.search(cells[0].source), (
        f"{path.name}: the first code cell must read test_mode = "
        'os.environ.get("EHM_NOTEBOOK_TEST_MODE") == "1" and shorten the runs with it')


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_uses_public_api_only(path):
    problems = []
    for i, cell in enumerate(_code_cells(_read(path))):
        problems += [f"code cell {i}, {p}" for p in private_uses(cell.source)]
    assert not problems, f"{path.name} uses private names:\n" + "\n".join(problems)


def test_private_use_detection():
    assert private_uses("from ehm_drake.sweep import _second_difference")
    assert private_uses("from ehm_drake._impl import thing")
    assert private_uses("import ehm_drake.analysis._x as x")
    assert private_uses("import ehm_drake.sweep as s\ns._second_difference(y, 200.0)")
    assert private_uses("if x:\n    %matplotlib inline\n    y = frf._take(idx)")
    assert not private_uses("from ehm_drake.sweep import run_sweep\nx = obj.__class__")


def test_python3_kernel_runs_this_interpreter():
    """The kernel must be this interpreter (with ehm_drake installed): jupyter_client runs
    a spec whose command is plain `python`/`python3` with sys.executable, and without a
    spec ipykernel's built-in one (sys.executable too)."""
    from jupyter_client.kernelspec import KernelSpecManager

    argv0 = KernelSpecManager().get_kernel_spec(KERNEL_NAME).argv[0]
    major, minor = sys.version_info[:2]
    assert argv0 in ("python", f"python{major}", f"python{major}.{minor}", sys.executable), (
        f"kernel spec {KERNEL_NAME!r} runs {argv0}, not this interpreter ({sys.executable}); "
        f"reinstall it: {sys.executable} -m ipykernel install --sys-prefix")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_in_test_mode(path, tmp_path, monkeypatch):
    from nbclient import NotebookClient

    # The kernel inherits this environment.
    monkeypatch.setenv("EHM_NOTEBOOK_TEST_MODE", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(nb, timeout=CELL_TIMEOUT_S, kernel_name=KERNEL_NAME,
                            resources={"metadata": {"path": str(tmp_path)}})
    client.execute()  # raises CellExecutionError with the cell's traceback
    errors = [o for cell in _code_cells(nb) for o in cell.outputs if o.output_type == "error"]
    assert not errors
