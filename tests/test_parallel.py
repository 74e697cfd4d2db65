"""Process pools (`ehm_drake.parallel`): results in order, workers that see
the caller's environment as it is when the pool is made, (on a platform
with a fork server) workers that start with the package already imported,
and workers that end when their caller is killed."""

from __future__ import annotations

import multiprocessing
import os
import sys

import pytest

from ehm_drake.parallel import PRELOAD, _gone, run_jobs


def _worker_view(name: str) -> tuple:
    """(the variable `name` in the worker's environment, its pid, the
    preloaded modules it had before this job ran)."""
    return os.environ.get(name), os.getpid(), sorted(m for m in PRELOAD if m in sys.modules)


def _blas_threads(_=None) -> list[int]:
    from threadpoolctl import threadpool_info

    return sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})


def test_blas_runs_one_thread_in_the_caller_and_in_the_workers():
    """A multi-threaded BLAS rounds sums differently from one thread, so a
    diagnosis' refit would change in its eighth digit with the machine's
    thread count; the package pins it, workers included."""
    assert _blas_threads() == [1]
    assert run_jobs([(_blas_threads, None)] * 2, workers=2) == [[1], [1]]


def test_the_blas_thread_count_is_the_users_to_change():
    import subprocess

    code = ("import ehm_drake, threadpoolctl; print(sorted({i['num_threads'] for i in "
            "threadpoolctl.threadpool_info() if i['user_api'] == 'blas'}))")
    env = dict(os.environ, EHM_DRAKE_BLAS_THREADS="2")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True).stdout
    assert out.strip() == "[2]"
    env["EHM_DRAKE_BLAS_THREADS"] = "two"
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert r.returncode != 0
    assert "EHM_DRAKE_BLAS_THREADS='two': expected a whole number" in r.stderr


def test_results_come_back_in_order_from_other_processes():
    out = run_jobs([(abs, -k) for k in range(7)], workers=2)
    assert out == list(range(7))
    views = run_jobs([(_worker_view, "PATH")] * 4, workers=2)
    assert all(pid != os.getpid() for _, pid, _ in views)


def test_workers_see_the_environment_of_the_moment(monkeypatch):
    """A fork server's workers would otherwise keep the environment of the
    first pool (the cache location, for example)."""
    monkeypatch.setenv("EHM_PARALLEL_PROBE", "first")
    assert {v for v, _, _ in run_jobs([(_worker_view, "EHM_PARALLEL_PROBE")] * 2,
                                      workers=2)} == {"first"}
    monkeypatch.setenv("EHM_PARALLEL_PROBE", "second")
    assert {v for v, _, _ in run_jobs([(_worker_view, "EHM_PARALLEL_PROBE")] * 2,
                                      workers=2)} == {"second"}
    monkeypatch.delenv("EHM_PARALLEL_PROBE")
    assert {v for v, _, _ in run_jobs([(_worker_view, "EHM_PARALLEL_PROBE")] * 2,
                                      workers=2)} == {None}


@pytest.mark.skipif("forkserver" not in multiprocessing.get_all_start_methods(),
                    reason="no fork server on this platform (workers are spawned)")
def test_workers_start_with_the_package_imported():
    """Forked from a server that imported `PRELOAD` once: no worker imports
    Drake and the package afresh (1-2 s of CPU each when spawned)."""
    for _, _, modules in run_jobs([(_worker_view, "PATH")] * 2, workers=2):
        assert modules == sorted(PRELOAD)


_CALLER = """
import os, sys, time
from pathlib import Path


def job(folder):
    (Path(folder) / str(os.getpid())).write_text("")
    time.sleep(60)


if __name__ == "__main__":
    from ehm_drake import parallel

    if sys.argv[2] == "spawn":
        parallel.multiprocessing.get_all_start_methods = lambda: ["spawn"]
    parallel.PRELOAD = ["numpy"]  # (a light fork server: this test is about the workers)
    parallel.run_jobs([(job, sys.argv[1])] * 2, workers=2)
"""


def _alive(pid: int) -> bool:
    return not _gone(pid)


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc")
@pytest.mark.parametrize("method", ["forkserver", "spawn"])
def test_workers_end_when_their_caller_is_killed(tmp_path, method):
    """A caller killed outright (SIGKILL: a scheduler's limit, a Jupyter
    kernel restarted) cannot shut its pool down; its workers, each in a
    60 s job, end within a few seconds anyway instead of computing on and
    then waiting for work forever.  The caller stays unreaped meanwhile (a
    zombie, as under a parent that reaps late): dead all the same."""
    import signal
    import subprocess
    import time

    if method not in multiprocessing.get_all_start_methods():
        pytest.skip(f"no {method} on this platform")
    script = tmp_path / "caller.py"
    script.write_text(_CALLER)
    pids = tmp_path / "pids"
    pids.mkdir()
    caller = subprocess.Popen([sys.executable, str(script), str(pids), method])
    try:
        deadline = time.monotonic() + 60
        while len(list(pids.iterdir())) < 2:
            assert caller.poll() is None, "the caller ended before its workers started"
            assert time.monotonic() < deadline, "the workers did not start in 60 s"
            time.sleep(0.1)
        workers = [int(p.name) for p in pids.iterdir()]
        assert all(_alive(p) for p in workers)
    finally:
        # Killed and left unreaped for now: a zombie counts as gone.
        caller.send_signal(signal.SIGKILL)
    deadline = time.monotonic() + 10
    while any(_alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [p for p in workers if _alive(p)]
    caller.wait()
    for p in left:  # (do not leave them behind when the test fails)
        os.kill(p, signal.SIGKILL)
    assert not left, f"workers {left} outlived their killed caller"


_UNGUARDED = """
from ehm_drake.gap.single.diagnose import load_families
from ehm_drake.model.anthropometry import REFERENCE
from ehm_drake.params import load_params

# No `if __name__ == "__main__":` guard: each worker re-runs this line.
load_families(load_params(), REFERENCE, ["reflex_delay"], ["lumbar_stiffness"], workers=2)
"""


@pytest.mark.skipif(os.name != "posix", reason="the cache's lock is POSIX's")
def test_an_unguarded_script_fails_clearly_instead_of_waiting_forever(tmp_path):
    """A script that builds the linear families at its top level, with no
    entry-point guard: its workers re-run that line while the script holds
    the cache's lock.  It ends with an error that names the guard (it waited
    forever before: the workers for the lock, the script for its workers)."""
    import subprocess

    script = tmp_path / "unguarded.py"
    script.write_text(_UNGUARDED)
    env = {**os.environ, "EHM_DRAKE_CACHE": str(tmp_path / "cache")}
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=300, env=env, cwd=tmp_path)
    assert run.returncode != 0
    assert 'if __name__ == "__main__":' in run.stderr
    assert "worker process" in run.stderr
