"""run_sweep: a spec into an output folder -- expand the runs, reuse the stored
ones, run the rest on a back end, write the summary."""

from __future__ import annotations

import concurrent.futures as cf
import json
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..progress import Progress
from .backends import drive, open_backend
from .expand import RunSpec, expand_runs
from .spec import SweepSpec, load_sweep_spec
from .store import RunStore, SweepResult, atomic_write
from .summary import write_summary


def run_sweep(spec: SweepSpec | Mapping[str, Any] | str | Path, out_dir: str | Path,
              executor: cf.Executor | None = None, scheduler: str | None = None,
              max_workers: int | None = None, progress: bool = True, force: bool = False,
              retry_failed: bool = False) -> SweepResult:
    """Run a sweep into `out_dir`, resuming what an earlier run of it finished.

    Parameters
    ----------
    spec : a SweepSpec, a spec mapping or the path of a spec file.
    out_dir : output folder (created); see the package doc for its content.
    executor : a concurrent.futures.Executor to use (not shut down here).
    scheduler : address of a Dask distributed scheduler (``tcp://host:8786``); the runs
        go to its workers (they need ehm_drake installed; results come back to this
        process, which writes every file).
    max_workers : size of the local process pool (default: the number of CPUs).
    progress : show runs done/total, failures and ETA on stderr.
    force : recompute runs that are already stored.
    retry_failed : recompute runs stored as failed.

    Returns
    -------
    SweepResult
        ``interrupted`` is True after Ctrl-C (finished runs are kept; run again to
        resume).
    """
    spec = load_sweep_spec(spec)
    if executor is not None and scheduler is not None:
        raise ValueError("give either executor or scheduler, not both")
    if max_workers is not None and (isinstance(max_workers, bool)
                                    or not isinstance(max_workers, int) or max_workers < 1):
        raise ValueError(f"max_workers must be a positive integer, got {max_workers!r}")
    runs = expand_runs(spec)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"sweep output {out} exists and is not a folder")
    store = RunStore(out)
    atomic_write(out / "sweep_spec.json", json.dumps(spec.to_dict(), indent=2))

    t0 = time.perf_counter()
    todo, n_unique = store.to_compute(runs, force, retry_failed)
    prog = Progress("sweep", total=n_unique, enabled=progress, start=len(store.reused),
                    unit="runs")

    def note() -> str:
        return f"{len(store.reused)} reused, {store.n_failed} failed"

    def finished(run: RunSpec, rec: dict[str, Any]) -> None:
        store.store(run, rec)
        prog.step(note())

    def tick() -> None:  # the clock of a bar on a terminal (a finished bar stays)
        if prog.done < n_unique:
            prog.update(prog.done, note())

    prog.update(prog.done, note(), force=True)
    interrupted = False
    with open_backend(len(todo), executor, scheduler, max_workers) as backend:
        if backend is not None:
            interrupted = drive(backend, todo, finished, tick, prog.say)
    prog.close()

    result = SweepResult(out, runs, store.ordered(runs), store.computed, store.reused,
                         interrupted, time.perf_counter() - t0)
    write_summary(result, spec)
    return result
