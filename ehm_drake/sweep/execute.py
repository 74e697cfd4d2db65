"""One run, as a worker executes it: plain inputs in (RunSpec.inputs), a plain
record out.  Workers build their own models (Drake diagrams are not picklable),
so nothing here holds state between runs."""

from __future__ import annotations

import os
import socket
import tempfile
import time
import traceback
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .schema import ANALYSIS_DEFAULTS

STATUS_DONE, STATUS_FAILED, STATUS_PENDING = "done", "failed", "pending"
#: Transmissibility channels summarized per excited axis d: the translation along d
#: and the rotation the excitation drives (pitch for x and z, roll for y).
PEAK_SEGMENTS = ("pelvis", "trunk", "head")


def _second_difference(y: np.ndarray, fs: float) -> np.ndarray:
    """Acceleration from displacement samples (central second difference, ends held)."""
    a = np.zeros_like(y)
    a[1:-1] = (y[2:] - 2.0 * y[1:-1] + y[:-2]) * fs**2
    a[0], a[-1] = a[1], a[-2]
    return a


def _comfort_summary(m: dict[str, Any]) -> dict[str, Any]:
    return {k: m[k] for k in ("weighted_rms", "overall", "vdv", "overall_vdv", "msdv_z")}


def summarize_result(settled, result, signal, analysis: Mapping[str, Any] | None = None,
                     ) -> tuple[dict[str, Any], Any]:
    """The compact result of one run and its transmissibility table.

    Returns ``(summary, frf)``: summary holds ``transmissibility`` (per excited axis d
    and segment pelvis/trunk/head, the peak gain and frequency of the translation along d
    and of the pitch (x, z) or roll (y) within ``analysis['peak_band_hz']``; gains in m/m
    and deg/m), ``comfort`` (ISO 2631-1 comfort metrics of the seat acceleration and of
    the head acceleration, the second difference of the absolute head displacement;
    over the full-amplitude part, after the onset), ``posture`` (the settled posture
    summary) and ``vibrate_wall_s``.
    """
    from ..analysis.comfort import comfort_metrics
    from ..analysis.transmissibility import transmissibility

    analysis = dict(ANALYSIS_DEFAULTS, **(analysis or {}))
    vib = result.after(signal.settle_time)
    frf = transmissibility(vib.to_timeseries())
    lo, hi = analysis["peak_band_hz"]
    direction = signal.meta.get("direction", "")
    peaks: dict[str, Any] = {}
    for d in (a for a in "xyz" if a in direction):
        for seg in PEAK_SEGMENTS:
            for dof in (d, "roll" if d == "y" else "pitch"):
                f, gain, _, coh = frf.get(d, seg, dof)
                sel = np.flatnonzero((f >= lo) & (f <= hi))
                if not sel.size:
                    continue
                k = sel[int(np.argmax(gain[sel]))]
                peaks[f"{d}/{seg}/{dof}"] = {"peak_gain": float(gain[k]),
                                             "peak_freq_hz": float(f[k]),
                                             "coherence": float(coh[k])}
    fs = vib.sample_rate
    steady = vib.times >= signal.steady_start - 1e-9
    head = np.column_stack([vib.channel("head", a) for a in "xyz"])
    head_acc = _second_difference(head, fs)
    comfort = {
        "seat": _comfort_summary(comfort_metrics(vib.seat_acceleration[steady], fs, "seat")),
        "head": _comfort_summary(comfort_metrics(head_acc[steady], fs, "head")),
        "from_t_s": float(signal.steady_start),
        "note": "seat: Wd x, y, Wk z; head: second difference of the absolute head "
                "displacement, seat weightings, k = 1",
    }
    summary = {
        "transmissibility": peaks,
        "transmissibility_units": "m/m (x, y, z), deg/m (roll, pitch)",
        "comfort": comfort,
        "posture": settled.summary,
        "vibrate_wall_s": float(result.meta.get("wall_s", float("nan"))),
        "real_time_factor": float(result.meta.get("real_time_factor", float("nan"))),
    }
    return summary, frf


def execute_run(inputs: Mapping[str, Any]) -> dict[str, Any]:
    """Run one sweep run from its plain inputs (see RunSpec.inputs) and return its
    record: ``status`` "done" with ``results`` (and ``frf_csv`` text), or "failed" with
    ``error`` {type, message, source: "run"}.  Never raises for a model error."""
    t0 = time.perf_counter()
    record: dict[str, Any] = {"host": socket.gethostname(), "pid": os.getpid()}
    try:
        from ..diagram import on_design
        from ..model.anthropometry import BodyMeasures
        from ..params import params_from_dict
        from ..signals import make_seat_signal
        from ..simulation import simulate

        params = params_from_dict(dict(inputs["params"]))
        measures = BodyMeasures(**inputs["body"])
        measures.validate()
        s = inputs["settings"]
        # The run's design (expand_runs resolved "auto"); the implicit one at
        # the step chosen by accuracy for this body, variant and parameters.
        params = on_design(params, s.get("design"), None, measures, s["variant"])
        sim = params.simulation
        signal = make_seat_signal(s["excitation"], s["direction"], s["rms"], s["duration"],
                                  int(s["seed"]), sim.time_step_s, sim.settle_time_s,
                                  sim.onset_time_s, frequency_hz=s["frequency_hz"])
        settled, result = simulate(params, measures, s["variant"], signal=signal)
        summary, frf = summarize_result(settled, result, signal, inputs.get("analysis"))
        if inputs.get("analysis", {}).get("frf", True):
            with tempfile.TemporaryDirectory() as tmp:
                record["frf_csv"] = frf.to_csv(Path(tmp) / "frf.csv").read_text()
        wall = time.perf_counter() - t0
        summary["wall_s"] = wall
        summary["settle_wall_s"] = wall - summary["vibrate_wall_s"]
        summary["design"] = sim.design
        summary["time_step_s"] = sim.time_step_s
        record.update(status=STATUS_DONE, results=summary)
    except Exception as e:  # noqa: BLE001 - every model error is recorded, not raised
        record.update(status=STATUS_FAILED, error={
            "type": type(e).__name__, "message": str(e), "source": "run",
            "traceback": traceback.format_exc(limit=-4)})
        record["results"] = {"wall_s": time.perf_counter() - t0}
    return record
