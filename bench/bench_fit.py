"""Time and outcome of a 20-parameter fit (target: under 60 s on 2 cores).

    python bench/bench_fit.py [--workers 2]
    python bench/bench_fit.py --subject [--duration 90] [--design implicit|reference]

Default data: the model's own linear transmissibility on the paper's
channels with the 20 default free parameters moved 20-40% (seeded), H1
noise of coherence 0.9; the fit starts from the defaults.

`--subject`: a subject made by the model with five parameters changed
inside the fit's bounds (lumbar stiffness x1.5, spine axial x1.4,
pelvis-pan contact x1.3, neck damping x0.6, head-in-space kp x1.5),
simulated in the time domain (x, y and z together at the default level,
seed 31), then `ehm-drake fit DATA --holdout direction=y`, both on `--design`
(default: the commands' own, the implicit design): prints the cost's fall,
the held-out lateral error, the five recovered scales and the fit's wall
time.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ehm_drake.identification.fit import fit
from ehm_drake.identification.parameters import apply_scales, resolve_free
from ehm_drake.identification.synthetic import synthetic_frf
from ehm_drake.params import load_params

#: The subject of `--subject`: fit parameter -> scale.
SUBJECT = {"lumbar_stiffness": 1.5, "spine_axial_stiffness": 1.4,
           "contact_pelvis_stiffness": 1.3, "neck_damping": 0.6, "his_kp": 1.5}


def subject(workers: int, duration: float, design: str) -> None:
    import json
    import tempfile
    from pathlib import Path

    from ehm_drake.cli import main as cli
    from ehm_drake.params import save_params

    free = resolve_free(",".join(SUBJECT))
    truth = apply_scales(load_params(), free, list(SUBJECT.values()))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        save_params(truth, tmp / "subject.yaml")
        t0 = time.perf_counter()
        cli(["simulate", "--params", str(tmp / "subject.yaml"), "--direction", "xyz",
             "--duration", str(duration), "--seed", "31", "--design", design,
             "--out", str(tmp / "data"), "--quiet"])
        t_sim = time.perf_counter() - t0
        t0 = time.perf_counter()
        cli(["fit", str(tmp / "data"), "--holdout", "direction=y", "--no-verify",
             "--design", design, "--workers", str(workers), "--out", str(tmp / "fit"),
             "--quiet"])
        t_cmd = time.perf_counter() - t0
        r = json.loads((tmp / "fit" / "fit_report.json").read_text())
    scales = {p["name"]: p["scale"] for p in r["parameters"]}
    print(f"subject ({design} design, {duration:g} s, x+y+z together): simulated in "
          f"{t_sim:.0f} s; fit {r['fit_wall_s']:.1f} s ({t_cmd:.1f} s the whole command, "
          f"{workers} workers, {r['n_model_evaluations']} model evaluations)")
    print(f"cost {r['cost_before']:.4g} -> {r['cost_after']:.4g} "
          f"({100 * (1 - r['cost_after'] / r['cost_before']):.1f}% lower); held-out lateral "
          f"error {r['heldout_error']:.3f} (start {r['heldout_error_before']:.3f})")
    print("recovered / true scale: " + ", ".join(
        f"{n} {scales[n]:.3f}/{s:g}" for n, s in SUBJECT.items()))
    others = [abs(v - 1) for n, v in scales.items() if n not in SUBJECT]
    print(f"the other {len(others)} parameters: at most {100 * max(others):.0f}% from the start")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--subject", action="store_true")
    ap.add_argument("--duration", type=float, default=90.0)
    ap.add_argument("--design", default="implicit", choices=["reference", "implicit"])
    args = ap.parse_args()
    if args.subject:
        subject(args.workers, args.duration, args.design)
        return
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
