"""The reference group of the gap diagnosis (`reference`): K subjects
measured with one protocol, none with the effects in question; their mean
log transmissibility per row, each subject's deviation from it, and the
deviations' smoothed variance."""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..single.diagnose import DiagnosisError, LabData, load_lab_data
from ..single.localize import BANDS, MODEL_FLOOR, Rows, cell_keys, gap_value, localize

#: Fewest reference subjects: the leave-one-out null needs K - 1 >= 3 in
#: each group it forms, and the scatter's variance needs a few subjects.
MIN_SUBJECTS = 4
#: Subjects a reference group should have; below it the report carries a
#: caution (`group_size_caution`).  Each candidate's threshold
#: rests on K leave-one-out values, and those are heavy-tailed (most near
#: 0, one subject in 8-16 far above): with 8 the same candidate's threshold
#: varied tenfold from one group to the next.  Measured on `lumped` (stop
#: 45, `bench/rescore_blind.py --reference`): the same stored blind trials
#: diagnosed against their run's 8 subjects and against those 8 plus 8 of
#: another run of the same protocol: an effect named on 7 of 42 no-effect
#: subjects against 8, on 2 against 16; hidden effects found in 35 of 51
#: trials against 43 (docs/history/gap-diagnosis-on-realities.md, "A group of 16").
RECOMMENDED_SUBJECTS = 16
#: Bins of the running mean of the group's variance per channel (a variance
#: from K subjects is itself scattered by sqrt(2 / (K - 1)) ~ 50% at K = 8).
VARIANCE_SMOOTHING_BINS = 5



def _row_keys(rows: Rows) -> list[str]:
    return [f"{d}|{c}|{lv:.6g}|{f:.6f}" for d, c, lv, f in
            zip(rows.direction, rows.channel, rows.level, rows.freq, strict=True)]


def wrap_log(x: np.ndarray) -> np.ndarray:
    """log H with its phase wrapped to (-pi, pi]."""
    return x.real + 1j * (np.pi - (np.pi - x.imag) % (2 * np.pi))


def level_pairs(rows: Rows) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi): the rows measured in one direction, channel and frequency
    at two levels, each higher level with the lowest of its direction (index
    arrays into `rows`; empty without a second level or where the levels
    are not given)."""
    lowest: dict = {}
    for d, lv in zip(rows.direction, rows.level, strict=True):
        if np.isfinite(lv):
            lowest[d] = min(lowest.get(d, np.inf), round(float(lv), 6))
    at_lowest = {}
    for i, (d, c, lv, f) in enumerate(zip(rows.direction, rows.channel, rows.level, rows.freq,
                                          strict=True)):
        if np.isfinite(lv) and round(float(lv), 6) == lowest[d]:
            at_lowest[(d, c, round(float(f), 6))] = i
    lo, hi = [], []
    for i, (d, c, lv, f) in enumerate(zip(rows.direction, rows.channel, rows.level, rows.freq,
                                          strict=True)):
        j = at_lowest.get((d, c, round(float(f), 6)))
        if np.isfinite(lv) and round(float(lv), 6) > lowest[d] and j is not None:
            lo.append(j)
            hi.append(i)
    return np.array(lo, dtype=int), np.array(hi, dtype=int)


def smooth_over_frequency(rows: Rows, v: np.ndarray,
                          n: int = VARIANCE_SMOOTHING_BINS) -> np.ndarray:
    """Running mean of `v` over `n` frequency bins within each test and
    channel (rows are in frequency order there)."""
    out = np.empty_like(v)
    keys = [f"{d}|{c}|{lv:.6g}" for d, c, lv in zip(rows.direction, rows.channel, rows.level,
                                                     strict=True)]
    _, inv = np.unique(keys, return_inverse=True)
    kernel = np.ones(n)
    for k in range(inv.max() + 1):
        m = np.flatnonzero(inv == k)
        m = m[np.argsort(rows.freq[m])]
        out[m] = np.convolve(v[m], kernel, "same") / np.convolve(np.ones(len(m)), kernel, "same")
    return out


@dataclass
class ReferenceGroup:
    """K subjects measured with one protocol, without the effects in
    question.  `rows`: the protocol's rows (H = the group's geometric mean,
    gain and phase); `deviations` (K, rows): each subject's log H minus the
    mean; `variance`: their smoothed variance per row (complex, both
    components)."""

    sources: list[str]
    rows: Rows
    tests: list
    mean_log: np.ndarray
    deviations: np.ndarray
    variance: np.ndarray

    @property
    def size(self) -> int:
        return len(self.deviations)

    @classmethod
    def from_labs(cls, labs: list[LabData]) -> ReferenceGroup:
        if len(labs) < MIN_SUBJECTS:
            raise DiagnosisError(f"a reference group needs at least {MIN_SUBJECTS} subjects, "
                                 f"got {len(labs)}")
        keys = [_row_keys(lab.rows) for lab in labs]
        common = set(keys[0]).intersection(*keys[1:])
        first = labs[0]
        keep = np.array([k in common for k in keys[0]])
        if keep.sum() < 0.5 * len(keys[0]):
            raise DiagnosisError(
                "the reference subjects were not measured with one protocol: they share "
                f"{int(keep.sum())} of {len(keys[0])} rows (tests, channels, frequencies) of "
                f"{first.source}")
        rows = first.rows.take(keep)
        order = [k for k in keys[0] if k in common]
        logs = []
        for lab, ks in zip(labs, keys, strict=True):
            idx = {k: i for i, k in enumerate(ks)}
            H = lab.rows.H[[idx[k] for k in order]]
            if np.any(~np.isfinite(H)) or np.any(H == 0):
                raise DiagnosisError(f"{lab.source}: zero or non-finite transmissibility in "
                                     "the reference data")
            logs.append(np.log(H))
        seen = {}
        for lab, x in zip(labs, logs, strict=True):
            digest = hashlib.sha256(np.ascontiguousarray(x).tobytes()).hexdigest()
            if digest in seen:
                raise DiagnosisError(
                    f"{lab.source} holds the same data as {seen[digest]}: a subject listed "
                    "twice (e.g. a folder and a link to it) would narrow the group's scatter; "
                    "give each subject once")
            seen[digest] = lab.source
        pivot = logs[0]
        rel = np.array([wrap_log(x - pivot) for x in logs])
        mean_rel = rel.mean(axis=0)
        dev = rel - mean_rel
        K = len(labs)
        var = np.sum(np.abs(dev) ** 2, axis=0) / (K - 1)
        mean_log = pivot + mean_rel
        tests_there = {(d, round(lv, 6)) for d, lv in rows.tests}
        tests = [t for t in first.tests if (t.direction, round(t.level, 6)) in tests_there]
        return cls([lab.source for lab in labs], dataclasses.replace(rows, H=np.exp(mean_log)),
                   tests, mean_log, dev, smooth_over_frequency(rows, var))

    def without(self, j: int) -> ReferenceGroup:
        """The group less subject j (its deviations re-centred)."""
        keep = [i for i in range(self.size) if i != j]
        dev = self.deviations[keep]
        shift = dev.mean(axis=0)
        dev = dev - shift
        var = np.sum(np.abs(dev) ** 2, axis=0) / (len(keep) - 1)
        mean_log = self.mean_log + shift
        return ReferenceGroup([self.sources[i] for i in keep],
                              dataclasses.replace(self.rows, H=np.exp(mean_log)), self.tests,
                              mean_log, dev, smooth_over_frequency(self.rows, var))

    def subject_log(self, j: int) -> np.ndarray:
        return self.mean_log + self.deviations[j]

    def fingerprint(self) -> str:
        h = hashlib.sha256()
        for a in (self.mean_log, self.deviations, self.rows.freq, self.rows.level):
            h.update(np.ascontiguousarray(a).tobytes())
        h.update("|".join(_row_keys(self.rows)).encode())
        return h.hexdigest()[:20]

    def align(self, lab: LabData) -> np.ndarray:
        """Index of each group row in the subject's rows; a clear error when
        the subject lacks a test or channel of the group's protocol."""
        idx = {k: i for i, k in enumerate(_row_keys(lab.rows))}
        missing = [k for k in _row_keys(self.rows) if k not in idx]
        if missing:
            d, c, lv, f = missing[0].split("|")
            raise DiagnosisError(
                f"{lab.source}: {len(missing)} rows of the reference protocol are not in the "
                f"data (first: direction {d}, level {lv} m/s^2, channel {c}, {f} Hz); the "
                "subject and the reference group must be measured with the same tests")
        return np.array([idx[k] for k in _row_keys(self.rows)])


def expand_reference_paths(paths) -> list[Path]:
    """Subject folders: each path is a subject (frf.csv or timeseries.csv
    in it, or an frf.csv) or a folder of subject folders."""
    out = []
    for p in map(Path, paths):
        if p.is_file() or (p / "frf.csv").is_file() or (p / "timeseries.csv").is_file():
            out.append(p)
        elif p.is_dir():
            subs = sorted(q for q in p.iterdir() if q.is_dir() and (
                (q / "frf.csv").is_file() or (q / "timeseries.csv").is_file()))
            if not subs:
                raise DiagnosisError(f"{p}: no subject data (frf.csv) in it or its subfolders")
            out += subs
        else:
            raise FileNotFoundError(f"reference data not found: {p}")
    return out


def load_reference(paths, channels: str = "plane") -> ReferenceGroup:
    return ReferenceGroup.from_labs([load_lab_data(p, channels)
                                     for p in expand_reference_paths(paths)])


def model_form(group: ReferenceGroup, log_model: np.ndarray) -> dict:
    """Where the model (refit to the group) differs from the group mean:
    the cells beyond the group mean's uncertainty plus the model floor, each
    with its RMS log-gain difference."""
    rows = group.rows
    d = wrap_log(log_model - group.mean_log)
    chi = np.abs(d) ** 2 / (group.variance / group.size + 2 * MODEL_FLOOR**2)
    cells = localize(rows, chi)
    lo = np.array([b[0] for b in BANDS])[rows.band]
    for c in cells:
        m = (rows.direction == c["direction"]) & (rows.segment == c["segment"]) & \
            (rows.dof == c["dof"]) & (lo == c["f_lo_hz"])
        c["rms_log_gain_difference"] = float(np.sqrt(np.mean(d.real[m] ** 2)))
    return {"rms_log_gain_difference": float(np.sqrt(np.mean(d.real**2))),
            "rms_phase_difference_deg": float(np.degrees(np.sqrt(np.mean(d.imag**2)))),
            "gap": gap_value(chi, cell_keys(rows)), "cells": cells[:12],
            "significant_cells": int(sum(c["significant"] for c in cells))}


def group_size_caution(size: int) -> str | None:
    """What a group of `size` subjects means for the thresholds, when it is
    smaller than `group.RECOMMENDED_SUBJECTS` (None from there on)."""
    if size >= RECOMMENDED_SUBJECTS:
        return None
    return (f"a reference group of {size} subjects: each candidate's threshold rests on "
            f"{size} leave-one-out values, which scatter widely from one group to the next; "
            f"at least {RECOMMENDED_SUBJECTS} subjects are recommended (the `lumped` "
            f"reality's stored blind trials: an effect named on 7 of 42 no-effect "
            f"subjects against their groups of 8, on 2 against groups of 16; hidden effects "
            f"found in 35 of 51 trials against 43)")
