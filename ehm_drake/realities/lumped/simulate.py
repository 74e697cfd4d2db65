"""Settle and vibrate the `lumped` reality (prepare / run), and turn its
logged marker poses into the lab's 30 channels."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from pydrake.systems.analysis import Simulator

from .. import CHANNEL_NAMES, SEGMENTS, RealityError, RealityRecord
from .plant import GRAVITY, SUPPORTS, build

#: Settling: the tonic (postural) torque adapts for SETTLE_ADAPT_S, then is
#: frozen and the body comes to rest for SETTLE_REST_S more.
SETTLE_ADAPT_S = 3.0
SETTLE_REST_S = 1.5


@dataclass
class Prepared:
    """Everything the tests of one subject share (picklable)."""

    values: dict
    effects: dict
    h: float
    x_plant: np.ndarray
    x_human: np.ndarray
    seated_depth: np.ndarray
    marker_p: np.ndarray  # (5, 3) settled marker positions in S
    marker_R: np.ndarray  # (5, 3, 3) settled orientations
    summary: dict = field(default_factory=dict)


def _contexts(built, x_plant=None, x_human=None):
    sim = Simulator(built.diagram)
    root = sim.get_mutable_context()
    pc = built.plant.GetMyContextFromRoot(root)
    sc = built.system.GetMyContextFromRoot(root)
    if x_plant is not None:
        built.plant.SetPositionsAndVelocities(pc, x_plant)
    if x_human is not None:
        sc.SetDiscreteState(x_human)
    return sim, root, pc, sc


def _advance(sim, t_end: float, who: str) -> None:
    try:
        sim.AdvanceTo(t_end)
    except RealityError:
        raise
    except Exception as exc:  # a solver failure: report when and what
        t = sim.get_context().get_time()
        raise RealityError(f"lumped: {who} failed at t = {t:.3f} s: {exc}") from exc


def _settled_markers(built, sc):
    """Marker positions and orientations at the system context's state."""
    s = built.system
    s.invalidate()
    out = s._evaluate(sc)
    spec = built.spec
    mk = spec.marker_kin
    R = s._R[mk].copy()
    p = s._p[mk] + (R @ spec.marker_B[:, :, None])[:, :, 0]
    return out, p, R


def prepare(values: dict, effects: dict, h: float) -> Prepared:
    """Seat the subject: drop into the seat with the tonic torque adapting,
    then freeze it and let the body come to rest."""
    built = build(values, effects, h)
    sim, root, pc, sc = _contexts(built)
    system = built.system
    system.adapt_tonic = True
    sim.Initialize()
    _advance(sim, SETTLE_ADAPT_S, "settling")
    system.adapt_tonic = False
    system.invalidate()
    _advance(sim, SETTLE_ADAPT_S + SETTLE_REST_S, "settling")
    x_plant = built.plant.GetPositionsAndVelocities(pc).copy()
    x_human = sc.get_discrete_state_vector().CopyToVector()
    out, p, R = _settled_markers(built, sc)
    spec = built.spec
    weight = built.plan.total_mass * GRAVITY
    support = spec.A_support @ out["f"]
    nv = built.plant.num_velocities()
    summary = {
        "weight_N": weight,
        "support_force_N": {n: support[i].tolist() for i, n in enumerate(SUPPORTS)},
        "vertical_balance": float(support[:, 2].sum() / weight),
        "contact_normal_N": dict(zip(spec.c_names, out["fn"].round(2).tolist(), strict=True)),
        "max_joint_deviation_deg": float(np.degrees(np.abs(x_plant[spec.dof_q]).max())),
        "joint_angles_deg": dict(zip(spec.dof_names,
                                     np.degrees(x_plant[spec.dof_q]).round(3).tolist(),
                                     strict=True)),
        "pelvis_shift_m": (x_plant[spec.pelvis_xyz] - spec.pelvis_xyz0).tolist(),
        "max_speed": float(np.abs(x_plant[-nv:]).max()),
        "mass_kg": built.plan.total_mass,
        "dof": nv,
    }
    return Prepared(dict(values), dict(effects), h, x_plant, x_human,
                    np.maximum(out["depth"], 0.0), p, R, summary)


def _rpy(M):
    """Roll, pitch, yaw (x-y-z extrinsic) of rotation matrices (..., 3, 3)."""
    roll = np.arctan2(M[..., 2, 1], M[..., 2, 2])
    pitch = np.arcsin(np.clip(-M[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(M[..., 1, 0], M[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


@dataclass
class RunOutput:
    t: np.ndarray
    channels: np.ndarray  # (n, 30) m and deg
    support: np.ndarray  # (n, 3 supports, 3) force of each seat part on the body, N
    wall_s: float
    positions: tuple | None = None  # (names, (n, nq) array)


def run(prep: Prepared, signal, positions: bool = False) -> RunOutput:
    """Play the whole seat signal from the settled state (`positions`: also
    return the plant's generalized positions, with their names)."""
    if abs(signal.time_step - prep.h) > 1e-12:
        raise RealityError(f"lumped: the seat signal's time step is {signal.time_step:g} s; "
                           f"this reality runs at {prep.h:g} s")
    built = build(prep.values, prep.effects, prep.h)
    spec, system = built.spec, built.system
    x_human = prep.x_human.copy()
    if "cocontraction" in prep.effects:
        # The subject has adapted to the level: the running mean square
        # starts at the signal's over its full-amplitude part.
        k0 = signal.sample_index(signal.steady_start)
        steady = signal.acceleration[k0:]
        x_human[spec.layout.ms] = float(np.mean(np.sum(steady**2, axis=1))) if len(steady) \
            else 0.0
    sim, root, pc, sc = _contexts(built, prep.x_plant, x_human)
    hard = prep.effects.get("seat_foam_stiffening", {}).get("hardening_per_mm2", 0.0)
    if hard > 0:
        d = prep.seated_depth
        spec.c_kt0 = 1.5 * spec.c_k * np.sqrt(d)  # Hunt-Crossley tangent at the seated depth
        system.seated_depth = d
        system.hardening = hard * 1e6  # per mm^2 -> per m^2
    # Tissue friction (Jenkins elements under the pelvis and thighs), relaxed
    # at the seated state: a share of the tissue's Hunt-Crossley tangent
    # stiffness there is frictional (stuck: the tissue as stiff as its
    # elastic law; slipping beyond +-x_J: softer); the softening effect adds
    # to the share and narrows the stick range.
    soft = prep.effects.get("softening", {})
    share = prep.values["tissue_friction_share"] + soft.get("extra_friction_share", 0.0)
    if not 0.0 <= share < 1.0:
        raise RealityError(f"lumped: the tissue's friction share must be in [0, 1), got "
                           f"{share:.3g} (tissue_friction_share + softening)")
    if share > 0:
        d = prep.seated_depth
        kt = spec.c_jenkins * spec.c_n * spec.c_k * d ** (spec.c_n - 1.0)
        system.jenkins_k = share * kt
        system.jenkins_x = spec.c_jenkins * prep.values["tissue_friction_slip"] \
            * soft.get("slip_factor", 1.0)
        system.seated_depth = d
        system.jenkins = True
    system.seat_acc = signal.acceleration
    n = signal.num_samples
    system.start_log(n, positions)
    t0 = time.perf_counter()
    sim.Initialize()
    _advance(sim, signal.duration, "vibration")
    system.invalidate()
    system._evaluate(sc)  # log the final sample
    wall = time.perf_counter() - t0
    log = system.log
    if np.isnan(log["p"]).any():
        k = int(np.argwhere(np.isnan(log["p"]).any(axis=(1, 2)))[0, 0])
        raise RealityError(f"lumped: no record at t = {k * prep.h:.3f} s")
    trans = log["p"] - prep.marker_p[None] + signal.displacement[:, None, :]
    rel = log["R"] @ np.swapaxes(prep.marker_R, -1, -2)[None]
    rot = np.degrees(_rpy(rel))
    channels = np.concatenate([trans, rot], axis=2).reshape(n, 6 * len(SEGMENTS))
    q = None
    if positions:
        names = [str(x) for x in built.plant.GetPositionNames(False)]
        q = (names, log["q"])
    return RunOutput(signal.times, channels, log["support"], wall, q)


def record_from_output(reality, prep: Prepared, out: RunOutput, signal) -> RealityRecord:
    """The steady part (t >= signal.steady_start) of a run as a record."""
    k0 = signal.sample_index(signal.steady_start)
    channels = {name: out.channels[k0:, i].copy() for i, name in enumerate(CHANNEL_NAMES)}
    record = RealityRecord(
        t=out.t[k0:].copy(), seat_acc=signal.acceleration[k0:].copy(), channels=channels,
        real_time_factor=signal.duration / out.wall_s if out.wall_s > 0 else float("nan"),
        meta={"reality": reality.name, "effects": sorted(prep.effects)})
    record.check(f"reality {reality.name}")
    return record
