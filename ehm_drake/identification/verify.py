"""Time-domain verification of fitted parameters (see
`ehm_drake.identification.fit`): the fit uses the linearized model, so the
fitted parameters are simulated in the nonlinear time domain with the
measured excitation and compared with the data before they are kept.
"""

from __future__ import annotations

import numpy as np

from ..analysis.formats import FrfData
from ..model.anthropometry import REFERENCE, BodyMeasures
from ..params import ModelParams
from .evaluation import _level_key, path_shares
from .fit import FitResult


def verify_time_domain(params: ModelParams, frf: FrfData, directions: str,
                       measures: BodyMeasures = REFERENCE, variant: str = "default",
                       duration: float = 60.0, seed: int = 1, timeseries=None,
                       progress: bool = False, leave_out=()) -> dict:
    """Simulate the measured excitation with `params` (nonlinear, time
    domain), estimate the transmissibility as a lab would, and compare it
    with the data.  The excitation is the recorded seat acceleration when
    `timeseries` is given, else random 0.1-12 Hz per measured direction at
    the measured level.  Fails on divergence, lost posture or instability.
    `leave_out`: "direction/segment/dof" paths kept out of the error (the
    fit's `zero_paths`: with simultaneous axes their data and simulation are
    both estimation noise, which would dominate it).  Per direction: the RMS
    log-gain error per channel, and over all rows weighted by each path's
    share of its output (as the fit weighs them)."""
    from ..analysis.transmissibility import transmissibility
    from ..signals import make_seat_signal, signal_from_samples
    from ..simulation import EquilibriumError, SimulationDiverged, settle, vibrate

    out: dict = {"passed": True, "directions": {}}
    try:
        settled = settle(params, measures, variant)
    except (SimulationDiverged, EquilibriumError) as e:
        return {"passed": False, "reason": f"settling failed: {e}"}
    posture = settled.summary
    out["posture"] = {"max_joint_error_deg": posture["max_joint_error_deg"],
                      "back_in_contact": posture["back_in_contact"]}
    if posture["max_joint_error_deg"] > 0.5 or not posture["back_in_contact"]:
        out["passed"] = False
        out["reason"] = "posture lost after settling"
    s = params.simulation
    if timeseries is not None:
        runs = {timeseries.meta.get("direction") or "recorded": signal_from_samples(
            timeseries.t, timeseries.seat_acc, s.time_step_s, s.settle_time_s, 0.5)}
    else:
        runs = {}
        for d in directions:
            levels = frf.select(direction=d).level_rms
            level = float(np.nanmedian(levels)) if np.isfinite(levels).any() else 0.1941
            runs[d] = make_seat_signal("random", d, level, duration, seed, s.time_step_s,
                                       s.settle_time_s, s.onset_time_s)
    shares = path_shares(frf)
    left_out = set(leave_out)
    for label, sig in runs.items():
        try:
            run = vibrate(params, settled, sig, measures, variant, progress=progress)
        except SimulationDiverged as e:
            out["passed"] = False
            out["reason"] = str(e)
            out["directions"][label] = {"diverged": str(e)}
            continue
        est = transmissibility(run.after(sig.steady_start).to_timeseries())
        errs = {}
        sum_we2 = sum_w = 0.0
        for key in est.channels():
            d, seg, dof = key[:3]
            if f"{d}/{seg}/{dof}" in left_out:
                continue
            rows = frf.select(d, seg, dof)
            if len(rows) == 0:
                continue
            f, g, _, coh = rows.get(d, seg, dof)
            ef, eg, _, ecoh = est.get(d, seg, dof)
            gi = np.interp(f, ef, eg)
            ok = (coh > 0.5) & (np.interp(f, ef, ecoh) > 0.5) & (g > 0) & (gi > 0)
            if ok.sum() > 3:
                e2 = np.log(gi[ok] / g[ok]) ** 2
                errs[f"{d}/{seg}/{dof}"] = float(np.sqrt(np.mean(e2)))
                lv = _level_key(float(rows.level_rms[0]))
                w = np.array([shares.get((d, seg, dof, round(float(fi), 9), lv), 1.0)
                              for fi in f[ok]])
                sum_we2 += float(w @ e2)
                sum_w += float(w.sum())
        # The summary weighs each row by its path's share of the output (1 for
        # one axis at a time): a small cross-axis path beside a large one is
        # mostly estimation noise there, as the fit weighs it (`path_shares`).
        out["directions"][label] = {
            "excitation": sig.description,
            "rms_log_gain_error": float(np.sqrt(sum_we2 / sum_w)) if sum_w > 0 else None,
            "per_channel": errs,
            "paths_left_out": len(left_out & {"/".join(k[:3]) for k in est.channels()}),
            "real_time_factor": run.meta["real_time_factor"]}
    return out


def safe_parameters(result: FitResult, frf: FrfData, verify, **kw):
    """The fitted parameters if they pass `verify`, else the largest step
    back towards the start (log-scale fractions 0.5, 0.25) that passes, else
    the start.  Returns (params, fraction, verification)."""
    from .parameters import apply_scales

    x = np.log(result.scales)
    kw.setdefault("leave_out", result.report.get("zero_paths", ()))
    last = None
    for frac in (1.0, 0.5, 0.25, 0.0):
        params = apply_scales(result.start, result.free, np.exp(frac * x))
        last = verify(params, frf, result.directions, **kw)
        if last["passed"]:
            return params, frac, last
    return result.start, 0.0, last
