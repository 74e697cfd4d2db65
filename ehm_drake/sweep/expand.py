"""Run expansion: the runs of a sweep (bodies x grid x seats x Monte Carlo
samples), each with plain inputs and a stable id (the hash of its inputs)."""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .checks import deep_merge, default_params_dict, get_path, set_path
from .schema import SETTING_DEFAULTS, SweepSpecError, canonical
from .spec import SweepSpec, load_sweep_spec

#: Version of the run record format (part of every run id).
RUN_FORMAT = 1


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
    blob = json.dumps(canonical(inputs), sort_keys=True, separators=(",", ":"),
                      allow_nan=False)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


# ---------------------------------------------------------------------------
# Monte Carlo draws
# ---------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------
# Expansion
# ---------------------------------------------------------------------------


def expand_runs(spec: SweepSpec | Mapping[str, Any] | str | Path) -> list[RunSpec]:
    """The runs of a sweep: bodies x grid x seat configurations (x Monte Carlo samples).

    Every random draw is seeded (``monte_carlo.seed``), so the same spec gives the same
    runs.  Runs with identical inputs (e.g. a Monte Carlo with zero spread) share their
    run id and are computed once.
    """
    from ..model.anthropometry import BodyMeasures
    from ..params import COMMAND_DESIGN

    spec = load_sweep_spec(spec)
    base = deep_merge(default_params_dict(), spec.params, "params")
    grid_keys = list(spec.grid)
    grid_combos = list(itertools.product(*(spec.grid[k] for k in grid_keys)))
    seats: list[tuple[str | None, dict[str, Any]]] = list(spec.seats) or [(None, {})]
    mc = spec.monte_carlo
    samples: list[int | None] = list(range(mc.n)) if mc else [None]
    stated = _states_stepping(spec)
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
        if settings["design"] == "auto":
            # As `simulate` chooses: a step or design the spec states is kept.
            settings["design"] = (params["simulation"]["design"] if stated
                                  else COMMAND_DESIGN)
        runs.append((swept, params, body, settings))
    out = []
    for i, (swept, params, body, settings) in enumerate(runs):
        params = canonical(params)
        run = RunSpec("", i, swept, params, canonical(body), settings,
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


def _states_stepping(spec: SweepSpec) -> bool:
    """Whether the spec states ``simulation.design`` or ``simulation.time_step_s``
    (params_file, params, grid, seat or monte_carlo), as a parameter file does
    for `ehm_drake.params.names_stepping`."""
    named = set(spec.grid) | {k for _, s in spec.seats for k in s}
    if spec.monte_carlo is not None:
        named |= set(spec.monte_carlo.vary)
    from ..params import STEPPING_KEYS

    sim = spec.params.get("simulation")
    if isinstance(sim, Mapping):
        named |= {f"simulation.{k}" for k in sim}
    return any(f"simulation.{k}" in named for k in STEPPING_KEYS)


def _describe(swept: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in swept.items()) or "base"


def _assign(key: str, value: Any, params: dict, body: dict, settings: dict) -> None:
    if key in SETTING_DEFAULTS:
        settings[key] = value
    elif key.startswith("body."):
        body[key[5:]] = value
    else:
        set_path(params, key.split("."), value)


def _lookup(key: str, params: dict, body: dict, settings: dict) -> Any:
    if key in SETTING_DEFAULTS:
        return settings[key]
    if key.startswith("body."):
        name = key[5:]
        if name == "sitting_height_m" and body.get(name) is None:
            from ..model.anthropometry import BodyMeasures

            return BodyMeasures(**body).resolved_sitting_height()
        return body[name]
    return get_path(params, key.split("."))
