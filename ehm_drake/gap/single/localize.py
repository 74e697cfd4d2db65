"""Where the gap lies: model-versus-measurement residuals normalised by the
measurement's own uncertainty, per direction x segment x DoF x band.

Uncertainty of a measured H1 transmissibility row (Bendat & Piersol,
Random Data, 4th ed., Sec. 9.2.3): the normalized random error of the gain
and the standard deviation of the phase (rad) are both

    eps = sqrt(1 - g^2) / (|g| sqrt(2 n)),

g^2 the coherence and n the number of averages; the complex error then has
a standard deviation eps |H| per component.  A model floor of 3% of |H|
per component is added: the candidate models are equivalent
linearizations of a nonlinear simulation and differ from it by a few
percent even when the physics is right, which must not read as a gap.

A cell's statistic is chi^2 = sum over its rows of |H_model - H_meas|^2 /
sigma^2 (two degrees of freedom per row).  A cell is significant when
chi^2 exceeds the chi^2 quantile at p = 0.01 divided by the number of cells
(Bonferroni), i.e. noise alone flags a cell in fewer than 1% of datasets;
its share is its excess chi^2 - dof over the total excess.  The scalar gap
of a set of rows is the total excess over the degrees of freedom,
sum over cells of max(chi^2 - dof, 0) / sum of dof (0 = every cell within
the measurement noise; see `gap_value`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from ...analysis.formats import FrfData
from ...systems.outputs import CHANNEL_NAMES

BANDS = ((0.1, 1.0), (1.0, 2.5), (2.5, 5.0), (5.0, 8.0), (8.0, 12.0))
MODEL_FLOOR = 0.03
#: Coherence below which the H1 error formula is not trusted (g^2 floor).
COHERENCE_FLOOR = 0.05
SIGNIFICANCE = 0.01
#: Number of averages assumed when the data do not say (a 60 s record in
#: 10 s segments with 50% overlap).
DEFAULT_N_AVERAGES = 10


def band_index(f: np.ndarray) -> np.ndarray:
    """Band of each frequency (-1 outside 0.1-12 Hz); edges go to the
    upper band except 12 Hz."""
    out = np.full(len(f), -1)
    for i, (lo, hi) in enumerate(BANDS):
        last = i == len(BANDS) - 1
        out[(f >= lo - 1e-9) & ((f < hi - 1e-9) | (last & (f <= hi + 1e-9)))] = i
    return out


def band_label(i: int) -> str:
    lo, hi = BANDS[i]
    return f"{lo:g}-{hi:g} Hz"


@dataclass
class Rows:
    """The measured rows in arrays (only rows inside the bands)."""

    direction: np.ndarray
    segment: np.ndarray
    dof: np.ndarray
    channel: np.ndarray  # index into CHANNEL_NAMES
    freq: np.ndarray
    level: np.ndarray  # m/s^2 (NaN if not given)
    band: np.ndarray
    H: np.ndarray  # complex measured transmissibility (m/m, deg/m)
    coherence: np.ndarray
    n_averages: np.ndarray
    rel_var: np.ndarray  # (eps^2 + floor^2): variance per component / |H|^2

    def __len__(self) -> int:
        return len(self.freq)

    def take(self, mask) -> Rows:
        return Rows(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))

    @property
    def tests(self) -> list[tuple[str, float]]:
        """(direction, level) of every test, in order of appearance."""
        seen = []
        lv = np.where(np.isnan(self.level), -1.0, self.level)
        for d, v in zip(self.direction, lv, strict=True):
            key = (str(d), float(v))
            if key not in seen:
                seen.append(key)
        return [(d, (np.nan if v < 0 else v)) for d, v in seen]

    def test_mask(self, direction: str, level: float) -> np.ndarray:
        if np.isnan(level):
            return (self.direction == direction) & np.isnan(self.level)
        return (self.direction == direction) & np.isclose(self.level, level, rtol=1e-6)


def relative_variance(coherence: np.ndarray, n_averages: np.ndarray,
                      floor: float = MODEL_FLOOR) -> np.ndarray:
    """(eps^2 + floor^2): the variance per complex component over |H|^2."""
    g2 = np.clip(coherence, COHERENCE_FLOOR, 0.9999)
    return (1.0 - g2) / (2.0 * n_averages * g2) + floor**2


#: Bins of the running mean of the coherence (per channel) used for the
#: error estimate.
COHERENCE_SMOOTHING_BINS = 5


def coherence_for_error(frf: FrfData, n_averages: np.ndarray) -> np.ndarray:
    """The coherence that enters the error formula: per channel, a running
    mean over `COHERENCE_SMOOTHING_BINS` frequency bins, corrected for the
    estimator's bias, (n g^2 - 1)/(n - 1).  A single bin's coherence from
    ~10 averages is noisy and biased high where the true coherence is low
    (0.07 and 0.68 in neighbouring bins of a channel at coherence ~0.15):
    taken as is, it understates the error of exactly the worst rows."""
    out = np.array(frf.coherence, float)
    half = COHERENCE_SMOOTHING_BINS // 2
    for idx in frf._groups().values():
        order = idx[np.argsort(frf.freq_hz[idx])]
        c = out[order]
        pad = np.pad(c, half, mode="edge")
        kernel = np.ones(2 * half + 1) / (2 * half + 1)
        out[order] = np.convolve(pad, kernel, mode="valid")
    n = np.maximum(n_averages, 2.0)
    return np.clip((n * out - 1.0) / (n - 1.0), 0.0, 1.0)


#: Channels analysed per excitation direction: those a left-right symmetric
#: body moves in.  x and z excite the sagittal plane (x, z, pitch of every
#: segment); y excites the lateral motions (y, roll, yaw) and, through the
#: pelvis' roll and yaw, every DoF of the knees (left and right opposite).
#: Elsewhere a symmetric model predicts no response: there the data hold
#: only the subject's asymmetry and noise.
PLANE_CHANNELS = {
    "x": tuple(f"{s}_{d}" for s in ("pelvis", "trunk", "head", "knee_l", "knee_r")
               for d in ("x", "z", "pitch")),
    "z": tuple(f"{s}_{d}" for s in ("pelvis", "trunk", "head", "knee_l", "knee_r")
               for d in ("x", "z", "pitch")),
    "y": tuple(f"{s}_{d}" for s in ("pelvis", "trunk", "head") for d in ("y", "roll", "yaw"))
    + tuple(f"{k}_{d}" for k in ("knee_l", "knee_r")
            for d in ("x", "y", "z", "roll", "pitch", "yaw")),
}


def rows_from_frf(frf: FrfData, floor: float = MODEL_FLOOR,
                  default_n_averages: int = DEFAULT_N_AVERAGES,
                  channels: str = "plane") -> Rows:
    """The analysed rows of `frf`: inside the bands, not the first two bins of a
    Welch grid (`FrfData.lowest_welch_bins`) and, with channels = "plane" (default), in
    the excitation's plane of motion (`PLANE_CHANNELS`; "all" keeps every
    channel)."""
    if channels not in ("plane", "all"):
        raise ValueError(f"channels must be 'plane' or 'all', got {channels!r}")
    b = band_index(frf.freq_hz)
    H = frf.gain * np.exp(1j * np.radians(frf.phase_deg))
    n = np.where(np.isfinite(frf.n_averages), frf.n_averages, float(default_n_averages))
    names = np.char.add(np.char.add(frf.segment.astype(str), "_"), frf.dof.astype(str))
    keep = (b >= 0) & ~frf.lowest_welch_bins()
    if channels == "plane":
        keep &= np.array([nm in PLANE_CHANNELS[d] for nm, d in zip(names, frf.direction,
                                                                   strict=True)])
    index = {c: i for i, c in enumerate(CHANNEL_NAMES)}
    ch = np.array([index[c] for c in names])
    rows = Rows(frf.direction, frf.segment, frf.dof, ch, frf.freq_hz, frf.level_rms, b, H,
                frf.coherence, n, relative_variance(coherence_for_error(frf, n), n, floor))
    return rows.take(keep)


def chi2_rows(rows: Rows, H_model: np.ndarray) -> np.ndarray:
    """Per-row chi^2 (2 degrees of freedom each).  The error scales with
    the true |H|: the larger of the measured and the modelled magnitude (the
    measured one alone is biased low where the coherence is poor)."""
    mag2 = np.maximum(np.abs(rows.H), np.abs(H_model)) ** 2
    return np.abs(H_model - rows.H) ** 2 / (rows.rel_var * mag2 + 1e-300)


def bic_penalty(k: int, n_rows: int) -> float:
    """The BIC penalty k ln(2n) of k extra parameters on n complex rows."""
    return k * math.log(max(2 * n_rows, 2))


def delta_bic(chi_held: np.ndarray, chi_held_ref: np.ndarray, k: int, n_rows: int) -> float:
    """Held-out chi^2 change against a reference fit plus the BIC penalty
    k ln(2n) of k extra parameters on n complex rows (< 0: supported)."""
    return float(np.nansum(chi_held) - np.nansum(chi_held_ref) + bic_penalty(k, n_rows))


def mark_after(cells_before: list[dict], cells_after: list[dict]) -> list[dict]:
    """The cells before, each with the gap and significance it has after."""
    after = {(c["direction"], c["segment"], c["dof"], c["f_lo_hz"]): c for c in cells_after}
    out = []
    for c in cells_before:
        a = after[(c["direction"], c["segment"], c["dof"], c["f_lo_hz"])]
        out.append({**c, "gap_after": a["gap"], "significant_after": a["significant"]})
    return out


def gap_value(chi: np.ndarray, keys: np.ndarray | None = None) -> float:
    """The scalar gap of a set of rows: the excess chi^2 of every cell
    (direction x channel x band), floored at 0, summed and divided by the
    degrees of freedom, sum_c max(chi2_c - dof_c, 0) / sum_c dof_c (0 = every
    cell within the noise).  Cell-wise, so a few cells far outside the noise
    are not averaged away by many cells inside it.  Without `keys`, the rows
    form one cell.  Rows with a NaN chi^2 (not evaluated) are left out."""
    chi = np.asarray(chi, float)
    ok = np.isfinite(chi)
    if not np.any(ok):
        return 0.0
    if keys is None:
        return max(float(np.sum(chi[ok]) / (2.0 * ok.sum()) - 1.0), 0.0)
    _, inv = np.unique(np.asarray(keys)[ok], return_inverse=True)
    sums = np.bincount(inv, weights=chi[ok])
    dof = 2.0 * np.bincount(inv)
    return float(np.maximum(sums - dof, 0.0).sum() / dof.sum())


def cell_keys(rows: Rows) -> np.ndarray:
    """Integer id of the (direction, channel, band) cell of every row."""
    d = np.searchsorted(np.array(["x", "y", "z"]), rows.direction)
    return (d * len(CHANNEL_NAMES) + rows.channel) * len(BANDS) + rows.band


def localize(rows: Rows, chi: np.ndarray, alpha: float = SIGNIFICANCE) -> list[dict]:
    """Cells with their statistics, largest excess first."""
    keys = cell_keys(rows)
    uniq, inv = np.unique(keys, return_inverse=True)
    sums = np.bincount(inv, weights=chi)
    counts = np.bincount(inv)
    dof = 2.0 * counts
    excess = np.maximum(sums - dof, 0.0)
    total = excess.sum()
    threshold_p = alpha / max(len(uniq), 1)
    crit = chi2.isf(threshold_p, dof)
    out = []
    for k in range(len(uniq)):
        i = int(np.flatnonzero(inv == k)[0])
        out.append({
            "direction": str(rows.direction[i]),
            "segment": str(rows.segment[i]),
            "dof": str(rows.dof[i]),
            "f_lo_hz": BANDS[rows.band[i]][0],
            "f_hi_hz": BANDS[rows.band[i]][1],
            "share": float(excess[k] / total) if total > 0 else 0.0,
            "significant": bool(sums[k] > crit[k]),
            "chi2": float(sums[k]),
            "dof_chi2": int(dof[k]),
            "gap": float(max(sums[k] / dof[k] - 1.0, 0.0)),
            "p_value": float(chi2.sf(sums[k], dof[k])),
            "rows": int(counts[k]),
        })
    out.sort(key=lambda c: -c["chi2"] + c["dof_chi2"])
    return out
