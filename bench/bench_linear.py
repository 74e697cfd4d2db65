"""Speed of the linear analysis: static equilibrium + linearization + modes,
and the linear frequency response (3 directions x 30 channels x 240
frequencies) that identification evaluates in its loop.

    python bench/bench_linear.py
"""

from __future__ import annotations

import time

import numpy as np

from ehm_drake.analysis.linear import default_frequencies, linearize
from ehm_drake.diagram import build_diagram
from ehm_drake.params import load_params
from ehm_drake.simulation import static_equilibrium


def best_of(fn, n=20):
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), float(np.median(times))


def main() -> None:
    params = load_params()
    t0 = time.perf_counter()
    model = build_diagram(params, guard=False)
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    ctx, _ = static_equilibrium(model)
    t_eq = time.perf_counter() - t0
    t0 = time.perf_counter()
    lm = linearize(model, ctx, method="fd")
    t_lin = time.perf_counter() - t0
    t0 = time.perf_counter()
    modes = lm.modes()
    t_modes = time.perf_counter() - t0
    f = default_frequencies()
    arr = best_of(lambda: lm.transmissibility_array(f))
    tab = best_of(lambda: lm.transmissibility(f))
    print(f"build diagram {t_build:.2f} s; static equilibrium {t_eq:.2f} s; "
          f"FD linearization ({lm.A.shape[0]} states) {t_lin:.2f} s; "
          f"modes ({len(modes)}) {t_modes * 1e3:.1f} ms")
    print(f"linear FRF, 3 directions x 30 channels x {len(f)} frequencies: "
          f"{arr[0] * 1e3:.2f} ms as arrays (median {arr[1] * 1e3:.2f}), "
          f"{tab[0] * 1e3:.1f} ms as an frf.csv table (median {tab[1] * 1e3:.1f})")


if __name__ == "__main__":
    main()
