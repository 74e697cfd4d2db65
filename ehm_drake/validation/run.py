"""Running the model in a fact's configuration: the nonlinear time-domain
simulation (settle, then vibrate), reduced to the measures the facts use
(apparent mass, seat-to-head transmissibility), and its equivalent-linear
prediction beside it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .facts import Run

#: Where a resonance is looked for (Hz): above the trunk's sway modes, below
#: the analysis band's end.
RESONANCE_BAND_HZ = (2.0, 12.0)
#: Welch segment (s): 0.1 Hz bins.
SEGMENT_S = 10.0


@dataclass
class RunMeasures:
    """What the facts read from one run (frequencies in Hz)."""

    run: Run
    freq_hz: np.ndarray
    apparent_mass: np.ndarray  # normalized modulus, vertical
    am_coherence: np.ndarray
    head_z: np.ndarray  # seat-to-head vertical transmissibility (m/m)
    head_coherence: np.ndarray
    static_mass_kg: float
    linear_resonance_hz: float = math.nan  # the equivalent-linear model's
    meta: dict = field(default_factory=dict)
    frf: object = field(default=None, repr=False)  # FrfData of the run

    @property
    def resonance_hz(self) -> float:
        """Of the normalized vertical apparent mass (NaN for a sinusoid)."""
        if not np.any(np.isfinite(self.apparent_mass)):
            return math.nan
        return peak_frequency(self.freq_hz, self.apparent_mass, RESONANCE_BAND_HZ)

    def head_z_at(self, f_hz: float) -> float:
        """Seat-to-head vertical transmissibility at `f_hz` (m/m; a sine
        run has its one frequency)."""
        return float(np.interp(f_hz, self.freq_hz, self.head_z))

    def to_dict(self) -> dict:
        return {"run": self.run.key, "configuration": self.run.configuration,
                "excitation": self.run.describe(),
                "resonance_hz": self.resonance_hz,
                "linear_resonance_hz": self.linear_resonance_hz,
                "static_mass_kg": self.static_mass_kg, **self.meta}


def peak_frequency(f, y, band=RESONANCE_BAND_HZ) -> float:
    """The frequency of the maximum of `y` within `band`, refined by a
    parabola through the three bins around it (after a 3-bin moving
    average, which keeps a 0.1 Hz grid's peak within a bin)."""
    f = np.asarray(f, float)
    y = np.convolve(np.asarray(y, float), np.ones(3) / 3, mode="same")
    sel = np.flatnonzero((f >= band[0]) & (f <= band[1]))
    if len(sel) < 3:
        return math.nan
    k = sel[int(np.argmax(y[sel]))]
    if k in (sel[0], sel[-1]):
        return float(f[k])
    y0, y1, y2 = y[k - 1], y[k], y[k + 1]
    den = y0 - 2 * y1 + y2
    shift = 0.5 * (y0 - y2) / den if den < 0 else 0.0
    return float(f[k] + shift * (f[k + 1] - f[k]))


def run_params(params_mapping: dict, configuration: str):
    """The parameters of a configuration for the body `params_mapping` (a
    complete parameter mapping): the configuration file's keys over it."""
    from ..params import configuration_path, params_from_dict, read_params_mapping

    merged = _merge(params_mapping, read_params_mapping(configuration_path(configuration)))
    return params_from_dict(merged)


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def simulate_run(job) -> RunMeasures:
    """One run (a job for `ehm_drake.parallel.run_jobs`): `job` = (Run,
    parameter mapping, duration s, seed, design or None)."""
    from ..analysis.equivalent import SeatSpectrum, equivalent_linear
    from ..analysis.linear import default_frequencies
    from ..analysis.transmissibility import transmissibility
    from ..diagram import build_diagram, on_design
    from ..signals import make_seat_signal
    from ..simulation import settle, vibrate

    run, mapping, duration, seed, design = job
    params = run_params(mapping, run.configuration)
    if design is not None:
        params = on_design(params, design)
    s = params.simulation
    signal = make_seat_signal(run.kind, run.direction, run.level_rms, duration, seed,
                              s.time_step_s, s.settle_time_s, s.onset_time_s,
                              frequency_hz=run.frequency_hz or 4.0, band=run.band_hz)
    settled = settle(params)
    result = vibrate(params, settled, signal).after(signal.steady_start)
    fs = result.sample_rate
    nper = int(round(SEGMENT_S * fs))
    static_mass = float(np.mean(result.pan_force()[:, 2])) / 9.81
    if run.kind == "sine":
        # One frequency: the complex amplitudes of the head's and the seat's
        # vertical displacement at it, over whole periods.
        from ..systems.outputs import CHANNEL_NAMES

        f0 = run.frequency_hz
        t = result.times - result.times[0]
        n = int(round(np.floor(t[-1] * f0) * fs / f0))
        basis = np.exp(-2j * np.pi * f0 * t[:n])
        head_amp = basis @ result.channels[:n, CHANNEL_NAMES.index("head_z")]
        seat_amp = basis @ result.seat_displacement[:n, 2]
        f_h = np.array([f0])
        gain, coh_h = np.array([abs(head_amp / seat_amp)]), np.array([1.0])
        frf = None
    else:
        frf = transmissibility(result.to_timeseries())
        f_h, gain, _, coh_h = frf.get(run.direction, "head", "z")
    if run.kind == "random":
        # The apparent mass on 0.1 Hz bins (10 s Hann segments, 50% overlap).
        from ..analysis.spectral import apparent_mass

        est = apparent_mass(result.pan_force()[:, 2], result.seat_acceleration[:, 2], fs,
                            static_mass, f_max=12.0, nperseg=min(nper, len(result.times)))
        f_am, mod, coh = est.f, est.modulus_normalized, est.coherence
    else:  # a sinusoid excites one frequency: no apparent-mass curve
        f_am = f_h
        mod = coh = np.full(len(f_h), np.nan)
    head = np.interp(f_am, f_h, gain)
    head_coh = np.interp(f_am, f_h, coh_h)
    # The equivalent-linear model at the run's spectrum, for comparison.
    lin_res = math.nan
    if run.kind == "random":
        model = build_diagram(params, guard=False)
        eq = equivalent_linear(model, SeatSpectrum.flat(run.direction, run.level_rms,
                                                        run.band_hz))
        fl = default_frequencies(1200)
        lin_res = peak_frequency(fl, eq.linear.apparent_mass(fl, "z")["z"][1])
    return RunMeasures(run, np.asarray(f_am), np.asarray(mod), np.asarray(coh),
                       np.asarray(head), np.asarray(head_coh), static_mass, lin_res,
                       {"duration_s": duration, "seed": seed, "design": s.design,
                        "time_step_s": s.time_step_s,
                        "seat_rms_measured": float(np.sqrt(np.mean(
                            result.seat_acceleration[:, "xyz".index(run.direction)] ** 2)))},
                       frf)


def run_all(runs, params_mapping: dict, duration: float, seed: int, design=None,
            workers: int | None = None, progress=None) -> dict:
    """{run key: RunMeasures} of `runs`, on a process pool."""
    from ..parallel import run_jobs

    jobs = [(simulate_run, (r, params_mapping, duration, seed + i, design))
            for i, r in enumerate(runs)]
    results = run_jobs(jobs, workers, progress)
    return {m.run.key: m for m in results}


__all__ = ["RESONANCE_BAND_HZ", "RunMeasures", "peak_frequency", "run_all", "run_params",
           "simulate_run"]
