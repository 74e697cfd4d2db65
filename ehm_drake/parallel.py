"""Process pools for the parallel parts (fits, linearizations, synthetic
labs, diagnoses, sweeps).

Workers are *spawned*, not forked: forking a process that already runs
threads (a Jupyter kernel, pytest-xdist, Drake's own) can copy a held lock
into the child, which then waits forever (seen as a hung `fit`).  Spawned
workers import the package afresh (~1-2 s) and ignore Ctrl-C, which the
parent handles by cancelling what is pending.  Scripts that use these
functions must guard their entry point (``if __name__ == "__main__":``), as
for any spawn-based multiprocessing.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import signal


def ignore_sigint(*_args) -> None:
    """Worker initializer: Ctrl-C is the parent's to handle."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _init(initializer, initargs) -> None:
    ignore_sigint()
    if initializer is not None:
        initializer(*initargs)


def worker_count(workers: int | None = None) -> int:
    """`workers`, or the machine's cores; between 1 and 8."""
    return max(1, min(workers or (os.cpu_count() or 1), 8))


def process_pool(workers: int, initializer=None, initargs=()) -> cf.ProcessPoolExecutor:
    """A spawn-context pool whose workers ignore SIGINT and then run
    `initializer(*initargs)`."""
    return cf.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                  initializer=_init, initargs=(initializer, initargs))


def run_jobs(jobs, workers: int | None = None, progress=None, initializer=None,
             initargs=()) -> list:
    """Run [(function, argument)] on a pool (inline with one worker) and
    return the results in order; `progress(done, total, index, result)`
    after each.  On Ctrl-C the pending jobs are cancelled and
    KeyboardInterrupt raised."""
    jobs = list(jobs)
    nwork = min(worker_count(workers), max(len(jobs), 1))
    results = [None] * len(jobs)
    if nwork <= 1:
        if initializer is not None:
            initializer(*initargs)
        for i, (fn, arg) in enumerate(jobs):
            results[i] = fn(arg)
            if progress:
                progress(i + 1, len(jobs), i, results[i])
        return results
    pool = process_pool(nwork, initializer, initargs)
    try:
        futs = {pool.submit(fn, arg): i for i, (fn, arg) in enumerate(jobs)}
        for done, f in enumerate(cf.as_completed(futs), 1):
            i = futs[f]
            results[i] = f.result()
            if progress:
                progress(done, len(jobs), i, results[i])
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
    return results
