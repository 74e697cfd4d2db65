"""Fit the model to measured transmissibility (paper Sec. III-A, Fig. 4).

Cost
----
For every measured row (direction, segment, dof, frequency) with coherence
above `min_coherence`:

* the log-gain error ln|T_model| - ln(gain), and, where the coherence is
  above `phase_min_coherence`, the wrapped phase error (rad) times
  `phase_weight`;
* weighted by the row's coherence as the inverse variance of an H1 gain,
  gamma^2 / (1 - gamma^2) (gamma^2 capped at 0.99 so noise-free simulated
  data stays finite), by the channel's weight (default: head and trunk 1,
  pelvis 0.5, knees 0.3, as the paper prioritised head and trunk), and by
  1/(rows of the channel) so that every channel counts once.

The model side is the linear frequency response of the closed loop
(`ehm_drake.analysis.linear`) at the data's vibration levels (the body's
softening, `ehm_drake.identification.evaluation`), linearized by finite
differences about the static equilibrium of the starting parameters (the
equilibrium moves by millimetres as contact stiffnesses change, a
second-order effect on the FRF; the final parameters are re-linearized at
their own equilibrium and softening, and verified in the nonlinear time
domain).  Paths the symmetric model cannot produce are left out; with
simultaneous axes each path is weighted by its share of its output.

The optimizer is scipy's bounded trust-region least squares on log(scale)
of each free parameter, with the finite-difference Jacobian evaluated in
parallel worker processes, run from two starts (`STARTS`: the phases
first, then gain and phase; and gain and phase at once), the lower cost
kept; the report says when the starts disagree (`starts_disagree`).  Each
descent of gain and phase makes a second stage about the first stage's
parameters' own equilibrium and softening, which removes the first
linearization point's bias; that is a small move, made with the last
differenced Jacobian updated by Broyden's rule (a few model evaluations
where a differenced Jacobian costs twenty).  The lower start's end is then
polished by a descent with every model at its own equilibrium and
softening (at most `POLISH_EVALUATIONS`): a parameter that moves the
equilibrium (the hips' stiffness moves the trunk's posture) is all but
invisible to a descent about a held point, which can then stop far from
the data's parameters.

Identifiability
---------------
From the Jacobian J (in log-scale) at the solution (or where the polish
started, when it moved no scale by more than `REDIFFERENCE`; the report's
``jacobian_scales``), each column evaluated
at its parameters' own static equilibrium (as the reported model is):
covariance s^2 (J^T J)^+ with s^2 the residual variance.  (The optimizer's
Jacobian holds the equilibrium fixed; the equilibrium, the PID's integral
state included, moves with the stiffnesses, and along the lumbar-hip
stiffness valley that fixed-equilibrium Jacobian put the hip stiffness'
standard error at 3.3% where its own-equilibrium one is 5.4%, with the fit
19% from the truth.)  A parameter is reported as
determined by the data when its relative standard error is at most
`ident_threshold` (default 3.3%: within 10% at three standard errors), it
is not on a bound, and it correlates with no other free parameter at
|rho| > 0.95; otherwise it is listed, with the reason, under
`not_identifiable`.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from scipy.optimize import least_squares

from ..analysis.formats import FrfData
from ..model.anthropometry import REFERENCE, BodyMeasures
from ..parallel import process_pool
from ..params import ModelParams, ParameterError, save_params
from ..progress import Progress
from ..signals import BAND_HZ
from .evaluation import (
    Evaluator,
    FitError,
    Residuals,
    drop_paths,
    excitation_groups,
    init_worker,
    path_shares,
    penalized,
    residual,
    structural_zeros,
    worker_residual,
    zero_paths_warning,
)
from .parameters import (
    FreeParameter,
    representative,
    resolve_free,
    scale_bounds,
)

#: The fit's starts (`fit(starts=...)`), each a staged descent from the
#: start parameters; the lower cost at its own equilibrium is kept.  "phase
#: first" fits the phase rows alone, then gain and phase from there; "plain"
#: fits gain and phase at once.  On the 20-parameter recovery test (truth
#: 20-40% from the start on every parameter) plain lands in a local minimum
#: when z is held out (4.7x the truth's cost, thigh contact x7.6, held-out
#: error 0.46 against 0.18 at the start), while phase first reaches the
#: truth's cost (held-out error 0.064) and, on all three directions, a cost
#: a little below plain's.  The log gains are far more multimodal than the
#: phases here: gains alone reach the truth's gain error in another basin,
#: with a ridge in the gain cost between it and the truth.
STARTS = ("phase first", "plain")
#: Further starts `fit(starts=...)` accepts: "gain first" (gains alone, then
#: both), which lands in that other basin (3.5x the truth's cost, held out).
OTHER_STARTS = ("gain first",)


# ---------------------------------------------------------------------------
# Channel weights
# ---------------------------------------------------------------------------


def load_weights(path: str | Path | None) -> dict[str, float]:
    """Channel weights: keys `segment`, `segment_dof` or `direction/segment/dof`
    (the most specific wins), values >= 0."""
    if path is None:
        return {}
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"--weights file not found: {path}")
    text = path.read_text()
    data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    if not isinstance(data, dict):
        raise ParameterError(f"{path}: expected a mapping channel -> weight")
    out = {}
    for k, v in data.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise ParameterError(
                f"{path}: weight of {k!r} must be a non-negative number, got {v!r}")
        parts = str(k).replace("/", " ").replace("_", " ").split()
        if not parts:
            raise ParameterError(f"{path}: empty key")
        out[str(k)] = float(v)
    return out


@dataclass
class FitResult:
    params: ModelParams
    start: ModelParams
    free: list[FreeParameter]
    scales: np.ndarray
    report: dict
    T_start: np.ndarray
    T_fit: np.ndarray
    freqs: np.ndarray
    directions: str
    interrupted: bool = False


def split_holdout(frf: FrfData, holdout: str | None) -> tuple[FrfData, FrfData | None]:
    """`direction=z`, `segment=knee_l`, `level=0.3` (several joined by ';')."""
    if not holdout:
        return frf, None
    mask = np.zeros(len(frf), bool)
    for item in holdout.split(";"):
        if "=" not in item:
            raise FitError(f"--holdout {holdout!r}: expected KEY=VALUE with KEY direction, "
                           "segment, dof or level")
        key, value = (s.strip() for s in item.split("=", 1))
        if key == "direction":
            m = frf.direction == value
        elif key == "segment":
            m = frf.segment == value
        elif key == "dof":
            m = frf.dof == value
        elif key == "level":
            try:
                v = float(value)
            except ValueError:
                raise FitError(f"--holdout level={value!r}: not a number") from None
            m = np.isclose(frf.level_rms, v, rtol=1e-6)
        else:
            raise FitError(f"--holdout: unknown key {key!r} (direction, segment, dof, level)")
        if not m.any():
            raise FitError(f"--holdout {item!r} matches no data row")
        mask |= m
    if mask.all():
        raise FitError(f"--holdout {holdout!r} leaves no data to fit")
    return frf._take(np.flatnonzero(~mask)), frf._take(np.flatnonzero(mask))


def check_fit_data(frf: FrfData) -> list[str]:
    """Errors for data that cannot be fitted, warnings for what looks odd."""
    from ..analysis.formats import check_units

    warnings = []
    segs = set(frf.segment)
    if not ({"head", "trunk"} & segs):
        warnings.append("no head or trunk channel in the data: the fit has little to go on "
                        "(the paper fitted head and trunk first)")
    unit_warnings = check_units(frf)
    for w in unit_warnings:
        if "1000" in w or "mm" in w or "rad" in w:
            raise FitError(f"suspect units: {w}")
    return warnings + unit_warnings


class _Tracker:
    def __init__(self, progress: bool, cost0: float | None = None):
        self.best_cost = math.inf
        self.best_x = None
        self.n = 0
        self.progress = Progress("fit", None, progress, unit="evaluations")
        self.cost0 = cost0

    def record(self, x, r) -> None:
        self.n += 1
        cost = 0.5 * float(r @ r)
        if cost < self.best_cost:
            self.best_cost, self.best_x = cost, np.array(x)
        start = f" (start {self.cost0:.4g})" if self.cost0 is not None else ""
        # In a log, every 10th evaluation (a fit makes hundreds).
        self.progress.update(self.n, f"cost {cost:.4g}, best {self.best_cost:.4g}{start}",
                             force=self.n % 10 == 0)


def fit(frf: FrfData, start: ModelParams | None = None, free: str | list | None = None,
        weights: dict | None = None, holdout: str | None = None,
        measures: BodyMeasures = REFERENCE, variant: str = "default", workers: int = 2,
        progress: bool = True, max_evaluations: int = 400, ident_threshold: float = 0.033,
        phase_weight: float = 0.5, stages: int | str = "auto",
        starts: tuple[str, ...] = STARTS, excitation: str = "separate",
        band_hz: tuple[float, float] = tuple(BAND_HZ)) -> FitResult:
    """Identify the free parameters from measured transmissibility `frf`.

    `starts`: the descents to make (a name or names of `STARTS` and
    `OTHER_STARTS`; each costs about one fit);
    the lower cost is kept and the report lists each one's.
    `excitation`: how the data were recorded, ``separate`` (one seat axis
    per test) or ``simultaneous`` (the directions at a level excited
    together, multiple-input estimates); `band_hz`: the excitation's band.
    With the level of each row, they set the model's softening at the
    data's level (`ehm_drake.identification.evaluation`)."""
    from ..params import load_params

    start = start or load_params()
    starts = (starts,) if isinstance(starts, str) else tuple(starts)
    unknown = [s_ for s_ in starts if s_ not in STARTS + OTHER_STARTS]
    if not starts or unknown:
        raise FitError(f"starts {list(starts)}: choose one or more of "
                       f"{list(STARTS + OTHER_STARTS)}")
    free_params = resolve_free(free) if not isinstance(free, list) else free
    warnings = check_fit_data(frf)
    groups = excitation_groups(frf, excitation)
    shares = path_shares(frf) if excitation == "simultaneous" else None
    train, held = split_holdout(frf, holdout)

    def build(part):
        if part is None or not len(part):
            return None
        return Residuals.build(part, weights or {}, phase_weight, groups=groups, shares=shares)

    res, held_res = build(train), build(held)
    freqs = np.unique(np.concatenate([res.freqs] + ([held_res.freqs] if held_res else [])))
    directions = "".join(d for d in "xyz" if d in set(frf.direction))
    # Residual layouts indexed into the common frequency grid and directions.
    res = res.reindexed(freqs, directions)
    held_res = held_res.reindexed(freqs, directions) if held_res else None
    bounds = np.array([scale_bounds(start, fp) for fp in free_params])
    lo, hi = np.log(bounds[:, 0]), np.log(bounds[:, 1])
    ev = Evaluator(start.to_dict(), (measures.mass_kg, measures.stature_m,
                                     measures.resolved_sitting_height()),
                   variant, [fp.name for fp in free_params], freqs, directions, groups,
                   tuple(band_hz)).setup()
    if any(math.isnan(g[1]) for g in groups) and any(s_ is not None for s_ in ev.rms):
        warnings.append("rows without a level (level_rms) are compared with the model at "
                        "rest: its softening with the vibration's magnitude left out there")
    x0 = np.zeros(len(free_params))
    T0, stable0 = ev.transmissibility(x0)
    # Paths the model cannot produce (zero by its left-right symmetry, which
    # every free parameter keeps) carry only estimation noise, whatever their
    # coherence (with simultaneous axes it is the output's multiple
    # coherence): left out, or their log error (ln of a rounding-level model
    # gain) would swamp the cost and its Jacobian.
    zero = structural_zeros(T0, directions)
    if zero:
        if len(drop_paths(train, zero)) == 0:
            raise FitError("every path of the data is zero in the model (by its left-right "
                           "symmetry): nothing to fit")
        train, held = drop_paths(train, zero), drop_paths(held, zero)
        res = build(train).reindexed(freqs, directions)
        held_res = build(held)
        held_res = held_res.reindexed(freqs, directions) if held_res else None
        warnings.append(zero_paths_warning(zero, frf))
    r0 = res(T0)
    tracker = _Tracker(progress, 0.5 * float(r0 @ r0))
    tracker.record(x0, r0)
    pool = process_pool(workers, init_worker, (ev, res)) if workers > 1 else None
    cache: dict = {}

    def fun(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = residual(ev, res, x)
            tracker.record(x, cache[key])
        return cache[key]

    # A 3% parameter step: its effect on the FRF stands well above the ~1e-4
    # numerical noise of the finite-difference linearization (with 0.1% steps
    # the weakest columns were noise and their standard errors too small).
    step = 0.03

    # The last differenced Jacobian, under its parameters and linearization
    # point (a descent that starts where the last ended, about the same
    # point, starts from it; a later stage updates it, see `descend`).
    latest: dict = {"key": None, "J": None}

    def jac(x, f0=None, own_equilibrium: bool = False):
        """Finite-difference Jacobian about the current linearization state
        `ev.x_ref`, or each column at its parameters' own equilibrium."""
        key = None if own_equilibrium else (x.tobytes(), ev.x_ref.tobytes(),
                                            *(None if s_ is None else s_.tobytes()
                                              for s_ in (ev.rms or ())))
        if key is not None and key == latest["key"]:
            return latest["J"]
        f0 = fun(x) if f0 is None else f0
        xs = [x + step * np.eye(len(x))[j] * (1 if x[j] + step <= hi[j] else -1)
              for j in range(len(x))]
        x_ref = None if own_equilibrium else ev.x_ref
        if pool is not None:
            cols = list(pool.map(worker_residual, [(xj, x_ref, ev.rms) for xj in xs]))
        else:
            cols = [residual(ev, res, xj, at_equilibrium=own_equilibrium) for xj in xs]
        tracker.n += len(xs)
        J = np.column_stack([(c - f0) / (xj - x).sum() for c, xj in zip(cols, xs,
                                                                        strict=True)])
        latest.update(key=key, J=J)
        return J

    x_ref0, rms0 = ev.x_ref, ev.rms
    n_stages = 2 if stages == "auto" else int(stages)
    nfev = max(10, max_evaluations // (len(x0) + 1))
    options = dict(bounds=(lo, hi), method="trf", x_scale=1.0, ftol=1e-3, xtol=1e-3,
                   gtol=1e-8, max_nfev=nfev)

    # The gain rows of the residual (the phase rows follow them).
    gain_rows = np.arange(res.size) < res.size // 2

    def descend(x_start, phase: bool = True, gain: bool = True, n: int = n_stages):
        """The staged fit from `x_start`: stage 1 linearizes about the
        starting parameters' equilibrium and softening; stage 2 about the
        stage-1 parameters' own (contact stiffness moves the equilibrium by
        millimetres), removing that bias.  Without `phase` (`gain`), the
        gain (phase) rows alone are fitted.  `n`: the most stages."""
        mask = np.where(gain_rows, float(gain), float(phase))

        def f(x):
            return fun(x) * mask

        def jf(x):
            return jac(x) * mask[:, None]

        # A later stage only removes the bias of the earlier one's
        # linearization point, a small move: it starts from the last
        # differenced Jacobian and updates it by Broyden's rule from the
        # residuals the descent evaluates (the final Jacobian, for the
        # standard errors, is differenced in full).
        secant = None

        def jf_secant(x):
            return secant(x, fun(x)) * mask[:, None]

        x_best = x_start
        for stage in range(n):
            if stage > 0:
                x_eq = ev.equilibrium(x_best)
                rms = ev.element_rms(x_best, x_eq, warm=ev.rms)
                if stages == "auto" and np.max(np.abs(x_eq - ev.x_ref)) < 2e-4 \
                        and _rms_change(rms, ev.rms) < 0.02:
                    break  # equilibrium and softening barely moved: no bias to remove
                ev.x_ref, ev.rms = x_eq, rms
            cache.clear()
            tracker.best_cost = 0.5 * float(fun(x_best) @ fun(x_best))
            tracker.best_x = x_best
            n_before, t0 = tracker.n, time.perf_counter()
            secant = Secant(latest["J"]) if stage > 0 and latest["J"] is not None else None
            sol = least_squares(f, x_best, jac=jf if secant is None else jf_secant, **options)
            descents.append({"rows": "phase" if not gain else "gain" if not phase else "all",
                             "stage": stage + 1, "evaluations": tracker.n - n_before,
                             "iterations": int(sol.njev or 0),
                             "jacobian": "differences" if secant is None else "secant",
                             "seconds": time.perf_counter() - t0,
                             "cost": 0.5 * float(sol.fun @ sol.fun)})
            x_best = sol.x if not (phase and gain) \
                or 0.5 * float(sol.fun @ sol.fun) <= tracker.best_cost \
                else tracker.best_x
        return x_best

    def at_own_equilibrium(x):
        """(cost, T, stable, element RMS) of the model at its own static
        equilibrium and its own softening at the data's levels."""
        T, stable, ev.rms = ev.own(x, warm=ev.rms)
        r = res(T)
        return 0.5 * float(r @ r), T, stable, ev.rms

    def polish(x, r, J):
        """The descent from `x` (residual `r`, Jacobian `J` there, both at
        its own equilibrium) with every evaluation at its own equilibrium and
        softening: the stages' linearization point is held while they
        descend, and where a parameter moves the equilibrium (the hips'
        stiffness the trunk's posture) that bias can hold a descent far from
        the data's parameters, where the model at its own equilibrium fits
        better.  Broyden's rule updates `J`.  Returns (x, (cost, T, stable,
        element RMS)) of the lower cost."""
        seen: dict = {}
        secant = Secant(J, x, r)

        def f_own(xx):
            key = xx.tobytes()
            if key not in seen:
                T, stable, rms = ev.own(xx, warm=ev.rms)
                rr = penalized(res, T, stable)
                seen[key] = (rr, (0.5 * float(rr @ rr), T, stable, rms))
                tracker.record(xx, rr)
            return seen[key][0]

        def jac_own(xx):
            return secant(xx, f_own(xx))

        seen[x.tobytes()] = (r, None)
        n_before, t0 = tracker.n, time.perf_counter()
        sol = least_squares(f_own, x, jac=jac_own, **{**options, "max_nfev": POLISH_EVALUATIONS})
        cost = 0.5 * float(sol.fun @ sol.fun)
        descents.append({"rows": "all", "stage": "own equilibrium",
                         "evaluations": tracker.n - n_before, "iterations": int(sol.njev or 0),
                         "jacobian": "secant", "seconds": time.perf_counter() - t0,
                         "cost": cost})
        if cost < 0.5 * float(r @ r) and seen[sol.x.tobytes()][1] is not None:
            return sol.x, seen[sol.x.tobytes()][1]
        return x, None

    descents: list = []  # per optimizer run: rows fitted, stage, evaluations, cost

    def from_start(name):
        ev.x_ref, ev.rms = x_ref0, rms0
        descents.append({"start": name})
        if name == "plain":
            return descend(x0)
        if name == "phase first":
            # (Without phase rows, e.g. phase_weight 0, it is plain.)  The
            # phase descent only finds the basin the full descent starts
            # from: its linearization point's bias is the full descent's to
            # remove, so it makes one stage.
            return descend(descend(x0, gain=False, n=1) if np.any(res.w_phase > 0) else x0)
        return descend(descend(x0, phase=False))

    t_start = time.perf_counter()
    interrupted = False
    x_best, J, x_J = x0, None, None
    ends = []  # (log scales, start, (cost, T, stable) at its own equilibrium)
    try:
        try:
            for name in starts:
                x_end = from_start(name)
                ends.append((x_end, name, at_own_equilibrium(x_end)))
        except KeyboardInterrupt:
            interrupted = True
        # The final model at its own equilibrium, and the Jacobian there (for
        # the standard errors; see the module docstring).
        if ends:
            x_best, _, (_, T_fit, stable, ev.rms) = min(ends, key=lambda e: e[2][0])
        else:
            x_best = tracker.best_x
            T_fit, stable = ev.transmissibility(x_best, at_equilibrium=True)
        r_fit = res(T_fit)
        if not interrupted:
            try:
                J = jac(x_best, r_fit, own_equilibrium=True)
                x_J = x_best
                if ends:
                    descents.append({"polish": "the lowest start"})
                    x_own, better = polish(x_best, r_fit, J)
                    if better is not None:
                        moved = np.max(np.abs(x_own - x_best))
                        x_best, (_, T_fit, stable, ev.rms) = x_own, better
                        r_fit = res(T_fit)
                        # (Standard errors: the Jacobian again where a
                        # parameter moved by more than `REDIFFERENCE`.)
                        if moved > REDIFFERENCE:
                            J = jac(x_best, r_fit, own_equilibrium=True)
                            x_J = x_best
            except KeyboardInterrupt:
                interrupted = True
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    t_fit = time.perf_counter() - t_start
    tracker.progress.close()
    if J is None:
        J = np.full((res.size, len(x0)), np.nan)
    report = _report(free_params, start, ev, x_best, bounds, J, r_fit, r0, res, T0, T_fit,
                     held_res, stable, stable0, ident_threshold)
    report.update({"warnings": warnings, "holdout": holdout, "interrupted": interrupted,
                   "fit_wall_s": t_fit, "n_model_evaluations": tracker.n,
                   "free": [fp.name for fp in free_params], "variant": variant,
                   "data_rows_used": len(res.row_f),
                   # "direction/segment/dof" of the paths left out as zero by
                   # the model's symmetry (the time-domain check leaves them out too).
                   "zero_paths": sorted(f"{d}/{c.rsplit('_', 1)[0]}/{c.rsplit('_', 1)[1]}"
                                        for d, c in zero),
                   "starts": [{"start": name, "cost": own[0], "scales": np.exp(x).tolist()}
                              for x, name, own in ends],
                   "descents": descents,
                   # The scales the standard errors' Jacobian was differenced at.
                   "jacobian_scales": None if x_J is None else np.exp(x_J).tolist()})
    disagreement = starts_disagree(report)
    if disagreement:
        report["warnings"].append(disagreement)
    report["excitation"] = {"kind": excitation, "band_hz": list(band_hz),
                            "groups": [{"directions": d, "level_rms": None if math.isnan(lv)
                                        else lv} for d, lv in groups]}
    return FitResult(ev.params(x_best), start, free_params, np.exp(x_best), report,
                     ev.per_direction(T0), ev.per_direction(T_fit), freqs, directions,
                     interrupted)


#: The most model evaluations of the final descent at the models' own
#: equilibrium (`fit`'s polish; each costs a static equilibrium and the
#: softening's iteration beside the linearization).
POLISH_EVALUATIONS = 15


#: The polish's largest move (in the log of a scale) under which the
#: standard errors keep the Jacobian differenced where it started: a
#: parameter's log-scale sensitivity changes by about as much as the
#: parameter, so the standard errors by a few percent of themselves (the
#: Jacobian costs twenty model evaluations at their own equilibria).
REDIFFERENCE = 0.05


#: Starts agree when their costs are within this fraction of the lower and
#: every parameter the data determine within this fraction of each other.
STARTS_AGREE = 0.05


def broyden(J: np.ndarray, dx: np.ndarray, df: np.ndarray) -> np.ndarray:
    """Broyden's rank-one update of the Jacobian `J` after a step `dx`
    that changed the residual by `df`: the least change of `J` that
    predicts `df` exactly."""
    return J + np.outer(df - J @ dx, dx) / float(dx @ dx)


class Secant:
    """A Jacobian kept up to date by `broyden` along the points a descent
    evaluates: called with a point and its residual, it returns the
    Jacobian there (updated from the last point, if any and different)."""

    def __init__(self, J: np.ndarray, x: np.ndarray | None = None,
                 f: np.ndarray | None = None):
        self.J, self.x, self.f = J, x, f

    def __call__(self, x: np.ndarray, f: np.ndarray) -> np.ndarray:
        if self.x is not None and not np.array_equal(x, self.x):
            self.J = broyden(self.J, x - self.x, f - self.f)
        if self.x is None or not np.array_equal(x, self.x):
            self.x, self.f = x, f
        return self.J


def starts_disagree(report: dict) -> str:
    """A warning when the starts ended in different places (local minima,
    or a valley the data do not pin down), else ''."""
    ends = report.get("starts", [])
    if len(ends) < 2:
        return ""
    costs = np.array([e["cost"] for e in ends])
    scales = np.array([e["scales"] for e in ends])
    determined = np.array([p["identifiable"] for p in report["parameters"]])
    spread = scales.max(axis=0) / scales.min(axis=0) - 1.0
    apart = [(p["name"], s) for p, s, d in zip(report["parameters"], spread, determined,
                                              strict=True) if d and s > STARTS_AGREE]
    cost_gap = costs.max() / costs.min() - 1.0
    if cost_gap <= STARTS_AGREE and not apart:
        return ""
    names = ", ".join(f"{n} {100 * s:.0f}%" for n, s in sorted(apart, key=lambda a: -a[1]))
    return (f"the starts disagree: costs {', '.join(f'{c:.4g}' for c in costs)} "
            f"({100 * cost_gap:.0f}% apart)" + (f"; determined parameters apart: {names}"
                                                  if names else "")
            + " (the lower cost is kept; a local minimum or a valley the data do not pin "
              "down: more data or fewer free parameters)")


def _rms_change(a: list, b: list) -> float:
    """Largest relative change of the groups' element RMS movements."""
    out = 0.0
    for x, y in zip(a, b, strict=True):
        if x is not None and y is not None:
            out = max(out, float(np.max(np.abs(x - y) / np.maximum(np.abs(y), 1e-9))))
    return out


def _report(free, start, ev, x, bounds, J, r_fit, r0, res, T0, T_fit, held_res, stable,
            stable0, threshold) -> dict:
    m, n = J.shape
    cost_before = 0.5 * float(r0 @ r0)
    cost_after = 0.5 * float(r_fit @ r_fit)
    dof = max(m - n, 1)
    s2 = 2 * cost_after / dof
    # Covariance of log-scales: s^2 (J^T J)^+ (pseudo-inverse: singular
    # directions are the undetermined combinations).
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    tol = sv.max() * 1e-9 if sv.size and np.isfinite(sv).all() else 0.0
    inv = np.where(sv > tol, 1.0 / np.maximum(sv, 1e-300) ** 2, np.inf)
    cov = (Vt.T * inv) @ Vt if np.all(np.isfinite(inv)) else (Vt.T * np.where(
        np.isfinite(inv), inv, 1e12)) @ Vt
    cov = s2 * cov
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = cov / np.outer(np.maximum(se, 1e-300), np.maximum(se, 1e-300))
    fitted = ev.params(x)
    params_out = []
    undetermined = []
    for i, fp in enumerate(free):
        at_bound = bool(x[i] <= np.log(bounds[i, 0]) + 1e-6 or x[i] >= np.log(bounds[i, 1]) - 1e-6)
        partners = [free[j].name for j in range(n) if j != i and abs(corr[i, j]) > 0.95]
        rel = float(min(se[i], 1e6))
        ok = rel <= threshold and not at_bound and not partners
        value = representative(fitted, fp)
        params_out.append({
            "name": fp.name, "unit": fp.unit, "start": representative(start, fp),
            "fitted": value, "scale": float(np.exp(x[i])),
            "std_error": rel * value, "rel_std_error": rel, "at_bound": at_bound,
            "correlated_with": partners, "identifiable": bool(ok)})
        if not ok:
            why = []
            if rel > threshold:
                why.append(f"relative standard error {rel:.2g} > {threshold}")
            if at_bound:
                why.append("at a physiological bound")
            if partners:
                why.append("correlated (|rho| > 0.95) with " + ", ".join(partners))
            undetermined.append({"name": fp.name, "reason": "; ".join(why)})
    out = {
        "cost_before": cost_before,
        "cost_after": cost_after,
        "gain_error_before": res.gain_error(T0),
        "gain_error_after": res.gain_error(T_fit),
        "error_per_channel": {k: {"before": v, "after": res.channel_errors(T_fit)[k]}
                              for k, v in res.channel_errors(T0).items()},
        "parameters": params_out,
        "correlation": {"names": [fp.name for fp in free],
                        "matrix": np.round(np.nan_to_num(corr), 4).tolist()},
        "not_identifiable": undetermined,
        "stable_before": bool(stable0),
        "stable_after": bool(stable),
    }
    if held_res is not None:
        out["heldout_error"] = held_res.gain_error(T_fit)
        out["heldout_error_before"] = held_res.gain_error(T0)
        out["heldout_cost"] = 0.5 * float(np.sum(held_res(T_fit) ** 2))
        out["train_error"] = out["gain_error_after"]
    return out


# ---------------------------------------------------------------------------
# Outputs
# ---------------------------------------------------------------------------


def write_outputs(result: FitResult, frf: FrfData, out: Path) -> list[str]:
    from ..analysis.figures import plot_cases
    from ..analysis.linear import frf_from_array

    files = []
    save_params(result.params, out / "params.yaml")
    files.append("params.yaml")
    (out / "fit_report.json").write_text(json.dumps(result.report, indent=1))
    files.append("fit_report.json")
    models = {"start": frf_from_array(result.T_start, result.freqs, result.directions),
              "fitted": frf_from_array(result.T_fit, result.freqs, result.directions)}
    files += [p.name for p in plot_cases(models, out, measured=frf, prefix="fit")]
    return files
