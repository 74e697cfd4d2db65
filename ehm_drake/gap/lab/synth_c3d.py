"""A virtual motion-capture lab: a simulated test written as a C3D session.

`synth --c3d` writes each test's record the way the lab of
``ehm_drake/data/marker_map_example.yaml`` would record it: rigid clusters of 4 markers on
the pelvis, trunk, head and thighs and of 6 on the seat (pan and backrest), in a lab frame
turned 90 deg about z from the seat's axes, in mm; the seat accelerometer (3 axes, 0.0102 V
per m/s^2) as analog channels at the marker rate.  The markers carry motion-capture noise
and dropouts, so reading the sessions back (`ehm_drake.analysis.mocap`) exercises the whole
lab path:

* noise: white, `MARKER_NOISE_M` RMS per coordinate and sample (optical systems: 0.05-0.2 mm);
* dropouts: each marker occluded over `MARKER_DROPOUT` of the frames, in bursts of 1-6
  frames; and `FRAME_DROPOUT` of the frames lost whole (every marker), in bursts of 1-3;
  together at most 9 frames (45 ms at 200 Hz), within the map's ``max_gap_s``.

A body marker is placed rigidly on the segment: from the channels of the test (the
segment's tracked point M and its rotation, relative to the reference pose, on the seat
axes), marker k is at ``p_M_ref + dp(t) + R(t) o_k``, where ``o_k`` is its offset from M in
the reference pose and ``R(t)`` the channels' roll-pitch-yaw; the seat markers follow the
seat's displacement (the seat acceleration integrated twice, with the drift of the
record's absolute translations, so the body stays on the seat).  Read back without noise
or dropouts, the channels are recovered to the C3D's float32 precision (tests/test_c3d.py).
"""

from __future__ import annotations

import numpy as np

from ...analysis.formats import TimeSeriesData
from ...analysis.formats.c3d import C3DSession
from ...analysis.marker_map import EXAMPLE_MARKER_MAP, load_marker_map

__all__ = ["MARKER_NOISE_M", "MARKER_DROPOUT", "FRAME_DROPOUT", "virtual_session",
           "MARKER_MAP_FILENAME", "C3D_FOLDER"]

MARKER_NOISE_M = 1.5e-4
MARKER_DROPOUT = 0.02
FRAME_DROPOUT = 0.02
#: Where `synth --c3d` puts the sessions and the map, inside its data folder.
C3D_FOLDER = "c3d"
MARKER_MAP_FILENAME = "marker_map.yaml"
#: The seat frame's origin in the lab (m); the seat's axes in the lab: the map's.
p_LoSo_L = np.array([1.5, 2.0, 0.45])

#: Segment points M in the reference pose (seat axes, m; where a seated adult's are).
_M = {"pelvis": (0.12, 0.0, 0.12), "trunk": (0.0, 0.0, 0.45), "head": (0.08, 0.0, 0.80),
      "knee_l": (0.45, 0.10, 0.10), "knee_r": (0.45, -0.10, 0.10)}
#: Marker offsets from M (seat axes, m), consistent with the example map's origins; each
#: cluster asymmetric (a symmetric one fits a swap of its markers turned over).
_OFFSETS = {
    "pelvis": {"LASI": (0.10, 0.12, 0.05), "RASI": (0.10, -0.12, 0.05),
               "LILC": (0.0, 0.15, 0.10), "RILC": (0.0, -0.15, 0.10)},
    "trunk": {"STRN": (0.18, 0.0, -0.05), "CLAV": (0.16, 0.0, 0.12),
              "LSHO": (0.02, 0.18, 0.15), "RSHO": (0.02, -0.18, 0.15)},
    "head": {"LFHD": (0.08, 0.07, 0.05), "RFHD": (0.08, -0.07, 0.05),
             "LBHD": (-0.08, 0.07, 0.06), "RBHD": (-0.06, -0.07, 0.07)},
    "knee_l": {"LKNE": (0.0, 0.05, 0.0), "LTH1": (-0.12, 0.08, 0.06),
               "LTH2": (-0.22, 0.08, -0.02), "LTH3": (-0.17, 0.03, 0.10)},
    "knee_r": {"RKNE": (0.0, -0.05, 0.0), "RTH1": (-0.12, -0.08, 0.06),
               "RTH2": (-0.22, -0.08, -0.02), "RTH3": (-0.17, -0.03, 0.10)},
}
#: The seat's markers (seat axes, m): the pan's corners and the backrest's top (spread in
#: height, they resolve the seat's pitch and roll: its rotation noise, times the lever arm
#: up to the head, adds to the segments' translations).
_SEAT = {"SEAT_FL": (0.45, 0.25, 0.0), "SEAT_FR": (0.45, -0.25, 0.0),
         "SEAT_BL": (-0.05, 0.25, 0.0), "SEAT_BR": (-0.05, -0.25, 0.0),
         "BACK_L": (-0.12, 0.22, 0.75), "BACK_R": (-0.12, -0.22, 0.75)}


def _rotations(rpy: np.ndarray) -> np.ndarray:
    """(F, 3) roll, pitch, yaw (rad) -> (F, 3, 3) Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = np.cos(rpy[:, 0]), np.sin(rpy[:, 0])
    cp, sp = np.cos(rpy[:, 1]), np.sin(rpy[:, 1])
    cy, sy = np.cos(rpy[:, 2]), np.sin(rpy[:, 2])
    return np.stack([
        np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], axis=-1),
        np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], axis=-1),
        np.stack([-sp, cp * sr, cp * cr], axis=-1)], axis=1)


def _displacement(acc: np.ndarray, fs: float, f_lo: float = 0.05) -> np.ndarray:
    """(F, 3) acceleration -> displacement (FFT double integration above `f_lo`)."""
    n = len(acc)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    A = np.fft.rfft(acc - acc.mean(axis=0), axis=0)
    w = 2 * np.pi * np.where(f > f_lo, f, np.inf)
    return np.fft.irfft(-A / w[:, None] ** 2, n, axis=0)


def _seat_path(ts: TimeSeriesData) -> np.ndarray:
    """(F, 3) the seat's displacement in the lab: its acceleration integrated twice, plus
    the straight-line drift of the record's absolute translations (the simulation's seat
    displacement drifts with the velocity it has when the record starts), so the body
    stays on the seat."""
    d = _displacement(ts.seat_acc, ts.fs)
    pelvis = np.column_stack([ts.channels[f"pelvis_{a}"] for a in "xyz"])
    A = np.column_stack([np.ones(ts.n_samples), ts.t - ts.t[0]])
    coef, *_ = np.linalg.lstsq(A, pelvis - d, rcond=None)
    return d + A @ coef


def _bursts(rng, n: int, fraction: float, longest: int) -> np.ndarray:
    """A mask of ~`fraction` of `n` frames in bursts of 1..`longest` frames."""
    mask = np.zeros(n, bool)
    if fraction <= 0:
        return mask
    count = int(round(fraction * n / ((1 + longest) / 2)))
    for start, length in zip(rng.integers(0, n, count), rng.integers(1, longest + 1, count),
                             strict=True):
        mask[start:start + length] = True
    return mask


def virtual_session(ts: TimeSeriesData, seat_acc: np.ndarray, seed: int,
                    noise_m: float = MARKER_NOISE_M, marker_dropout: float = MARKER_DROPOUT,
                    frame_dropout: float = FRAME_DROPOUT) -> C3DSession:
    """The C3D session of a test: `ts` its noise-free record (every channel of the five
    segments), `seat_acc` (F, 3) the accelerometer's record (m/s^2, with its noise), the
    markers' noise and dropouts seeded by `seed`."""
    mmap = load_marker_map(EXAMPLE_MARKER_MAP)
    R_LS = mmap.R_LS
    rng = np.random.default_rng(np.random.SeedSequence([seed, 4]))
    n = ts.n_samples
    labels, tracks = [], []
    d_S = _seat_path(ts)
    for name, o in _SEAT.items():
        labels.append(name)
        tracks.append(np.asarray(o) + d_S)
    for seg, offsets in _OFFSETS.items():
        dp = np.column_stack([ts.channels[f"{seg}_{d}"] for d in "xyz"])
        R = _rotations(np.radians(np.column_stack([ts.channels[f"{seg}_{d}"]
                                                   for d in ("roll", "pitch", "yaw")])))
        for name, o in offsets.items():
            labels.append(name)
            tracks.append(np.asarray(_M[seg]) + dp + R @ np.asarray(o))
    p_S = np.stack(tracks, axis=1)  # (F, markers, 3) seat axes, m
    p_L = p_LoSo_L + p_S @ R_LS.T
    p_L = p_L + noise_m * rng.standard_normal(p_L.shape)
    for k in range(len(labels)):
        p_L[_bursts(rng, n, marker_dropout, 6), k] = np.nan
    p_L[_bursts(rng, n, frame_dropout, 3)] = np.nan
    acc = {a.axis: a for a in mmap.accelerometers}
    analogs = np.column_stack([acc[d].sign * acc[d].sensitivity * seat_acc[:, i]
                               for i, d in enumerate("xyz")])
    return C3DSession(point_rate=ts.fs, point_units=mmap.units, labels=tuple(labels),
                      points=p_L / mmap.scale_m, analog_rate=ts.fs,
                      analog_labels=tuple(acc[d].channel for d in "xyz"),
                      analog_units=tuple(acc[d].unit for d in "xyz"), analogs=analogs)
