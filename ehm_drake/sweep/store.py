"""The run store: one JSON record per finished run in ``DIR/runs``, written
atomically as the run completes, so an interrupted sweep resumes where it
stopped; which stored runs are reused; and what a sweep did (SweepResult)."""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .execute import STATUS_DONE, STATUS_FAILED, STATUS_PENDING
from .expand import RUN_FORMAT, RunSpec
from .schema import canonical


def atomic_write(path: Path, text: str) -> None:
    """Write `path` whole or not at all (a temporary file renamed over it)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("ehm_drake")
    except Exception:  # noqa: BLE001 - running from a source tree without metadata
        return "unknown"


def _load_record(path: Path) -> dict[str, Any] | None:
    try:
        rec = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    return rec if isinstance(rec, dict) and rec.get("status") in (
        STATUS_DONE, STATUS_FAILED) else None


def _reusable(rec: dict[str, Any] | None, retry_failed: bool) -> bool:
    if rec is None:
        return False
    if rec["status"] == STATUS_DONE:
        return True
    # A model error repeats (deterministic inputs); an executor error may not.
    return not retry_failed and rec.get("error", {}).get("source") == "run"


class RunStore:
    """The records of one sweep folder: those reused from an earlier run of the sweep
    and those computed now (each written as it is stored)."""

    def __init__(self, out_dir: Path):
        self.out_dir = out_dir
        self.runs_dir = out_dir / "runs"
        self.runs_dir.mkdir(parents=True, exist_ok=True)
        self.records: dict[str, dict[str, Any]] = {}
        self.reused: list[str] = []
        self.computed: list[str] = []
        self.n_failed = 0  # computed now

    def to_compute(self, runs: list[RunSpec], force: bool, retry_failed: bool
                   ) -> tuple[list[RunSpec], int]:
        """Take the reusable stored records; return the distinct runs still to compute
        and the number of distinct runs."""
        todo: list[RunSpec] = []
        seen: set[str] = set()
        for run in runs:
            if run.run_id in seen:
                continue
            seen.add(run.run_id)
            rec = None if force else _load_record(self.runs_dir / f"{run.run_id}.json")
            if _reusable(rec, retry_failed):
                assert rec is not None
                self.records[run.run_id] = rec
                self.reused.append(run.run_id)
            else:
                todo.append(run)
        return todo, len(seen)

    def store(self, run: RunSpec, rec: dict[str, Any]) -> dict[str, Any]:
        """Write the full record of a run a worker returned (and its frf table)."""
        full = {"ehm_drake_sweep_run": RUN_FORMAT, "run_id": run.run_id,
                "status": rec.get("status", STATUS_FAILED), "index": run.index,
                "swept": canonical(run.swept), "inputs": run.inputs(),
                "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                "ehm_drake_version": _version(),
                **{k: v for k, v in rec.items() if k not in ("status", "frf_csv")}}
        if rec.get("frf_csv"):
            atomic_write(self.runs_dir / f"{run.run_id}.frf.csv", rec["frf_csv"])
            full["frf_file"] = f"{run.run_id}.frf.csv"
        atomic_write(self.runs_dir / f"{run.run_id}.json",
                     json.dumps(full, indent=1, allow_nan=True))
        self.records[run.run_id] = full
        self.computed.append(run.run_id)
        self.n_failed += full["status"] == STATUS_FAILED
        return full

    def ordered(self, runs: list[RunSpec]) -> list[dict[str, Any]]:
        """One record per run, in spec order ("pending" for a run not finished)."""
        return [self.records.get(run.run_id) or {"run_id": run.run_id, "status": STATUS_PENDING}
                for run in runs]


@dataclass
class SweepResult:
    """What a sweep did; `records` holds one run record per run, in spec order
    (status "pending" for runs not finished when interrupted)."""

    out_dir: Path
    runs: list[RunSpec]
    records: list[dict[str, Any]]
    computed: list[str]
    reused: list[str]
    interrupted: bool
    wall_s: float

    def count(self, status: str) -> int:
        return sum(r["status"] == status for r in self.records)

    @property
    def n_done(self) -> int:
        return self.count(STATUS_DONE)

    @property
    def n_failed(self) -> int:
        return self.count(STATUS_FAILED)

    @property
    def n_pending(self) -> int:
        return self.count(STATUS_PENDING)
