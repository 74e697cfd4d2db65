"""The body's softening with vibration magnitude: the law, shared by the
time-domain system (`ehm_drake.systems.softening.BodySoftening`) and the
equivalent-linear models (`ehm_drake.analysis.equivalent`, the gap
diagnosis' families).

Why.  The principal vertical resonance of seated people falls as the
vibration grows: about 6 Hz at 0.25 m/s^2 r.m.s. to about 4 Hz at 2.0 m/s^2
on a rigid seat (Fairley & Griffin 1989, J Biomech 22(2):81-94,
doi:10.1016/0021-9290(89)90031-6), in every later study.  A linear model
resonates at one frequency whatever the magnitude.

What.  Soft tissue and active muscle are thixotropic: their stiffness falls
with their own recent movement and recovers at rest (muscle: Lakie, Walsh &
Wright 1984, J Physiol 353:265-285, doi:10.1113/jphysiol.1984.sp015335, the
wrist's resonant frequency falling as the forcing grows; Proske, Morgan &
Gregory 1993, Prog Neurobiol 41(6):705-721,
doi:10.1016/0301-0082(93)90032-N).  The nonlinearity of seated people
behaves as modal parameters that change with the magnitude rather than as
distortion within a record: coherence stays high, and with intermittent
vibration the resonance moves less than with continuous vibration of the
same magnitudes (Huang & Griffin 2008, J Sound Vib 312:273-295,
doi:10.1016/j.jsv.2007.10.047), i.e. it has a memory of seconds.

The law.  Each softening element (a body-seat contact point's tissue, or a
trunk or hip joint's muscles) keeps a running mean mu and variance V of its
deformation d with time constant tau (exponential windows, updated every
step):

    mu+ = mu + a (d - mu),   V+ = V + a ((d - mu)^2 - V),   a = h / tau.

Its stiffness is k(s) = k0 (1 - r g(s / s_c)), g(x) = x / (1 + x), with s =
sqrt(V) the RMS movement, k0 the stiffness at rest, r the fraction that
movement can take away (`max_loss`) and s_c the RMS movement at which half
of it is gone (`critical_rms`).  Within a stationary test s settles to the
deformation's standard deviation, and the element acts as a linear spring
of stiffness k(s): its describing function at the test's level is k(s)
exactly (up to the few-percent fluctuation of a running estimate), so the
equivalent-linear model of a test is the linear model with each element's
k(s) for its own s (`equivalent_loss`), found self-consistently
(`ehm_drake.analysis.equivalent`).

Short range on long range.  The tissue's stiffness to small movements is
its long-range stiffness k_inf = k0 (1 - r) plus a short-range part that
movement takes away, as in muscle (Loram et al.: short-range stiffness on
top of a long-range one) and in the thixotropic account, where the extra
stiffness re-forms at rest wherever the tissue now is.  So the contact
carries the body's weight with its long-range stiffness (the static
compression is that of a soft tissue: centimetres, not millimetres; a model
that carried it with the stiffness at rest would lift off the seat at 2
m/s^2), and the short-range part k(s) - k_inf acts about the running mean
(`BodySoftening`): at rest it adds k0 - k_inf to small movements, so the
dynamic stiffness at rest is k0, and the posture is that of the long-range
stiffness.  The joints' muscles keep their stiffness in the controllers
(the integrator holds the posture) and the element takes the loss away
about the running mean.

Tissue in series with a seat.  The contact pair's stiffness at rest k_c
(parameter ``contact.<pair>.stiffness``) is the tissue's own k_t0
(``softening.tissue.<pair>_stiffness``) in series with the seat's k_s
(infinite on a rigid seat: k_t0 = k_c).  The tissue deforms by d_t = d k_p
/ k_t of the pair's deformation d (one force through both), and it is the
tissue's movement that softens it: s_t = s_d k_s / (k_s + k_t(s_t)).  The
pair's stiffness is then k_p(s) = 1 / (1/k_t(s_t) + 1/k_s); its long-range
stiffness, the contact's in the plant, k_p(inf) = 1 / (1/k_inf + 1/k_s)
(`long_range_contacts`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..jit import kernel
from .joint_layout import pid_vectors

#: The contact pairs whose tissue softens: under the ischial tuberosities and
#: the thighs on the pan, and the back (lumbar and scapular) at the pads; not
#: the soles of the feet.
TISSUE_PAIRS = ("pelvis_pan", "thighs_pan", "lower_back_pad", "upper_back_pad")
#: The joint groups whose muscles' short-range stiffness softens (the PID's
#: kp of the trunk and hip DoFs).
MUSCLE_GROUPS = ("lumbar", "thoracic", "hips")
#: Fixed-point iterations for the tissue's share of a series deformation
#: (a contraction: each changes s_t by less than r k_t / (k_s + k_t) of the
#: previous change).
SERIES_ITERATIONS = 4


def loss_fraction(s, critical, max_loss):
    """r g(s / s_c): the fraction of the rest stiffness lost at RMS
    movement `s` (array or scalar; AutoDiffXd arrays work)."""
    x = s / critical
    return max_loss * x / (1.0 + x)


@dataclass(frozen=True)
class ElementSet:
    """The softening elements of one model, in the order of the system's
    states: first the tissue points, then the muscle DoFs.

    Per element: `k_rest` (the stiffness at rest, N/m or N m/rad: the contact
    pair's k_c, or the DoF's kp), `k_tissue` (the tissue's own k_t0; equal
    to `k_rest` for muscles and on a rigid seat), `max_loss`, `critical`
    (m or rad) and `time_constant` (s)."""

    kinds: tuple[str, ...]  # "tissue" or "muscle"
    names: tuple[str, ...]
    k_rest: np.ndarray
    k_tissue: np.ndarray
    max_loss: np.ndarray
    critical: np.ndarray
    time_constant: np.ndarray

    @property
    def n(self) -> int:
        return len(self.names)

    def series_compliance(self) -> np.ndarray:
        """1/k_s of the seat under each element (0: rigid, and for muscles)."""
        return self._constants[0]

    @cached_property
    def _kernel_arguments(self):
        """The element arrays `_element_spring_kernel` takes after `s`."""
        c, k_long, tissue = self._constants
        return (np.ascontiguousarray(self.k_rest, float),
                np.ascontiguousarray(self.k_tissue, float), c, k_long,
                np.ascontiguousarray(self.critical, float),
                np.ascontiguousarray(self.max_loss, float), tissue, SERIES_ITERATIONS)

    @cached_property
    def _constants(self):
        """(series compliance, long-range stiffness, tissue mask): what the
        laws read at every step, once per element set."""
        c = np.maximum(1.0 / self.k_rest - 1.0 / self.k_tissue, 0.0)
        k_inf = self.k_tissue * (1.0 - self.max_loss)
        return c, 1.0 / (1.0 / k_inf + c), np.array([k == "tissue" for k in self.kinds])


def element_set(params, points=(), layout=None) -> ElementSet:
    """The enabled softening elements of `params`: the restraint points of
    `points` on the `TISSUE_PAIRS` (tissue) and the rotational DoFs of
    `layout` in the `MUSCLE_GROUPS` with kp > 0 (muscle)."""
    kinds, names, k0, kt, r, sc, tau = [], [], [], [], [], [], []
    t = params.softening.tissue
    if t.enabled:
        for p in points:
            if p.pair in TISSUE_PAIRS:
                kinds.append("tissue")
                names.append(p.name)
                k0.append(getattr(params.contact, p.pair).stiffness)
                kt.append(getattr(t, f"{p.pair}_stiffness"))
                r.append(t.max_loss)
                sc.append(t.critical_rms_m)
                tau.append(t.time_constant_s)
    m = params.softening.muscle
    if m.enabled and layout is not None:
        kp = pid_vectors(params, layout)["kp"]
        for i, (name, group) in enumerate(zip(layout.names, layout.groups, strict=True)):
            if group in MUSCLE_GROUPS and kp[i] > 0:
                kinds.append("muscle")
                names.append(name)
                k0.append(kp[i])
                kt.append(kp[i])
                r.append(m.max_loss)
                sc.append(m.critical_rms_rad)
                tau.append(m.time_constant_s)
    k0, kt, r, sc, tau = (np.array(v, float) for v in (k0, kt, r, sc, tau))
    return ElementSet(tuple(kinds), tuple(names), k0, kt, r, sc, tau)


def tissue_element_set(params, names, pairs) -> tuple[np.ndarray, ElementSet]:
    """The tissue elements of `params` at restraint points given by their
    `names` and contact `pairs` (in that order): (mask of the points that
    are tissue elements, their `ElementSet` in point order)."""
    from types import SimpleNamespace

    points = [SimpleNamespace(name=n, pair=p) for n, p in zip(names, pairs, strict=True)]
    el = element_set(params, points, None)
    mask = np.array([p.pair in TISSUE_PAIRS for p in points]) if el.n else \
        np.zeros(len(points), bool)
    return mask, el


def tissue_movement(s_d, k_tissue, series_compliance, critical, max_loss,
                    iterations: int = SERIES_ITERATIONS):
    """The element's own RMS movement s_t from its pair's s_d: s_t = s_d
    k_s / (k_s + k_t(s_t)) = s_d / (1 + k_t(s_t) / k_s), by fixed-point
    iteration from s_t = s_d (a rigid seat, 1/k_s = 0, gives s_d)."""
    s_t = s_d
    for _ in range(iterations):
        k_t = k_tissue * (1.0 - loss_fraction(s_t, critical, max_loss))
        s_t = s_d / (1.0 + k_t * series_compliance)
    return s_t


def equivalent_loss(elements: ElementSet, s_d):
    """The stiffness each element takes away at RMS deformation `s_d` (per
    element, in the pair's or the DoF's deformation; N/m or N m/rad, >= 0):
    k_rest - k(s)."""
    c = elements.series_compliance()
    s_t = tissue_movement(s_d, elements.k_tissue, c, elements.critical, elements.max_loss)
    k_t = elements.k_tissue * (1.0 - loss_fraction(s_t, elements.critical, elements.max_loss))
    k_p = 1.0 / (1.0 / k_t + c)
    return elements.k_rest - k_p


def long_range_stiffness(elements: ElementSet) -> np.ndarray:
    """Each element's stiffness once movement has taken all it can: the
    tissue's k_t0 (1 - r) in series with the seat (N/m); for muscles the
    same k0 (1 - r)."""
    return elements._constants[1]


def element_spring(elements: ElementSet, s):
    """The stiffness each element applies about its running mean at RMS
    movement `s` (N/m or N m/rad): for tissue its short-range part on the
    contact's long-range stiffness, k_p(s) - k_p(inf) (>= 0); for muscles
    minus the loss (<= 0).  Every time step: compiled
    (`_element_spring_kernel`) for a float vector of the elements."""
    if (_spring_kernel is not None and type(s) is np.ndarray and s.dtype == np.float64
            and s.shape == (elements.n,)):
        return _spring_kernel(s, *elements._kernel_arguments)
    loss = equivalent_loss(elements, s)
    _, k_long, tissue = elements._constants
    return np.where(tissue, elements.k_rest - k_long - loss, -loss)


def _element_spring_kernel(s, k_rest, k_tissue, compliance, k_long, critical, max_loss,
                           tissue, iterations):
    """`element_spring` element by element: `tissue_movement`,
    `equivalent_loss` and its last step with the same operations in the
    same order (compiled by `ehm_drake.jit`; the same numbers to rounding,
    tests/test_softening.py)."""
    out = np.empty(s.shape[0])
    for i in range(s.shape[0]):
        s_d = s[i]
        s_t = s_d
        for _ in range(iterations):
            x = s_t / critical[i]
            k_t = k_tissue[i] * (1.0 - max_loss[i] * x / (1.0 + x))
            s_t = s_d / (1.0 + k_t * compliance[i])
        x = s_t / critical[i]
        k_t = k_tissue[i] * (1.0 - max_loss[i] * x / (1.0 + x))
        loss = k_rest[i] - 1.0 / (1.0 / k_t + compliance[i])
        out[i] = k_rest[i] - k_long[i] - loss if tissue[i] else -loss
    return out


#: `_element_spring_kernel` compiled, or None without numba.
spring_kernel = _spring_kernel = kernel(_element_spring_kernel)


def long_range_contacts(params):
    """`params` with each softening contact pair's stiffness at its
    long-range value (what the plant's contact carries the weight with;
    see the module docstring); unchanged without tissue softening."""
    t = params.softening.tissue
    if not t.enabled:
        return params
    p = params.copy()
    for pair in TISSUE_PAIRS:
        c = getattr(p.contact, pair)
        k_t0 = getattr(t, f"{pair}_stiffness")
        compliance = max(1.0 / c.stiffness - 1.0 / k_t0, 0.0)
        c.stiffness = 1.0 / (1.0 / (k_t0 * (1.0 - t.max_loss)) + compliance)
    return p


def static_sink(params_at_rest, body_weight: float, load_share: dict) -> dict:
    """How much deeper each softening contact pair sits under its nominal
    load (`load_share` of `body_weight`, N) on its long-range stiffness than
    on its stiffness at rest (m; {} without tissue softening): the seat is
    adjusted by it (`ehm_drake.model.plant.adjust_seat_for_sink`) so that
    the settled posture is the one the parameters were set for."""
    t = params_at_rest.softening.tissue
    if not t.enabled:
        return {}
    long_range = long_range_contacts(params_at_rest)
    return {pair: load_share[pair] * body_weight
            * (1.0 / getattr(long_range.contact, pair).stiffness
               - 1.0 / getattr(params_at_rest.contact, pair).stiffness)
            for pair in TISSUE_PAIRS}


def stationary_rms(variance) -> np.ndarray:
    """RMS movement from the running variance (0 for V <= 0; a tiny floor
    keeps its derivative finite for AutoDiffXd at rest)."""
    return np.sqrt(np.maximum(variance, 0.0) + 1e-30)


def describe(params) -> str:
    """One line on the softening of `params`, for reports."""
    t, m = params.softening.tissue, params.softening.muscle
    parts = []
    if t.enabled:
        parts.append(f"tissue (loses up to {100 * t.max_loss:.0f}%, half at "
                     f"{1e3 * t.critical_rms_m:.2g} mm RMS, tau {t.time_constant_s:g} s)")
    if m.enabled:
        parts.append(f"muscle (loses up to {100 * m.max_loss:.0f}%, half at "
                     f"{math.degrees(m.critical_rms_rad):.2g} deg RMS, "
                     f"tau {m.time_constant_s:g} s)")
    return "softening: " + (", ".join(parts) if parts else "off (the paper's linear model)")


__all__ = ["ElementSet", "MUSCLE_GROUPS", "TISSUE_PAIRS", "describe", "element_set",
           "element_spring", "equivalent_loss", "long_range_contacts", "long_range_stiffness",
           "loss_fraction", "spring_kernel", "static_sink", "stationary_rms", "tissue_element_set",
           "tissue_movement"]
