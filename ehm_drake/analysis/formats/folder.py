"""A folder a lab hands over: ``frf.csv`` and/or ``timeseries.csv`` (:func:`read_data_dir`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .frf import FRF_FILENAME, FrfData, read_frf
from .timeseries import TIMESERIES_FILENAME, TimeSeriesData, read_timeseries

__all__ = ["read_data_dir"]


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
