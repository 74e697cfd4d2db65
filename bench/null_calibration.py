"""How often the reference design's threshold is exceeded by subjects
without any effect: the measured level of `calibration.null_threshold`.

Every no-effect trial of a blind run against a reference group carries, per
candidate, its evidence and the leave-one-out gains of the run's group (the
null its threshold is set from).  This script collects them from one or
more runs, judges them with each candidate's own bound and with the cube-root
bound's gains clipped at -MIN_GAIN instead of 0 (an alternative once tried),
and prints the per-candidate exceedance rate against its nominal level
(FAMILY_ALPHA / candidates) and the share of subjects with any candidate
named (the false-alarm rate); then that share with the library's
thresholds, the bounds and the family-wise conformal test
(`calibration.thresholds`):

    python bench/null_calibration.py RUN [RUN ...] [--out nulls.json]

A RUN is a blind run's folder, or the JSON `bench/rescore_blind.py --out`
wrote when it diagnosed a run's trials again (e.g. against another group,
`--reference`; its ranking entries carry the null gains).

`--out` writes the collected values (per run: the candidates' null gains
and the borrowed spread; per subject: each candidate's evidence), the form
`tests/data/lumped_null_evidence.json` is stored in (five `lumped` blind
runs, 68 no-effect subjects; docs/history).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def collect(runs) -> dict:
    """{run name: {"candidates", "null_gains" {name: [K]}, "borrowed_spread",
    "evidence" [[per candidate] per no-effect subject]}} from the runs'
    stored reports."""
    out = {}
    for run in map(Path, runs):
        if run.is_file():
            out[run.stem] = _collect_rescored(run)
            continue
        entry = None
        for rf in sorted(run.glob("trial_*/result.json")):
            r = json.loads(rf.read_text())
            rep_path = rf.parent / "diagnosis" / "report.json"
            if "skipped" in r or r["hidden"] or not rep_path.exists():
                continue
            rep = json.loads(rep_path.read_text())
            if rep.get("method", {}).get("design") != "reference group":
                raise SystemExit(f"{rep_path}: not a diagnosis against a reference group")
            entry = _add_subject(entry, rep["method"]["candidates"], rep["ranking"],
                                 rep["method"].get("borrowed_null_spread"), rf.parent)
        if entry is None:
            raise SystemExit(f"{run}: no diagnosed no-effect trial against a reference group")
        out[run.name] = entry
    return out


def _add_subject(entry, names, ranking, borrowed, where):
    """`entry` (a new one when None) with one no-effect subject's evidence
    per candidate in `names` added; the run's null gains are taken from its
    first subject and must be the same for every other (one group per run)."""
    by = {e["effect"]: e for e in ranking}
    if entry is None:
        entry = {"candidates": names, "null_gains": {n: by[n]["null_gains"] for n in names},
                 "borrowed_spread": borrowed, "evidence": []}
    elif any(by[n]["null_gains"] != entry["null_gains"][n] for n in names):
        raise SystemExit(f"{where}: another group's null gains in one run")
    entry["evidence"].append([by[n]["evidence"] for n in names])
    return entry


def _collect_rescored(path: Path) -> dict:
    """The same entry from a `rescore_blind.py --out` JSON: its no-effect
    trials' evidence and the null gains of the group they were diagnosed
    against (one group per file)."""
    entry = None
    for t in json.loads(path.read_text())["trials"]:
        if "skipped" in t or t["hidden"]:
            continue
        if any(e.get("null_gains") is None for e in t["ranking"]):
            raise SystemExit(f"{path}: trial {t['trial']} has no null gains (rescored before "
                             "rescore_blind.py kept them)")
        entry = _add_subject(entry, sorted(e["effect"] for e in t["ranking"]), t["ranking"],
                             t.get("borrowed_null_spread"), path)
    if entry is None:
        raise SystemExit(f"{path}: no rescored no-effect trial")
    return entry


def exceedances(data: dict, threshold) -> dict:
    """Per-candidate exceedances, tests, subjects with any, subjects, judged
    with `threshold(null, n_candidates, borrowed_spread)`."""
    hits = tests = named = subjects = 0
    for entry in data.values():
        names = entry["candidates"]
        thr = np.array([threshold(entry["null_gains"][n], len(names), entry["borrowed_spread"])
                        for n in names])
        ev = np.asarray(entry["evidence"], float)
        over = ev > thr
        hits += int(over.sum())
        tests += over.size
        named += int(over.any(axis=1).sum())
        subjects += len(ev)
    return {"exceedances": hits, "tests": tests, "named": named, "subjects": subjects}


def family_named(data: dict) -> dict:
    """Subjects with any candidate named under the library's thresholds
    (`calibration.thresholds`: each candidate's bound and the family-wise
    conformal test), and subjects."""
    from ehm_drake.gap.reference_group.calibration import thresholds

    named = subjects = 0
    for entry in data.values():
        names = entry["candidates"]
        nulls = {n: entry["null_gains"][n] for n in names}
        for ev in entry["evidence"]:
            e = dict(zip(names, ev, strict=True))
            thr = thresholds(nulls, e, borrowed_spread=entry["borrowed_spread"])[0]
            named += any(e[n] > thr[n] for n in names)
            subjects += 1
    return {"named": named, "subjects": subjects}


def clipped_at(clip: float):
    """`calibration.null_threshold` with the cube-root bound's gains clipped
    at `clip` (the library's default is 0; -MIN_GAIN is the alternative once tried): a
    threshold(null, n_candidates, borrowed_spread)."""
    from ehm_drake.gap.reference_group.calibration import null_threshold

    def threshold(null, n, spread):
        return null_threshold(null, n, borrowed_spread=spread, clip=clip)
    return threshold


def main(argv=None) -> int:
    from ehm_drake.gap.reference_group.calibration import FAMILY_ALPHA, MIN_GAIN

    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", help="blind run folders (against a reference group) or "
                   "rescore_blind.py --out files")
    p.add_argument("--out", help="write the collected null gains and evidence (JSON)")
    a = p.parse_args(argv)
    data = collect(a.runs)
    if a.out:
        Path(a.out).write_text(json.dumps(data, indent=1) + "\n")
    current = exceedances(data, clipped_at(0.0))
    other = exceedances(data, clipped_at(-MIN_GAIN))
    n_cand = {len(e["candidates"]) for e in data.values()}
    nominal = FAMILY_ALPHA / max(n_cand)
    print(f"{sum(len(e['evidence']) for e in data.values())} no-effect subjects in "
          f"{len(data)} runs; nominal per-candidate level {nominal:.4f}")
    for label, m in (("per-candidate bound", current), ("clipped at -MIN_GAIN", other)):
        rate = m["exceedances"] / m["tests"]
        print(f"{label:28s} per candidate {m['exceedances']}/{m['tests']} = {rate:.4f} "
              f"({rate / nominal:.2f} x nominal); subjects named {m['named']}/{m['subjects']} "
              f"= {m['named'] / m['subjects']:.1%}")
    fam = family_named(data)
    print(f"{'with the family-wise test':28s} subjects named {fam['named']}/{fam['subjects']} = "
          f"{fam['named'] / fam['subjects']:.1%} (the library's thresholds)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
