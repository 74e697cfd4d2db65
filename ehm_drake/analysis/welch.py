"""Signal preparation for the Welch-averaged estimators of :mod:`.spectral`.

* :func:`band_filter` -- zero-phase Butterworth band-pass (``sosfiltfilt``), applied alike
  to inputs and outputs so that it cancels in the FRF ratio (the reference experiment
  filters seat input and body responses with a 0-12 Hz Butterworth band-pass);
* :func:`default_nperseg` -- the default Welch segment length (about 0.075 Hz resolution,
  at least 8 averages);
* :func:`segmentation` and :func:`segment_ffts` -- the segments (window, 50 % overlap by
  default, per-segment detrending) and their FFTs, shared by every estimator;
* :func:`check_fs` and :func:`as_signal` -- checks of a sample rate and of a signal array.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import signal

__all__ = [
    "DEFAULT_BAND",
    "DEFAULT_RESOLUTION_HZ",
    "MIN_AVERAGES",
    "MIN_NPERSEG",
    "band_filter",
    "default_nperseg",
]

#: Band of the paper's Butterworth band-pass (Hz); 0.05 Hz instead of 0 removes drift.
DEFAULT_BAND: tuple[float, float] = (0.05, 12.0)
#: Target frequency resolution of the default Welch segment (Hz).
DEFAULT_RESOLUTION_HZ: float = 0.075
#: Minimum number of Welch averages the default segment length aims for.
MIN_AVERAGES: int = 8
#: Smallest segment length accepted.
MIN_NPERSEG: int = 16


# ------------------------------------------------------------------------------------------
# input checking and segments
# ------------------------------------------------------------------------------------------


def check_fs(fs: float) -> float:
    """``fs`` as a float, checked to be a finite positive sample rate (Hz)."""
    if isinstance(fs, bool) or not isinstance(fs, int | float | np.floating | np.integer):
        raise TypeError(f"fs must be a number (Hz), got {type(fs).__name__}")
    fs = float(fs)
    if not math.isfinite(fs) or fs <= 0:
        raise ValueError(f"fs must be a finite positive sample rate (Hz), got {fs}")
    return fs


def as_signal(x: Any, name: str, ndim: tuple[int, ...] = (1, 2)) -> np.ndarray:
    """``x`` as a finite real float64 array, time along axis 0 (``name`` in messages)."""
    if np.iscomplexobj(x):
        raise TypeError(f"{name} must be real, got complex values")
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a real numeric array") from None
    if arr.ndim not in ndim:
        raise ValueError(f"{name} must have ndim in {ndim} (time along axis 0), got {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError(f"{name} is empty")
    bad = np.argwhere(~np.isfinite(arr))
    if bad.size:
        raise ValueError(f"{name} has a non-finite value at index {tuple(int(i) for i in bad[0])}")
    return arr


def _check_band(band: Sequence[float | None], fs: float) -> tuple[float | None, float]:
    if len(band) != 2:
        raise ValueError(f"band must be (low_hz, high_hz), got {band!r}")
    lo, hi = band
    nyq = fs / 2
    if hi is None or not (0 < float(hi) < nyq):
        raise ValueError(f"band high edge must satisfy 0 < high < fs/2 = {nyq:g} Hz, got {hi!r}")
    if lo is not None and float(lo) != 0.0:
        if not (0 < float(lo) < float(hi)):
            raise ValueError(f"band low edge must satisfy 0 < low < high, got band={band!r}")
        return float(lo), float(hi)
    return None, float(hi)


def default_nperseg(n: int, fs: float) -> int:
    """Default Welch segment length.

    About ``fs / 0.075`` samples (0.075 Hz resolution, inside the 0.05-0.1 Hz target), but at
    most ``n // 8`` so that 50 % overlap gives at least ~15 averages (>= 8).

    Raises
    ------
    ValueError
        If the record is too short for a segment of at least 16 samples.
    """
    target = int(round(fs / DEFAULT_RESOLUTION_HZ))
    nperseg = min(target, n // MIN_AVERAGES)
    if nperseg < MIN_NPERSEG:
        raise ValueError(
            f"record too short for spectral estimation: {n} samples gives segments of "
            f"{nperseg} < {MIN_NPERSEG} samples with >= {MIN_AVERAGES} averages"
        )
    return nperseg


def segmentation(
    n: int, fs: float, nperseg: int | None, noverlap: int | None
) -> tuple[int, int, int]:
    """Checked ``(nperseg, noverlap, n_averages)`` for a record of ``n`` samples."""
    if nperseg is None:
        nperseg = default_nperseg(n, fs)
    nperseg = int(nperseg)
    if nperseg < MIN_NPERSEG:
        raise ValueError(f"nperseg must be >= {MIN_NPERSEG}, got {nperseg}")
    if nperseg > n:
        raise ValueError(f"nperseg={nperseg} exceeds the record length of {n} samples")
    if noverlap is None:
        noverlap = nperseg // 2
    noverlap = int(noverlap)
    if not 0 <= noverlap < nperseg:
        raise ValueError(f"noverlap must satisfy 0 <= noverlap < nperseg={nperseg}, got {noverlap}")
    n_avg = 1 + (n - nperseg) // (nperseg - noverlap)
    return nperseg, noverlap, n_avg


def segment_ffts(
    z: np.ndarray,
    fs: float,
    nperseg: int,
    noverlap: int,
    window: str | tuple | np.ndarray,
    detrend: str | bool,
) -> tuple[np.ndarray, np.ndarray]:
    """FFTs of windowed, detrended segments: returns f (nf,), Z (nseg, nf, q)."""
    step = nperseg - noverlap
    n_avg = 1 + (z.shape[0] - nperseg) // step
    starts = np.arange(n_avg) * step
    idx = starts[:, None] + np.arange(nperseg)[None, :]
    seg = z[idx]  # (nseg, nperseg, q)
    if detrend in ("constant", "linear"):
        seg = signal.detrend(seg, axis=1, type=detrend)
    elif detrend not in (False, None, "none"):
        raise ValueError(f"detrend must be 'constant', 'linear' or False, got {detrend!r}")
    if isinstance(window, np.ndarray):
        win = np.asarray(window, dtype=np.float64)
        if win.shape != (nperseg,):
            raise ValueError(f"window array must have shape ({nperseg},), got {win.shape}")
    else:
        win = signal.get_window(window, nperseg)
    spec = np.fft.rfft(seg * win[None, :, None], axis=1)
    f = np.fft.rfftfreq(nperseg, d=1.0 / fs)
    return f, spec


# ------------------------------------------------------------------------------------------
# filtering
# ------------------------------------------------------------------------------------------


def band_filter(
    x: Any,
    fs: float,
    band: Sequence[float | None] = DEFAULT_BAND,
    order: int = 4,
) -> np.ndarray:
    """Zero-phase Butterworth band-pass along axis 0.

    Parameters
    ----------
    x : array_like, shape (N,) or (N, k)
        Signals, time along axis 0.
    fs : float
        Sample rate (Hz).
    band : (float or None, float)
        Pass band edges (Hz).  A low edge of 0 or None gives a low-pass (the paper's
        "0-12 Hz" band).  Default (0.05, 12).
    order : int
        Butterworth order of the designed filter; ``sosfiltfilt`` runs it forward and
        backward, so the magnitude response is squared (-6 dB at the edges) and the phase
        is zero.

    Returns
    -------
    numpy.ndarray
        Filtered signals, same shape as ``x``.

    Notes
    -----
    Apply the same filter to inputs and outputs: it then cancels in H1 estimates.  Edge
    transients of the low cut-off last a few ``1 / low`` seconds.
    """
    fs = check_fs(fs)
    arr = as_signal(x, "x")
    lo, hi = _check_band(band, fs)
    if isinstance(order, bool) or not isinstance(order, int | np.integer) or order < 1:
        raise ValueError(f"order must be a positive integer, got {order!r}")
    if lo is None:
        sos = signal.butter(int(order), hi, btype="lowpass", fs=fs, output="sos")
    else:
        sos = signal.butter(int(order), (lo, hi), btype="bandpass", fs=fs, output="sos")
    padlen = 3 * (2 * sos.shape[0] + 1)
    if arr.shape[0] <= padlen:
        raise ValueError(
            f"x has {arr.shape[0]} samples; zero-phase filtering needs more than {padlen}"
        )
    return signal.sosfiltfilt(sos, arr, axis=0)
