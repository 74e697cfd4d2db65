"""Sim-to-real gap diagnosis: where the model and the lab disagree, which
unmodelled effect explains it, and how far the gap shrinks with it.

Procedure (`diagnose`):

1. The measured transmissibility rows (excitation-plane channels, 0.1-12 Hz)
   with their H1 uncertainty (`localize`).  Each test's seat spectrum comes
   from its time series when the lab gave them (else flat 0.1-12 Hz at the
   stated level).
2. The base refit: the default set of base parameters (20) is fitted to all
   data with a subject-variability prior (log-scale std 0.25).  What it
   leaves is the gap; its cells (direction x segment x DoF x band) are
   tested for significance and ranked by share.  No significant cell and
   no candidate whose held-out improvement is itself significant (the
   joint test of step 4): `no_significant_gap`.
3. Every candidate effect (`effects.EFFECTS`) is fitted together with the
   base parameters (`models.fit_candidate`), on all data and in cross-
   validation folds: each test (direction, level) is held out once and
   predicted by the fit to the others.  Held-out rows decide: the held-out
   gap reduction against the base refit, and delta BIC = held-out chi^2
   difference + k ln(n) for the k effect parameters.
4. Verdict: `explained` when the best candidate removes at least half of
   the held-out gap and clearly more than the runner-up; `ambiguous` when
   the runner-up is as good (within 5 points of held-out reduction, and not
   separated by the level-dependence evidence), with the experiment that
   would separate them (the test and channel where their predictions differ
   most); `unexplained` when no candidate removes half of it.  An effect
   spread thinly over many cells can leave every cell below its
   Bonferroni threshold (p < 0.01 / cells) and still be clear in all of
   them together: where no cell is significant, the best candidate is
   still named when it removes at least half of the held-out gap (the
   `explained` bar) and its held-out chi^2 improvement passes a chi^2 test
   with its k parameters at p < 0.01 / candidates (`joint_test`; on the
   thousands of rows of a lab data set the BIC penalty k ln(2n) is already
   about that threshold; on a few hundred rows the test is the stricter).
   That p-value is nominal: the bins of a cell are correlated (Welch
   averaging), so on no-effect data it falls to 1e-8; the half of the
   held-out gap is the guard (no-effect and undetectable trials of the
   own-family blind run: at most 40%).
5. The model-form gap (`discrepancy`): when no candidate explains it, a
   smooth discrepancy per direction and channel, shared by the levels, with
   its scale estimated from the data, is fitted; if it removes at least half
   of the held-out gap, the candidates are scored again beyond it.  Verdict
   `structural` (the model's form dominates the gap; where it lies) unless
   one effect removes at least 20% of what remains beyond the discrepancy,
   then `explained` with the effect's own share of the gap.
6. Evidence from the data alone: level dependence (the same direction's
   FRF at two levels differing beyond their uncertainty) and coherence
   that does not rise with level (linear + sensor noise would give
   SNR-scaled coherence), both pointing at nonlinear candidates.
7. The level rule (`resonance.softening_rule`): when nothing else is named,
   a vertical resonance that falls clearly more per doubling of the level
   than the refitted model's names `softening` (`explained`).
"""

from __future__ import annotations

import copy
import fcntl
import hashlib
import json
import math
import os
import pickle
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import chi2 as chi2_dist

from ...analysis.formats import (
    DataFormatError,
    FrfData,
    find_test_timeseries,
    read_frf,
    read_timeseries,
)
from ...identification.parameters import resolve_free
from ...model.anthropometry import REFERENCE, BodyMeasures
from ...parallel import check_not_starting_worker, run_jobs, worker_count
from ...params import ModelParams, load_params
from ...progress import Progress
from ..library.effects import EFFECT_NAMES, EFFECTS
from ..library.family import build_families, linearize_cut, static_penetrations
from ..library.models import (
    GRID_EFFECTS,
    Candidate,
    Predictor,
    Statics,
    TestInput,
    coordinate,
    family_of,
    family_specs,
    fit_candidate,
)
from .localize import (
    BANDS,
    Rows,
    cell_keys,
    chi2_rows,
    delta_bic,
    gap_value,
    localize,
    mark_after,
    rows_from_frf,
)
from .resonance import apply_softening_rule, resonance_shift
from .verdict import AMBIGUITY_MARGIN, EXPLAINED_REDUCTION, decide, explain

SEPARATION_OFFSET_MM = 4.0
CACHE_VERSION = "1"


class DiagnosisError(ValueError):
    """Data or settings the diagnosis cannot work with."""


# ---------------------------------------------------------------------------
# Lab data
# ---------------------------------------------------------------------------


@dataclass
class LabData:
    frf: FrfData
    rows: Rows
    tests: list[TestInput]
    source: str
    notes: list[str] = field(default_factory=list)


def _find_timeseries(root: Path, direction: str, level: float) -> Path | None:
    try:
        return find_test_timeseries(root, direction, level)
    except DataFormatError as e:
        raise DiagnosisError(str(e)) from None


def load_lab_data(path, channels: str = "plane") -> LabData:
    """Measured data: a folder with frf.csv (every test, with level_rms),
    optionally tests.json and per-test time series (<d>_<level>/
    timeseries.csv); or a folder with one timeseries.csv; or an frf.csv."""
    from ...analysis.transmissibility import transmissibility

    path = Path(path)
    notes = []
    if path.is_file():
        frf, root = read_frf(path), path.parent
    elif path.is_dir():
        root = path
        if (path / "frf.csv").is_file():
            frf = read_frf(path / "frf.csv")
        elif (path / "timeseries.csv").is_file():
            ts = read_timeseries(path / "timeseries.csv")
            frf = transmissibility(ts, nperseg=int(round(10.0 * ts.fs)))
            notes.append("frf estimated from timeseries.csv (H1, 10 s segments)")
        else:
            raise DiagnosisError(f"{path}: no frf.csv or timeseries.csv")
    else:
        raise FileNotFoundError(f"data not found: {path}")
    if not frf.has_level or np.any(np.isnan(frf.level_rms)):
        raise DiagnosisError(
            f"{path}: every FRF row needs its test's level (level_rms, m/s^2 RMS): the "
            "level-dependent candidates are judged at the level of each test")
    if not frf.has_n_averages:
        notes.append("no n_averages column: 10 averages assumed for the error estimate")
    rows = rows_from_frf(frf, channels=channels)
    if len(rows) == 0:
        raise DiagnosisError(f"{path}: no rows in the 0.1-12 Hz bands on the analysed "
                             "channels")
    tests = []
    for d, lv in rows.tests:
        p = _find_timeseries(root, d, lv)
        if p is not None:
            ts = read_timeseries(p)
            tests.append(TestInput.from_seat_acceleration(d, lv, ts.seat(d), ts.fs))
        else:
            tests.append(TestInput.flat(d, lv))
            notes.append(f"test {d} @ {lv:g} m/s^2: no time series; flat 0.1-12 Hz seat "
                         "spectrum assumed")
    levels = {}
    for d, lv in rows.tests:
        levels.setdefault(d, []).append(lv)
    if all(len(v) < 2 for v in levels.values()):
        notes.append("one level per direction: level dependence cannot be observed; the "
                     "nonlinear candidates are judged at a single level")
    return LabData(frf, rows, tests, str(path), notes)


# ---------------------------------------------------------------------------
# Families (cached: they depend on the model only, not on the data)
# ---------------------------------------------------------------------------


def cache_dir() -> Path:
    env = os.environ.get("EHM_DRAKE_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "ehm_drake"


def _sources_fingerprint(files) -> str:
    """Hash of the contents of `files`, in the order given."""
    h = hashlib.sha256()
    for f in files:
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def _code_fingerprint() -> str:
    """Hash of the sources the linear families depend on (a cached family
    from other model code is never reused)."""
    root = Path(__file__).resolve().parents[2]
    library = root / "gap" / "library"
    return _sources_fingerprint(sorted([
        *root.glob("model/*.py"), *root.glob("systems/*.py"), root / "diagram.py",
        root / "params.py", library / "family.py", library / "effects.py",
        root / "simulation.py", root / "analysis" / "linear.py"]))


def scoring_fingerprint() -> str:
    """Hash of the sources that score a candidate on a residual (cached
    reference-group thresholds from other scoring code are never reused)."""
    gap = Path(__file__).resolve().parents[1]
    return _sources_fingerprint(gap / n for n in (
        "library/models.py", "reference_group/group.py", "reference_group/reference.py",
        "reference_group/scatter.py", "single/localize.py"))


def _family_key(params: ModelParams, measures: BodyMeasures, base_names, spec) -> str:
    blob = json.dumps([CACHE_VERSION, _code_fingerprint(), params.to_dict(),
                       [measures.mass_kg, measures.stature_m,
                       measures.sitting_height_m], list(base_names), spec.name,
                       spec.effects, [list(map(float, v)) for v in spec.grid_values],
                       spec.grid_mode], sort_keys=True, default=float)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def load_families(params: ModelParams, measures: BodyMeasures, effect_names, base_names,
                  workers: int | None = None, progress=None, use_cache: bool = True) -> dict:
    """The linear families (base + grid effects) and the static separation
    slope, from the cache or computed (and cached)."""
    check_not_starting_worker("the linear families' build")
    specs = family_specs(effect_names)
    cdir = cache_dir() / "families"
    if not use_cache:
        return _load_or_build(specs, cdir, params, measures, base_names, workers, progress,
                              False)
    # One builder at a time: concurrent diagnoses (a batch, a blind run, parallel
    # tests) wait for the first to fill the cache instead of repeating its work.
    try:
        cdir.mkdir(parents=True, exist_ok=True)
        lock = open(cdir / ".lock", "w")  # noqa: SIM115 (held across the build)
    except OSError:
        return _load_or_build(specs, cdir, params, measures, base_names, workers, progress,
                              True)
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            return _load_or_build(specs, cdir, params, measures, base_names, workers,
                                  progress, True)
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _load_or_build(specs, cdir, params, measures, base_names, workers, progress,
                   use_cache) -> dict:
    out, todo = {}, []
    for sp in specs:
        path = cdir / f"{_family_key(params, measures, base_names, sp)}.pkl"
        if use_cache and path.is_file():
            try:
                with open(path, "rb") as f:
                    out[sp.name] = pickle.load(f)
                continue
            except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ImportError):
                pass
        todo.append((sp, path))
    if todo:
        fams = build_families(params, [sp for sp, _ in todo], measures, base_names, workers,
                              progress)
        for sp, path in todo:
            out[sp.name] = fams[sp.name]
            if use_cache:
                try:
                    path.parent.mkdir(parents=True, exist_ok=True)
                    tmp = path.with_suffix(".tmp")
                    with open(tmp, "wb") as f:
                        pickle.dump(fams[sp.name], f)
                    tmp.replace(path)
                except OSError:
                    pass
    return out


def separation_slope(params: ModelParams, measures: BodyMeasures) -> np.ndarray:
    """d(static penetration)/d(backrest offset), m per mm, per restraint point."""
    p0 = static_penetrations(params, measures)
    p1 = static_penetrations(params, measures, {"backrest_separation": {
        "offset_mm": SEPARATION_OFFSET_MM}})
    return (p1 - p0) / SEPARATION_OFFSET_MM


# ---------------------------------------------------------------------------
# Folds
# ---------------------------------------------------------------------------


def make_folds(rows: Rows) -> tuple[str, list[tuple[str, np.ndarray]]]:
    """Held-out sets: each test (direction, level) once when there are two
    or more tests, else the segments (pelvis + knees vs trunk + head)."""
    tests = rows.tests
    if len(tests) >= 2:
        folds = [(f"{d}@{lv:g}", rows.test_mask(d, lv)) for d, lv in tests]
        return "test", folds
    a = np.isin(rows.segment, ["pelvis", "knee_l", "knee_r"])
    return "segment", [("pelvis+knees", a), ("trunk+head", ~a)]


# ---------------------------------------------------------------------------
# Candidate evaluation (worker side)
# ---------------------------------------------------------------------------


_W: dict = {}


def _init_worker(state: dict) -> None:
    _W.clear()
    _W.update(state)


def _evaluate_candidate(name: str) -> dict:
    """Fit candidate `name` to all data and in every fold; per-row chi^2."""
    st = _W
    t0 = time.perf_counter()
    cand = Candidate(() if name == "none" else tuple(name.split("+")))
    fam = st["families"][cand.grid_effect or "base"]
    rows, folds = st["rows"], st["folds"]
    pred = Predictor(fam, cand, rows, st["tests"], st["base_names"],
                     Statics(fam.family.info, st["slope"]))
    all_rows = np.ones(len(rows), bool)
    fit = fit_candidate(pred, all_rows)
    recentered = None
    if cand.grid_effect:
        # Exact at the fitted effect parameters (the grid interpolates).
        coords = fit.theta[pred.n_base:]
        exact = linearize_cut(st["params"], st["measures"], cand.values(coords))
        fam = copy.copy(fam)
        fam.recenter(coords, exact)
        pred.family = fam
        recentered = (coords.copy(), fam.correction)
        fit = fit_candidate(pred, all_rows, fit.theta)
    chi_all = chi2_rows(rows, pred.predict(fit.theta))
    chi_held = np.full(len(rows), np.nan)
    fold_fits = []
    for fname, held in folds:
        ff = fit_candidate(pred, ~held, fit.theta, rounds=1)
        pred.update_statistics(ff.theta)
        chi_held[held] = chi2_rows(rows.take(held), pred.predict(ff.theta, held)[held])
        fold_fits.append({"fold": fname, "theta": ff.theta.tolist(), "wall_s": ff.wall_s})
    pred.update_statistics(fit.theta)
    return {"name": name, "theta": fit.theta.tolist(), "chi_all": chi_all,
            "chi_heldout": chi_held, "cost": fit.cost, "folds": fold_fits,
            "sigmas": fit.sigmas, "recentered": recentered,
            "wall_s": time.perf_counter() - t0, "H_all": pred.predict(fit.theta)}


# ---------------------------------------------------------------------------
# Evidence from the data alone
# ---------------------------------------------------------------------------


def level_evidence(rows: Rows) -> dict:
    """Per direction with two or more levels: do the FRFs at the lowest
    and highest level differ beyond their measurement error (no model
    floor), and does the coherence rise with level as linear + noise
    would make it?"""
    from .localize import relative_variance

    out = {}
    for d in "xyz":
        levels = sorted({lv for dd, lv in rows.tests if dd == d})
        if len(levels) < 2:
            continue
        lo, hi = levels[0], levels[-1]
        a, b = rows.take(rows.test_mask(d, lo)), rows.take(rows.test_mask(d, hi))
        ka = {(c, round(f, 6)): i for i, (c, f) in enumerate(zip(a.channel, a.freq,
                                                                 strict=True))}
        pairs = [(ka[(c, round(f, 6))], j) for j, (c, f) in enumerate(zip(b.channel, b.freq,
                                                                          strict=True))
                 if (c, round(f, 6)) in ka]
        if not pairs:
            continue
        ia, ib = np.array(pairs).T
        va = relative_variance(a.coherence[ia], a.n_averages[ia], 0.0)
        vb = relative_variance(b.coherence[ib], b.n_averages[ib], 0.0)
        mag = np.maximum(np.abs(a.H[ia]), np.abs(b.H[ib]))
        chi = np.abs(a.H[ia] - b.H[ib]) ** 2 / ((va + vb) * mag**2 + 1e-300)
        dof = 2 * len(chi)
        # Coherence: linear + fixed sensor noise predicts SNR x (hi/lo)^2.
        g_lo = np.clip(a.coherence[ia], 1e-3, 0.999)
        snr = g_lo / (1 - g_lo) * (hi / lo) ** 2
        g_pred = snr / (1 + snr)
        informative = (g_lo > 0.2) & (g_lo < 0.95)
        deficit = float(np.mean(g_pred[informative] - b.coherence[ib][informative])) \
            if np.any(informative) else 0.0
        out[d] = {
            "levels": [lo, hi],
            "difference_gap": max(float(chi.sum() / dof - 1.0), 0.0),
            "p_value": float(chi2_dist.sf(chi.sum(), dof)),
            "significant": bool(chi2_dist.sf(chi.sum(), dof) < 0.01),
            "coherence_deficit": deficit,
        }
    return out


# ---------------------------------------------------------------------------
# The diagnosis
# ---------------------------------------------------------------------------


@dataclass
class Diagnosis:
    report: dict
    rows: Rows
    results: dict  # candidate name -> worker result
    base_names: list[str]
    cells_before: list
    cells_after: list


def _heldout_gap(chi: np.ndarray, keys: np.ndarray) -> float:
    return gap_value(chi, keys)


def _gap_of(res: dict, keys: np.ndarray) -> dict:
    """The gap a candidate's fit leaves: on the fitted data and held out."""
    return {"train": gap_value(res["chi_all"], keys),
            "heldout": _heldout_gap(res["chi_heldout"], keys)}


def _ranking_entry(name, res, base, n_base, n_rows, base_names, keys) -> dict:
    cand = Candidate(() if name == "none" else tuple(name.split("+")))
    theta = np.array(res["theta"])
    g_train0, g_train = gap_value(base["chi_all"], keys), gap_value(res["chi_all"], keys)
    g_held0 = _heldout_gap(base["chi_heldout"], keys)
    g_held = _heldout_gap(res["chi_heldout"], keys)
    k = len(cand.params)
    dbic = delta_bic(res["chi_heldout"], base["chi_heldout"], k, n_rows)
    values = cand.values(theta[n_base:])
    return {
        "effect": name,
        "params": {e: {p: float(v) for p, v in vals.items()} for e, vals in values.items()},
        "gap_reduction_train": float(1 - g_train / g_train0) if g_train0 > 0 else 0.0,
        "gap_reduction_heldout": float(1 - g_held / g_held0) if g_held0 > 0 else 0.0,
        "delta_bic": dbic,
        "gap_train": g_train,
        "gap_heldout": g_held,
        "level_dependent": cand.level_dependent,
        "n_effect_params": k,
        "base_scales": {n: float(math.exp(b)) for n, b in zip(base_names, theta[:n_base],
                                                              strict=True)},
    }


def separating_experiment(best: dict, other: dict, state: dict) -> dict:
    """The test (direction, level) and channel/band where the fitted models
    of two candidates differ most, in units of a 3% measurement."""
    from ..library.models import TestInput as TI
    from .localize import MODEL_FLOOR, band_index

    rows = state["rows"]
    f = np.arange(1, 121) * 0.1
    measured = {(d, round(lv, 6)) for d, lv in rows.tests}
    levels = sorted({lv for _, lv in rows.tests} | {1.0, 1.5})
    best_score = None
    preds = {}
    for name, res in (("a", best), ("b", other)):
        cand = Candidate(() if res["effect"] == "none" else tuple(res["effect"].split("+")))
        fam = family_of(state, res["effect"])
        tests = [TI.flat(d, lv) for d in "xyz" for lv in levels]
        # Synthetic rows: every plane channel at f, for each test.
        from ...systems.outputs import CHANNEL_NAMES
        from .localize import PLANE_CHANNELS
        recs = []
        for t in tests:
            for chn in PLANE_CHANNELS[t.direction]:
                seg, dof = chn.rsplit("_", 1)
                for fi in f:
                    recs.append((t.direction, seg, dof, CHANNEL_NAMES.index(chn), fi,
                                 t.level))
        arr = list(zip(*recs, strict=True))
        n = len(recs)
        fake = Rows(np.array(arr[0]), np.array(arr[1]), np.array(arr[2]), np.array(arr[3]),
                    np.array(arr[4], float), np.array(arr[5], float),
                    band_index(np.array(arr[4], float)), np.ones(n, complex), np.ones(n),
                    np.full(n, 10.0), np.full(n, MODEL_FLOOR**2))
        pred = Predictor(fam, cand, fake, tests, state["base_names"],
                         Statics(fam.family.info, state["slope"]))
        theta = np.concatenate([np.log([res["base_scales"][b] for b in state["base_names"]]),
                                [coordinate(p, res["params"][e][p.name])
                                 for e, p in cand.params]])
        pred.update_statistics(theta)
        preds[name] = (pred.predict(theta), fake)
    Ha, fake = preds["a"]
    Hb, _ = preds["b"]
    score = np.abs(Ha - Hb) ** 2 / ((MODEL_FLOOR * np.maximum(np.abs(Ha), np.abs(Hb))) ** 2
                                    + 1e-300)
    keys = np.array([f"{d}|{lv:g}|{s}|{q}|{b}" for d, lv, s, q, b in
                     zip(fake.direction, fake.level, fake.segment, fake.dof, fake.band,
                         strict=True)])
    uniq, inv = np.unique(keys, return_inverse=True)
    mean = np.bincount(inv, weights=score) / np.bincount(inv)
    k = int(np.argmax(mean))
    d, lv, seg, dof, b = uniq[k].split("|")
    sel = inv == k
    ga, gb = float(np.mean(np.abs(Ha[sel]))), float(np.mean(np.abs(Hb[sel])))
    new = (d, round(float(lv), 6)) not in measured
    best_score = float(mean[k])
    lo, hi = BANDS[int(b)]
    return {
        "direction": d, "level_rms": float(lv), "segment": seg, "dof": dof,
        "f_lo_hz": lo, "f_hi_hz": hi, "new_test": new,
        "difference_in_3pct_units": math.sqrt(best_score),
        "text": (f"{'run a new test' if new else 'repeat with more averages'}: seat "
                 f"{d} at {float(lv):g} m/s^2, {seg} {dof} in {lo:g}-{hi:g} Hz: "
                 f"{best['effect']} predicts |T| ~ {ga:.3g}, {other['effect']} ~ {gb:.3g} "
                 f"({100 * abs(ga - gb) / max(ga, gb, 1e-12):.0f}% apart)"),
    }


def candidate_names(effects=None) -> list[str]:
    """The candidate effects to test (default all), checked by name."""
    names = list(EFFECT_NAMES) if not effects else list(effects)
    for n in names:
        if n not in EFFECTS:
            raise DiagnosisError(f"unknown effect {n!r}; choose from {', '.join(EFFECT_NAMES)}")
    return names


def diagnose(data, params: ModelParams | None = None, effects=None,
             measures: BodyMeasures = REFERENCE, workers: int | None = None,
             progress: bool = True, channels: str = "plane",
             use_cache: bool = True, discrepancy: bool = True) -> Diagnosis:
    """Run the diagnosis on the data in `data` (see module doc)."""
    t_start = time.perf_counter()
    params = params if params is not None else load_params()
    names = candidate_names(effects)
    lab = data if isinstance(data, LabData) else load_lab_data(data, channels)
    rows = lab.rows
    base_names = [f.name for f in resolve_free("default")]
    Progress("diagnose", enabled=progress).say(
        f"{len(rows)} rows, {len(lab.tests)} tests "
        f"({', '.join(f'{t.direction}@{t.level:g}' for t in lab.tests)}); "
        f"{len(names)} candidates")
    t0 = time.perf_counter()
    fam_prog = Progress("diagnose: linearizing the candidate models", None, progress,
                        unit="models")

    def fam_progress(done, total):
        fam_prog.total = total
        fam_prog.update(done, force=done % 10 == 0)

    fams = load_families(params, measures, names, base_names, workers, fam_progress,
                         use_cache)
    slope = separation_slope(params, measures)
    t_fam = time.perf_counter() - t0
    fold_kind, folds = make_folds(rows)
    state = {"families": fams, "rows": rows, "tests": lab.tests, "base_names": base_names,
             "slope": slope, "folds": folds, "params": params, "measures": measures}
    cand_names = ["none"] + names
    # The expensive candidates first (grid effects: recentering).
    order = sorted(cand_names, key=lambda n: (n not in GRID_EFFECTS, n != "none"))
    results = {}
    t1 = time.perf_counter()
    nwork = min(worker_count(workers), len(order))

    fit_prog = Progress("diagnose: candidates", len(order), progress, unit="fitted")

    def on_result(done, total, i, r):
        fit_prog.step(f"({r['name']}, {r['wall_s']:.0f} s)")

    for r in run_jobs([(_evaluate_candidate, n) for n in order], nwork, on_result,
                      _init_worker, (state,)):
        results[r["name"]] = r
    t_fit = time.perf_counter() - t1
    state["recentered"] = {n: r["recentered"] for n, r in results.items() if r["recentered"]}
    report, cells_before, cells_after = _assemble(lab, rows, results, base_names, names,
                                                  state, fold_kind, folds)
    if discrepancy and report["verdict"] == "unexplained":
        from .discrepancy import apply_to_report, structural_pass

        sp = structural_pass(state, results, names, workers, progress)
        apply_to_report(report, sp, rows)
        t_fit = time.perf_counter() - t1
    if apply_softening_rule(report, names):
        # The gap after, and where it lies, with the named effect's own fit.
        res = results["softening"]
        report["gap_after"] = _gap_of(res, cell_keys(rows))
        cells_after = localize(rows, res["chi_all"])
        report["localization"] = mark_after(cells_before, cells_after)
    report["timing_s"] = {"families": t_fam, "fits": t_fit,
                          "total": time.perf_counter() - t_start, "workers": nwork}
    return Diagnosis(report, rows, results, base_names, cells_before, cells_after)


def _assemble(lab, rows, results, base_names, names, state, fold_kind, folds):
    nb = len(base_names)
    base = results["none"]
    cells_before = localize(rows, base["chi_all"])
    significant = [c for c in cells_before if c["significant"]]
    keys = cell_keys(rows)
    ranking = [_ranking_entry(n, results[n], base, nb, len(rows), base_names, keys)
               for n in names]
    ranking.sort(key=lambda r: (r["delta_bic"], -r["gap_reduction_heldout"]))
    evidence = level_evidence(rows)
    resonance = resonance_shift(rows, base["H_all"])
    d = decide(len(significant), ranking, len(rows), len(names), evidence)
    best, verdict = d["best"], d["verdict"]
    experiment = separating_experiment(best, d["close"][0], state) if d["close"] else None
    best_effect = best["effect"] if verdict in ("explained", "ambiguous") else None
    ambiguous_with = [r["effect"] for r in d["close"]]
    explanation = explain(d, len(significant), len(names))
    after_res = results[best["effect"]] if best else base
    cells_after = localize(rows, after_res["chi_all"])
    localization = mark_after(cells_before, cells_after)
    g = {"before": _gap_of(base, keys), "after": _gap_of(after_res, keys)}
    report = {
        "verdict": verdict,
        "best_effect": best_effect if verdict in ("explained", "ambiguous") else None,
        "best_candidate": best["effect"] if best else None,
        "ranking": ranking,
        "localization": localization,
        "gap_before": g["before"],
        "gap_after": g["after"],
        "gap_given_model": gap_value(chi2_rows(rows, _given_prediction(state)), keys),
        "significant_cells": len(significant),
        "joint_test": d["joint"],
        "ambiguous_with": ambiguous_with,
        "separating_experiment": experiment,
        "explanation": explanation,
        "evidence": {"level": evidence, "nonlinear": d["nonlinear_evidence"],
                     "resonance": resonance},
        "base_refit": {n: float(math.exp(b)) for n, b in
                       zip(base_names, results["none"]["theta"][:nb], strict=True)},
        "data": {"source": lab.source, "rows": len(rows),
                 "tests": [{"direction": t.direction, "level_rms": t.level,
                            "spectrum": t.source} for t in lab.tests],
                 "notes": lab.notes},
        "method": {"folds": fold_kind, "heldout_sets": [f for f, _ in folds],
                   "bands_hz": [list(b) for b in BANDS], "model_floor": 0.03,
                   "significance": "chi^2 per cell, p < 0.01 / cells",
                   "explained_reduction": EXPLAINED_REDUCTION,
                   "ambiguity_margin": AMBIGUITY_MARGIN,
                   "candidates": names},
    }
    return report, cells_before, cells_after


def _given_prediction(state) -> np.ndarray:
    fam = state["families"]["base"]
    pred = Predictor(fam, Candidate(()), state["rows"], state["tests"], state["base_names"],
                     Statics(fam.family.info, state["slope"]))
    theta = np.zeros(len(state["base_names"]))
    pred.update_statistics(theta)
    return pred.predict(theta)
