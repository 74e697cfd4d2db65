"""The diagnosis' verdict from its significant cells and its ranking of the
candidates (`diagnose`, step 4 of its procedure), and the sentence that
explains it.

- `no_significant_gap`: no cell significant, and no candidate named on the
  joint test below;
- `unexplained`: the best candidate does not meet the `explained` bar (ΔBIC
  < 0 on the held-out tests and at least half of the held-out gap removed);
- `ambiguous`: a runner-up within `AMBIGUITY_MARGIN` of the best's held-out
  reduction that the level evidence does not separate from it;
- `explained`: otherwise.

An effect spread thinly over many cells can leave every cell below its
Bonferroni threshold and still be clear in all of them together: with no
significant cell, the best candidate is named when it meets the
`explained` bar and its held-out chi^2 improvement passes `joint_test`.
"""

from __future__ import annotations

from scipy.stats import chi2 as chi2_dist

from .localize import bic_penalty

VERDICTS = ("explained", "ambiguous", "unexplained", "no_significant_gap")
#: The best candidate must remove this share of the held-out gap.
EXPLAINED_REDUCTION = 0.5
#: Candidates within this held-out reduction of the best are not separated.
AMBIGUITY_MARGIN = 0.05
#: Significance of the joint test (per candidate, Bonferroni over the candidates),
#: the same level as the cells' test.
JOINT_SIGNIFICANCE = 0.01


def decide(n_significant: int, ranking: list[dict], n_rows: int, n_candidates: int,
           evidence: dict) -> dict:
    """The verdict from the significant cells and the candidates' ranking
    (best first; entries as `_ranking_entry` makes them) and the level
    evidence: `verdict`, the `best` entry, the entries `close` to it (the
    ambiguity), the `joint` test of the best, whether the effect is named
    on it alone (`jointly`: no cell significant) and whether any level
    evidence is significant (`nonlinear_evidence`)."""
    nonlinear_evidence = any(e["significant"] for e in evidence.values())
    best = ranking[0] if ranking else None
    joint = joint_test(best, n_rows, n_candidates) if best else None
    supported = best is not None and best["delta_bic"] < 0 and \
        best["gap_reduction_heldout"] >= EXPLAINED_REDUCTION
    jointly = not n_significant and supported and joint["significant"]
    close = []
    if not n_significant and not jointly:
        verdict = "no_significant_gap"
    elif not supported:
        verdict = "unexplained"
    else:
        close = [r for r in ranking[1:] if r["delta_bic"] < 0 and
                 best["gap_reduction_heldout"] - r["gap_reduction_heldout"] < AMBIGUITY_MARGIN]
        # Level-dependence evidence separates a nonlinear from a linear candidate.
        close = [r for r in close if not (
            (nonlinear_evidence and best["level_dependent"] and not r["level_dependent"])
            or (evidence and not nonlinear_evidence and not best["level_dependent"]
                and r["level_dependent"]))]
        verdict = "ambiguous" if close else "explained"
    return {"verdict": verdict, "best": best, "close": close, "joint": joint,
            "jointly": jointly, "nonlinear_evidence": nonlinear_evidence}


def joint_test(entry: dict, n_rows: int, n_candidates: int,
               alpha: float = JOINT_SIGNIFICANCE) -> dict:
    """The best candidate's held-out chi^2 improvement tested as a whole.

    The cells' test looks at each (direction, segment, DoF, band) cell on its
    own at p < alpha / cells; an effect spread over many cells can stay below
    that in every cell.  Here the improvement of the held-out chi^2 by the
    candidate's k parameters (the likelihood-ratio statistic of the held-out
    rows) is compared with chi^2 on k degrees of freedom at alpha /
    candidates (the best of n_candidates was picked).  The p-value is
    nominal (correlated bins make it too small); `decide` names an effect
    on it only together with the half of the held-out gap removed."""
    k = max(int(entry["n_effect_params"]), 1)
    # delta BIC less its penalty: the held-out chi^2 improvement itself.
    dchi2 = -(float(entry["delta_bic"]) - bic_penalty(entry["n_effect_params"], n_rows))
    p = float(chi2_dist.sf(dchi2, k)) if dchi2 > 0 else 1.0
    return {"effect": entry["effect"], "delta_chi2_heldout": dchi2, "dof": k,
            "p_value": p, "threshold": float(chi2_dist.isf(alpha / max(n_candidates, 1), k)),
            "significant": bool(p < alpha / max(n_candidates, 1))}


def explain(d: dict, n_significant: int, n_candidates: int) -> str:
    """The sentence of `report.json`'s `explanation` for a `decide` result."""
    best, joint, verdict = d["best"], d["joint"], d["verdict"]
    if verdict == "no_significant_gap":
        return ("the base refit leaves no cell whose error exceeds the measurement "
                "uncertainty (+3% model floor) at p < 0.01 (Bonferroni)"
                + (f", and no candidate removes half of the held-out gap with a "
                   f"significant improvement (best: {best['effect']}, "
                   f"{100 * best['gap_reduction_heldout']:.0f}% of it, nominal p = "
                   f"{joint['p_value']:.2g})" if best else ""))
    if verdict == "unexplained":
        return (f"{n_significant} significant cells; the best candidate "
                + (f"({best['effect']}) removes {100 * best['gap_reduction_heldout']:.0f}% of "
                   f"the held-out gap (< {100 * EXPLAINED_REDUCTION:.0f}%)" if best else "none")
                + ": an effect outside the candidate library")
    close = d["close"]
    if close:
        text = (f"{best['effect']} and {', '.join(r['effect'] for r in close)} explain the "
                f"held-out data equally well ({100 * best['gap_reduction_heldout']:.0f}"
                f"% vs {100 * close[0]['gap_reduction_heldout']:.0f}%)")
    else:
        text = (f"{best['effect']} removes {100 * best['gap_reduction_heldout']:.0f}% "
                f"of the held-out gap ({100 * best['gap_reduction_train']:.0f}% on the "
                f"fitted data)")
    if d["jointly"]:
        text = (f"no single cell exceeds the measurement uncertainty (+3% model "
                f"floor) at p < 0.01 (Bonferroni), but together they do: "
                f"{best['effect']}'s held-out chi^2 improvement "
                f"{joint['delta_chi2_heldout']:.0f} is significant "
                f"(nominal p = {joint['p_value']:.2g} against {JOINT_SIGNIFICANCE:g} / "
                f"{n_candidates} candidates); " + text)
    return text


def family_record(fam: dict) -> dict:
    """The report's record of the family-wise conformal test
    (`calibration.thresholds`): the group's k-th score, k, the level, and
    the subject's own score (beyond the group's k-th: the family passes)."""
    return {"family_score": fam["score"], "family_rank": fam["rank"],
            "family_level": fam["level"], "family_subject_score": fam.get("subject_score")}


def held_back_note(ranking: list[dict], fam: dict) -> str | None:
    """What the family-wise test held back, when no candidate is named:
    the candidate furthest beyond its own bound (`null_bound`), if any, with
    the subject's and the group's scores (`calibration.thresholds`) -- a
    lead to check with another test, not a finding.  None when no candidate
    exceeds its own bound."""
    own = [e for e in ranking if e["evidence"] > e["null_bound"]]
    if not own or fam.get("score") is None:
        return None
    e = max(own, key=lambda e: e["evidence"] / e["null_bound"])
    return (f"{e['effect']} exceeds its own bound ({e['evidence']:.0f} against "
            f"{e['null_bound']:.0f}) but the subject stands out of the group less than the "
            f"group's own most outlying subjects do (largest ratio of evidence to scale "
            f"{fam['subject_score']:.2f} against {fam['score']:.2f}; family-wise test): not "
            f"named, a lead to check with another test")
