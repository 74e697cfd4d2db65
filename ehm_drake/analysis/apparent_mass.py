"""Apparent mass (ISO 5982): seat-pan force over seat acceleration.

The modulus is normalized by the static seated mass (the mean vertical
pan force divided by g), so a rigid mass on the pan has 1 at every
frequency.  File `apparent_mass.csv`: columns
``direction,freq_hz,modulus_normalized,phase_deg,coherence``.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .spectral import apparent_mass

G = 9.81
COLUMNS = ("direction", "freq_hz", "modulus_normalized", "phase_deg", "coherence")


@dataclass
class ApparentMassTable:
    direction: np.ndarray
    freq_hz: np.ndarray
    modulus_normalized: np.ndarray
    phase_deg: np.ndarray
    coherence: np.ndarray
    static_mass_kg: float

    def select(self, direction: str):
        k = self.direction == direction
        return self.freq_hz[k], self.modulus_normalized[k], self.phase_deg[k], self.coherence[k]

    def to_csv(self, path: str | Path) -> Path:
        path = Path(path)
        with path.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(COLUMNS)
            for row in zip(self.direction, self.freq_hz, self.modulus_normalized,
                           self.phase_deg, self.coherence, strict=True):
                w.writerow([row[0], *(f"{v:.6g}" for v in row[1:])])
        return path


def apparent_mass_table(seat_acceleration, pan_force, fs: float, directions="xz",
                        static_mass: float | None = None, f_max: float = 12.0,
                        band=(0.05, 12.0)) -> ApparentMassTable:
    """Normalized apparent mass per excited direction.

    Parameters
    ----------
    seat_acceleration : (N, 3) seat acceleration, m/s^2.
    pan_force : (N, 3) force of the seat pan on the body, N.
    fs : sample rate, Hz.
    directions : axes to evaluate (each must be excited).
    static_mass : kg; default: mean vertical pan force / g.
    """
    a = np.asarray(seat_acceleration, float)
    F = np.asarray(pan_force, float)
    if a.shape != F.shape or a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"seat acceleration {a.shape} and pan force {F.shape} must both be (N, 3)")
    if static_mass is None:
        static_mass = float(np.mean(F[:, 2])) / G
    if not static_mass > 0:
        raise ValueError(f"static seated mass must be positive, got {static_mass} kg "
                         "(is the pan force the force ON the body, upward positive?)")
    rows = {k: [] for k in COLUMNS}
    for d in directions:
        ax = "xyz".index(d)
        est = apparent_mass(F[:, ax], a[:, ax], fs, static_mass, band=band, f_max=f_max)
        n = len(est[0])
        rows["direction"] += [d] * n
        rows["freq_hz"].append(est[0])
        rows["modulus_normalized"].append(est[1])
        rows["phase_deg"].append(est[2])
        rows["coherence"].append(est[3])
    return ApparentMassTable(
        np.array(rows["direction"]),
        *(np.concatenate(rows[k]) if rows[k] else np.zeros(0) for k in COLUMNS[1:]),
        static_mass_kg=static_mass,
    )
