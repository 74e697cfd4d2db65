"""Seat-to-body transmissibility from time histories, as an ``frf.csv`` table.

:func:`transmissibility` turns a :class:`~ehm_drake.analysis.formats.TimeSeriesData` into
:class:`~ehm_drake.analysis.formats.FrfData` rows with the H1 estimators of
:mod:`.spectral` (one excited axis: :func:`~.spectral.tfestimate`; several:
:func:`~.spectral.mimo_h1`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .formats import (
    DIRECTIONS,
    DataFormatError,
    FrfData,
    TimeSeriesData,
    parse_channel_name,
)
from .spectral import mimo_h1, tfestimate
from .welch import band_filter

__all__ = ["TRANSMISSIBILITY_BAND", "transmissibility"]

#: Band of `transmissibility`: the paper's 0-12 Hz low-pass.  No high-pass
#: edge: the second difference has no drift to remove, and a 0.05 Hz
#: high-pass rang over the whole of a 60 s record, corrupting the bins
#: below 0.3 Hz (gains off by 0.5-4.5x, coherence lost, in random tests).
TRANSMISSIBILITY_BAND: tuple[float | None, float] = (None, 12.0)


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
    detrend: str | bool = False,
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

    No per-segment detrending by default.  The second difference already removes an offset
    or a linear drift of a motion channel, and the mean of ``y2`` over a segment is the
    difference of its end velocities divided by the segment length: motion-capture noise
    times ``fs``, not motion.  Removing that mean puts a quarter of it, times the segment
    length, into the first bin of the Hann window (H1 at 0.1 Hz of synthetic lab records,
    10 s segments, 0.05 deg noise: trunk pitch under z 33-39 deg/m instead of 0.16-0.23).
    The seat acceleration's offset (a sensor bias, or gravity on a vertical accelerometer)
    is its record mean, removed once before the band filter.

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
        Welch parameters, see :func:`tfestimate`.  ``detrend`` (default False) applies to
        the seat acceleration and ``y2`` alike; ``'constant'`` corrupts the first bin (see
        above).
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
    seat = seat - seat.mean(axis=0)
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
