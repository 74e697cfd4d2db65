"""Seconds per sweep run on each design: the seat engineer's batch of body
sizes x cushion stiffnesses (vertical random 0.1-12 Hz at the paper's
0.1941 m/s^2, `--duration` s per run after the paper's 5 s settling), the
same spec run once as `sweep` runs it by default (`design: auto`, the
implicit design at each body's accurate step) and once on the paper's
reference design (`design: reference`, 1 ms).

    python bench/bench_sweep.py [--duration 30] [--workers 1] [--bodies small,median,large]

Prints, per design, the steps the runs took, the wall time per run (settle +
vibrate + analysis, in the worker) and the vibration's real-time factor.  The
designs' accuracy is `bench_step_accuracy.py`'s (a short run's peaks differ
between the designs mostly by the realization of the excitation, which
depends on the step).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from ehm_drake.params import load_params
from ehm_drake.sweep import run_sweep


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--bodies", default="small,median,large")
    args = ap.parse_args()
    k = load_params().contact.pelvis_pan.stiffness
    spec = {"name": "bench", "direction": "z", "duration": args.duration, "seed": 3,
            "body": args.bodies.split(","),
            "grid": {"contact.pelvis_pan.stiffness": [0.7 * k, 1.3 * k]},
            "analysis": {"frf": False}}
    for design in ("auto", "reference"):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            result = run_sweep(dict(spec, design=design), Path(tmp) / "out",
                               max_workers=args.workers, progress=False)
            wall = time.perf_counter() - t0
        runs = [r["results"] for r in result.records if r["status"] == "done"]
        if len(runs) != len(result.records):
            raise SystemExit(f"design {design}: {len(result.records) - len(runs)} runs failed")
        per_run = [r["wall_s"] for r in runs]
        steps = sorted({r["time_step_s"] for r in runs})
        print(f"design {design:9s} ({runs[0]['design']}, steps "
              f"{', '.join(f'{1e3 * h:.3g} ms' for h in steps)}): {len(runs)} runs in "
              f"{wall:.1f} s on {args.workers} worker(s); per run median "
              f"{statistics.median(per_run):.1f} s (max {max(per_run):.1f}); vibration "
              f"{statistics.median(r['real_time_factor'] for r in runs):.1f}x real time")


if __name__ == "__main__":
    main()
