"""The marker map of a motion-capture lab: :class:`MarkerMap` and :func:`load_marker_map`.

A YAML file says how a lab's C3D sessions become the project's time series
(`ehm_drake.analysis.mocap`); the package's example is
``ehm_drake/data/marker_map_example.yaml``::

    units: mm                 # POINT:UNITS the C3D files must have (mm, cm or m)
    seat_axes: {x: +X, y: +Y, z: +Z}   # the seat's axes (x forward, y left, z up) in the lab
    max_gap_s: 0.05           # longest span a cluster may be lost and still be filled
    max_residual_m: 0.003     # a cluster fit worse than this: a marker swap or a loose marker
    accelerometers:           # the seat accelerometer(s): analog channel, unit, sensitivity
      - {channel: SeatAccZ, axis: +z, unit: V, sensitivity: 0.0102}   # V per m/s^2
    clusters:                 # rigid marker clusters, >= 3 markers each
      seat:   {markers: [SEAT1, SEAT2, SEAT3, SEAT4]}
      pelvis: {markers: [PELV1, PELV2, PELV3, PELV4], origin: [PELV1, PELV2],
               origin_offset_m: [0.0, 0.0, -0.02]}
      ...

``seat`` is required and at least one of the segments ``pelvis``, ``trunk``, ``head``,
``knee_l``, ``knee_r``.  A segment's tracked point (whose displacement the time series
reports) is the mean of its ``origin`` markers (default: all the cluster's markers) at the
reference pose, plus ``origin_offset_m`` on the seat's axes; it moves rigidly with the
cluster.  Its rotation does not depend on where the point is.

Errors raise :class:`MarkerMapError` (a ``DataFormatError``) naming the file and the key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .formats import SEGMENTS, DataFormatError

__all__ = ["MarkerMapError", "Cluster", "Accelerometer", "MarkerMap", "load_marker_map",
           "marker_map_from_dict", "EXAMPLE_MARKER_MAP", "UNIT_SCALE_M"]

#: The package's example map (also a test fixture).
EXAMPLE_MARKER_MAP = Path(__file__).resolve().parent.parent / "data" / "marker_map_example.yaml"
#: Metres per point unit.
UNIT_SCALE_M = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
MIN_CLUSTER_MARKERS = 3
_TOP_KEYS = ("units", "seat_axes", "max_gap_s", "max_residual_m", "accelerometers", "clusters")
_CLUSTER_KEYS = ("markers", "origin", "origin_offset_m")
_ACC_KEYS = ("channel", "axis", "unit", "sensitivity")
_LAB_AXES = {"X": 0, "Y": 1, "Z": 2}


class MarkerMapError(DataFormatError):
    """An invalid marker map (names the file and the key)."""


@dataclass(frozen=True)
class Cluster:
    """A rigid marker cluster: its markers, and the tracked point of a segment."""

    name: str
    markers: tuple[str, ...]
    origin: tuple[str, ...]
    origin_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Accelerometer:
    """A seat accelerometer: ``sign`` * (analog value / ``sensitivity``) is the seat
    acceleration along seat axis ``axis`` (m/s^2); ``unit`` is the channel's unit."""

    channel: str
    axis: str
    sign: float
    unit: str
    sensitivity: float


@dataclass(frozen=True)
class MarkerMap:
    """A lab's marker map (see the module docstring).

    ``R_LS`` is the rotation from the seat frame S to the lab frame L: its columns are the
    seat's x, y, z axes in lab coordinates.
    """

    units: str
    R_LS: np.ndarray
    seat: Cluster
    segments: dict[str, Cluster]
    accelerometers: tuple[Accelerometer, ...]
    max_gap_s: float
    max_residual_m: float
    source: str = ""

    @property
    def scale_m(self) -> float:
        """Metres per point unit."""
        return UNIT_SCALE_M[self.units]

    @property
    def clusters(self) -> dict[str, Cluster]:
        """Seat first, then the segments in `SEGMENTS` order."""
        return {"seat": self.seat, **self.segments}


def _fail(where: str, key: str, msg: str):
    raise MarkerMapError(f"{where}{key}: {msg}")


def _number(where: str, key: str, v: Any, lo: float, hi: float, unit: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        _fail(where, key, f"must be a number ({unit}), got {v!r}")
    if not lo < v <= hi:
        _fail(where, key, f"= {v!r}: allowed {lo:g} < value <= {hi:g} {unit}")
    return float(v)


def _names(where: str, key: str, v: Any, least: int) -> tuple[str, ...]:
    if not isinstance(v, list) or not all(isinstance(x, str) and x.strip() for x in v):
        _fail(where, key, f"must be a list of marker names, got {v!r}")
    names = tuple(x.strip() for x in v)
    dup = sorted({x for x in names if names.count(x) > 1})
    if dup:
        _fail(where, key, f"repeats {dup}")
    if len(names) < least:
        _fail(where, key, f"needs at least {least} markers (a rigid pose), got {len(names)}")
    return names


def _unknown(where: str, key: str, d: dict, allowed: tuple[str, ...]) -> None:
    bad = [k for k in d if k not in allowed]
    if bad:
        _fail(where, key, f"unknown key(s) {bad}; allowed: {', '.join(allowed)}")


def _cluster(where: str, name: str, d: Any) -> Cluster:
    key = f"clusters.{name}"
    if not isinstance(d, dict):
        _fail(where, key, f"must be a mapping with 'markers', got {d!r}")
    _unknown(where, key, d, _CLUSTER_KEYS)
    if "markers" not in d:
        _fail(where, key, "missing 'markers'")
    markers = _names(where, f"{key}.markers", d["markers"], MIN_CLUSTER_MARKERS)
    origin = markers
    if d.get("origin") is not None:
        origin = _names(where, f"{key}.origin", d["origin"], 1)
    off = d.get("origin_offset_m", [0.0, 0.0, 0.0])
    if not (isinstance(off, list) and len(off) == 3):
        _fail(where, f"{key}.origin_offset_m", f"must be 3 numbers (m, seat axes), got {off!r}")
    off = tuple(_number(where, f"{key}.origin_offset_m", x, -1.0 - 1e-12, 1.0, "m")
                for x in off)
    if name == "seat" and (d.get("origin") is not None or any(off)):
        _fail(where, key, "the seat's origin is its cluster's centre; give no origin")
    return Cluster(name, markers, origin, off)


def _axis(where: str, key: str, v: Any, letters: str) -> tuple[int, float]:
    """'+X' / '-y' -> (index, sign)."""
    s = str(v).strip() if isinstance(v, str) else ""
    sign = -1.0 if s.startswith("-") else 1.0
    s = s.lstrip("+-")
    if len(s) != 1 or s not in letters:
        _fail(where, key, f"must be an axis like +{letters[0]} or -{letters[-1]}, got {v!r}")
    return letters.index(s), sign


def marker_map_from_dict(d: Any, source: str = "") -> MarkerMap:
    """A :class:`MarkerMap` from the parsed YAML (``source`` names it in messages)."""
    where = f"{source}: " if source else ""
    if not isinstance(d, dict):
        raise MarkerMapError(f"{where}must be a mapping with keys {', '.join(_TOP_KEYS)}")
    _unknown(where, "marker map", d, _TOP_KEYS)
    for k in ("units", "clusters", "accelerometers"):
        if k not in d:
            _fail(where, k, "missing (see ehm_drake/data/marker_map_example.yaml)")
    units = d["units"]
    if units not in UNIT_SCALE_M:
        _fail(where, "units", f"must be one of {', '.join(UNIT_SCALE_M)}, got {units!r}")
    axes = d.get("seat_axes", {"x": "+X", "y": "+Y", "z": "+Z"})
    if not isinstance(axes, dict) or sorted(axes) != ["x", "y", "z"]:
        _fail(where, "seat_axes", f"must give x, y and z as lab axes, got {axes!r}")
    R_LS = np.zeros((3, 3))
    for j, a in enumerate("xyz"):
        i, sign = _axis(where, f"seat_axes.{a}", axes[a], "XYZ")
        R_LS[i, j] = sign
    if abs(np.linalg.det(R_LS) - 1.0) > 1e-9:
        _fail(where, "seat_axes", f"{axes} is not a right-handed frame (x forward, y left, "
              "z up: z = x cross y)")
    clusters = d["clusters"]
    if not isinstance(clusters, dict):
        _fail(where, "clusters", "must map cluster names to {markers: [...]}")
    bad = [c for c in clusters if c != "seat" and c not in SEGMENTS]
    if bad:
        _fail(where, "clusters", f"unknown cluster(s) {bad}; allowed: seat, "
              f"{', '.join(SEGMENTS)}")
    if "seat" not in clusters:
        _fail(where, "clusters", "needs the 'seat' cluster (motion is taken relative to it)")
    if not any(s in clusters for s in SEGMENTS):
        _fail(where, "clusters", f"needs at least one segment of {', '.join(SEGMENTS)}")
    parsed = {name: _cluster(where, name, clusters[name])
              for name in ("seat", *SEGMENTS) if name in clusters}
    owner: dict[str, str] = {}
    for c in parsed.values():
        for m in c.markers:
            if m in owner:
                _fail(where, f"clusters.{c.name}.markers", f"marker {m!r} is also in "
                      f"cluster {owner[m]!r}")
            owner[m] = c.name
    accs = d["accelerometers"]
    if not isinstance(accs, list) or not accs:
        _fail(where, "accelerometers", "must list at least one seat accelerometer")
    acc_out = []
    for k, a in enumerate(accs):
        key = f"accelerometers[{k}]"
        if not isinstance(a, dict):
            _fail(where, key, f"must be a mapping with {', '.join(_ACC_KEYS)}, got {a!r}")
        _unknown(where, key, a, _ACC_KEYS)
        missing = [x for x in _ACC_KEYS if x not in a]
        if missing:
            _fail(where, key, f"missing {missing}")
        if not isinstance(a["channel"], str) or not a["channel"].strip():
            _fail(where, f"{key}.channel", f"must be the analog channel's label, got "
                  f"{a['channel']!r}")
        i, sign = _axis(where, f"{key}.axis", a["axis"], "xyz")
        if not isinstance(a["unit"], str) or not a["unit"].strip():
            _fail(where, f"{key}.unit", f"must be the channel's unit (ANALOG:UNITS, e.g. V), "
                  f"got {a['unit']!r}")
        sens = _number(where, f"{key}.sensitivity", a["sensitivity"], 0.0, 1e6,
                       f"{a['unit']} per m/s^2")
        acc_out.append(Accelerometer(a["channel"].strip(), "xyz"[i], sign, a["unit"].strip(),
                                     sens))
    axes_used = [a.axis for a in acc_out]
    if len(set(axes_used)) != len(axes_used):
        _fail(where, "accelerometers", f"two accelerometers on one seat axis ({axes_used})")
    return MarkerMap(
        units=units, R_LS=R_LS, seat=parsed["seat"],
        segments={n: c for n, c in parsed.items() if n != "seat"},
        accelerometers=tuple(acc_out),
        max_gap_s=_number(where, "max_gap_s", d.get("max_gap_s", 0.05), 0.0, 1.0, "s"),
        max_residual_m=_number(where, "max_residual_m", d.get("max_residual_m", 0.003), 0.0,
                               0.05, "m"),
        source=source)


def load_marker_map(path: str | Path) -> MarkerMap:
    """Read and check a marker map YAML file (see the module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"marker map not found: {path}")
    try:
        d = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f"line {mark.line + 1}: " if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise MarkerMapError(f"{path}: {line}not valid YAML ({problem})") from None
    return marker_map_from_dict(d, str(path))
