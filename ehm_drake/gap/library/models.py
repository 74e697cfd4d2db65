"""Candidate models of the gap diagnosis: the base model and each
unmodelled effect as a linear(ized) model of the measured tests.

Every candidate predicts the measured transmissibility of each test
(direction, level) from

* the base parameters, as log-scales b of the fit registry's default set
  (the base refit: a gap that refitting absorbs is no unmodelled effect);
* its effect parameters, in coordinates c (the log of log-type values).

How each effect enters:

* `arms`, `visceral_mass`, `seat_cushion_dynamics` add bodies and joints:
  their extended model is linearized over a grid of the effect's parameter
  coordinates (cubic splines in between) with its own base sensitivities.
* `reflex_delay`: the feedback of the cut-open linearization is delayed,
  exp(-j w tau), in the frequency domain (see `family.response`).
* The level-dependent effects act through equivalent (statistical)
  linearization about the response they produce at each test's level,
  with the seat-acceleration spectrum of that test:

  - `seat_foam_stiffening`: the cubic normal force k gamma d^3 of a
    Gaussian compression d (std s) has the mean tangent stiffness
    3 k gamma s^2 (Gaussian closure), added to the contact's k;
  - `backrest_separation`: the pads' static compression drops by the
    offset (slope from two static equilibria); a unilateral contact with
    static compression d0 acts as the linear one times the probability of
    contact, Phi(d0 / s), on the pad's normal stiffness and damping and on
    its (contact-gated) shear restraints;
  - `seat_friction`, and the base restraints' own force limits: each
    restraint is a Jenkins element (spring in series with a slider of limit
    min(F_max, mu N0)); its describing function (Caughey 1960), averaged
    over a Rayleigh distribution of the deflection amplitude, gives the
    storage and loss stiffness at the response's mean frequency, matched by
    a Maxwell element (`maxwell_equivalent`): the restraint's spring, and
    its slip as an extra state per axis that relaxes the deflection;
  - `cocontraction`: the running RMS equals the test's level, so the
    active stiffness is kp (1 + c a_rms) exactly.

  The response statistics (s) are those of the candidate's own linear
  model, updated to self-consistency between least-squares rounds.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import norm

from ...model.softening import TISSUE_PAIRS, equivalent_loss, loss_fraction, tissue_element_set
from ...params import params_from_dict
from ..single.localize import Rows
from .effects import BACK_PADS, EFFECTS, SEAT_SURFACES, SOFTENING_PAIRS, EffectParam
from .family import (
    GROUP_NAMES,
    RESTRAINT_GROUPS,
    FamilySpec,
    ModelFamily,
    response,
    to_transmissibility,
)

#: Effects that add bodies/joints (linearized over a grid of their
#: parameters) and their grids (parameter values per axis).
GRID_EFFECTS = {
    "visceral_mass": {"mass_kg": [0.1, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0]},
    "seat_cushion_dynamics": {"stiffness": list(np.logspace(4.0, 7.0, 6))},
    "arms": {"shoulder_stiffness": list(np.logspace(math.log10(5.0), math.log10(5000.0), 4)),
             "hand_stiffness": list(np.logspace(math.log10(20.0), math.log10(1.0e5), 4))},
}
#: How each grid is interpolated (see `family.EffectGrid`).
GRID_MODE = {"visceral_mass": "spline", "seat_cushion_dynamics": "stiffness",
             "arms": "stiffness"}
#: Reference point of each grid effect (where its base sensitivities are).
GRID_REFERENCE = {"visceral_mass": {"mass_kg": 3.0},
                  "seat_cushion_dynamics": {"stiffness": 2.0e5},
                  "arms": {"shoulder_stiffness": 150.0, "hand_stiffness": 1.5e3}}


#: Where a candidate's fit starts: fractions of its plausible strength.
STRENGTH_PATH = (0.2, 0.45, 0.7, 1.0)


def coordinate(p: EffectParam, value: float) -> float:
    return math.log(value) if p.log else float(value)


def value_of(p: EffectParam, c: float) -> float:
    return math.exp(c) if p.log else float(c)


def coordinate_bounds(p: EffectParam) -> tuple[float, float]:
    lo, hi = p.bounds
    if p.log:
        return math.log(lo), math.log(hi)
    return float(lo), float(hi)


def family_specs(effect_names) -> list[FamilySpec]:
    """The linear families the candidates `effect_names` need: the base
    family (also for the delay and the level-dependent effects) and one
    per grid effect."""
    specs = [FamilySpec("base", {})]
    for name in effect_names:
        if name not in GRID_EFFECTS:
            continue
        e = EFFECTS[name]
        ref = {**e.fixed, **GRID_REFERENCE[name]}
        values = [GRID_EFFECTS[name][p.name] for p in e.params]
        axes = [[coordinate(p, v) for v in vals] for p, vals in
                zip(e.params, values, strict=True)]
        specs.append(FamilySpec(name, {name: ref}, name, axes, values, GRID_MODE[name],
                                tuple(p.log for p in e.params)))
    return specs


# ---------------------------------------------------------------------------
# Equivalent linearization of the Jenkins element (spring + slider)
# ---------------------------------------------------------------------------


def _jenkins_table():
    """Rayleigh-averaged describing function of an elastic-perfectly-plastic
    element (Caughey 1960): for a sinusoidal deflection of amplitude a
    (in units of the yield deflection, a > 1), equivalent stiffness
    k/pi (t - sin(2t)/2), t = arccos(1 - 2/a), and loss stiffness
    4 k (a - 1)/(pi a^2); averaged over a Rayleigh amplitude distribution
    of parameter r = sigma / x_yield (narrow-band random response)."""
    r = np.logspace(-3, 3, 241)
    a = np.logspace(-4, 4, 4001)  # amplitude / yield
    t = np.arccos(np.clip(1.0 - 2.0 / np.maximum(a, 1.0), -1.0, 1.0))
    gk_a = np.where(a <= 1.0, 1.0, (t - 0.5 * np.sin(2 * t)) / np.pi)
    gh_a = np.where(a <= 1.0, 0.0, 4.0 * (a - 1.0) / (np.pi * a * a))
    gk, gh = [], []
    for ri in r:
        w = a / ri**2 * np.exp(-0.5 * (a / ri) ** 2)
        norm_ = np.trapezoid(w, a)
        gk.append(np.trapezoid(w * gk_a, a) / norm_)
        gh.append(np.trapezoid(w * gh_a, a) / norm_)
    return np.log(r), np.array(gk), np.array(gh)


_JENKINS = _jenkins_table()


def jenkins_factors(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(equivalent stiffness / k, loss stiffness / k) at sigma / x_yield = r."""
    lr = np.log(np.clip(r, 1e-3, 1e3))
    return np.interp(lr, _JENKINS[0], _JENKINS[1]), np.interp(lr, _JENKINS[0], _JENKINS[2])


def maxwell_equivalent(gk, gh, omega):
    """Maxwell equivalent of a Jenkins element with describing-function
    storage and loss stiffness gk, gh (relative to k) at frequency omega
    (rad/s): a spring k_M in series with a slip that relaxes the elastic
    deflection at rate lam (the anchor creeps), K(w) = k_M i w / (lam + i w),
    equal to k (gk + i gh) at omega.  Returns (k_M / k, lam in 1/s):
    k_M = k (gk^2 + gh^2) / gk, lam = omega gh / gk.  Unlike a spring-damper
    equivalent (the earlier choice: gh k / omega as viscous damping), it
    slips at frequencies below lam, as the anchors of a stick-slip contact
    random-walk away under broadband load, and holds above; with it the
    seat_friction candidate explains 71% of the held-out gap of full-strength
    friction data instead of 18%."""
    gk = np.asarray(gk, float)
    gh = np.asarray(gh, float)
    gk_safe = np.maximum(gk, 1e-6)
    return (gk * gk + gh * gh) / gk_safe, np.where(gh > 0, omega * gh / gk_safe, 0.0)


# ---------------------------------------------------------------------------
# Tests and candidates
# ---------------------------------------------------------------------------


@dataclass
class TestInput:
    """One measured test: the excitation's direction, level and spectrum."""

    direction: str
    level: float  # RMS m/s^2 along the direction
    psd_f: np.ndarray  # Hz, grid of the response-statistics integrals
    psd: np.ndarray  # one-sided seat-acceleration PSD there, (m/s^2)^2/Hz
    source: str = "flat"  # "flat" (assumed) or "timeseries" (measured)

    @property
    def input_index(self) -> int:
        return "xyz".index(self.direction)

    @classmethod
    def flat(cls, direction: str, level: float, band=(0.1, 12.0), df: float = 0.1):
        f = np.arange(band[0], band[1] + 0.5 * df, df)
        return cls(direction, level, f, np.full(len(f), level**2 / (band[1] - band[0])))

    @classmethod
    def from_seat_acceleration(cls, direction: str, level: float, a: np.ndarray, fs: float,
                               band=(0.1, 12.0), df: float = 0.1):
        from scipy.signal import welch

        nper = min(len(a), int(round(fs / df)))
        f, P = welch(a - np.mean(a), fs, nperseg=nper)
        grid = np.arange(band[0], band[1] + 0.5 * df, df)
        psd = np.interp(grid, f, P)
        # Scale to the level over the band (the lab's nominal RMS).
        total = np.sum(psd) * df
        if total > 0:
            psd *= level**2 / total
        return cls(direction, level, grid, psd, "timeseries")


#: The level-dependent effects whose equivalent-linear change vanishes with
#: the response's amplitude: the foam's cubic force adds 3 k gamma s^2 (s
#: the compression's standard deviation), the friction's Jenkins slider
#: sticks below mu N0, co-contraction adds c a_rms kp.  Each of them changes
#: the response only as far as the level does, so all of its signature on
#: a subject comes with level differences (`scatter._evidence` holds it
#: to them).  A backrest separation is level-dependent but not amplitude
#: driven: a pad beyond reach is gone at any amplitude.
AMPLITUDE_DRIVEN = ("seat_foam_stiffening", "seat_friction", "cocontraction", "softening")


@dataclass
class Candidate:
    """A candidate explanation: no effect ("none") or one or more effects."""

    effects: tuple[str, ...]

    @property
    def name(self) -> str:
        return "+".join(self.effects) if self.effects else "none"

    @property
    def params(self) -> list[tuple[str, EffectParam]]:
        return [(e, p) for e in self.effects for p in EFFECTS[e].params]

    @property
    def grid_effect(self) -> str | None:
        grids = [e for e in self.effects if e in GRID_EFFECTS]
        if len(grids) > 1:
            raise ValueError(f"candidate {self.name}: at most one effect that adds bodies")
        return grids[0] if grids else None

    @property
    def level_dependent(self) -> bool:
        return any(EFFECTS[e].kind == "level" for e in self.effects)

    @property
    def amplitude_driven(self) -> bool:
        """Every effect of the candidate is `AMPLITUDE_DRIVEN`."""
        return bool(self.effects) and all(e in AMPLITUDE_DRIVEN for e in self.effects)

    def values(self, coords) -> dict:
        """{effect: {param: value}} (with the fixed values) at `coords`."""
        out = {e: dict(EFFECTS[e].fixed) for e in self.effects}
        for (e, p), c in zip(self.params, coords, strict=True):
            out[e][p.name] = value_of(p, c)
        return out

    def start_grid(self, strengths=STRENGTH_PATH) -> list[np.ndarray]:
        """Starting coordinates to scan: the effect's strength path (the
        fractions `strengths` of its plausible range)."""
        if not self.effects:
            return [np.zeros(0)]
        per_effect = []
        for e in self.effects:
            eff = EFFECTS[e]
            per_effect.append([np.array([coordinate(p, eff.values(s)[p.name]) for p in eff.params])
                               for s in strengths])
        if len(per_effect) == 1:
            return per_effect[0]
        return [np.concatenate(c) for c in zip(*per_effect, strict=True)]


# ---------------------------------------------------------------------------
# Prediction
# ---------------------------------------------------------------------------


BASE_PRIOR_SIGMA = 0.25  # log-scale spread of a subject's base parameters
BASE_BOUND = 0.7  # |log-scale| bound of the base refit (x2)
#: Increments of the equivalent directions below this are taken as zero
#: (then tests share their eigen-decomposition).
EQUIVALENT_TOL = 1e-3
#: The body's softening: the tissue's movement is iterated to this relative
#: change, at most this many times per statistics update.
SOFTENING_TOLERANCE = 2e-3
SOFTENING_ITERATIONS = 25
#: Restraint groups whose tissue softens (the model's `TISSUE_PAIRS`), those
#: the `softening` candidate softens further (its `SOFTENING_PAIRS`, as in the
#: time domain), and the contact pair of each group.
TISSUE_GROUPS = tuple(RESTRAINT_GROUPS[p] for p in TISSUE_PAIRS)
SOFTENING_GROUPS = tuple(RESTRAINT_GROUPS[p] for p in SOFTENING_PAIRS)
RESTRAINT_PAIRS = {g: p for p, g in RESTRAINT_GROUPS.items()}
#: Slip relaxation rates below this (1/s) are taken as zero: slower than the
#: lowest analysed frequency by two decades.
CREEP_TOL_PER_S = 2 * math.pi * 0.1 / 100


@dataclass
class Statics:
    """Static facts of the restraint points of a family (see PointInfo),
    with the pads' penetration slope per mm of backrest offset."""

    info: object
    separation_slope: np.ndarray  # d penetration / d offset_mm (m/mm), per point

    def pad_unloading_mm(self) -> np.ndarray:
        """The backrest offset (mm) at which each pad point's static
        penetration reaches zero (linear in the offset), sorted; empty when
        no pad point moves out of contact as the pads move back."""
        pads = np.isin(self.info.parts, BACK_PADS) & (self.separation_slope < 0)
        return np.sort(self.info.penetration[pads] / -self.separation_slope[pads])


@dataclass
class Predictor:
    """Predicts the measured rows of the tests for a candidate.

    theta = [base log-scales (len(base_names)), effect coordinates].  The
    response statistics of the equivalent linearization are frozen in
    `sigmas` (per test) and refreshed by `update_statistics(theta)`."""

    family: ModelFamily
    candidate: Candidate
    rows: Rows
    tests: list[TestInput]
    base_names: list[str]
    statics: Statics
    sigmas: list = field(default_factory=list)

    def __post_init__(self):
        d_names = self.family.directions
        self._base_idx = np.array([d_names.index(n) for n in self.base_names], int)
        self._eq_names = [n for n in d_names if n not in self.base_names]
        self._eq_idx = np.array([d_names.index(n) for n in self._eq_names], int)
        info = self.statics.info
        self._group_of = np.array(info.groups)
        self._fgrid = np.unique(self.rows.freq)
        self._row_fi = np.searchsorted(self._fgrid, self.rows.freq)
        self._test_rows = [self.rows.test_mask(t.direction, t.level) for t in self.tests]
        if not self.sigmas:
            self.sigmas = [None] * len(self.tests)
        info = self.statics.info
        pairs = [RESTRAINT_PAIRS[g] for g in info.groups]
        params = params_from_dict(self.family.family.params)
        self._tissue = tissue_element_set(params, info.names, pairs)
        self._critical = params.softening.tissue.critical_rms_m

    @property
    def n_base(self) -> int:
        return len(self.base_names)

    @property
    def n_params(self) -> int:
        return self.n_base + len(self.candidate.params)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = [-BASE_BOUND] * self.n_base + [coordinate_bounds(p)[0] for _, p in
                                           self.candidate.params]
        hi = [BASE_BOUND] * self.n_base + [coordinate_bounds(p)[1] for _, p in
                                          self.candidate.params]
        return np.array(lo), np.array(hi)

    # -- equivalent linearization ------------------------------------------------------

    def _equivalent(self, test_i: int, coords) -> np.ndarray:
        """Increments of the equivalent directions for test `test_i`, then
        the slip relaxation (creep) rate of each restraint group (1/s,
        `GROUP_NAMES` order)."""
        e = np.zeros(len(self._eq_names))
        lam = np.zeros(len(GROUP_NAMES))
        st = self.sigmas[test_i]
        info = self.statics.info
        values = self.candidate.values(coords)
        idx = {n: i for i, n in enumerate(self._eq_names)}
        if "cocontraction" in values:
            e[idx["kp_cocontraction"]] = values["cocontraction"]["c_per_ms2"] * \
                self.tests[test_i].level
        if st is None:
            return np.concatenate([e, lam])
        s_n, s_d, s_v = st["normal"], st["deflection"], st["deflection_rate"]
        n = len(info.names)
        # Restraint force limits (Jenkins elements), friction on the seat.
        limit = info.force_limit.copy()
        if "seat_friction" in values:
            mu = values["seat_friction"]["mu"]
            seat = np.isin(info.parts, SEAT_SURFACES)
            N0 = info.k_contact * np.maximum(info.penetration, 0.0)
            limit = np.where(seat, np.minimum(limit, mu * N0), limit)
        margin = np.maximum(limit[:, None] / info.k_shear[:, None] - np.abs(info.deflection),
                            1e-6)
        sd = s_d.reshape(n, 2)
        dom = np.argmax(sd, axis=1)
        r = sd[np.arange(n), dom] / margin[np.arange(n), dom]
        gk, gh = jenkins_factors(r)
        omega = np.where(sd[np.arange(n), dom] > 0,
                         s_v.reshape(n, 2)[np.arange(n), dom] /
                         np.maximum(sd[np.arange(n), dom], 1e-300), 2 * np.pi * 3.0)
        # Unilateral pad contact (backrest separation).
        phi = np.ones(n)
        if "backrest_separation" in values:
            off = values["backrest_separation"]["offset_mm"]
            pads = np.isin(info.parts, BACK_PADS)
            pen = info.penetration + self.statics.separation_slope * off
            phi = np.where(pads, norm.cdf(pen / np.maximum(s_n, 1e-9)), 1.0)
        k_m, creep = maxwell_equivalent(gk, gh, omega)
        k_rel = phi * k_m
        c_rel = phi * gk
        for g in GROUP_NAMES:
            sel = self._group_of == g
            e[idx[f"k_shear:{g}"]] += float(np.mean(k_rel[sel])) - 1.0
            e[idx[f"c_shear:{g}"]] += float(np.mean(c_rel[sel])) - 1.0
            lam[GROUP_NAMES.index(g)] = float(np.mean(creep[sel]))
            if "backrest_separation" in values and g in ("lower_pad", "upper_pad"):
                e[idx[f"k_normal:{g}"]] += float(np.mean(phi[sel])) - 1.0
                e[idx[f"c_normal:{g}"]] += float(np.mean(phi[sel])) - 1.0
        if "seat_foam_stiffening" in values:
            gamma = values["seat_foam_stiffening"]["gamma_per_mm2"] * 1e6
            for g in ("pelvis", "thighs", "lower_pad", "upper_pad"):
                sel = self._group_of == g
                e[idx[f"k_normal:{g}"]] += 3.0 * gamma * float(np.mean(s_n[sel] ** 2))
        # The body's own softening (`ehm_drake.model.softening`): at the
        # test's movement each tissue point has lost part of the short-range
        # stiffness the family was linearized with (at rest).
        mask, elements = self._tissue
        if elements.n or "softening" in values:
            rel = np.zeros(n)
            if elements.n:
                rel[mask] = -equivalent_loss(elements, s_n[mask]) / info.k_contact[mask]
            if "softening" in values:
                # The candidate's extra loss, in units of the contact's own
                # (long-range) stiffness.
                tissue = np.isin(self._group_of, SOFTENING_GROUPS)
                rel[tissue] -= loss_fraction(s_n[tissue], self._critical,
                                             values["softening"]["extra_loss"])
            for g in TISSUE_GROUPS:
                sel = self._group_of == g
                e[idx[f"k_normal:{g}"]] += float(np.mean(rel[sel]))
        e[np.abs(e) < EQUIVALENT_TOL] = 0.0
        lam[lam < CREEP_TOL_PER_S] = 0.0
        return np.concatenate([e, lam])

    # -- matrices and responses --------------------------------------------------------

    def _grid_coords(self, coords):
        g = self.candidate.grid_effect
        if g is None:
            return None
        return np.array([c for (e, _), c in zip(self.candidate.params, coords, strict=True)
                         if e == g])

    def _delay(self, coords) -> float:
        for (e, p), c in zip(self.candidate.params, coords, strict=True):
            if e == "reflex_delay":
                return value_of(p, c)
        return 0.0

    def test_matrices(self, theta, test_i: int):
        """(A, Bu, Bw, C, K) of test `test_i` at `theta`, and the effect
        coordinates."""
        b = np.asarray(theta[:self.n_base], float)
        coords = np.asarray(theta[self.n_base:], float)
        u = np.zeros(len(self.family.directions))
        u[self._base_idx] = np.expm1(b)
        eq = self._equivalent(test_i, coords)
        ne = len(self._eq_names)
        u[self._eq_idx] = eq[:ne]
        mats = self.family.matrices(self._grid_coords(coords), u)
        return self._with_creep(mats, eq[ne:], u), coords

    def _with_creep(self, mats, lam_group, u):
        """The matrices with the slip of the creeping restraint axes as extra
        states: s+ = s + h lam (d - s), d the axis deflection (C rows of
        ``restraint_deflection``); the slip acts on the body through the
        plant's dx+/ds (`slip_coupling`), scaled with the group's equivalent
        shear stiffness."""
        A, Bu, Bw, C = mats
        K = self.family.K
        coupling = self.family.family.nominal.slip_coupling
        if coupling is None or not np.any(lam_group > 0):
            return A, Bu, Bw, C, K
        gi = np.array([GROUP_NAMES.index(g) for g in self._group_of])
        lam_axis = np.repeat(lam_group[gi], 2)
        act = np.flatnonzero(lam_axis > 0)
        d_names = self.family.directions
        k_scale = np.repeat(1.0 + u[[d_names.index(f"k_shear:{g}") for g in self._group_of]], 2)
        rows = self.family.output_groups["restraint_deflection"]
        h = self.family.h
        n, m = A.shape[0], len(act)
        lam = lam_axis[act]
        A2 = np.zeros((n + m, n + m))
        A2[:n, :n] = A
        A2[:n, n:] = coupling[:, act] * k_scale[act]
        A2[n:, :n] = (h * lam)[:, None] * C[rows.start + act]
        A2[n:, n:] = np.diag(1.0 - h * lam)
        C2 = np.hstack([C, np.zeros((C.shape[0], m))])
        C2[rows.start + act, n + np.arange(m)] = -1.0
        return (A2, np.vstack([Bu, np.zeros((m, Bu.shape[1]))]),
                np.vstack([Bw, np.zeros((m, Bw.shape[1]))]), C2,
                np.hstack([K, np.zeros((K.shape[0], m))]))

    def _response(self, mats, coords, freqs, inputs, rows):
        A, Bu, Bw, C, K = mats
        tau = self._delay(coords)
        return response(A, Bu, Bw, C, K, self.family.h, freqs, inputs, rows=rows,
                        delay_steps=tau / self.family.h)

    def predict(self, theta, mask=None) -> np.ndarray:
        """Modelled H for every row (NaN outside `mask` if given).  Tests
        whose equivalent increments agree share one response evaluation."""
        H = np.full(len(self.rows), np.nan + 0j)
        ch = self.family.output_groups["channels"]
        coords = np.asarray(theta[self.n_base:], float)
        groups: dict = {}
        for i in range(len(self.tests)):
            m = self._test_rows[i] if mask is None else self._test_rows[i] & mask
            if np.any(m):
                key = self._equivalent(i, coords).tobytes()
                groups.setdefault(key, []).append((i, m))
        for members in groups.values():
            mats, _ = self.test_matrices(theta, members[0][0])
            dirs = "".join(sorted({self.tests[i].direction for i, _ in members}))
            R = self._response(mats, coords, self._fgrid, ["xyz".index(d) for d in dirs], ch)
            T = to_transmissibility(R, self._fgrid, self.family.h, dirs)
            for i, m in members:
                k = dirs.index(self.tests[i].direction)
                H[m] = T[self._row_fi[m], self.rows.channel[m], k]
        return H

    def update_statistics(self, theta) -> None:
        """Response statistics (std of restraint normal displacement,
        shear deflection and its rate) of every test at `theta`, from the
        candidate's own linear model and the test's seat spectrum."""
        groups = self.family.output_groups
        rows_n = groups["restraint_normal_displacement"]
        rows_d = groups["restraint_deflection"]
        nn = rows_n.stop - rows_n.start
        sel = np.r_[np.arange(rows_n.start, rows_n.stop), np.arange(rows_d.start, rows_d.stop)]
        softening = self._tissue[1].n > 0 or "softening" in self.candidate.effects

        def statistics(i, t):
            mats, coords = self.test_matrices(theta, i)
            H = self._response(mats, coords, t.psd_f, [t.input_index], sel)[:, :, 0]
            df = np.gradient(t.psd_f)
            w = t.psd * df
            P = np.abs(H) ** 2
            var = (P * w[:, None]).sum(axis=0)
            var_rate = (P * ((2 * np.pi * t.psd_f) ** 2 * w)[:, None]).sum(axis=0)
            return {"normal": np.sqrt(var[:nn]), "deflection": np.sqrt(var[nn:]),
                    "deflection_rate": np.sqrt(var_rate[nn:])}

        for i, t in enumerate(self.tests):
            st = statistics(i, t)
            # The body's softening depends on the movement it shapes: iterate
            # the tissue's movement to self-consistency (under-relaxed in the
            # log, as `ehm_drake.analysis.equivalent` does).
            for _ in range(SOFTENING_ITERATIONS if softening else 0):
                old = self.sigmas[i]
                self.sigmas[i] = st
                if old is not None:
                    st = dict(st, normal=np.sqrt(np.maximum(old["normal"], 1e-15)
                                                 * np.maximum(st["normal"], 1e-15)))
                    self.sigmas[i] = st
                new = statistics(i, t)
                change = np.max(np.abs(new["normal"] - st["normal"])
                                / np.maximum(new["normal"], 0.01 * self._critical))
                st = new
                if change < SOFTENING_TOLERANCE:
                    break
            self.sigmas[i] = st


# ---------------------------------------------------------------------------
# Fitting
# ---------------------------------------------------------------------------


@dataclass
class CandidateFit:
    """A candidate fitted to a set of rows."""

    candidate: Candidate
    theta: np.ndarray
    sigmas: list
    cost: float  # chi^2 of the fitted rows + prior
    nfev: int
    wall_s: float

    def base_scales(self, names) -> dict:
        return {n: float(math.exp(b)) for n, b in zip(names, self.theta[:len(names)],
                                                         strict=True)}

    def effect_values(self, n_base: int) -> dict:
        return self.candidate.values(self.theta[n_base:])


def row_sigma(rel_var, Hd, Hm) -> np.ndarray:
    """Std of each complex component of a row's error: the data's relative
    variance times the larger of the measured and modelled magnitudes (rows
    the model did not evaluate, NaN, take the measured one)."""
    return np.maximum(np.sqrt(rel_var) * np.maximum(np.abs(Hd), np.abs(np.nan_to_num(Hm))),
                      1e-300)


def residuals(pred: Predictor, theta, mask) -> np.ndarray:
    """Normalised complex errors of the rows in `mask` (real and imaginary
    parts), then the prior on the base log-scales."""
    Hm = pred.predict(theta, mask)[mask]
    Hd = pred.rows.H[mask]
    r = (Hm - Hd) / row_sigma(pred.rows.rel_var[mask], Hd, Hm)
    return np.concatenate([r.real, r.imag, theta[:pred.n_base] / BASE_PRIOR_SIGMA])


def fit_candidate(pred: Predictor, mask, theta0=None, rounds: int = 2,
                  max_iterations: int = 25) -> CandidateFit:
    """Least-squares fit of the base log-scales and the effect coordinates
    to the rows in `mask` (bounded trust region; forward-difference
    Jacobian), with the response statistics refreshed between rounds."""
    import time

    from scipy.optimize import least_squares

    t0 = time.perf_counter()
    lo, hi = pred.bounds()
    nb = pred.n_base
    nfev = 0
    if theta0 is None:
        starts = pred.candidate.start_grid()
        best = None
        for c in starts:
            th = np.concatenate([np.zeros(nb), np.clip(c, lo[nb:], hi[nb:])])
            pred.update_statistics(th)
            cost = float(np.sum(residuals(pred, th, mask) ** 2))
            nfev += 1
            if best is None or cost < best[0]:
                best = (cost, th)
        theta = best[1]
    else:
        theta = np.clip(np.asarray(theta0, float), lo, hi)
    steps = np.concatenate([np.full(nb, 0.01), 0.005 * (hi[nb:] - lo[nb:])])

    # least_squares evaluates the residuals at a point, then asks for the
    # Jacobian there: the last evaluation is kept for it (one response
    # evaluation in P + 2 fewer per iteration; the statistics, on which the
    # residuals also depend, stay fixed within a least_squares call).
    last = [None, None]

    def fun(th):
        r = residuals(pred, th, mask)
        last[0], last[1] = th.tobytes(), r.copy()
        return r

    def jac(th):
        r0 = last[1] if last[0] == th.tobytes() else residuals(pred, th, mask)
        J = np.empty((len(r0), len(th)))
        for k in range(len(th)):
            step = steps[k] if th[k] + steps[k] <= hi[k] else -steps[k]
            tp = th.copy()
            tp[k] += step
            J[:, k] = (residuals(pred, tp, mask) - r0) / step
        return J

    for _ in range(rounds):
        pred.update_statistics(theta)
        last[0] = None  # the statistics changed
        res = least_squares(fun, theta, jac=jac,
                            bounds=(lo, hi), method="trf", x_scale="jac", ftol=1e-4,
                            xtol=1e-4, max_nfev=max_iterations)
        nfev += res.nfev * (len(theta) + 1)
        theta = res.x
    pred.update_statistics(theta)
    cost = float(np.sum(residuals(pred, theta, mask) ** 2))
    return CandidateFit(pred.candidate, theta, list(pred.sigmas), cost, nfev,
                        time.perf_counter() - t0)


def family_of(state: dict, name: str):
    """The (re-centered) family candidate `name` was fitted with."""
    cand = Candidate(() if name == "none" else tuple(name.split("+")))
    fam = state["families"][cand.grid_effect or "base"]
    rec = state.get("recentered", {}).get(name)
    if rec is not None:
        fam = copy.copy(fam)
        fam.anchor, fam.correction = rec
    return fam
