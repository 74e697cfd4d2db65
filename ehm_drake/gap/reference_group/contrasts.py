"""Empirical effect signatures from contrast measurements of the reference group.

A lab can impose several candidate effects on some subjects of its reference
group and measure them again with the same protocol: hands resting on the
thighs or not (`arms`), tensed or relaxed (`cocontraction`), leaning on the
backrest or not (`backrest_separation`), another cushion, foam or cover (the
seat effects).  The change of one subject, delta = log H(with the effect) -
log H(without), is the effect's signature on a human body, with no model in
it.  Against a reference group the model-based signature (`reference._Scorer`:
the EHM's change of log H at the group's anchor) is the weak part on bodies
that are not the model: on the stored blind runs the effects missed carried
enough change to pass every threshold had a candidate followed them (a perfect
signature would have scored 3-60 times the family-wise bar on `lumped` seed
2062's 13 misses), but the EHM's own versions of arms, co-contraction, visceral
mass and reflex delay act elsewhere (docs/history/gap-diagnosis-on-realities.md).

Layout: a folder ``contrasts/<effect>/<subject>/`` (frf.csv or timeseries.csv,
as a subject folder), where ``<effect>`` is a candidate's name and ``<subject>``
the folder name of one of the reference group's subjects: the same subject
measured with the effect.  At least `MIN_CONTRASTS` subjects per effect.

Scoring (`ContrastScorer`): the signature s is the mean delta over the
effect's contrast subjects, smoothed over frequency (`SIGNATURE_SMOOTHING_HZ`);
for the group's own subject j in the leave-one-out null, the mean over the
others, so that no subject's own contrast scores it.
It is fitted to a subject's residual r against the group with one amplitude
a >= 0 (the effect's strength relative to the contrasts'), the group's scatter
profiled as in `reference._Scorer.score` (the K deviations as a low-rank
covariance, `scatter.profile_nuisance`), held out per test (a and the nuisance
fitted on the other tests); and, with two levels, to the subject's level
differences (`scatter._LevelDesign`) with its own amplitude.  The result has
the fields of a model-based candidate's (`reference._Scorer.score`), so the
evidence (held-out chi^2 gain plus level gain), the thresholds and the
verdict are the same code and on the same scale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..single.diagnose import DiagnosisError, candidate_names, load_lab_data
from ..single.localize import BANDS, Rows, cell_keys
from .group import (
    ReferenceGroup,
    expand_reference_paths,
    level_pairs,
    smooth_over_frequency,
    wrap_log,
)
from .scatter import _LevelDesign

#: Contrast subjects an effect needs: the leave-one-out null of a group
#: subject that is one of them scores it with the others' mean.
MIN_CONTRASTS = 2
#: Name of the contrasts folder inside a reference folder (`find_contrasts`).
CONTRASTS_FOLDER = "contrasts"
#: Width (Hz) of the running mean over frequency, within each test and
#: channel, that a signature is smoothed with: a contrast's change per bin
#: is mostly the noise of two sittings (short records: 4 Welch averages at
#: 30 s), which an amplitude fitted to a subject's residual follows as much
#: as the change itself; an effect changes a resonance at least as wide as
#: ~1 Hz (the body's half-power bandwidths 2 zeta f: 1-3 Hz for the 4-6 Hz
#: vertical mode, zeta 0.2-0.4).  On the stored groups' contrasts the
#: subjects' agreement rises from 0.06-0.84 per bin to 0.25-0.96 at 0.9 Hz
#: (docs/history/gap-diagnosis-on-realities.md).  0: none.
SIGNATURE_SMOOTHING_HZ = 0.9
#: Below this agreement (see `contrast_quality`) an effect's contrasts are
#: said to disagree: their common change is weaker than what differs
#: between them (the sittings' noise, or a condition imposed differently).
LOW_AGREEMENT = 0.3


def smoothing_bins(rows: Rows, width_hz: float = SIGNATURE_SMOOTHING_HZ) -> int:
    """Odd number of bins nearest `width_hz` on the rows' frequency grid
    (1: no smoothing)."""
    f = np.unique(np.round(rows.freq, 9))
    if width_hz <= 0 or len(f) < 2:
        return 1
    n = int(round(width_hz / float(np.median(np.diff(f)))))
    return max(1, n + 1 - n % 2)


@dataclass
class Contrasts:
    """{effect: (subject indices in the group, deltas (n, rows) complex)}
    on the group's rows (`rows`; with them the signatures are smoothed over
    `SIGNATURE_SMOOTHING_HZ`)."""

    by_effect: dict
    source: str
    rows: Rows | None = None

    @property
    def effects(self) -> list[str]:
        return list(self.by_effect)

    def smooth(self, delta: np.ndarray) -> np.ndarray:
        """`delta` (complex, per row) smoothed over frequency within each
        test and channel (unchanged without rows)."""
        if self.rows is None:
            return delta
        n = smoothing_bins(self.rows)
        return delta if n == 1 else smooth_over_frequency(self.rows, delta, n)

    def signature(self, effect: str, without: int | None = None) -> np.ndarray:
        """Mean delta of `effect`'s contrast subjects (less subject
        `without` of the group, when it is one of them), smoothed."""
        subjects, deltas = self.by_effect[effect]
        keep = [i for i, j in enumerate(subjects) if j != without]
        return self.smooth(deltas[keep].mean(axis=0))

    def describe(self) -> dict:
        return {e: len(s) for e, (s, _) in self.by_effect.items()}


def find_contrasts(reference) -> Path | None:
    """The contrasts folder of a reference given as one folder (None when
    it has none, or when the reference is a list of subject folders or a
    loaded `ReferenceGroup`)."""
    if isinstance(reference, ReferenceGroup):
        return None
    paths = [reference] if isinstance(reference, (str, Path)) else list(reference)
    if len(paths) != 1:
        return None
    folder = Path(paths[0]) / CONTRASTS_FOLDER
    return folder if folder.is_dir() else None


def load_contrasts(folder, group: ReferenceGroup, channels: str = "plane") -> Contrasts:
    """The contrast measurements in `folder` (see the module doc), each
    paired with its subject in `group`; clear errors for an unknown effect
    or subject, another protocol, or bad values."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DiagnosisError(f"contrasts folder not found: {folder}")
    names = {Path(s).name: j for j, s in enumerate(group.sources)}
    by_effect = {}
    for eff_dir in sorted(p for p in folder.iterdir() if p.is_dir()):
        effect = eff_dir.name
        candidate_names([effect])  # a clear error for an unknown effect
        subjects, deltas = [], []
        for sub in expand_reference_paths([eff_dir]):
            name = sub.name if sub.is_dir() else sub.parent.name
            if name not in names:
                raise DiagnosisError(
                    f"{sub}: contrast of a subject not in the reference group; name its folder "
                    f"after one of the group's subjects ({', '.join(sorted(names))})")
            j = names[name]
            if j in subjects:
                raise DiagnosisError(f"{eff_dir}: subject {name} is given twice")
            lab = load_lab_data(sub, channels)
            H = lab.rows.H[group.align(lab)]
            if np.any(~np.isfinite(H)) or np.any(H == 0):
                raise DiagnosisError(f"{lab.source}: zero or non-finite transmissibility in "
                                     "the contrast data")
            subjects.append(j)
            deltas.append(wrap_log(np.log(H) - group.subject_log(j)))
        if len(subjects) < MIN_CONTRASTS:
            raise DiagnosisError(
                f"{eff_dir}: {len(subjects)} contrast subject(s); an effect needs at least "
                f"{MIN_CONTRASTS} (the leave-one-out null scores each of them with the others)")
        by_effect[effect] = (subjects, np.array(deltas))
    if not by_effect:
        raise DiagnosisError(f"{folder}: no effect folders with contrast subjects in it")
    return Contrasts(by_effect, str(folder), group.rows)


class ContrastScorer:
    """Empirical signatures fitted to residuals against one group (see the
    module doc).  The per-fold normal equations of the scatter are formed
    once."""

    def __init__(self, group: ReferenceGroup):
        K = group.size
        self.group = group
        self.sw = 1.0 / np.sqrt(np.maximum(group.variance, 1e-12) * (1 + 1 / K))
        self.A = group.deviations.T * math.sqrt((1 + 1 / K) / (K - 1)) * self.sw[:, None]
        every = np.ones(len(self.sw), bool)
        self.folds = [(every, every)] + [
            (~m, m) for m in (group.rows.test_mask(t.direction, t.level) for t in group.tests)]
        self._gram = [self._normal(self.A, train) for train, _ in self.folds]
        self.pairs = level_pairs(group.rows)

    @staticmethod
    def _normal(A, train):
        At = np.vstack([A[train].real, A[train].imag])
        return At, At.T @ At + np.eye(At.shape[1])

    @staticmethod
    def _fit(At, G, y, c):
        """min |y - At u - a c|^2 + |u|^2 over u and a >= 0 (c None: a = 0)."""
        b = At.T @ y
        u0 = np.linalg.solve(G, b)
        if c is None or not c @ c > 0.0:  # (a signature with no rows here)
            return u0, 0.0
        n = len(b)
        M = np.empty((n + 1, n + 1))
        M[:n, :n] = G
        M[:n, n] = M[n, :n] = At.T @ c
        M[n, n] = c @ c
        z = np.linalg.solve(M, np.append(b, c @ y))
        if z[n] <= 0.0:
            return u0, 0.0
        return z[:n], float(z[n])

    def _chi(self, x, s):
        """Per-row chi^2 on all rows and held out per test, and the
        amplitude fitted on all rows."""
        n = len(x)
        chi_all = np.full(n, np.nan)
        chi_held = np.full(n, np.nan)
        a_all = 0.0
        for k, ((train, where), (At, G)) in enumerate(zip(self.folds, self._gram, strict=True)):
            y = np.concatenate([x[train].real, x[train].imag])
            c = None if s is None else np.concatenate([s[train].real, s[train].imag])
            u, a = self._fit(At, G, y, c)
            e = x - self.A @ u - (a * s if s is not None else 0.0)
            if k == 0:
                chi_all = np.abs(e) ** 2
                a_all, u_all = a, u
            else:
                chi_held[where] = np.abs(e[where]) ** 2
        return chi_all, chi_held, a_all, float(u_all @ u_all)

    def _level_gain(self, r, s) -> tuple[float, float]:
        lo, hi = self.pairs
        if not len(lo):
            return 0.0, 0.0
        L = _LevelDesign(r, self.group, lo, hi)
        At = np.vstack([L.A.real, L.A.imag])
        G = At.T @ At + np.eye(At.shape[1])
        x = L.dr * L.sw
        c = L.delta(s) * L.sw
        y = np.concatenate([x.real, x.imag])
        cc = np.concatenate([c.real, c.imag])

        def cost(u, a):  # |x - A u - a c|^2 + |u|^2 (`_LevelDesign.cost` at a = 0)
            return float(np.sum((y - At @ u - a * cc) ** 2) + u @ u)
        u, a = self._fit(At, G, y, cc)
        # Both costs by the same arithmetic, so that a = 0 gains exactly 0.
        return cost(self._fit(At, G, y, None)[0], 0.0) - cost(u, a), a

    def score(self, r: np.ndarray, effect: str, s: np.ndarray) -> dict:
        """`effect`'s empirical signature `s` fitted to residual r: the
        fields of `reference._Scorer.score`'s entries."""
        x = r * self.sw
        chi_all, chi_held, a, prior = self._chi(x, s * self.sw)
        level, a_level = self._level_gain(r, s)
        return {"chi_all": chi_all, "chi_heldout": chi_held, "coords": [a],
                "cost": float(np.sum(chi_all) + prior), "signature": a * s,
                "level_gain": level, "level_coords": [a_level], "level_gain_at_fit": 0.0,
                "amplitude_driven": False,
                "params": {effect: {"contrast_amplitude": a}},
                "level_params": {effect: {"contrast_amplitude": a_level}}}

    def baseline(self, r: np.ndarray) -> dict:
        """No candidate (the "none" entry)."""
        chi_all, chi_held, _, prior = self._chi(r * self.sw, None)
        return {"chi_all": chi_all, "chi_heldout": chi_held, "coords": [],
                "cost": float(np.sum(chi_all) + prior), "level_gain": 0.0}


def contrast_evidence(res: dict, base: dict) -> float:
    """Held-out chi^2 gain over no candidate plus the level gain (the
    model-based candidates' `reference._evidence` for a level-dependent,
    not amplitude-driven candidate)."""
    return float(np.nansum(base["chi_heldout"]) - np.nansum(res["chi_heldout"])
                 + res["level_gain"])


def contrast_nulls(group: ReferenceGroup, contrasts: Contrasts, effects=None) -> dict:
    """{effect: [evidence of reference subject j against the other K - 1,
    with the signature of the contrasts other than j's own]}, for `effects`
    (default every effect the contrasts hold)."""
    effects = list(contrasts.effects if effects is None else effects)
    unknown = [e for e in effects if e not in contrasts.effects]
    if unknown:
        raise DiagnosisError(f"{contrasts.source}: no contrasts for {', '.join(unknown)}")
    out = {e: [] for e in effects}
    for j in range(group.size):
        sub = group.without(j)
        r = wrap_log(group.subject_log(j) - sub.mean_log)
        scorer = ContrastScorer(sub)
        base = scorer.baseline(r)
        for e in effects:
            res = scorer.score(r, e, contrasts.signature(e, without=j))
            out[e].append(contrast_evidence(res, base))
    return out


def contrast_quality(group: ReferenceGroup, contrasts: Contrasts, effects=None) -> dict:
    """What a lab can read off its contrasts before any subject is
    diagnosed, per effect (default every effect the contrasts hold), on the
    subjects' changes smoothed as the signature is (`Contrasts.smooth`) and
    the rows whitened by the group's scatter (w = 1 / the smoothed variance):

    - ``subjects``: the group's subjects measured with the effect;
    - ``rms_change_sd``: the signature's (mean change's) RMS per row, in
      units of the group's between-subject scatter there;
    - ``agreement``: how far each contrast subject's change follows the
      others' mean (whitened correlation, averaged over the subjects): 1 =
      the same change in every subject, 0 = nothing in common, below
      `LOW_AGREEMENT` the change is mostly what differs between the
      sittings (noise) or between the subjects;
    - ``cells``: where the change is common to the subjects (direction x
      channel x band; the whitened products of every two subjects' changes,
      summed over the cell), the three largest, each with its share of the
      common change and the signature's RMS log-gain change there.
    """
    effects = list(contrasts.effects if effects is None else effects)
    w = 1.0 / np.maximum(group.variance, 1e-12)
    _, inv = np.unique(cell_keys(group.rows), return_inverse=True)
    rows = group.rows
    out = {}
    for e in effects:
        subjects, raw = contrasts.by_effect[e]
        n = len(subjects)
        if n < MIN_CONTRASTS:
            raise DiagnosisError(f"{contrasts.source}: {e} has {n} contrast subject(s); "
                                 f"their agreement needs at least {MIN_CONTRASTS}")
        deltas = np.array([contrasts.smooth(d) for d in raw])
        s = deltas.mean(axis=0)
        agree = []
        for i in range(n):
            m = np.delete(deltas, i, axis=0).mean(axis=0)
            den = math.sqrt(np.sum(w * np.abs(deltas[i]) ** 2) * np.sum(w * np.abs(m) ** 2))
            agree.append(np.sum(w * (deltas[i] * np.conj(m)).real) / den if den > 0 else 0.0)
        # The mean product of two subjects' changes: the common change's
        # energy (the sittings' noise, independent, averages out).
        common = (np.abs(deltas.sum(axis=0)) ** 2 - np.sum(np.abs(deltas) ** 2, axis=0)) \
            / (n * (n - 1))
        energy = np.bincount(inv, weights=w * common)
        total = np.sum(np.maximum(energy, 0.0))
        cells = []
        for k in np.argsort(-energy)[:3]:
            if energy[k] <= 0:
                break
            m = inv == k
            i = int(np.flatnonzero(m)[0])
            cells.append({"direction": str(rows.direction[i]), "segment": str(rows.segment[i]),
                          "dof": str(rows.dof[i]), "f_lo_hz": BANDS[rows.band[i]][0],
                          "f_hi_hz": BANDS[rows.band[i]][1], "share": float(energy[k] / total),
                          "rms_log_gain_change": float(np.sqrt(np.mean(s.real[m] ** 2)))})
        out[e] = {"subjects": [Path(group.sources[j]).name for j in subjects],
                  "rms_change_sd": float(np.sqrt(np.mean(w * np.abs(s) ** 2))),
                  "agreement": float(np.mean(agree)), "cells": cells}
    return out
