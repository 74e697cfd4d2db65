"""Process pools (`ehm_drake.parallel`): results in order, workers that see
the caller's environment as it is when the pool is made, and (on a platform
with a fork server) workers that start with the package already imported."""

from __future__ import annotations

import multiprocessing
import os
import sys

import pytest

from ehm_drake.parallel import PRELOAD, run_jobs


def _worker_view(name: str) -> tuple:
    """(the variable `name` in the worker's environment, its pid, the
    preloaded modules it had before this job ran)."""
    return os.environ.get(name), os.getpid(), sorted(m for m in PRELOAD if m in sys.modules)


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
