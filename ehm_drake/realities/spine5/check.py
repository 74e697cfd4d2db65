"""Quick response checks of the `spine5` reality against published seated-
human ranges (its own H1 estimator; nothing of `ehm_drake.analysis`).

``python -m ehm_drake.realities.spine5.check [--duration 60] [--rms 0.5]``
runs random vertical and fore-aft tests of the nominal subject and prints
the vertical apparent-mass peak, the seat-to-head vertical transmissibility
peak and the fore-aft pelvis and head peaks, with the ranges compared
against:

* vertical apparent mass (normalised by the static pan load): peak at
  4-6 Hz, 1.3-1.8 (Fairley & Griffin 1989; Mansfield & Griffin 2000;
  ISO 5982:2019 range);
* seat-to-head vertical transmissibility: peak 4-6 Hz, 1.2-2.2 (Paddan &
  Griffin 1998 review; ISO 5982);
* fore-aft: pelvis x and head x transmissibility peaks below ~4 Hz with a
  back-rest (Paddan & Griffin 1998; Nawayseh & Griffin 2005).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import csd, welch

SEGMENT_S = 10.0


def h1(u: np.ndarray, y: np.ndarray, fs: float, segment_s: float = SEGMENT_S):
    """H1 estimate y/u with Hann segments (50 % overlap): (f, H, coherence)."""
    nper = int(round(segment_s * fs))
    f, puu = welch(u, fs, window="hann", nperseg=nper, detrend="constant")
    _, puy = csd(u, y, fs, window="hann", nperseg=nper, detrend="constant")
    _, pyy = welch(y, fs, window="hann", nperseg=nper, detrend="constant")
    with np.errstate(divide="ignore", invalid="ignore"):
        H = puy / puu
        coh = np.abs(puy) ** 2 / (puu * pyy)
    return f, H, coh


def transmissibility(record, channel: str, axis: int, segment_s: float = SEGMENT_S,
                     seat_disp=None):
    """Seat-to-channel transmissibility per metre of seat displacement:
    T = -(2 pi f)^2 H_{a->y} (m/m or deg/m).  With the seat displacement
    (n, 3) of the record, a translation's motion relative to the seat is
    used, T = [axis] + -(2 pi f)^2 H_{a->y_rel}: the doubly integrated seat
    displacement drifts far below the band and leaks into the low bins of
    short segments."""
    fs = 1.0 / (record.t[1] - record.t[0])
    y = np.asarray(record.channels[channel], float)
    dof = channel.rsplit("_", 1)[-1]
    offset = 0.0
    if seat_disp is not None and dof in "xyz":
        y = y - seat_disp[:, "xyz".index(dof)]
        offset = 1.0 if "xyz".index(dof) == axis else 0.0
    f, H, coh = h1(record.seat_acc[:, axis], y, fs, segment_s)
    return f, offset - ((2 * np.pi * f) ** 2) * H, coh


def apparent_mass(t, seat_acc, pan_force, axis: int = 2, segment_s: float = SEGMENT_S):
    """Seat-pan apparent mass F/a (kg) of the dynamic pan force."""
    fs = 1.0 / (t[1] - t[0])
    return h1(seat_acc[:, axis], pan_force, fs, segment_s)


def peak(f, g, band=(0.5, 12.0)):
    m = (f >= band[0]) & (f <= band[1])
    i = int(np.argmax(np.abs(g[m])))
    return float(f[m][i]), float(np.abs(g[m])[i])


def resonance(f, g, band=(2.0, 9.0), smooth_hz: float = 0.3):
    """Frequency of the peak of |g| smoothed with a Gaussian of `smooth_hz`
    (the seated body's broad vertical peak is flat-topped and ragged in
    short records: the unsmoothed maximum jumps between bins 0.5 Hz apart),
    refined by a parabola through the three bins about it."""
    df = float(f[1] - f[0])
    a = gaussian_filter1d(np.abs(g), smooth_hz / df)
    m = (f >= band[0]) & (f <= band[1])
    i = int(np.argmax(np.where(m, a, -np.inf)))
    y0, y1, y2 = a[i - 1:i + 2]
    den = y0 - 2.0 * y1 + y2
    return float(f[i] + (0.5 * (y0 - y2) / den * df if den < 0 else 0.0))


def run_checks(duration: float = 60.0, rms: float = 0.5, seed: int = 7, subject=None,
               effects=None, verbose: bool = True) -> dict:
    from ehm_drake.signals import make_seat_signal

    from .reality import Spine5Reality

    r = Spine5Reality()
    subj = r.nominal_subject() if subject is None else subject
    prepared = r.prepare(subj, effects or {})
    out: dict = {"statics": prepared.summary}
    static_pan = prepared.summary["pan_force_n"][2] / 9.81
    for direction in ("z", "x"):
        sig = make_seat_signal("random", direction, rms, duration + 1.0, seed, r.time_step,
                               1.0, 1.0)
        t0 = time.perf_counter()
        run = r.simulate(prepared, sig)
        wall = time.perf_counter() - t0
        rec = run.record
        disp = sig.displacement[int(round(sig.steady_start / sig.time_step)):]
        ax = "xyz".index(direction)
        res = {"real_time_factor": rec.real_time_factor, "wall_s": wall}
        for ch in ("pelvis", "trunk", "head"):
            f, T, coh = transmissibility(rec, f"{ch}_{direction}", ax, seat_disp=disp)
            res[f"{ch}_{direction}_peak"] = peak(f, T)
            if direction == "z":
                i = int(np.argmin(np.abs(f - 0.5)))
                res[f"{ch}_z_at_0.5Hz"] = float(np.abs(T[i]))
        f, T, _ = transmissibility(rec, "head_pitch", ax)
        res["head_pitch_peak"] = peak(f, T)
        if direction == "z":
            f, M, coh = apparent_mass(rec.t, rec.seat_acc, run.seat_forces[:, 2])
            fp, mp = peak(f, M)
            res["apparent_mass_peak_hz"] = fp
            res["apparent_mass_peak_norm"] = mp / static_pan
            i = int(np.argmin(np.abs(f - 0.5)))
            res["apparent_mass_0.5Hz_norm"] = float(np.abs(M[i]) / static_pan)
            lat = [np.std(rec.channels[c]) for c in ("pelvis_y", "head_y", "trunk_roll",
                                                      "head_yaw")]
            sag = [np.std(rec.channels[c]) for c in ("pelvis_z", "head_z", "trunk_pitch",
                                                      "head_pitch")]
            res["lateral_over_sagittal"] = float(max(lat) / max(sag))
        out[direction] = res
        if verbose:
            print(direction, {k: (tuple(round(x, 3) for x in v) if isinstance(v, tuple)
                                  else round(v, 4)) for k, v in res.items()})
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--rms", type=float, default=0.5)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--subject", type=int, default=None, help="subject seed (default nominal)")
    a = ap.parse_args(argv)
    from .reality import Spine5Reality

    subj = None if a.subject is None else Spine5Reality().subject(a.subject)
    run_checks(a.duration, a.rms, a.seed, subj)


if __name__ == "__main__":
    main()
