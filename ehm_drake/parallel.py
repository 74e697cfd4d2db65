"""Process pools for the parallel parts (fits, linearizations, synthetic
labs, diagnoses, sweeps).

Workers are never forked from the calling process: forking a process that
already runs threads (a Jupyter kernel, pytest-xdist, Drake's own) can copy
a held lock into the child, which then waits forever (seen as a hung `fit`).
Where the platform has it (Linux, macOS) they are forked from a *fork
server*: a fresh, single-threaded interpreter that imports the package once
(`PRELOAD`) and forks every worker from there.  The first pool of a process
waits for those imports (~2 s); every later pool has its workers running in
~0.05 s, where spawned workers (*spawn* is the fallback elsewhere) import
Drake, SciPy and the package afresh, ~1-2 s of CPU each (a short blind run
starts 16).  Each worker takes the caller's environment as it is
when the pool is made (as a spawned one would), ignores Ctrl-C, which the
parent handles by cancelling what is pending, and ends itself within about a
second once the caller is gone (killed, it could not shut its pool down).
Scripts that use these functions must guard their entry point (``if
__name__ == "__main__":``), as for any spawn-based multiprocessing.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import signal
import threading
import time


def ignore_sigint(*_args) -> None:
    """Worker initializer: Ctrl-C is the parent's to handle."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


#: What the fork server imports once for all its workers (what the pools'
#: jobs use; anything else a job needs is imported in its worker).
PRELOAD = ["numpy", "scipy.optimize", "scipy.signal", "ehm_drake.diagram",
           "ehm_drake.simulation", "ehm_drake.analysis.linear", "ehm_drake.gap.single.diagnose",
           "ehm_drake.gap.lab.synth", "ehm_drake.identification.fit"]


#: How often a worker checks that the process that made its pool is alive.
PARENT_CHECK_S = 1.0


def _exit_with_parent(pid: int) -> None:
    """Worker side: end this worker once process `pid` (the caller that
    made the pool) is gone.  Killed rather than interrupted (a scheduler's
    time limit, a Jupyter kernel restarted, `kill`), the caller cannot shut
    its pool down, and a worker of a `ProcessPoolExecutor` never notices on
    its own: it finishes its job and then waits for the next one forever
    (checked: after the caller got SIGTERM, both spawned and fork-server
    workers were still there half an hour later, one still computing)."""
    if os.name != "posix":  # (os.kill(pid, 0) would terminate it on Windows)
        return

    def watch():
        while not _gone(pid):
            time.sleep(PARENT_CHECK_S)
        os._exit(1)

    threading.Thread(target=watch, name="ehm_drake-parent-watch", daemon=True).start()


def _gone(pid: int) -> bool:
    """Process `pid` has ended: no such process, one of another user (the
    pid reused), or a zombie (dead, not yet reaped by its own parent)."""
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, PermissionError):
        return True
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[-1].split()[0] == "Z"
    except OSError:  # no /proc (macOS): the signal's answer stands
        return False


def _init(initializer, initargs, environ: dict, parent: int) -> None:
    ignore_sigint()
    _exit_with_parent(parent)
    if environ != dict(os.environ):
        # A fork server's worker has the server's environment (that of the
        # first pool); the caller's may have changed since.
        os.environ.clear()
        os.environ.update(environ)
    if initializer is not None:
        initializer(*initargs)


#: Threads for the BLAS/LAPACK library under NumPy and SciPy (an
#: environment variable, read at import): 1 unless set.  A multi-threaded
#: BLAS splits sums across threads and rounds differently from one thread
#: (about 1e-8 relative in a diagnosis' refit), so results would depend on
#: the machine's thread configuration; and the model's matrices (tens of
#: states) are too small for threads to pay: a diagnosis' candidate fit is
#: ~15% faster on one.  The pools give every core a process instead.
BLAS_THREADS_VARIABLE = "EHM_DRAKE_BLAS_THREADS"


def pin_blas_threads() -> int | None:
    """Limit the BLAS of NumPy and SciPy to `$EHM_DRAKE_BLAS_THREADS` threads (default 1;
    ``0`` leaves the library's own choice) in this process and the pools'
    workers, which import the package.  Returns the limit applied."""
    raw = os.environ.get(BLAS_THREADS_VARIABLE, "1").strip()
    try:
        n = int(raw)
    except ValueError:
        n = -1
    if n < 0:
        raise ValueError(f"${BLAS_THREADS_VARIABLE}={raw!r}: expected a whole number of "
                         "threads (0 leaves the BLAS library's own choice)")
    if n == 0:
        return None
    # Load the BLAS libraries first (NumPy's, and SciPy's own in its wheels):
    # threadpoolctl limits the ones loaded when it is called.
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_limits

    threadpool_limits(n, user_api="blas")
    return n


def check_not_starting_worker(what: str) -> None:
    """Raise a clear error when `what` is called while this process starts
    as a pool worker.  A worker re-runs the top level of the script that
    made its pool; in a script without an ``if __name__ == "__main__":``
    guard that top level calls the package again, which could wait forever
    on a lock the script holds (the linear families' cache) instead of
    failing."""
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        raise RuntimeError(
            f"{what} was called while a worker process was starting: the script "
            "that uses ehm_drake's parallel functions must guard its entry point with "
            "`if __name__ == \"__main__\":` (each worker re-runs the script's top level)")


def worker_count(workers: int | None = None) -> int:
    """`workers`, or the machine's cores; between 1 and 8."""
    return max(1, min(workers or (os.cpu_count() or 1), 8))


def process_pool(workers: int, initializer=None, initargs=()) -> cf.ProcessPoolExecutor:
    """A pool (fork server, or spawn where there is none) whose workers
    take the caller's environment, ignore SIGINT, end with the caller and
    then run `initializer(*initargs)`."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
    else:
        ctx = multiprocessing.get_context("spawn")
    return cf.ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init,
                                  initargs=(initializer, initargs, dict(os.environ),
                                            os.getpid()))


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
            try:
                results[i] = f.result()
            except cf.process.BrokenProcessPool as e:
                raise RuntimeError(
                    "a worker process ended abruptly (killed, out of memory, or started "
                    "by a script without an `if __name__ == \"__main__\":` guard, whose "
                    "top level each worker re-runs)") from e
            if progress:
                progress(done, len(jobs), i, results[i])
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
    return results
