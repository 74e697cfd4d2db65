"""Shared pieces of the data formats: errors, labels, channel names, CSV parsing.

:class:`DataFormatError`, the label vocabulary (excitation axes, segments, dofs), channel
names ``<segment>_<dof>`` and their file units, the normalisation of a metadata
``direction``, and the CSV / number parsing every reader uses (messages name the file, the
line and the column at fault).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = [
    "DIRECTIONS",
    "SEGMENTS",
    "DOFS",
    "TRANSLATIONAL_DOFS",
    "ROTATIONAL_DOFS",
    "DataFormatError",
    "parse_channel_name",
    "channel_unit",
]

DIRECTIONS: tuple[str, ...] = ("x", "y", "z")
SEGMENTS: tuple[str, ...] = ("pelvis", "trunk", "head", "knee_l", "knee_r")
TRANSLATIONAL_DOFS: tuple[str, ...] = ("x", "y", "z")
ROTATIONAL_DOFS: tuple[str, ...] = ("roll", "pitch", "yaw")
DOFS: tuple[str, ...] = TRANSLATIONAL_DOFS + ROTATIONAL_DOFS


class DataFormatError(ValueError):
    """Invalid content in a data file or data object (names file, line and column)."""


def location(source: str | None, line: int | None = None, column: str | None = None) -> str:
    """Message prefix naming the place at fault ('' when nothing is known)."""
    parts = []
    if source:
        parts.append(str(source))
    if line is not None:
        parts.append(f"line {line}")
    if column is not None:
        parts.append(f"column '{column}'")
    return (", ".join(parts) + ": ") if parts else ""


def parse_channel_name(name: str) -> tuple[str, str]:
    """Split a time-series channel name ``<segment>_<dof>`` into ``(segment, dof)``.

    Parameters
    ----------
    name : str
        Column name such as ``"head_pitch"`` or ``"knee_l_z"``.

    Returns
    -------
    tuple of str
        ``(segment, dof)``.

    Raises
    ------
    DataFormatError
        If the name is not a known segment followed by ``_`` and a known dof.
    """
    for dof in DOFS:
        suffix = "_" + dof
        if name.endswith(suffix):
            segment = name[: -len(suffix)]
            if segment in SEGMENTS:
                return segment, dof
    raise DataFormatError(
        f"unknown channel name '{name}': expected '<segment>_<dof>' with segment in "
        f"{list(SEGMENTS)} and dof in {list(DOFS)}"
    )


def channel_unit(dof: str) -> str:
    """File unit of a motion channel: ``'m'`` for translational dofs, ``'deg'`` otherwise."""
    if dof in TRANSLATIONAL_DOFS:
        return "m"
    if dof in ROTATIONAL_DOFS:
        return "deg"
    raise DataFormatError(f"unknown dof '{dof}': expected one of {list(DOFS)}")


def normalise_directions(value: Any, where: str) -> str:
    """Metadata ``direction`` ("z", "xz", ["x", "z"]) -> canonical string like "xz"."""
    if isinstance(value, str):
        items = list(value.replace(",", "").replace(" ", "").lower())
    elif isinstance(value, Sequence) and all(isinstance(v, str) for v in value):
        items = [v.strip().lower() for v in value]
    else:
        raise DataFormatError(
            f"{where}metadata 'direction' must be a string like 'z' or 'xz' or a list of "
            f"axes, got {value!r}"
        )
    bad = [v for v in items if v not in DIRECTIONS]
    if not items or bad:
        raise DataFormatError(
            f"{where}metadata 'direction'={value!r} is not made of axes {list(DIRECTIONS)}"
        )
    if len(set(items)) != len(items):
        raise DataFormatError(f"{where}metadata 'direction'={value!r} repeats an axis")
    return "".join(d for d in DIRECTIONS if d in items)


def read_csv_rows(text: str, source: str, first_line: int) -> tuple[list[str], list[list[str]]]:
    """Parse CSV text; returns header and rows (ragged rows raise)."""
    reader = csv.reader(io.StringIO(text))
    rows = [r for r in reader]
    # drop fully blank trailing lines
    while rows and (not rows[-1] or all(not c.strip() for c in rows[-1])):
        rows.pop()
    if not rows:
        raise DataFormatError(f"{location(source)}file is empty (no header line)")
    header = [h.strip() for h in rows[0]]
    body = rows[1:]
    for i, r in enumerate(body):
        if len(r) != len(header):
            raise DataFormatError(
                f"{location(source, first_line + 1 + i)}has {len(r)} fields but the header has "
                f"{len(header)}"
            )
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DataFormatError(f"{location(source, first_line)}duplicate column(s) {dup}")
    return header, body


def to_float_column(
    cells: Sequence[str],
    column: str,
    source: str,
    first_data_line: int,
    allow_empty: bool = False,
) -> np.ndarray:
    """Convert a column of strings to float64, naming the first bad cell."""
    out = np.empty(len(cells), dtype=np.float64)
    for i, c in enumerate(cells):
        s = c.strip()
        if not s:
            if allow_empty:
                out[i] = np.nan
                continue
            raise DataFormatError(f"{location(source, first_data_line + i, column)}empty value")
        try:
            v = float(s)
        except ValueError:
            raise DataFormatError(
                f"{location(source, first_data_line + i, column)}'{s}' is not a number"
            ) from None
        if not math.isfinite(v):
            raise DataFormatError(
                f"{location(source, first_data_line + i, column)}non-finite value '{s}'"
            )
        out[i] = v
    return out
