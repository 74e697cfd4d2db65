"""What the fit compares: the measured rows as a weighted residual
(`Residuals`) and the model's linear transmissibility at the data's
vibration levels (`Evaluator`, picklable for the worker processes).

The model's level.  The body softens with the vibration's magnitude
(`ehm_drake.model.softening`): data recorded at a level are the
equivalent-linear model's at that level, not the linearization at rest.
The rows fall into excitation groups (`excitation_groups`): one test per
direction and level (``separate``) or the directions excited together at a
level (``simultaneous``).  Each group's element RMS movements are found by
the equivalent-linear iteration (`ehm_drake.analysis.equivalent`) on a flat
spectrum of the group's band and level, then held fixed while the
optimizer moves the parameters; they are found again with the equilibrium
between the fit's stages and for the final model (as the equilibrium is).
Rows without a level (``level_rms`` absent) are compared with the model at
rest.

Simultaneous axes.  With several seat axes excited at once, the estimate
of each path is multiple-input H1 and the coherence column holds the
output's multiple coherence, the same for every input: it says nothing of
a small path beside a large one.  The variance of path j of an output with
independent inputs of equal spectra is (1 - g^2)/g^2 sum_i |H_i|^2 /
(2 n), so relative to |H_j|^2 the path's inverse-variance weight is the
coherence weight times |H_j|^2 / sum_i |H_i|^2 (`path_shares`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..analysis.formats import FrfData
from ..model.anthropometry import BodyMeasures
from ..params import ModelParams, params_from_dict
from ..signals import BAND_HZ
from ..systems.outputs import CHANNEL_NAMES
from .parameters import apply_scales


class FitError(RuntimeError):
    """The fit cannot proceed (bad data for fitting, no usable rows, ...)."""


#: Default channel weights: head and trunk prioritised over the pelvis
#: (Desai et al. IV), knees least.
DEFAULT_SEGMENT_WEIGHTS = {"head": 1.0, "trunk": 1.0, "pelvis": 0.5, "knee_l": 0.3, "knee_r": 0.3}
COHERENCE_CAP = 0.99
UNSTABLE_PENALTY = 30.0
EXCITATIONS = ("separate", "simultaneous")
#: A model path whose largest gain is below this fraction of the largest gain
#: of the outputs of its kind (translations or rotations, every direction) is
#: zero by the model's symmetry: in the symmetric model such paths are ~1e-10
#: of it (rounding in the linearization), real paths at least ~1e-3.
STRUCTURAL_ZERO = 1e-6


def channel_weight(weights: dict[str, float], direction: str, segment: str, dof: str) -> float:
    for key in (f"{direction}/{segment}/{dof}", f"{segment}_{dof}", segment):
        if key in weights:
            return weights[key]
    return DEFAULT_SEGMENT_WEIGHTS.get(segment, 1.0)


# ---------------------------------------------------------------------------
# Excitation groups
# ---------------------------------------------------------------------------


def _level_key(level: float) -> float:
    return -1.0 if not math.isfinite(level) else round(float(level), 9)


def excitation_groups(frf: FrfData, excitation: str) -> list[tuple[str, float]]:
    """The tests behind the rows of `frf` (all of them, held-out rows
    included): (directions excited together, level in m/s^2 RMS or NaN),
    sorted."""
    if excitation not in EXCITATIONS:
        raise FitError(f"excitation {excitation!r}: choose {' or '.join(EXCITATIONS)}")
    by_level: dict[float, set[str]] = {}
    for d, lv in zip(frf.direction, frf.level_rms, strict=True):
        by_level.setdefault(_level_key(lv), set()).add(str(d))
    groups = []
    for key, dirs in sorted(by_level.items()):
        level = math.nan if key < 0 else key
        if excitation == "simultaneous":
            groups.append(("".join(sorted(dirs)), level))
        else:
            groups += [(d, level) for d in sorted(dirs)]
    return groups


def group_of(groups: list[tuple[str, float]], direction: str, level: float) -> int:
    key = _level_key(level)
    for g, (dirs, lv) in enumerate(groups):
        if direction in dirs and _level_key(lv) == key:
            return g
    raise FitError(f"no excitation group for direction {direction} at level {level}")


def path_shares(frf: FrfData) -> dict[tuple, float]:
    """|H_j|^2 / sum_i |H_i|^2 per row key (direction, segment, dof, freq,
    level) over the directions measured together (module docstring)."""
    total: dict[tuple, float] = {}
    keys = [(str(d), str(s), str(o), round(float(f), 9), _level_key(lv))
            for d, s, o, f, lv in zip(frf.direction, frf.segment, frf.dof, frf.freq_hz,
                                      frf.level_rms, strict=True)]
    g2 = np.asarray(frf.gain, float) ** 2
    for k, v in zip(keys, g2, strict=True):
        total[k[1:]] = total.get(k[1:], 0.0) + v
    return {k: float(v / total[k[1:]]) if total[k[1:]] > 0 else 1.0
            for k, v in zip(keys, g2, strict=True)}


# ---------------------------------------------------------------------------
# Residuals
# ---------------------------------------------------------------------------


@dataclass
class Residuals:
    """Maps a model transmissibility array (groups, nf, 30, ndir) to the
    weighted residual vector for a fixed set of measured rows (picklable)."""

    freqs: np.ndarray  # unique frequencies the model is evaluated at
    directions: str
    row_f: np.ndarray  # index into freqs per row
    row_c: np.ndarray  # channel index (0..29) per row
    row_d: np.ndarray  # direction index per row
    log_gain: np.ndarray
    phase: np.ndarray  # rad
    w_gain: np.ndarray
    w_phase: np.ndarray
    keys: list  # (direction, segment, dof, level) per row
    rows_per_key: dict = field(default_factory=dict)
    row_g: np.ndarray | None = None  # excitation group per row (None: one group)

    @classmethod
    def build(cls, frf: FrfData, weights: dict[str, float], phase_weight: float = 0.5,
              min_coherence: float = 0.3, phase_min_coherence: float = 0.8,
              groups: list[tuple[str, float]] | None = None,
              shares: dict[tuple, float] | None = None) -> Residuals:
        """`groups`: the excitation groups (`excitation_groups`) the rows are
        assigned to; `shares`: each path's share of its output
        (`path_shares`, simultaneous axes), which scales its weight."""
        # The first two bins of each Welch grid are not estimates of T(f) (their
        # windows reach below the excited band: `FrfData.lowest_welch_bins`); the fit
        # leaves them out as the gap diagnosis does.
        keep = (frf.coherence >= min_coherence) & ~frf.lowest_welch_bins()
        if not np.any(keep):
            raise FitError(f"no data row has coherence >= {min_coherence} (the first two bins "
                           "of each Welch grid left out); nothing to fit")
        direction = frf.direction[keep]
        segment = frf.segment[keep]
        dof = frf.dof[keep]
        f = frf.freq_hz[keep]
        gain = frf.gain[keep]
        coh = frf.coherence[keep]
        level = frf.level_rms[keep]
        if np.any(gain <= 0):
            i = int(np.argmax(gain <= 0))
            raise FitError(f"zero gain in {direction[i]}/{segment[i]}/{dof[i]} at {f[i]:g} Hz: "
                           "its log error is undefined; drop the row or its channel")
        directions = "".join(d for d in "xyz" if d in set(direction))
        freqs = np.unique(f)
        c = np.array([CHANNEL_NAMES.index(f"{s}_{d}") for s, d in zip(segment, dof, strict=True)])
        g2 = np.minimum(coh, COHERENCE_CAP) ** 2
        w_coh = g2 / (1.0 - g2)
        if shares is not None:
            w_coh = w_coh * np.array([
                shares.get((str(d), str(s), str(o), round(float(fi), 9), _level_key(lv)), 1.0)
                for d, s, o, fi, lv in zip(direction, segment, dof, f, level, strict=True)])
        keys = [(d, s, o, float(lv)) for d, s, o, lv in zip(direction, segment, dof, level,
                                                             strict=True)]
        counts: dict = {}
        for k in keys:
            counts[k] = counts.get(k, 0) + 1
        w_ch = np.array([channel_weight(weights, k[0], k[1], k[2]) for k in keys])
        n_rows = np.array([counts[k] for k in keys], float)
        base = w_ch * w_coh / n_rows
        base = base / base.sum()
        w_gain = np.sqrt(base)
        w_phase = np.where(coh >= phase_min_coherence, np.sqrt(base) * phase_weight, 0.0)
        row_g = None if groups is None else np.array(
            [group_of(groups, str(d), float(lv)) for d, lv in zip(direction, level, strict=True)])
        return cls(freqs, directions, np.searchsorted(freqs, f), c,
                   np.array([directions.index(d) for d in direction]), np.log(gain),
                   np.radians(frf.phase_deg[keep]), w_gain, w_phase, keys, counts, row_g)

    def reindexed(self, freqs: np.ndarray, directions: str) -> Residuals:
        """Its rows indexed into a common frequency grid and directions."""
        self.row_f = np.searchsorted(freqs, self.freqs[self.row_f])
        self.row_d = np.array([directions.index(k[0]) for k in self.keys])
        self.freqs = freqs
        self.directions = directions
        return self

    @property
    def size(self) -> int:
        return 2 * len(self.row_f)

    def model_values(self, T: np.ndarray) -> np.ndarray:
        if T.ndim == 3:
            return T[self.row_f, self.row_c, self.row_d]
        g = np.zeros(len(self.row_f), int) if self.row_g is None else self.row_g
        return T[g, self.row_f, self.row_c, self.row_d]

    def __call__(self, T: np.ndarray) -> np.ndarray:
        t = self.model_values(T)
        e_gain = np.log(np.abs(t)) - self.log_gain
        e_phase = np.angle(t * np.exp(-1j * self.phase))
        return np.concatenate([self.w_gain * e_gain, self.w_phase * e_phase])

    def channel_errors(self, T: np.ndarray) -> dict[str, float]:
        """RMS log-gain error per channel, as a fraction (0.1 = ~10%)."""
        t = self.model_values(T)
        e = np.log(np.abs(t)) - self.log_gain
        out: dict[str, list[float]] = {}
        for k, ei in zip(self.keys, e, strict=True):
            name = f"{k[0]}/{k[1]}/{k[2]}" + ("" if math.isnan(k[3]) else f"@{k[3]:g}")
            out.setdefault(name, []).append(ei)
        return {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in out.items()}

    def gain_error(self, T: np.ndarray) -> float:
        """Weighted RMS log-gain error (fraction) over all rows."""
        t = self.model_values(T)
        e = np.log(np.abs(t)) - self.log_gain
        w = self.w_gain**2
        return float(np.sqrt(np.sum(w * e * e) / np.sum(w)))


# ---------------------------------------------------------------------------
# Paths the model cannot produce
# ---------------------------------------------------------------------------


def structural_zeros(T: np.ndarray, directions: str) -> set[tuple[str, str]]:
    """(direction, channel) paths the model `T` ((groups,) nf, 30, ndir)
    cannot produce: zero at every frequency relative to the largest gain of
    the outputs of their kind (translations, rotations)."""
    A = np.abs(T).reshape((-1,) + T.shape[-2:])
    peak = A.max(axis=0)  # (30, ndir)
    rotation = np.array([c.rsplit("_", 1)[1] in ("roll", "pitch", "yaw") for c in CHANNEL_NAMES])
    ref = np.where(rotation, peak[rotation].max(), peak[~rotation].max())[:, None]
    small = peak <= STRUCTURAL_ZERO * np.maximum(ref, 1e-300)
    return {(directions[j], CHANNEL_NAMES[c]) for c, j in zip(*np.nonzero(small), strict=True)}


def drop_paths(frf: FrfData | None, paths: set[tuple[str, str]]) -> FrfData | None:
    if frf is None:
        return None
    keep = [i for i in range(len(frf))
            if (frf.direction[i], f"{frf.segment[i]}_{frf.dof[i]}") not in paths]
    return frf._take(np.array(keep, int))


def zero_paths_warning(paths: set[tuple[str, str]], frf: FrfData) -> str:
    in_data = {(d, f"{s}_{o}") for d, s, o in zip(frf.direction, frf.segment, frf.dof,
                                                   strict=True)}
    present = sorted(paths & in_data)
    names = ", ".join(f"{d}->{c}" for d, c in present)
    return (f"{len(present)} path(s) left out: the model's response there is zero by its "
            f"left-right symmetry, so the data hold only estimation noise ({names})")


# ---------------------------------------------------------------------------
# Model evaluation (runs in worker processes too)
# ---------------------------------------------------------------------------


@dataclass
class Evaluator:
    """Builds the model for a scale vector and returns its linear
    transmissibility (groups, nf, 30, ndir) at each excitation group's level;
    picklable (plain inputs only)."""

    base: dict  # ModelParams as a dict
    measures: tuple  # (mass, stature, sitting height)
    variant: str
    free_names: list[str]
    freqs: np.ndarray
    directions: str
    groups: list = field(default_factory=lambda: [("xyz", math.nan)])
    band_hz: tuple = tuple(BAND_HZ)
    x_ref: np.ndarray | None = None
    #: Each group's element RMS movements (None: at rest).
    rms: list | None = None
    _free: list = field(default=None, repr=False)
    _base: ModelParams = field(default=None, repr=False)

    def setup(self) -> Evaluator:
        from .parameters import load_registry

        registry, _ = load_registry()
        self._free = [registry[n] for n in self.free_names]
        self._base = params_from_dict(self.base)
        if self.x_ref is None:
            self.x_ref = self.equilibrium(np.zeros(len(self._free)))
        if self.rms is None:
            self.rms = self.element_rms(np.zeros(len(self._free)), self.x_ref)
        return self

    def body(self) -> BodyMeasures:
        return BodyMeasures(*self.measures)

    def _model(self, log_scales):
        from ..diagram import build_diagram

        return build_diagram(self.params(log_scales), self.body(), None, self.variant,
                             guard=False, seat_forces=False)

    def _context(self, model, at_equilibrium: bool):
        from ..simulation import StateMap, static_equilibrium

        if at_equilibrium:
            return static_equilibrium(model)[0]
        ctx = model.diagram.CreateDefaultContext()
        StateMap(model).set(ctx, self.x_ref)
        return ctx

    def equilibrium(self, log_scales) -> np.ndarray:
        """Static equilibrium state of the model with these scales."""
        from ..simulation import static_equilibrium

        ctx, smap = static_equilibrium(self._model(log_scales))
        return smap.get(ctx)

    def params(self, log_scales) -> ModelParams:
        return apply_scales(self._base, self._free, np.exp(log_scales))

    def element_rms(self, log_scales, x_ref=None, warm: list | None = None) -> list:
        """Each group's element RMS movements at its level, the model with
        these scales linearized about `x_ref` (None: its own equilibrium);
        None for a group without a level or a model without softening."""
        from ..simulation import StateMap

        model = self._model(log_scales)
        if model.systems.get("body_softening") is None:
            return [None] * len(self.groups)
        if x_ref is None:
            ctx = self._context(model, True)
        else:
            ctx = model.diagram.CreateDefaultContext()
            StateMap(model).set(ctx, x_ref)
        return self._element_rms(model, ctx, warm)

    def own(self, log_scales, warm: list | None = None):
        """(T, stable, each group's element RMS movements) of the model
        with these scales at its own static equilibrium and its own
        softening at the groups' levels (`warm`: RMS movements to start
        from)."""
        model = self._model(log_scales)
        ctx = self._context(model, True)
        rms = ([None] * len(self.groups) if model.systems.get("body_softening") is None
               else self._element_rms(model, ctx, warm))
        lms = self._linear_models(model, ctx, rms)
        T = np.stack([lm.transmissibility_array(self.freqs, self.directions) for lm in lms])
        return T, all(lm.is_stable for lm in lms), rms

    def _element_rms(self, model, ctx, warm) -> list:
        from ..analysis.equivalent import EquivalentLinearError, SeatSpectrum, equivalent_linear

        out = []
        for g, (dirs, level) in enumerate(self.groups):
            if not math.isfinite(level):
                out.append(None)
                continue
            spectrum = SeatSpectrum.flat(dirs, level, self.band_hz)
            try:
                eq = equivalent_linear(model, spectrum, ctx, outputs=["channels"],
                                       rms_start=None if warm is None else warm[g])
            except EquivalentLinearError as e:
                raise FitError(f"the model at {spectrum.description}: {e}") from None
            out.append(eq.movement_rms)
        return out

    def linear_models(self, log_scales, at_equilibrium: bool = False) -> list:
        """One linear model per excitation group (shared where their RMS
        movements are the same)."""
        model = self._model(log_scales)
        return self._linear_models(model, self._context(model, at_equilibrium), self.rms)

    def _linear_models(self, model, ctx, rms) -> list:
        from ..analysis.linear import linearize

        soft = model.systems.get("body_softening")
        sctx = soft.GetMyMutableContextFromRoot(ctx) if soft is not None else None
        made: dict = {}
        out = []
        for s in (rms or [None] * len(self.groups)):
            key = None if s is None or soft is None else np.asarray(s).tobytes()
            if key not in made:
                if soft is not None:
                    soft.set_rms(sctx, s)
                made[key] = linearize(model, ctx, method="fd", outputs=["channels"])
            out.append(made[key])
        return out

    def transmissibility(self, log_scales, at_equilibrium: bool = False):
        """(T (groups, nf, 30, ndir), stable)."""
        lms = self.linear_models(log_scales, at_equilibrium)
        T = np.stack([lm.transmissibility_array(self.freqs, self.directions) for lm in lms])
        return T, all(lm.is_stable for lm in lms)

    def per_direction(self, T: np.ndarray) -> np.ndarray:
        """(nf, 30, ndir): each direction's response from the first group
        that excites it (for figures)."""
        out = np.empty(T.shape[1:], complex)
        for j, d in enumerate(self.directions):
            g = next((g for g, (dirs, _) in enumerate(self.groups) if d in dirs), 0)
            out[:, :, j] = T[g, :, :, j]
        return out


_WORKER: dict = {}


def init_worker(evaluator: Evaluator, residuals: Residuals) -> None:
    _WORKER["ev"] = evaluator.setup()
    _WORKER["res"] = residuals


def worker_residual(task) -> np.ndarray:
    """(log scales, the state to linearize about, or None for the
    parameters' own static equilibrium, the groups' RMS movements) ->
    residual."""
    log_scales, x_ref, rms = task
    _WORKER["ev"].rms = rms
    if x_ref is None:
        return residual(_WORKER["ev"], _WORKER["res"], log_scales, at_equilibrium=True)
    _WORKER["ev"].x_ref = x_ref
    return residual(_WORKER["ev"], _WORKER["res"], log_scales)


def residual(ev: Evaluator, res: Residuals, log_scales, at_equilibrium: bool = False
             ) -> np.ndarray:
    return penalized(res, *ev.transmissibility(log_scales, at_equilibrium))


def penalized(res: Residuals, T: np.ndarray, stable: bool) -> np.ndarray:
    """The residual of `T`, pushed away from an unstable model (keeps the
    optimizer in the stable region)."""
    r = res(T)
    if not stable:
        r = r + UNSTABLE_PENALTY * np.sign(r + 1e-300) * np.abs(res.w_gain).max()
    return r
