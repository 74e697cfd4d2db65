"""Welch-averaged H1 estimators: transfer functions, coherence, apparent mass, random error.

The reference experiment estimates frequency response functions with MATLAB's
``tfestimate``.  This module reproduces it with numpy/scipy (signal preparation -- band
filter, segments, segment FFTs -- is in :mod:`.welch`; the seat-to-body transmissibility
table built on these estimators is in :mod:`.transmissibility`):

* :func:`tfestimate` -- single-input H1 estimator ``H = S_yx / S_xx`` with ordinary coherence
  ``|S_yx|^2 / (S_xx S_yy)``, Welch averaging (window, 50 % overlap by default), vectorised
  over output channels;
* :func:`mimo_h1` -- multiple-input H1 ``H = S_yx S_xx^{-1}`` for simultaneous multi-axis
  excitation, with multiple coherence per output;
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

from .welch import as_signal, band_filter, check_fs, segment_ffts, segmentation

__all__ = [
    "FrfEstimate",
    "MimoEstimate",
    "ApparentMass",
    "tfestimate",
    "mimo_h1",
    "apparent_mass",
    "frf_uncertainty",
]

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
# estimators
# ------------------------------------------------------------------------------------------


def _safe_ratio(num: np.ndarray, den: np.ndarray, ok: np.ndarray, fill: float) -> np.ndarray:
    out = np.full(np.broadcast(num, den).shape, fill, dtype=np.result_type(num, den, float))
    np.divide(num, den, out=out, where=ok)
    return out


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
    fs = check_fs(fs)
    x = as_signal(x, "x", ndim=(1,))
    y = as_signal(y, "y")
    if y.shape[0] != x.shape[0]:
        raise ValueError(f"x and y must have the same length, got {x.shape[0]} and {y.shape[0]}")
    if not np.any(x - x.mean()):
        raise ValueError("x is constant: the input has no power, H1 is undefined")
    squeeze = y.ndim == 1
    y2 = y[:, None] if squeeze else y
    nperseg, noverlap, n_avg = segmentation(x.shape[0], fs, nperseg, noverlap)
    f, spec = segment_ffts(np.column_stack([x, y2]), fs, nperseg, noverlap, window, detrend)
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
    fs = check_fs(fs)
    X = as_signal(X, "X")
    if X.ndim == 1:
        X = X[:, None]
    Y = as_signal(Y, "Y")
    if Y.ndim == 1:
        Y = Y[:, None]
    if Y.shape[0] != X.shape[0]:
        raise ValueError(f"X and Y must have the same length, got {X.shape[0]} and {Y.shape[0]}")
    p, m = X.shape[1], Y.shape[1]
    for j in range(p):
        if not np.any(X[:, j] - X[:, j].mean()):
            raise ValueError(f"input column {j} of X is constant (no power)")
    nperseg, noverlap, n_avg = segmentation(X.shape[0], fs, nperseg, noverlap)
    f, spec = segment_ffts(np.column_stack([X, Y]), fs, nperseg, noverlap, window, detrend)
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
    fs = check_fs(fs)
    if isinstance(static_mass, bool) or not isinstance(static_mass, int | float):
        raise TypeError(f"static_mass must be a number (kg), got {type(static_mass).__name__}")
    if not (math.isfinite(static_mass) and static_mass > 0):
        raise ValueError(f"static_mass must be a finite positive mass (kg), got {static_mass}")
    force = as_signal(force, "force", ndim=(1,))
    accel = as_signal(accel, "accel", ndim=(1,))
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
