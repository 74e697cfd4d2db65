"""Small cases of the commands whose outputs must not change when code only
moves (the structure issue): ``simulate``, ``sweep``, ``synth`` and
``diagnose``.  `run_cases(root)` runs them into `root`; the test
(tests/test_golden_outputs.py) compares the files with the ones stored
beside this module, which were written by the code before the move
(``python tests/golden/cases.py --write`` rewrites them: only for a change
that is meant to change the outputs, with the reason in its commit)."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

SWEEP_SPEC = {
    "name": "golden",
    "duration": 3.0,
    "rms": 0.5,
    "direction": "z",
    "seed": 2,
    "params": {"simulation": {"settle_time_s": 0.5, "onset_time_s": 0.5}},
    "grid": {"pid.neck.kp": [[25.0, 22.0, 15.0], [30.0, 26.0, 18.0]],
             "design": ["auto", "reference"]},  # (auto: the implicit design at 5 ms)
}

#: (command name, argv after `ehm-drake`, output folder).  Run in order:
#: diagnose reads synth's data.
CASES = (
    ("simulate", ["simulate", "--design", "reference", "--out", "simulate", "--duration", "3",
                  "--direction", "xyz", "--seed", "1", "--quiet"], "simulate"),
    # The commands' default design (implicit, 5 ms).
    ("simulate_implicit", ["simulate", "--out", "simulate_implicit", "--duration", "3",
                           "--direction", "xyz", "--seed", "1", "--quiet"],
     "simulate_implicit"),
    ("sweep", ["sweep", "sweep_spec.json", "--out", "sweep", "--workers", "2", "--quiet"],
     "sweep"),
    ("synth", ["synth", "--effect", "seat_foam_stiffening", "--strength", "1", "--seed", "5",
               "--levels", "0.3,0.6", "--directions", "z", "--duration", "30", "--workers",
               "2", "--out", "synth", "--key", "synth_key.json", "--quiet"], "synth"),
    ("diagnose", ["diagnose", "synth", "--out", "diagnose", "--effects",
                  "seat_foam_stiffening,reflex_delay", "--workers", "2", "--quiet"],
     "diagnose"),
)

#: Data files compared byte for byte (figures are drawn from these).
SUFFIXES = (".csv", ".json", ".md", ".npz", ".yaml")

#: Keys whose values are clocks, not results (wall times, real-time
#: factors, host names): replaced by a placeholder before comparing.
VOLATILE = ("wall", "real_time_factor", "elapsed", "host", "utc", "timing", "seconds")
#: Keys naming the process that ran a job (at a record's top level: the
#: parameters' ``pid`` group is a result).
PROCESS = ("pid",)


def _volatile(key: str, top: bool = False) -> bool:
    return (top and key in PROCESS) or any(v in key for v in VOLATILE)


def _scrub(obj, top: bool = True):
    if isinstance(obj, dict):
        return {k: ("<clock>" if _volatile(k, top) else _scrub(v, False))
                for k, v in obj.items()}
    if isinstance(obj, list):
        return [_scrub(v, False) for v in obj]
    return obj


def normalized(path: Path) -> bytes:
    """The file's bytes; JSON with its clock values replaced."""
    data = path.read_bytes()
    if path.suffix == ".json":
        return (json.dumps(_scrub(json.loads(data)), indent=1, sort_keys=True) + "\n").encode()
    if path.suffix == ".csv":
        # Tables with a clock column (the sweep summary's wall time) lose that
        # column; every other table is compared as it is.
        lines = data.decode().splitlines(keepends=True)
        head = next((i for i, line in enumerate(lines) if not line.startswith("#")), None)
        if head is None:
            return data
        names = next(csv.reader([lines[head]]))
        if not any(_volatile(k) for k in names):
            return data
        keep = [i for i, k in enumerate(names) if not _volatile(k)]
        buf = io.StringIO()
        buf.writelines(lines[:head])
        csv.writer(buf, lineterminator="\n").writerows(
            [r[i] for i in keep] for r in csv.reader(lines[head:]))
        return buf.getvalue().encode()
    if path.suffix == ".md":
        # The report's run-time sentence is a clock.
        return b"".join(b"<clock>\n" if line.startswith(b"Run time") else line
                        for line in data.splitlines(keepends=True))
    return data


def output_files(root: Path) -> dict[str, bytes]:
    """{relative path: normalized bytes} of every data file the cases wrote."""
    out = {}
    for _, _, folder in CASES:
        for p in sorted((root / folder).rglob("*")):
            if p.is_file() and p.suffix in SUFFIXES:
                out[str(p.relative_to(root))] = normalized(p)
    key = root / "synth_key.json"
    out["synth_key.json"] = normalized(key)
    return out


def versions() -> dict[str, str]:
    """The numerical libraries the stored files were made with: bytes are
    compared only under the same versions (another Drake may step
    differently)."""
    from importlib.metadata import version

    return {p: version(p) for p in ("drake", "numpy", "scipy")}


def avx512_targets() -> list[str]:
    """NumPy's runtime-dispatched AVX-512 targets (e.g. ``X86_V4``,
    ``AVX512_SKX``), which the cases run without: NumPy's AVX-512 kernels
    of some functions round differently from its AVX2 ones, so the same
    versions wrote other bytes for every frequency response (FRF CSVs, the
    diagnosis report) on an AVX-512 machine (an AMD EPYC) than on the one
    that stored them, while every time series matched; without them both
    write the stored bytes (`NPY_DISABLE_CPU_FEATURES`)."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__
    except ImportError:  # NumPy 1.x
        from numpy.core._multiarray_umath import __cpu_dispatch__
    return [t for t in __cpu_dispatch__ if t == "X86_V4" or t.startswith("AVX512")]


def run_cases(root: Path) -> None:
    root.mkdir(parents=True, exist_ok=True)
    (root / "sweep_spec.json").write_text(json.dumps(SWEEP_SPEC))
    env = dict(os.environ, EHM_DRAKE_CACHE=str(root / "cache"),
               NPY_DISABLE_CPU_FEATURES=" ".join(avx512_targets()))
    for name, argv, _ in CASES:
        r = subprocess.run([sys.executable, "-m", "ehm_drake.cli", *argv], cwd=root, env=env,
                           capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"{name} failed ({r.returncode}): {r.stderr[-2000:]}")


#: Files up to this size are stored whole (a failing comparison shows the
#: first differing line); larger ones only by their SHA-256.
STORE_WHOLE_BYTES = 256_000


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def write_expected(files: dict[str, bytes], dest: Path = HERE / "expected") -> None:
    """Store `files` as the expected outputs: MANIFEST.json (the hash of
    every file and the library versions) and the small files whole."""
    shutil.rmtree(dest, ignore_errors=True)
    dest.mkdir(parents=True)
    for rel, data in files.items():
        if len(data) <= STORE_WHOLE_BYTES:
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            (dest / rel).write_bytes(data)
    manifest = {"versions": versions(),
                "sha256": {rel: sha256(data) for rel, data in sorted(files.items())}}
    (dest / "MANIFEST.json").write_text(json.dumps(manifest, indent=1) + "\n")


if __name__ == "__main__":
    import argparse
    import tempfile

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--write", action="store_true", help="rewrite the stored files")
    ap.add_argument("--root", help="run into this (new) folder (default: a temporary one)")
    ap.add_argument("--reuse", action="store_true", help="do not run: take the outputs "
                    "already in --root")
    a = ap.parse_args()
    root = Path(a.root or tempfile.mkdtemp(prefix="ehm_golden_"))
    if not a.reuse:
        run_cases(root)
    files = output_files(root)
    print(f"{len(files)} files in {root}")
    if a.write:
        write_expected(files)
        print(f"written to {HERE / 'expected'}")
