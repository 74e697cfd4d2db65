"""ISO 2631-1:1997 frequency weightings and whole-body-vibration comfort metrics.

Weightings
----------
Each weighting is the product of the standard's analog transfer functions
(ISO 2631-1:1997 Annex A; parameters in
:data:`~ehm_drake.analysis.iso2631_tables.WEIGHTING_PARAMETERS`), with ``s = j 2 pi f``
and ``w_i = 2 pi f_i``:

* band-limiting high-pass  ``H_h = s^2 / (s^2 + s w1 / Q1 + w1^2)``;
* band-limiting low-pass   ``H_l = w2^2 / (s^2 + s w2 / Q2 + w2^2)``;
* a-v transition           ``H_t = (1 + s / w3) / (1 + s / (Q4 w4) + s^2 / w4^2)``;
* upward step              ``H_s = (1 + s / (Q5 w5) + s^2 / w5^2)
  / (1 + s / (Q6 w6) + s^2 / w6^2) * (w5 / w6)^2``;

a term whose corner frequency is infinite is 1 (Wd, Wc, We have no upward step; Wj has no
a-v transition; Wf has ``f3 = inf`` so its transition is a pure 2nd-order low-pass, and it
does have an upward step, ``f5 = 0.0625 Hz``, ``f6 = 0.1 Hz``, per Table A.1).

:func:`apply_weighting` filters in the frequency domain with this *exact* analog response
(FFT, multiply, inverse FFT) -- no bilinear-transform warping.  The FFT treats the record
as one period of a periodic signal; by default the record is zero-padded by ten times the
slowest time constant of the weighting so that the result equals causal analog filtering
from rest (including the start-up transient a time-domain instrument would show), with
negligible wrap-around.  ``pad=False`` gives the circular (periodic) result, which is exact
for records holding an integer number of periods of a periodic signal.

Metrics (ISO 2631-1:1997 clause 6)
----------------------------------
* :func:`weighted_rms` -- ``a_w = sqrt(mean(a_w(t)^2))`` (m/s^2);
* :func:`vdv` -- ``VDV = (integral a_w^4 dt)^(1/4)`` (m/s^1.75);
* :func:`mtvv` -- maximum of the running RMS with linear integration over ``tau`` (1 s);
* :func:`crest_factor` -- ``max |a_w| / a_w``;
* :func:`msdv_z` -- motion sickness dose value ``(integral a_wf^2 dt)^(1/2)`` (m/s^1.5);
* :func:`overall_value` -- ``sqrt(sum (k_i a_wi)^2)``;
* :func:`comfort_metrics` -- all of the above for a tri-axial record.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import fft as sp_fft

from .iso2631_tables import WEIGHTING_PARAMETERS
from .welch import as_signal, check_fs

__all__ = [
    "WEIGHTINGS",
    "LOCATIONS",
    "weighting_response",
    "apply_weighting",
    "weighted_rms",
    "vdv",
    "mtvv",
    "crest_factor",
    "msdv_z",
    "overall_value",
    "comfort_metrics",
]

#: Supported weighting names.
WEIGHTINGS: tuple[str, ...] = tuple(WEIGHTING_PARAMETERS)

#: location -> per-axis (weighting, multiplying factor k) for :func:`comfort_metrics`.
LOCATIONS: dict[str, dict[str, tuple[str, float]]] = {
    # ISO 2631-1 8.2.2 / Table 1: seat surface, comfort
    "seat": {"x": ("Wd", 1.0), "y": ("Wd", 1.0), "z": ("Wk", 1.0)},
    # ISO 2631-1 8.2.2: seat-back
    "backrest": {"x": ("Wc", 0.8), "y": ("Wd", 0.5), "z": ("Wd", 0.4)},
    # not covered by ISO 2631-1 for seated persons: seat weightings, k = 1 (convention)
    "head": {"x": ("Wd", 1.0), "y": ("Wd", 1.0), "z": ("Wk", 1.0)},
}

_AXES = ("x", "y", "z")
#: Zero-padding length in units of the weighting's slowest time constant.
_PAD_TIME_CONSTANTS = 10.0


def _canonical(name: str) -> str:
    if not isinstance(name, str):
        raise TypeError(f"weighting must be a name like 'Wk', got {type(name).__name__}")
    key = name.strip()
    if len(key) == 1:
        key = "W" + key
    key = key[:1].upper() + key[1:].lower()
    if key not in WEIGHTING_PARAMETERS:
        raise ValueError(f"unknown weighting '{name}'; expected one of {list(WEIGHTINGS)}")
    return key


def _as_signal(x: Any, name: str = "x") -> np.ndarray:
    """`x` checked by the spectral estimators' rule, with at least 2 samples."""
    arr = as_signal(x, name)
    if arr.shape[0] < 2:
        raise ValueError(f"{name} needs at least 2 samples, got {arr.shape[0]}")
    return arr


def weighting_response(name: str, f: Any) -> np.ndarray:
    """Complex frequency response ``H(j 2 pi f)`` of an ISO 2631-1 weighting.

    Parameters
    ----------
    name : str
        ``'Wk'``, ``'Wd'``, ``'Wf'``, ``'Wc'``, ``'We'`` or ``'Wj'`` (case-insensitive;
        ``'k'`` is accepted for ``'Wk'``).
    f : array_like
        Frequencies (Hz, >= 0).

    Returns
    -------
    numpy.ndarray
        Complex response, same shape as ``f``.
    """
    key = _canonical(name)
    f = np.asarray(f, dtype=np.float64)
    if not np.all(np.isfinite(f)) or np.any(f < 0):
        raise ValueError("f must be finite and >= 0 Hz")
    f1, q1, f2, q2, f3, f4, q4, f5, q5, f6, q6 = WEIGHTING_PARAMETERS[key]
    s = 2j * np.pi * f
    w1, w2 = 2 * np.pi * f1, 2 * np.pi * f2
    h = s**2 / (s**2 + s * w1 / q1 + w1**2)
    h = h * w2**2 / (s**2 + s * w2 / q2 + w2**2)
    if math.isfinite(f4):
        w4 = 2 * np.pi * f4
        num = 1.0 + s / (2 * np.pi * f3) if math.isfinite(f3) else 1.0
        h = h * num / (1.0 + s / (q4 * w4) + (s / w4) ** 2)
    if math.isfinite(f5):
        w5, w6 = 2 * np.pi * f5, 2 * np.pi * f6
        h = h * (1.0 + s / (q5 * w5) + (s / w5) ** 2) / (1.0 + s / (q6 * w6) + (s / w6) ** 2)
        h = h * (w5 / w6) ** 2
    return h


def _slowest_time_constant(key: str) -> float:
    """Largest ``1 / |Re(pole)|`` of the weighting (s)."""
    f1, q1, f2, q2, _f3, f4, q4, _f5, _q5, f6, q6 = WEIGHTING_PARAMETERS[key]
    taus = [
        2 * q / (2 * np.pi * fc)
        for fc, q in ((f1, q1), (f2, q2), (f4, q4), (f6, q6))
        if math.isfinite(fc)
    ]
    return max(taus)


def apply_weighting(
    name: str, x: Any, fs: float, pad: bool = True, remove_mean: bool = True
) -> np.ndarray:
    """Frequency-weight an acceleration record with the exact analog ISO 2631-1 response.

    Parameters
    ----------
    name : str
        Weighting name (see :func:`weighting_response`).
    x : array_like, shape (N,) or (N, k)
        Acceleration (m/s^2), time along axis 0.
    fs : float
        Sample rate (Hz).
    pad : bool
        Zero-pad by ten slowest time constants before the FFT (default): linear, causal
        filtering from rest.  ``False``: circular filtering (periodic extension), exact for
        records with an integer number of periods.
    remove_mean : bool
        Subtract the mean first (default).  The weighting blocks DC anyway; removing it
        avoids start/stop transients from a sensor offset.

    Returns
    -------
    numpy.ndarray
        Weighted acceleration, same shape as ``x``.

    Notes
    -----
    The response is applied up to the Nyquist frequency without bilinear warping; content
    above ``fs/2`` cannot be represented, so ``fs`` should be well above the band of
    interest (the weightings extend to ~100 Hz; Wf to ~1 Hz).
    """
    key = _canonical(name)
    fs = check_fs(fs)
    arr = _as_signal(x)
    if remove_mean:
        arr = arr - arr.mean(axis=0)
    n = arr.shape[0]
    n_pad = int(math.ceil(_PAD_TIME_CONSTANTS * _slowest_time_constant(key) * fs)) if pad else 0
    nfft = sp_fft.next_fast_len(n + n_pad, real=True)
    spec = sp_fft.rfft(arr, n=nfft, axis=0)
    f = sp_fft.rfftfreq(nfft, d=1.0 / fs)
    h = weighting_response(key, f)
    if nfft % 2 == 0:
        h[-1] = h[-1].real  # the Nyquist bin of a real signal must stay real
    shape = (-1,) + (1,) * (arr.ndim - 1)
    out = sp_fft.irfft(spec * h.reshape(shape), n=nfft, axis=0)
    return out[:n]


def _weighted(x: Any, fs: float, weighting: str | None, pad: bool) -> np.ndarray:
    if weighting is None:
        arr = _as_signal(x)
        return arr - arr.mean(axis=0)
    return apply_weighting(weighting, x, fs, pad=pad)


def weighted_rms(x: Any, fs: float, weighting: str | None, pad: bool = True) -> Any:
    """Frequency-weighted RMS acceleration ``a_w`` (m/s^2).

    Parameters
    ----------
    x : array_like, shape (N,) or (N, k)
        Acceleration (m/s^2).
    fs : float
        Sample rate (Hz).
    weighting : str or None
        Weighting name; ``None`` for the unweighted (mean-removed) RMS.
    pad : bool
        See :func:`apply_weighting`.

    Returns
    -------
    float or numpy.ndarray
        Scalar for 1-D input, shape (k,) for 2-D input.
    """
    fs = check_fs(fs)
    aw = _weighted(x, fs, weighting, pad)
    r = np.sqrt(np.mean(aw**2, axis=0))
    return float(r) if np.ndim(r) == 0 else r


def vdv(x: Any, fs: float, weighting: str | None, pad: bool = True) -> Any:
    """Fourth-power vibration dose value ``(integral a_w^4 dt)^(1/4)`` (m/s^1.75).

    For a sinusoid of amplitude ``A`` and duration ``T`` (integer number of periods):
    ``VDV = (3 T / 8)^(1/4) A |W(f)|``.
    """
    fs = check_fs(fs)
    aw = _weighted(x, fs, weighting, pad)
    r = (np.sum(aw**4, axis=0) / fs) ** 0.25
    return float(r) if np.ndim(r) == 0 else r


def _running_rms(aw: np.ndarray, fs: float, tau: float) -> np.ndarray:
    if isinstance(tau, bool) or not isinstance(tau, int | float) or not tau > 0:
        raise ValueError(f"tau must be a positive integration time (s), got {tau!r}")
    w = int(round(tau * fs))
    if w < 1:
        raise ValueError(f"tau={tau} s is shorter than one sample at fs={fs} Hz")
    if w > aw.shape[0]:
        raise ValueError(
            f"record of {aw.shape[0] / fs:.4g} s is shorter than the integration time tau={tau} s"
        )
    c = np.concatenate([np.zeros((1,) + aw.shape[1:]), np.cumsum(aw**2, axis=0)])
    ms = (c[w:] - c[:-w]) / w
    return np.sqrt(np.maximum(ms, 0.0))


def mtvv(x: Any, fs: float, weighting: str | None, tau: float = 1.0, pad: bool = True) -> Any:
    """Maximum transient vibration value (m/s^2), ISO 2631-1 6.3.1.

    Maximum over time of the running RMS with linear (rectangular) integration over the
    last ``tau`` seconds (default 1 s), computed for every full window in the record.
    """
    fs = check_fs(fs)
    aw = _weighted(x, fs, weighting, pad)
    r = np.max(_running_rms(aw, fs, tau), axis=0)
    return float(r) if np.ndim(r) == 0 else r


def crest_factor(x: Any, fs: float, weighting: str | None, pad: bool = True) -> Any:
    """Crest factor ``max |a_w(t)| / a_w`` of the weighted acceleration.

    Raises
    ------
    ValueError
        If the weighted signal is identically zero (crest factor undefined).
    """
    fs = check_fs(fs)
    aw = _weighted(x, fs, weighting, pad)
    rms = np.sqrt(np.mean(aw**2, axis=0))
    if np.any(rms == 0):
        raise ValueError("crest factor undefined: the weighted signal is identically zero")
    r = np.max(np.abs(aw), axis=0) / rms
    return float(r) if np.ndim(r) == 0 else r


def msdv_z(az: Any, fs: float, pad: bool = True) -> float:
    """Motion sickness dose value ``MSDV_z = (integral a_wf^2 dt)^(1/2)`` (m/s^1.5).

    Vertical acceleration weighted with Wf (ISO 2631-1 Annex D).  For a sinusoid of
    amplitude ``A`` lasting ``T``: ``MSDV = A |Wf(f)| sqrt(T / 2)``.
    """
    fs = check_fs(fs)
    arr = _as_signal(az, "az")
    if arr.ndim != 1:
        raise ValueError(f"az must be 1-D (vertical acceleration), got shape {arr.shape}")
    aw = apply_weighting("Wf", arr, fs, pad=pad)
    return float(np.sqrt(np.sum(aw**2) / fs))


def overall_value(rms_xyz: Sequence[float], k: Sequence[float] = (1.0, 1.0, 1.0)) -> float:
    """Vibration total value ``sqrt((k_x a_wx)^2 + (k_y a_wy)^2 + (k_z a_wz)^2)``.

    Parameters
    ----------
    rms_xyz : sequence of 3 floats
        Weighted RMS per axis (m/s^2).
    k : sequence of 3 floats
        Multiplying factors.
    """
    a = np.asarray(rms_xyz, dtype=np.float64)
    kk = np.asarray(k, dtype=np.float64)
    if a.shape != (3,) or kk.shape != (3,):
        raise ValueError(f"rms_xyz and k must have 3 values, got {a.shape} and {kk.shape}")
    if not (np.all(np.isfinite(a)) and np.all(a >= 0)):
        raise ValueError(f"rms_xyz must be finite and >= 0, got {a.tolist()}")
    if not (np.all(np.isfinite(kk)) and np.all(kk >= 0)):
        raise ValueError(f"k must be finite and >= 0, got {kk.tolist()}")
    return float(np.sqrt(np.sum((kk * a) ** 2)))


def comfort_metrics(
    acc_xyz: Any, fs: float, location: str = "seat", tau: float = 1.0, pad: bool = True
) -> dict[str, Any]:
    """ISO 2631-1 comfort metrics of a tri-axial acceleration record.

    Weightings and multiplying factors per ``location``:

    * ``'seat'`` -- x: Wd, y: Wd, z: Wk, k = 1, 1, 1 (ISO 2631-1 comfort, seat surface);
    * ``'backrest'`` -- x: Wc (k = 0.8), y: Wd (0.5), z: Wd (0.4);
    * ``'head'`` -- ISO 2631-1 gives no weighting for the head of a seated person; by
      convention the seat weightings with k = 1 are used.

    Parameters
    ----------
    acc_xyz : array_like, shape (N, 3)
        Acceleration along x, y, z (m/s^2).
    fs : float
        Sample rate (Hz).
    location : {'seat', 'backrest', 'head'}
    tau : float
        MTVV integration time (s).
    pad : bool
        See :func:`apply_weighting`.

    Returns
    -------
    dict
        ``weighted_rms``, ``vdv``, ``mtvv``, ``crest_factor``: dicts axis -> value (before
        the k factors); ``overall``: ``sqrt(sum (k a_w)^2)``; ``overall_vdv``:
        ``(sum (k VDV)^4)^(1/4)``; ``msdv_z``: MSDV of the z axis (Wf); ``weightings`` and
        ``k``: dicts axis -> weighting name / factor; ``location``.
    """
    if location not in LOCATIONS:
        raise ValueError(f"unknown location '{location}'; expected one of {list(LOCATIONS)}")
    fs = check_fs(fs)
    acc = _as_signal(acc_xyz, "acc_xyz")
    if acc.ndim != 2 or acc.shape[1] != 3:
        raise ValueError(f"acc_xyz must have shape (N, 3), got {acc.shape}")
    spec = LOCATIONS[location]
    out: dict[str, Any] = {
        "location": location,
        "weightings": {a: spec[a][0] for a in _AXES},
        "k": {a: spec[a][1] for a in _AXES},
        "weighted_rms": {},
        "vdv": {},
        "mtvv": {},
        "crest_factor": {},
    }
    for j, axis in enumerate(_AXES):
        aw = apply_weighting(spec[axis][0], acc[:, j], fs, pad=pad)
        rms = float(np.sqrt(np.mean(aw**2)))
        out["weighted_rms"][axis] = rms
        out["vdv"][axis] = float((np.sum(aw**4) / fs) ** 0.25)
        out["mtvv"][axis] = float(np.max(_running_rms(aw, fs, tau)))
        # an axis without vibration has no defined crest factor: reported as 0.0
        out["crest_factor"][axis] = float(np.max(np.abs(aw)) / rms) if rms > 0 else 0.0
    ks = [spec[a][1] for a in _AXES]
    out["overall"] = overall_value([out["weighted_rms"][a] for a in _AXES], ks)
    out["overall_vdv"] = float(
        sum((kk * out["vdv"][a]) ** 4 for kk, a in zip(ks, _AXES, strict=True)) ** 0.25
    )
    out["msdv_z"] = msdv_z(acc[:, 2], fs, pad=pad)
    return out
