"""Where runs execute: a :class:`concurrent.futures.Executor`, by default a
local process pool (ehm_drake.parallel), or a Dask distributed cluster given
its scheduler address, or any executor passed in; and the loop that feeds it
and collects the runs, with Ctrl-C handling.

Ctrl-C stops submitting, waits for the running runs and keeps them; a second
Ctrl-C abandons the running runs (a local pool's workers are stopped).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import os
import sys
from collections.abc import Callable, Iterator
from typing import Any

from ..parallel import process_pool
from .execute import STATUS_FAILED, execute_run
from .expand import RunSpec


def dask_client(address: str):
    """A client of the Dask scheduler at `address` (ValueError if unreachable)."""
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - dask is a test/extra dependency
        raise ValueError("--scheduler needs dask.distributed: pip install 'dask[distributed]'"
                         ) from None
    try:
        return Client(address, timeout="20s")
    except (OSError, TimeoutError) as e:
        raise ValueError(f"cannot connect to the Dask scheduler at {address}: {e}") from None


class Backend:
    """The executor of a sweep and what it takes to stop it."""

    def __init__(self, executor: cf.Executor, client: Any = None, own_pool=None,
                 max_workers: int | None = None):
        self.executor, self.client, self.own_pool = executor, client, own_pool
        self.max_workers = max_workers
        #: Set by drive on Ctrl-C: a pool of our own is then not waited for.
        self.interrupted = False

    def workers(self) -> int:
        """How many runs may be in flight (one per worker)."""
        if self.client is not None:
            try:
                return max(1, sum(self.client.nthreads().values()))
            except Exception:  # noqa: BLE001 - scheduler busy: keep a modest queue
                return 2
        n = getattr(self.executor, "_max_workers", None)
        return int(n or self.max_workers or os.cpu_count() or 1)

    def kill(self) -> None:
        """Stop a process pool of our own now (abandoning its runs)."""
        pool = self.own_pool
        if pool is None:
            return
        terminate = getattr(pool, "terminate_workers", None)  # Python >= 3.14
        if terminate is not None:
            terminate()
            return
        for p in list((getattr(pool, "_processes", None) or {}).values()):
            if p.is_alive():
                p.terminate()
        pool.shutdown(wait=False, cancel_futures=True)


@contextlib.contextmanager
def open_backend(n_runs: int, executor: cf.Executor | None = None,
                 scheduler: str | None = None, max_workers: int | None = None
                 ) -> Iterator[Backend | None]:
    """The backend for `n_runs` runs (None when there is nothing to run): the given
    executor, a Dask client's, or a local pool of min(max_workers or CPUs, n_runs)
    processes.  On exit a pool of our own is shut down (without waiting after Ctrl-C)
    and a Dask client closed."""
    if not n_runs:
        yield None
        return
    client = own_pool = None
    if scheduler is not None:
        client = dask_client(scheduler)
        executor = client.get_executor(pure=False)
    elif executor is None:
        own_pool = process_pool(min(max_workers or os.cpu_count() or 1, n_runs))
        executor = own_pool
    backend = Backend(executor, client, own_pool, max_workers)
    try:
        yield backend
    finally:
        if own_pool is not None:
            own_pool.shutdown(wait=not backend.interrupted, cancel_futures=True)
        if client is not None:
            client.close()


def drive(backend: Backend, todo: list[RunSpec],
          store: Callable[[RunSpec, dict[str, Any]], Any], tick: Callable[[], None],
          say: Callable[[str], None]) -> bool:
    """Submit the runs (no more in flight than there are workers), `store` each as it
    completes (a finished run or an executor error), `tick` about every second (for a
    progress display), `say` what happens on Ctrl-C.  Returns True if
    interrupted by Ctrl-C (then ``backend.interrupted`` is set too)."""
    executor = backend.executor
    queue = list(reversed(todo))
    running: dict[cf.Future, RunSpec] = {}
    interrupted = False

    def collect(done) -> None:
        for fut in done:
            run = running.pop(fut)
            if fut.cancelled():
                continue
            exc = fut.exception()
            if exc is None:
                store(run, fut.result())
            elif isinstance(exc, KeyboardInterrupt):
                continue  # interrupted, not finished: computed again on resume
            else:  # the executor failed (worker died, lost connection, ...)
                store(run, {"status": STATUS_FAILED, "error": {
                    "type": type(exc).__name__, "message": str(exc), "source": "executor"}})

    try:
        while queue or running:
            # No more in flight than there are workers: nothing waits in the
            # executor's queue, so Ctrl-C leaves only the running runs to finish.
            limit = backend.workers()
            while queue and len(running) < limit:
                try:
                    fut = executor.submit(execute_run, queue[-1].inputs())
                except (cf.BrokenExecutor, RuntimeError) as e:  # pool died / shut down
                    sys.stderr.write(f"\nsweep: the executor cannot run more ({type(e).__name__}"
                                     f": {e}); {len(queue)} run(s) not started; run the "
                                     "sweep again to resume\n")
                    queue.clear()
                    break
                running[fut] = queue.pop()
            done, _ = cf.wait(list(running), timeout=1.0, return_when=cf.FIRST_COMPLETED)
            collect(done)
            tick()
    except KeyboardInterrupt:
        interrupted = backend.interrupted = True
        for fut in running:
            fut.cancel()
        active = [f for f in running if not f.cancelled()]
        say(f"interrupted: no new runs; waiting for {len(active)} running run(s) to "
            "finish (Ctrl-C again to abandon them)")
        try:
            collect([f for f in running if f.cancelled()])
            while running:
                done, _ = cf.wait(list(running), timeout=1.0, return_when=cf.FIRST_COMPLETED)
                collect(done)
        except KeyboardInterrupt:
            say(f"abandoning {len(running)} running run(s)")
            backend.kill()
    return interrupted
