"""Free parameters of the identification: registry, bounds, scaling.

The registry lives in `ehm_drake/data/fit_parameters.yaml` (with the
physiological bounds and their sources).  A free parameter scales one or
more parameter vectors of a `ModelParams` by a common factor s; the fit
works on log(s).  Scale bounds follow from the absolute bounds and the
starting values.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
import yaml

from ..params import ModelParams, ParameterError, validate


@dataclass(frozen=True)
class FreeParameter:
    name: str
    paths: tuple[str, ...]
    bounds: tuple[float, float]
    unit: str
    #: Paths scaled by the same factor but neither bounded nor reported: a
    #: quantity that is part of the parameter's physics (a contact pair's
    #: tissue, `softening.tissue`, stiffens with the pair).
    follows: tuple[str, ...] = ()


def _registry_path() -> Path:
    return Path(str(resources.files("ehm_drake") / "data" / "fit_parameters.yaml"))


def load_registry() -> tuple[dict[str, FreeParameter], dict[str, list[str]]]:
    data = yaml.safe_load(_registry_path().read_text())
    params = {n: FreeParameter(n, tuple(d["paths"]), tuple(map(float, d["bounds"])), d["unit"],
                               tuple(d.get("follows", ())))
              for n, d in data["parameters"].items()}
    return params, {g: list(v) for g, v in data["groups"].items()}


def resolve_free(spec: str | None) -> list[FreeParameter]:
    """Free parameters from a comma-separated list of groups and/or names
    (default: the `default` group)."""
    registry, groups = load_registry()
    names: list[str] = []
    for item in (spec or "default").split(","):
        item = item.strip()
        if not item:
            continue
        if item in groups:
            names += groups[item]
        elif item in registry:
            names.append(item)
        else:
            raise ParameterError(
                f"--free: unknown parameter or group {item!r}; groups: {', '.join(groups)}; "
                f"parameters: {', '.join(registry)}")
    seen = []
    for n in names:
        if n not in seen:
            seen.append(n)
    return [registry[n] for n in seen]


def _get(d: dict, path: str):
    for k in path.split("."):
        d = d[k]
    return d


def values_of(params: ModelParams, free: FreeParameter) -> np.ndarray:
    """All components of a free parameter's vectors (flattened)."""
    d = params.to_dict()
    return np.concatenate([np.atleast_1d(np.asarray(_get(d, p), float)) for p in free.paths])


def representative(params: ModelParams, free: FreeParameter) -> float:
    """A single number per free parameter: the largest component (the pitch
    axis of a joint group, typically), for reports."""
    return float(np.max(values_of(params, free)))


def scale_bounds(params: ModelParams, free: FreeParameter) -> tuple[float, float]:
    """Bounds on the scale factor keeping every non-zero component within
    the absolute bounds."""
    v = values_of(params, free)
    v = v[v > 0]
    if len(v) == 0:
        raise ParameterError(f"free parameter {free.name} is zero in the starting parameters; "
                             "it cannot be scaled (give it a non-zero start value)")
    lo, hi = free.bounds
    s_lo, s_hi = float(np.max(lo / v)), float(np.min(hi / v))
    if s_lo > 1.0 or s_hi < 1.0:
        raise ParameterError(
            f"starting value of {free.name} ({representative(params, free):g} {free.unit}) is "
            f"outside its physiological bounds [{lo:g}, {hi:g}] {free.unit}")
    return s_lo, s_hi


def apply_scales(params: ModelParams, free: list[FreeParameter], scales) -> ModelParams:
    """A copy of `params` with each free parameter's vectors scaled, and
    validated (`params.validate`).  Built field by field: the same values as
    through `params_from_dict` (which types a mapping by way of YAML: about
    9 ms a call against 0.6 ms), `params` itself unchanged."""
    out = params
    for fp, s in zip(free, scales, strict=True):
        for path in fp.paths + fp.follows:
            out = _scaled(out, path.split("."), float(s))
    return validate(out)


def _scaled(obj, keys: list[str], s: float):
    """A copy of the dataclass `obj` with the number or vector at the path
    `keys` multiplied by `s` (the other fields shared, as `dataclasses.replace`
    does)."""
    if not dataclasses.is_dataclass(obj) or not hasattr(obj, keys[0]):
        raise ParameterError(f"no parameter {'.'.join(keys)} under {type(obj).__name__}")
    v = getattr(obj, keys[0])
    if len(keys) > 1:
        v = _scaled(v, keys[1:], s)
    elif isinstance(v, tuple):
        v = tuple(x * s for x in v)
    else:
        v = v * s
    return dataclasses.replace(obj, **{keys[0]: v})
