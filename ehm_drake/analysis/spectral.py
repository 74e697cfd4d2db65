"""Transmissibility and apparent-mass estimation (Welch-averaged H1 estimators).

The reference experiment filters both the seat input and the body responses with a
0-12 Hz Butterworth band-pass and estimates frequency response functions with MATLAB's
``tfestimate``.  This module reproduces that chain with numpy/scipy:

* :func:`band_filter` -- zero-phase Butterworth band-pass (``sosfiltfilt``), applied alike
  to inputs and outputs so that it cancels in the FRF ratio;
* :func:`tfestimate` -- single-input H1 estimator ``H = S_yx / S_xx`` with ordinary coherence
  ``|S_yx|^2 / (S_xx S_yy)``, Welch averaging (window, 50 % overlap by default), vectorised
  over output channels;
* :func:`mimo_h1` -- multiple-input H1 ``H = S_yx S_xx^{-1}`` for simultaneous multi-axis
  excitation, with multiple coherence per output;
* :func:`transmissibility` -- seat-to-body transmissibility from a
  :class:`~ehm_drake.analysis.dataio.TimeSeriesData`, returned as
  :class:`~ehm_drake.analysis.dataio.FrfData`;
* :func:`apparent_mass` -- seat-pan force over seat acceleration, normalised by static mass;
* :func:`frf_uncertainty` -- random error of an H1 gain estimate (Bendat & Piersol).

Conventions
-----------
Spectra are averaged over segments ``s`` of the windowed, detrended records:
``S_xy(f) = mean_s conj(X_s(f)) Y_s(f)`` (scipy/MATLAB ``cpsd`` convention), so that for
``y = h * x`` the H1 estimate ``S_xy / S_xx`` equals ``H(f)`` with the ``exp(+j 2 pi f t)``
sign convention (phase lag is negative).  Absolute PSD scaling cancels in every ratio and
is therefore not applied.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from scipy import signal

from .dataio import (
    DIRECTIONS,
    DataFormatError,
    FrfData,
    TimeSeriesData,
    parse_channel_name,
)

__all__ = [
    "DEFAULT_BAND",
    "TRANSMISSIBILITY_BAND",
    "DEFAULT_RESOLUTION_HZ",
    "FrfEstimate",
    "MimoEstimate",
    "ApparentMass",
    "band_filter",
    "default_nperseg",
    "tfestimate",
    "mimo_h1",
    "transmissibility",
    "apparent_mass",
    "frf_uncertainty",
]

#: Band of the paper's Butterworth band-pass (Hz); 0.05 Hz instead of 0 removes drift.
DEFAULT_BAND: tuple[float, float] = (0.05, 12.0)
#: Band of `transmissibility`: the paper's 0-12 Hz low-pass.  No high-pass
#: edge: the second difference has no drift to remove, and a 0.05 Hz
#: high-pass rang over the whole of a 60 s record, corrupting the bins
#: below 0.3 Hz (gains off by 0.5-4.5x, coherence lost, in random tests).
TRANSMISSIBILITY_BAND: tuple[float | None, float] = (None, 12.0)
#: Target frequency resolution of the default Welch segment (Hz).
DEFAULT_RESOLUTION_HZ: float = 0.075
#: Minimum number of Welch averages the default segment length aims for.
MIN_AVERAGES: int = 8
#: Smallest segment length accepted.
MIN_NPERSEG: int = 16
#: Bins whose input power is below this fraction of the maximum are treated as empty.
_EMPTY_BIN_RTOL = 1e-12
#: Relative smallest singular value below which a MIMO input matrix is singular.
_SINGULAR_RTOL = 1e-10


# ------------------------------------------------------------------------------------------
# results
# ------------------------------------------------------------------------------------------


@dataclass(eq=False)
class FrfEstimate:
    """Result of :func:`tfestimate`.

    Attributes
    ----------
    f : numpy.ndarray, shape (nf,)
        Frequencies (Hz), ``0 .. fs/2`` in steps of ``fs / nperseg``.
    H : numpy.ndarray, complex, shape (nf,) or (nf, m)
        H1 estimate (output units per input unit).  NaN at bins where the input has no
        power (``S_xx <= 1e-12 max S_xx``), where H1 is undefined.
    coherence : numpy.ndarray, shape like ``H``
        Ordinary coherence in [0, 1]; 0 where undefined (no input or no output power).
    n_averages : int
        Number of Welch segments averaged.
    nperseg : int
        Segment length (samples).
    """

    f: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    n_averages: int
    nperseg: int


@dataclass(eq=False)
class MimoEstimate:
    """Result of :func:`mimo_h1`.

    Attributes
    ----------
    f : numpy.ndarray, shape (nf,)
        Frequencies (Hz).
    H : numpy.ndarray, complex, shape (nf, m, p)
        ``H[f, k, j]`` = response of output ``k`` to input ``j``.  NaN at bins where the
        input spectral matrix is singular (empty or linearly dependent inputs).
    multiple_coherence : numpy.ndarray, shape (nf, m)
        Multiple coherence of each output with all inputs, in [0, 1]; 0 where undefined.
    n_averages : int
        Number of Welch segments averaged.
    nperseg : int
        Segment length (samples).
    input_condition : numpy.ndarray, shape (nf,)
        Ratio of the largest to the smallest singular value of ``S_xx`` (inf if singular).
    """

    f: np.ndarray
    H: np.ndarray
    multiple_coherence: np.ndarray
    n_averages: int
    nperseg: int
    input_condition: np.ndarray


class ApparentMass(NamedTuple):
    """Result of :func:`apparent_mass` (unpacks as ``f, modulus, phase_deg, coherence``)."""

    f: np.ndarray
    modulus_normalized: np.ndarray
    phase_deg: np.ndarray
    coherence: np.ndarray


# ------------------------------------------------------------------------------------------
# input checking
# ------------------------------------------------------------------------------------------


def _check_fs(fs: float) -> float:
    if isinstance(fs, bool) or not isinstance(fs, int | float | np.floating | np.integer):
        raise TypeError(f"fs must be a number (Hz), got {type(fs).__name__}")
    fs = float(fs)
    if not math.isfinite(fs) or fs <= 0:
        raise ValueError(f"fs must be a finite positive sample rate (Hz), got {fs}")
    return fs


def _as_signal(x: Any, name: str, ndim: tuple[int, ...] = (1, 2)) -> np.ndarray:
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


def _segmentation(
    n: int, fs: float, nperseg: int | None, noverlap: int | None
) -> tuple[int, int, int]:
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


def _segment_ffts(
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


def _safe_ratio(num: np.ndarray, den: np.ndarray, ok: np.ndarray, fill: float) -> np.ndarray:
    out = np.full(np.broadcast(num, den).shape, fill, dtype=np.result_type(num, den, float))
    np.divide(num, den, out=out, where=ok)
    return out


# ------------------------------------------------------------------------------------------
# filtering and estimators
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
    fs = _check_fs(fs)
    arr = _as_signal(x, "x")
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


def tfestimate(
    x: Any,
    y: Any,
    fs: float,
    nperseg: int | None = None,
    noverlap: int | None = None,
    window: str | tuple | np.ndarray = "hann",
    detrend: str | bool = "constant",
) -> FrfEstimate:
    """H1 transfer-function estimate from ``x`` to ``y`` (as MATLAB ``tfestimate``).

    ``H(f) = S_yx(f) / S_xx(f)`` with ``S_yx = mean_s conj(X_s) Y_s`` and
    ``S_xx = mean_s |X_s|^2`` over Welch segments, and ordinary coherence
    ``C(f) = |S_yx|^2 / (S_xx S_yy)``.

    Parameters
    ----------
    x : array_like, shape (N,)
        Input signal.
    y : array_like, shape (N,) or (N, m)
        Output signal(s); the estimate is vectorised over the m columns.
    fs : float
        Sample rate (Hz).
    nperseg : int, optional
        Segment length.  Default :func:`default_nperseg` (about 0.075 Hz resolution, at most
        N // 8 samples).
    noverlap : int, optional
        Overlap in samples, default ``nperseg // 2`` (50 %).
    window : str, tuple or array
        Window passed to :func:`scipy.signal.get_window` (periodic), default ``'hann'``.
    detrend : {'constant', 'linear', False}
        Per-segment detrending.

    Returns
    -------
    FrfEstimate
        ``f`` (Hz), ``H`` (shape ``(nf,)`` or ``(nf, m)``), ``coherence``, ``n_averages``.
    """
    fs = _check_fs(fs)
    x = _as_signal(x, "x", ndim=(1,))
    y = _as_signal(y, "y")
    if y.shape[0] != x.shape[0]:
        raise ValueError(f"x and y must have the same length, got {x.shape[0]} and {y.shape[0]}")
    if not np.any(x - x.mean()):
        raise ValueError("x is constant: the input has no power, H1 is undefined")
    squeeze = y.ndim == 1
    y2 = y[:, None] if squeeze else y
    nperseg, noverlap, n_avg = _segmentation(x.shape[0], fs, nperseg, noverlap)
    f, spec = _segment_ffts(np.column_stack([x, y2]), fs, nperseg, noverlap, window, detrend)
    X, Y = spec[:, :, 0], spec[:, :, 1:]
    sxx = np.mean(np.abs(X) ** 2, axis=0)  # (nf,)
    syy = np.mean(np.abs(Y) ** 2, axis=0)  # (nf, m)
    sxy = np.mean(np.conj(X)[:, :, None] * Y, axis=0)  # (nf, m)
    ok_x = (sxx > _EMPTY_BIN_RTOL * sxx.max())[:, None]
    H = _safe_ratio(sxy, sxx[:, None], np.broadcast_to(ok_x, sxy.shape), np.nan)
    H = H.astype(complex)
    ok_xy = ok_x & (syy > 0)
    coh = _safe_ratio(np.abs(sxy) ** 2, sxx[:, None] * syy, ok_xy, 0.0)
    coh = np.clip(coh.real, 0.0, 1.0)
    if squeeze:
        H, coh = H[:, 0], coh[:, 0]
    return FrfEstimate(f=f, H=H, coherence=coh, n_averages=n_avg, nperseg=nperseg)


def mimo_h1(
    X: Any,
    Y: Any,
    fs: float,
    nperseg: int | None = None,
    noverlap: int | None = None,
    window: str | tuple | np.ndarray = "hann",
    detrend: str | bool = "constant",
) -> MimoEstimate:
    """Multiple-input H1 estimate ``H(f) = S_yx(f) S_xx(f)^{-1}``.

    With input spectrum vector ``X(f)`` (p) and output vector ``Y(f)`` (m), ``Y = H X``;
    ``S_xx = E[X X^H]`` (p x p), ``S_yx = E[Y X^H]`` (m x p), averaged over Welch segments.
    The multiple coherence of output k is
    ``gamma_k^2 = Re(S_yx[k] S_xx^{-1} S_yx[k]^H) / S_yy[k]``.

    Parameters
    ----------
    X : array_like, shape (N, p)
        Inputs (e.g. seat accelerations on the excited axes); must not be fully correlated.
    Y : array_like, shape (N,) or (N, m)
        Outputs.
    fs, nperseg, noverlap, window, detrend
        As in :func:`tfestimate`.

    Returns
    -------
    MimoEstimate
        ``H`` has shape ``(nf, m, p)``; bins where ``S_xx`` is singular (smallest singular
        value below 1e-10 of the largest, or no input power) are NaN with coherence 0.
    """
    fs = _check_fs(fs)
    X = _as_signal(X, "X")
    if X.ndim == 1:
        X = X[:, None]
    Y = _as_signal(Y, "Y")
    if Y.ndim == 1:
        Y = Y[:, None]
    if Y.shape[0] != X.shape[0]:
        raise ValueError(f"X and Y must have the same length, got {X.shape[0]} and {Y.shape[0]}")
    p, m = X.shape[1], Y.shape[1]
    for j in range(p):
        if not np.any(X[:, j] - X[:, j].mean()):
            raise ValueError(f"input column {j} of X is constant (no power)")
    nperseg, noverlap, n_avg = _segmentation(X.shape[0], fs, nperseg, noverlap)
    f, spec = _segment_ffts(np.column_stack([X, Y]), fs, nperseg, noverlap, window, detrend)
    Xs, Ys = spec[:, :, :p], spec[:, :, p:]
    # S_xx[f, i, j] = E[X_i conj(X_j)];  S_yx[f, k, j] = E[Y_k conj(X_j)]
    sxx = np.einsum("sfi,sfj->fij", Xs, np.conj(Xs)) / n_avg
    syx = np.einsum("sfk,sfj->fkj", Ys, np.conj(Xs)) / n_avg
    syy = np.mean(np.abs(Ys) ** 2, axis=0)  # (nf, m)
    sv = np.linalg.svd(sxx, compute_uv=False)  # (nf, p), descending
    smax = sv[:, 0]
    ok = (smax > _EMPTY_BIN_RTOL * smax.max()) & (sv[:, -1] > _SINGULAR_RTOL * smax)
    cond = np.full(f.shape, np.inf)
    cond[ok] = smax[ok] / sv[ok, -1]
    H = np.full((f.size, m, p), np.nan, dtype=complex)
    coh = np.zeros((f.size, m))
    if np.any(ok):
        # H S_xx = S_yx  <=>  S_xx^T H^T = S_yx^T
        Ht = np.linalg.solve(np.swapaxes(sxx[ok], 1, 2), np.swapaxes(syx[ok], 1, 2))
        H[ok] = np.swapaxes(Ht, 1, 2)
        num = np.real(np.einsum("fkj,fkj->fk", syx[ok], np.conj(H[ok])))
        den = syy[ok]
        coh[ok] = _safe_ratio(num, den, den > 0, 0.0)
    coh = np.clip(coh, 0.0, 1.0)
    return MimoEstimate(
        f=f,
        H=H,
        multiple_coherence=coh,
        n_averages=n_avg,
        nperseg=nperseg,
        input_condition=cond,
    )


# ------------------------------------------------------------------------------------------
# transmissibility
# ------------------------------------------------------------------------------------------


def _excited_directions(
    ts: TimeSeriesData,
    directions: str | Sequence[str] | None,
    seat_filtered: np.ndarray,
    multi_axis_ratio: float,
) -> tuple[str, ...]:
    if directions is not None:
        if isinstance(directions, str):
            items = list(directions)
        else:
            items = list(directions)
        bad = [d for d in items if d not in DIRECTIONS]
        if not items or bad or len(set(items)) != len(items):
            raise ValueError(
                f"directions must be distinct axes from {list(DIRECTIONS)}, got {directions!r}"
            )
        return tuple(d for d in DIRECTIONS if d in items)
    if ts.excited_directions is not None:
        return ts.excited_directions
    rms = np.sqrt(np.mean(seat_filtered**2, axis=0))
    if not np.any(rms > 0):
        raise ValueError("seat acceleration is zero on all axes: nothing is excited")
    return tuple(
        d for d, r in zip(DIRECTIONS, rms, strict=True) if r >= multi_axis_ratio * rms.max()
    )


def transmissibility(
    ts: TimeSeriesData,
    directions: str | Sequence[str] | None = None,
    band: Sequence[float | None] = TRANSMISSIBILITY_BAND,
    f_max: float = 12.0,
    nperseg: int | None = None,
    noverlap: int | None = None,
    window: str | tuple | np.ndarray = "hann",
    detrend: str | bool = "constant",
    filter_order: int = 4,
    multi_axis_ratio: float = 0.3,
    f_min: float = 0.0,
) -> FrfData:
    """Seat-to-body transmissibility from time histories, as an :class:`FrfData` table.

    The seat displacement ``d`` is not recorded, only the seat acceleration ``a``; in the
    frequency domain ``A = (j 2 pi f)^2 D = -(2 pi f)^2 D``, hence, exactly,

    ``T(f) = Y / D = -(2 pi f)^2 H_{a->y}(f)``,

    where ``H_{a->y}`` is the transfer function from seat acceleration to the output
    channel.  With the channel file units (m, deg) ``T`` is in m/m for translational
    channels and deg/m for rotational ones.

    ``H_{a->y} = -T / (2 pi f)^2`` is steep at low frequency, and a Welch H1 estimate of it
    suffers a window-leakage bias (about +3 % at 0.5 Hz with 0.075 Hz resolution).  The same
    identity is therefore evaluated on a smooth function: with the central second difference
    ``y2[n] = (y[n+1] - 2 y[n] + y[n-1]) fs^2`` (a local operation, no periodic extension),
    whose exact frequency response is ``-(2 fs sin(pi f / fs))^2``,

    ``T(f) = H1_{a->y2}(f) * (pi f / fs)^2 / sin^2(pi f / fs)``,

    which equals ``-(2 pi f)^2 H_{a->y}(f)`` exactly for the true spectra while
    ``H1_{a->y2} ~ T`` is smooth.  The coherence is that of ``a -> y2`` (equal to that of
    ``a -> y`` for the true spectra, as ``y2`` is ``y`` through a fixed linear filter).

    Excitation axes are ``directions`` if given, else ``ts.meta['direction']``, else the
    seat axes whose band-filtered RMS is at least ``multi_axis_ratio`` times the largest.
    One excited axis: SISO H1 per channel (:func:`tfestimate`).  Two or three: MIMO H1
    (:func:`mimo_h1`) with the excited seat axes as inputs; the coherence column then holds
    the multiple coherence of the output (the same for every input axis).

    Parameters
    ----------
    ts : TimeSeriesData
        Record with motion channels.
    directions : str or sequence of str, optional
        Excited axes, e.g. ``"z"`` or ``"xz"``.
    band : (float or None, float)
        Butterworth band applied (zero-phase) to seat and body signals alike (default:
        the 0-12 Hz low-pass, `TRANSMISSIBILITY_BAND`).
        ``None`` disables filtering.
    f_max : float
        Only rows with ``0 < f <= f_max`` are returned.
    nperseg, noverlap, window, detrend
        Welch parameters, see :func:`tfestimate`.
    filter_order : int
        Butterworth order (see :func:`band_filter`).
    multi_axis_ratio : float
        Relative RMS threshold for auto-detecting excited axes.
    f_min : float
        Only rows with ``f > f_min`` are returned (e.g. below a multisine's
        lowest line, where the seat has no power).

    Returns
    -------
    FrfData
        Rows ordered by direction, channel, frequency.  ``level_rms`` is
        ``ts.meta['level_rms']`` if given, else the RMS of the (mean-removed, unfiltered)
        seat acceleration on that axis; ``n_averages`` the number of Welch segments.

    Raises
    ------
    ValueError
        No motion channels, bad parameters, or an excited input with no power at some
        returned frequency (H1 undefined there).
    """
    if not isinstance(ts, TimeSeriesData):
        raise TypeError(f"ts must be a TimeSeriesData, got {type(ts).__name__}")
    if not ts.channels:
        raise ValueError("ts has no motion channels (<segment>_<dof> columns) to analyse")
    fs = ts.fs
    if not (isinstance(f_max, int | float | np.integer | np.floating) and 0 < f_max <= fs / 2):
        raise ValueError(f"f_max must satisfy 0 < f_max <= fs/2 = {fs / 2:g} Hz, got {f_max!r}")
    names = list(ts.channels)
    keys = [parse_channel_name(n) for n in names]
    Y = np.column_stack([ts.channels[n] for n in names])
    # Central second difference of the outputs (aligned with the seat samples
    # 1..N-2) BEFORE the band filter: both filtered signals are then
    # accelerations, so the filter's start-up transients match; filtering the
    # drifting displacement first biased the lowest bins by 4-8% on 30-45 s
    # records.
    Y2 = (Y[2:] - 2.0 * Y[1:-1] + Y[:-2]) * fs**2
    seat = ts.seat_acc[1:-1]
    if band is not None:
        seat = band_filter(seat, fs, band, filter_order)
        Y2 = band_filter(Y2, fs, band, filter_order)
    dirs = _excited_directions(ts, directions, seat, multi_axis_ratio)
    cols = [DIRECTIONS.index(d) for d in dirs]
    meta_level = ts.meta.get("level_rms")
    if len(dirs) == 1:
        est = tfestimate(seat[:, cols[0]], Y2, fs, nperseg, noverlap, window, detrend)
        f = est.f
        Hs = est.H[:, :, None]  # (nf, m, 1)
        coh = est.coherence  # (nf, m)
        n_avg = est.n_averages
    else:
        mest = mimo_h1(seat[:, cols], Y2, fs, nperseg, noverlap, window, detrend)
        f, Hs, coh = mest.f, mest.H, mest.multiple_coherence
        n_avg = mest.n_averages
    sel = (f > max(f_min, 0.0)) & (f <= f_max + 1e-9 * f_max)
    if not np.any(sel):
        raise ValueError(f"no frequency bin in (0, {f_max}] Hz; use a longer nperseg")
    f, Hs, coh = f[sel], Hs[sel], coh[sel]
    bad = np.argwhere(np.isnan(Hs[:, 0, :]))
    if bad.size:
        fi, j = bad[0]
        raise ValueError(
            f"seat acceleration along '{dirs[j]}' has no usable power at f = {f[fi]:.4g} Hz "
            "(or excited axes are linearly dependent): transmissibility undefined there"
        )
    u = np.pi * f / fs  # in (0, pi/2]: sin(u) > 0
    T = ((u / np.sin(u)) ** 2)[:, None, None] * Hs  # (nf, m, p), = -(2 pi f)^2 H_{a->y}
    parts = []
    for j, d in enumerate(dirs):
        if meta_level is not None:
            level = float(meta_level)
        else:
            a = ts.seat_acc[:, cols[j]]
            level = float(np.sqrt(np.mean((a - a.mean()) ** 2)))
        for k, (seg, dof) in enumerate(keys):
            nf = f.size
            parts.append(
                FrfData(
                    direction=np.full(nf, d),
                    segment=np.full(nf, seg),
                    dof=np.full(nf, dof),
                    freq_hz=f,
                    gain=np.abs(T[:, k, j]),
                    phase_deg=np.degrees(np.angle(T[:, k, j])),
                    coherence=coh[:, k],
                    level_rms=np.full(nf, level if level > 0 else np.nan),
                    n_averages=np.full(nf, float(n_avg)),
                )
            )
    try:
        return FrfData.concat(parts)
    except DataFormatError as exc:  # pragma: no cover - defensive, values are validated above
        raise ValueError(f"transmissibility produced an invalid table: {exc}") from None


# ------------------------------------------------------------------------------------------
# apparent mass and uncertainty
# ------------------------------------------------------------------------------------------


def apparent_mass(
    force: Any,
    accel: Any,
    fs: float,
    static_mass: float,
    band: Sequence[float | None] | None = None,
    f_max: float | None = None,
    nperseg: int | None = None,
    noverlap: int | None = None,
    window: str | tuple | np.ndarray = "hann",
    detrend: str | bool = "constant",
) -> ApparentMass:
    """Normalised apparent mass ``|F / a| / m_static`` of the seated body.

    H1 from seat acceleration (m/s^2) to seat-pan force in the same axis (N), so
    ``M(f) = S_af / S_aa`` in kg; its modulus is divided by the static seated mass.

    Parameters
    ----------
    force : array_like, shape (N,)
        Seat-pan force (N), dynamic part (the static weight is removed by detrending).
    accel : array_like, shape (N,)
        Seat acceleration along the same axis (m/s^2).
    fs : float
        Sample rate (Hz).
    static_mass : float
        Static mass supported by the seat pan (kg, > 0).
    band : (float or None, float), optional
        Optional zero-phase Butterworth band applied to both signals.
    f_max : float, optional
        Keep ``0 < f <= f_max``; default all positive frequencies.
    nperseg, noverlap, window, detrend
        See :func:`tfestimate`.

    Returns
    -------
    ApparentMass
        ``(f, modulus_normalized, phase_deg, coherence)`` for ``f > 0``.
    """
    fs = _check_fs(fs)
    if isinstance(static_mass, bool) or not isinstance(static_mass, int | float):
        raise TypeError(f"static_mass must be a number (kg), got {type(static_mass).__name__}")
    if not (math.isfinite(static_mass) and static_mass > 0):
        raise ValueError(f"static_mass must be a finite positive mass (kg), got {static_mass}")
    force = _as_signal(force, "force", ndim=(1,))
    accel = _as_signal(accel, "accel", ndim=(1,))
    if force.shape != accel.shape:
        raise ValueError(
            f"force and accel must have the same length, got {force.shape[0]} and {accel.shape[0]}"
        )
    if band is not None:
        both = band_filter(np.column_stack([accel, force]), fs, band)
        accel, force = both[:, 0], both[:, 1]
    est = tfestimate(accel, force, fs, nperseg, noverlap, window, detrend)
    sel = est.f > 0
    if f_max is not None:
        if not (isinstance(f_max, int | float | np.integer | np.floating) and 0 < f_max):
            raise ValueError(f"f_max must be a positive frequency (Hz), got {f_max!r}")
        sel &= est.f <= f_max
    f, H, coh = est.f[sel], est.H[sel], est.coherence[sel]
    bad = np.flatnonzero(np.isnan(H))
    if bad.size:
        raise ValueError(
            f"accel has no usable power at f = {f[bad[0]]:.4g} Hz: apparent mass undefined; "
            "pass f_max or band to restrict the range"
        )
    return ApparentMass(f, np.abs(H) / static_mass, np.degrees(np.angle(H)), coh)


def frf_uncertainty(gain: Any, coherence: Any, n_averages: int) -> np.ndarray:
    """Standard random error of an H1 gain estimate (Bendat & Piersol).

    Normalised random error of ``|H1|``::

        eps = sqrt(1 - gamma^2) / (|gamma| sqrt(2 n_d))

    with ``gamma^2`` the ordinary coherence and ``n_d`` the number of averages.  The
    returned standard error is ``sigma = eps * gain`` (same units as ``gain``).

    Parameters
    ----------
    gain : array_like
        FRF modulus.
    coherence : array_like
        Coherence ``gamma^2`` in [0, 1], broadcastable with ``gain``.
    n_averages : int
        Number of independent averages (>= 1).

    Returns
    -------
    numpy.ndarray
        ``sigma``; ``inf`` where the coherence is 0 (no information).
    """
    if isinstance(n_averages, bool) or not isinstance(n_averages, int | np.integer):
        raise TypeError(f"n_averages must be an integer, got {type(n_averages).__name__}")
    if n_averages < 1:
        raise ValueError(f"n_averages must be >= 1, got {n_averages}")
    g = np.asarray(gain, dtype=np.float64)
    c = np.asarray(coherence, dtype=np.float64)
    if not np.all(np.isfinite(g)) or np.any(g < 0):
        raise ValueError("gain must be finite and >= 0")
    if not np.all(np.isfinite(c)) or np.any((c < 0) | (c > 1)):
        raise ValueError("coherence must be finite and within [0, 1]")
    g, c = np.broadcast_arrays(g, c)
    sigma = np.full(g.shape, np.inf)
    ok = c > 0
    sigma[ok] = g[ok] * np.sqrt(1.0 - c[ok]) / (np.sqrt(c[ok]) * math.sqrt(2.0 * n_averages))
    return sigma
