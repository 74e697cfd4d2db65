"""The package's structure: one room per idea, no import cycles, no module
over 700 lines, and the shared progress helper's behaviour."""

from __future__ import annotations

import ast
import io
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from ehm_drake.progress import Progress

PACKAGE = Path(__file__).resolve().parents[1] / "ehm_drake"
MAX_LINES = 700


def _modules() -> dict[str, Path]:
    out = {}
    for p in sorted(PACKAGE.rglob("*.py")):
        parts = p.relative_to(PACKAGE.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _resolve(module: str, node: ast.ImportFrom, is_package: bool) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    base = base if is_package else base[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _import_graph() -> dict[str, set[str]]:
    """Module -> package modules it imports, imports inside functions
    included: one there cannot close a cycle at import time, but it hides
    a circle in the design all the same (two modules that need each other
    are one idea, or a third one is missing)."""
    mods = _modules()
    graph = {}
    for name, path in mods.items():
        deps = set()
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                src = _resolve(name, node, is_pkg)
                targets = [src] + [f"{src}.{a.name}" for a in node.names]
            else:
                continue
            deps |= {t for t in targets if t in mods and t != name}
        graph[name] = deps
    return graph


def test_every_package_is_installed():
    """A non-editable install (the quick start, CI) ships only the packages
    pyproject.toml lists: a new sub-package left out imports in a checkout
    and fails after `pip install .`."""
    import tomllib

    listed = set(tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())
                 ["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(PACKAGE.parent).parts)
             for p in PACKAGE.rglob("__init__.py")}
    assert found - listed == set()


def test_no_module_is_longer_than_700_lines():
    long = {n: len(p.read_text().splitlines()) for n, p in _modules().items()}
    assert {n: k for n, k in long.items() if k > MAX_LINES} == {}


def test_the_import_graph_has_no_cycle():
    graph = _import_graph()
    state: dict[str, int] = {}  # 1 on the stack, 2 done

    def visit(n, stack):
        state[n] = 1
        for d in sorted(graph[n]):
            # A package's __init__ importing its own submodules is not a
            # cycle; a submodule importing its package's __init__ is.
            if state.get(d) == 1 and not n.startswith(d + "."):
                cycle = stack[stack.index(d):] + [d]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if d not in state:
                visit(d, stack + [d])
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n, [n])
    # The checker sees the imports it must see.
    assert "ehm_drake.cli_common" in graph["ehm_drake.cli"]


def test_command_modules_share_helpers_from_below():
    graph = _import_graph()
    assert "ehm_drake.cli" not in graph["ehm_drake.gap.commands"]
    assert graph["ehm_drake.cli_common"] == set()


#: The third-party libraries the package imports.  `_IMPORTER` loads them once
#: (single-threaded BLAS: nothing runs beside the main thread when it forks),
#: then forks one child per package module, which imports that module first.
_THIRD_PARTY = ("numpy", "scipy.optimize", "scipy.signal", "scipy.stats", "scipy.interpolate",
                "yaml", "matplotlib.pyplot", "pydrake.all")
_IMPORTER = """
import importlib, os, sys, traceback
for lib in sys.argv[1].split(","):
    importlib.import_module(lib)
assert not any(m.split(".")[0] == "ehm_drake" for m in sys.modules)
bad = []
for name in sys.argv[2:]:
    pid = os.fork()
    if pid == 0:
        try:
            importlib.import_module(name)
        except BaseException:
            traceback.print_exc()
            os._exit(1)
        os._exit(0)
    if os.waitpid(pid, 0)[1] != 0:
        bad.append(name)
print(" ".join(bad))
"""


@pytest.mark.slow
def test_every_module_imports_alone():
    """Each module imported first in an interpreter that holds none of the
    package (the order-dependent failures a cycle causes show up only this
    way): forked from a parent that loaded the third-party libraries once
    (a fresh interpreter per module where there is no fork)."""
    names = list(_modules())
    assert len(names) > 40
    if hasattr(os, "fork"):
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")

        def run(chunk):
            r = subprocess.run([sys.executable, "-c", _IMPORTER, ",".join(_THIRD_PARTY),
                                *chunk], capture_output=True, text=True, env=env)
            assert r.returncode == 0, r.stderr[-2000:]
            return r.stdout.split(), r.stderr

        with ThreadPoolExecutor(2) as pool:
            out = list(pool.map(run, [names[0::2], names[1::2]]))
        bad = [n for failed, _ in out for n in failed]
        assert bad == [], f"{bad} fail when imported first:\n" + \
            "\n".join(err for _, err in out)[-4000:]
        return

    def run_one(name):
        r = subprocess.run([sys.executable, "-c", f"import {name}"], capture_output=True,
                           text=True)
        return name, r.returncode, r.stderr.strip().splitlines()[-1:] if r.stderr else []

    with ThreadPoolExecutor(2) as pool:
        bad = [(n, err) for n, rc, err in pool.map(run_one, names) if rc != 0]
    assert bad == []


def test_xdist_groups_keep_their_tests_on_one_worker(request):
    """The modules with expensive module fixtures (blind runs, fits) mark
    themselves `xdist_group` so that the fixture is built once.  pytest-xdist
    tags a grouped test by editing its node id; where the installed pytest
    ignores that edit (9.2 with xdist 3.8), the groups are spread over the
    workers and each fixture is built again (CI: +130 s)."""
    if not (hasattr(request.config, "workerinput")
            and request.config.getoption("loadgroup", False)):
        pytest.skip("not running under pytest-xdist --dist loadgroup")
    grouped = [it for it in request.session.items if it.get_closest_marker("xdist_group")]
    if not grouped:
        pytest.skip("no grouped test selected")
    untagged = [it.nodeid for it in grouped if "@" not in it.nodeid]
    assert untagged == []


# ---------------------------------------------------------------------------
# Progress
# ---------------------------------------------------------------------------


class _Log(io.StringIO):
    def isatty(self):
        return False


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_progress_in_a_log_writes_a_line_per_tenth_and_per_step():
    log = _Log()
    p = Progress("job", 100, stream=log)
    for i in range(1, 101):
        p.update(i)
    lines = log.getvalue().splitlines()
    assert len(lines) == 11  # the start (1 %), then 10 %, 20 %, ..., 100 %
    assert "  1.0%" in lines[0] and " 10.0%" in lines[1]
    assert lines[-1].startswith("job: [") and "100.0%" in lines[-1]
    log = _Log()
    p = Progress("runs", 3, stream=log, unit="runs")
    p.step("first")
    assert log.getvalue().splitlines()[-1].startswith("runs: [")
    assert "1/3 runs" in log.getvalue() and "first" in log.getvalue()


def test_progress_eta_counts_only_this_calls_work():
    p = Progress("blind", 10, enabled=False)
    for _ in range(6):
        p.skip()  # reused from an earlier run: no time
    assert p.eta() is None  # nothing ran yet: no rate
    p.t0 -= 10.0  # 10 s for the one trial run now
    p._rate_t0 -= 10.0
    p.step()
    assert p.done == 7
    assert p.eta() == pytest.approx(30.0, rel=0.01)  # 3 left at 10 s each


def test_progress_leaves_one_off_setup_out_of_the_rate():
    """A blind run's first trial against a reference group also calibrates
    the group (tens of minutes; then a few per trial): after `setup_done`
    the time left comes from the units after it."""
    p = Progress("blind", 30, enabled=False)
    p.t0 -= 1800.0
    p._rate_t0 -= 1800.0
    p.step()  # the first trial, with the calibration
    assert p.eta() == pytest.approx(29 * 1800.0, rel=0.01)
    p.setup_done()
    assert p.eta() is None and p.elapsed > 1800.0  # the elapsed time is kept
    p._rate_t0 -= 120.0
    p.step()
    assert p.eta() == pytest.approx(28 * 120.0, rel=0.01)


def test_progress_on_a_terminal_redraws_in_place_and_keeps_messages_apart():
    tty = _Tty()
    p = Progress("simulate", 2.0, stream=tty)
    p.update(1.0)
    assert tty.getvalue().startswith("\rsimulate: [") and not tty.getvalue().endswith("\n")
    p.say("settled")
    assert tty.getvalue().endswith("\nsimulate: settled\n")
    p.update(2.0)
    assert tty.getvalue().endswith("\n")


def test_quiet_progress_writes_nothing():
    log = _Log()
    p = Progress("x", 5, enabled=False, stream=log)
    p.update(5)
    p.step()
    p.say("hello")
    p.close()
    assert log.getvalue() == ""


def test_the_systems_find_a_templates_module_as_pydrake_does():
    """`ehm_drake.systems` replaces pydrake's `_get_module_from_stack` (which
    reads the source of every frame on the stack: 0.7 s of importing the
    systems) by a lookup in the frame's globals; both name the same module,
    from a test function's frame and from a converted system's methods."""
    from pydrake.common import cpp_template

    import ehm_drake.systems as systems
    from ehm_drake.systems.forces import ForceLaws_

    assert cpp_template._get_module_from_stack is systems._module_of_frame

    def probe():
        return systems._module_of_frame(1), systems._module_from_stack(1)

    fast, slow = probe()
    assert fast is slow is sys.modules[__name__]
    # What the lookup serves: the scalar-conversion methods of an instantiation.
    from pydrake.autodiffutils import AutoDiffXd

    cls = ForceLaws_[AutoDiffXd]
    assert cls.ToScalarType._scope is sys.modules["pydrake.systems.scalar_conversion"]
