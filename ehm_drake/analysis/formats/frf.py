"""The ``frf.csv`` table: :class:`FrfData`, :func:`read_frf` and :func:`check_units`.

Transmissibilities, one row per channel and frequency bin; the column specification is in
:mod:`ehm_drake.analysis.formats`.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .common import (
    DIRECTIONS,
    DOFS,
    SEGMENTS,
    TRANSLATIONAL_DOFS,
    DataFormatError,
    location,
    read_csv_rows,
    to_float_column,
)

__all__ = ["FRF_COLUMNS", "FRF_OPTIONAL_COLUMNS", "FrfData", "read_frf", "check_units"]

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

FRF_FILENAME = "frf.csv"


def _fmt(x: float) -> str:
    """Shortest float text that round-trips exactly; '' for NaN (absent)."""
    if isinstance(x, float) and math.isnan(x):
        return ""
    return repr(float(x))


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
                    f"{location(src)}FrfData field '{name}' has {arr.size} rows, expected {n}"
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
                    f"{location(src)}FrfData field '{name}' is not numeric: {exc}"
                ) from None
            if arr.size != n:
                raise DataFormatError(
                    f"{location(src)}FrfData field '{name}' has {arr.size} rows, expected {n}"
                )
            setattr(self, name, arr)
        labels = self._row_labels

        def label(i: int) -> str:
            return str(labels[i]) if labels is not None else f"row {i}"

        def fail(idx: np.ndarray, column: str, msg: str) -> None:
            i = int(idx[0])
            raise DataFormatError(f"{location(src)}{label(i)}, column '{column}': {msg(i)}")

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
                    f"{location(src)}{label(second)}: duplicate of {label(first)} (same "
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

    def lowest_welch_bins(self) -> np.ndarray:
        """Rows that are one of the first two bins of their channel's Welch grid: f < 2.5 df,
        df the spacing of the channel's frequencies (a table that starts higher has none).

        The Hann window's main lobe spans +-2 df, so the first bin's reaches 0 Hz and the
        second bin's reaches below the lowest excited frequency (the first bin, at the
        project's 0.1 Hz band edge and 10 s segments): H1 there averages T over a window
        weighted towards higher frequencies, biased wherever T rises steeply.  Where the gain
        rises as f^2 (every rotation under a translation at low frequency) the first bin is
        about twice the truth and the second about 12% above it on average, the bins above
        within 2.5% (mean ln ratio over 8 noise-free 120 s records of a flat 0.1-12 Hz
        excitation, 10 s segments: tests/test_spectral.py).  On 30 s records the second
        bin's bias hides in its coherence-based error; on 120 s records of the trunk's
        fore-and-aft motion under vertical vibration it reached 1.1-1.45 times the subject's
        own response, up to five times that error.  Neither the gap diagnosis nor the fit
        uses these rows."""
        out = np.zeros(len(self.freq_hz), bool)
        for idx in self._groups().values():
            f = np.unique(self.freq_hz[idx])
            if f.size < 2:
                continue
            df = float(np.min(np.diff(f)))
            out[idx] = self.freq_hz[idx] < 2.5 * df
        return out

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
    header, body = read_csv_rows("".join(lines[skipped:]), source, skipped + 1)
    header_line = skipped + 1
    missing = [c for c in FRF_COLUMNS if c not in header]
    if missing:
        raise DataFormatError(
            f"{location(source, header_line)}missing column(s) {missing}; header must be "
            f"{','.join(FRF_COLUMNS)}[,level_rms][,n_averages]"
        )
    unknown = [c for c in header if c not in FRF_COLUMNS + FRF_OPTIONAL_COLUMNS]
    if unknown:
        raise DataFormatError(
            f"{location(source, header_line)}unknown column(s) {unknown}; allowed: "
            f"{list(FRF_COLUMNS + FRF_OPTIONAL_COLUMNS)}"
        )
    if not body:
        raise DataFormatError(f"{location(source)}no data rows after the header")
    first = header_line + 1
    col = {h: [r[j] for r in body] for j, h in enumerate(header)}
    data: dict[str, Any] = {}
    for name in ("direction", "segment", "dof"):
        data[name] = np.array([c.strip() for c in col[name]], dtype=str)
    for name in ("freq_hz", "gain", "phase_deg", "coherence"):
        data[name] = to_float_column(col[name], name, source, first)
    for name in FRF_OPTIONAL_COLUMNS:
        if name in col:
            data[name] = to_float_column(col[name], name, source, first, allow_empty=True)
    labels = np.array([f"line {first + i}" for i in range(len(body))], dtype=object)
    return FrfData(**data, _row_labels=labels, _source=source)


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
