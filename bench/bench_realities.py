"""Speed of the independent realities: real-time factor of one random test.

    python bench/bench_realities.py [--reality spine5,lumped] [--direction z] [--duration 30]
    EHM_DRAKE_NO_JIT=1 python bench/bench_realities.py    # their NumPy laws only

The nominal subject of each reality, settled, then a random seat test (flat
0.1-12 Hz, 0.3 m/s^2 RMS, seed 7) at the reality's own time step, after a
2 s run that compiles the numba kernels (cached on disk after the first run
on a machine).  Prints the wall time and the real-time factor of the test.
A blind run on a reality spends most of its time in these simulations.
"""

from __future__ import annotations

import argparse
import time

from ehm_drake import jit
from ehm_drake.realities import RealityError, get_reality
from ehm_drake.signals import SignalError, make_seat_signal


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reality", default="spine5,lumped")
    ap.add_argument("--direction", default="z", choices=["x", "y", "z", "xyz"])
    ap.add_argument("--duration", type=float, default=30.0)
    a = ap.parse_args()
    print(f"compiled laws: {'yes' if jit.available() else 'no (NumPy laws)'}")
    for name in a.reality.split(","):
        try:
            reality = get_reality(name.strip())
            h = reality.time_step
            signal = make_seat_signal("random", a.direction, 0.3, a.duration, 7, h, 0.5, 1.0)
        except (RealityError, SignalError) as e:
            ap.error(str(e))
        t0 = time.perf_counter()
        prepared = reality.prepare(reality.nominal_subject(), {})
        t_prep = time.perf_counter() - t0
        reality.run_test(prepared, make_seat_signal("random", a.direction, 0.3, 2.0, 7, h,
                                                    0.5, 1.0))
        t0 = time.perf_counter()
        reality.run_test(prepared, signal)
        wall = time.perf_counter() - t0
        print(f"{name}: {signal.duration:.1f} s of {a.direction} at a {1e3 * h:g} ms step in "
              f"{wall:.1f} s: {signal.duration / wall:.2f}x real time (settling "
              f"{t_prep:.1f} s)")


if __name__ == "__main__":
    main()
