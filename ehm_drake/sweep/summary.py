"""The sweep's summary files: ``summary.csv`` (one row per run: id, status,
swept values, key results) and ``summary.json`` (the normalized spec, counts
and every run's results)."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

from .schema import canonical
from .spec import SweepSpec
from .store import SweepResult, atomic_write


def _flat_results(rec: dict[str, Any]) -> dict[str, Any]:
    """Key results of a run record as flat columns."""
    row: dict[str, Any] = {}
    res = rec.get("results") or {}
    comfort = res.get("comfort", {})
    for loc in ("seat", "head"):
        m = comfort.get(loc)
        if not m:
            continue
        row[f"{loc}_aw_overall"] = m["overall"]
        for a in "xyz":
            row[f"{loc}_aw_{a}"] = m["weighted_rms"][a]
        row[f"{loc}_vdv_overall"] = m["overall_vdv"]
        row[f"{loc}_msdv_z"] = m["msdv_z"]
    for key, p in res.get("transmissibility", {}).items():
        name = "T_" + key.replace("/", "_")
        row[f"{name}_peak_gain"] = p["peak_gain"]
        row[f"{name}_peak_hz"] = p["peak_freq_hz"]
    posture = res.get("posture", {})
    for k in ("head_pitch_drift_deg", "trunk_T8_forward_drift_m", "back_in_contact"):
        if k in posture:
            row[k] = posture[k]
    for k in ("design", "time_step_s", "wall_s"):
        if k in res:
            row[k] = res[k]
    err = rec.get("error")
    if err:
        row["error_type"] = err.get("type")
        row["error_message"] = err.get("message")
    return row


def _cell(v: Any) -> Any:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (list, dict)):
        return json.dumps(v)
    return v


def write_summary(result: SweepResult, spec: SweepSpec) -> tuple[Path, Path]:
    """DIR/summary.csv (one row per run) and DIR/summary.json."""
    rows = []
    swept_keys: list[str] = []
    result_keys: list[str] = []
    for run, rec in zip(result.runs, result.records, strict=True):
        for k in run.swept:
            if k not in swept_keys:
                swept_keys.append(k)
        flat = _flat_results(rec)
        for k in flat:
            if k not in result_keys:
                result_keys.append(k)
        rows.append({"run_id": run.run_id, "index": run.index, "status": rec["status"],
                     **run.swept, **flat})
    # Errors last, for readability.
    result_keys = ([k for k in result_keys if not k.startswith("error_")]
                   + [k for k in result_keys if k.startswith("error_")])
    columns = ["run_id", "index", "status", *swept_keys, *result_keys]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for row in rows:
        w.writerow([_cell(row.get(c, "")) for c in columns])
    out = result.out_dir
    atomic_write(out / "summary.csv", buf.getvalue())
    counts = {"runs": len(result.runs), "unique_runs": len({r.run_id for r in result.runs}),
              "done": result.n_done, "failed": result.n_failed,
              "pending": result.n_pending, "computed": len(result.computed),
              "reused": len(result.reused)}
    summary = {
        "name": spec.name,
        "spec": spec.to_dict(),
        "counts": counts,
        "interrupted": result.interrupted,
        "wall_s": result.wall_s,
        "runs": [{"run_id": run.run_id, "index": run.index, "status": rec["status"],
                  "swept": canonical(run.swept),
                  **({"results": rec["results"]} if rec.get("results") else {}),
                  **({"error": {k: rec["error"][k] for k in ("type", "message", "source")
                                if k in rec["error"]}} if rec.get("error") else {})}
                 for run, rec in zip(result.runs, result.records, strict=True)],
    }
    atomic_write(out / "summary.json", json.dumps(summary, indent=1, allow_nan=True))
    return out / "summary.csv", out / "summary.json"
