"""Linear model families for the gap diagnosis: the closed loop linearized
with the controllers' feedback cut open, and its first-order sensitivity
to the base parameters and to the seat/joint quantities through which the
level-dependent effects act.

Why cut open.  The reflex delay sits in the feedback from the body's state
to the PID and head-in-space controllers.  Linearizing the diagram with
that feedback as an input (``controller_state``, see `build_diagram`'s
`controller_input`) gives

    x+ = A x + Bu a + Bw w,      w = K x  (delayed by d steps: z^-d K x)

so the closed loop without delay is A + Bw K, and with a delay of d time
steps its frequency response is C (zI - A - z^-d Bw K)^-1 Bu, evaluated
through the eigen-decomposition of A and a small solve per frequency (Bw
has the rank of the controller torques).

Sensitivities.  Every direction is a first-order finite difference of the
cut-open matrices, at the nominal static equilibrium (the equilibrium
moves by millimetres when stiffnesses change, a second-order effect, as in
`ehm_drake.identification.fit`):

* base parameters (the fit registry's, `ehm_drake/data/fit_parameters.yaml`):
  per unit relative change of the parameter (u = theta / theta0 - 1);
* equivalent-linear directions, per restraint group (pelvis, thighs, lower
  and upper pad, feet): an extra normal spring / damper about the static
  compression (per unit of the pair's contact stiffness / damping) and a
  change of the shear restraint's stiffness / damping (per unit of its own
  value); and the active stiffness of the co-contracting joints (per unit
  of their kp).  The forces of all of these are linear in the parameter,
  so the first-order model is exact up to SAP's (small) implicit coupling.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np

from ...analysis.linear import FD_STEP, INPUT_FD_STEP, _linearize_fd
from ...diagram import build_diagram
from ...model.anthropometry import REFERENCE, BodyMeasures
from ...model.extensions import equilibrium_effects
from ...parallel import run_jobs
from ...params import ModelParams, params_from_dict
from ...systems.seat import restraint_block
from .effects import COCONTRACTION_GROUPS

GAP_OUTPUTS = ("channels", "restraint_normal_displacement", "restraint_deflection")
#: Restraint point groups (by contact pair) of the equivalent directions.
RESTRAINT_GROUPS = {"pelvis_pan": "pelvis", "thighs_pan": "thighs",
                    "lower_back_pad": "lower_pad", "upper_back_pad": "upper_pad",
                    "feet_floor": "feet"}
GROUP_NAMES = tuple(RESTRAINT_GROUPS.values())
EQUIVALENT_KINDS = ("k_normal", "c_normal", "k_shear", "c_shear")
EQUIVALENT_DIRECTIONS = tuple(f"{k}:{g}" for g in GROUP_NAMES for k in EQUIVALENT_KINDS) + (
    "kp_cocontraction",)
#: Relative step of the base-parameter sensitivities.
SENSITIVITY_STEP = 0.1


def _without_delay(effects: dict) -> dict:
    """`effects` without the feedback delay (it is applied in the frequency
    domain, see `response`) or any other extension left out of the static
    equilibrium."""
    return equilibrium_effects(effects)


@dataclass
class PointInfo:
    """Static facts of the restraint points, for the equivalent linearizations."""

    names: list[str]
    groups: np.ndarray  # group name per point
    parts: np.ndarray  # seat part per point
    k_contact: np.ndarray  # pair normal contact stiffness (N/m)
    c_contact: np.ndarray  # pair normal contact damping (N s/m)
    k_shear: np.ndarray  # shear restraint stiffness (N/m)
    c_shear: np.ndarray
    force_limit: np.ndarray  # N
    penetration: np.ndarray  # static penetration (m), > 0 in contact
    deflection: np.ndarray  # (n, 2) static shear deflection (m)


@dataclass
class CutLinearization:
    """x+ = A x + Bu a + Bw w, y = C x (reduced: the restraints' slip states
    dropped, as they do not move below the force limits; `slip_coupling` =
    dx+/ds, the state update's dependence on the slip of each restraint
    axis (columns in the order of the ``restraint_deflection`` output), for
    the equivalent linearization of slipping restraints)."""

    A: np.ndarray
    Bu: np.ndarray
    Bw: np.ndarray
    C: np.ndarray
    K: np.ndarray  # (nw, n): w = K x (the plant state in x)
    h: float
    state_names: list[str]
    output_groups: dict
    y0: np.ndarray
    slip_coupling: np.ndarray | None = None  # (n, 2 x points)

    @property
    def n(self) -> int:
        return self.A.shape[0]


def _prepare(params: ModelParams, measures: BodyMeasures, effects: dict):
    """The cut-open diagram at the static equilibrium: (model, context,
    state map)."""
    from ...simulation import StateMap, set_normal_reference, static_equilibrium

    closed = build_diagram(params, measures, None, guard=False, seat_forces=False,
                           effects=_without_delay(effects))
    ctx, smap = static_equilibrium(closed)
    x_eq = smap.get(ctx)
    cut = build_diagram(params, measures, None, guard=False, seat_forces=False,
                        effects=_without_delay(effects), controller_input=True)
    cctx = cut.diagram.CreateDefaultContext()
    cmap = StateMap(cut)
    cmap.set(cctx, cmap.transfer(smap, x_eq, cmap.get(cctx)))
    for name in ("seat_acceleration", "seat_displacement"):
        cut.diagram.GetInputPort(name).FixValue(cctx, np.zeros(3))
    xp = x_eq[smap.slice("plant")]
    cut.diagram.GetInputPort("controller_state").FixValue(cctx, xp)
    set_normal_reference(cut, cctx)
    return cut, cctx, cmap


def _linearize_cut(cut, cctx, cmap, central: bool = True) -> CutLinearization:
    diagram = cut.diagram
    A, B, C, D = _linearize_fd(diagram, cctx, cmap, GAP_OUTPUTS, FD_STEP, central,
                               inputs=[("seat_acceleration", INPUT_FD_STEP),
                                       ("controller_state", FD_STEP)])
    names = []
    for s, n in zip(cmap.systems, cmap.sizes, strict=True):
        names += [f"{s.get_name()}:{i}" for i in range(n)]
    # Dropped: the restraints' slip (it does not move below the force
    # limits) and the body's softening's running means and variances (the
    # means follow the tissue below 0.08 Hz, under the analysed band; the
    # variances act on nothing at rest): the softening's short-range
    # stiffness then acts about the equilibrium, as the equivalent
    # directions do.
    keep = np.array([not n.startswith(("shear_restraints:", "body_softening:"))
                     for n in names])
    idx = np.flatnonzero(keep)
    plant = cmap.slice("plant")
    nw = plant.stop - plant.start
    K = np.zeros((nw, len(idx)))
    pos = {int(i): j for j, i in enumerate(idx)}
    for r, i in enumerate(range(plant.start, plant.stop)):
        K[r, pos[i]] = 1.0
    sizes = [diagram.GetOutputPort(p).size() for p in GAP_OUTPUTS]
    off = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    groups = {p: slice(int(off[i]), int(off[i + 1])) for i, p in enumerate(GAP_OUTPUTS)}
    y0 = np.concatenate([diagram.GetOutputPort(p).Eval(cctx) for p in GAP_OUTPUTS])
    if np.max(np.abs(D[:, 3:])) > 1e-9 * max(1.0, np.max(np.abs(C))):
        raise RuntimeError("gap outputs depend directly on the controller input")
    slip = cmap.slice("shear_restraints")
    return CutLinearization(A[np.ix_(idx, idx)], B[idx, :3], B[idx, 3:], C[:, idx], K,
                            cut.params.simulation.time_step_s, [names[i] for i in idx],
                            groups, y0, A[idx, slip.start:slip.stop])


def _point_info(cut, cctx, lin: CutLinearization) -> PointInfo:
    restraints = cut.systems["shear_restraints"]
    pts = restraints.points
    prm = restraints.GetMyContextFromRoot(cctx).get_numeric_parameter(
        restraints.parameter_index).CopyToVector()
    normal = lin.y0[lin.output_groups["restraint_normal_displacement"]]
    defl = lin.y0[lin.output_groups["restraint_deflection"]].reshape(-1, 2)
    face = np.array([p.face_offset for p in pts])
    params = cut.params
    return PointInfo(
        names=[p.name for p in pts],
        groups=np.array([RESTRAINT_GROUPS[p.pair] for p in pts]),
        parts=np.array([p.part for p in pts]),
        k_contact=np.array([getattr(params.contact, p.pair).stiffness for p in pts]),
        c_contact=np.array([getattr(params.contact, p.pair).damping for p in pts]),
        k_shear=restraint_block(prm, "stiffness").copy(),
        c_shear=restraint_block(prm, "damping").copy(),
        force_limit=restraint_block(prm, "force_limit").copy(),
        penetration=face - normal,
        deflection=defl,
    )


def _equivalent_variant(cut, cctx, direction: str, info: PointInfo):
    """Apply one equivalent direction (unit step) to the cut model's numeric
    parameters in `cctx`; returns an undo function."""
    if direction == "kp_cocontraction":
        pid = cut.systems["joint_pid"]
        pctx = pid.GetMyMutableContextFromRoot(cctx)
        prm = pctx.get_mutable_numeric_parameter(pid.parameter_index)
        old = prm.CopyToVector()
        layout = cut.hp.layout
        n = layout.num_rotational
        new = old.copy()
        mask = np.array([g in COCONTRACTION_GROUPS for g in layout.groups])
        new[:n][mask] *= 2.0  # kp -> kp (1 + 1)
        prm.SetFromVector(new)
        return lambda: prm.SetFromVector(old)
    kind, group = direction.split(":")
    restraints = cut.systems["shear_restraints"]
    rctx = restraints.GetMyMutableContextFromRoot(cctx)
    prm = rctx.get_mutable_numeric_parameter(restraints.parameter_index)
    old = prm.CopyToVector()
    new = old.copy()
    sel = info.groups == group
    if kind == "k_normal":
        restraint_block(new, "normal_linear_stiffness")[sel] += info.k_contact[sel]
    elif kind == "c_normal":
        restraint_block(new, "normal_linear_damping")[sel] += info.c_contact[sel]
    elif kind == "k_shear":
        restraint_block(new, "stiffness")[sel] *= 2.0
        # Keep the static shear force: halve the elastic deflection by
        # moving the anchors (the slip state) towards the points.
        slip = rctx.get_mutable_discrete_state(restraints.slip_state_index)
        old_slip = slip.CopyToVector()
        rows = np.repeat(sel, 2)
        pos = restraints.axis_deflection(rctx)
        new_slip = old_slip.copy()
        new_slip[rows] = pos[rows] - 0.5 * (pos[rows] - old_slip[rows])
        prm.SetFromVector(new)
        slip.SetFromVector(new_slip)

        def undo():
            prm.SetFromVector(old)
            slip.SetFromVector(old_slip)

        return undo
    elif kind == "c_shear":
        restraint_block(new, "damping")[sel] *= 2.0
    prm.SetFromVector(new)
    return lambda: prm.SetFromVector(old)


# ---------------------------------------------------------------------------
# Worker functions (module level: picklable)
# ---------------------------------------------------------------------------


def _job_equivalent(args):
    params_dict, measures, effects, directions = args
    params = params_from_dict(params_dict)
    cut, cctx, cmap = _prepare(params, BodyMeasures(*measures), effects)
    base = _linearize_cut(cut, cctx, cmap)
    info = _point_info(cut, cctx, base)
    out = {"__base__": base, "__info__": info}
    for d in directions:
        undo = _equivalent_variant(cut, cctx, d, info)
        out[d] = _linearize_cut(cut, cctx, cmap)
        undo()
    return out


def _job_base_parameter(args):
    """Cut linearization with base parameter `name` scaled by 1 + step, at
    its own static equilibrium (the PID integrals and restraint slips then
    carry the same static loads: at a foreign equilibrium state the static
    joint torques would differ, and with them the geometric stiffness)."""
    from ...identification.parameters import apply_scales, load_registry

    params_dict, measures, effects, name, step = args
    registry, _ = load_registry()
    params = apply_scales(params_from_dict(params_dict), [registry[name]], [1.0 + step])
    cut, cctx, cmap = _prepare(params, BodyMeasures(*measures), effects)
    return name, _linearize_cut(cut, cctx, cmap)


@dataclass
class LinearFamily:
    """A nominal cut-open linearization and its sensitivities.

    `evaluate(u)` gives the matrices at deviations `u` (one value per
    direction in `directions`: base parameters as relative changes,
    equivalent directions in their units)."""

    nominal: CutLinearization
    info: PointInfo
    directions: list[str]
    dA: np.ndarray  # (P, n, n)
    dBu: np.ndarray
    dBw: np.ndarray
    dC: np.ndarray
    effects: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)

    def index(self, name: str) -> int:
        return self.directions.index(name)

    def matrices(self, u: np.ndarray):
        u = np.asarray(u, float)
        nz = np.flatnonzero(u)
        lin = self.nominal
        if len(nz) == 0:
            return lin.A, lin.Bu, lin.Bw, lin.C
        w = u[nz]
        return (lin.A + np.tensordot(w, self.dA[nz], 1), lin.Bu + np.tensordot(w, self.dBu[nz], 1),
                lin.Bw + np.tensordot(w, self.dBw[nz], 1), lin.C + np.tensordot(w, self.dC[nz], 1))


def _job_grid(args):
    """Cut linearization of the model with `effects` (a grid point of an
    effect's parameters) at its own equilibrium."""
    params_dict, measures, effects = args
    cut, cctx, cmap = _prepare(params_from_dict(params_dict), BodyMeasures(*measures), effects)
    lin = _linearize_cut(cut, cctx, cmap)
    return lin, _point_info(cut, cctx, lin)


def stiffness_basis(values) -> np.ndarray:
    """[1, v1, sqrt(v1), v2, sqrt(v2), ..., sqrt(v1 v2)]: linearized dynamics
    in the stiffnesses of spring-dampers whose damping goes with
    sqrt(stiffness) (constant damping ratio) are nearly of this form (the
    cross term and SAP's implicit solve couple them slightly)."""
    v = np.asarray(values, float)
    terms = [1.0] + list(np.ravel(np.column_stack([v, np.sqrt(v)])))
    if len(v) == 2:
        terms.append(math.sqrt(v[0] * v[1]))
    return np.array(terms)


@dataclass
class EffectGrid:
    """Cut linearizations of an effect's extended model over a grid of its
    parameter values, and their interpolation:

    * "spline": (tensor-product) cubic splines in the coordinates (the log
      of log-type values), for smooth dependences such as on a mass;
    * "stiffness": least-squares coefficients of `stiffness_basis` (the
      matrices are ~affine in stiffness and its square root, which splines
      in log-stiffness resolve poorly); `fit_residual` is the largest
      misfit at the grid points relative to the largest entry."""

    effect: str
    axes: list  # coordinate grid per effect parameter
    A: np.ndarray  # (*grid, n, n) or (n_basis, n, n)
    Bu: np.ndarray
    Bw: np.ndarray
    C: np.ndarray
    mode: str = "spline"
    log_axes: tuple = ()
    fit_residual: float = 0.0

    def at(self, coords):
        from scipy.interpolate import CubicSpline

        coords = np.atleast_1d(np.asarray(coords, float))
        mats = (self.A, self.Bu, self.Bw, self.C)
        if self.mode == "stiffness":
            vals = [math.exp(c) if lg else c for c, lg in zip(coords, self.log_axes,
                                                             strict=True)]
            phi = stiffness_basis(vals)
            return tuple(np.tensordot(phi, M, 1) for M in mats)
        # The spline along the last grid axis is over the stored matrices,
        # the same at every call: made once (its construction was 12% of a
        # diagnosis).  Along the other axes it is over values that depend on
        # the coordinates, so those are made per call.
        last = len(self.axes) - 1
        splines = self.__dict__.get("_last_axis_splines")
        if splines is None:
            splines = [CubicSpline(self.axes[last], M, axis=last) for M in mats]
            self.__dict__["_last_axis_splines"] = splines
        out = []
        for spline in splines:
            V = spline(coords[last])
            for ax in reversed(range(last)):
                # Spline along the last remaining axis, evaluate, drop the axis.
                V = CubicSpline(self.axes[ax], V, axis=ax)(coords[ax])
            out.append(V)
        return tuple(out)

    def __getstate__(self):
        """Pickled without the splines (remade from the matrices)."""
        state = dict(self.__dict__)
        state.pop("_last_axis_splines", None)
        return state


@dataclass
class ModelFamily:
    """A linear family (nominal + sensitivities), optionally over an
    effect's parameter grid: matrices(coords, u) = grid(coords) + sum u dM."""

    family: LinearFamily
    grid: EffectGrid | None = None
    #: Re-centering: exact matrices minus the grid's at `anchor` coordinates
    #: (added everywhere: exact at the anchor, the grid's shape around it).
    anchor: np.ndarray | None = None
    correction: tuple | None = None

    def recenter(self, coords, exact: CutLinearization) -> None:
        """Make the grid exact at `coords` (an exact linearization there)."""
        grid = self.grid.at(coords)
        self.anchor = np.atleast_1d(np.asarray(coords, float))
        self.correction = tuple(getattr(exact, k) - g for k, g in
                                zip(("A", "Bu", "Bw", "C"), grid, strict=True))

    @property
    def directions(self) -> list[str]:
        return self.family.directions

    @property
    def K(self):
        return self.family.nominal.K

    @property
    def h(self) -> float:
        return self.family.nominal.h

    @property
    def output_groups(self) -> dict:
        return self.family.nominal.output_groups

    def matrices(self, coords, u):
        fam = self.family
        if self.grid is None:
            base = (fam.nominal.A, fam.nominal.Bu, fam.nominal.Bw, fam.nominal.C)
        else:
            base = self.grid.at(coords)
            if self.correction is not None:
                base = tuple(b + c for b, c in zip(base, self.correction, strict=True))
        u = np.asarray(u, float)
        nz = np.flatnonzero(u)
        if len(nz) == 0:
            return base
        w = u[nz]
        return tuple(M + np.tensordot(w, dM[nz], 1) for M, dM in
                     zip(base, (fam.dA, fam.dBu, fam.dBw, fam.dC), strict=True))


@dataclass
class FamilySpec:
    """What to linearize for one candidate model: `effects` at the
    reference point (sensitivities there) and, for effects that add
    dynamics, a grid over the effect's parameters."""

    name: str
    effects: dict
    grid_effect: str | None = None
    grid_axes: list = field(default_factory=list)  # coordinates per parameter
    grid_values: list = field(default_factory=list)  # parameter values per axis
    grid_mode: str = "spline"  # see EffectGrid
    log_axes: tuple = ()


def build_families(params: ModelParams, specs: list[FamilySpec],
                   measures: BodyMeasures = REFERENCE, base_parameters=(),
                   workers: int | None = None, progress=None) -> dict:
    """Linear families for `specs`, all jobs on one pool of `workers`
    processes.  Returns {spec name: ModelFamily}."""
    pd = params.to_dict()
    mtuple = (measures.mass_kg, measures.stature_m, measures.sitting_height_m)
    half = math.ceil(len(EQUIVALENT_DIRECTIONS) / 2)
    jobs, keys = [], []
    for sp in specs:
        eff = dict(sp.effects)
        for part in (EQUIVALENT_DIRECTIONS[:half], EQUIVALENT_DIRECTIONS[half:]):
            jobs.append((_job_equivalent, (pd, mtuple, eff, list(part))))
            keys.append((sp.name, "eq", None))
        for n in base_parameters:
            jobs.append((_job_base_parameter, (pd, mtuple, eff, n, SENSITIVITY_STEP)))
            keys.append((sp.name, "base", n))
        if sp.grid_effect:
            names = [p.name for p in _effect_params(sp.grid_effect)]
            for idx in np.ndindex(*[len(a) for a in sp.grid_values]):
                vals = dict(eff[sp.grid_effect])
                vals.update({n: float(sp.grid_values[k][i]) for k, (n, i) in
                             enumerate(zip(names, idx, strict=True))})
                jobs.append((_job_grid, (pd, mtuple, {**eff, sp.grid_effect: vals})))
                keys.append((sp.name, "grid", idx))
    results = run_jobs(jobs, workers,
                       (lambda done, total, *_: progress(done, total)) if progress else None)
    out = {}
    for sp in specs:
        res = {}
        grid = {}
        for key, r in zip(keys, results, strict=True):
            if key[0] != sp.name:
                continue
            if key[1] == "eq":
                res.update(r)
            elif key[1] == "base":
                res[key[2]] = r[1]
            else:
                grid[key[2]] = r[0]
        nominal, info = res["__base__"], res["__info__"]
        directions = list(base_parameters) + list(EQUIVALENT_DIRECTIONS)
        steps = {n: SENSITIVITY_STEP for n in base_parameters}
        steps.update({d: 1.0 for d in EQUIVALENT_DIRECTIONS})
        dM = {k: [] for k in ("A", "Bu", "Bw", "C")}
        for d in directions:
            lin = res[d]
            if lin.A.shape != nominal.A.shape:
                raise RuntimeError(f"sensitivity {d}: state dimension changed")
            for k in dM:
                dM[k].append((getattr(lin, k) - getattr(nominal, k)) / steps[d])
        fam = LinearFamily(nominal, info, directions, *(np.array(dM[k]) for k in
                                                          ("A", "Bu", "Bw", "C")),
                           dict(sp.effects), pd)
        egrid = None
        if sp.grid_effect:
            shape = tuple(len(a) for a in sp.grid_values)
            points = list(np.ndindex(*shape))
            mats, resid = [], 0.0
            for k in ("A", "Bu", "Bw", "C"):
                arr = np.array([getattr(grid[idx], k) for idx in points])
                if sp.grid_mode == "stiffness":
                    Phi = np.array([stiffness_basis([sp.grid_values[a][i] for a, i in
                                                     enumerate(idx)]) for idx in points])
                    Y = arr.reshape(len(points), -1)
                    coef = np.linalg.lstsq(Phi, Y, rcond=None)[0]
                    scale = max(float(np.max(np.abs(Y))), 1e-300)
                    resid = max(resid, float(np.max(np.abs(Phi @ coef - Y))) / scale)
                    mats.append(coef.reshape((Phi.shape[1],) + arr.shape[1:]))
                else:
                    mats.append(arr.reshape(shape + arr.shape[1:]))
            egrid = EffectGrid(sp.grid_effect, [np.asarray(a, float) for a in sp.grid_axes],
                               *mats, mode=sp.grid_mode, log_axes=tuple(sp.log_axes),
                               fit_residual=resid)
        out[sp.name] = ModelFamily(fam, egrid)
    return out


def build_family(params: ModelParams, measures: BodyMeasures = REFERENCE,
                 effects: dict | None = None, base_parameters=(), workers: int | None = None,
                 progress=None) -> LinearFamily:
    """The linear family of the model with `effects` (no grid)."""
    spec = FamilySpec("model", dict(effects or {}))
    return build_families(params, [spec], measures, base_parameters, workers,
                          progress)["model"].family


def _effect_params(name: str):
    from .effects import EFFECTS

    return EFFECTS[name].params


# ---------------------------------------------------------------------------
# Frequency response
# ---------------------------------------------------------------------------


def _rc(R: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """Real @ complex through two real products (numpy has no BLAS path for
    mixed real-complex matmul: 15 ms instead of 0.1 ms at 30 x 86 x 86)."""
    return R @ Z.real + 1j * (R @ Z.imag)


_FACTORS: dict = {}


def _feedback_factor(Bw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bw = U Wr with U orthonormal of Bw's rank (its SVD).  Bw is the
    family's feedback input matrix, the same for every evaluation of a
    family: the factor is kept by content (half the time of a delayed
    candidate's fit went into this SVD)."""
    key = (Bw.shape, hashlib.blake2b(np.ascontiguousarray(Bw).tobytes(), digest_size=16)
           .digest())
    out = _FACTORS.get(key)
    if out is None:
        Uf, sv, Vt = np.linalg.svd(Bw, full_matrices=False)
        r = int(np.sum(sv > 1e-9 * sv[0])) if len(sv) and sv[0] > 0 else 0
        out = (Uf[:, :r], sv[:r, None] * Vt[:r])
        if len(_FACTORS) > 64:
            _FACTORS.clear()
        _FACTORS[key] = out
    return out


def response(A, Bu, Bw, C, K, h: float, freqs_hz, inputs, delay_steps: float = 0,
             rows=None) -> np.ndarray:
    """H(z) = C (zI - A - z^-d Bw K)^-1 Bu[:, inputs] at z = exp(j 2 pi f h):
    array (nf, ny, len(inputs)), per m/s^2 of seat acceleration.  A
    fractional d is a pure delay of d h seconds, exp(-j 2 pi f d h)."""
    f = np.asarray(freqs_hz, float)
    z = np.exp(2j * np.pi * f * h)
    Cr = C if rows is None else C[rows]
    Bj = Bu[:, inputs]
    if delay_steps == 0:
        lam, V = np.linalg.eig(A + Bw @ K)
        W = np.linalg.solve(V, Bj.astype(complex))
        G = 1.0 / (z[:, None] - lam[None, :])
        return (_rc(Cr, V)[None, :, :] * G[:, None, :]) @ W
    # Woodbury about the open loop (zI - A)^-1 = V diag(g) V^-1, with the
    # feedback Bw K = U W of the controllers' rank (PID + head-in-space
    # torques: 27 for 62 feedback signals).
    U, Wr = _feedback_factor(Bw)
    Wf = Wr @ K
    lam, V = np.linalg.eig(A)
    Vi = np.linalg.inv(V)
    G = 1.0 / (z[:, None] - lam[None, :])  # (nf, n)
    CV, WV = _rc(Cr, V), _rc(Wf, V)
    ViB = Vi @ Bj.astype(complex)
    ViU = Vi @ U.astype(complex)
    c = np.exp(-2j * np.pi * f * h * delay_steps)  # (nf,)
    GB = G[:, :, None] * ViB[None]  # (nf, n, m): V^-1 M^-1 Bu
    GU = G[:, :, None] * ViU[None]  # (nf, n, r)
    S = np.eye(U.shape[1])[None] - c[:, None, None] * (WV[None] @ GU)  # (nf, r, r)
    X = np.linalg.solve(S, WV[None] @ GB)  # (nf, r, m)
    return CV[None] @ (GB + c[:, None, None] * (GU @ X))


def seat_displacement_per_acceleration(freqs_hz, h: float) -> np.ndarray:
    """The simulation's discrete double integration of the seat motion."""
    z = np.exp(2j * np.pi * np.asarray(freqs_hz, float) * h)
    return h**2 * z / (z - 1.0) ** 2


def to_transmissibility(H_channels: np.ndarray, freqs_hz, h: float, directions: str):
    """Channel responses per m/s^2 (nf, 30, ndir) -> transmissibility (m/m,
    deg/m; absolute translations) as in `LinearModel.transmissibility_array`."""
    from ...analysis.linear import _ROT_MASK
    from ...systems.outputs import CHANNEL_NAMES

    T = H_channels / seat_displacement_per_acceleration(freqs_hz, h)[:, None, None]
    for j, d in enumerate(directions):
        T[:, CHANNEL_NAMES.index(f"pelvis_{d}")::6, j] += 1.0
    T[:, _ROT_MASK, :] *= 180.0 / np.pi
    return T


def linearize_cut(params: ModelParams, measures: BodyMeasures = REFERENCE,
                  effects: dict | None = None) -> CutLinearization:
    """The cut-open linearization of the model with `effects` (no delay) at
    its static equilibrium."""
    cut, cctx, cmap = _prepare(params, measures, dict(effects or {}))
    return _linearize_cut(cut, cctx, cmap)


def static_penetrations(params: ModelParams, measures: BodyMeasures = REFERENCE,
                        effects: dict | None = None) -> np.ndarray:
    """Static penetration of every restraint point (m) at the equilibrium
    of the model with `effects`."""
    cut, cctx, cmap = _prepare(params, measures, dict(effects or {}))
    restraints = cut.systems["shear_restraints"]
    rctx = restraints.GetMyContextFromRoot(cctx)
    face = np.array([p.face_offset for p in restraints.points])
    return face - restraints.normal_displacement(rctx)
