"""Gap diagnosis against a reference group: the model-form gap cancels.

A real subject differs from any model by more than the measurement error;
on such data the model-based diagnosis (`diagnose.diagnose`) cannot tell an
unmodelled effect from the model's structural error.  A lab that also
measures a *reference group* (same population, seat and protocol, none of
them with the effect in question) has what the model lacks: the
population's own transmissibility and scatter.  The subject is compared
with the group; the model gives only the *shape* of each candidate effect:

1. The group: per row (test x channel x frequency), the mean of log H over
   the K subjects (gain and phase, as one complex number), the deviations
   of each subject from it, and their variance smoothed over 5 bins.
2. The anchor: the model's base parameters (the default 20, within their
   physiological bounds) refit to the group mean, re-linearized after each
   step and a step kept only where it fits better (`anchor.fit_anchor`),
   so that the effect signatures are those
   of a model that resonates where the group does.  What the anchor still
   misses is the model-form gap; the report says where it lies
   (`model_form`).
3. The subject's residual r = log H_subject - group mean, with the
   covariance of the group's smoothed variance times (1 + 1/K) plus the K
   deviations as a low-rank part (subjects differ from the mean by whole
   resonances shifted together, not bin by bin): chi^2 = min_u |e - A u|^2
   + |u|^2, e whitened by the diagonal, A the whitened deviations
   (Woodbury; `profile_nuisance`).
4. Each candidate's signature at the anchor, log H_effect(c) - log
   H_anchor, its coordinates c fitted to r; held out per test (fitted to
   the other tests, the nuisance u too).  A candidate that depends on the
   level is also fitted to the subject's level differences (log H at each
   higher level less the lowest, whitened by the group's own scatter of
   them, `_LevelDesign`), where the subject's structural difference from
   the group cancels.  Its evidence: the held-out chi^2 gain plus that
   level gain (`_evidence`).  An effect the lab measured on some of the
   group's subjects (`contrasts`) takes its measured signature instead of
   the model's, scored the same way.
5. Calibration from the group itself: each reference subject against the
   other K - 1 (leave one out) gives every candidate's evidence on
   subjects without any effect.  A candidate is named when its evidence
   exceeds the upper prediction bound of these K values for one more
   subject (Student t, family-wise `FAMILY_ALPHA` over the candidates;
   `calibration.null_threshold`), and `MIN_GAIN`.  A candidate that no
   reference subject fits (every null gain 0) borrows the group's typical
   spread.  And the subject must stand out of the group as a whole: its
   largest ratio of evidence to scale over the candidates must exceed the
   k-th smallest, k = ceil(0.9 (K + 1)), of the group's subjects' (the
   largest at K = 16; a candidate's scale is its runner-up among the K + 1
   subjects, `calibration.family_scales`) -- a full conformal test that
   holds the family-wise level whatever the gains' distribution
   (`calibration.thresholds`).
6. Verdict: `explained` (among the candidates beyond their null, the one
   furthest beyond its threshold, evidence less threshold), `ambiguous`
   (another within `AMBIGUITY_MARGIN` of its held-out share),
   `unexplained` (the subject differs from the group beyond its scatter, no
   candidate beyond its null) or `no_significant_gap`.  The effect's own share: the share of the
   subject's held-out gap against the group it removes; the model-form gap
   is reported apart.
"""

from __future__ import annotations

import hashlib
import json
import math
import time

import numpy as np

from ...identification.parameters import resolve_free
from ...model.anthropometry import REFERENCE, BodyMeasures
from ...parallel import run_jobs, worker_count
from ...params import ModelParams, load_params
from ...progress import Progress
from ..library.models import STRENGTH_PATH, Candidate, Predictor, Statics, coordinate
from ..single.diagnose import (
    Diagnosis,
    DiagnosisError,
    LabData,
    _code_fingerprint,
    cache_dir,
    candidate_names,
    load_families,
    load_lab_data,
    scoring_fingerprint,
    separation_slope,
)
from ..single.localize import MODEL_FLOOR, cell_keys, gap_value, localize, mark_after
from ..single.verdict import AMBIGUITY_MARGIN, family_record, held_back_note
from .anchor import ANCHOR_ITERATIONS, fit_anchor, read_cache_json, write_cache_json
from .calibration import (
    DEGENERATE_GAIN,
    FAMILY_ALPHA,
    MIN_GAIN,
    calibrate_cells,
    cell_key,
    group_null_spread,
    thresholds,
)
from .contrasts import (
    ContrastScorer,
    contrast_nulls,
    contrast_quality,
    find_contrasts,
    load_contrasts,
)
from .group import (
    ReferenceGroup,
    group_size_caution,
    level_pairs,
    load_reference,
    model_form,
    wrap_log,
)
from .scatter import (
    DESCENT_EVALUATIONS,
    _descend,
    _evidence,
    _gain,
    _gain_at_level_fit,
    _LevelDesign,
    profile_nuisance,
    scatter_residual,
)

#: Where each candidate's fit starts: its strength path (fractions of the
#: model's plausible range, `models.STRENGTH_PATH`) and "off"; for a
#: level-dependent (equivalent-linearized) candidate also, below the path, a
#: decade of weak strengths.  A body that is not the model can carry an effect
#: at a small fraction of the model's scale of it (the lumped reality's foam
#: hardening fits best at about 3% of the model's gamma path, and every start
#: on the path costs more than "off"), and an equivalent-linearized effect's
#: signature is flat at "off" (its equivalent stiffness is below
#: `EQUIVALENT_TOL` for the descent's first difference), so no descent from
#: "off" reaches it.  A linear or delay candidate's signature is smooth at
#: "off", so the descent from there (`_descend`) reaches weak strengths
#: itself; weak starts for them only add local minima (on a blind run of the
#: lumped reality they fitted 3-4 ms reflex delays on four trials where the
#: path's starts found none, one of them that run's false alarm).
WEAK_STRENGTHS = (0.01, 0.03, 0.1)
#: A candidate's fit is flat along its strength path when the costs of the
#: starts differ by less than this fraction.
FLAT_PATH = 1e-6
#: A backrest separation's offset may reach this multiple of the offset at
#: which the last pad point unloads at the anchor (the model's own 8 mm bound
#: is set by the model's pad preload; a body that is not the model can lean on
#: its backrest harder: on `spine5`'s group the anchor's pads carry 5.1 and
#: 9.1 mm, and unload only at 8 and 17 mm; on `lumped`'s at 7.5 and 18 mm).
#: Beyond the unloading, the probability of contact falls over a few standard
#: deviations of the pad's compression (at those anchors 0.3-1.3 mm in the
#: fore-aft tests, 0.1-0.3 mm in the vertical ones: up to about 2.5 mm of
#: offset each), so 1.5x (8-9 mm beyond) reaches a back with no support left.
#: The unloading offsets are also starts of the fit
#: (`_Scorer.separation_starts`): the cost is not monotonic on the way there
#: (a pad losing contact softens the trunk's fore-aft mode before the back
#: support is gone), so no descent from the strength path reaches them.
SEPARATION_REACH = 1.5
CACHE_VERSION = "6"
#: The null's entry holding each reference subject's chi^2 sums per cell.
CELL_NULL = "_cells"




# ---------------------------------------------------------------------------
# Scoring a subject against the group
# ---------------------------------------------------------------------------


class _Scorer:
    """The candidates' signatures at the anchor on the group's rows, and
    their fits to a subject's residual against a (possibly reduced) group."""

    def __init__(self, group: ReferenceGroup, families: dict, slope, base_names):
        self.rows, self.tests = group.rows, group.tests
        self.families, self.slope, self.base_names = families, slope, base_names
        self.statics = Statics(families["base"].family.info, slope)
        self.theta0 = np.zeros(len(base_names))
        base = self._predictor(Candidate(()))
        base.update_statistics(self.theta0)
        self.log0 = np.log(base.predict(self.theta0))
        self.test_masks = [self.rows.test_mask(t.direction, t.level) for t in self.tests]
        self.level_pairs = level_pairs(self.rows)

    def _predictor(self, cand: Candidate) -> Predictor:
        fam = self.families[cand.grid_effect or "base"]
        return Predictor(fam, cand, self.rows, self.tests, self.base_names,
                         Statics(fam.family.info, self.slope))

    def signature_fn(self, cand: Candidate):
        """sig(c): the candidate's log H at coordinates c less the
        anchor's, with the response statistics of the equivalent
        linearization as last refreshed (refresh(c) sets them at c; as in
        `fit_candidate`, they are held during a descent and refreshed
        between descents)."""
        pred = self._predictor(cand)

        def refresh(c):
            pred.update_statistics(np.concatenate([self.theta0, c]))

        def sig(c):
            th = np.concatenate([self.theta0, c])
            return wrap_log(np.log(pred.predict(th)) - self.log0)
        lo, hi = pred.bounds()
        nb = len(self.base_names)
        return sig, refresh, lo[nb:], self.separation_reach(cand, hi[nb:])

    def separation_reach(self, cand: Candidate, hi: np.ndarray) -> np.ndarray:
        """`hi` with a backrest separation's offset bound raised to
        `SEPARATION_REACH` times the offset at which the last pad point
        unloads at the anchor."""
        i = self._separation_index(cand)
        unload = self.statics.pad_unloading_mm()
        if i is None or not len(unload):
            return hi
        hi = hi.copy()
        hi[i] = max(hi[i], SEPARATION_REACH * unload[-1])
        return hi

    @staticmethod
    def _separation_index(cand: Candidate) -> int | None:
        for i, (e, p) in enumerate(cand.params):
            if e == "backrest_separation" and p.name == "offset_mm":
                return i
        return None

    def separation_starts(self, cand: Candidate, off: np.ndarray, hi: np.ndarray) -> list:
        """Extra starts of a candidate with a backrest separation: the
        offsets at which each pad point unloads at the anchor, and the far
        bound (every pad out of contact), the other coordinates "off"; none
        when no pad point unloads (as `separation_reach` then leaves the
        bound)."""
        i = self._separation_index(cand)
        unload = self.statics.pad_unloading_mm()
        if i is None or not len(unload):
            return []
        out = []
        for v in (*unload, hi[i]):
            c = off.copy()
            c[i] = min(v, hi[i])
            out.append(c)
        return out

    def score(self, r: np.ndarray, group: ReferenceGroup, names) -> dict:
        """Fit every candidate in `names` to the residual r (complex log,
        the group's rows); per-row chi^2 before and after, on all rows and
        held out per test."""
        K = group.size
        # (Floored: identical subjects would give infinite weights.)
        sw = 1.0 / np.sqrt(np.maximum(group.variance, 1e-12) * (1 + 1 / K))
        A_all = group.deviations.T * math.sqrt((1 + 1 / K) / (K - 1)) * sw[:, None]

        def rows_chi(x, train, where):
            """Per-row chi^2 at `where` after the nuisance fitted on
            `train`, and the prior term |u|^2."""
            u = profile_nuisance(x, A_all, train)
            chi = np.full(len(x), np.nan)
            chi[where] = np.abs(x - A_all @ u)[where] ** 2
            return chi, float(u @ u)

        def held_out(x):
            """Each test's rows scored with the others' nuisance fit, the
            residual `x` fixed."""
            chi = np.full(len(x), np.nan)
            for m in self.test_masks:
                chi[m] = rows_chi(x, ~m, m)[0][m]
            return chi

        every = np.ones(len(r), bool)
        x0 = r * sw
        chi0_all, p0 = rows_chi(x0, every, every)
        chi0_held = held_out(x0)
        out = {"none": {"chi_all": chi0_all, "chi_heldout": chi0_held, "coords": [],
                        "cost": float(np.sum(chi0_all) + p0), "level_gain": 0.0}}
        cands = {name: Candidate(tuple(name.split("+"))) for name in names}
        # (Only where a candidate scored here depends on the level: a subject
        # job scores one candidate.)
        level = (_LevelDesign(r, group, *self.level_pairs)
                 if len(self.level_pairs[0]) and any(c.level_dependent for c in cands.values())
                 else None)
        for name, cand in cands.items():
            sig, refresh, lo, hi = self.signature_fn(cand)

            def res(c, train, sig=sig):
                return scatter_residual((r - sig(c)) * sw, A_all, train)

            def start_cost(c, refresh=refresh, res=res):
                refresh(c)
                return float(np.sum(res(c, every) ** 2))
            # The strength path and the effect off (where a null subject
            # sits).  Where the fit is flat along all of them (a backrest
            # separation whose pads stay in contact up to the plausible
            # offset), the far end of the bounds too: the signature may start
            # only beyond the path, where no descent from it would go.  (Only
            # then: a start beyond the plausible range raises the null gains
            # of candidates whose path is not flat, and their thresholds.)
            off = np.array([coordinate(p, p.off) if p.off > 0 or not p.log else lo[i]
                            for i, (_, p) in enumerate(cand.params)])
            strengths = (*WEAK_STRENGTHS, *STRENGTH_PATH) if cand.level_dependent \
                else STRENGTH_PATH
            starts = [np.clip(c, lo, hi) for c in [*cand.start_grid(strengths), off,
                                                   *self.separation_starts(cand, off, hi)]]
            costs = [start_cost(c) for c in starts]
            x = starts[int(np.argmin(costs))]
            if cand.grid_effect is None and len(off) and \
                    max(costs) - min(costs) <= FLAT_PATH * min(costs):
                far = np.array([hi[i] if coordinate(p, p.full) > off[i] else lo[i]
                                for i, (_, p) in enumerate(cand.params)])
                if start_cost(far) < min(costs):
                    x = far
            for nfev in (DESCENT_EVALUATIONS, DESCENT_EVALUATIONS // 2):
                refresh(x)
                x = _descend(lambda c, res=res: res(c, every), x, lo, hi, nfev)
            refresh(x)
            s_all = sig(x)
            level_at_fit = (level.gain_of(s_all) if level is not None and cand.level_dependent
                            else 0.0)
            chi_all, p = rows_chi((r - s_all) * sw, every, every)
            chi_held = np.full(len(r), np.nan)
            for m in self.test_masks:
                x2 = _descend(lambda c, m=m, res=res: res(c, ~m), x, lo, hi,
                              DESCENT_EVALUATIONS // 2)
                chi_held[m] = rows_chi((r - sig(x2)) * sw, ~m, m)[0][m]
            out[name] = {"chi_all": chi_all, "chi_heldout": chi_held,
                         "coords": x.tolist(), "cost": float(np.sum(chi_all) + p),
                         "signature": s_all, "level_gain": 0.0, "level_coords": None,
                         "level_gain_at_fit": level_at_fit,
                         "amplitude_driven": cand.amplitude_driven}
            if level is not None and cand.level_dependent:
                out[name].update(level.fit(sig, refresh, lo, hi, [*starts, x]))
                if cand.amplitude_driven:
                    # Held out also at the level-only fit's size (`_evidence`),
                    # the statistics refreshed there once from the nominal ones.
                    xl = np.asarray(out[name]["level_coords"])
                    sig_l, refresh_l, *_ = self.signature_fn(cand)
                    refresh_l(xl)
                    out[name]["chi_heldout_level_fit"] = held_out((r - sig_l(xl)) * sw)
        return out


# ---------------------------------------------------------------------------
# Worker side (the leave-one-out null and the subject, in parallel)
# ---------------------------------------------------------------------------


_W: dict = {}


def _init_worker(state: dict) -> None:
    _W.clear()
    _W.update(state)


def _scorer() -> _Scorer:
    if "scorer" not in _W:
        _W["scorer"] = _Scorer(_W["group"], _W["families"], _W["slope"], _W["base_names"])
    return _W["scorer"]


def _null_job(j: int) -> dict:
    """Subject j of the group against the other K - 1: each candidate's
    evidence (`_evidence`)."""
    g = _W["group"]
    sub = g.without(j)
    r = wrap_log(g.subject_log(j) - sub.mean_log)
    res = _scorer().score(r, sub, _W["names"])
    return {"subject": j, "gains": {n: _evidence(res[n], res["none"]) for n in _W["names"]},
            "cells": {cell_key(c): c["chi2"] for c in localize(g.rows, res["none"]["chi_all"])}}


def _subject_job(name: str) -> dict:
    """One candidate (or "none") fitted to the subject's residual."""
    s = _scorer()
    res = s.score(_W["residual"], _W["group"], [] if name == "none" else [name])
    return {"name": name, **res[name]}


def _null_key(group: ReferenceGroup, names, anchor_key: str) -> str:
    """Cache key of the null gains: group, candidates, anchor, model and scoring code."""
    return hashlib.sha256(json.dumps([CACHE_VERSION, anchor_key, group.fingerprint(), sorted(
        names), _code_fingerprint(), scoring_fingerprint()]).encode()).hexdigest()[:20]


def null_gains(group: ReferenceGroup, families, slope, base_names, names, workers=None,
               progress=None, use_cache: bool = True, anchor_key: str = "") -> dict:
    """{candidate: [held-out gain of each reference subject against the
    others]}: the gains of subjects without any effect, and under `CELL_NULL`
    each subject's chi^2 sums per cell (`calibrate_cells`).  Cached."""
    path = cache_dir() / "reference_null" / f"{_null_key(group, names, anchor_key)}.json"
    cached = read_cache_json(path) if use_cache else None
    if cached is not None:
        return cached
    state = {"group": group, "families": families, "slope": slope, "base_names": base_names,
             "names": list(names)}
    out = {n: [None] * group.size for n in [*names, CELL_NULL]}
    for r in run_jobs([(_null_job, j) for j in range(group.size)],
                      min(worker_count(workers), group.size),
                      (lambda done, total, i, r: progress(done, total)) if progress else None,
                      _init_worker, (state,)):
        for n, g in {**r["gains"], CELL_NULL: r["cells"]}.items():
            out[n][r["subject"]] = g
    if use_cache:
        write_cache_json(path, out)
    return out


# ---------------------------------------------------------------------------
# The diagnosis
# ---------------------------------------------------------------------------


def diagnose_with_reference(data, reference, params: ModelParams | None = None, effects=None,
                            measures: BodyMeasures = REFERENCE, workers: int | None = None,
                            progress: bool = True, channels: str = "plane",
                            use_cache: bool = True, contrasts=None) -> Diagnosis:
    """Diagnose the subject in `data` against the reference group
    `reference` (a `ReferenceGroup`, or subject folders / a folder of them);
    see the module doc.  `contrasts`: a folder of contrast measurements of
    the group (`contrasts`; default the reference folder's own
    ``contrasts``, if any): the effects it holds are scored with their
    empirical signatures instead of the model's."""
    t_start = time.perf_counter()
    params = params if params is not None else load_params()
    names = candidate_names(effects)
    group = reference if isinstance(reference, ReferenceGroup) else \
        load_reference(reference, channels)
    lab = data if isinstance(data, LabData) else load_lab_data(data, channels)
    idx = group.align(lab)
    folder = contrasts if contrasts is not None else find_contrasts(reference)
    contrasts = load_contrasts(folder, group, channels) if folder is not None else None
    empirical = [n for n in names if contrasts is not None and n in contrasts.effects]
    modelled = [n for n in names if n not in empirical]
    H = lab.rows.H[idx]
    if np.any(~np.isfinite(H)) or np.any(H == 0):
        raise DiagnosisError(f"{lab.source}: zero or non-finite transmissibility in the data")
    say = Progress("diagnose", enabled=progress).say
    say(f"reference group of {group.size} subjects, {len(group.rows)} rows, "
        f"{len(group.tests)} tests; {len(names)} candidates"
        + (f", {len(empirical)} with empirical signatures from contrasts" if empirical else ""))
    caution = group_size_caution(group.size)
    if caution:
        say(f"caution: {caution}")
    base_names = [f.name for f in resolve_free("default")]

    t0 = time.perf_counter()
    anchor_prog = Progress("diagnose: model refit to the group", ANCHOR_ITERATIONS - 1,
                           progress, unit="steps")
    anchor = fit_anchor(group, params, measures, workers=workers,
                        progress=lambda k, n, b, a: anchor_prog.step(f"(cost {b:.3g} -> {a:.3g})"),
                        use_cache=use_cache)
    anchor_prog.close()  # (the fit may end before its last step)
    fam_prog = Progress("diagnose: linearizing the candidate models at the anchor", None,
                        progress, unit="models")

    def fam_progress(done, total):
        fam_prog.total = total
        fam_prog.update(done, force=done % 10 == 0)

    families = load_families(anchor["params"], measures, modelled, base_names, workers,
                             fam_progress, use_cache)
    slope = separation_slope(anchor["params"], measures)
    t_fam = time.perf_counter() - t0

    t1 = time.perf_counter()
    null_prog = Progress("diagnose: calibration on the group (leave one out)", group.size,
                         progress, unit="subjects")
    anchor_key = hashlib.sha256(json.dumps(anchor["log_scales"]).encode()).hexdigest()[:16]
    nulls = null_gains(group, families, slope, base_names, modelled, workers,
                       lambda done, total: null_prog.update(done), use_cache, anchor_key)
    residual = wrap_log(np.log(H) - group.mean_log)
    state = {"group": group, "families": families, "slope": slope, "base_names": base_names,
             "names": modelled, "residual": residual}
    fit_prog = Progress("diagnose: candidates", len(modelled) + 1, progress, unit="fitted")
    results = {}
    for r in run_jobs([(_subject_job, n) for n in ["none", *modelled]],
                      min(worker_count(workers), len(modelled) + 1),
                      lambda done, total, i, r: fit_prog.step(f"({r['name']})"),
                      _init_worker, (state,)):
        results[r["name"]] = r
    if empirical:
        nulls.update(contrast_nulls(group, contrasts, empirical))
        scorer = ContrastScorer(group)
        for n in empirical:
            results[n] = scorer.score(residual, n, contrasts.signature(n))
    t_fit = time.perf_counter() - t1
    log_model = _Scorer(group, families, slope, base_names).log0
    report, before, after = _assemble(lab, group, idx, results, names, nulls, anchor,
                                      log_model, base_names)
    if contrasts is not None:
        report["reference"]["contrasts"] = {"source": contrasts.source,
                                            "subjects": contrasts.describe(),
                                            "quality": contrast_quality(group, contrasts)}
    report["timing_s"] = {"families": t_fam, "fits": t_fit,
                          "total": time.perf_counter() - t_start,
                          "workers": min(worker_count(workers), len(names) + 1)}
    rows = lab.rows.take(idx)
    # The figures compare the subject with the group mean and with the
    # group mean plus the best effect's signature.
    shown = {"none": {"H_all": np.exp(group.mean_log)}}
    best = report["best_candidate"]
    if best in results:
        shown[best] = {"H_all": np.exp(group.mean_log + results[best]["signature"])}
    return Diagnosis(report, rows, shown, base_names, before, after)


def decide(ranking: list[dict], n_significant: int) -> tuple[str, str | None, list[str]]:
    """The verdict from the candidates' entries (each with `effect`,
    `evidence`, `null_threshold`, `beyond_null`, `gap_reduction_heldout`;
    sorted here in place) and the number of cells where the subject differs
    from the group beyond its scatter.  Returns (verdict, best effect or
    None, the effects it is ambiguous with).

    The candidates beyond their null come first, ordered by how far their
    evidence exceeds their own threshold; the others follow by evidence.
    Held-out gains of different candidates are not on one scale under the
    null: on one `lumped` group (with per-candidate bounds alone)
    `seat_cushion_dynamics` reaches a threshold of 318 on subjects without
    any effect, `reflex_delay` 68, and a reflex delay gaining 243 (3.6 times
    its bar) lost to the cushion's 369 (1.2 times) when the largest evidence
    was named."""
    ranking.sort(key=lambda e: (not e["beyond_null"],
                                -(e["evidence"] - e["null_threshold"]) if e["beyond_null"]
                                else -e["evidence"]))
    supported = [e for e in ranking if e["beyond_null"]]
    if supported:
        best = supported[0]
        close = [e["effect"] for e in supported[1:] if best["gap_reduction_heldout"]
                 - e["gap_reduction_heldout"] < AMBIGUITY_MARGIN]
        return ("ambiguous" if close else "explained"), best["effect"], close
    return ("unexplained" if n_significant else "no_significant_gap"), None, []


def _against_null(evidence: float, threshold: float, bound: float) -> dict:
    """A candidate's threshold (`calibration.thresholds`), its own bound
    before the family-wise factor, and whether its evidence is beyond the
    threshold (the entries of the report's ranking)."""
    return {"null_threshold": threshold, "null_bound": bound,
            "beyond_null": bool(evidence > threshold)}


def rethreshold(report: dict) -> dict:
    """A reference-group `report` judged again with this code's thresholds
    (`calibration.thresholds`) from its stored null gains and evidence:
    each candidate's `null_threshold`, `null_bound` and `beyond_null`, the
    method's family-wise record, the ranking's order
    and the verdict (`decide`).  The fits are not redone; the explanation
    and the gaps after the best effect stay as stored.  Returns a copy."""
    if report.get("method", {}).get("design") != "reference group":
        raise DiagnosisError("rethreshold needs a diagnosis against a reference group "
                             "(`diagnose --reference`); this report has no null gains")
    out = json.loads(json.dumps(report))
    names = out["method"]["candidates"]
    spread = out["method"].get("borrowed_null_spread")
    if len(out["ranking"]) != len(names):
        raise DiagnosisError(f"the report ranks {len(out['ranking'])} candidates but names "
                             f"{len(names)}")
    thr, bounds, fam = thresholds({e["effect"]: e["null_gains"] for e in out["ranking"]},
                                  {e["effect"]: e["evidence"] for e in out["ranking"]},
                                  borrowed_spread=spread)
    for e in out["ranking"]:
        e.update(_against_null(e["evidence"], thr[e["effect"]], bounds[e["effect"]]))
    out["method"].update(family_record(fam))
    verdict, best, ambiguous_with = decide(out["ranking"], out["significant_cells"])
    out.update(verdict=verdict, best_effect=best, ambiguous_with=ambiguous_with,
               best_candidate=out["ranking"][0]["effect"] if out["ranking"] else None)
    return out


def _assemble(lab, group, idx, results, names, nulls, anchor, log_model, base_names):
    rows = group.rows
    keys = cell_keys(rows)
    base = results["none"]
    n_rows = len(rows)
    ranking = []
    # Each candidate's null: per reference subject, in the group's order.
    null_of = {n: list(nulls.get(n, [])) for n in names}
    spread = group_null_spread(null_of)
    evidence_of = {n: _evidence(results[n], base) for n in names}
    thr, bounds, fam = thresholds(null_of, evidence_of, borrowed_spread=spread)
    for n in names:
        r = results[n]
        cand = Candidate(tuple(n.split("+")))
        gain = _gain(r, base)
        evidence, null = evidence_of[n], null_of[n]
        g0_t, g_t = gap_value(base["chi_all"], keys), gap_value(r["chi_all"], keys)
        g0_h, g_h = gap_value(base["chi_heldout"], keys), gap_value(r["chi_heldout"], keys)
        k = len(r["coords"])
        ranking.append({
            "effect": n,
            "signature": "contrasts" if "params" in r else "model",
            "params": r.get("params") or {
                e: {p: float(v) for p, v in vals.items()}
                for e, vals in cand.values(np.array(r["coords"])).items()},
            "gap_reduction_train": float(1 - g_t / g0_t) if g0_t > 0 else 0.0,
            "gap_reduction_heldout": float(1 - g_h / g0_h) if g0_h > 0 else 0.0,
            "delta_bic": float(-gain + k * math.log(2 * n_rows)),
            "gap_train": g_t, "gap_heldout": g_h,
            "heldout_gain": gain, "level_gain": float(r.get("level_gain", 0.0)),
            "heldout_gain_level_fit": _gain_at_level_fit(r, base),
            "level_gain_at_fit": float(r.get("level_gain_at_fit", 0.0)),
            "amplitude_driven": cand.amplitude_driven,
            "level_params": (r.get("level_params") if "params" in r else
                             None if r.get("level_coords") is None else
                             {e: {p: float(v) for p, v in vals.items()} for e, vals in
                              cand.values(np.array(r["level_coords"])).items()}),
            "evidence": evidence, "null_gains": null,
            **_against_null(evidence, thr[n], bounds[n]),
            "level_dependent": cand.level_dependent, "n_effect_params": k,
            "base_scales": dict(zip(base_names, np.exp(anchor["log_scales"]).tolist(),
                                    strict=True)),
        })
    cells_before = localize(rows, base["chi_all"])
    cell_record = calibrate_cells(cells_before, nulls.get(CELL_NULL))
    significant = [c for c in cells_before if c["significant"]]
    verdict, best_effect, ambiguous_with = decide(ranking, len(significant))
    best = ranking[0] if ranking else None  # the supported best when there is one
    if best_effect is not None:
        if verdict == "ambiguous":
            other = next(e for e in ranking if e["effect"] == ambiguous_with[0])
            explanation = (f"{best_effect} and {', '.join(ambiguous_with)} explain the subject's "
                           f"difference from the reference group equally well "
                           f"({100 * best['gap_reduction_heldout']:.0f}% vs "
                           f"{100 * other['gap_reduction_heldout']:.0f}% of the held-out gap)")
        else:
            explanation = (f"{best_effect} removes {100 * best['gap_reduction_heldout']:.0f}% of "
                           f"the subject's held-out gap to the reference group (chi^2 gain "
                           f"{best['heldout_gain']:.0f} held out, {best['level_gain']:.0f} on "
                           f"the level differences; together "
                           f"{best['evidence'] / best['null_threshold']:.1f}x their threshold "
                           f"from the group's own subjects)")
    elif verdict == "unexplained":
        explanation = (f"the subject differs from the reference group beyond its scatter in "
                       f"{len(significant)} cells, and no candidate exceeds the gains it reaches "
                       f"on the group's own subjects: an effect outside the candidate library, "
                       f"or a subject outside the group's population")
    else:
        explanation = ("the subject is within the reference group's scatter (no cell beyond "
                       "what the group's own subjects reach) and no candidate exceeds the gains "
                       "it reaches on the group's own subjects")
    held_back = held_back_note(ranking, fam) if best_effect is None else None
    if held_back:
        explanation += "; " + held_back
    after = results[best["effect"]] if best else base
    cells_after = localize(rows, after["chi_all"])
    calibrate_cells(cells_after, nulls.get(CELL_NULL))  # (the same bar after the effect)
    form = model_form(group, log_model)
    report = {
        "verdict": verdict,
        "best_effect": best_effect,
        "best_candidate": best["effect"] if best else None,
        "ranking": ranking,
        "localization": mark_after(cells_before, cells_after),
        "gap_before": {"train": gap_value(base["chi_all"], keys),
                       "heldout": gap_value(base["chi_heldout"], keys)},
        "gap_after": {"train": gap_value(after["chi_all"], keys),
                      "heldout": gap_value(after["chi_heldout"], keys)},
        "significant_cells": len(significant),
        "ambiguous_with": ambiguous_with,
        "separating_experiment": None,
        "explanation": explanation,
        "model_form": form,
        "reference": {"subjects": group.sources, "size": group.size,
                      "caution": group_size_caution(group.size),
                      "anchor_scales": dict(zip(base_names,
                                                np.exp(anchor["log_scales"]).tolist(),
                                                strict=True)),
                      "anchor_history": anchor["history"]},
        "data": {"source": lab.source, "rows": len(rows),
                 "rows_not_in_reference": int(len(lab.rows) - len(idx)),
                 "tests": [{"direction": t.direction, "level_rms": t.level,
                            "spectrum": t.source} for t in group.tests],
                 "notes": lab.notes},
        "method": {"design": "reference group", "folds": "test",
                   "heldout_sets": [f"{t.direction}@{t.level:g}" for t in group.tests],
                   "null_alpha": FAMILY_ALPHA, "min_gain": MIN_GAIN,
                   "degenerate_null_gain": DEGENERATE_GAIN,
                   "borrowed_null_spread": spread, **family_record(fam),
                   "explained_reduction": 0.0, "ambiguity_margin": AMBIGUITY_MARGIN,
                   "model_floor": MODEL_FLOOR,
                   "significance": "chi^2 per cell against the group's scatter, p < 0.01 / "
                                   "cells, and beyond the group's own subjects (family-wise)",
                   "cell_calibration": cell_record,
                   "candidates": names},
    }
    return report, cells_before, cells_after
