"""The ``timeseries.csv`` format: :class:`TimeSeriesData` and :func:`read_timeseries`.

Time histories on seat-aligned axes, with optional metadata in a one-line JSON comment
(parsed here) or a sidecar ``meta.json`` (:mod:`.metadata`); the specification is in
:mod:`ehm_drake.analysis.formats`.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .common import (
    DIRECTIONS,
    DataFormatError,
    location,
    parse_channel_name,
    read_csv_rows,
    to_float_column,
)
from .metadata import META_FILENAME, merge_sidecar_meta, validate_meta

__all__ = [
    "SEAT_COLUMNS",
    "MIN_DURATION_S",
    "MIN_SAMPLES",
    "SAMPLING_RTOL",
    "TimeSeriesData",
    "read_timeseries",
]

SEAT_COLUMNS: tuple[str, ...] = ("seat_ax", "seat_ay", "seat_az")

#: Minimum record length accepted by :func:`read_timeseries` (s).
MIN_DURATION_S: float = 10.0
#: Minimum number of samples accepted by :func:`read_timeseries`.
MIN_SAMPLES: int = 256
#: Relative tolerance on the sampling interval (uniform sampling check).
SAMPLING_RTOL: float = 1e-3

TIMESERIES_FILENAME = "timeseries.csv"


def _check_timeseries_columns(
    names: Sequence[str], source: str | None = None, line: int | None = None
) -> None:
    """``t``, all seat columns, only ``<segment>_<dof>`` otherwise, no duplicates."""
    where = location(source, line)
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
            raise DataFormatError(f"{location(source, line, h)}unknown column: {exc}") from None


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
            raise DataFormatError(f"{location(src)}t / seat_acc must be numeric: {exc}") from None
        if t.ndim != 1 or t.size < 2:
            raise DataFormatError(
                f"{location(src)}'t' must be 1-D with >= 2 samples, got shape {t.shape}"
            )
        n = t.size
        if acc.shape != (n, 3):
            raise DataFormatError(
                f"{location(src)}seat acceleration must have shape ({n}, 3), got {acc.shape}"
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
                    f"{location(src)}{row(i)}, column '{column}': non-finite value {arr[i]}"
                )

        check_finite(t, "t")
        for j, c in enumerate(SEAT_COLUMNS):
            check_finite(acc[:, j], c)
        chans: dict[str, np.ndarray] = {}
        for name, values in self.channels.items():
            try:
                parse_channel_name(name)
            except DataFormatError as exc:
                raise DataFormatError(f"{location(src)}{exc}") from None
            try:
                arr = np.asarray(values, dtype=np.float64)
            except (TypeError, ValueError):
                raise DataFormatError(
                    f"{location(src, column=name)}channel values are not numeric"
                ) from None
            if arr.shape != (n,):
                raise DataFormatError(
                    f"{location(src, column=name)}channel has shape {arr.shape}, expected ({n},)"
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
                f"{location(src)}{row(i)}, column 't': time is not increasing "
                f"(t={t[i]!r} after t={t[i - 1]!r})"
            )
        dt_med = float(np.median(dt))
        dev = np.abs(dt - dt_med)
        bad = np.flatnonzero(dev > SAMPLING_RTOL * dt_med)
        if bad.size:
            i = int(bad[0]) + 1
            raise DataFormatError(
                f"{location(src)}{row(i)}, column 't': non-uniform sampling, step "
                f"{dt[i - 1]!r} s differs from the median step {dt_med!r} s by more than "
                f"{SAMPLING_RTOL:g} (relative)"
            )
        self.meta = validate_meta(self.meta or {}, location(src))

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
        src = location(self._source)
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
            f"{location(source, 1)}comment header is not valid JSON ({exc.msg}); expected e.g. "
            '# {"level_rms": 0.3, "direction": "z"}'
        ) from None
    if not isinstance(meta, dict):
        raise DataFormatError(f"{location(source, 1)}comment header JSON must be an object")
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
    merge_sidecar_meta(meta, path, source)
    header_line = skipped + 1
    header, body = read_csv_rows("".join(lines[skipped:]), source, header_line)
    _check_timeseries_columns(header, source, header_line)
    if not body:
        raise DataFormatError(f"{location(source)}no data rows after the header")
    first = header_line + 1
    cols = {
        h: to_float_column([r[j] for r in body], h, source, first) for j, h in enumerate(header)
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
