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
from .fit import FitResult


def verify_time_domain(params: ModelParams, frf: FrfData, directions: str,
                       measures: BodyMeasures = REFERENCE, variant: str = "default",
                       duration: float = 60.0, seed: int = 1, timeseries=None,
                       progress: bool = False) -> dict:
    """Simulate the measured excitation with `params` (nonlinear, time
    domain), estimate the transmissibility as a lab would, and compare it
    with the data.  The excitation is the recorded seat acceleration when
    `timeseries` is given, else random 0.1-12 Hz per measured direction at
    the measured level.  Fails on divergence, lost posture or instability."""
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
        for key in est.channels():
            d, seg, dof = key[:3]
            f, g, _, coh = frf.get(d, seg, dof) if len(frf.select(d, seg, dof)) else ([],) * 4
            if len(f) == 0:
                continue
            ef, eg, _, ecoh = est.get(d, seg, dof)
            gi = np.interp(f, ef, eg)
            ok = (coh > 0.5) & (np.interp(f, ef, ecoh) > 0.5) & (g > 0) & (gi > 0)
            if ok.sum() > 3:
                errs[f"{d}/{seg}/{dof}"] = float(np.sqrt(np.mean(np.log(gi[ok] / g[ok]) ** 2)))
        out["directions"][label] = {
            "excitation": sig.description, "rms_log_gain_error": float(np.mean(list(
                errs.values()))) if errs else None, "per_channel": errs,
            "real_time_factor": run.meta["real_time_factor"]}
    return out


def safe_parameters(result: FitResult, frf: FrfData, verify, **kw):
    """The fitted parameters if they pass `verify`, else the largest step
    back towards the start (log-scale fractions 0.5, 0.25) that passes, else
    the start.  Returns (params, fraction, verification)."""
    from .parameters import apply_scales

    x = np.log(result.scales)
    last = None
    for frac in (1.0, 0.5, 0.25, 0.0):
        params = apply_scales(result.start, result.free, np.exp(frac * x))
        last = verify(params, frf, result.directions, **kw)
        if last["passed"]:
            return params, frac, last
    return result.start, 0.0, last
