"""Typed parameter mappings: what `pydrake.common.yaml.yaml_load_typed`
needs around it to read a YAML/JSON mapping into the parameter dataclasses
(`ehm_drake.params`) with one-line errors: the schema it reads (fixed-size
vectors as lists, defaults to start from), the checks it does not make
(groups are mappings, vectors of their size, one number for a whole
vector), the key it refused, and the values that differ from the defaults.
It imports nothing of the package (`ehm_drake.params` is built on it)."""

from __future__ import annotations

import dataclasses
import functools
import json
import typing
from collections.abc import Mapping
from dataclasses import fields


class ParameterError(ValueError):
    """A parameter file or value is invalid; the message names the key."""


@functools.cache
def _hints(cls) -> dict:
    return typing.get_type_hints(cls)


def _vector_size(tp) -> int | None:
    return len(typing.get_args(tp)) if typing.get_origin(tp) is tuple else None


@functools.cache
def _schema(cls):
    """`cls` as Drake's yaml_load_typed reads it: the same fields, with the
    fixed-size vectors (tuples, which it does not read) as list[float], and
    defaults (None, or the empty group) so that it can start from scratch."""
    spec = []
    for f in fields(cls):
        tp = _hints(cls)[f.name]
        if dataclasses.is_dataclass(tp):
            spec.append((f.name, _schema(tp), dataclasses.field(default_factory=_schema(tp))))
        else:
            spec.append((f.name, list[float] if _vector_size(tp) else tp, None))
    return dataclasses.make_dataclass(cls.__name__, spec)


def _freeze(obj, cls):
    """The loaded `obj` (a schema instance, or `cls` with lists) as `cls`."""
    kwargs = {}
    for f in fields(cls):
        v, tp = getattr(obj, f.name), _hints(cls)[f.name]
        if dataclasses.is_dataclass(tp):
            v = _freeze(v, tp)
        elif _vector_size(tp):
            v = tuple(v)
        kwargs[f.name] = v
    return cls(**kwargs)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _reads_as_number(v) -> bool:
    """A number, or text that Drake's loader reads as one (as "8.0e4", which
    YAML 1.1 leaves a string)."""
    if isinstance(v, str):
        try:
            float(v)
        except ValueError:
            return False
        return True
    return _is_number(v)


def _expand(data, cls, path: str) -> dict:
    """What yaml_load_typed cannot do itself: check that groups are mappings
    and vectors lists of their size, and expand one number given for a
    vector to all its components.  Returns a new mapping (keys unknown to
    `cls` are kept for the loader to report)."""
    if not isinstance(data, Mapping):
        raise ParameterError(f"{path or 'parameters'}: expected a mapping, got {data!r}")
    out = dict(data)
    for name, value in data.items():
        tp = _hints(cls).get(name)
        key = f"{path}.{name}" if path else str(name)
        if tp is not None and dataclasses.is_dataclass(tp):
            out[name] = _expand(value, tp, key)
        elif tp is not None and (n := _vector_size(tp)):
            if _reads_as_number(value):
                out[name] = [value] * n
            elif not isinstance(value, (list, tuple)) or len(value) != n:
                raise ParameterError(f"{key}: expected a list of {n} numbers, got {value!r}")
    return out


_EXPECTED = {float: "a number", bool: "true/false", str: "a string"}


@functools.cache
def _leaf_schema(tp):
    """A one-field schema to load a single value of type `tp`."""
    return dataclasses.make_dataclass(f"Leaf_{tp.__name__}",
                                      [("value", tp, dataclasses.field(default=tp()))])


def _refused_key(data: Mapping, cls, path: str = "") -> str | None:
    """One line naming the first key of `data` (already `_expand`ed) that
    Drake's loader refuses, or None.

    Drake's own messages name only the innermost field ('damping', or '_'
    for a list item), so after a failed load each value is loaded again on
    its own, against its field's type, through the same public loader: the
    loader decides what is refused, this names where."""
    from pydrake.common.yaml import yaml_load_typed

    names = [f.name for f in fields(cls)]
    unknown = [str(k) for k in data if k not in names]
    if unknown:
        where = f"{path}." if path else ""
        return (f"unknown parameter key: {', '.join(where + u for u in unknown)} "
                f"(known here: {', '.join(names)})")
    for name, value in data.items():
        key = f"{path}.{name}" if path else name
        tp = _hints(cls)[name]
        if dataclasses.is_dataclass(tp):
            if msg := _refused_key(value, tp, key):
                return msg
            continue
        items = ([(f"{key}[{i}]", v) for i, v in enumerate(value)] if _vector_size(tp)
                 else [(key, value)])
        leaf = float if _vector_size(tp) else tp
        for where, v in items:
            try:
                yaml_load_typed(schema=_leaf_schema(leaf),
                                data=json.dumps({"value": v}, default=repr))
            except (RuntimeError, ValueError, TypeError, OverflowError):
                return f"{where}: expected {_EXPECTED[leaf]}, got {v!r}"
    return None


_MISSING = object()


def _same(v, d) -> bool:
    if isinstance(v, (list, tuple)) and isinstance(d, list):
        return len(v) == len(d) and all(map(_same, v, d))
    return type(v) is type(d) and repr(v) == repr(d)


def _changes(data: Mapping, default: dict) -> dict:
    """`data` without the values equal to `default`'s in type and value: the
    loader keeps those anyway, and has less text to parse (callers such as
    the sweep and the fit pass complete parameter sets)."""
    out = {}
    for k, v in data.items():
        d = default.get(k, _MISSING) if isinstance(k, str) else _MISSING
        if isinstance(v, Mapping) and isinstance(d, dict):
            if sub := _changes(v, d):
                out[k] = sub
        elif d is _MISSING or not _same(v, d):
            out[k] = v
    return out


