"""Test metadata: ``meta.json``, the lab folder's test list ``tests.json``,
and the checks on metadata values.

A test's metadata (``level_rms`` in m/s^2, ``direction`` the excited axis or axes) comes from
the comment line of ``timeseries.csv`` and/or a sidecar ``meta.json`` in the same folder; see
:mod:`ehm_drake.analysis.formats` for the specification.

A lab folder with several tests (``frf.csv`` holding every test) may list them in
``tests.json``: ``{"directions": "xz", "levels_rms": [0.3, 0.6], "tests": [{"direction": "x",
"level_rms": 0.3, "timeseries": "x_0.3/timeseries.csv", "duration_s": ..., "n_averages":
...}, ...], "processing": {...}, "channel_units": {...}}``; without it a test's time series is
looked for at ``<direction>_<level>/timeseries.csv``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from .common import DataFormatError, normalise_directions

__all__ = ["META_FILENAME", "TESTS_FILENAME", "validate_meta", "merge_sidecar_meta",
           "write_test_list", "find_test_timeseries"]

META_FILENAME = "meta.json"
TESTS_FILENAME = "tests.json"


def validate_meta(meta: Mapping[str, Any], where: str) -> dict[str, Any]:
    """Checked copy of ``meta``: ``level_rms`` a positive float, ``direction`` canonical.

    ``where`` prefixes the error messages (file name, see :func:`.common.location`).
    """
    out = dict(meta)
    if "level_rms" in out and out["level_rms"] is not None:
        v = out["level_rms"]
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise DataFormatError(f"{where}metadata 'level_rms' must be a number, got {v!r}")
        if not math.isfinite(v) or v <= 0:
            raise DataFormatError(
                f"{where}metadata 'level_rms' must be a finite positive RMS (m/s^2), got {v!r}"
            )
        out["level_rms"] = float(v)
    if "direction" in out and out["direction"] is not None:
        out["direction"] = normalise_directions(out["direction"], where)
    return out


def merge_sidecar_meta(meta: dict[str, Any], path: Path, source: str) -> dict[str, Any]:
    """Merge the ``meta.json`` next to ``path`` (if any) into ``meta`` (in place).

    A key given in both with different values raises :class:`DataFormatError`.
    """
    sidecar = path.parent / META_FILENAME
    if sidecar.is_file():
        try:
            side = json.loads(sidecar.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise DataFormatError(f"{sidecar}: not valid JSON ({exc.msg})") from None
        if not isinstance(side, dict):
            raise DataFormatError(f"{sidecar}: JSON must be an object")
        for k, v in side.items():
            if k in meta and meta[k] != v:
                raise DataFormatError(
                    f"{source}: metadata '{k}' is {meta[k]!r} in the comment header but "
                    f"{v!r} in {sidecar}"
                )
            meta[k] = v
    return meta


def write_test_list(folder: Path, directions: str, levels: list[float], tests: list[dict],
                    processing: Mapping[str, Any], channel_units: Mapping[str, str]) -> Path:
    """Write ``tests.json`` into `folder` (see the module docstring)."""
    path = Path(folder) / TESTS_FILENAME
    path.write_text(json.dumps({
        "directions": directions,
        "levels_rms": list(levels),
        "tests": tests,
        "processing": dict(processing),
        "channel_units": dict(channel_units),
    }, indent=2) + "\n")
    return path


def find_test_timeseries(root: Path, direction: str, level: float) -> Path | None:
    """The time series of the test at (`direction`, `level` m/s^2 RMS) in the
    lab folder `root`: from ``tests.json`` if there is one, else at
    ``<direction>_<level>/timeseries.csv``; None if there is none."""
    tj = Path(root) / TESTS_FILENAME
    if tj.is_file():
        try:
            for t in json.loads(tj.read_text()).get("tests", []):
                if t.get("direction") == direction and \
                        math.isclose(float(t.get("level_rms", -1)), level, rel_tol=1e-6):
                    p = Path(root) / t["timeseries"]
                    return p if p.is_file() else None
        except (ValueError, KeyError, TypeError, AttributeError) as e:
            raise DataFormatError(f"{tj}: unreadable test list ({e})") from None
    p = Path(root) / f"{direction}_{level:g}" / "timeseries.csv"
    return p if p.is_file() else None
