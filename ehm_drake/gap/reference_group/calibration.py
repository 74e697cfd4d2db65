"""Thresholds of the gap diagnosis against a reference group: how much
evidence a candidate must show to be named, from the evidence it reaches on
the group's own subjects, each scored against the others (leave one out;
`reference.null_gains`)."""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import t as student_t

from ..single.diagnose import DiagnosisError

#: The chance that a subject without any effect has one named (family-wise,
#: over the candidates scored): the false-alarm bar of the validation (10%),
#: Bonferroni-split between the candidates (`null_threshold`).
FAMILY_ALPHA = 0.10
#: ... and at least this chi^2 gain (the 0.1% point of chi^2 with 3
#: degrees of freedom: a candidate of up to 3 parameters at p < 0.001).
MIN_GAIN = 16.3
#: A candidate's null is degenerate when every reference subject's gain is
#: within this of 0 (its fit stays "off" up to round-off; the blind run's
#: scoring gives such a candidate no rank either): its threshold then
#: borrows the group's typical spread (`null_threshold`).  On one `spine5`
#: group the separation's null was 8 exact zeros, its threshold
#: `MIN_GAIN`, and a no-effect subject was named with a gain of 180.
DEGENERATE_GAIN = 1.0


def null_threshold(null, n_candidates: int, alpha: float = FAMILY_ALPHA,
                   name: str = "a candidate", borrowed_spread: float | None = None,
                   clip: float = 0.0) -> float:
    """The evidence (`reference._evidence`: held-out gain plus level
    gain) a candidate must exceed to be named: the one-sided
    upper prediction bound, at level alpha / n_candidates, of one more
    subject's gain from the K gains of the group's own subjects (`null`,
    leave one out), mean + t_{K-1} s sqrt(1 + 1/K) -- exact for normal
    gains --, the same bound on the cube roots of the gains clipped at 0,
    cubed -- close for chi^2-like gains, which the first bound under-covers
    4-6 fold -- and `MIN_GAIN`, whichever is largest.  The first bound
    counts where the null is mostly negative (its median below -`MIN_GAIN`)
    or degenerate: the spread counts there, not only the largest: a
    candidate whose fit ends at a bound on every subject (gains -900 to
    -100) can still reach +150 on the next one, which twice the largest
    (-100) would not cover.  Where half the gains or more are near 0 or
    above, a negative tail would only widen it (see below).
    `name`: the candidate, for errors.
    `clip`: where the cube-root bound's gains are clipped (0; other values
    are for studies of the rule, `bench/null_calibration.py`).

    A degenerate null -- every gain within `DEGENERATE_GAIN` of 0: the
    candidate's fit stays "off" on every reference subject -- has no spread
    of its own, and its bound would fall to `MIN_GAIN` although K subjects
    cannot show that one more stays off (with K = 8, 0 of 8 is compatible
    with one subject in four fitting it, at 90% confidence).  Its spread is
    then `borrowed_spread`, the group's typical one (`borrowed_spread`:
    the median of the candidates' null variances, square-rooted)."""
    g = np.asarray([x for x in null if x is not None], float)
    if len(g) < 2 or not np.all(np.isfinite(g)):
        raise DiagnosisError(f"{name}: the reference group's null needs at least 2 finite "
                             f"gains, got {list(null)}")
    if n_candidates < 1 or not 0 < alpha < 1:
        raise ValueError(f"n_candidates >= 1 and 0 < alpha < 1 needed, got {n_candidates}, "
                         f"{alpha}")
    k = len(g)
    q = student_t.ppf(1 - alpha / n_candidates, k - 1) * math.sqrt(1 + 1 / k)
    spread = g.std(ddof=1)
    degenerate = borrowed_spread is not None and bool(np.all(np.abs(g) <= DEGENERATE_GAIN))
    if degenerate:
        spread = max(spread, float(borrowed_spread))
    # Where half the subjects or more are near 0 (above -MIN_GAIN) or above,
    # the linear bound is left out: the fit stays off or
    # helps there, and the negative tail is fits that overfit the training
    # rows, which widens the linear bound without saying how far above 0
    # the next subject reaches.  On `lumped` the seat foam's null was half
    # -1..23 and half -3,698..-5: a linear bound of 1,775 against a largest
    # gain of 23, and foams with evidence 501 and 515 went unnamed.  The
    # cube-root bound alone there; false alarms stay with the family-wise
    # test (`thresholds`).
    linear = degenerate or bool(np.median(g) < -MIN_GAIN)
    bound = g.mean() + q * spread if linear else -math.inf
    # The same bound on the cube roots of the gains clipped at 0 (Wilson &
    # Hilferty 1931: the cube root of a chi^2 variable is nearly normal).
    # The null gains are skewed to the right: most near 0, one subject in
    # eight far above (e.g. 9, 0, -5, 17, 0, -6, 342, 37), as chi^2 with
    # 1-3 degrees of freedom is; the bound above, exact for normal gains, is
    # then exceeded 4-6 times more often than alpha / n, the one on cube
    # roots 1-1.5 times (`tests/test_gap_reference.py`).  Negative gains (a
    # fit that fails on the held-out test) say nothing about how far above 0
    # the next subject reaches, and on the cube-root scale they would widen
    # the spread most (thresholds 2.5-5.6 times the true quantile on
    # simulated held-out gains): clipped.  Clipped at -MIN_GAIN instead
    # (a loss within the noise taken as the null's own spread), 4
    # instead of 10 of 68 measured no-effect `lumped` subjects had an effect
    # named (`bench/null_calibration.py`), but the fresh effect runs lost
    # hits: seeds 2046 + 2047, 30 of 51 found against 35.  Gains that are
    # mostly negative (a fit ending at its bounds, the spread several
    # hundred) keep the linear bound, the higher one there.
    c = np.cbrt(np.maximum(g, clip))
    cube_bound = float(c.mean() + q * c.std(ddof=1)) ** 3
    return float(max(MIN_GAIN, bound, cube_bound))


def group_null_spread(nulls: dict) -> float | None:
    """The spread of a typical candidate's null gains on the group: the
    square root of the median, over the candidates, of their null gains'
    variance (None without any candidate of 2 finite gains).  What a
    degenerate null borrows (`null_threshold`)."""
    var = []
    for gains in nulls.values():
        g = np.asarray([x for x in gains if x is not None], float)
        if len(g) >= 2 and np.all(np.isfinite(g)):
            var.append(g.var(ddof=1))
    return float(math.sqrt(np.median(var))) if var else None


def thresholds(nulls: dict, evidence: dict, alpha: float = FAMILY_ALPHA,
               borrowed_spread: float | None = None) -> tuple[dict, dict, dict]:
    """Every candidate's threshold for one subject, from the group's null
    gains (`nulls`: {candidate: [evidence of reference subject 0 .. K-1,
    each against the others]}, the same subjects in the same order for
    every candidate) and the subject's own evidence (`evidence`:
    {candidate: value}).  Returns (thresholds, bounds, the family-wise
    record).

    Two conditions, both needed for a candidate to be named:

    1. its own bound (`null_threshold` on its null gains, Bonferroni over
       the candidates): the thresholds' first form;
    2. a full conformal test of the family (Vovk, Gammerman & Shafer 2005;
       Lei et al. 2018), which holds the family-wise level whatever the
       gains' distribution.  The K + 1 subjects -- the group's and this
       one -- are scored alike: each candidate's scale (`family_scales`)
       is its runner-up among the K + 1 values of its evidence (the
       largest of them less the largest), at least the candidates' median
       runner-up and `MIN_GAIN`; a subject's score is its largest ratio of
       evidence to scale over the candidates.  The scales are symmetric
       functions of the K + 1 subjects, so the scores stay exchangeable
       (scales from the group's K values alone do not keep that:
       simulated, 30% false alarms against 1/17), and no single subject
       moves them, so a strong effect's score is not capped by its own
       value.  A subject without any effect is exchangeable with the
       group's, so its score exceeds the k-th smallest of theirs, k =
       ceil((1 - alpha)(K + 1)), with probability at most 1 - k / (K + 1)
       <= alpha (with K < 1 / alpha - 1 subjects the largest is used and
       the level is 1 / (K + 1)).  For candidate c this reads: evidence >
       (its scale) x (that k-th score).  (Each reference subject's
       evidence is against K - 1 others, the subject's against K: the
       reference subjects' scores are, if anything, the larger, and the
       test the more cautious.)

       The scale is the runner-up, not a parametric bound on the K + 1
       values less the largest (an earlier form): a candidate whose null
       has a heavy cluster (on `spine5`, backrest separation: 13 of 16
       subjects at 0, two at 436 and 1,005) then scores its outlier
       against the cluster (1,005 / 436), not against a bound that the
       cluster itself exceeds (1,005 / 309), and a candidate with a tight
       null (visceral mass: at most 186 on the group) scores an effect
       against that null, not against a bound twice its largest value.
       The median floor keeps a lone subject on an otherwise silent
       candidate (runner-up 0) from setting everyone's bar.

    Why: the per-candidate bounds assume a distribution of the gains, and
    the nulls of a body that is not the model are mixtures -- most subjects
    0 (the fit stays "off"), a few far above -- whose tails no bound from K
    values captures: on one `spine5` group of 16 they let 6 of 30
    fresh no-effect subjects have an effect named (20%).  The threshold
    reported is max(bound, scale x k-th score): the evidence must exceed
    it.  It depends on the subject's evidence (through the scales), so it
    is the subject's own."""
    names = list(nulls)
    if not names:
        return {}, {}, {"score": None, "rank": None, "level": None, "subjects": 0}
    n = len(names)
    sizes = {len(nulls[c]) for c in names}
    if len(sizes) > 1:
        raise DiagnosisError(f"the candidates' null gains are of different lengths {sizes}: "
                             "the family-wise test needs each reference subject's gain for "
                             "every candidate")
    missing = [c for c in names if c not in evidence]
    if missing:
        raise DiagnosisError(f"no evidence for candidates {missing}")
    bad = {c: evidence[c] for c in names
           if evidence[c] is None or not math.isfinite(evidence[c])}
    if bad:
        raise DiagnosisError(f"the subject's evidence is not finite for {bad}: its fit "
                             "failed; no threshold can judge it")
    bounds = {c: null_threshold(nulls[c], n, alpha, name=c, borrowed_spread=borrowed_spread)
              for c in names}
    scale = family_scales({c: [*nulls[c], evidence[c]] for c in names})
    k_subj = sizes.pop()
    ratio = np.full((k_subj, n), -np.inf)
    for i, c in enumerate(names):
        g = np.array([np.nan if x is None else x for x in nulls[c]], float)
        ok = np.isfinite(g)
        ratio[ok, i] = g[ok] / scale[c]
    score, k, level = conformal_bar(ratio.max(axis=1), alpha)
    thr = {c: max(bounds[c], scale[c] * score) for c in names}
    return thr, bounds, {"score": score, "rank": k, "level": level,
                         "subjects": int(k_subj),
                         "subject_score": float(max(evidence[c] / scale[c] for c in names))}


def conformal_bar(scores, alpha: float) -> tuple[float, int, float]:
    """The bar of a full conformal test from the K group subjects' `scores`:
    the k-th smallest, k = ceil((1 - alpha)(K + 1)) (the largest with fewer
    than 1 / alpha - 1 subjects).  A subject exchangeable with the group's
    exceeds it with probability at most the level 1 - k / (K + 1).
    Returns (bar, k, level)."""
    s = np.sort(np.asarray(scores, float))
    K = len(s)
    k = min(K, math.ceil((1 - alpha) * (K + 1)))
    return float(s[k - 1]), int(k), float(1 - k / (K + 1))


def family_scales(values: dict) -> dict:
    """Each candidate's scale in the family-wise test, from its K + 1
    values ({candidate: values}, None left out): its runner-up (the
    largest of them less the largest), at least the median runner-up of
    the candidates and `MIN_GAIN` ({} for no candidate)."""
    if not values:
        return {}
    runner_up = {}
    for c, vals in values.items():
        v = _all_but_the_largest(vals)
        runner_up[c] = v[-1] if v else -math.inf
    floor = max(MIN_GAIN, float(np.median(list(runner_up.values()))))
    return {c: max(floor, r) for c, r in runner_up.items()}


def _all_but_the_largest(values) -> list:
    """`values` (None left out) without one of its largest: a symmetric
    function of them that one subject, however far out, does not move."""
    v = sorted(x for x in values if x is not None)
    return v[:-1]


def cell_key(cell: dict) -> str:
    """A localization cell's name: direction, segment, DoF and band."""
    return f"{cell['direction']}|{cell['segment']}|{cell['dof']}|{cell['f_lo_hz']:g}"


def calibrate_cells(cells: list[dict], group_cells: list[dict] | None,
                    alpha: float = 0.01) -> dict | None:
    """Judge the subject's localization `cells` against the sums the group's
    own subjects reach in them, each against the others (`group_cells`: one
    {`cell_key`: chi^2 sum} per reference subject): a cell stays
    significant only beyond both its chi^2 bound and the group's bar, and
    carries that bar (``group_bar``).  Returns the record (None, and the
    cells as they are, without the group's sums).

    The chi^2 bound takes a cell's frequency bins as independent. Between
    subjects they are not: a subject's deviation from the group is smooth
    in frequency (neighbouring bins correlate 0.4-0.9 on a `lumped` group of
    32), and 12 of that group's 32 subjects pass the bound in some cell
    against the other 31. So, as for the candidates (`thresholds`), a full
    conformal test over the cells: each cell's scale is the median of its
    K + 1 sums, a subject's score its largest ratio of sum to scale, and the
    bar the k-th smallest of the group's scores, k = ceil((1 - alpha)(K +
    1)), the largest for fewer than 1 / alpha - 1 subjects (level 1 / (K + 1))."""
    if not group_cells:
        return None
    keys = [cell_key(c) for c in cells]
    missing = [k for k in keys if any(k not in g for g in group_cells)]
    if missing:
        raise DiagnosisError(f"the group's leave-one-out cell sums lack cells {missing[:3]}")
    G = np.array([[g[k] for k in keys] for g in group_cells], float)
    s = np.array([c["chi2"] for c in cells], float)
    scale = np.maximum(np.median(np.vstack([G, s]), axis=0), 1e-12)
    bar, _, level = conformal_bar((G / scale).max(axis=1), alpha)
    for c, sc in zip(cells, scale, strict=True):
        c["group_bar"] = float(sc * bar)
        c["significant"] = bool(c["significant"] and c["chi2"] > c["group_bar"])
    return {"cell_bar_score": bar, "cell_level": level, "cell_subjects": len(G),
            "subject_cell_score": float((s / scale).max()) if len(s) else 0.0}
