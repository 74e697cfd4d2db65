"""Scoring of a blind check of the gap diagnosis: each trial's diagnosis
against its hidden truth (`score`), the run's figures against its bar
(`summarize`) and the report (`markdown`).  The rules (detectable, top-1,
top-3, false alarm, held-out reduction) are those of `ehm_drake.gap.lab.blind`;
against a reference group each detectable miss also gets its cause
(`MISS_CAUSES`)."""

from __future__ import annotations

import math

import numpy as np

from ...realities import MODEL_REALITY

#: The bar of a blind run (fractions) on data made by the model itself.
ACCEPTANCE = {"top1": 0.80, "top3": 0.95, "false_alarm": 0.10, "heldout_reduction": 0.70}
#: The bar on an independent reality (a body that is not the model): no
#: held-out share required, at least 30 scored trials.
ACCEPTANCE_REALITY = {"top1": 0.75, "top3": 0.90, "false_alarm": 0.10,
                      "heldout_reduction": None, "trials": 30}


def acceptance_for(reality: str = MODEL_REALITY) -> dict:
    """The acceptance bar of a blind run on `reality`."""
    return ACCEPTANCE if reality == MODEL_REALITY else ACCEPTANCE_REALITY


def score(truth: dict, report: dict, detectable: bool | None = None,
          reality: bool = False) -> dict:
    """Score one trial; `detectable` from `detectability` (None: every
    trial with a hidden effect counts as detectable; on the own family a
    trial whose diagnosis found a significant gap counts as detectable in
    any case).  On an independent `reality` every dataset has a model-form
    gap: detectable is the twin check alone, a false alarm is an effect
    named when none is hidden (on the own family: any gap claimed), and
    when the structural pass ran its ranking and the effect's own share of
    the gap are scored."""
    hidden = list(truth)
    verdict = report["verdict"]
    sp = report.get("structural") or {}
    structural = bool(sp.get("ran"))
    entries = sp["ranking"] if structural else report["ranking"]
    # Against a reference group, a candidate that gains less than one unit
    # of held-out chi^2 (its effect fitted off, up to round-off) has no
    # rank: such ties keep the candidate list's order and would count for
    # top-3 by chance.
    ranking = [e["effect"] for e in entries
               if e.get("evidence", e.get("heldout_gain", 2.0)) > 1.0]
    predicted = report.get("best_effect") if verdict in ("explained", "ambiguous") else None
    if predicted:  # (named by a rule outside the ranking, e.g. the level rule: first)
        ranking = [predicted] + [n for n in ranking if n != predicted]
    label_pred = predicted or verdict
    red = [e["effect_share" if structural else "gap_reduction_heldout"] for e in entries
           if e["effect"] in hidden]
    gap_claimed = verdict != "no_significant_gap"
    detectable = bool(hidden) and (detectable is None or bool(detectable)
                                   or (gap_claimed and not reality))
    top1 = bool(hidden) and predicted in hidden
    return {
        "truth_label": "+".join(sorted(hidden)) or "none",
        "predicted_label": label_pred,
        "verdict": verdict,
        # A gap the diagnosis found counts as detectable whatever the check
        # says (its linear models may miss what the nonlinear truth does):
        # only trials where neither sees a gap are left out.
        "detectable": detectable,
        "has_effect": bool(hidden),
        "top1": top1,
        "top3": bool(hidden) and gap_claimed and any(n in ranking[:3] for n in hidden),
        "false_alarm": (not hidden) and (predicted is not None if reality else gap_claimed),
        "heldout_reduction_true": max(red) if red else None,
        "gap_before_heldout": report["gap_before"]["heldout"],
        "ranking_top3": ranking[:3],
        "missed": (_why_missed(hidden, entries, predicted, report.get("method", {}))
                   if detectable and not top1 and not structural else None),
    }


#: Why a detectable hidden effect was not named first against a reference
#: group (`_why_missed`), in the order the causes are checked.
MISS_CAUSES = ("not a candidate", "another candidate named first", "the family-wise test",
               "below its own bound")


def _why_missed(hidden: list, ranking: list, predicted, method: dict) -> dict | None:
    """Against a reference group (ranking entries with a ``null_bound``):
    why a detectable trial's hidden effect was not named first, one of
    `MISS_CAUSES`: no hidden effect is among the candidates; another
    candidate was named first; a hidden effect's evidence exceeds its own
    bound (`calibration.null_threshold`) and `MIN_GAIN` but not the
    subject's threshold, which the family-wise test raised; or every hidden
    effect's evidence is within its own bound (the candidate fits the
    effect too little to stand out of the group's scatter).  With each
    hidden candidate's evidence, bound and threshold.  None for a diagnosis
    without a reference group."""
    if not ranking or "null_bound" not in ranking[0]:
        return None
    by = {e["effect"]: e for e in ranking}
    floor = float(method.get("min_gain", 0.0))
    effects = {n: {"evidence": by[n].get("evidence"), "bound": by[n].get("null_bound"),
                   "threshold": by[n].get("null_threshold")} for n in hidden if n in by}
    if not effects:
        cause = MISS_CAUSES[0]
    elif predicted is not None:
        cause = MISS_CAUSES[1]
    elif any(_finite(v["evidence"]) and v["evidence"] > floor
             and _finite(v["bound"]) and v["evidence"] > v["bound"]
             for v in effects.values()):
        cause = MISS_CAUSES[2]
    else:
        cause = MISS_CAUSES[3]
    return {"cause": cause, "named": predicted, "effects": effects}


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)


def summarize(results: list[dict], reality: str = MODEL_REALITY) -> dict:
    """Scores of a blind run's trial results, judged against `reality`'s bar."""
    bar = acceptance_for(reality)
    skipped = [r for r in results if "skipped" in r]
    results = [r for r in results if "skipped" not in r]
    det = [r for r in results if r["score"]["detectable"]]
    with_effect = [r for r in results if r["score"]["has_effect"]]
    none = [r for r in results if not r["score"]["has_effect"]]
    red = [r["score"]["heldout_reduction_true"] for r in det
           if r["score"]["heldout_reduction_true"] is not None]
    labels_t = sorted({r["score"]["truth_label"] for r in results})
    labels_p = sorted({r["score"]["predicted_label"] for r in results})
    conf = {t: {p: 0 for p in labels_p} for t in labels_t}
    for r in results:
        conf[r["score"]["truth_label"]][r["score"]["predicted_label"]] += 1

    def frac(xs):
        return float(np.mean(xs)) if xs else None

    m = {
        "trials": len(results),
        "skipped_trials": [{"trial": r["trial"], "hidden": r["hidden"], "reason": r["skipped"]}
                           for r in skipped],
        "effect_trials": len(with_effect),
        "detectable_trials": len(det),
        "no_effect_trials": len(none),
        "top1": frac([r["score"]["top1"] for r in det]),
        "top3": frac([r["score"]["top3"] for r in det]),
        "top1_all_effect_trials": frac([r["score"]["top1"] for r in with_effect]),
        "false_alarm": frac([r["score"]["false_alarm"] for r in none]),
        "heldout_reduction_mean": frac(red),
        "heldout_reduction_median": float(np.median(red)) if red else None,
        "confusion": conf,
        # Against a reference group: why the detectable misses were missed.
        "misses": {c: n for c in MISS_CAUSES
                   if (n := sum(1 for r in det if (r["score"].get("missed") or {}).get("cause")
                                == c))},
    }
    m["acceptance_bar"] = bar
    m["acceptance"] = {
        "top1": m["top1"] is not None and m["top1"] >= bar["top1"],
        "top3": m["top3"] is not None and m["top3"] >= bar["top3"],
        "false_alarm": m["false_alarm"] is None or m["false_alarm"] <= bar["false_alarm"],
    }
    if bar["heldout_reduction"] is not None:
        m["acceptance"]["heldout_reduction"] = (m["heldout_reduction_mean"] is not None and
                                                m["heldout_reduction_mean"]
                                                >= bar["heldout_reduction"])
    if bar.get("trials"):
        m["acceptance"]["trials"] = m["trials"] >= bar["trials"]
    m["passed"] = all(m["acceptance"].values())
    return m


def _p(x) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.0f}%"


def _miss_lines(summary: dict, results: list[dict]) -> list[str]:
    """The section on why the detectable misses were missed (against a
    reference group; none otherwise)."""
    misses = summary.get("misses")
    if not misses:
        return []
    lines = ["", "## Why the detectable misses were missed", "",
             "Each hidden effect's evidence against its own bound (from the group's "
             "leave-one-out gains) and against the subject's threshold (the bound, raised by "
             "the family-wise test where that is higher).", "",
             "| cause | trials |", "|---|---|",
             *(f"| {c} | {n} |" for c, n in misses.items()), "",
             "| trial | hidden | evidence | own bound | threshold | cause | named |",
             "|---|---|---|---|---|---|---|"]
    for r in results:
        m = (r.get("score") or {}).get("missed")
        if not m:
            continue
        eff = m["effects"] or {n: None for n in r["hidden"]}
        for n, v in eff.items():
            nums = ["-" if v is None or not _finite(v[k]) else f"{v[k]:.0f}"
                    for k in ("evidence", "bound", "threshold")]
            lines.append(f"| {r['trial']} | {n} | {' | '.join(nums)} | {m['cause']} | "
                         f"{m['named'] or '-'} |")
    return lines


def markdown(summary: dict, results: list[dict]) -> str:
    s = summary
    bar = s.get("acceptance_bar", ACCEPTANCE)

    def at_least(key):
        return "-" if bar.get(key) is None else f">= {_p(bar[key])}"
    sim = (s.get("settings", {}).get("params") or {}).get("simulation")
    lines = [f"# Blind check: {s['trials']} trials ({s['effect_trials']} with hidden effects, "
             f"{s['detectable_trials']} of them detectable; {s['no_effect_trials']} without)",
             *(["", f"{len(s['skipped_trials'])} more trials skipped: the reality's "
                f"simulation diverged (listed below, not scored)."]
               if s.get("skipped_trials") else []),
             *(["", f"Diagnosed against a reference group of "
                f"{s['settings']['references']} subjects (`diagnose --reference`)"
                + (f"; {s['settings']['contrasts']} of them measured again with each "
                   "imposable effect, whose measured signatures replace the model's "
                   "(`gap.contrasts`)." if s["settings"].get("contrasts") else ".")]
               if s.get("settings", {}).get("references") else []),
             *(["", f"The model: the {sim['design']} design at a "
                f"{1e3 * sim['time_step_s']:g} ms step (`params.json`)."] if sim else []),
             "", "| metric | value | acceptance |", "|---|---|---|",
             *([f"| scored trials | {s['trials']} | >= {bar['trials']} |"]
               if bar.get("trials") else []),
             f"| top-1 accuracy (detectable trials) | {_p(s['top1'])} | {at_least('top1')} |",
             f"| top-3 accuracy (detectable trials) | {_p(s['top3'])} | {at_least('top3')} |",
             f"| top-1 accuracy (all effect trials) | {_p(s['top1_all_effect_trials'])} "
             f"| - |",
             f"| false alarms (no-effect trials) | {_p(s['false_alarm'])} | <= "
             f"{_p(bar['false_alarm'])} |",
             f"| held-out gap removed by the true effect (mean / median) | "
             f"{_p(s['heldout_reduction_mean'])} / {_p(s['heldout_reduction_median'])} | "
             f"{at_least('heldout_reduction')} |", "",
             "## Confusion matrix (rows: hidden truth; columns: diagnosis)", ""]
    cols = sorted({p for row in s["confusion"].values() for p in row})
    lines.append("| truth \\ diagnosis | " + " | ".join(cols) + " |")
    lines.append("|---" * (len(cols) + 1) + "|")
    for t, row in s["confusion"].items():
        lines.append(f"| {t} | " + " | ".join(str(row.get(c, 0)) or "" for c in cols) + " |")
    lines += _miss_lines(s, results)
    lines += ["", "## Trials", "", "| trial | hidden (strength) | detectable | verdict | best | "
              "top-3 | held-out reduction |", "|---|---|---|---|---|---|---|"]
    for r in results:
        if "skipped" in r:
            hid = ", ".join(r["hidden"]) or "none"
            lines.append(f"| {r['trial']} | {hid} | - | skipped: {r['skipped']} | | | |")
            continue
        sc = r["score"]
        hid = ", ".join(f"{n} ({v:.2f})" for n, v in r["hidden"].items()) or "none"
        det = "-" if not sc["has_effect"] else ("yes" if sc["detectable"] else "no")
        lines.append(f"| {r['trial']} | {hid} | {det} | {sc['verdict']} | "
                     f"{sc['predicted_label']} | {', '.join(sc['ranking_top3'])} | "
                     f"{_p(sc['heldout_reduction_true'])} |")
    return "\n".join(lines) + "\n"
