"""How often the single-subject diagnosis (no reference group) names an
effect on subjects that have none: the false-alarm rate of its rule, and
the threshold of the structural pass that would hold it at a given level.

On a body that is not the model the ordinary pass seldom explains anything
(the model-form gap dominates) and the structural pass decides: a candidate
is named when it lowers the held-out chi^2 by more than its BIC penalty and
removes at least `discrepancy.EXPLAINED_BEYOND` of the held-out gap left
beyond the discrepancy.  Each no-effect subject contributes the removal of
the candidate the rule judges, the first by delta BIC (0 when its delta BIC
is not negative, or the pass did not run): the rule's statistic under the
null, judged at the threshold shipped now.  This script collects it
from blind runs made without a reference group, e.g.

    ehm-drake blind --reality lumped --trials 30 --p-none 1 --p-two 0 --seed S \\
        --directions x,z --levels 0.3,0.6 --duration 120 --out RUN
    python bench/single_subject_null.py RUN|VALUES.json [...] [--alpha 0.1] [--out null.json]

and prints, per reality, the subjects named under the shipped rule (with a
Clopper-Pearson 95% upper bound of the rate), the statistic's quantiles,
the smallest threshold under which at most `alpha` of the subjects are
named, per direction the band of the reports' resonance shift against the
model (data - model factor per doubling of the level: the peaks', and the
frequency scale of the whole resonance region) that holds all but `alpha`
of the subjects, and how many the level rule names
(`resonance.softening_rule` at its present threshold, from each subject's
scale and noise; for reports made before the scale existed, both computed
again from the trial's data).  A subject counts as named
when either rule names it.  `--out` writes the per-subject values; such
a file given in place of a run adds its subjects (a subject met twice, the
same reality, blind seed and trial, counts once), so a calibration can grow
over several sessions (docs/history/data/single_subject_null.json holds the
subjects diagnosed so far).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy.stats import beta


def recomputed_resonance(data: Path) -> dict:
    """The report's "resonance" evidence computed again from a trial's data
    (the base refit without candidates, then `resonance_shift`): for reports
    made before the frequency scale was part of it."""
    from ehm_drake.gap.library.models import Candidate, Predictor, Statics, fit_candidate
    from ehm_drake.gap.single import diagnose as dg
    from ehm_drake.gap.single.resonance import resonance_shift
    from ehm_drake.identification.parameters import resolve_free
    from ehm_drake.model.anthropometry import REFERENCE
    from ehm_drake.params import load_params

    lab = dg.load_lab_data(data)
    params = load_params()
    base_names = [f.name for f in resolve_free("default")]
    fam = dg.load_families(params, REFERENCE, [], base_names, 1, None, True)["base"]
    pred = Predictor(fam, Candidate(()), lab.rows, lab.tests, base_names,
                     Statics(fam.family.info, dg.separation_slope(params, REFERENCE)))
    fit = fit_candidate(pred, np.ones(len(lab.rows), bool))
    pred.update_statistics(fit.theta)
    return resonance_shift(lab.rows, pred.predict(fit.theta))


def subject_statistic(report: dict) -> dict:
    """One no-effect subject's single-subject report -> its verdict, the
    effect named (or None), the ordinary pass's best held-out reduction,
    the structural statistic (largest reduction beyond the discrepancy
    among candidates with delta BIC < 0) and, per direction tested at two
    levels, how much more the data's resonance moves per doubling of the
    level than the refitted model's (data - model factor; negative: the
    subject softens more)."""
    st = report.get("structural") or {}
    beyond = [e["reduction_beyond"] for e in st.get("ranking", []) if e["delta_bic"] < 0]
    ranking = report.get("ranking") or []
    resonance = (report.get("evidence") or {}).get("resonance") or {}
    return {"verdict": report["verdict"], "named": report.get("best_effect"),
            "resonance_difference": {d: e["data_per_doubling"] - e["model_per_doubling"]
                                     for d, e in resonance.items()
                                     if "model_per_doubling" in e},
            "scale_difference": {d: e["scale"]["data_per_doubling"]
                                 - e["scale"]["model_per_doubling"]
                                 for d, e in resonance.items()
                                 if (e.get("scale") or {}).get("model_per_doubling") is not None
                                 and e["scale"]["data_per_doubling"] is not None},
            "scale_std": {d: e["scale"]["data_std"] for d, e in resonance.items()
                          if "data_std" in (e.get("scale") or {})},
            "ordinary_best_reduction": ranking[0]["gap_reduction_heldout"] if ranking else None,
            "structural_ran": bool(st.get("ran")),
            "structural_statistic": max(beyond, default=0.0) if st.get("ran") else 0.0,
            "structural_best": next((e["effect"] for e in st.get("ranking", [])
                                     if e["delta_bic"] < 0), None),
            "structural_rule_statistic": rule_statistic(st)}


#: A subject's values that come from the resonance (recomputed for old reports).
RESONANCE_KEYS = ("resonance_difference", "scale_difference", "scale_std")


def rule_statistic(structural: dict) -> float:
    """The structural rule's own statistic (`discrepancy.structural_pass`):
    the removal beyond the discrepancy of the first candidate by delta BIC
    (the subject's ``structural_best``), 0 when its delta BIC is not negative
    or the pass did not run."""
    first = (structural.get("ranking") or [None])[0] if structural.get("ran") else None
    return 0.0 if first is None or first["delta_bic"] >= 0 else first["reduction_beyond"]


def level_rule_names(subject: dict) -> bool:
    """Whether the level rule as shipped now names softening on this subject,
    from its vertical scale difference and noise, as the rule decides
    (`resonance.names_softening`; the reports' own reading may come from an
    earlier threshold)."""
    from ehm_drake.gap.single.resonance import names_softening

    diff = subject.get("scale_difference", {}).get("z")
    return diff is not None and names_softening(diff, subject.get("scale_std", {}).get("z"))


def named_effect(subject: dict) -> str | None:
    """The effect a subject's single-subject diagnosis names under the rules
    shipped now (the structural rule's at the present `EXPLAINED_BEYOND`,
    where the subject's values hold the rule's statistic, else the report's
    own name; then the level rule's)."""
    from ehm_drake.gap.single.discrepancy import EXPLAINED_BEYOND

    named = subject["named"]
    if subject.get("structural_ran") and "structural_rule_statistic" in subject:
        named = (subject["structural_best"]
                 if subject["structural_rule_statistic"] >= EXPLAINED_BEYOND else None)
    return named or ("softening" if level_rule_names(subject) else None)


def collect(runs, known=frozenset()) -> dict:
    """{reality: [subject statistics]} of the no-effect trials of blind runs
    made without a reference group; trials in `known` ((reality, seed,
    trial) already counted with their frequency scale) are left out."""
    out: dict[str, list] = {}
    for run in map(Path, runs):
        settings_path = run / "blind_settings.json"
        if not settings_path.is_file():
            raise SystemExit(f"{run}: not a blind run (no blind_settings.json)")
        settings = json.loads(settings_path.read_text())
        if settings.get("references", 0):
            raise SystemExit(f"{run}: diagnosed against a reference group; this script "
                             "studies the single-subject rule")
        reality = settings.get("reality", "ehm")
        seed = settings.get("seed")
        found = 0
        for rf in sorted(run.glob("trial_*/result.json")):
            r = json.loads(rf.read_text())
            rep_path = rf.parent / "diagnosis" / "report.json"
            if "skipped" in r or r.get("hidden") or not rep_path.exists():
                continue
            report = json.loads(rep_path.read_text())
            if (reality, seed, rf.parent.name) in known:
                # Held with its resonance already: the report's other values
                # only (no diagnosis again).
                s = {k: v for k, v in subject_statistic(report).items()
                     if k not in RESONANCE_KEYS}
                out.setdefault(reality, []).append(dict(s, trial=rf.parent.name, seed=seed))
                found += 1
                continue
            if not any("scale" in e for e in report["evidence"]["resonance"].values()):
                report["evidence"]["resonance"] = recomputed_resonance(rf.parent / "data")
            s = subject_statistic(report)
            s["trial"] = rf.parent.name
            s["seed"] = seed
            out.setdefault(reality, []).append(s)
            found += 1
        if not found:
            raise SystemExit(f"{run}: no diagnosed no-effect trial")
    return out


def gather(sources) -> dict:
    """{reality: [subject statistics]} from blind run folders (`collect`)
    and files of per-subject values written by `--out`; a subject found
    twice (same reality, seed and trial) counts once, and is not diagnosed
    again when a file already holds its frequency scale."""
    merged: dict[str, dict] = {}
    for src in map(Path, sources):
        if src.is_file():
            try:
                data = json.loads(src.read_text())
            except json.JSONDecodeError as e:
                raise SystemExit(f"{src}: not a file of subject values ({e})") from None
            if not isinstance(data, dict) or not all(isinstance(v, list)
                                                     for v in data.values()):
                raise SystemExit(f"{src}: not a file of subject values "
                                 "({reality: [subjects]}, as --out writes)")
        else:
            data = collect([src], {(r, *k) for r, v in merged.items()
                                   for k, s in v.items() if "scale_difference" in s})
        for reality, subjects in data.items():
            for s in subjects:
                held = merged.setdefault(reality, {})
                key = (s.get("seed"), s["trial"])
                held[key] = {**held.get(key, {}), **s}
    return {r: list(v.values()) for r, v in merged.items()}


def upper_bound(k: int, n: int, confidence: float = 0.95) -> float:
    """One-sided Clopper-Pearson upper bound of a rate seen k times in n."""
    return 1.0 if k >= n else float(beta.ppf(confidence, k + 1, n - k))


def threshold_for(statistics, alpha: float) -> float:
    """The smallest structural threshold naming at most alpha of these
    subjects (a subject is named when its statistic reaches it)."""
    s = np.sort(np.asarray(statistics, float))[::-1]
    allowed = int(np.floor(alpha * len(s)))
    return float(s[allowed]) + 1e-9 if allowed < len(s) else 0.0


def resonance_band(subjects: list, alpha: float, key: str = "resonance_difference") -> dict:
    """Per direction: the no-effect subjects' resonance differences (data -
    model factor per doubling; `key` "resonance_difference": of the peaks,
    "scale_difference": of the frequency scale), their median, and the band
    holding all but alpha of them (alpha / 2 cut from each side, nearest
    order statistics): a rule naming softening below it, or stiffening
    above, names at most alpha of such subjects."""
    out = {}
    for d in "xyz":
        v = np.sort([s[key][d] for s in subjects if d in s.get(key, {})])
        if not len(v):
            continue
        cut = int(np.floor(alpha / 2 * len(v)))
        out[d] = {"subjects": len(v), "median": float(np.median(v)),
                  "band_at_alpha": [float(v[cut]), float(v[len(v) - 1 - cut])]}
    return out


def summary(subjects: list, alpha: float) -> dict:
    n = len(subjects)
    named = [named_effect(s) for s in subjects if named_effect(s)]
    stat = [s.get("structural_rule_statistic", s["structural_statistic"]) for s in subjects]
    return {"subjects": n, "named": len(named),
            "named_effects": sorted(set(named)),
            "level_rule_named": sum(map(level_rule_names, subjects)),
            "rate": len(named) / n, "rate_upper_95": upper_bound(len(named), n),
            "structural_ran": sum(s["structural_ran"] for s in subjects),
            "statistic_quantiles": {q: float(np.quantile(stat, q)) for q in (0.5, 0.9, 1.0)},
            "threshold_at_alpha": threshold_for(stat, alpha),
            "resonance": resonance_band(subjects, alpha),
            "scale": resonance_band(subjects, alpha, "scale_difference")}


def main(argv=None) -> None:
    from ehm_drake.gap.single.discrepancy import EXPLAINED_BEYOND
    from ehm_drake.gap.single.resonance import SOFTENING_SHIFT

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--alpha", type=float, default=0.10)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    data = gather(a.runs)
    print(f"structural threshold shipped: {EXPLAINED_BEYOND:.2f} of the gap beyond the "
          f"discrepancy; level rule: vertical resonance shift below {-SOFTENING_SHIFT:+.3f} "
          "per doubling")
    for reality, subjects in sorted(data.items()):
        s = summary(subjects, a.alpha)
        q = s["statistic_quantiles"]
        print(f"{reality}: {s['named']} of {s['subjects']} no-effect subjects named "
              f"({100 * s['rate']:.0f}%, 95% upper bound {100 * s['rate_upper_95']:.0f}%; "
              f"{', '.join(s['named_effects']) or 'none'}); structural pass ran on "
              f"{s['structural_ran']}; statistic median {q[0.5]:.3f}, 90% {q[0.9]:.3f}, "
              f"max {q[1.0]:.3f}; threshold for <= {100 * a.alpha:.0f}%: "
              f"{s['threshold_at_alpha']:.3f}; level rule names {s['level_rule_named']}")
        for what, key in (("resonance peak", "resonance"), ("frequency scale", "scale")):
            for d, r in s[key].items():
                lo, hi = r["band_at_alpha"]
                print(f"  {d}: {what} per doubling, data - model, over {r['subjects']} "
                      f"subjects: median {r['median']:+.3f}, {100 * (1 - a.alpha):.0f}% of them "
                      f"in [{lo:+.3f}, {hi:+.3f}]")
    if a.out:
        Path(a.out).write_text(json.dumps(data, indent=1) + "\n")


if __name__ == "__main__":
    main()
