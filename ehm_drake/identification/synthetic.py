"""Synthetic measured FRFs from the linear model, with estimation noise of a
given coherence (for identification studies and tests; the lab-like
nonlinear time-domain data generator is `ehm_drake.gap.lab.synth`)."""

from __future__ import annotations

import numpy as np

from ..analysis.equivalent import SeatSpectrum, equivalent_linear
from ..analysis.formats import FrfData
from ..analysis.linear import default_frequencies, frf_from_array, linearize
from ..diagram import build_diagram
from ..model.anthropometry import REFERENCE, BodyMeasures
from ..params import ModelParams
from ..systems.outputs import CHANNEL_NAMES, PAPER_CHANNELS

__all__ = ["PAPER_CHANNELS", "h1_noise_std", "synthetic_frf"]

def h1_noise_std(coherence: float, n_averages: int) -> float:
    """Normalized random error of an H1 gain (Bendat & Piersol):
    sqrt(1 - g^2) / (|g| sqrt(2 n)); also the phase error in rad."""
    g2 = coherence**2
    return float(np.sqrt(1.0 - g2) / (np.sqrt(g2) * np.sqrt(2.0 * n_averages)))


def synthetic_frf(params: ModelParams, directions: str = "xyz", channels=None, freqs=None,
                  coherence: float = 0.9, n_averages: int = 30, seed: int = 0,
                  measures: BodyMeasures = REFERENCE, level_rms: float | None = None) -> FrfData:
    """Linear-model transmissibility of `params` on the paper's channels, with
    log-normal gain and Gaussian phase noise of an H1 estimate at the given
    coherence and number of averages (seeded).  With `level_rms` (m/s^2),
    each direction is its own test at that level (flat 0.1-12 Hz) and the
    model is the equivalent-linear one there (its softening); without, the
    model at rest."""
    freqs = default_frequencies() if freqs is None else np.asarray(freqs, float)
    model = build_diagram(params, measures, None, guard=False, seat_forces=False)
    if level_rms is None:
        T = linearize(model, method="fd", outputs=["channels"]).transmissibility_array(
            freqs, directions)
    else:
        # One test per direction at the level: the model's softening there
        # (`ehm_drake.analysis.equivalent`), as the fit compares it.
        T = np.empty((len(freqs), len(CHANNEL_NAMES), len(directions)), complex)
        for j, d in enumerate(directions):
            lm = equivalent_linear(model, SeatSpectrum.flat(d, level_rms),
                                   outputs=["channels"]).linear
            T[:, :, j] = lm.transmissibility_array(freqs, d)[:, :, 0]
    frf = frf_from_array(T, freqs, directions, coherence)
    chans = channels or PAPER_CHANNELS
    keep = np.zeros(len(frf), bool)
    for d in directions:
        for seg, dof in chans[d]:
            keep |= (frf.direction == d) & (frf.segment == seg) & (frf.dof == dof)
    frf = frf._take(np.flatnonzero(keep))
    rng = np.random.default_rng(seed)
    sigma = h1_noise_std(coherence, n_averages)
    gain = frf.gain * np.exp(sigma * rng.standard_normal(len(frf)))
    phase = frf.phase_deg + np.degrees(sigma * rng.standard_normal(len(frf)))
    phase = (phase + 180.0) % 360.0 - 180.0
    return FrfData(frf.direction, frf.segment, frf.dof, frf.freq_hz, gain, phase,
                   frf.coherence, None if level_rms is None else np.full(len(frf), level_rms))
