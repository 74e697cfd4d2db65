"""Seat excitation signals (pure numpy; no Drake).

A `SeatSignal` is the seat's translational acceleration sampled at the
simulation time step h over the whole run: quiet for the settle time
(paper: 5 s), then a half-cosine onset, then the excitation.  Velocity and
displacement are integrated with the same semi-implicit Euler rule as
Drake's discrete solver (v+ = v + h a, x+ = x + h v+), so the seat motion
the simulated body feels and the one reported agree to round-off.

Every random signal takes a seed: the same seed gives the same bytes.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

AXES = ("x", "y", "z")
#: The paper's excitation: 0.1941 m/s^2 RMS (Desai et al. Sec. III).
PAPER_RMS = 0.1941
#: The paper's analysis band (0-12 Hz); random excitation starts at 0.1 Hz.
BAND_HZ = (0.1, 12.0)
KINDS = ("random", "multisine", "sweep", "sine", "csv")


class SignalError(ValueError):
    """An excitation request or file is invalid."""


@dataclass
class SeatSignal:
    """Seat acceleration samples a[k] at t_k = k h, shape (N, 3), in S."""

    time_step: float
    settle_time: float
    onset_time: float
    acceleration: np.ndarray
    kind: str = "random"
    description: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        # (+ 0.0: a new array, without negative zeros, which the excitation's
        # zero-order hold would turn positive: what the plant reads and
        # what is logged are then the same bits.)
        a = np.asarray(self.acceleration, float) + 0.0
        if a.ndim != 2 or a.shape[1] != 3:
            raise SignalError(f"seat acceleration must have shape (N, 3), got {a.shape}")
        if not np.all(np.isfinite(a)):
            k = int(np.argwhere(~np.isfinite(a))[0, 0])
            raise SignalError(f"seat acceleration is not finite at sample {k} "
                              f"(t={k * self.time_step:g} s)")
        self.acceleration = a
        h = self.time_step
        v = np.vstack([np.zeros(3), np.cumsum(a[:-1] * h, axis=0)])
        self.velocity = v
        self.displacement = np.vstack([np.zeros(3), np.cumsum(v[1:] * h, axis=0)])

    @property
    def num_samples(self) -> int:
        return len(self.acceleration)

    @property
    def duration(self) -> float:
        """End time of the run (s), settle time included."""
        return (self.num_samples - 1) * self.time_step

    @property
    def times(self) -> np.ndarray:
        return np.arange(self.num_samples) * self.time_step

    @property
    def steady_start(self) -> float:
        """Start of the full-amplitude excitation (after settle and onset)."""
        return self.settle_time + self.onset_time

    def rms(self) -> np.ndarray:
        """RMS per axis over the full-amplitude part (m/s^2)."""
        k0 = int(round(self.steady_start / self.time_step))
        part = self.acceleration[k0:]
        return np.sqrt(np.mean(part**2, axis=0)) if len(part) else np.zeros(3)

    def level(self) -> float:
        """One magnitude of the whole excitation (m/s^2): the RMS of the
        acceleration vector over the full-amplitude part, or a third of the
        vector's largest magnitude when that is more (a shock's peak, which
        its RMS hides; a random signal's peaks stay within about 3-4.5 RMS)."""
        a = self.acceleration
        peak = float(np.sqrt(np.max(np.einsum("ij,ij->i", a, a)))) if len(a) else 0.0
        return max(float(np.linalg.norm(self.rms())), peak / 3.0)

    def sample_index(self, t: float) -> int:
        k = int(math.floor(t / self.time_step + 1e-6))
        return min(max(k, 0), self.num_samples - 1)


def _rms_vector(rms, direction: str) -> np.ndarray:
    if direction not in ("x", "y", "z", "xyz"):
        raise SignalError(f"direction must be x, y, z or xyz, got {direction!r}")
    r = np.zeros(3)
    for ax in direction:
        r[AXES.index(ax)] = rms
    return r


def _check_rms(rms: float) -> float:
    if not (isinstance(rms, (int, float)) and math.isfinite(rms)) or rms < 0:
        raise SignalError(f"RMS must be a finite non-negative number in m/s^2, got {rms!r}")
    if rms > 20.0:
        raise SignalError(
            f"RMS {rms} m/s^2 is beyond whole-body vibration levels (<20 m/s^2); "
            "is it in mm/s^2 or in g?"
        )
    return float(rms)


def band_limited_noise(n: int, h: float, rms_per_axis, band=BAND_HZ, seed: int = 0) -> np.ndarray:
    """Gaussian noise, flat between band[0] and band[1] Hz (brick-wall in the
    frequency domain), scaled to the given RMS per axis.  Shape (n, 3)."""
    rng = np.random.default_rng(seed)
    white = rng.standard_normal((n, 3))
    spec = np.fft.rfft(white, axis=0)
    f = np.fft.rfftfreq(n, h)
    spec[(f < band[0]) | (f > band[1])] = 0.0
    x = np.fft.irfft(spec, n=n, axis=0)
    std = np.sqrt(np.mean(x**2, axis=0))
    return x / np.where(std > 0, std, 1.0) * np.asarray(rms_per_axis)


def multisine(n: int, h: float, rms_per_axis, band=BAND_HZ, resolution_hz: float = 0.05,
              seed: int = 0) -> np.ndarray:
    """Random-phase multisine (flat amplitude, seeded phases) on a grid of
    `resolution_hz` within the band; periodic over 1/resolution_hz s."""
    rng = np.random.default_rng(seed)
    freqs = np.arange(math.ceil(band[0] / resolution_hz), math.floor(band[1] / resolution_hz) + 1)
    freqs = freqs * resolution_hz
    t = np.arange(n) * h
    out = np.zeros((n, 3))
    for ax in range(3):
        phases = rng.uniform(0, 2 * np.pi, len(freqs))
        x = np.sin(2 * np.pi * np.outer(t, freqs) + phases).sum(axis=1)
        out[:, ax] = x / np.sqrt(np.mean(x**2))
    return out * np.asarray(rms_per_axis)


def sine_sweep(n: int, h: float, rms_per_axis, band=BAND_HZ) -> np.ndarray:
    """Logarithmic sine sweep from band[0] to band[1] Hz over the record."""
    t = np.arange(n) * h
    T = max(t[-1], h)
    f0, f1 = band
    k = math.log(f1 / f0)
    phase = 2 * np.pi * f0 * T / k * (np.exp(t / T * k) - 1.0)
    x = np.sin(phase)
    return np.outer(x / np.sqrt(np.mean(x**2)), rms_per_axis)


def sine(n: int, h: float, rms_per_axis, frequency_hz: float) -> np.ndarray:
    if not 0 < frequency_hz < 0.5 / h:
        raise SignalError(f"sine frequency {frequency_hz} Hz must be in (0, {0.5 / h:g}) Hz")
    t = np.arange(n) * h
    return np.outer(np.sqrt(2.0) * np.sin(2 * np.pi * frequency_hz * t), rms_per_axis)


def read_acceleration_csv(path: str | Path, h: float) -> np.ndarray:
    """Measured seat acceleration: CSV with columns t, seat_ax, seat_ay,
    seat_az (s, m/s^2), uniformly sampled; resampled to step h."""
    path = Path(path)
    if not path.is_file():
        raise SignalError(f"excitation file not found: {path}")
    with path.open(newline="") as f:
        rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
    if not rows:
        raise SignalError(f"{path}: empty file")
    header = [c.strip() for c in rows[0]]
    need = ["t", "seat_ax", "seat_ay", "seat_az"]
    missing = [c for c in need if c not in header]
    if missing:
        raise SignalError(f"{path}: missing column(s) {', '.join(missing)} "
                          f"(have {', '.join(header)})")
    cols = [header.index(c) for c in need]
    data = np.full((len(rows) - 1, 4), np.nan)
    for i, r in enumerate(rows[1:]):
        for j, c in enumerate(cols):
            try:
                data[i, j] = float(r[c])
            except (ValueError, IndexError):
                raise SignalError(f"{path}: row {i + 2}, column {need[j]}: not a number: "
                                  f"{r[c] if c < len(r) else ''!r}") from None
    bad = np.argwhere(~np.isfinite(data))
    if len(bad):
        i, j = bad[0]
        raise SignalError(f"{path}: row {i + 2}, column {need[j]} is NaN/inf")
    if len(data) < 10:
        raise SignalError(f"{path}: only {len(data)} samples; need a record of at least 10")
    t = data[:, 0]
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0))
        raise SignalError(f"{path}: time is not increasing at row {i + 3}")
    if np.max(np.abs(dt - dt.mean())) > 1e-3 * dt.mean():
        i = int(np.argmax(np.abs(dt - dt.mean())))
        raise SignalError(f"{path}: non-uniform sampling at row {i + 3} (dt={dt[i]:g} s, "
                          f"mean {dt.mean():g} s)")
    tt = np.arange(0.0, t[-1] - t[0] + 0.5 * h, h)
    return np.column_stack([np.interp(tt, t - t[0], data[:, k]) for k in (1, 2, 3)])


def signal_from_samples(t, acceleration, time_step: float = 1e-3, settle_time: float = 5.0,
                        onset_time: float = 0.0, description: str = "recorded") -> SeatSignal:
    """A SeatSignal replaying recorded seat acceleration (t, (N, 3)) after
    the settle time, resampled to `time_step` by linear interpolation."""
    t = np.asarray(t, float)
    a = np.asarray(acceleration, float)
    if a.ndim != 2 or a.shape[1] != 3 or len(t) != len(a) or len(t) < 10:
        raise SignalError(f"recorded seat acceleration must be (N>=10, 3) with N times, got "
                          f"{a.shape} and {t.shape}")
    h = float(time_step)
    tt = np.arange(0.0, t[-1] - t[0] + 0.5 * h, h)
    vib = np.column_stack([np.interp(tt, t - t[0], a[:, k]) for k in range(3)])
    n_on = int(round(onset_time / h))
    if n_on:
        k = np.arange(min(n_on, len(vib)))
        vib[: len(k)] *= 0.5 * (1.0 - np.cos(np.pi * k / n_on))[:, None]
    n_settle = int(round(settle_time / h))
    rms = np.sqrt(np.mean(a**2, axis=0))
    direction = "".join(ax for ax, r in zip(AXES, rms, strict=True) if r > 0.3 * rms.max())
    meta = {"kind": "csv", "direction": direction, "rms": float(rms.max()), "seed": None,
            "duration": float(tt[-1]), "band_hz": list(BAND_HZ)}
    return SeatSignal(h, n_settle * h, onset_time,
                      np.vstack([np.zeros((n_settle, 3)), vib]), "csv", description, meta)


def at_time_step(signal: SeatSignal, time_step: float) -> SeatSignal:
    """`signal` played at another time step: its samples after the settle
    time linearly interpolated at `time_step` (fade-in included, none added),
    the same settle time and metadata; `signal` itself at its own step.  So
    runs of one model at different steps see the same excitation."""
    if not (isinstance(time_step, int | float) and math.isfinite(time_step) and time_step > 0):
        raise SignalError(f"time step must be a positive number of seconds, got {time_step!r}")
    if abs(time_step - signal.time_step) < 1e-12:
        return signal
    k0 = int(round(signal.settle_time / signal.time_step))
    out = signal_from_samples(signal.times[k0:] - signal.times[k0], signal.acceleration[k0:],
                              time_step, signal.settle_time, 0.0)
    out.meta.update(signal.meta)
    return out


def make_seat_signal(
    kind: str = "random",
    direction: str = "z",
    rms: float = PAPER_RMS,
    duration: float = 60.0,
    seed: int = 0,
    time_step: float = 1e-3,
    settle_time: float = 5.0,
    onset_time: float = 1.0,
    frequency_hz: float = 4.0,
    band=BAND_HZ,
    csv_path: str | Path | None = None,
) -> SeatSignal:
    """Build the excitation for one run.

    `duration` is the vibration time after settling (onset included); the
    RMS applies to the full-amplitude part.  `direction` is x, y, z or xyz
    (simultaneous, independent per axis).  For `kind="csv"`, the file's
    signal is played as measured (`rms`, `direction` ignored).
    """
    if kind not in KINDS:
        raise SignalError(f"excitation kind must be one of {', '.join(KINDS)}, got {kind!r}")
    for name, val in (("duration", duration), ("settle_time", settle_time),
                      ("onset_time", onset_time)):
        if not (isinstance(val, (int, float)) and math.isfinite(val)) or val < 0:
            raise SignalError(
                f"{name} must be a finite non-negative number of seconds, got {val!r}")
    if kind != "csv" and duration <= onset_time:
        raise SignalError(f"duration ({duration} s) must exceed the onset time ({onset_time} s)")
    h = float(time_step)
    n_settle = int(round(settle_time / h))
    if kind == "csv":
        if csv_path is None:
            raise SignalError("kind='csv' needs csv_path")
        vib = read_acceleration_csv(csv_path, h)
        description = f"measured seat acceleration from {csv_path}"
    else:
        rms = _check_rms(rms)
        r = _rms_vector(rms, direction)
        n = int(round(duration / h)) + 1
        n_on = int(round(onset_time / h))
        if kind == "random":
            vib = band_limited_noise(n, h, np.ones(3), band, seed)
        elif kind == "multisine":
            vib = multisine(n, h, np.ones(3), band, seed=seed)
        elif kind == "sweep":
            vib = sine_sweep(n, h, np.ones(3), band)
        else:
            vib = sine(n, h, np.ones(3), frequency_hz)
        # Scale so that the full-amplitude part has exactly the RMS asked for.
        steady = vib[n_on:]
        scale = np.sqrt(np.mean(steady**2, axis=0))
        vib = vib / np.where(scale > 0, scale, 1.0) * r
        description = f"{kind} {rms:g} m/s^2 RMS in {direction}"
    n_on = int(round(onset_time / h))
    ramp = np.ones(len(vib))
    k = np.arange(min(n_on, len(vib)))
    ramp[: len(k)] = 0.5 * (1.0 - np.cos(np.pi * k / max(n_on, 1)))
    vib = vib * ramp[:, None]
    accel = np.vstack([np.zeros((n_settle, 3)), vib])
    meta = {"kind": kind, "direction": direction, "rms": rms, "seed": seed,
            "duration": duration, "band_hz": list(band)}
    return SeatSignal(h, n_settle * h, onset_time, accel, kind, description, meta)
