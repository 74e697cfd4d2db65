"""Static equilibrium of the `spine5` subject on the seat.

The muscles hold every joint at its reference angle (their tone is the
feed-forward activation computed here), so at rest the body is one rigid
body on its contact springs.

1. The seat is fitted to the subject (`fit_seat`): the unloaded skin
   compressions of the four contact groups (pelvis grid, thigh grid, back
   pads, soles) are chosen so that the reference pose is in equilibrium with
   the tissue shear relaxed (the subject sat down into it) and the floor
   carrying `share_floor` of the body weight.  This is linear in the four
   compressions (fore-aft, vertical and pitch balance plus the floor share;
   the back-rest load follows from the fore-aft balance with the pan tilt).
2. `solve_statics` then solves the rigid-body equilibrium (pelvis pose,
   passive DoFs: visceral mass, cushion) by damped Newton; it stays at the
   reference unless an effect changes the balance.  With
   `backrest_separation` a trunk flexion offset (half at L5/S1, half at
   T12/L1) is solved too, so that the pads carry only their target force.
   Where the equilibrium needs more shear than mu N, the anchors slide
   (slip) and the solve is repeated.
3. The muscle feed-forward is the joint torque the rest of the body needs
   (inverse statics).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .body import G
from .forces import Spine5Forces
from .model import Spine5Model


class Spine5StaticsError(RuntimeError):
    """No static equilibrium (the subject cannot sit on this seat)."""


@dataclass
class Statics:
    x: np.ndarray  # plant state (v = 0)
    xd: np.ndarray  # force-system discrete state
    q_ref: np.ndarray  # joint reference angles (muscle set points)
    a_ff: np.ndarray  # feed-forward activations
    t_ff: np.ndarray  # feed-forward torques, N m
    cushion_load: float
    offsets: np.ndarray  # seat surface offset per contact point
    hand_anchors: np.ndarray  # palm anchors on the thighs (arms effect)
    summary: dict = field(default_factory=dict)


GROUPS = ("pelvis", "thigh", "back", "foot")


def fit_seat(model: Spine5Model, forces: Spine5Forces) -> tuple[np.ndarray, dict]:
    """Per-point surface offsets (compressions of the groups) that hold the
    reference pose with relaxed shear.  Returns (offsets, compressions mm)."""
    plant = model.plant
    ctx = plant.CreateDefaultContext()
    nq = model.nq
    x = np.concatenate([model.reference_positions(), np.zeros(nq)])
    forces.kinematics(x)
    # Unloaded skin points on the surface normal: offset = N . p + d.
    base = np.einsum("ni,ni->n", forces.N, forces.P)
    rows = model.iq_float
    anchors = forces.tangential_points(x)

    def wrench(d_groups):
        forces.set_offsets(base + sum(d * (forces.group == g) for g, d in
                                      zip(GROUPS, d_groups, strict=True)))
        tau, F, _, _, _ = forces.static_generalized_forces(x, anchors, ctx)
        return tau[rows], np.sum(F[forces.is_foot, 2])

    r0, b0 = wrench(np.zeros(4))
    cols, bcol = [], []
    for i in range(4):
        d = np.zeros(4)
        d[i] = 1e-3
        r, b = wrench(d)
        cols.append((r - r0) / 1e-3)
        bcol.append((b - b0) / 1e-3)
    A = np.vstack([np.column_stack(cols), bcol])
    weight = model.total_mass * G
    rhs = np.concatenate([-r0, [model.v["share_floor"] * weight - b0]])
    d = np.linalg.lstsq(A, rhs, rcond=None)[0]
    if np.any(d <= 0):
        raise Spine5StaticsError(
            "spine5: the seat cannot be fitted to this subject (unloaded-skin compressions "
            + ", ".join(f"{g} {x * 1e3:.2f} mm" for g, x in zip(GROUPS, d, strict=True)) + ")")
    off = base + sum(di * (forces.group == g) for g, di in zip(GROUPS, d, strict=True))
    forces.set_offsets(off)
    return off, {g: float(di * 1e3) for g, di in zip(GROUPS, d, strict=True)}


def _lumbar_rows(model: Spine5Model) -> np.ndarray:
    names = model.dofs.names
    return np.array([names.index("lumbar_y"), names.index("lower_thorax_y")])


def solve_statics(model: Spine5Model, forces: Spine5Forces, back_target: float | None = None,
                  offsets: np.ndarray | None = None, tol: float = 1e-9) -> Statics:
    """The settled subject on the seat `offsets` (default: fitted)."""
    plant = model.plant
    ctx = plant.CreateDefaultContext()
    nq = model.nq
    weight = model.total_mass * G
    if offsets is None:
        offsets, compressions = fit_seat(model, forces)
    else:
        forces.set_offsets(offsets)
        compressions = {}
    q0 = model.reference_positions()
    iq_unknown = np.concatenate([model.iq_float, model.iq_passive]).astype(int)
    rows = iq_unknown
    nu = len(iq_unknown)
    lumbar = _lumbar_rows(model)
    with_phi = back_target is not None
    cushion_load = 0.0

    # Anchors: the tangential points of the reference pose (relaxed shear).
    anchors = forces.tangential_points(np.concatenate([q0, np.zeros(nq)]))

    def state(u):
        q = q0.copy()
        q[iq_unknown] = u[:nu]
        if with_phi:
            q[model.dofs.iq[lumbar]] = 0.5 * u[nu]
        return np.concatenate([q, np.zeros(nq)])

    def residual(u, anchors):
        x = state(u)
        if forces.hands:
            forces.hand_anchors_from_state(x)
        tau, F, _, _, _ = forces.static_generalized_forces(x, anchors, ctx)
        r = tau[rows]
        if with_phi:
            r = np.append(r, np.sum(F[forces.is_back, 0]) - back_target)
        return r

    u = np.concatenate([q0[iq_unknown], [0.0] if with_phi else []])
    uscale = np.full(len(u), 0.005)  # translations 5 mm, rotations 0.01 rad
    uscale[:3] = 0.01
    if with_phi:
        uscale[nu] = 0.01

    def solve(u, anchors):
        return _newton(lambda uu: residual(uu, anchors), u, uscale, tol * weight)

    if "cushion" in model.body.segments:
        # The cushion carries the pan load at q = 0: rigid-pan load first.
        _, F, _, _, _ = forces.static_generalized_forces(state(u), anchors, ctx)
        cushion_load = float(np.sum(F[forces.is_pan, 2]))
        model.set_cushion_preload(forces, cushion_load)
    it = 0
    for _ in range(30):
        u, it = solve(u, anchors)
        _, _, new_anchor, _, slip = forces.static_generalized_forces(state(u), anchors, ctx)
        if not slip.any():
            break
        anchors = new_anchor.copy()
    res = residual(u, anchors)
    if not np.all(np.isfinite(res)) or np.max(np.abs(res)) > 1e-6 * weight:
        raise Spine5StaticsError(f"spine5: no static equilibrium found (residual "
                                 f"{np.max(np.abs(res)):.3g} after {it} Newton steps)")
    x = state(u)
    if forces.hands:
        forces.hand_anchors_from_state(x)
    tau, F, anchors_eq, dpen, slip = forces.static_generalized_forces(x, anchors, ctx)
    dofs = model.dofs
    t_ff = -tau[dofs.iv]
    ratio = t_ff / dofs.tmax
    if np.max(np.abs(ratio)) > 0.9:
        i = int(np.argmax(np.abs(ratio)))
        raise Spine5StaticsError(f"spine5: joint {dofs.labels[i]} needs {t_ff[i]:.1f} N m to "
                                 f"hold the posture, beyond 90 % of its maximum "
                                 f"{dofs.tmax[i]:.0f} N m")
    a_ff = np.arctanh(ratio)
    q_ref = x[:nq][dofs.iq].copy()
    lay = forces.layout
    xd = np.zeros(forces.nx)
    xd[lay["q_d"]] = q_ref
    xd[lay["act"]] = a_ff
    xd[lay["anchor"]] = anchors_eq.reshape(-1)
    xd[lay["dslow"]] = dpen
    Fpan, Fback, Ffoot = (F[m].sum(axis=0) for m in (forces.is_pan, forces.is_back,
                                                      forces.is_foot))
    if min(Fpan[2], Ffoot[2]) <= 0:
        raise Spine5StaticsError(f"spine5: the subject does not sit on pan and floor "
                                 f"(vertical pan {Fpan[2]:.0f} N, floor {Ffoot[2]:.0f} N)")
    pel = model.body.segments["pelvis"].origin
    summary = {
        "body_mass_kg": model.total_mass,
        "weight_n": weight,
        "pan_force_n": Fpan.tolist(),
        "back_force_n": Fback.tolist(),
        "floor_force_n": Ffoot.tolist(),
        "support_sum_z_n": float(Fpan[2] + Fback[2] + Ffoot[2]),
        "unloaded_compression_mm": compressions,
        "pelvis_shift_mm": ((x[model.iq_float[3:]] - pel) * 1e3).tolist(),
        "pelvis_rotation_deg": np.degrees(x[model.iq_float[:3]]).tolist(),
        "trunk_offset_deg": math.degrees(u[nu]) if with_phi else 0.0,
        "max_compression_mm": float(dpen.max() * 1e3),
        "points_in_contact": int(np.sum(dpen > 0)),
        "slipping_points": int(np.sum(slip)),
        "max_tone_fraction": float(np.max(np.abs(ratio))),
        "residual": float(np.max(np.abs(res))),
    }
    return Statics(x, xd, q_ref, a_ff, t_ff, cushion_load, offsets.copy(),
                   forces.hand_anchors(), summary)


def _newton(fun, u, uscale, tol, max_iter=60):
    """Damped Newton with finite-difference Jacobians: steps limited to two
    scale units (contacts open and close), backtracking on |r|."""
    u = np.array(u, float)
    r = fun(u)
    it = 0
    while it < max_iter and np.max(np.abs(r)) >= tol:
        it += 1
        n = len(u)
        J = np.empty((len(r), n))
        for i in range(n):
            du = np.zeros(n)
            du[i] = 1e-4 * uscale[i]
            J[:, i] = (fun(u + du) - fun(u - du)) / (2 * du[i])
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        big = np.max(np.abs(step) / uscale)
        if big > 2.0:
            step *= 2.0 / big
        norm0 = np.linalg.norm(r)
        r_new = r
        for _ in range(20):
            r_new = fun(u + step)
            if np.linalg.norm(r_new) < norm0:
                break
            step *= 0.5
        u = u + step
        r = r_new
    return u, it
