"""Real-time factor of `simulate`: 60 s of 3D seat excitation (0.1941 m/s^2
RMS per axis, random 0.1-12 Hz), outputs logged at 200 Hz, one core.

    python bench/bench_simulate.py [--duration 60] [--time-step 0.001]

Prints the settle time (static equilibrium + 5 s settling) and the
real-time factor of the vibration run (simulated seconds per wall second).
"""

from __future__ import annotations

import argparse
import os
import time

from ehm_drake.params import load_params
from ehm_drake.signals import make_seat_signal
from ehm_drake.simulation import settle, vibrate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--time-step", type=float, default=None)
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    params = load_params()
    if args.time_step:
        params.simulation.time_step_s = args.time_step
    s = params.simulation
    t0 = time.perf_counter()
    settled = settle(params)
    t_settle = time.perf_counter() - t0
    signal = make_seat_signal("random", "xyz", 0.1941, args.duration, 1, s.time_step_s,
                              s.settle_time_s, s.onset_time_s)
    result = vibrate(params, settled, signal)
    print(f"time step {s.time_step_s * 1e3:g} ms, outputs at {s.output_rate_hz:g} Hz")
    print(f"settle (equilibrium + {s.settle_time_s:g} s): {t_settle:.1f} s wall")
    print(f"vibrate {args.duration:g} s of 3D excitation: {result.meta['wall_s']:.1f} s wall, "
          f"real-time factor {result.meta['real_time_factor']:.2f}")


if __name__ == "__main__":
    main()
