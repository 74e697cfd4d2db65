"""Equivalent-linear models: the linearization of the body at a test's
vibration level.

The model's only level-dependent part is the body's softening
(`ehm_drake.model.softening`): each element acts as a linear spring whose
stiffness depends on its RMS movement, which depends on the response, which
depends on the stiffness.  `equivalent_linear` solves that loop for a seat
excitation of given spectrum: linearize with every element's RMS movement
frozen (the `BodySoftening` system's ``rms_fixed`` parameter), compute the
elements' RMS deformation from the linear response to the excitation's
spectrum, change the springs to that movement's and repeat until it stops
changing.  The model is linearized once: each element's force is zero at
the equilibrium, so a spring's change enters the linear step only as that
element's force fed back (`softening_columns`, `with_springs`), which
matches a new linearization to the finite differences' accuracy
(`tests/test_softening.py`) at a few percent of its cost per iteration.
Without softening (the paper's linear model) it is one linearization.

The excitation's spectrum is `SeatSpectrum`: a one-sided PSD of the seat
acceleration per axis ((m/s^2)^2/Hz on a frequency grid), from a flat band
and an RMS level (`SeatSpectrum.flat`, the form of the project's random
signals, `ehm_drake.signals.band_limited_noise`), from a recorded signal
(`SeatSpectrum.of_signal`), or for a sinusoid (`SeatSpectrum.sine`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..signals import BAND_HZ

#: Relative change of every element's RMS movement at which the iteration
#: stops, and the most iterations.
TOLERANCE = 2e-3
MAX_ITERATIONS = 60


class EquivalentLinearError(RuntimeError):
    """The equivalent-linear iteration did not settle (or the model is
    unstable at the test's level)."""


@dataclass(frozen=True)
class SeatSpectrum:
    """One-sided PSD of the seat acceleration: `psd[k, axis]` on `freqs[k]`
    ((m/s^2)^2/Hz; a sinusoid is one bin holding its mean square), axes x,
    y, z."""

    freqs: np.ndarray
    psd: np.ndarray  # (nf, 3)
    description: str = ""
    df: np.ndarray = field(default=None, repr=False)  # bin widths

    def __post_init__(self):
        f = np.asarray(self.freqs, float)
        P = np.asarray(self.psd, float)
        if f.ndim != 1 or P.shape != (len(f), 3):
            raise ValueError(f"spectrum: freqs {f.shape} and psd {P.shape} must be (n,), (n, 3)")
        if not (np.all(np.isfinite(P)) and np.all(P >= 0) and np.all(f > 0)):
            raise ValueError("spectrum: frequencies must be > 0 and the PSD finite, >= 0")
        object.__setattr__(self, "freqs", f)
        object.__setattr__(self, "psd", P)
        if self.df is None:
            object.__setattr__(self, "df", np.gradient(f) if len(f) > 1 else np.ones(1))

    @property
    def rms(self) -> np.ndarray:
        """RMS acceleration per axis (m/s^2)."""
        return np.sqrt(np.sum(self.psd * self.df[:, None], axis=0))

    @classmethod
    def flat(cls, direction: str, rms: float, band=BAND_HZ, resolution_hz: float = 0.02):
        """Flat between band[0] and band[1] Hz on each axis of `direction`
        ("x", "z", "xyz", ...), `rms` m/s^2 per axis."""
        lo, hi = float(band[0]), float(band[1])
        if not (0 < lo < hi) or not rms > 0:
            raise ValueError(f"flat spectrum: band {band} and rms {rms} must be positive")
        f = np.arange(lo + resolution_hz / 2, hi, resolution_hz)
        P = np.zeros((len(f), 3))
        for d in direction:
            P[:, "xyz".index(d)] = rms**2 / (hi - lo)
        return cls(f, P, f"{direction} flat {lo:g}-{hi:g} Hz, {rms:g} m/s^2 RMS",
                   np.full(len(f), resolution_hz))

    @classmethod
    def sine(cls, direction: str, frequency_hz: float, rms: float):
        """A sinusoid of `rms` m/s^2 at `frequency_hz` on each axis of
        `direction`."""
        P = np.zeros((1, 3))
        for d in direction:
            P[0, "xyz".index(d)] = rms**2
        return cls(np.array([float(frequency_hz)]), P,
                   f"{direction} sine {frequency_hz:g} Hz, {rms:g} m/s^2 RMS", np.ones(1))

    @classmethod
    def of_signal(cls, signal, resolution_hz: float = 0.05):
        """The PSD of a `SeatSignal`'s steady part (Welch, Hann)."""
        from scipy.signal import welch

        a = signal.acceleration[signal.sample_index(signal.steady_start):]
        fs = 1.0 / signal.time_step
        nper = min(len(a), int(round(fs / resolution_hz)))
        f, P = welch(a, fs=fs, nperseg=nper, axis=0, detrend="constant")
        keep = (f > 0) & (f <= 0.5 * fs)
        return cls(f[keep], P[keep], "recorded signal")


@dataclass
class EquivalentLinear:
    """The linear model at a test's level and what the iteration found."""

    linear: object  # LinearModel
    spectrum: SeatSpectrum
    element_names: tuple[str, ...]
    element_kinds: tuple[str, ...]
    movement_rms: np.ndarray  # per element (m or rad)
    stiffness_loss: np.ndarray  # per element (N/m or N m/rad)
    iterations: int

    def summary(self) -> dict:
        return {"spectrum": self.spectrum.description, "iterations": self.iterations,
                "elements": [{"name": n, "kind": k, "movement_rms": float(s),
                              "stiffness_loss": float(dk)}
                             for n, k, s, dk in zip(self.element_names, self.element_kinds,
                                                    self.movement_rms, self.stiffness_loss,
                                                    strict=True)]}


def element_rms(linear, spectrum: SeatSpectrum) -> np.ndarray:
    """RMS of each softening element's deformation in the linear response
    to `spectrum` (the ``softening_deformation`` output)."""
    H = linear.frequency_response(spectrum.freqs, "softening_deformation")  # (nf, n, 3)
    w = spectrum.psd * spectrum.df[:, None]  # (nf, 3)
    return np.sqrt(np.einsum("fnu,fu->n", np.abs(H) ** 2, w))


def equivalent_linear(model, spectrum: SeatSpectrum, root_context=None, outputs=None,
                      tolerance: float = TOLERANCE, max_iterations: int = MAX_ITERATIONS,
                      fd_step: float | None = None, rms_start=None) -> EquivalentLinear:
    """The linearization of `model` (an `EhmDiagram` built without a signal)
    at the level of `spectrum`, about its static equilibrium (computed when
    `root_context` is None).  `outputs`: the output ports to linearize
    (default `ehm_drake.analysis.linear.OUTPUT_PORTS`); `rms_start`: the
    elements' RMS movements to start the iteration from (default at rest;
    a nearby model's answer saves iterations).

    The model is linearized once, with the elements' RMS movements frozen at
    the start, and with each element's force as one more input
    (`softening_columns`); the iteration then changes only the elements'
    springs, whose effect on the step is that input fed back
    (`with_springs`), exact to first order as every element's force is
    zero at the equilibrium."""
    from ..model.softening import element_spring, equivalent_loss
    from ..simulation import static_equilibrium
    from .linear import FD_STEP, OUTPUT_PORTS, linearize

    if root_context is None:
        root_context, _ = static_equilibrium(model)
    soft = model.systems.get("body_softening")
    ports = list(outputs or OUTPUT_PORTS)
    step = FD_STEP if fd_step is None else fd_step
    if soft is None:
        lin = linearize(model, root_context, method="fd", fd_step=step, outputs=ports)
        return EquivalentLinear(lin, spectrum, (), (), np.zeros(0), np.zeros(0), 1)
    if "softening_deformation" not in ports:
        ports.append("softening_deformation")
    elements = soft.elements
    sctx = soft.GetMyMutableContextFromRoot(root_context)

    s = np.zeros(elements.n) if rms_start is None else np.asarray(rms_start, float).copy()
    warm = rms_start is not None
    relax, last = 0.5, np.inf
    active = soft.active(soft.GetMyContextFromRoot(root_context))
    try:
        soft.set_rms(sctx, s)
        lin0 = linearize(model, root_context, method="fd", fd_step=step, outputs=ports)
        k0 = active * element_spring(elements, s)
        columns = softening_columns(model, root_context, lin0, step)
        for it in range(1, max_iterations + 1):
            lin = with_springs(lin0, columns, active * element_spring(elements, s) - k0)
            if not lin.is_stable:
                raise EquivalentLinearError(
                    f"the model is unstable at {spectrum.description} (iteration {it}, "
                    f"element RMS movement up to {np.max(s):.3g})")
            s_new = element_rms(lin, spectrum)
            # (Relative to at least 1% of the critical amplitude: an element
            # that barely moves, as the pelvis's normal under lateral
            # excitation, has no loss to settle.)
            change = np.max(np.abs(s_new - s) / np.maximum(s_new, 0.01 * elements.critical))
            if change < tolerance:
                s = s_new
                break
            # Under-relaxed in the log (the map s -> s_new falls as s grows: a
            # full step can oscillate), more so while the change does not fall.
            if change > 0.7 * last:
                relax = max(0.5 * relax, 0.05)
            last = change
            s = (np.exp((1 - relax) * np.log(np.maximum(s, 1e-12)) + relax * np.log(s_new))
                 if it > 1 or warm else s_new)
        else:
            raise EquivalentLinearError(
                f"the equivalent-linear iteration did not settle in {max_iterations} steps "
                f"at {spectrum.description} (last change {change:.2g})")
        # The springs at the answer (whose movements the last model gave).
        lin = with_springs(lin0, columns, active * element_spring(elements, s) - k0)
    finally:
        # The context keeps the running measure (as the caller gave it).
        soft.set_rms(sctx, None)
    return EquivalentLinear(lin, spectrum, elements.names, elements.kinds, s,
                            equivalent_loss(elements, s), it)


@dataclass(frozen=True)
class SofteningColumns:
    """How each softening element's force moves the linearized step:
    `B` (states x elements) and `D` (outputs x elements) per unit force,
    and `C_dev` (elements x states): the element's deformation from its
    running mean, the spring's argument, per unit state."""

    B: np.ndarray
    D: np.ndarray
    C_dev: np.ndarray


def softening_columns(model, root_context, lin, fd_step: float) -> SofteningColumns:
    """The `BodySoftening` elements' force as inputs of the linearization
    `lin` of `model` about the state in `root_context` (central differences
    of the step and the outputs in each element's ``force_offset``; step:
    the force of the element's rest stiffness over `fd_step`, the force a
    state step makes)."""
    from ..simulation import StateMap

    soft = model.systems["body_softening"]
    sctx = soft.GetMyMutableContextFromRoot(root_context)
    smap = StateMap(model)
    ports = [p for p in lin.output_groups]
    n = soft.elements.n
    steps = soft.elements.k_rest * fd_step

    def evaluate(offset):
        soft.set_force_offset(sctx, offset)
        return smap.step(root_context), np.concatenate(
            [model.diagram.GetOutputPort(p).Eval(root_context) for p in ports])

    B, D = np.zeros((len(lin.x0), n)), np.zeros((len(lin.y0), n))
    try:
        for e in range(n):
            unit = np.zeros(n)
            unit[e] = steps[e]
            (xp, yp), (xm, ym) = evaluate(unit), evaluate(-unit)
            B[:, e] = (xp - xm) / (2 * steps[e])
            D[:, e] = (yp - ym) / (2 * steps[e])
    finally:
        soft.set_force_offset(sctx, None)
    means = smap.slice("body_softening").start + np.arange(n)
    C_dev = lin.C[lin.output_groups["softening_deformation"]].copy()
    C_dev[np.arange(n), means] -= 1.0
    return SofteningColumns(B, D, C_dev)


def with_springs(lin, columns: SofteningColumns, dk):
    """`lin` with each softening element's spring changed by `dk` (N/m or
    N m/rad per element): the element force -dk (d - mean) fed back."""
    from dataclasses import replace

    feedback = -dk[:, None] * columns.C_dev
    return replace(lin, A=lin.A + columns.B @ feedback, C=lin.C + columns.D @ feedback,
                   _eig=None)


__all__ = ["EquivalentLinear", "EquivalentLinearError", "SeatSpectrum", "SofteningColumns",
           "element_rms", "equivalent_linear", "softening_columns", "with_springs"]
