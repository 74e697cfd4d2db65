"""C3D sessions to a lab folder: :func:`c3d_lab_folder`.

Each C3D file is one test (one excitation direction and level).  Every session is reduced
to a time series (`ehm_drake.analysis.mocap`), its transmissibility estimated with the
project's H1 (10 s Hann segments, 50% overlap, as `synth` and `diagnose` do), and the lab
folder written -- only once every file has been read without error, so a bad file leaves
nothing behind::

    OUT/frf.csv                                  every test's transmissibility
    OUT/<direction>_<level>/timeseries.csv       each test's reduced record
    OUT/tests.json                               the test list (with each test's C3D file)
    OUT/mocap_report.json                        per file: rate, frames used, per cluster the
                                                 fit residual, missing markers, gaps filled

The folder is what `diagnose`, `fit` and `transmissibility` read.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from .formats import DataFormatError, FrfData, write_test_list
from .marker_map import MarkerMap, load_marker_map
from .mocap import MocapResult, read_session
from .transmissibility import transmissibility

__all__ = ["SEGMENT_S", "REPORT_FILENAME", "LabFolder", "c3d_files", "c3d_lab_folder"]

#: Welch segment length (s), as `synth` and `diagnose` use.
SEGMENT_S = 10.0
REPORT_FILENAME = "mocap_report.json"


@dataclass
class LabFolder:
    """What :func:`c3d_lab_folder` made: the folder, its transmissibility, the tests
    (tests.json entries), the sessions' reports and warnings."""

    out: Path | None
    frf: FrfData
    tests: list[dict]
    reports: list[dict]
    warnings: list[str] = field(default_factory=list)


def c3d_files(paths) -> list[Path]:
    """The C3D files named by `paths` (files, or folders whose ``*.c3d`` are taken)."""
    files: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.suffix.lower() == ".c3d")
            if not found:
                raise FileNotFoundError(f"{p}: no .c3d files in the folder")
            files += found
        elif p.is_file():
            files.append(p)
        else:
            raise FileNotFoundError(f"C3D file not found: {p}")
    if len(set(files)) != len(files):
        raise ValueError("a C3D file is given twice")
    return files


def _test_frf(result: MocapResult) -> FrfData:
    ts = result.timeseries
    ts.check_length()
    nperseg = int(round(min(SEGMENT_S, ts.duration / 2) * ts.fs))
    return transmissibility(ts, directions=ts.meta["direction"], nperseg=nperseg)


def c3d_lab_folder(paths, marker_map: MarkerMap | str | Path, out: str | Path | None,
                   force: bool = False, progress: bool = True) -> LabFolder:
    """Reduce the C3D sessions `paths` with `marker_map` and write the lab folder `out`
    (see the module docstring; None: nothing written).  An existing non-empty `out` needs
    `force`.  Raises DataFormatError (one line naming the file) on any bad input, before
    anything is written."""
    from ..progress import Progress

    mmap = marker_map if isinstance(marker_map, MarkerMap) else load_marker_map(marker_map)
    files = c3d_files(paths)
    if out is not None:
        out = Path(out)
        if out.exists() and (not out.is_dir() or (any(out.iterdir()) and not force)):
            raise ValueError(f"output folder {out} exists and is not empty; use --force to "
                             "write into it (files of the same name are replaced)")
    prog = Progress("c3d", len(files), progress, unit="sessions")
    results, frfs, seen = [], [], {}
    for f in files:
        res = read_session(f, mmap)
        ts = res.timeseries
        key = (ts.meta["direction"], ts.meta["level_rms"])
        if key in seen:
            raise DataFormatError(f"{f}: the same test as {seen[key]} (direction "
                                  f"{key[0]}, {key[1]:g} m/s^2 RMS); give each test once")
        seen[key] = f
        frfs.append(_test_frf(res))
        results.append(res)
        prog.step(f"{f.name}: {key[0]} @ {key[1]:g} m/s^2, {ts.duration:.0f} s")
    frf = FrfData.concat(frfs)
    tests = []
    for f, res, part in zip(files, results, frfs, strict=True):
        ts = res.timeseries
        name = f"{ts.meta['direction']}_{ts.meta['level_rms']:g}"
        tests.append({"direction": ts.meta["direction"], "level_rms": ts.meta["level_rms"],
                      "timeseries": f"{name}/timeseries.csv", "duration_s": float(ts.duration),
                      "n_averages": int(part.n_averages[0]), "c3d": f.name})
    warnings = [w for r in results for w in r.warnings]
    reports = [r.report for r in results]
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        frf.to_csv(out / "frf.csv")
        for t, res in zip(tests, results, strict=True):
            sub = out / Path(t["timeseries"]).parent
            sub.mkdir(exist_ok=True)
            res.timeseries.to_csv(out / t["timeseries"])
        directions = "".join(d for d in "xyz" if any(d in t["direction"] for t in tests))
        write_test_list(out, directions, sorted({t["level_rms"] for t in tests}), tests,
                        {"estimator": "H1", "segment_s": SEGMENT_S, "overlap": 0.5,
                         "window": "hann", "band_hz": [0.0, 12.0],
                         "source": "C3D sessions (ehm_drake.analysis.mocap)",
                         "marker_map": mmap.source},
                        {"translation": "m/m", "rotation": "deg/m"})
        (out / REPORT_FILENAME).write_text(json.dumps(
            {"marker_map": mmap.source, "sessions": reports}, indent=1) + "\n")
    return LabFolder(out, frf, tests, reports, warnings)
