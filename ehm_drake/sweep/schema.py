"""The sweep spec file's schema: dataclasses read by Drake's typed YAML loader
(:func:`pydrake.common.yaml.yaml_load_typed`), the names and defaults derived
from them, and the checks of the values the schema types.

The loader builds the dataclasses (defaults, ``Optional``, nested mappings and
lists, ``int`` to ``float``) but is lenient where the sweep must not be: it
turns the string ``"0.2"`` into a number, ``3.0`` into an integer, and its
errors name only the innermost field.  So every typed value is checked first,
on the plain data, by :func:`check_fields` (the field's type from the schema,
its admissible range from the field's metadata), with a one-line message naming
the key and what is allowed; the loader then sees only data it takes as is.

What the schema cannot say, and so is checked by hand (checks.py): choices
among strings (the loader has no ``Literal``: direction, excitation, variant,
dist, body presets), ranges across fields (``low < high``), "exactly one of
these sets of keys" (a distribution's forms), "one item or a list" (``body``),
and the free-form keys (``params``, ``grid``, ``seat``: parameter paths with
values of any parameter's type).

No ``from __future__ import annotations`` here: the loader reads the field
types from ``dataclasses.fields``, where they would then be strings.  This
module imports nothing of the package above it (the variants are imported
only where a setting is checked).
"""

import dataclasses
import math
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Union

import numpy as np
import yaml


class SweepSpecError(ValueError):
    """The sweep spec is invalid; the message names the key."""


# ---------------------------------------------------------------------------
# Plain data
# ---------------------------------------------------------------------------


def is_number(v: Any) -> bool:
    """A finite int or float (not a bool)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def canonical(v: Any) -> Any:
    """Plain JSON data with every number a float (30000 and 30000.0 hash alike)."""
    if isinstance(v, Mapping):
        return {str(k): canonical(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [canonical(x) for x in v]
    if isinstance(v, (bool, str)) or v is None:
        return v
    if isinstance(v, (int, float, np.integer, np.floating)):
        return float(v)
    raise TypeError(f"not plain data: {v!r}")


def join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


# ---------------------------------------------------------------------------
# Field declarations: type from the annotation, range and wording in metadata
# ---------------------------------------------------------------------------


def spec_field(default: Any = None, *, factory: Callable[[], Any] | None = None,
               expect: str | None = None, ok: Callable[[Any], bool] | None = None,
               missing: str | None = None, check: Callable[..., Any] | None = None):
    """A schema field.

    `expect`: the allowed values in words, for the error (default: from the
    type).  `ok`: range check of a value of the right type.  `missing`: the key
    is required; the error text when it is absent.  `check`: ``check(name,
    value, where)`` replaces the type and range check (for values that are
    checked the same way elsewhere, e.g. swept settings).
    """
    meta = {k: v for k, v in (("expect", expect), ("ok", ok), ("missing", missing),
                              ("check", check)) if v is not None}
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    return field(default=default, metadata=meta)


def _type_ok(value: Any, tp: Any) -> bool:
    """`value` is plain data of the schema type `tp` (strictly: no bool for a number,
    no float for an int, no string for anything else)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (Union, types.UnionType):
        return any(_type_ok(value, a) for a in args)
    if tp is type(None):
        return value is None
    if tp is float:
        return is_number(value)
    if tp is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if tp in (str, bool):
        return isinstance(value, tp)
    if origin is list:
        return isinstance(value, list) and all(_type_ok(v, args[0]) for v in value)
    if origin is dict or dataclasses.is_dataclass(tp):
        return isinstance(value, Mapping)  # the entries are checked by their section
    raise TypeError(f"no check for schema type {tp!r}")  # pragma: no cover


def _expect(tp: Any) -> str:
    names = {float: "a number", int: "an integer", str: "a string", bool: "true/false"}
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    return names.get(args[0] if len(args) == 1 else tp, "a mapping")


def check_keys(raw: Mapping, schema: type, where: str, extra: tuple[str, ...] = ()) -> None:
    """No key of `raw` beyond the fields of `schema` (and `extra`)."""
    known = [f.name for f in dataclasses.fields(schema)] + list(extra)
    unknown = sorted(str(k) for k in raw if k not in known)
    if unknown:
        raise SweepSpecError(f"{where}: unknown key(s) {', '.join(unknown)} "
                             f"(known: {', '.join(known)})")


def check_fields(raw: Mapping, schema: type, where: str) -> None:
    """Check the values of `raw` against the fields of `schema`, in field order."""
    hints = typing.get_type_hints(schema)
    for f in dataclasses.fields(schema):
        key = join(where, f.name)
        if f.name not in raw:
            if "missing" in f.metadata:
                raise SweepSpecError(f"{key}: {f.metadata['missing']}")
            continue
        value = raw[f.name]
        if "check" in f.metadata:
            f.metadata["check"](f.name, value, key)
            continue
        ok = f.metadata.get("ok")
        if not _type_ok(value, hints[f.name]) or (ok is not None and value is not None
                                                   and not ok(value)):
            expect = f.metadata.get("expect") or _expect(hints[f.name])
            raise SweepSpecError(f"{key}: expected {expect}, got {value!r}")


def _plain(v: Any) -> Any:
    if isinstance(v, Mapping):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (bool, str)) or v is None:
        return v
    if isinstance(v, (int, np.integer)):
        return int(v)
    return float(v)


def load_typed(schema: type, data: Mapping[str, Any]):
    """`data` (checked plain data) as an instance of the dataclass `schema`, built by
    Drake's typed loader.  The loader reads YAML text, so the data is written as YAML
    first (spec files are read once, by the spec's own loader: see spec.py)."""
    # Imported here: pydrake is heavy and `ehm-drake --help` needs none of it.
    from pydrake.common.yaml import yaml_load_typed

    text = yaml.safe_dump(_plain(data), sort_keys=False)
    return yaml_load_typed(schema=schema, data=text)


# ---------------------------------------------------------------------------
# Common settings of a run (checked alike at the top level and in grids)
# ---------------------------------------------------------------------------

DIRECTIONS = ("x", "y", "z", "xyz")
#: Excitation kinds a sweep can generate (a measured csv file is not portable to
#: remote workers and is not offered).
EXCITATIONS = ("random", "multisine", "sweep", "sine")


def check_setting(name: str, value: Any, where: str) -> Any:
    """A common setting's value (numbers as floats, the seed as an int)."""
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
        from ..params import VARIANTS

        if value not in VARIANTS:
            raise SweepSpecError(f"{where}: variant must be one of {', '.join(VARIANTS)}, "
                                 f"got {value!r}")
    elif name == "design":
        from ..params import CHOICES

        # auto: as the ``simulate`` command chooses (`params.command_design`).
        designs = ("auto", *CHOICES["simulation.design"])
        if value not in designs:
            raise SweepSpecError(f"{where}: design must be one of {', '.join(designs)}, "
                                 f"got {value!r}")
    elif name == "seed":
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise SweepSpecError(f"{where}: seed must be an integer >= 0, got {value!r}")
    else:  # rms, duration, frequency_hz
        if not is_number(value) or value <= 0:
            raise SweepSpecError(f"{where}: {name} must be a positive finite number, "
                                 f"got {value!r}")
        if name == "rms" and value > 20.0:
            raise SweepSpecError(f"{where}: rms {value} m/s^2 is beyond whole-body vibration "
                                 "levels (< 20 m/s^2); is it in mm/s^2 or in g?")
        value = float(value)
    return value


def _setting(default: Any):
    return spec_field(default, check=check_setting)


# ---------------------------------------------------------------------------
# The schema
# ---------------------------------------------------------------------------


@dataclass
class BodyEntry:
    """A body given by its measures (``body: {mass_kg: 60, stature_m: 1.62}``)."""

    name: str | None = None
    # Required (checks.check_bodies names the missing ones); the loader needs defaults.
    mass_kg: float = math.nan
    stature_m: float = math.nan
    sitting_height_m: float | None = None


BODY_KEYS = ("mass_kg", "stature_m", "sitting_height_m")


@dataclass
class Distribution:
    """How one Monte Carlo path varies: ``dist`` and one of its forms."""

    dist: str = ""
    rel_sd: float | None = spec_field(None, expect="a number >= 0", ok=lambda v: v >= 0)
    sd: float | None = spec_field(None, expect="a number >= 0", ok=lambda v: v >= 0)
    rel_range: float | None = spec_field(None, expect="a number >= 0", ok=lambda v: v >= 0)
    low: float | None = None
    high: float | None = None


#: The parameters each distribution takes (one of the forms).
DISTRIBUTIONS = {
    "normal": (("rel_sd",), ("sd",)),
    "lognormal": (("rel_sd",),),
    "uniform": (("rel_range",), ("low", "high")),
}


@dataclass
class MonteCarloFile:
    """``monte_carlo:``: `n` samples, seeded, of the `vary` paths."""

    n: int = spec_field(0, expect="an integer >= 1", ok=lambda v: v >= 1,
                        missing="missing (the number of samples)")
    seed: int | None = spec_field(None, expect="an integer >= 0", ok=lambda v: v >= 0,
                                     missing="missing (every random choice takes a seed)")
    vary: dict[str, Distribution] = spec_field(
        factory=dict, ok=bool, expect="a non-empty mapping {path: {dist: normal, rel_sd: 0.1}}",
        missing="missing (a non-empty mapping {path: {dist: normal, rel_sd: 0.1}})")


@dataclass
class AnalysisFile:
    """``analysis:``: what is kept of each run."""

    peak_band_hz: list[float] = spec_field(
        factory=lambda: [0.5, 12.0], expect="[low, high] Hz with 0 <= low < high",
        ok=lambda b: len(b) == 2 and 0 <= b[0] < b[1])
    frf: bool = True


@dataclass
class SpecFile:
    """The typed keys of a sweep spec file.  ``params``, ``grid`` and ``seat`` are not
    here: their keys are parameter paths and their values any parameter's type (numbers,
    vectors, strings, booleans), which the typed loader cannot express; they are
    checked against the parameter tree instead (checks.py)."""

    name: str = spec_field("sweep", expect="a non-empty string", ok=bool)
    direction: str = _setting("z")
    rms: float = _setting(0.1941)  # paper level, m/s^2 (ehm_drake.signals.PAPER_RMS)
    duration: float = _setting(60.0)
    seed: int = _setting(0)
    variant: str = _setting("default")
    #: auto: the commands' default (the implicit design at the step chosen by
    #: accuracy, unless the parameters state simulation.design or time_step_s).
    design: str = _setting("auto")
    excitation: str = _setting("random")
    frequency_hz: float = _setting(4.0)
    params_file: str | None = spec_field(None, expect="a file name")
    # Sections, each checked by its own function (checks.py):
    #: Presets or measures (one body may be given alone, not in a list).
    body: list[BodyEntry | str] | None = None
    monte_carlo: MonteCarloFile | None = None
    analysis: AnalysisFile = spec_field(factory=AnalysisFile)


#: The keys of SpecFile that hold a section (not a plain value).
SECTIONS = ("body", "monte_carlo", "analysis")


#: Common settings of a run and their defaults (the CLI's `simulate` defaults).
SETTING_DEFAULTS: dict[str, Any] = {
    f.name: f.default for f in dataclasses.fields(SpecFile) if "check" in f.metadata}
#: Keys of the spec whose values are free-form (checked against the parameters).
FREE_FORM_KEYS = ("params", "grid", "seat")
SPEC_KEYS = (
    "name", *SETTING_DEFAULTS, "params_file", "params", "body", "grid", "seat",
    "monte_carlo", "analysis",
)
assert set(SPEC_KEYS) == {f.name for f in dataclasses.fields(SpecFile)} | set(FREE_FORM_KEYS)
ANALYSIS_DEFAULTS: dict[str, Any] = dataclasses.asdict(AnalysisFile())

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
