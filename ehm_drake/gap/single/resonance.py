"""The resonance against level: how far a subject's resonance moves when the
vibration grows, in the data and in a model, per doubling of the level.

The one robust fact of seated-human biodynamics is that the vertical
resonance falls as the vibration grows (about x0.87 per doubling from 0.25
to 2 m/s^2 r.m.s.; Fairley & Griffin 1989, doi:10.1016/0021-9290(89)90031-6).
A diagnosis of one subject measured at two levels reports whether the
subject softens more, less or as much as the refitted model
(`resonance_shift`), whatever its candidates say.

One subject alone has no reference group to tell an effect from the body's
own difference from the model, but its two levels do: a structural error
of the model is the same at both, a level-dependent effect is not.  The
level rule (`softening_rule`) names `softening` when the subject's vertical
resonance falls clearly more per doubling of the level than the refitted
model's: by more than `SOFTENING_SHIFT` and by more than
`SOFTENING_SIGMAS` standard deviations of the data's own measurement noise
(`shift_noise`).
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
#: The level rule's threshold on (data - model) per doubling of the level,
#: vertical excitation.  Calibrated on no-effect subjects of two independent
#: realities diagnosed alone at 0.3 and 0.6 m/s^2 (bench/single_subject_null.py;
#: the subjects and their values in docs/history/data/single_subject_null.json):
#: it lies below every one of them so far (lowest -0.025, on `lumped`), while
#: the softening subjects of both realities met so far shifted by about
#: -0.056.  For scale: people's whole softening is about -0.13 per doubling
#: (x0.87; Fairley & Griffin 1989), the model's own most of that.
SOFTENING_SHIFT = 0.04
#: ... and the shift must exceed this many standard deviations of what the
#: data's measurement noise alone moves it by.
SOFTENING_SIGMAS = 3.0
#: Draws of the measurement noise behind that standard deviation (a fixed
#: seed: the same data give the same report).
NOISE_DRAWS = 200


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
        entry["data_per_doubling_std"] = shift_noise(rows, d, lo, hi, list(entry["segments"]))
        if H_model is not None:
            diff = entry["data_per_doubling"] - entry["model_per_doubling"]
            entry["compared"] = ("as much as" if not abs(diff) > RESONANCE_TOLERANCE
                                 else "more than" if diff < 0 else "less than")
        out[d] = entry
    return out


def shift_noise(rows: Rows, direction: str, lo: float, hi: float, segments,
                draws: int = NOISE_DRAWS, seed: int = 0) -> float:
    """The standard deviation of the data's per-doubling factor (median over
    `segments`) from measurement noise alone: the rows redrawn `draws` times
    with their H1 error (complex Gaussian, variance per component from the
    coherence and the number of averages, no model floor) and the peaks
    found again."""
    from .localize import relative_variance

    doublings = math.log2(hi / lo)
    rng = np.random.default_rng(seed)
    picks = []
    for seg in segments:
        ch = CHANNEL_NAMES.index(f"{seg}_{direction}")
        pair = []
        for lv in (lo, hi):
            m = rows.test_mask(direction, lv) & (rows.channel == ch)
            sd = np.sqrt(relative_variance(rows.coherence[m], rows.n_averages[m], 0.0)
                         ) * np.abs(rows.H[m])
            pair.append((rows.freq[m], rows.H[m], sd))
        picks.append(pair)
    factors = np.empty(draws)
    for k in range(draws):
        per_segment = []
        for pair in picks:
            pk = [peak_frequency(f, H + sd * (rng.standard_normal(len(H))
                                              + 1j * rng.standard_normal(len(H))))
                  for f, H, sd in pair]
            per_segment.append((pk[1] / pk[0]) ** (1.0 / doublings))
        factors[k] = np.median(per_segment)
    return float(np.std(factors))


def softening_rule(resonance: dict) -> dict | None:
    """The single-subject level rule on a `resonance_shift` result (with the
    model's prediction): `named` when the vertical resonance falls more per
    doubling than the model's by more than `SOFTENING_SHIFT` and by more than
    `SOFTENING_SIGMAS` of its noise; None without a vertical test at two
    levels."""
    e = resonance.get("z")
    if not e or "model_per_doubling" not in e:
        return None
    diff = e["data_per_doubling"] - e["model_per_doubling"]
    sd = e.get("data_per_doubling_std", 0.0)
    return {"effect": "softening", "direction": "z", "levels": e["levels"],
            "data_per_doubling": e["data_per_doubling"],
            "model_per_doubling": e["model_per_doubling"], "difference": diff,
            "noise_std": sd, "threshold": -SOFTENING_SHIFT, "sigmas": SOFTENING_SIGMAS,
            "named": bool(diff < -SOFTENING_SHIFT and diff < -SOFTENING_SIGMAS * sd)}


def apply_softening_rule(report: dict, names) -> None:
    """Record the level rule in a single-subject report (`level_rule`) and,
    when it names `softening` (a candidate of this diagnosis) and nothing
    else was named, make the verdict `explained` by it.  The candidate's own
    fit (its held-out share of the gap) is quoted beside it: it is judged on
    every channel and band, where the resonance shift weighs little."""
    rule = softening_rule(report["evidence"]["resonance"])
    report["level_rule"] = rule
    if (rule is None or not rule["named"] or "softening" not in names
            or report["verdict"] in ("explained", "ambiguous")):
        return
    st = report.get("structural") or {}
    fitted = next((e for e in st.get("ranking", []) if e["effect"] == "softening"), None)
    share = (f"{100 * fitted['effect_share']:.0f}% of the held-out gap beyond the "
             "discrepancy" if fitted else
             f"{100 * next(e['gap_reduction_heldout'] for e in report['ranking'] if e['effect'] == 'softening'):.0f}% "  # noqa: E501
             "of the held-out gap")
    report["verdict"] = "explained"
    report["best_effect"] = report["best_candidate"] = "softening"
    report["explanation"] = (
        f"level rule: the vertical resonance falls x{rule['data_per_doubling']:.3f} per "
        f"doubling of the level, the refitted model's x{rule['model_per_doubling']:.3f}: "
        f"the subject softens more than the model by {-rule['difference']:.3f} per doubling "
        f"(rule: beyond {SOFTENING_SHIFT:g} and {SOFTENING_SIGMAS:g} standard deviations of "
        f"the measurement noise, {rule['noise_std']:.3f}); the softening candidate's own "
        f"fit over every channel removes {share}. " + report["explanation"])
