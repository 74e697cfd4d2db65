"""Responses and speed of the independent reality `lumped` against published
seated-human ranges.

    python bench/bench_reality_lumped.py [--seed N] [--level 0.4] [--duration 60]

Random seat excitation (flat 0.1-12 Hz) in z and in x; H1 estimates with
10 s Hann segments (this script's own estimator).  Prints the vertical
apparent-mass peak (pan force / seat acceleration, normalized by its 0.5-0.8
Hz value), the seat-to-pelvis/trunk/head transmissibility peaks, the
settled state and the real-time factor of each run.
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.signal as ss

from ehm_drake.realities import CHANNEL_NAMES
from ehm_drake.realities.lumped import LumpedReality
from ehm_drake.realities.lumped.simulate import run
from ehm_drake.signals import make_seat_signal

RANGES = {
    "apparent mass z": "peak 4-6 Hz, normalized 1.3-1.8 (Fairley & Griffin 1989)",
    "head z": "peak 4-6 Hz, gain 1.2-2.2 (Paddan & Griffin 1998)",
    "pelvis x / head x": "peaks below ~4 Hz (fore-aft with backrest)",
}


def h1(x, y, fs):
    n = int(round(10.0 * fs))
    f, pxy = ss.csd(x, y, fs, window="hann", nperseg=n)
    _, pxx = ss.welch(x, fs, window="hann", nperseg=n)
    _, pyy = ss.welch(y, fs, window="hann", nperseg=n)
    return f, pxy / pxx, np.abs(pxy) ** 2 / (pxx * pyy)


def peak(f, H, lo=0.5, hi=12.0):
    m = (f >= lo) & (f <= hi)
    i = int(np.argmax(np.abs(H[m])))
    return float(f[m][i]), float(np.abs(H[m][i]))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=None, help="subject seed (default: nominal)")
    ap.add_argument("--level", type=float, default=0.4)
    ap.add_argument("--duration", type=float, default=60.0)
    a = ap.parse_args()
    reality = LumpedReality()
    subject = reality.nominal_subject() if a.seed is None else reality.subject(a.seed)
    prep = reality.prepare(subject, {})
    s = prep.summary
    print(f"settled: {s['mass_kg']:.1f} kg, {s['dof']} DoF, vertical balance "
          f"{s['vertical_balance']:.5f}, supports (N) "
          + ", ".join(f"{k} {np.round(v, 1).tolist()}" for k, v in s["support_force_N"].items()))
    for d in "zx":
        sig = make_seat_signal("random", d, a.level, a.duration + 1.0, seed=7, settle_time=0.5,
                               onset_time=1.0)
        out = run(prep, sig)
        k0 = sig.sample_index(sig.steady_start)
        fs = 1.0 / sig.time_step
        ax = "xyz".index(d)
        disp = sig.displacement[k0:, ax]
        print(f"--- {d}, {a.level} m/s^2 RMS, {a.duration:g} s: real-time factor "
              f"{sig.duration / out.wall_s:.2f}")
        if d == "z":
            f, M, _ = h1(sig.acceleration[k0:, 2], out.support[k0:, 0, 2], fs)
            m0 = float(np.abs(M[(f >= 0.5) & (f <= 0.8)]).mean())
            fp, mp = peak(f, M, 1.0)
            print(f"  apparent mass z: {m0:.1f} kg at 0.5-0.8 Hz, peak {fp:.1f} Hz "
                  f"{mp:.1f} kg, normalized {mp / m0:.2f}   [{RANGES['apparent mass z']}]")
        for seg in ("pelvis", "trunk", "head"):
            for dof in (d, "pitch"):
                f, H, coh = h1(disp, out.channels[k0:, CHANNEL_NAMES.index(f"{seg}_{dof}")], fs)
                fp, g = peak(f, H)
                unit = "m/m" if dof in "xyz" else "deg/m"
                print(f"  {seg}_{dof}: peak {fp:.1f} Hz, {g:.3g} {unit} (coherence at the "
                      f"peak {coh[np.argmin(np.abs(f - fp))]:.2f})")
    for k, v in RANGES.items():
        print(f"published: {k}: {v}")


if __name__ == "__main__":
    main()
