"""Re-diagnose the trials of a finished (or partial) blind run with the
current code, in this process, and score them as `blind` does.

A blind run (``ehm-drake blind ... --out RUN``) keeps each trial's data, its
key and its detectability; this script diagnoses the stored data again
(against the run's reference group when it has one) without touching the run
folder, so a change to the diagnosis can be measured on the same trials:

    python bench/rescore_blind.py RUN [--trials 0-9,12] [--out rescored.json]

With ``--rethreshold`` (a run against a reference group) the stored reports
are not re-diagnosed but judged again with the current thresholds from
their stored null gains and evidence (`reference.rethreshold`), in seconds:
a change to the threshold rule alone, measured on the same fits.

It prints one line per trial and the summary (top-1, top-3, false alarms)
judged against the run's bar; `--out` writes the per-trial reports' scores.

With ``--rethreshold --contrasts DIR`` (contrast measurements of the run's
reference subjects, `ehm_drake.gap.reference_group.contrasts`; e.g. made afterwards for the
stored group with `blind --contrasts` settings) the effects in DIR are scored
again with their measured signatures on each trial's stored data and the
group's leave-one-out null, the other candidates keep their stored evidence,
and all are judged again: the contrasts' worth measured on the same trials,
without re-fitting the model (seconds a trial).

With ``--reference DIR [DIR ...]`` the trials are diagnosed against the
reference subjects in those folders (a run's ``reference`` folder, or subject
folders) instead of the run's own group: a change of the group (its size, its
subjects) measured on the same trials, e.g. the run's 8 subjects and another
run's 8 of the same reality and protocol.

With ``--design implicit`` (a reality's run) the model is linearized on that
design: the data, made by the reality, stay valid, so the diagnosis's figures
on another design are measured on the same trials without simulating again.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


def _trial_set(text: str | None):
    if not text:
        return None
    out = set()
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.update(range(int(a), int(b or a) + 1))
    return out


def _with_contrasts(report, data, group, contrasts, nulls, scorer, better=False) -> None:
    """Replace, in a stored report, the evidence and null gains of the
    effects that have contrasts with their measured signatures' (`better`:
    the larger of the measured and the stored model-based evidence, the
    null gains likewise, subject by subject)."""
    import numpy as np

    from ehm_drake.gap.reference_group.contrasts import contrast_evidence
    from ehm_drake.gap.reference_group.group import wrap_log
    from ehm_drake.gap.reference_group.reference import _gain
    from ehm_drake.gap.single.diagnose import load_lab_data
    from ehm_drake.gap.single.localize import cell_keys, gap_value

    keys = cell_keys(group.rows)
    lab = load_lab_data(data)
    r = wrap_log(np.log(lab.rows.H[group.align(lab)]) - group.mean_log)
    base = scorer.baseline(r)
    g0 = gap_value(base["chi_heldout"], keys)
    for e in report["ranking"]:
        if e["effect"] in contrasts.effects:
            res = scorer.score(r, e["effect"], contrasts.signature(e["effect"]))
            ev, null = contrast_evidence(res, base), nulls[e["effect"]]
            if better:
                null = [max(a, b) for a, b in zip(null, e["null_gains"], strict=True)]
                if e["evidence"] > ev:  # the modelled signature's evidence stays
                    e["null_gains"] = null
                    continue
            e.update(evidence=ev, null_gains=null, heldout_gain=_gain(res, base),
                     level_gain=res["level_gain"], signature="contrasts",
                     params=res["params"],
                     gap_reduction_heldout=float(1 - gap_value(res["chi_heldout"], keys) / g0)
                     if g0 > 0 else 0.0)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", type=Path, help="the blind run's output folder")
    p.add_argument("--trials", default=None, help="trial numbers, e.g. 0-9,12 (default all)")
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--out", type=Path, default=None, help="write the scores here (JSON)")
    p.add_argument("--rethreshold", action="store_true",
                   help="judge the stored reports again with the current thresholds instead "
                        "of re-diagnosing (reference-group runs)")
    p.add_argument("--contrasts", type=Path, default=None,
                   help="with --rethreshold: score the effects in this contrasts folder "
                        "(DIR/<effect>/<subject>/) with their measured signatures")
    p.add_argument("--better", action="store_true",
                   help="with --contrasts: each such effect's evidence is the larger of its "
                        "measured and its modelled signature's (the null likewise)")
    p.add_argument("--design", choices=("reference", "implicit"), default=None,
                   help="re-diagnose with the model on this design (default: the packaged "
                        "parameters'); the data, made by a reality, do not depend on it")
    p.add_argument("--reference", type=Path, nargs="+", default=None,
                   help="diagnose against these reference folders instead of the run's own "
                        "group (re-diagnoses)")
    args = p.parse_args(argv)

    from ehm_drake.gap.lab.scoring import score, summarize
    from ehm_drake.gap.reference_group.group import load_reference
    from ehm_drake.gap.reference_group.reference import diagnose_with_reference, rethreshold
    from ehm_drake.gap.single.diagnose import DiagnosisError, diagnose, load_lab_data
    from ehm_drake.realities import MODEL_REALITY

    settings = json.loads((args.run / "blind_settings.json").read_text())
    reality = settings.get("reality", MODEL_REALITY)
    params = None
    if args.design is not None:
        if reality == MODEL_REALITY:
            p.error("--design: the model's own trials were simulated on the run's design; "
                    "re-diagnosing them on another compares two designs, not the diagnosis")
        if args.rethreshold:
            p.error("--design re-diagnoses; it cannot be combined with --rethreshold")
        from ehm_drake.diagram import on_design
        from ehm_drake.params import load_params

        params = on_design(load_params(), args.design)
    candidates = settings.get("candidates")
    if args.rethreshold and not settings.get("references"):
        p.error("--rethreshold needs a run against a reference group")
    if args.contrasts and not args.rethreshold:
        p.error("--contrasts is for --rethreshold (a re-diagnosis finds the run's own "
                "reference/contrasts folder)")
    if args.reference and args.rethreshold:
        p.error("--reference re-diagnoses; it cannot be combined with --rethreshold")
    if args.reference:
        try:
            group = load_reference(args.reference)
        except (FileNotFoundError, DiagnosisError) as e:
            p.error(f"--reference: {e}")
    else:
        group = (load_reference([args.run / "reference"])
                 if settings.get("references") and not args.rethreshold else None)
    contrasts = None
    if args.contrasts:
        from ehm_drake.gap.reference_group.contrasts import (
            ContrastScorer,
            contrast_nulls,
            load_contrasts,
        )

        group = load_reference([args.run / "reference"])
        contrasts = load_contrasts(args.contrasts, group)
        nulls = contrast_nulls(group, contrasts)
        scorer = ContrastScorer(group)
        print(f"contrasts: {contrasts.describe()}", flush=True)
    wanted = _trial_set(args.trials)
    results = []
    for rfile in sorted(args.run.glob("trial_*/result.json")):
        old = json.loads(rfile.read_text())
        if wanted is not None and old["trial"] not in wanted:
            continue
        if "skipped" in old:
            results.append(old)
            continue
        t0 = time.perf_counter()
        if args.rethreshold:
            stored = json.loads((rfile.parent / "diagnosis" / "report.json").read_text())
            if contrasts is not None:
                _with_contrasts(stored, rfile.parent / "data", group, contrasts, nulls, scorer,
                                args.better)
            rep = rethreshold(stored)
        elif group is not None:
            data = load_lab_data(rfile.parent / "data")
            diag = diagnose_with_reference(data, group, params, effects=candidates,
                                           workers=args.workers, progress=False)
            rep = diag.report
        else:
            data = load_lab_data(rfile.parent / "data")
            rep = diagnose(data, params, effects=candidates, workers=args.workers,
                           progress=False).report
        sc = score(old["hidden"], rep, old["detectability"]["detectable"],
                   reality != MODEL_REALITY)
        new = {k: v for k, v in old.items() if k not in ("score",)}
        new["score"] = sc
        new["ranking"] = [{k: e.get(k) for k in ("effect", "heldout_gain", "level_gain",
                                                 "evidence", "null_threshold",
                                                 "beyond_null", "gap_reduction_heldout",
                                                 "null_gains", "params")}
                          for e in rep["ranking"]]
        new["borrowed_null_spread"] = rep.get("method", {}).get("borrowed_null_spread")
        results.append(new)
        was = old.get("score", {}).get("predicted_label", "-")
        top = ", ".join(f"{e['effect']} {e.get('evidence', e.get('heldout_gain', 0)):.0f}/"
                        f"{e.get('null_threshold', 0):.0f}" for e in rep["ranking"][:3])
        print(f"trial {old['trial']:3d} {sc['truth_label']:40s} -> {sc['predicted_label']:24s}"
              f" (was {was}; det {'y' if sc['detectable'] else 'n'}; "
              f"{time.perf_counter() - t0:.0f} s) {top}", flush=True)
    summary = summarize(results, reality)
    print(json.dumps({k: summary[k] for k in ("trials", "detectable_trials", "no_effect_trials",
                                              "top1", "top3", "false_alarm", "passed")},
                     indent=1))
    if args.out:
        args.out.write_text(json.dumps({"summary": summary, "trials": results}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
