"""Checks of a sweep spec that need more than its schema: parameter paths and
values (against the packaged parameter tree), swept values, seats, bodies,
the Monte Carlo distributions and the analysis section.

Every error is a :class:`SweepSpecError` whose message names the key and what
is allowed; load_sweep_spec prefixes the file name.
"""

from __future__ import annotations

import copy
import functools
import itertools
import json
from collections.abc import Mapping
from typing import Any

from .schema import (
    BODY_KEYS,
    BODY_PRESETS,
    DISTRIBUTIONS,
    SETTING_DEFAULTS,
    AnalysisFile,
    BodyEntry,
    Distribution,
    MonteCarloFile,
    SweepSpecError,
    canonical,
    check_fields,
    check_keys,
    check_setting,
    is_number,
)

# ---------------------------------------------------------------------------
# The parameter tree (plain nested dicts)
# ---------------------------------------------------------------------------


@functools.lru_cache(maxsize=1)
def _default_params_json() -> str:
    from ..params import load_params

    return json.dumps(load_params().to_dict())


def default_params_dict() -> dict[str, Any]:
    """The packaged default parameters as a nested dict (a fresh copy)."""
    return json.loads(_default_params_json())


def deep_merge(base: dict, over: Mapping, where: str) -> dict:
    """`over` merged into a copy of `base`; every key of `over` must exist in `base`."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        key = f"{where}.{k}" if where else str(k)
        if k not in out:
            known = ", ".join(out)
            raise SweepSpecError(f"unknown parameter key: {key} (known here: {known})")
        if isinstance(out[k], dict):
            if not isinstance(v, Mapping):
                raise SweepSpecError(f"{key}: expected a mapping, got {v!r}")
            out[k] = deep_merge(out[k], v, key)
        else:
            out[k] = copy.deepcopy(v)
    return out


def merge_overrides(base: dict, over: Mapping) -> dict:
    """Nested overrides `over` merged into a copy of the overrides `base`."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), dict):
            out[k] = merge_overrides(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def set_path(d: dict, parts: list[str], value: Any) -> None:
    for p in parts[:-1]:
        d = d[p]
    d[parts[-1]] = copy.deepcopy(value)


def get_path(d: dict, parts: list[str]) -> Any:
    for p in parts:
        d = d[p]
    return d


def param_leaf(path: str, where: str) -> list[str]:
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


def check_params(params: dict, where: str) -> None:
    """A complete parameter set is admissible (the parameters' own checks)."""
    from ..params import ParameterError, params_from_dict

    try:
        params_from_dict(params)
    except ParameterError as e:
        raise SweepSpecError(f"{where}: {e}") from None


# ---------------------------------------------------------------------------
# Swept values: grids and seats
# ---------------------------------------------------------------------------


def key_kind(key: Any, where: str) -> str:
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
    param_leaf(key, where)
    return "param"


def check_values(key: str, values: Any, where: str, base: dict) -> list[Any]:
    """The values swept for `key` (a setting, a body measure or a parameter path)."""
    kind = key_kind(key, where)
    if not isinstance(values, list) or not values:
        raise SweepSpecError(f"{where}[{key!r}]: expected a non-empty list of values, "
                             f"got {values!r}")
    seen = set()
    out = []
    for i, v in enumerate(values):
        w = f"{where}[{key!r}][{i}]"
        if kind == "setting":
            v = check_setting(key, v, w)
        elif kind == "body":
            if not is_number(v) or v <= 0:
                raise SweepSpecError(f"{w}: expected a positive number, got {v!r}")
            v = float(v)
        else:
            trial = copy.deepcopy(base)
            set_path(trial, key.split("."), v)
            check_params(trial, f"{w} = {v!r}")
        tag = json.dumps(canonical(v), sort_keys=True)
        if tag in seen:
            raise SweepSpecError(f"{w}: duplicate value {v!r}")
        seen.add(tag)
        out.append(v)
    return out


def _seat_key(key: Any, where: str) -> None:
    if not (isinstance(key, str) and key.split(".")[0] in ("contact", "restraints")):
        raise SweepSpecError(f"{where}: seat keys are contact.* or restraints.* "
                             f"parameter paths, got {key!r}")
    param_leaf(key, where)


def check_seats(seat: Any, base: dict) -> list[tuple[str, dict[str, Any]]]:
    """Seat configurations (label, {path: value}): a grid {path: [values]} or a list."""
    if isinstance(seat, Mapping):  # a grid
        for key in seat:
            _seat_key(key, "seat")
        keys = list(seat)
        lists = [check_values(k, seat[k], "seat", base) for k in keys]
        out = []
        for combo in itertools.product(*lists):
            values = dict(zip(keys, combo, strict=True))
            label = ",".join(f"{k}={json.dumps(canonical(v))}" for k, v in values.items())
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
            _seat_key(k, f"{where}.{k}")
            set_path(trial, k.split("."), v)
        check_params(trial, where)
        out.append((label, values))
    return out


# ---------------------------------------------------------------------------
# Sections of the schema: body, monte_carlo, analysis
# ---------------------------------------------------------------------------


def check_bodies(body: Any) -> list[Any]:
    """The bodies as a list (one may be given alone): preset names or mappings of
    measures, each admissible, with distinct labels."""
    from ..model.anthropometry import BodyMeasures

    items = body if isinstance(body, list) else [body]
    if not items:
        raise SweepSpecError("body: expected a preset name, a mapping or a non-empty list")
    labels = set()
    for i, b in enumerate(items):
        where = f"body[{i}]" if isinstance(body, list) else "body"
        if isinstance(b, str):
            if b not in BODY_PRESETS:
                raise SweepSpecError(f"{where}: unknown body preset {b!r}; expected one of "
                                     f"{', '.join(BODY_PRESETS)} or a mapping of "
                                     f"{', '.join(BODY_KEYS)}")
            label = b
        elif isinstance(b, Mapping):
            check_keys(b, BodyEntry, where)
            missing = [k for k in ("mass_kg", "stature_m") if k not in b]
            if missing:
                raise SweepSpecError(f"{where}: missing {', '.join(missing)}")
            check_fields(b, BodyEntry, where)
            m = {k: None if b.get(k) is None else float(b[k]) for k in BODY_KEYS}
            try:
                BodyMeasures(**m).validate()
            except ValueError as e:
                raise SweepSpecError(f"{where}: {e}") from None
            label = b.get("name") or where
        else:
            raise SweepSpecError(f"{where}: expected a preset name or a mapping of "
                                 f"{', '.join(BODY_KEYS)}, got {b!r}")
        if label in labels:
            raise SweepSpecError(f"{where}: duplicate body {label!r}")
        labels.add(label)
    return items


def body_label(entry: str | BodyEntry, where: str) -> str:
    """The label of a (loaded) body entry: the preset, the name or where it was given."""
    return entry if isinstance(entry, str) else (entry.name or where)


def check_monte_carlo(mc: Any, base: dict) -> None:
    """``monte_carlo``: n, seed and, for every varied path, a distribution in one of
    its forms (DISTRIBUTIONS) with admissible parameters."""
    if not isinstance(mc, Mapping):
        raise SweepSpecError(f"monte_carlo: expected a mapping with n, seed, vary, got {mc!r}")
    check_keys(mc, MonteCarloFile, "monte_carlo")
    check_fields(mc, MonteCarloFile, "monte_carlo")
    for path, d in mc["vary"].items():
        where = f"monte_carlo.vary[{path!r}]"
        kind = key_kind(path, where)
        if kind == "setting" and path not in ("rms", "frequency_hz", "duration"):
            raise SweepSpecError(f"{where}: only numeric settings (rms, frequency_hz, "
                                 "duration) can vary")
        if kind == "param":
            leaf = get_path(base, path.split("."))
            numeric = is_number(leaf) or (isinstance(leaf, list) and leaf
                                          and all(is_number(x) for x in leaf))
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
        # The schema cannot say "exactly one of these sets of keys".
        if not any(set(args) == set(f) for f in forms):
            expected = " or ".join("+".join(f) for f in forms)
            raise SweepSpecError(f"{where}: dist {dist} takes {expected}, got "
                                 f"{', '.join(args) or 'nothing'}")
        check_fields(d, Distribution, where)
        if dist == "lognormal" and args["rel_sd"] <= 0:
            raise SweepSpecError(f"{where}.rel_sd: must be positive for lognormal")
        if dist == "uniform" and "low" in args and not args["low"] < args["high"]:
            raise SweepSpecError(f"{where}: low ({args['low']}) must be below high "
                                 f"({args['high']})")
        if dist == "uniform" and "rel_range" in args and args["rel_range"] >= 1:
            raise SweepSpecError(f"{where}.rel_range: must be below 1 (a sign change), "
                                 f"got {args['rel_range']}")


def check_analysis(a: Any) -> None:
    if not isinstance(a, Mapping):
        raise SweepSpecError(f"analysis: expected a mapping, got {a!r}")
    check_keys(a, AnalysisFile, "analysis")
    check_fields(a, AnalysisFile, "analysis")
