"""The sweep spec: reading a spec file (or mapping), checking it and the
validated, normalized :class:`SweepSpec` the rest of the sweep works from.

The file's format is the schema in schema.py (typed keys, loaded with Drake's
``yaml_load_typed``) plus three free-form keys checked against the parameter
tree (``params``, ``grid``, ``seat``; checks.py).
"""

from __future__ import annotations

import copy
import dataclasses
import json
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .checks import (
    body_label,
    check_analysis,
    check_bodies,
    check_monte_carlo,
    check_params,
    check_seats,
    check_values,
    deep_merge,
    default_params_dict,
    merge_overrides,
)
from .schema import (
    ANALYSIS_DEFAULTS,
    BODY_PRESETS,
    FREE_FORM_KEYS,
    SECTIONS,
    SETTING_DEFAULTS,
    SPEC_KEYS,
    SpecFile,
    SweepSpecError,
    canonical,
    check_fields,
    load_typed,
)


@dataclass
class MonteCarlo:
    """Monte Carlo population: `n` samples, seeded, of the `vary` paths."""

    n: int
    seed: int
    vary: dict[str, dict[str, Any]]


@dataclass
class SweepSpec:
    """A validated sweep spec (see the package doc for the file format)."""

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


# ---------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------


class _Loader(yaml.SafeLoader):
    """YAML loader that also reads ``3e4`` as a number (YAML 1.1 needs ``3.0e+4``).

    The file is read here, not by Drake's loader: the free-form keys (grid values)
    need the numbers, and a spec may also come as a mapping from Python."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


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


# ---------------------------------------------------------------------------
# Checking and normalizing
# ---------------------------------------------------------------------------

#: Keys whose null value means "not given" (a null setting or name is an error).
_NULL_IS_ABSENT = ("params_file", *SECTIONS, *FREE_FORM_KEYS)


def _parameters(data: dict, base_dir: Path) -> tuple[dict, dict]:
    """(complete parameters, overrides) of params_file then params over the defaults."""
    from ..params import ParameterError, read_params_mapping

    base = default_params_dict()
    overrides: dict[str, Any] = {}
    if "params_file" in data:
        pf = Path(data["params_file"])
        pf = pf if pf.is_absolute() else base_dir / pf
        try:
            file_params = read_params_mapping(pf)
            base = deep_merge(base, file_params, "")
        except (ParameterError, SweepSpecError) as e:
            raise SweepSpecError(f"params_file: {e}") from None
        overrides = copy.deepcopy(file_params)
    if "params" in data:
        if not isinstance(data["params"], Mapping):
            raise SweepSpecError(f"params: expected a mapping, got {data['params']!r}")
        base = deep_merge(base, data["params"], "params")
        overrides = merge_overrides(overrides, data["params"])
    check_params(base, "params")
    return base, overrides


def _build_spec(data: dict, base_dir: Path, source: str | None) -> SweepSpec:
    unknown = [k for k in data if k not in SPEC_KEYS]
    if unknown:
        raise SweepSpecError(f"unknown key(s): {', '.join(map(str, unknown))} "
                             f"(known: {', '.join(SPEC_KEYS)})")
    data = {k: v for k, v in data.items() if not (v is None and k in _NULL_IS_ABSENT)}
    # The plain typed values (name, settings, params_file), then the rest in order.
    check_fields({k: v for k, v in data.items() if k not in SECTIONS}, SpecFile, "")
    base, overrides = _parameters(data, base_dir)
    bodies = check_bodies(data["body"]) if "body" in data else None
    grid = data.get("grid") or {}
    if not isinstance(grid, Mapping):
        raise SweepSpecError(f"grid: expected a mapping {{path: [values]}}, got {grid!r}")
    grid = {k: check_values(k, v, "grid", base) for k, v in grid.items()}
    seats = check_seats(data["seat"], base) if "seat" in data else []
    overlap = sorted(set(grid) & {k for _, s in seats for k in s})
    if overlap:
        raise SweepSpecError(f"seat: {', '.join(overlap)} also swept in grid")
    if "monte_carlo" in data:
        check_monte_carlo(data["monte_carlo"], base)
    if "analysis" in data:
        check_analysis(data["analysis"])

    typed = {k: v for k, v in data.items() if k not in FREE_FORM_KEYS}
    if bodies is not None:
        typed["body"] = bodies
    f = load_typed(SpecFile, typed)

    spec = SweepSpec(name=f.name, settings={k: getattr(f, k) for k in SETTING_DEFAULTS},
                     params=canonical(overrides), grid=grid, seats=seats,
                     analysis=dataclasses.asdict(f.analysis), source=source)
    if f.body is not None:
        spec.body_swept = True
        single = not isinstance(data["body"], list)
        spec.bodies = []
        for i, entry in enumerate(f.body):
            where = "body" if single else f"body[{i}]"
            measures = (dict(BODY_PRESETS[entry]) if isinstance(entry, str) else
                        {k: getattr(entry, k) for k in ("mass_kg", "stature_m",
                                                         "sitting_height_m")})
            spec.bodies.append((body_label(entry, where), measures))
    if f.monte_carlo is not None:
        mc, raw = f.monte_carlo, data["monte_carlo"]["vary"]
        # The parameters in the order given (the normalized spec keeps it).
        vary = {path: {"dist": d.dist, **{k: getattr(d, k) for k in raw[path] if k != "dist"}}
                for path, d in mc.vary.items()}
        spec.monte_carlo = MonteCarlo(mc.n, mc.seed, vary)
    return spec
