"""Batch runs: parameter grids, anthropometry, seat sweeps, Monte Carlo populations.

``ehm-drake sweep SPEC --out DIR`` (or :func:`run_sweep` from Python) runs many
settle + vibrate simulations (:func:`ehm_drake.simulation.simulate`) described by
one spec file, in parallel, and keeps a compact result per run.

Spec file (YAML or JSON)
------------------------
::

    name: seat-stiffness            # optional label
    # common settings of every run (defaults shown)
    direction: z                    # x, y, z or xyz
    rms: 0.1941                     # seat acceleration RMS per axis, m/s^2
    duration: 60.0                  # vibration time after settling, s (onset included)
    seed: 0                         # excitation seed
    variant: default                # default, no-integrator, high-stiffness
    excitation: random              # random, multisine, sweep, sine
    frequency_hz: 4.0               # for excitation: sine
    params_file: my_params.yaml     # optional, relative to the spec file
    params:                         # optional overrides (nested, as the parameter file)
      simulation: {settle_time_s: 3.0}
    body: [small, median, {mass_kg: 60, stature_m: 1.62}]   # presets or measures
    grid:                           # full factorial over dotted paths
      contact.pelvis_pan.stiffness: [30000, 45000, 60000]
      rms: [0.2, 0.5]               # common settings may be swept too
      body.mass_kg: [60, 80]        # and body measures
    seat:                           # seat configurations: a grid of contact./restraints.
      - {name: soft, contact.thighs_pan.stiffness: 20000, restraints.pelvis_pan.stiffness: 4000}
      - {name: hard, contact.thighs_pan.stiffness: 90000}
    monte_carlo:                    # population: n samples around every grid point
      n: 20
      seed: 1
      vary:
        contact.pelvis_pan.stiffness: {dist: normal, rel_sd: 0.1}
        body.mass_kg: {dist: lognormal, rel_sd: 0.15}
        pid.neck.kp: {dist: uniform, rel_range: 0.2}
    analysis:
      peak_band_hz: [0.5, 12.0]     # band searched for transmissibility peaks
      frf: true                     # keep each run's frf.csv

Runs are the product bodies x grid x seat (x Monte Carlo samples), in that order.
Monte Carlo sample ``i`` draws from ``numpy.random.default_rng([seed, i])``, one draw per
varied path in sorted path order, so the same seed gives the same runs and raising ``n``
keeps the earlier samples.  Distributions: ``normal`` (``rel_sd``: v (1 + rel_sd z), or
``sd``: v + sd z), ``lognormal`` (``rel_sd``: mean v, coefficient of variation rel_sd;
always positive), ``uniform`` (``rel_range``: v (1 + U(-r, r)), or ``low``/``high``).
A vector parameter (e.g. ``pid.neck.kd``) gets one draw for all its components.  A sample
outside the admissible range (negative stiffness, a body beyond the scaling) is a failed
run, recorded like any other.

Output folder
-------------
* ``runs/<run_id>.json``: one per finished run, written atomically as it completes: its
  full inputs (complete parameter set, body, settings), the swept values, status, results
  (transmissibility peaks, ISO 2631-1 comfort of seat and head, settled posture, wall
  times) or, for a failed run, the error type and message.  ``runs/<run_id>.frf.csv``:
  the run's transmissibility table (``analysis.frf``).
* ``summary.csv`` (one row per run: id, status, swept values, key results) and
  ``summary.json``; ``sweep_spec.json``: the normalized spec.

``run_id`` is a hash of the run's inputs, so re-running the same spec into the same
folder skips the finished runs (failed runs too: they are deterministic; pass
``retry_failed``), and recomputes only what is missing.  A run whose worker crashed
(an executor error, not a model error) is retried automatically.

Execution goes through a :class:`concurrent.futures.Executor`: a local process pool by
default (``max_workers``), a Dask distributed cluster given its scheduler address, or
any executor passed in.  Workers build their own models from plain dicts (Drake diagrams
are not picklable).  Ctrl-C stops submitting, waits for the running runs and keeps them;
a second Ctrl-C abandons the running runs.  Everything finished is kept and the summary
is written; re-running the command resumes.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import copy
import csv
import functools
import hashlib
import io
import itertools
import json
import math
import os
import re
import socket
import sys
import tempfile
import time
import traceback
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .parallel import process_pool

#: Version of the run record format (part of every run id).
RUN_FORMAT = 1

#: Common settings of a run and their defaults (the CLI's `simulate` defaults).
SETTING_DEFAULTS: dict[str, Any] = {
    "direction": "z",
    "rms": 0.1941,  # paper level, m/s^2 (ehm_drake.signals.PAPER_RMS)
    "duration": 60.0,
    "seed": 0,
    "variant": "default",
    "excitation": "random",
    "frequency_hz": 4.0,
}
DIRECTIONS = ("x", "y", "z", "xyz")
#: Excitation kinds a sweep can generate (a measured csv file is not portable to
#: remote workers and is not offered).
EXCITATIONS = ("random", "multisine", "sweep", "sine")

#: Named bodies.  The model's segment proportions are the de Leva male ones scaled
#: to mass and stature (ehm_drake.model.anthropometry), so "small" is female-like
#: in size only.
#:
#: * ``median``: the paper's 50th-percentile male (Desai et al.), 75.3 kg, 1.76 m,
#:   sitting height 0.92 m -- exactly the reference body of the package.
#: * ``small``: 55 kg, 1.55 m, about a 5th-percentile adult female in stature
#:   (the Hybrid III 5th-percentile female dummy is 1.51 m, 49 kg; adult
#:   survey tables put the 5th-percentile female stature at 1.50-1.55 m); the mass
#:   is a little above the dummy's so that the BMI (22.9) stays typical.
#: * ``large``: 98 kg, 1.87 m, about a 95th-percentile adult male (Hybrid III
#:   95th-percentile male dummy: 1.88 m, 101 kg).
#:
#: The sitting heights of ``small`` and ``large`` scale with stature.
BODY_PRESETS: dict[str, dict[str, float | None]] = {
    "small": {"mass_kg": 55.0, "stature_m": 1.55, "sitting_height_m": None},
    "median": {"mass_kg": 75.3, "stature_m": 1.76, "sitting_height_m": 0.92},
    "large": {"mass_kg": 98.0, "stature_m": 1.87, "sitting_height_m": None},
}
BODY_KEYS = ("mass_kg", "stature_m", "sitting_height_m")
SPEC_KEYS = (
    "name", *SETTING_DEFAULTS, "params_file", "params", "body", "grid", "seat",
    "monte_carlo", "analysis",
)
ANALYSIS_DEFAULTS: dict[str, Any] = {"peak_band_hz": [0.5, 12.0], "frf": True}
DISTRIBUTIONS = {
    "normal": (("rel_sd",), ("sd",)),
    "lognormal": (("rel_sd",),),
    "uniform": (("rel_range",), ("low", "high")),
}
#: Transmissibility channels summarized per excited axis d: the translation along d
#: and the rotation the excitation drives (pitch for x and z, roll for y).
PEAK_SEGMENTS = ("pelvis", "trunk", "head")
STATUS_DONE, STATUS_FAILED, STATUS_PENDING = "done", "failed", "pending"


class SweepSpecError(ValueError):
    """The sweep spec is invalid; the message names the key."""


# ---------------------------------------------------------------------------
# Spec
# ---------------------------------------------------------------------------


class _Loader(yaml.SafeLoader):
    """YAML loader that also reads ``3e4`` as a number (YAML 1.1 needs ``3.0e+4``)."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


@dataclass
class MonteCarlo:
    """Monte Carlo population: `n` samples, seeded, of the `vary` paths."""

    n: int
    seed: int
    vary: dict[str, dict[str, Any]]


@dataclass
class SweepSpec:
    """A validated sweep spec (see the module doc for the file format)."""

    name: str = "sweep"
    settings: dict[str, Any] = field(default_factory=lambda: dict(SETTING_DEFAULTS))
    #: Parameter overrides over the packaged defaults (params_file, then params).
    params: dict[str, Any] = field(default_factory=dict)
    #: (label, measures) of each body.
    bodies: list[tuple[str, dict[str, Any]]] = field(
        default_factory=lambda: [("median", dict(BODY_PRESETS["median"]))])
    #: True when the spec named bodies (the body label is then a swept value).
    body_swept: bool = False
    grid: dict[str, list[Any]] = field(default_factory=dict)
    #: Seat configurations: (label, {path: value}); empty: the parameters' seat.
    seats: list[tuple[str, dict[str, Any]]] = field(default_factory=list)
    monte_carlo: MonteCarlo | None = None
    analysis: dict[str, Any] = field(default_factory=lambda: copy.deepcopy(ANALYSIS_DEFAULTS))
    source: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The normalized spec as plain data (it loads back with load_sweep_spec)."""
        out: dict[str, Any] = {"name": self.name, **self.settings}
        if self.params:
            out["params"] = copy.deepcopy(self.params)
        if self.body_swept:
            out["body"] = [{"name": label, **b} for label, b in self.bodies]
        if self.grid:
            out["grid"] = copy.deepcopy(self.grid)
        if self.seats:
            out["seat"] = [{"name": label, **values} for label, values in self.seats]
        if self.monte_carlo is not None:
            mc = self.monte_carlo
            out["monte_carlo"] = {"n": mc.n, "seed": mc.seed, "vary": copy.deepcopy(mc.vary)}
        out["analysis"] = copy.deepcopy(self.analysis)
        return out


@functools.lru_cache(maxsize=1)
def _default_params_json() -> str:
    from .params import load_params

    return json.dumps(load_params().to_dict())


def default_params_dict() -> dict[str, Any]:
    """The packaged default parameters as a nested dict (a fresh copy)."""
    return json.loads(_default_params_json())


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _canonical(v: Any) -> Any:
    """Plain JSON data with every number a float (30000 and 30000.0 hash alike)."""
    if isinstance(v, Mapping):
        return {str(k): _canonical(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_canonical(x) for x in v]
    if isinstance(v, (bool, str)) or v is None:
        return v
    if isinstance(v, (int, float, np.integer, np.floating)):
        return float(v)
    raise TypeError(f"not plain data: {v!r}")


def _deep_merge(base: dict, over: Mapping, where: str) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        key = f"{where}.{k}" if where else str(k)
        if k not in out:
            known = ", ".join(out)
            raise SweepSpecError(f"unknown parameter key: {key} (known here: {known})")
        if isinstance(out[k], dict):
            if not isinstance(v, Mapping):
                raise SweepSpecError(f"{key}: expected a mapping, got {v!r}")
            out[k] = _deep_merge(out[k], v, key)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _param_leaf(path: str, where: str) -> list[str]:
    """Check that `path` names a parameter value (not a group); return its parts."""
    parts = path.split(".")
    node: Any = default_params_dict()
    for i, p in enumerate(parts):
        if not isinstance(node, dict) or p not in node:
            here = ".".join(parts[:i]) or "the top level"
            known = ", ".join(node) if isinstance(node, dict) else "none (a value)"
            raise SweepSpecError(
                f"{where}: {path!r} is not a parameter path (no {p!r} under {here}; known "
                f"there: {known}); use dotted keys of the parameter file, a common "
                f"setting ({', '.join(SETTING_DEFAULTS)}) or body.<{'|'.join(BODY_KEYS)}>")
        node = node[p]
    if isinstance(node, dict):
        raise SweepSpecError(f"{where}: {path!r} is a parameter group; name one of its values "
                             f"({', '.join(path + '.' + k for k in node)})")
    return parts


def _set_path(d: dict, parts: list[str], value: Any) -> None:
    for p in parts[:-1]:
        d = d[p]
    d[parts[-1]] = copy.deepcopy(value)


def _get_path(d: dict, parts: list[str]) -> Any:
    for p in parts:
        d = d[p]
    return d


def _key_kind(key: Any, where: str) -> str:
    """'setting', 'body' or 'param' for a swept key."""
    if not isinstance(key, str) or not key:
        raise SweepSpecError(f"{where}: keys must be non-empty strings, got {key!r}")
    if key in SETTING_DEFAULTS:
        return "setting"
    if key.startswith("body."):
        if key[5:] not in BODY_KEYS:
            raise SweepSpecError(f"{where}: unknown body measure {key!r}; expected "
                                 f"{', '.join('body.' + k for k in BODY_KEYS)}")
        return "body"
    _param_leaf(key, where)
    return "param"


def _check_setting(name: str, value: Any, where: str) -> Any:
    if name == "direction":
        if value not in DIRECTIONS:
            raise SweepSpecError(f"{where}: direction must be one of {', '.join(DIRECTIONS)}, "
                                 f"got {value!r}")
    elif name == "excitation":
        if value not in EXCITATIONS:
            extra = " (a measured csv cannot be swept)" if value == "csv" else ""
            raise SweepSpecError(f"{where}: excitation must be one of {', '.join(EXCITATIONS)}"
                                 f", got {value!r}{extra}")
    elif name == "variant":
        from .params import VARIANTS

        if value not in VARIANTS:
            raise SweepSpecError(f"{where}: variant must be one of {', '.join(VARIANTS)}, "
                                 f"got {value!r}")
    elif name == "seed":
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise SweepSpecError(f"{where}: seed must be an integer >= 0, got {value!r}")
    else:  # rms, duration, frequency_hz
        if not _is_number(value) or value <= 0:
            raise SweepSpecError(f"{where}: {name} must be a positive finite number, "
                                 f"got {value!r}")
        if name == "rms" and value > 20.0:
            raise SweepSpecError(f"{where}: rms {value} m/s^2 is beyond whole-body vibration "
                                 "levels (< 20 m/s^2); is it in mm/s^2 or in g?")
        value = float(value)
    return value


def _check_body(b: Any, where: str) -> tuple[str | None, dict[str, Any]]:
    from .model.anthropometry import BodyMeasures

    if isinstance(b, str):
        if b not in BODY_PRESETS:
            raise SweepSpecError(f"{where}: unknown body preset {b!r}; expected one of "
                                 f"{', '.join(BODY_PRESETS)} or a mapping of "
                                 f"{', '.join(BODY_KEYS)}")
        return b, dict(BODY_PRESETS[b])
    if not isinstance(b, Mapping):
        raise SweepSpecError(f"{where}: expected a preset name or a mapping of "
                             f"{', '.join(BODY_KEYS)}, got {b!r}")
    label = b.get("name")
    unknown = sorted(set(b) - set(BODY_KEYS) - {"name"})
    if unknown:
        raise SweepSpecError(f"{where}: unknown key(s) {', '.join(unknown)}; expected "
                             f"{', '.join(BODY_KEYS)} (and an optional name)")
    missing = [k for k in ("mass_kg", "stature_m") if k not in b]
    if missing:
        raise SweepSpecError(f"{where}: missing {', '.join(missing)}")
    m = {k: b.get(k) for k in BODY_KEYS}
    for k in BODY_KEYS:
        if m[k] is None and k == "sitting_height_m":
            continue
        if not _is_number(m[k]):
            raise SweepSpecError(f"{where}.{k}: expected a number, got {m[k]!r}")
        m[k] = float(m[k])
    try:
        BodyMeasures(**m).validate()
    except ValueError as e:
        raise SweepSpecError(f"{where}: {e}") from None
    if label is not None and not isinstance(label, str):
        raise SweepSpecError(f"{where}.name: expected a string, got {label!r}")
    return label, m


def _check_param_value(base: dict, parts: list[str], value: Any, where: str) -> None:
    """Validate `value` at `parts` over the base parameters (names `where`)."""
    from .params import ParameterError, params_from_dict

    trial = copy.deepcopy(base)
    _set_path(trial, parts, value)
    try:
        params_from_dict(trial)
    except ParameterError as e:
        raise SweepSpecError(f"{where} = {value!r}: {e}") from None


def _check_values(key: str, values: Any, where: str, base: dict) -> list[Any]:
    kind = _key_kind(key, where)
    if not isinstance(values, list) or not values:
        raise SweepSpecError(f"{where}[{key!r}]: expected a non-empty list of values, "
                             f"got {values!r}")
    seen = set()
    out = []
    for i, v in enumerate(values):
        w = f"{where}[{key!r}][{i}]"
        if kind == "setting":
            v = _check_setting(key, v, w)
        elif kind == "body":
            if not _is_number(v) or v <= 0:
                raise SweepSpecError(f"{w}: expected a positive number, got {v!r}")
            v = float(v)
        else:
            _check_param_value(base, key.split("."), v, w)
        tag = json.dumps(_canonical(v), sort_keys=True)
        if tag in seen:
            raise SweepSpecError(f"{w}: duplicate value {v!r}")
        seen.add(tag)
        out.append(v)
    return out


def _check_seats(seat: Any, base: dict) -> list[tuple[str, dict[str, Any]]]:
    def seat_key(key: Any, where: str) -> None:
        if not (isinstance(key, str) and key.split(".")[0] in ("contact", "restraints")):
            raise SweepSpecError(f"{where}: seat keys are contact.* or restraints.* "
                                 f"parameter paths, got {key!r}")
        _param_leaf(key, where)

    if isinstance(seat, Mapping):  # a grid
        for key in seat:
            seat_key(key, "seat")
        keys = list(seat)
        lists = [_check_values(k, seat[k], "seat", base) for k in keys]
        out = []
        for combo in itertools.product(*lists):
            values = dict(zip(keys, combo, strict=True))
            label = ",".join(f"{k}={json.dumps(_canonical(v))}" for k, v in values.items())
            out.append((label, values))
        return out
    if not isinstance(seat, list) or not seat:
        raise SweepSpecError("seat: expected a mapping {path: [values]} or a non-empty list of "
                             "seat configurations {name: ..., path: value, ...}")
    out = []
    labels = set()
    for i, item in enumerate(seat):
        where = f"seat[{i}]"
        if not isinstance(item, Mapping):
            raise SweepSpecError(f"{where}: expected a mapping of contact.*/restraints.* "
                                 f"paths to values, got {item!r}")
        label = item.get("name", where)
        if not isinstance(label, str):
            raise SweepSpecError(f"{where}.name: expected a string, got {label!r}")
        if label in labels:
            raise SweepSpecError(f"{where}.name: duplicate seat name {label!r}")
        labels.add(label)
        values = {k: v for k, v in item.items() if k != "name"}
        trial = copy.deepcopy(base)
        for k, v in values.items():
            seat_key(k, f"{where}.{k}")
            _set_path(trial, k.split("."), v)
        try:
            from .params import ParameterError, params_from_dict

            params_from_dict(trial)
        except ParameterError as e:
            raise SweepSpecError(f"{where}: {e}") from None
        out.append((label, values))
    return out


def _check_monte_carlo(mc: Any, base: dict) -> MonteCarlo:
    if not isinstance(mc, Mapping):
        raise SweepSpecError(f"monte_carlo: expected a mapping with n, seed, vary, got {mc!r}")
    unknown = sorted(set(mc) - {"n", "seed", "vary"})
    if unknown:
        raise SweepSpecError(f"monte_carlo: unknown key(s) {', '.join(unknown)} "
                             "(expected n, seed, vary)")
    n = mc.get("n")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise SweepSpecError(f"monte_carlo.n: expected an integer >= 1, got {n!r}")
    if "seed" not in mc:
        raise SweepSpecError("monte_carlo.seed: missing (every random choice takes a seed)")
    seed = mc["seed"]
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SweepSpecError(f"monte_carlo.seed: expected an integer >= 0, got {seed!r}")
    vary = mc.get("vary")
    if not isinstance(vary, Mapping) or not vary:
        raise SweepSpecError("monte_carlo.vary: expected a non-empty mapping "
                             "{path: {dist: normal, rel_sd: 0.1}}")
    out = {}
    for path, d in vary.items():
        where = f"monte_carlo.vary[{path!r}]"
        kind = _key_kind(path, where)
        if kind == "setting" and path not in ("rms", "frequency_hz", "duration"):
            raise SweepSpecError(f"{where}: only numeric settings (rms, frequency_hz, "
                                 "duration) can vary")
        if kind == "param":
            leaf = _get_path(base, path.split("."))
            numeric = _is_number(leaf) or (isinstance(leaf, list) and leaf
                                           and all(_is_number(x) for x in leaf))
            if not numeric:
                raise SweepSpecError(f"{where}: {path} is not numeric ({leaf!r})")
        if not isinstance(d, Mapping) or "dist" not in d:
            raise SweepSpecError(f"{where}: expected {{dist: normal|lognormal|uniform, ...}}, "
                                 f"got {d!r}")
        dist = d["dist"]
        if dist not in DISTRIBUTIONS:
            raise SweepSpecError(f"{where}.dist: expected one of {', '.join(DISTRIBUTIONS)}, "
                                 f"got {dist!r}")
        args = {k: v for k, v in d.items() if k != "dist"}
        forms = DISTRIBUTIONS[dist]
        if not any(set(args) == set(f) for f in forms):
            expected = " or ".join("+".join(f) for f in forms)
            raise SweepSpecError(f"{where}: dist {dist} takes {expected}, got "
                                 f"{', '.join(args) or 'nothing'}")
        for k, v in args.items():
            if not _is_number(v):
                raise SweepSpecError(f"{where}.{k}: expected a number, got {v!r}")
            if k in ("rel_sd", "sd", "rel_range") and v < 0:
                raise SweepSpecError(f"{where}.{k}: must not be negative, got {v}")
        if dist == "lognormal" and args["rel_sd"] <= 0:
            raise SweepSpecError(f"{where}.rel_sd: must be positive for lognormal")
        if dist == "uniform" and "low" in args and not args["low"] < args["high"]:
            raise SweepSpecError(f"{where}: low ({args['low']}) must be below high "
                                 f"({args['high']})")
        if dist == "uniform" and "rel_range" in args and args["rel_range"] >= 1:
            raise SweepSpecError(f"{where}.rel_range: must be below 1 (a sign change), "
                                 f"got {args['rel_range']}")
        out[path] = {"dist": dist, **{k: float(v) for k, v in args.items()}}
    return MonteCarlo(n, seed, out)


def _check_analysis(a: Any) -> dict[str, Any]:
    out = copy.deepcopy(ANALYSIS_DEFAULTS)
    if a is None:
        return out
    if not isinstance(a, Mapping):
        raise SweepSpecError(f"analysis: expected a mapping, got {a!r}")
    unknown = sorted(set(a) - set(ANALYSIS_DEFAULTS))
    if unknown:
        raise SweepSpecError(f"analysis: unknown key(s) {', '.join(unknown)} "
                             f"(known: {', '.join(ANALYSIS_DEFAULTS)})")
    if "peak_band_hz" in a:
        b = a["peak_band_hz"]
        if not (isinstance(b, list) and len(b) == 2 and all(_is_number(x) for x in b)
                and 0 <= b[0] < b[1]):
            raise SweepSpecError(f"analysis.peak_band_hz: expected [low, high] Hz with "
                                 f"0 <= low < high, got {b!r}")
        out["peak_band_hz"] = [float(b[0]), float(b[1])]
    if "frf" in a:
        if not isinstance(a["frf"], bool):
            raise SweepSpecError(f"analysis.frf: expected true/false, got {a['frf']!r}")
        out["frf"] = a["frf"]
    return out


def _read_spec_file(path: Path) -> dict:
    if not path.is_file():
        raise SweepSpecError(f"sweep spec not found: {path}")
    text = path.read_text()
    try:
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.load(text, _Loader)
    except (json.JSONDecodeError, yaml.YAMLError) as e:
        kind = "JSON" if path.suffix.lower() == ".json" else "YAML"
        raise SweepSpecError(f"{path}: not valid {kind}: {e}") from None
    if not isinstance(data, dict):
        raise SweepSpecError(f"{path}: expected a mapping of sweep settings at top level")
    return data


def load_sweep_spec(spec: str | Path | Mapping[str, Any] | SweepSpec,
                    base_dir: str | Path | None = None) -> SweepSpec:
    """Read and validate a sweep spec.

    Parameters
    ----------
    spec : path of a YAML/JSON file, a mapping with the same content, or a SweepSpec
        (returned as is).
    base_dir : folder against which a relative ``params_file`` is resolved (default: the
        spec file's folder, or the current folder for a mapping).

    Raises
    ------
    SweepSpecError
        Naming the offending key (prefixed with the file name for a file).
    """
    if isinstance(spec, SweepSpec):
        return spec
    source = None
    if isinstance(spec, (str, Path)):
        path = Path(spec)
        data = _read_spec_file(path)
        source = str(path)
        base_dir = path.parent if base_dir is None else Path(base_dir)
        try:
            return _build_spec(data, base_dir, source)
        except SweepSpecError as e:
            raise SweepSpecError(f"{path}: {e}") from None
    if not isinstance(spec, Mapping):
        raise SweepSpecError(f"sweep spec must be a file path or a mapping, got "
                             f"{type(spec).__name__}")
    return _build_spec(dict(spec), Path(base_dir) if base_dir else Path.cwd(), source)


def _build_spec(data: dict, base_dir: Path, source: str | None) -> SweepSpec:
    from .params import ParameterError, _read_mapping

    unknown = [k for k in data if k not in SPEC_KEYS]
    if unknown:
        raise SweepSpecError(f"unknown key(s): {', '.join(map(str, unknown))} "
                             f"(known: {', '.join(SPEC_KEYS)})")
    name = data.get("name", "sweep")
    if not isinstance(name, str) or not name:
        raise SweepSpecError(f"name: expected a non-empty string, got {name!r}")
    settings = {k: _check_setting(k, data.get(k, v), k) for k, v in SETTING_DEFAULTS.items()}
    overrides: dict[str, Any] = {}
    base = default_params_dict()
    if data.get("params_file") is not None:
        if not isinstance(data["params_file"], str):
            raise SweepSpecError(f"params_file: expected a file name, got "
                                 f"{data['params_file']!r}")
        pf = Path(data["params_file"])
        pf = pf if pf.is_absolute() else base_dir / pf
        try:
            file_params = _read_mapping(pf)
            base = _deep_merge(base, file_params, "")
        except (ParameterError, SweepSpecError) as e:
            raise SweepSpecError(f"params_file: {e}") from None
        overrides = copy.deepcopy(file_params)
    if data.get("params") is not None:
        if not isinstance(data["params"], Mapping):
            raise SweepSpecError(f"params: expected a mapping, got {data['params']!r}")
        base = _deep_merge(base, data["params"], "params")
        overrides = _merge_overrides(overrides, data["params"])
    try:
        from .params import params_from_dict

        params_from_dict(base)
    except ParameterError as e:
        raise SweepSpecError(f"params: {e}") from None

    body = data.get("body")
    body_swept = body is not None
    if body is None:
        bodies = [("median", dict(BODY_PRESETS["median"]))]
    else:
        items = body if isinstance(body, list) else [body]
        if not items:
            raise SweepSpecError("body: expected a preset name, a mapping or a non-empty list")
        bodies = []
        labels = set()
        for i, b in enumerate(items):
            where = f"body[{i}]" if isinstance(body, list) else "body"
            label, m = _check_body(b, where)
            label = label or where
            if label in labels:
                raise SweepSpecError(f"{where}: duplicate body {label!r}")
            labels.add(label)
            bodies.append((label, m))

    grid = data.get("grid") or {}
    if not isinstance(grid, Mapping):
        raise SweepSpecError(f"grid: expected a mapping {{path: [values]}}, got {grid!r}")
    grid = {k: _check_values(k, v, "grid", base) for k, v in grid.items()}
    seats = _check_seats(data["seat"], base) if data.get("seat") is not None else []
    overlap = sorted(set(grid) & {k for _, s in seats for k in s})
    if overlap:
        raise SweepSpecError(f"seat: {', '.join(overlap)} also swept in grid")
    mc = (_check_monte_carlo(data["monte_carlo"], base)
          if data.get("monte_carlo") is not None else None)
    analysis = _check_analysis(data.get("analysis"))
    return SweepSpec(name, settings, _canonical(overrides), bodies, body_swept, grid, seats,
                     mc, analysis, source)


def _merge_overrides(base: dict, over: Mapping) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), dict):
            out[k] = _merge_overrides(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


# ---------------------------------------------------------------------------
# Expansion
# ---------------------------------------------------------------------------


@dataclass
class RunSpec:
    """One run: plain inputs a worker can rebuild the model from."""

    run_id: str
    index: int
    #: The values this run was swept over: "body" (label), grid keys, "seat" (label),
    #: "mc_sample" (index) and "mc:<path>" (the sampled value).
    swept: dict[str, Any]
    #: The complete parameter set (packaged defaults merged with every override).
    params: dict[str, Any]
    body: dict[str, Any]
    settings: dict[str, Any]
    analysis: dict[str, Any]

    def inputs(self) -> dict[str, Any]:
        """What the run depends on (hashed into run_id)."""
        return {"format": RUN_FORMAT, "params": self.params, "body": self.body,
                "settings": self.settings, "analysis": self.analysis}


def run_id_of(inputs: Mapping[str, Any]) -> str:
    """Stable 16-hex-digit hash of a run's inputs."""
    blob = json.dumps(_canonical(inputs), sort_keys=True, separators=(",", ":"),
                      allow_nan=False)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def _draw(rng: np.random.Generator, value: Any, d: dict[str, Any]) -> Any:
    dist = d["dist"]
    if dist == "normal":
        z = rng.standard_normal()
        if "rel_sd" in d:
            return _apply(value, lambda v: v * (1.0 + d["rel_sd"] * z))
        return _apply(value, lambda v: v + d["sd"] * z)
    if dist == "lognormal":
        z = rng.standard_normal()
        s = math.sqrt(math.log1p(d["rel_sd"] ** 2))
        return _apply(value, lambda v: v * math.exp(s * z - 0.5 * s * s))
    u = rng.uniform(-1.0, 1.0)
    if "rel_range" in d:
        return _apply(value, lambda v: v * (1.0 + d["rel_range"] * u))
    x = d["low"] + 0.5 * (u + 1.0) * (d["high"] - d["low"])
    return _apply(value, lambda v: x)


def _apply(value: Any, fn) -> Any:
    if isinstance(value, list):
        return [float(fn(float(v))) for v in value]
    return float(fn(float(value)))


def expand_runs(spec: SweepSpec | Mapping[str, Any] | str | Path) -> list[RunSpec]:
    """The runs of a sweep: bodies x grid x seat configurations (x Monte Carlo samples).

    Every random draw is seeded (``monte_carlo.seed``), so the same spec gives the same
    runs.  Runs with identical inputs (e.g. a Monte Carlo with zero spread) share their
    run id and are computed once.
    """
    from .model.anthropometry import BodyMeasures

    spec = load_sweep_spec(spec)
    base = _deep_merge(default_params_dict(), spec.params, "params")
    grid_keys = list(spec.grid)
    grid_combos = list(itertools.product(*(spec.grid[k] for k in grid_keys)))
    seats: list[tuple[str | None, dict[str, Any]]] = list(spec.seats) or [(None, {})]
    mc = spec.monte_carlo
    samples: list[int | None] = list(range(mc.n)) if mc else [None]
    runs = []
    for (blabel, bvalues), combo, (slabel, svalues), sample in itertools.product(
            spec.bodies, grid_combos, seats, samples):
        params = copy.deepcopy(base)
        body = dict(bvalues)
        settings = dict(spec.settings)
        swept: dict[str, Any] = {}
        if spec.body_swept:
            swept["body"] = blabel
        for key, value in zip(grid_keys, combo, strict=True):
            swept[key] = value
            _assign(key, value, params, body, settings)
        if slabel is not None:
            swept["seat"] = slabel
        for key, value in svalues.items():
            _assign(key, value, params, body, settings)
        if sample is not None:
            assert mc is not None
            swept["mc_sample"] = sample
            rng = np.random.default_rng([mc.seed, sample])
            for key in sorted(mc.vary):
                current = _lookup(key, params, body, settings)
                value = _draw(rng, current, mc.vary[key])
                _assign(key, value, params, body, settings)
                swept[f"mc:{key}"] = value
        runs.append((swept, params, body, settings))
    out = []
    for i, (swept, params, body, settings) in enumerate(runs):
        params = _canonical(params)
        run = RunSpec("", i, swept, params, _canonical(body), settings,
                      copy.deepcopy(spec.analysis))
        run.run_id = run_id_of(run.inputs())
        out.append(run)
    # A body measure swept in the grid must still be a valid body (MC draws may fail
    # at run time and are recorded as failed runs instead).
    if mc is None:
        for run in out:
            try:
                BodyMeasures(**run.body).validate()
            except ValueError as e:
                raise SweepSpecError(f"run {run.index} ({_describe(run.swept)}): {e}") from None
    return out


def _describe(swept: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in swept.items()) or "base"


def _assign(key: str, value: Any, params: dict, body: dict, settings: dict) -> None:
    if key in SETTING_DEFAULTS:
        settings[key] = value
    elif key.startswith("body."):
        body[key[5:]] = value
    else:
        _set_path(params, key.split("."), value)


def _lookup(key: str, params: dict, body: dict, settings: dict) -> Any:
    if key in SETTING_DEFAULTS:
        return settings[key]
    if key.startswith("body."):
        name = key[5:]
        if name == "sitting_height_m" and body.get(name) is None:
            from .model.anthropometry import BodyMeasures

            return BodyMeasures(**body).resolved_sitting_height()
        return body[name]
    return _get_path(params, key.split("."))


# ---------------------------------------------------------------------------
# One run (executed in a worker; plain data in, plain data out)
# ---------------------------------------------------------------------------


def _second_difference(y: np.ndarray, fs: float) -> np.ndarray:
    """Acceleration from displacement samples (central second difference, ends held)."""
    a = np.zeros_like(y)
    a[1:-1] = (y[2:] - 2.0 * y[1:-1] + y[:-2]) * fs**2
    a[0], a[-1] = a[1], a[-2]
    return a


def _comfort_summary(m: dict[str, Any]) -> dict[str, Any]:
    return {k: m[k] for k in ("weighted_rms", "overall", "vdv", "overall_vdv", "msdv_z")}


def summarize_result(settled, result, signal, analysis: Mapping[str, Any] | None = None,
                     ) -> tuple[dict[str, Any], Any]:
    """The compact result of one run and its transmissibility table.

    Returns ``(summary, frf)``: summary holds ``transmissibility`` (per excited axis d
    and segment pelvis/trunk/head, the peak gain and frequency of the translation along d
    and of the pitch (x, z) or roll (y) within ``analysis['peak_band_hz']``; gains in m/m
    and deg/m), ``comfort`` (ISO 2631-1 comfort metrics of the seat acceleration and of
    the head acceleration, the second difference of the absolute head displacement;
    over the full-amplitude part, after the onset), ``posture`` (the settled posture
    summary) and ``vibrate_wall_s``.
    """
    from .analysis.comfort import comfort_metrics
    from .analysis.spectral import transmissibility

    analysis = dict(ANALYSIS_DEFAULTS, **(analysis or {}))
    vib = result.after(signal.settle_time)
    frf = transmissibility(vib.to_timeseries())
    lo, hi = analysis["peak_band_hz"]
    direction = signal.meta.get("direction", "")
    peaks: dict[str, Any] = {}
    for d in (a for a in "xyz" if a in direction):
        for seg in PEAK_SEGMENTS:
            for dof in (d, "roll" if d == "y" else "pitch"):
                f, gain, _, coh = frf.get(d, seg, dof)
                sel = np.flatnonzero((f >= lo) & (f <= hi))
                if not sel.size:
                    continue
                k = sel[int(np.argmax(gain[sel]))]
                peaks[f"{d}/{seg}/{dof}"] = {"peak_gain": float(gain[k]),
                                             "peak_freq_hz": float(f[k]),
                                             "coherence": float(coh[k])}
    fs = vib.sample_rate
    steady = vib.times >= signal.steady_start - 1e-9
    head = np.column_stack([vib.channel("head", a) for a in "xyz"])
    head_acc = _second_difference(head, fs)
    comfort = {
        "seat": _comfort_summary(comfort_metrics(vib.seat_acceleration[steady], fs, "seat")),
        "head": _comfort_summary(comfort_metrics(head_acc[steady], fs, "head")),
        "from_t_s": float(signal.steady_start),
        "note": "seat: Wd x, y, Wk z; head: second difference of the absolute head "
                "displacement, seat weightings, k = 1",
    }
    summary = {
        "transmissibility": peaks,
        "transmissibility_units": "m/m (x, y, z), deg/m (roll, pitch)",
        "comfort": comfort,
        "posture": settled.summary,
        "vibrate_wall_s": float(result.meta.get("wall_s", float("nan"))),
        "real_time_factor": float(result.meta.get("real_time_factor", float("nan"))),
    }
    return summary, frf


def execute_run(inputs: Mapping[str, Any]) -> dict[str, Any]:
    """Run one sweep run from its plain inputs (see RunSpec.inputs) and return its
    record: ``status`` "done" with ``results`` (and ``frf_csv`` text), or "failed" with
    ``error`` {type, message, source: "run"}.  Never raises for a model error."""
    t0 = time.perf_counter()
    record: dict[str, Any] = {"host": socket.gethostname(), "pid": os.getpid()}
    try:
        from .model.anthropometry import BodyMeasures
        from .params import params_from_dict
        from .signals import make_seat_signal
        from .simulation import simulate

        params = params_from_dict(dict(inputs["params"]))
        measures = BodyMeasures(**inputs["body"])
        measures.validate()
        s = inputs["settings"]
        sim = params.simulation
        signal = make_seat_signal(s["excitation"], s["direction"], s["rms"], s["duration"],
                                  int(s["seed"]), sim.time_step_s, sim.settle_time_s,
                                  sim.onset_time_s, frequency_hz=s["frequency_hz"])
        settled, result = simulate(params, measures, s["variant"], signal=signal)
        summary, frf = summarize_result(settled, result, signal, inputs.get("analysis"))
        if inputs.get("analysis", {}).get("frf", True):
            with tempfile.TemporaryDirectory() as tmp:
                record["frf_csv"] = frf.to_csv(Path(tmp) / "frf.csv").read_text()
        wall = time.perf_counter() - t0
        summary["wall_s"] = wall
        summary["settle_wall_s"] = wall - summary["vibrate_wall_s"]
        record.update(status=STATUS_DONE, results=summary)
    except Exception as e:  # noqa: BLE001 - every model error is recorded, not raised
        record.update(status=STATUS_FAILED, error={
            "type": type(e).__name__, "message": str(e), "source": "run",
            "traceback": traceback.format_exc(limit=-4)})
        record["results"] = {"wall_s": time.perf_counter() - t0}
    return record


# ---------------------------------------------------------------------------
# Storage
# ---------------------------------------------------------------------------


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("ehm_drake")
    except Exception:  # noqa: BLE001 - running from a source tree without metadata
        return "unknown"


def _load_record(path: Path) -> dict[str, Any] | None:
    try:
        rec = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    return rec if isinstance(rec, dict) and rec.get("status") in (
        STATUS_DONE, STATUS_FAILED) else None


def _reusable(rec: dict[str, Any] | None, retry_failed: bool) -> bool:
    if rec is None:
        return False
    if rec["status"] == STATUS_DONE:
        return True
    # A model error repeats (deterministic inputs); an executor error may not.
    return not retry_failed and rec.get("error", {}).get("source") == "run"


# ---------------------------------------------------------------------------
# Running
# ---------------------------------------------------------------------------


@dataclass
class SweepResult:
    """What a sweep did; `records` holds one run record per run, in spec order
    (status "pending" for runs not finished when interrupted)."""

    out_dir: Path
    runs: list[RunSpec]
    records: list[dict[str, Any]]
    computed: list[str]
    reused: list[str]
    interrupted: bool
    wall_s: float

    def count(self, status: str) -> int:
        return sum(r["status"] == status for r in self.records)

    @property
    def n_done(self) -> int:
        return self.count(STATUS_DONE)

    @property
    def n_failed(self) -> int:
        return self.count(STATUS_FAILED)

    @property
    def n_pending(self) -> int:
        return self.count(STATUS_PENDING)


class _Progress:
    def __init__(self, total: int, reused: int, enabled: bool):
        self.total, self.reused, self.enabled = total, reused, enabled
        self.t0 = time.perf_counter()
        self.done = self.failed = 0
        self._last: tuple[int, int] | None = None
        self._tty = sys.stderr.isatty()

    def show(self, note: str = "", final: bool = False) -> None:
        """One status line; on a terminal refreshed in place (the clock runs), in a
        log only when a run finished."""
        if not self.enabled:
            return
        state = (self.done, self.failed)
        if not (self._tty or state != self._last):
            return
        self._last = state
        finished = self.reused + self.done
        wall = time.perf_counter() - self.t0
        left = self.total - finished
        eta = f"eta {wall / self.done * left:5.0f} s" if self.done and left else "eta   --  "
        line = (f"sweep: {finished}/{self.total} runs ({self.reused} reused), "
                f"{self.failed} failed, {wall:5.0f} s, {eta} {note}")
        if self._tty:
            sys.stderr.write(f"\r{line}   " + ("\n" if final else ""))
        else:
            sys.stderr.write(line.rstrip() + "\n")
        sys.stderr.flush()

    def say(self, text: str) -> None:
        if self.enabled:
            sys.stderr.write(f"\n{text}\n")
            sys.stderr.flush()


def _workers_of(executor: cf.Executor, client: Any, max_workers: int | None) -> int:
    if client is not None:
        try:
            return max(1, sum(client.nthreads().values()))
        except Exception:  # noqa: BLE001 - scheduler busy: keep a modest queue
            return 2
    n = getattr(executor, "_max_workers", None)
    return int(n or max_workers or os.cpu_count() or 1)


def _kill_pool(executor: cf.Executor) -> None:
    """Stop a process pool's workers now (abandoning their runs)."""
    terminate = getattr(executor, "terminate_workers", None)  # Python >= 3.14
    if terminate is not None:
        terminate()
        return
    for p in list((getattr(executor, "_processes", None) or {}).values()):
        if p.is_alive():
            p.terminate()
    executor.shutdown(wait=False, cancel_futures=True)


def run_sweep(spec: SweepSpec | Mapping[str, Any] | str | Path, out_dir: str | Path,
              executor: cf.Executor | None = None, scheduler: str | None = None,
              max_workers: int | None = None, progress: bool = True, force: bool = False,
              retry_failed: bool = False) -> SweepResult:
    """Run a sweep into `out_dir`, resuming what an earlier run of it finished.

    Parameters
    ----------
    spec : a SweepSpec, a spec mapping or the path of a spec file.
    out_dir : output folder (created); see the module doc for its content.
    executor : a concurrent.futures.Executor to use (not shut down here).
    scheduler : address of a Dask distributed scheduler (``tcp://host:8786``); the runs
        go to its workers (they need ehm_drake installed; results come back to this
        process, which writes every file).
    max_workers : size of the local process pool (default: the number of CPUs).
    progress : show runs done/total, failures and ETA on stderr.
    force : recompute runs that are already stored.
    retry_failed : recompute runs stored as failed.

    Returns
    -------
    SweepResult
        ``interrupted`` is True after Ctrl-C (finished runs are kept; run again to
        resume).
    """
    spec = load_sweep_spec(spec)
    if executor is not None and scheduler is not None:
        raise ValueError("give either executor or scheduler, not both")
    if max_workers is not None and (isinstance(max_workers, bool)
                                    or not isinstance(max_workers, int) or max_workers < 1):
        raise ValueError(f"max_workers must be a positive integer, got {max_workers!r}")
    runs = expand_runs(spec)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"sweep output {out} exists and is not a folder")
    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    _atomic_write(out / "sweep_spec.json", json.dumps(spec.to_dict(), indent=2))

    t0 = time.perf_counter()
    records: dict[str, dict[str, Any]] = {}
    reused: list[str] = []
    todo: list[RunSpec] = []
    seen: set[str] = set()
    for run in runs:
        if run.run_id in seen:
            continue
        seen.add(run.run_id)
        rec = None if force else _load_record(runs_dir / f"{run.run_id}.json")
        if _reusable(rec, retry_failed):
            assert rec is not None
            records[run.run_id] = rec
            reused.append(run.run_id)
        else:
            todo.append(run)
    prog = _Progress(len(seen), len(reused), progress)
    prog.show()
    computed: list[str] = []
    interrupted = False

    def store(run: RunSpec, rec: dict[str, Any]) -> None:
        full = {"ehm_drake_sweep_run": RUN_FORMAT, "run_id": run.run_id,
                "status": rec.get("status", STATUS_FAILED), "index": run.index,
                "swept": _canonical(run.swept), "inputs": run.inputs(),
                "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                "ehm_drake_version": _version(),
                **{k: v for k, v in rec.items() if k not in ("status", "frf_csv")}}
        if rec.get("frf_csv"):
            _atomic_write(runs_dir / f"{run.run_id}.frf.csv", rec["frf_csv"])
            full["frf_file"] = f"{run.run_id}.frf.csv"
        _atomic_write(runs_dir / f"{run.run_id}.json",
                      json.dumps(full, indent=1, allow_nan=True))
        records[run.run_id] = full
        computed.append(run.run_id)
        prog.done += 1
        prog.failed += full["status"] == STATUS_FAILED

    own_pool = client = None
    if todo:
        if scheduler is not None:
            client = _dask_client(scheduler)
            executor = client.get_executor(pure=False)
        elif executor is None:
            own_pool = process_pool(min(max_workers or os.cpu_count() or 1, len(todo)))
            executor = own_pool
    try:
        interrupted = _drive(executor, client, todo, store, prog, max_workers, own_pool)
    finally:
        if own_pool is not None:
            own_pool.shutdown(wait=not interrupted, cancel_futures=True)
        if client is not None:
            client.close()
    prog.show(final=True)

    ordered = []
    for run in runs:
        rec = records.get(run.run_id)
        if rec is None:
            rec = {"run_id": run.run_id, "status": STATUS_PENDING}
        ordered.append(rec)
    result = SweepResult(out, runs, ordered, computed, reused, interrupted,
                         time.perf_counter() - t0)
    write_summary(result, spec)
    return result


def _dask_client(address: str):
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - dask is a test/extra dependency
        raise ValueError("--scheduler needs dask.distributed: pip install 'dask[distributed]'"
                         ) from None
    try:
        return Client(address, timeout="20s")
    except (OSError, TimeoutError) as e:
        raise ValueError(f"cannot connect to the Dask scheduler at {address}: {e}") from None


def _drive(executor, client, todo: list[RunSpec], store, prog: _Progress,
           max_workers: int | None, own_pool) -> bool:
    """Submit the runs (a bounded number in flight), store each as it completes.
    Returns True if interrupted by Ctrl-C."""
    queue = list(reversed(todo))
    running: dict[cf.Future, RunSpec] = {}
    interrupted = False

    def collect(done) -> None:
        for fut in done:
            run = running.pop(fut)
            if fut.cancelled():
                continue
            exc = fut.exception()
            if exc is None:
                store(run, fut.result())
            elif isinstance(exc, KeyboardInterrupt):
                continue  # interrupted, not finished: computed again on resume
            else:  # the executor failed (worker died, lost connection, ...)
                store(run, {"status": STATUS_FAILED, "error": {
                    "type": type(exc).__name__, "message": str(exc), "source": "executor"}})
            prog.show()

    try:
        while queue or running:
            # No more in flight than there are workers: nothing waits in the
            # executor's queue, so Ctrl-C leaves only the running runs to finish.
            limit = _workers_of(executor, client, max_workers)
            while queue and len(running) < limit:
                try:
                    fut = executor.submit(execute_run, queue[-1].inputs())
                except (cf.BrokenExecutor, RuntimeError) as e:  # pool died / shut down
                    sys.stderr.write(f"\nsweep: the executor cannot run more ({type(e).__name__}"
                                     f": {e}); {len(queue)} run(s) not started; run the "
                                     "sweep again to resume\n")
                    queue.clear()
                    break
                running[fut] = queue.pop()
            done, _ = cf.wait(list(running), timeout=1.0, return_when=cf.FIRST_COMPLETED)
            collect(done)
            prog.show()
    except KeyboardInterrupt:
        interrupted = True
        for fut in running:
            fut.cancel()
        active = [f for f in running if not f.cancelled()]
        prog.say(f"interrupted: no new runs; waiting for {len(active)} running run(s) to "
                 "finish (Ctrl-C again to abandon them)")
        try:
            collect([f for f in running if f.cancelled()])
            while running:
                done, _ = cf.wait(list(running), timeout=1.0, return_when=cf.FIRST_COMPLETED)
                collect(done)
        except KeyboardInterrupt:
            prog.say(f"abandoning {len(running)} running run(s)")
            if own_pool is not None:
                _kill_pool(own_pool)
    return interrupted


# ---------------------------------------------------------------------------
# Summary
# ---------------------------------------------------------------------------


def _flat_results(rec: dict[str, Any]) -> dict[str, Any]:
    """Key results of a run record as flat columns."""
    row: dict[str, Any] = {}
    res = rec.get("results") or {}
    comfort = res.get("comfort", {})
    for loc in ("seat", "head"):
        m = comfort.get(loc)
        if not m:
            continue
        row[f"{loc}_aw_overall"] = m["overall"]
        for a in "xyz":
            row[f"{loc}_aw_{a}"] = m["weighted_rms"][a]
        row[f"{loc}_vdv_overall"] = m["overall_vdv"]
        row[f"{loc}_msdv_z"] = m["msdv_z"]
    for key, p in res.get("transmissibility", {}).items():
        name = "T_" + key.replace("/", "_")
        row[f"{name}_peak_gain"] = p["peak_gain"]
        row[f"{name}_peak_hz"] = p["peak_freq_hz"]
    posture = res.get("posture", {})
    for k in ("head_pitch_drift_deg", "trunk_T8_forward_drift_m", "back_in_contact"):
        if k in posture:
            row[k] = posture[k]
    if "wall_s" in res:
        row["wall_s"] = res["wall_s"]
    err = rec.get("error")
    if err:
        row["error_type"] = err.get("type")
        row["error_message"] = err.get("message")
    return row


def _cell(v: Any) -> Any:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (list, dict)):
        return json.dumps(v)
    return v


def write_summary(result: SweepResult, spec: SweepSpec) -> tuple[Path, Path]:
    """DIR/summary.csv (one row per run) and DIR/summary.json."""
    rows = []
    swept_keys: list[str] = []
    result_keys: list[str] = []
    for run, rec in zip(result.runs, result.records, strict=True):
        for k in run.swept:
            if k not in swept_keys:
                swept_keys.append(k)
        flat = _flat_results(rec)
        for k in flat:
            if k not in result_keys:
                result_keys.append(k)
        rows.append({"run_id": run.run_id, "index": run.index, "status": rec["status"],
                     **run.swept, **flat})
    # Errors last, for readability.
    result_keys = ([k for k in result_keys if not k.startswith("error_")]
                   + [k for k in result_keys if k.startswith("error_")])
    columns = ["run_id", "index", "status", *swept_keys, *result_keys]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for row in rows:
        w.writerow([_cell(row.get(c, "")) for c in columns])
    out = result.out_dir
    _atomic_write(out / "summary.csv", buf.getvalue())
    counts = {"runs": len(result.runs), "unique_runs": len({r.run_id for r in result.runs}),
              "done": result.n_done, "failed": result.n_failed,
              "pending": result.n_pending, "computed": len(result.computed),
              "reused": len(result.reused)}
    summary = {
        "name": spec.name,
        "spec": spec.to_dict(),
        "counts": counts,
        "interrupted": result.interrupted,
        "wall_s": result.wall_s,
        "runs": [{"run_id": run.run_id, "index": run.index, "status": rec["status"],
                  "swept": _canonical(run.swept),
                  **({"results": rec["results"]} if rec.get("results") else {}),
                  **({"error": {k: rec["error"][k] for k in ("type", "message", "source")
                                if k in rec["error"]}} if rec.get("error") else {})}
                 for run, rec in zip(result.runs, result.records, strict=True)],
    }
    _atomic_write(out / "summary.json", json.dumps(summary, indent=1, allow_nan=True))
    return out / "summary.csv", out / "summary.json"


# ---------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--workers must be an integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"--workers must be >= 1, got {v}")
    return v


def add_sweep_arguments(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``sweep`` command to an argparse subparsers object (sets func=cmd_sweep)."""
    p = subparsers.add_parser(
        "sweep", help="batch runs over parameters, bodies, seats, Monte Carlo populations",
        description="Run the settle + vibrate simulations of a sweep spec (YAML/JSON) in "
        "parallel; each run is stored as it finishes, so re-running the same command "
        "resumes an interrupted sweep.")
    _sweep_options(p)
    p.set_defaults(func=cmd_sweep)
    return p


def _sweep_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("spec", metavar="SPEC", help="sweep spec file (YAML or JSON)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (resumed if it "
                   "holds an earlier run of the sweep)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask distributed scheduler, e.g. "
                   "tcp://host:8786 (default: a local process pool)")
    p.add_argument("--workers", type=_positive_int, metavar="N",
                   help="local worker processes (default: number of CPUs)")
    p.add_argument("--force", action="store_true",
                   help="recompute runs already stored in DIR")
    p.add_argument("--retry-failed", action="store_true",
                   help="recompute runs stored as failed")
    p.add_argument("--quiet", action="store_true", help="no progress display")


def cmd_sweep(args: argparse.Namespace) -> int:
    """Run ``ehm-drake sweep``.  Exit status: 0 all runs done, 3 some runs failed (they
    are recorded), 130 interrupted; a bad spec raises SweepSpecError (a ValueError)."""
    out = Path(args.out)
    if (out.is_dir() and any(out.iterdir()) and not (out / "sweep_spec.json").exists()
            and not args.force):
        raise ValueError(f"output folder {out} exists, is not empty and holds no sweep; use "
                         "--force to write into it")
    spec = load_sweep_spec(args.spec)
    if args.workers is not None and args.scheduler is not None:
        raise ValueError("--workers sizes the local pool; with --scheduler the cluster's "
                         "workers run the sweep")
    result = run_sweep(spec, out, scheduler=args.scheduler, max_workers=args.workers,
                       progress=not args.quiet, force=args.force,
                       retry_failed=args.retry_failed)
    print(f"sweep '{spec.name}': {len(result.runs)} runs, {result.n_done} done, "
          f"{result.n_failed} failed, {result.n_pending} not run; {len(result.computed)} "
          f"computed, {len(result.reused)} reused, {result.wall_s:.0f} s -> "
          f"{out / 'summary.csv'}")
    if result.interrupted:
        print("interrupted: run the same command again to resume", file=sys.stderr)
        return 130
    return 3 if result.n_failed else 0


def main(argv: list[str] | None = None) -> int:
    """``python -m ehm_drake.sweep SPEC --out DIR ...`` (same as ``ehm-drake sweep``)."""
    parser = argparse.ArgumentParser(prog="python -m ehm_drake.sweep",
                                     description=__doc__.split("\n\n")[0])
    _sweep_options(parser)
    args = parser.parse_args(argv)
    try:
        return cmd_sweep(args)
    except ValueError as e:
        print(f"sweep: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\nsweep: interrupted", file=sys.stderr)
        return 130


__all__ = [
    "BODY_PRESETS", "MonteCarlo", "RunSpec", "SweepResult", "SweepSpec", "SweepSpecError",
    "add_sweep_arguments", "cmd_sweep", "default_params_dict", "execute_run", "expand_runs",
    "load_sweep_spec", "run_id_of", "run_sweep", "summarize_result", "write_summary",
]


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
