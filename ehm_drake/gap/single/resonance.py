"""The resonance against level: how far a subject's resonance moves when the
vibration grows, in the data and in a model, per doubling of the level.

The one robust fact of seated-human biodynamics is that the vertical
resonance falls as the vibration grows (about x0.87 per doubling from 0.25
to 2 m/s^2 r.m.s.; Fairley & Griffin 1989, doi:10.1016/0021-9290(89)90031-6).
A diagnosis of one subject measured at two levels reports whether the
subject softens more, less or as much as the refitted model
(`resonance_shift`), whatever its candidates say.
"""

from __future__ import annotations

import math

import numpy as np

from ...systems.outputs import CHANNEL_NAMES
from .localize import Rows

#: The resonance against level: the excited direction's own translation of
#: these segments, peaks searched in this band (Hz; the seated body's
#: whole-body resonances: 4-6 Hz vertical, 1.5-4 Hz fore-and-aft), the gain
#: smoothed over this many frequency bins first.
RESONANCE_SEGMENTS = ("pelvis", "trunk", "head")
RESONANCE_BAND_HZ = (1.0, 12.0)
RESONANCE_SMOOTHING_BINS = 5
#: Per-doubling factors closer than this are reported "as much as" each
#: other: about three standard deviations of the factor's scatter from
#: measurement noise (0.007 on records with 1% noise per bin and damping
#: 0.3, `tests/test_gap.py`).
RESONANCE_TOLERANCE = 0.02


def peak_frequency(freq: np.ndarray, gain: np.ndarray,
                   band=RESONANCE_BAND_HZ, bins: int = RESONANCE_SMOOTHING_BINS) -> float:
    """The frequency of the largest gain in `band` (Hz), the gain smoothed
    over `bins` bins and the peak placed by a parabola through its
    neighbours; NaN without three bins in the band."""
    order = np.argsort(freq)
    f, g = freq[order], np.abs(gain[order])
    m = (f >= band[0]) & (f <= band[1])
    f, g = f[m], g[m]
    if len(f) < 3:
        return math.nan
    w = np.ones(min(bins, len(g)))
    g = np.convolve(g, w, "same") / np.convolve(np.ones_like(g), w, "same")
    k = int(np.argmax(g))
    if 0 < k < len(g) - 1:
        a, b, c = g[k - 1], g[k], g[k + 1]
        den = a - 2 * b + c
        if den < 0:
            return float(f[k] + 0.5 * (a - c) / den * (f[k + 1] - f[k - 1]) / 2)
    return float(f[k])


def resonance_shift(rows: Rows, H_model: np.ndarray | None = None) -> dict:
    """Per direction tested at two or more levels: the frequency of each
    measured segment's resonance (`RESONANCE_SEGMENTS`, the direction's own
    translation) at the lowest and the highest level, in the data and, given
    `H_model` (a prediction of every row), in the model; the ratio high /
    low and its factor per doubling of the level (people's vertical
    resonance: about x0.87 per doubling from 0.25 to 2 m/s^2 r.m.s., Fairley
    & Griffin 1989, doi:10.1016/0021-9290(89)90031-6)."""
    out = {}
    for d in "xyz":
        levels = sorted({lv for dd, lv in rows.tests if dd == d and np.isfinite(lv)})
        if len(levels) < 2:
            continue
        lo, hi = levels[0], levels[-1]
        doublings = math.log2(hi / lo)
        entry = {"levels": [lo, hi], "segments": {}}
        sources = {"data": rows.H} | ({} if H_model is None else {"model": H_model})
        for seg in RESONANCE_SEGMENTS:
            ch = CHANNEL_NAMES.index(f"{seg}_{d}")
            seg_entry = {}
            for name, H in sources.items():
                pk = []
                for lv in (lo, hi):
                    m = rows.test_mask(d, lv) & (rows.channel == ch)
                    pk.append(peak_frequency(rows.freq[m], H[m]))
                ratio = pk[1] / pk[0]
                seg_entry[name] = {"peak_hz": pk, "ratio": ratio,
                                   "per_doubling": ratio ** (1.0 / doublings)}
            if np.isfinite(seg_entry["data"]["per_doubling"]):  # (a channel not measured)
                entry["segments"][seg] = seg_entry
        if not entry["segments"]:
            continue
        for name in sources:
            entry[f"{name}_per_doubling"] = float(np.median(
                [e[name]["per_doubling"] for e in entry["segments"].values()]))
        if H_model is not None:
            diff = entry["data_per_doubling"] - entry["model_per_doubling"]
            entry["compared"] = ("as much as" if not abs(diff) > RESONANCE_TOLERANCE
                                 else "more than" if diff < 0 else "less than")
        out[d] = entry
    return out
