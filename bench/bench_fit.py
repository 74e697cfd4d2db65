"""Time of a 20-parameter fit on 3 directions x 240 frequencies (the
identification issue's target: under 60 s on 2 cores).

    python bench/bench_fit.py [--workers 2]

Data: the model's own linear transmissibility on the paper's channels with
the 20 default free parameters moved 20-40% (seeded), H1 noise of coherence
0.9; the fit starts from the defaults.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ehm_drake.identification.fit import fit
from ehm_drake.identification.parameters import apply_scales, resolve_free
from ehm_drake.identification.synthetic import synthetic_frf
from ehm_drake.params import load_params


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    params = load_params()
    free = resolve_free("default")
    rng = np.random.default_rng(3)
    true = np.exp(rng.choice([-1, 1], len(free)) * rng.uniform(np.log(1.2), np.log(1.4),
                                                                 len(free)))
    data = synthetic_frf(apply_scales(params, free, true), seed=1)
    t0 = time.perf_counter()
    result = fit(data, params, free, workers=args.workers, progress=False)
    wall = time.perf_counter() - t0
    r = result.report
    errs = [abs(p["scale"] / s - 1) for p, s in zip(r["parameters"], true, strict=True)
            if p["identifiable"]]
    print(f"{len(free)}-parameter fit, {len(set(data.direction))} directions x "
          f"{len(np.unique(data.freq_hz))} frequencies ({len(data)} rows), "
          f"{args.workers} workers: {wall:.1f} s wall "
          f"({r['n_model_evaluations']} model evaluations)")
    print(f"cost {r['cost_before']:.4g} -> {r['cost_after']:.4g}; {len(errs)} parameters "
          f"determined by the data, worst recovery error {100 * max(errs):.1f}%; "
          f"{len(r['not_identifiable'])} flagged as not determined")


if __name__ == "__main__":
    main()
