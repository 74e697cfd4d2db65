"""Discrete SAP step against a continuous plant on Drake's error-controlled
`cenic` integrator (to keep the faster design that meets the accuracy bar).

    python bench/bench_cenic.py [--design implicit|reference] [--duration 1]
        [--accuracies 1e-2,1e-3]

The closed loop cannot run on `cenic` as it is: its controllers are
discrete systems updated every step (the PID integral, the restraints'
slip), which would stop the integrator at every step.  What this measures
is the ceiling of each route, the plant alone (no Python system): it
replays the generalized forces the closed loop (the design at its own
step) applied during the first `duration` s of 3D excitation (0.1941
m/s^2 RMS per axis), from the settled state, on
  * the discrete plant at the design's step (zero-order hold, as in the
    closed loop), and
  * the same plant continuous (time_step 0), on `cenic` with error control
    at each accuracy (first-order hold of the same forces).
Printed: real-time factor (one core), steps and cost per step, and how far
each replay's positions end from the closed loop's (open loop: without
feedback the body drifts from the closed loop's path, so this is a sanity
figure, not the accuracy bar).  The controllers and outputs cost the same
per step on either route; a route whose plant alone is slower than the
other's cannot give the faster closed loop.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from bench_simulate import closed_loop_forces, replay  # this folder (run as a script)

from ehm_drake.params import load_params, with_design
from ehm_drake.signals import make_seat_signal
from ehm_drake.simulation import settle


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--design", choices=("implicit", "reference"), default="implicit")
    ap.add_argument("--duration", type=float, default=1.0)
    ap.add_argument("--accuracies", default="1e-2,1e-3")
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    params = with_design(load_params(), args.design)
    s = params.simulation
    h = s.time_step_s
    signal = make_seat_signal("random", "xyz", 0.1941, args.duration + 2.0, 1, h,
                              s.settle_time_s, s.onset_time_s)
    times, F, q_end, x_start = closed_loop_forces(params, settle(params), signal, args.duration)
    print(f"{args.design} design; the plant alone replaying {args.duration:g} s of the closed "
          f"loop's forces (3D excitation)")
    routes = [(f"discrete SAP, {h * 1e3:g} ms", h, None)] + [
        (f"cenic, accuracy {a}", 0.0, float(a)) for a in args.accuracies.split(",")]
    for label, step, accuracy in routes:
        try:
            rtf, n, wall, q = replay(params, times, F, x_start, step, accuracy)
        except Exception as e:  # noqa: BLE001  (report and go on to the next route)
            print(f"  {label:26s}: failed: {str(e).splitlines()[0][:200]}")
            continue
        print(f"  {label:26s}: {rtf:6.2f}x real time, {n:5d} steps "
              f"(mean {1e3 * (times[-1] - times[0]) / n:.2f} ms), {wall / n * 1e6:4.0f} us per "
              f"step; end positions {np.max(np.abs(q - q_end)):.1e} from the closed loop's",
              flush=True)


if __name__ == "__main__":
    main()
