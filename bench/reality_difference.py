"""How far an independent reality differs from the EHM model, beside how far
subjects differ from each other.

For each body (the EHM default subject; two seeded EHM subjects; two seeded
subjects of each reality) `ehm-drake synth` makes no-effect lab data (x, y,
z at the given levels).  The difference between two datasets is the RMS over
their common excitation-plane rows (0.5-12 Hz, coherence >= 0.9 in both)
of the log gain ratio, reported as exp(rms) - 1: 0.15 means gains differ by
15% RMS.  Prints the table; with --out, writes it as JSON.

    python bench/reality_difference.py --realities lumped,spine5 --duration 60
"""

from __future__ import annotations

import argparse
import itertools
import json
import tempfile
from pathlib import Path

import numpy as np

from ehm_drake.gap.lab.synth import SynthSpec, synthesize
from ehm_drake.gap.single.diagnose import load_lab_data

MIN_COHERENCE = 0.9
BAND_HZ = (0.5, 12.0)


def gains(folder: Path) -> dict:
    """{(direction, level, segment, dof, freq): (gain, coherence)} of the plane rows."""
    rows = load_lab_data(folder).rows
    keep = (rows.freq >= BAND_HZ[0]) & (rows.freq <= BAND_HZ[1])
    return {(str(d), round(float(lv), 6), str(s), str(o), round(float(f), 6)): (abs(h), c)
            for d, lv, s, o, f, h, c, k in zip(rows.direction, rows.level, rows.segment,
                                              rows.dof, rows.freq, rows.H, rows.coherence,
                                              keep, strict=True) if k}


def difference(a: dict, b: dict) -> tuple[float, int]:
    """exp(RMS log gain ratio) - 1 over the common coherent rows, and their count."""
    common = [k for k in a if k in b and min(a[k][1], b[k][1]) >= MIN_COHERENCE
              and a[k][0] > 0 and b[k][0] > 0]
    r = np.log([a[k][0] / b[k][0] for k in common])
    return float(np.expm1(np.sqrt(np.mean(r**2)))) if common else float("nan"), len(common)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--realities", default="lumped,spine5")
    ap.add_argument("--levels", default="0.3,0.6")
    ap.add_argument("--directions", default="xyz")
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--root", help="keep the data here (default: a temporary folder)")
    ap.add_argument("--out", help="write the table as JSON")
    a = ap.parse_args(argv)
    levels = tuple(float(v) for v in a.levels.split(","))
    root = Path(a.root or tempfile.mkdtemp(prefix="ehm_reality_diff_"))
    bodies = [("ehm default", "ehm", 0, 0.0), ("ehm subject 1", "ehm", 1, None),
              ("ehm subject 2", "ehm", 2, None)]
    for r in filter(None, a.realities.split(",")):
        bodies += [(f"{r} subject 1", r, 1, None), (f"{r} subject 2", r, 2, None)]
    data = {}
    for label, reality, seed, spread in bodies:
        folder = root / label.replace(" ", "_")
        if not (folder / "frf.csv").is_file():
            spec = SynthSpec({}, seed, levels, a.directions, a.duration, reality=reality)
            if spread is not None:
                spec.spread = spread
            synthesize(spec, folder, root / f"{folder.name}_key.json", workers=a.workers,
                       progress=True)
        data[label] = gains(folder)
    table = []
    for x, y in itertools.combinations(data, 2):
        d, n = difference(data[x], data[y])
        table.append({"a": x, "b": y, "rms_gain_difference": d, "rows": n})
        print(f"{x:>18s} vs {y:<18s}: {100 * d:5.1f}% RMS gain difference ({n} rows)")
    if a.out:
        Path(a.out).write_text(json.dumps(table, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
