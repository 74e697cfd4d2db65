"""Measured-data file formats: ``frf.csv`` and ``timeseries.csv``.

Two plain-text formats carry measured (or simulated) seated whole-body-vibration data.
Several tools read them, so they are kept exactly as specified here.

``frf.csv`` -- transmissibilities, one row per frequency bin::

    direction,segment,dof,freq_hz,gain,phase_deg,coherence[,level_rms]

* ``direction`` -- seat excitation axis, one of ``x``, ``y``, ``z``;
* ``segment`` -- one of ``pelvis``, ``trunk``, ``head``, ``knee_l``, ``knee_r``;
* ``dof`` -- one of ``x``, ``y``, ``z``, ``roll``, ``pitch``, ``yaw``;
* ``freq_hz`` -- frequency (Hz, > 0);
* ``gain`` -- |T|, per metre of seat displacement: m/m for translational dofs,
  deg/m for rotational dofs (>= 0);
* ``phase_deg`` -- phase of T (deg);
* ``coherence`` -- ordinary (or multiple) coherence, in [0, 1];
* ``level_rms`` -- optional: seat acceleration RMS of the test (m/s^2, > 0). An empty cell
  means "not given" and is read as NaN.
* ``n_averages`` -- optional: number of (Welch) averages of the estimate (>= 1); with the
  coherence it gives the estimate's random error.  An empty cell means "not given" (NaN).

``timeseries.csv`` -- time histories on seat-aligned axes::

    t,seat_ax,seat_ay,seat_az,<segment>_<dof>,...

* ``t`` -- time (s), uniformly sampled and increasing;
* ``seat_ax``, ``seat_ay``, ``seat_az`` -- seat acceleration (m/s^2), all three required;
* ``<segment>_<dof>`` -- absolute motion from the settled pose: displacement in m for
  translational dofs, rotation in deg for rotational dofs, e.g. ``head_pitch``, ``knee_l_z``.

Optional metadata ``level_rms`` (m/s^2) and ``direction`` (excited axis or axes, e.g. ``"z"`` or
``"xz"``) come either from a one-line JSON comment as the first line of the file
(``# {"level_rms": 0.3, "direction": "z"}``) or from a sidecar ``meta.json`` in the same folder.
When both exist they are merged; a key given in both with different values is an error.

All readers validate their input and raise :class:`DataFormatError` (a ``ValueError``) whose
message names the file, the line and the column at fault.  Python warnings are never emitted;
:func:`check_units` returns plausibility warnings as strings instead.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "DIRECTIONS",
    "SEGMENTS",
    "DOFS",
    "TRANSLATIONAL_DOFS",
    "ROTATIONAL_DOFS",
    "FRF_COLUMNS",
    "SEAT_COLUMNS",
    "MIN_DURATION_S",
    "MIN_SAMPLES",
    "SAMPLING_RTOL",
    "DataFormatError",
    "FrfData",
    "TimeSeriesData",
    "parse_channel_name",
    "channel_unit",
    "read_frf",
    "read_timeseries",
    "read_data_dir",
    "check_units",
]

DIRECTIONS: tuple[str, ...] = ("x", "y", "z")
SEGMENTS: tuple[str, ...] = ("pelvis", "trunk", "head", "knee_l", "knee_r")
TRANSLATIONAL_DOFS: tuple[str, ...] = ("x", "y", "z")
ROTATIONAL_DOFS: tuple[str, ...] = ("roll", "pitch", "yaw")
DOFS: tuple[str, ...] = TRANSLATIONAL_DOFS + ROTATIONAL_DOFS

FRF_COLUMNS: tuple[str, ...] = (
    "direction",
    "segment",
    "dof",
    "freq_hz",
    "gain",
    "phase_deg",
    "coherence",
)
FRF_OPTIONAL_COLUMNS: tuple[str, ...] = ("level_rms", "n_averages")
SEAT_COLUMNS: tuple[str, ...] = ("seat_ax", "seat_ay", "seat_az")

#: Minimum record length accepted by :func:`read_timeseries` (s).
MIN_DURATION_S: float = 10.0
#: Minimum number of samples accepted by :func:`read_timeseries`.
MIN_SAMPLES: int = 256
#: Relative tolerance on the sampling interval (uniform sampling check).
SAMPLING_RTOL: float = 1e-3

META_FILENAME = "meta.json"
FRF_FILENAME = "frf.csv"
TIMESERIES_FILENAME = "timeseries.csv"


class DataFormatError(ValueError):
    """Invalid content in a data file or data object (names file, line and column)."""


# ------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------


def _where(source: str | None, line: int | None = None, column: str | None = None) -> str:
    parts = []
    if source:
        parts.append(str(source))
    if line is not None:
        parts.append(f"line {line}")
    if column is not None:
        parts.append(f"column '{column}'")
    return (", ".join(parts) + ": ") if parts else ""


def _fmt(x: float) -> str:
    """Shortest float text that round-trips exactly; '' for NaN (absent)."""
    if isinstance(x, float) and math.isnan(x):
        return ""
    return repr(float(x))


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


def _normalise_directions(value: Any, where: str) -> str:
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


def _validate_meta(meta: Mapping[str, Any], where: str) -> dict[str, Any]:
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
        out["direction"] = _normalise_directions(out["direction"], where)
    return out


def _read_csv_rows(text: str, source: str, first_line: int) -> tuple[list[str], list[list[str]]]:
    """Parse CSV text; returns header and rows (ragged rows raise)."""
    reader = csv.reader(io.StringIO(text))
    rows = [r for r in reader]
    # drop fully blank trailing lines
    while rows and (not rows[-1] or all(not c.strip() for c in rows[-1])):
        rows.pop()
    if not rows:
        raise DataFormatError(f"{_where(source)}file is empty (no header line)")
    header = [h.strip() for h in rows[0]]
    body = rows[1:]
    for i, r in enumerate(body):
        if len(r) != len(header):
            raise DataFormatError(
                f"{_where(source, first_line + 1 + i)}has {len(r)} fields but the header has "
                f"{len(header)}"
            )
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DataFormatError(f"{_where(source, first_line)}duplicate column(s) {dup}")
    return header, body


def _to_float_column(
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
            raise DataFormatError(f"{_where(source, first_data_line + i, column)}empty value")
        try:
            v = float(s)
        except ValueError:
            raise DataFormatError(
                f"{_where(source, first_data_line + i, column)}'{s}' is not a number"
            ) from None
        if not math.isfinite(v):
            raise DataFormatError(
                f"{_where(source, first_data_line + i, column)}non-finite value '{s}'"
            )
        out[i] = v
    return out


# ------------------------------------------------------------------------------------------
# FRF table
# ------------------------------------------------------------------------------------------


@dataclass(eq=False)
class FrfData:
    """Tidy table of transmissibility rows (one row per channel and frequency bin).

    Attributes
    ----------
    direction, segment, dof : numpy.ndarray of str, shape (n,)
        Excitation axis, body segment and degree of freedom of each row.
    freq_hz : numpy.ndarray, shape (n,)
        Frequency (Hz, > 0).
    gain : numpy.ndarray, shape (n,)
        |T| per metre of seat displacement: m/m (translational dof) or deg/m (rotational).
    phase_deg : numpy.ndarray, shape (n,)
        Phase of T (deg).
    coherence : numpy.ndarray, shape (n,)
        Coherence in [0, 1].
    level_rms : numpy.ndarray, shape (n,)
        Seat acceleration RMS of the test (m/s^2); NaN where not given.
    n_averages : numpy.ndarray, shape (n,)
        Number of averages of the estimate; NaN where not given.

    Notes
    -----
    The constructor validates all values and raises :class:`DataFormatError` naming the row
    (0-based index into the arrays; file readers report file line numbers instead).
    """

    direction: np.ndarray
    segment: np.ndarray
    dof: np.ndarray
    freq_hz: np.ndarray
    gain: np.ndarray
    phase_deg: np.ndarray
    coherence: np.ndarray
    level_rms: np.ndarray | None = None
    n_averages: np.ndarray | None = None
    _row_labels: np.ndarray | None = field(default=None, repr=False, compare=False)
    _source: str | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        src = self._source
        n = None
        for name in ("direction", "segment", "dof"):
            arr = np.asarray(getattr(self, name), dtype=str).reshape(-1)
            setattr(self, name, arr)
            n = arr.size if n is None else n
            if arr.size != n:
                raise DataFormatError(
                    f"{_where(src)}FrfData field '{name}' has {arr.size} rows, expected {n}"
                )
        assert n is not None
        if self.level_rms is None:
            self.level_rms = np.full(n, np.nan)
        if self.n_averages is None:
            self.n_averages = np.full(n, np.nan)
        for name in ("freq_hz", "gain", "phase_deg", "coherence", "level_rms", "n_averages"):
            try:
                arr = np.asarray(getattr(self, name), dtype=np.float64).reshape(-1)
            except (TypeError, ValueError) as exc:
                raise DataFormatError(
                    f"{_where(src)}FrfData field '{name}' is not numeric: {exc}"
                ) from None
            if arr.size != n:
                raise DataFormatError(
                    f"{_where(src)}FrfData field '{name}' has {arr.size} rows, expected {n}"
                )
            setattr(self, name, arr)
        labels = self._row_labels

        def label(i: int) -> str:
            return str(labels[i]) if labels is not None else f"row {i}"

        def fail(idx: np.ndarray, column: str, msg: str) -> None:
            i = int(idx[0])
            raise DataFormatError(f"{_where(src)}{label(i)}, column '{column}': {msg(i)}")

        for name, allowed in (
            ("direction", DIRECTIONS),
            ("segment", SEGMENTS),
            ("dof", DOFS),
        ):
            arr = getattr(self, name)
            bad = np.flatnonzero(~np.isin(arr, allowed))
            if bad.size:
                fail(
                    bad,
                    name,
                    lambda i, a=arr, al=allowed: (
                        f"unknown value '{a[i]}', expected one of {list(al)}"
                    ),
                )
        for name in ("freq_hz", "gain", "phase_deg", "coherence"):
            arr = getattr(self, name)
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                fail(bad, name, lambda i, a=arr: f"non-finite value {a[i]}")
        bad = np.flatnonzero(np.isinf(self.level_rms))
        if bad.size:
            fail(bad, "level_rms", lambda i: f"non-finite value {self.level_rms[i]}")
        bad = np.flatnonzero(self.freq_hz <= 0)
        if bad.size:
            fail(bad, "freq_hz", lambda i: f"frequency must be > 0 Hz, got {self.freq_hz[i]}")
        bad = np.flatnonzero(self.gain < 0)
        if bad.size:
            fail(bad, "gain", lambda i: f"gain must be >= 0, got {self.gain[i]}")
        bad = np.flatnonzero((self.coherence < 0) | (self.coherence > 1))
        if bad.size:
            fail(
                bad, "coherence", lambda i: f"coherence must be in [0, 1], got {self.coherence[i]}"
            )
        bad = np.flatnonzero(self.level_rms <= 0)
        if bad.size:
            fail(
                bad, "level_rms", lambda i: f"level_rms must be > 0 m/s^2, got {self.level_rms[i]}"
            )
        bad = np.flatnonzero(np.isinf(self.n_averages) | (self.n_averages < 1))
        if bad.size:
            fail(bad, "n_averages",
                 lambda i: f"n_averages must be a number >= 1, got {self.n_averages[i]}")
        # duplicated (channel, level, frequency) rows are ambiguous; found by a
        # vectorized sort (a Python loop over rows cost 40 ms on a linear FRF).
        if n > 1:
            level = np.where(np.isnan(self.level_rms), -1.0, self.level_rms)
            keys = (self.freq_hz, level, self.dof, self.segment, self.direction)
            order = np.lexsort(keys)
            same = np.ones(n - 1, bool)
            for k in keys:
                ks = k[order]
                same &= ks[1:] == ks[:-1]
            if same.any():
                # lexsort is stable: equal keys keep their row order.  Report
                # the earliest row repeating an earlier one, and that one.
                js = np.flatnonzero(same)
                j = int(js[np.argmin(order[js + 1])])
                second = int(order[j + 1])
                while j > 0 and same[j - 1]:
                    j -= 1
                first = int(order[j])
                raise DataFormatError(
                    f"{_where(src)}{label(second)}: duplicate of {label(first)} (same "
                    f"direction, segment, dof, level and freq_hz={self.freq_hz[second]})"
                )

    # -- construction -------------------------------------------------------------------

    @classmethod
    def from_rows(cls, rows: Iterable[Mapping[str, Any]]) -> FrfData:
        """Build from an iterable of mappings with the ``frf.csv`` column names.

        ``level_rms`` may be omitted or ``None`` (read as NaN).
        """
        rows = list(rows)
        cols: dict[str, list[Any]] = {c: [] for c in FRF_COLUMNS + FRF_OPTIONAL_COLUMNS}
        for i, r in enumerate(rows):
            missing = [c for c in FRF_COLUMNS if c not in r]
            if missing:
                raise DataFormatError(f"row {i}: missing column(s) {missing}")
            unknown = [c for c in r if c not in cols]
            if unknown:
                raise DataFormatError(
                    f"row {i}: unknown column(s) {unknown}; allowed: "
                    f"{list(FRF_COLUMNS + FRF_OPTIONAL_COLUMNS)}"
                )
            for c in FRF_COLUMNS:
                cols[c].append(r[c])
            for c in FRF_OPTIONAL_COLUMNS:
                v = r.get(c)
                cols[c].append(np.nan if v is None else v)
        return cls(**{c: np.asarray(v) for c, v in cols.items()})

    @classmethod
    def concat(cls, parts: Iterable[FrfData]) -> FrfData:
        """Concatenate several tables (validated again, e.g. for duplicates)."""
        parts = list(parts)
        if not parts:
            raise DataFormatError("FrfData.concat needs at least one table")
        return cls(
            **{
                c: np.concatenate([getattr(p, c) for p in parts])
                for c in FRF_COLUMNS + FRF_OPTIONAL_COLUMNS
            }
        )

    # -- queries -----------------------------------------------------------------------

    def __len__(self) -> int:
        return int(self.freq_hz.size)

    @property
    def has_level(self) -> bool:
        """True if any row carries a ``level_rms`` value."""
        return bool(np.any(np.isfinite(self.level_rms)))

    @property
    def has_n_averages(self) -> bool:
        """True if any row carries an ``n_averages`` value."""
        return bool(np.any(np.isfinite(self.n_averages)))

    def _key(self, i: int) -> tuple:
        lv = self.level_rms[i]
        return (
            str(self.direction[i]),
            str(self.segment[i]),
            str(self.dof[i]),
            None if np.isnan(lv) else float(lv),
        )

    def _groups(self) -> dict[tuple, np.ndarray]:
        """Channel key -> row indices, keys in order of first appearance."""
        groups: dict[tuple, list[int]] = {}
        for i in range(len(self)):
            groups.setdefault(self._key(i), []).append(i)
        return {k: np.asarray(v, dtype=int) for k, v in groups.items()}

    def channels(self) -> list[tuple]:
        """Unique channel keys in order of first appearance.

        Returns
        -------
        list of tuple
            ``(direction, segment, dof)`` when no row has a level, else
            ``(direction, segment, dof, level_rms)`` with ``None`` for rows without level.
        """
        keys = list(self._groups())
        if self.has_level:
            return keys
        return [k[:3] for k in keys]

    def select(
        self,
        direction: str | None = None,
        segment: str | None = None,
        dof: str | None = None,
        level: float | None = None,
        level_rtol: float = 1e-6,
    ) -> FrfData:
        """Rows matching all given criteria (``None`` = any), sorted by channel then frequency.

        Parameters
        ----------
        direction, segment, dof : str, optional
            Exact labels; unknown labels raise :class:`DataFormatError`.
        level : float, optional
            Seat RMS level (m/s^2) matched with relative tolerance ``level_rtol``.
        """
        mask = np.ones(len(self), dtype=bool)
        for name, value, allowed in (
            ("direction", direction, DIRECTIONS),
            ("segment", segment, SEGMENTS),
            ("dof", dof, DOFS),
        ):
            if value is None:
                continue
            if value not in allowed:
                raise DataFormatError(
                    f"select(): unknown {name} '{value}', expected one of {list(allowed)}"
                )
            mask &= getattr(self, name) == value
        if level is not None:
            if not (isinstance(level, int | float) and math.isfinite(level) and level > 0):
                raise DataFormatError(f"select(): level must be a positive number, got {level!r}")
            with np.errstate(invalid="ignore"):
                mask &= np.abs(self.level_rms - level) <= level_rtol * level
        return self._take(np.flatnonzero(mask))

    def _take(self, idx: np.ndarray) -> FrfData:
        """Rows ``idx`` grouped by channel (first-appearance order), sorted by frequency."""
        idx = np.asarray(idx, dtype=int)
        order: dict[tuple, int] = {}
        for i in idx:
            order.setdefault(self._key(int(i)), len(order))
        idx = np.asarray(
            sorted(idx, key=lambda i: (order[self._key(int(i))], self.freq_hz[i])), dtype=int
        )
        return FrfData(**{c: getattr(self, c)[idx] for c in FRF_COLUMNS + FRF_OPTIONAL_COLUMNS})

    def get(
        self,
        direction: str,
        segment: str,
        dof: str,
        level: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Arrays ``(freq_hz, gain, phase_deg, coherence)`` of exactly one channel.

        Raises
        ------
        DataFormatError
            If no row or several channels (e.g. several levels) match.
        """
        sub = self.select(direction, segment, dof, level)
        if len(sub) == 0:
            raise DataFormatError(
                f"no FRF rows for direction={direction}, segment={segment}, dof={dof}"
                + ("" if level is None else f", level={level}")
            )
        chans = sub.channels()
        if len(chans) > 1:
            raise DataFormatError(
                f"{len(chans)} channels match direction={direction}, segment={segment}, "
                f"dof={dof}: {chans}; pass level= to choose one"
            )
        return sub.freq_hz, sub.gain, sub.phase_deg, sub.coherence

    # -- output ------------------------------------------------------------------------

    def to_csv(self, path: str | Path) -> Path:
        """Write ``frf.csv`` (the optional columns only when some row has a value)."""
        path = Path(path)
        cols = (list(FRF_COLUMNS) + (["level_rms"] if self.has_level else [])
                + (["n_averages"] if self.has_n_averages else []))
        with path.open("w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(cols)
            for i in range(len(self)):
                row = [
                    self.direction[i],
                    self.segment[i],
                    self.dof[i],
                    _fmt(self.freq_hz[i]),
                    _fmt(self.gain[i]),
                    _fmt(self.phase_deg[i]),
                    _fmt(self.coherence[i]),
                ]
                if self.has_level:
                    row.append(_fmt(self.level_rms[i]))
                if self.has_n_averages:
                    row.append(_fmt(self.n_averages[i]))
                w.writerow(row)
        return path


def read_frf(path: str | Path) -> FrfData:
    """Read and validate an ``frf.csv`` file.

    Parameters
    ----------
    path : str or Path
        CSV file with header ``direction,segment,dof,freq_hz,gain,phase_deg,coherence``
        and optional ``level_rms``.

    Returns
    -------
    FrfData

    Raises
    ------
    DataFormatError
        Missing or unknown columns, unknown labels, non-numeric / NaN / inf values,
        negative gain, coherence outside [0, 1], non-positive frequency or level,
        duplicated rows.  The message names the file line and column.
    FileNotFoundError
        If ``path`` does not exist.
    """
    path = Path(path)
    source = str(path)
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    skipped = 0
    while skipped < len(lines) and lines[skipped].lstrip().startswith("#"):
        skipped += 1
    header, body = _read_csv_rows("".join(lines[skipped:]), source, skipped + 1)
    header_line = skipped + 1
    missing = [c for c in FRF_COLUMNS if c not in header]
    if missing:
        raise DataFormatError(
            f"{_where(source, header_line)}missing column(s) {missing}; header must be "
            f"{','.join(FRF_COLUMNS)}[,level_rms][,n_averages]"
        )
    unknown = [c for c in header if c not in FRF_COLUMNS + FRF_OPTIONAL_COLUMNS]
    if unknown:
        raise DataFormatError(
            f"{_where(source, header_line)}unknown column(s) {unknown}; allowed: "
            f"{list(FRF_COLUMNS + FRF_OPTIONAL_COLUMNS)}"
        )
    if not body:
        raise DataFormatError(f"{_where(source)}no data rows after the header")
    first = header_line + 1
    col = {h: [r[j] for r in body] for j, h in enumerate(header)}
    data: dict[str, Any] = {}
    for name in ("direction", "segment", "dof"):
        data[name] = np.array([c.strip() for c in col[name]], dtype=str)
    for name in ("freq_hz", "gain", "phase_deg", "coherence"):
        data[name] = _to_float_column(col[name], name, source, first)
    for name in FRF_OPTIONAL_COLUMNS:
        if name in col:
            data[name] = _to_float_column(col[name], name, source, first, allow_empty=True)
    labels = np.array([f"line {first + i}" for i in range(len(body))], dtype=object)
    return FrfData(**data, _row_labels=labels, _source=source)


# ------------------------------------------------------------------------------------------
# time series
# ------------------------------------------------------------------------------------------


def _check_timeseries_columns(
    names: Sequence[str], source: str | None = None, line: int | None = None
) -> None:
    """``t``, all seat columns, only ``<segment>_<dof>`` otherwise, no duplicates."""
    where = _where(source, line)
    dup = sorted({h for h in names if list(names).count(h) > 1})
    if dup:
        raise DataFormatError(f"{where}duplicate column(s) {dup}")
    if "t" not in names:
        raise DataFormatError(f"{where}missing time column 't'")
    missing = [c for c in SEAT_COLUMNS if c not in names]
    if missing:
        raise DataFormatError(f"{where}missing seat acceleration column(s) {missing}")
    for h in names:
        if h == "t" or h in SEAT_COLUMNS:
            continue
        try:
            parse_channel_name(h)
        except DataFormatError as exc:
            raise DataFormatError(f"{_where(source, line, h)}unknown column: {exc}") from None


@dataclass(eq=False)
class TimeSeriesData:
    """Seat acceleration and body motion time histories.

    Attributes
    ----------
    t : numpy.ndarray, shape (N,)
        Time (s), uniformly sampled, increasing.
    seat_acc : numpy.ndarray, shape (N, 3)
        Seat acceleration along x, y, z (m/s^2).
    channels : dict of str to numpy.ndarray
        ``<segment>_<dof>`` -> motion in file units (m, or deg for rotational dofs).
    meta : dict
        Metadata, e.g. ``{"level_rms": 0.3, "direction": "z"}``.

    Notes
    -----
    The constructor checks shapes, finiteness, channel names and uniform sampling
    (relative tolerance :data:`SAMPLING_RTOL`).  Record length is checked by
    :meth:`check_length` (called by :func:`read_timeseries`), so short simulated records
    can still be held in memory.
    """

    t: np.ndarray
    seat_acc: np.ndarray
    channels: dict[str, np.ndarray] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    _source: str | None = field(default=None, repr=False, compare=False)
    _first_data_line: int | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        src = self._source
        try:
            t = np.asarray(self.t, dtype=np.float64)
            acc = np.asarray(self.seat_acc, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise DataFormatError(f"{_where(src)}t / seat_acc must be numeric: {exc}") from None
        if t.ndim != 1 or t.size < 2:
            raise DataFormatError(
                f"{_where(src)}'t' must be 1-D with >= 2 samples, got shape {t.shape}"
            )
        n = t.size
        if acc.shape != (n, 3):
            raise DataFormatError(
                f"{_where(src)}seat acceleration must have shape ({n}, 3), got {acc.shape}"
            )
        self.t, self.seat_acc = t, acc

        def row(i: int) -> str:
            if self._first_data_line is not None:
                return f"line {self._first_data_line + i}"
            return f"row {i}"

        def check_finite(arr: np.ndarray, column: str) -> None:
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                i = int(bad[0])
                raise DataFormatError(
                    f"{_where(src)}{row(i)}, column '{column}': non-finite value {arr[i]}"
                )

        check_finite(t, "t")
        for j, c in enumerate(SEAT_COLUMNS):
            check_finite(acc[:, j], c)
        chans: dict[str, np.ndarray] = {}
        for name, values in self.channels.items():
            try:
                parse_channel_name(name)
            except DataFormatError as exc:
                raise DataFormatError(f"{_where(src)}{exc}") from None
            try:
                arr = np.asarray(values, dtype=np.float64)
            except (TypeError, ValueError):
                raise DataFormatError(
                    f"{_where(src, column=name)}channel values are not numeric"
                ) from None
            if arr.shape != (n,):
                raise DataFormatError(
                    f"{_where(src, column=name)}channel has shape {arr.shape}, expected ({n},)"
                )
            check_finite(arr, name)
            chans[name] = arr
        self.channels = chans
        # sampling: strictly increasing and uniform
        dt = np.diff(t)
        bad = np.flatnonzero(dt <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise DataFormatError(
                f"{_where(src)}{row(i)}, column 't': time is not increasing "
                f"(t={t[i]!r} after t={t[i - 1]!r})"
            )
        dt_med = float(np.median(dt))
        dev = np.abs(dt - dt_med)
        bad = np.flatnonzero(dev > SAMPLING_RTOL * dt_med)
        if bad.size:
            i = int(bad[0]) + 1
            raise DataFormatError(
                f"{_where(src)}{row(i)}, column 't': non-uniform sampling, step "
                f"{dt[i - 1]!r} s differs from the median step {dt_med!r} s by more than "
                f"{SAMPLING_RTOL:g} (relative)"
            )
        self.meta = _validate_meta(self.meta or {}, _where(src))

    @classmethod
    def from_columns(
        cls,
        names: Sequence[str],
        data: Any,
        meta: Mapping[str, Any] | None = None,
    ) -> TimeSeriesData:
        """Build from column names (``timeseries.csv`` header) and a 2-D data array.

        Parameters
        ----------
        names : sequence of str
            Column names: ``t``, ``seat_ax``, ``seat_ay``, ``seat_az`` and any
            ``<segment>_<dof>`` channels, in any order.
        data : array_like, shape (N, len(names))
            Values in file units (s, m/s^2, m, deg).
        meta : mapping, optional
            Metadata such as ``{"level_rms": 0.3, "direction": "z"}``.

        Raises
        ------
        DataFormatError
            Missing/unknown/duplicate columns, a shape mismatch, or any constructor check.
        """
        names = [str(n) for n in names]
        _check_timeseries_columns(names)
        try:
            arr = np.asarray(data, dtype=np.float64)
        except (TypeError, ValueError):
            raise DataFormatError("data must be a numeric 2-D array") from None
        if arr.ndim != 2 or arr.shape[1] != len(names):
            raise DataFormatError(
                f"data must have shape (N, {len(names)}) to match the column names, got {arr.shape}"
            )
        col = {n: arr[:, j] for j, n in enumerate(names)}
        return cls(
            t=col["t"],
            seat_acc=np.column_stack([col[c] for c in SEAT_COLUMNS]),
            channels={n: col[n] for n in names if n != "t" and n not in SEAT_COLUMNS},
            meta=dict(meta or {}),
        )

    # -- properties --------------------------------------------------------------------

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return int(self.t.size)

    @property
    def dt(self) -> float:
        """Sampling interval (s), the median time step."""
        return float(np.median(np.diff(self.t)))

    @property
    def fs(self) -> float:
        """Sample rate (Hz)."""
        return 1.0 / self.dt

    @property
    def sample_rate(self) -> float:
        """Alias of :attr:`fs` (Hz)."""
        return self.fs

    @property
    def duration(self) -> float:
        """Record length N * dt (s)."""
        return self.n_samples * self.dt

    @property
    def excited_directions(self) -> tuple[str, ...] | None:
        """Excited axes from ``meta['direction']`` (e.g. ``('z',)``), or None if not given."""
        d = self.meta.get("direction")
        return None if d is None else tuple(d)

    def seat(self, axis: str) -> np.ndarray:
        """Seat acceleration along ``axis`` in {'x', 'y', 'z'} (m/s^2)."""
        if axis not in DIRECTIONS:
            raise DataFormatError(f"unknown axis '{axis}', expected one of {list(DIRECTIONS)}")
        return self.seat_acc[:, DIRECTIONS.index(axis)]

    def check_length(
        self, min_duration: float = MIN_DURATION_S, min_samples: int = MIN_SAMPLES
    ) -> None:
        """Raise :class:`DataFormatError` if the record is too short (says which limit)."""
        src = _where(self._source)
        if self.n_samples < min_samples:
            raise DataFormatError(
                f"{src}record too short: {self.n_samples} samples, fewer than the minimum "
                f"{min_samples} samples"
            )
        if self.duration < min_duration * (1 - SAMPLING_RTOL):
            raise DataFormatError(
                f"{src}record too short: {self.duration:.4g} s, less than the minimum "
                f"{min_duration:g} s"
            )

    # -- output ------------------------------------------------------------------------

    def to_csv(self, path: str | Path, meta: str = "header") -> Path:
        """Write ``timeseries.csv``.

        Parameters
        ----------
        path : str or Path
            Output file.
        meta : {'header', 'sidecar', 'none'}
            Where to store :attr:`meta` (if not empty): a ``# {json}`` first line, or a
            ``meta.json`` file next to ``path``.
        """
        if meta not in ("header", "sidecar", "none"):
            raise ValueError(f"meta must be 'header', 'sidecar' or 'none', got {meta!r}")
        path = Path(path)
        names = ["t", *SEAT_COLUMNS, *self.channels]
        cols = [self.t, *self.seat_acc.T, *self.channels.values()]
        with path.open("w", newline="", encoding="utf-8") as fh:
            if self.meta and meta == "header":
                fh.write("# " + json.dumps(self.meta) + "\n")
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(names)
            for i in range(self.n_samples):
                w.writerow([repr(float(c[i])) for c in cols])
        if self.meta and meta == "sidecar":
            (path.parent / META_FILENAME).write_text(json.dumps(self.meta, indent=2) + "\n")
        return path


def _parse_comment_meta(line: str, source: str) -> dict[str, Any]:
    body = line.lstrip()[1:].strip()
    if not body:
        return {}
    try:
        meta = json.loads(body)
    except json.JSONDecodeError as exc:
        raise DataFormatError(
            f"{_where(source, 1)}comment header is not valid JSON ({exc.msg}); expected e.g. "
            '# {"level_rms": 0.3, "direction": "z"}'
        ) from None
    if not isinstance(meta, dict):
        raise DataFormatError(f"{_where(source, 1)}comment header JSON must be an object")
    return meta


def read_timeseries(
    path: str | Path,
    min_duration: float = MIN_DURATION_S,
    min_samples: int = MIN_SAMPLES,
) -> TimeSeriesData:
    """Read and validate a ``timeseries.csv`` file (plus optional sidecar ``meta.json``).

    Parameters
    ----------
    path : str or Path
        CSV file with columns ``t, seat_ax, seat_ay, seat_az`` and ``<segment>_<dof>``.
    min_duration : float
        Minimum record length (s).
    min_samples : int
        Minimum number of samples.

    Returns
    -------
    TimeSeriesData

    Raises
    ------
    DataFormatError
        Missing ``t`` or seat columns, unknown or duplicate columns, non-numeric / NaN / inf
        values, non-increasing or non-uniform time, too-short records, invalid metadata or
        conflicting header/sidecar metadata.
    """
    path = Path(path)
    source = str(path)
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    meta: dict[str, Any] = {}
    skipped = 0
    if lines and lines[0].lstrip().startswith("#"):
        meta = _parse_comment_meta(lines[0], source)
        skipped = 1
    while skipped < len(lines) and lines[skipped].lstrip().startswith("#"):
        skipped += 1  # further comment lines are ignored
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
    header_line = skipped + 1
    header, body = _read_csv_rows("".join(lines[skipped:]), source, header_line)
    _check_timeseries_columns(header, source, header_line)
    if not body:
        raise DataFormatError(f"{_where(source)}no data rows after the header")
    first = header_line + 1
    cols = {
        h: _to_float_column([r[j] for r in body], h, source, first) for j, h in enumerate(header)
    }
    ts = TimeSeriesData(
        t=cols["t"],
        seat_acc=np.column_stack([cols[c] for c in SEAT_COLUMNS]),
        channels={h: cols[h] for h in header if h != "t" and h not in SEAT_COLUMNS},
        meta=meta,
        _source=source,
        _first_data_line=first,
    )
    ts.check_length(min_duration, min_samples)
    return ts


def read_data_dir(
    directory: str | Path, **timeseries_kwargs: Any
) -> tuple[FrfData | None, TimeSeriesData | None]:
    """Read ``frf.csv`` and/or ``timeseries.csv`` from a folder.

    Returns
    -------
    tuple
        ``(frf, timeseries)``; either may be ``None`` when its file is absent.

    Raises
    ------
    FileNotFoundError
        If ``directory`` is not a folder or contains neither file.
    """
    d = Path(directory)
    if not d.is_dir():
        raise FileNotFoundError(f"data directory not found: {d}")
    f_frf, f_ts = d / FRF_FILENAME, d / TIMESERIES_FILENAME
    if not f_frf.is_file() and not f_ts.is_file():
        raise FileNotFoundError(f"{d}: contains neither {FRF_FILENAME} nor {TIMESERIES_FILENAME}")
    frf = read_frf(f_frf) if f_frf.is_file() else None
    ts = read_timeseries(f_ts, **timeseries_kwargs) if f_ts.is_file() else None
    return frf, ts


# ------------------------------------------------------------------------------------------
# unit sanity checks
# ------------------------------------------------------------------------------------------

#: In-axis translational transmissibility (m/m) is O(1): these bounds flag a ~1000x slip.
_TRANS_MEDIAN_HIGH = 50.0
_TRANS_MEDIAN_LOW = 0.02
#: Rotational gains in deg/m: the most responsive channel should exceed this if in deg.
_ROT_MAX_MEDIAN_LOW = 3.0
_ROT_MEDIAN_HIGH = 5000.0


def check_units(frf: FrfData) -> list[str]:
    """Plausibility checks on FRF gain/phase units; returns human-readable warnings.

    No Python warning is emitted; an empty list means nothing looks wrong.

    Checks
    ------
    * in-axis translational channels (dof == direction): median gain > 50 or < 0.02 m/m
      suggests millimetres mixed with metres (factor 1000);
    * any translational channel with median gain > 50 m/m;
    * rotational channels: if even the most responsive one has median gain < 3 deg/m the
      gains are probably rad/m (factor 57.3) or deg/mm (factor 1000); a median > 5000 deg/m
      suggests per-mm seat displacement or millidegrees;
    * phase: all ``|phase_deg| <= pi`` over >= 20 rows suggests radians.

    Parameters
    ----------
    frf : FrfData

    Returns
    -------
    list of str
    """
    out: list[str] = []
    rot_medians: list[tuple[float, tuple]] = []
    for key, idx in frf._groups().items():
        d, s, q, lv = key
        med = float(np.median(frf.gain[idx]))
        name = f"{d}->{s}_{q}" + ("" if lv is None else f" @ {lv:g} m/s^2")
        if q in TRANSLATIONAL_DOFS:
            if med > _TRANS_MEDIAN_HIGH:
                out.append(
                    f"{name}: median translational gain {med:.3g} m/m is > "
                    f"{_TRANS_MEDIAN_HIGH:g}; output probably in mm while seat displacement is "
                    "in m (expected m/m)"
                )
            elif q == d and med < _TRANS_MEDIAN_LOW:
                out.append(
                    f"{name}: median in-axis gain {med:.3g} m/m is < {_TRANS_MEDIAN_LOW:g}; "
                    "seat displacement probably in mm while output is in m (expected m/m)"
                )
        else:
            rot_medians.append((med, key))
            if med > _ROT_MEDIAN_HIGH:
                out.append(
                    f"{name}: median rotational gain {med:.3g} deg/m is > "
                    f"{_ROT_MEDIAN_HIGH:g}; seat displacement probably in mm or rotation in "
                    "millidegrees (expected deg/m)"
                )
    if rot_medians:
        best, key = max(rot_medians, key=lambda m: m[0])
        if best < _ROT_MAX_MEDIAN_LOW:
            out.append(
                f"rotational gains: the largest channel median is {best:.3g} deg/m (< "
                f"{_ROT_MAX_MEDIAN_LOW:g}); rotations look like rad/m (x 57.3 to get deg/m) or "
                "deg/mm (expected deg per metre of seat displacement)"
            )
    if len(frf) >= 20 and float(np.max(np.abs(frf.phase_deg))) <= math.pi + 1e-9:
        out.append(
            f"phase_deg: all {len(frf)} values lie within +-pi; phases look like radians "
            "(expected degrees)"
        )
    return out
