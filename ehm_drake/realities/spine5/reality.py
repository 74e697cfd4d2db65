"""`spine5`: the `Reality` interface over the model, statics and simulation."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydrake.systems.analysis import Simulator

from .. import CHANNEL_NAMES, DOFS, Reality, RealityError, RealityRecord
from . import params as P
from .effects import effect_values, validate_effects
from .forces import build_diagram
from .model import MARKER_SEGMENTS, TIME_STEP, Spine5Diverged, Spine5Model
from .statics import Spine5StaticsError, solve_statics

SOURCES = (
    "Dempster W.T. (1955) WADC-TR-55-159, segment parameters as in Winter D.A. (2009) "
    "Biomechanics and Motor Control of Human Movement, Table 4.1",
    "Pearsall D.J., Reid J.G., Livingston L.A. (1996) Ann. Biomed. Eng. 24:198-210 "
    "(trunk mass per vertebral level, CT)",
    "Beier G. et al. (1980) Center of gravity and moments of inertia of human heads",
    "Gordon C.C. et al. (1989) 1988 Anthropometric Survey of U.S. Army Personnel (ANSUR)",
    "Drillis R., Contini R. (1966) segment length proportions",
    "Hanavan E.P. (1964) AMRL-TR-64-102 (segments as uniform solids)",
    "Panjabi M.M. et al. (1976, 1991, 1994), Oxland T.R. et al. (1992): spinal flexibility",
    "McGill S.M. et al. (1994) Passive stiffness of the lumbar torso, Spine 19:696",
    "Vasavada A.N., Li S., Delp S.L. (2001) neck muscle moment capacity; "
    "Anderson D.E. et al. (2007) maximum joint torques",
    "Winters J.M., Stark L. (1985); Zajac F.E. (1989): activation dynamics",
    "Zedka M. et al. (1998); Cholewicki J. et al. (2000): trunk reflex latencies",
    "Peng G.C.Y., Hain T.C., Peterson B.W. (1996) head-neck control model",
    "Wei L., Griffin M.J. (1998) J. Sound Vib. 212:855 (seated apparent-mass models)",
)


@dataclass
class Spine5Prepared:
    """A settled subject (picklable)."""

    values: dict
    effects: dict
    x: np.ndarray
    xd: np.ndarray
    q_ref: np.ndarray
    a_ff: np.ndarray
    R_head_ref: np.ndarray
    cushion_load: float
    offsets: np.ndarray  # seat surface offset per contact point
    hand_anchors: np.ndarray  # palm anchors on the thighs (arms effect)
    marker_p0: np.ndarray  # (5, 3)
    marker_R0: np.ndarray  # (5, 3, 3)
    summary: dict = field(default_factory=dict)


@dataclass
class Spine5Run:
    """A run with the extras a RealityRecord does not carry."""

    record: RealityRecord
    seat_forces: np.ndarray  # (n, 9): pan, back-rest, floor force on the body (S axes), N
    wall_s: float


def _rpy(R: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (rad) of rotation matrices (..., 3, 3), R = Rz Ry Rx."""
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    pitch = -np.arcsin(np.clip(R[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


def _subject_values(subject: dict) -> dict[str, float]:
    if not isinstance(subject, dict) or "values" not in subject:
        raise RealityError("spine5: a subject is the dict returned by subject(seed)")
    vals = subject["values"]
    missing = set(P.PARAMS) - set(vals)
    if missing:
        raise RealityError(f"spine5: subject lacks {', '.join(sorted(missing))}")
    return {k: float(vals[k]) for k in P.PARAMS}


class Spine5Reality(Reality):
    name = "spine5"
    description = ("3D seated human, five-body spine (pelvis, lumbar, lower and upper thorax, "
                   "cervical) + head and legs on Drake; standard-linear-solid joints, delayed "
                   "saturating muscle torques with vestibular neck control, distributed "
                   "viscoelastic stick-slip seat contact, non-inertial seat frame")
    sources = SOURCES
    time_step = TIME_STEP

    # -------------------------------------------------------------- subject
    def subject(self, seed: int) -> dict[str, Any]:
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise RealityError(f"spine5: seed must be a non-negative integer, got {seed!r}")
        factors = P.scatter_factors(int(seed))
        return {"reality": self.name, "seed": int(seed), "spread": P.SPREAD,
                "factors": factors, "values": P.subject_values(factors)}

    def nominal_subject(self) -> dict[str, Any]:
        """The unscattered subject (all factors 1)."""
        return {"reality": self.name, "seed": None, "spread": 0.0, "factors": {},
                "values": P.nominal_values()}

    def effect_values(self, name: str, strength: float) -> dict[str, float]:
        return effect_values(name, strength)

    def effect_names(self) -> tuple[str, ...]:
        from .effects import EFFECT_NAMES

        return EFFECT_NAMES

    # -------------------------------------------------------------- prepare
    def build(self, values: dict, effects: dict) -> Spine5Model:
        return Spine5Model(values, effects)

    def prepare(self, subject: dict[str, Any], effects: dict[str, dict[str, float]]):
        values = _subject_values(subject)
        effects = validate_effects(effects)
        model = self.build(values, effects)
        build_diagram(model)
        forces = model.forces
        try:
            st = solve_statics(model, forces)
            frac = effects.get("backrest_separation", {}).get("preload_fraction", 1.0)
            if frac < 1.0:
                fitted = st.summary
                st = solve_statics(model, forces, frac * fitted["back_force_n"][0],
                                   st.offsets)
                st.summary["unloaded_compression_mm"] = fitted["unloaded_compression_mm"]
                st.summary["base_back_force_n"] = fitted["back_force_n"]
        except Spine5StaticsError as e:
            raise RealityError(str(e)) from None
        forces.kinematics(st.x)
        R_head = forces.R[forces.i_head].copy()
        p0 = forces.markers()
        summary = dict(st.summary)
        summary["effects"] = sorted(effects)
        return Spine5Prepared(values, effects, st.x, st.xd, st.q_ref, st.a_ff, R_head,
                              st.cushion_load, st.offsets, st.hand_anchors, p0, forces.R.copy(),
                              summary)

    # -------------------------------------------------------------- run
    def simulate(self, prepared: Spine5Prepared, signal, record_from: float | None = None
                 ) -> Spine5Run:
        """Play `signal` from its start; record from `record_from` (default:
        the steady part)."""
        if not isinstance(prepared, Spine5Prepared):
            raise RealityError("spine5: run_test needs the result of prepare()")
        h = self.time_step
        if abs(signal.time_step - h) > 1e-12:
            raise RealityError(f"spine5: the signal's time step is {signal.time_step:g} s; "
                               f"this reality runs at {h:g} s")
        t_rec = signal.steady_start if record_from is None else record_from
        n = signal.num_samples
        k0 = min(max(int(round(t_rec / h)), 0), n - 1)
        n_rec = n - k0
        model = self.build(prepared.values, prepared.effects)
        diagram = build_diagram(model)
        forces = model.forces
        sim = Simulator(diagram)
        ctx = sim.get_mutable_context()
        pc = model.plant.GetMyMutableContextFromRoot(ctx)
        model.plant.SetPositionsAndVelocities(pc, prepared.x)
        if "cushion" in model.body.segments:
            model.set_cushion_preload(forces, prepared.cushion_load)
        xd = prepared.xd.copy()
        if "cocontraction" in prepared.effects:
            # Adapted to the level of the steady part when it starts.
            ks = int(round(signal.steady_start / h))
            steady = signal.acceleration[ks:]
            xd[forces.layout["ms"]] = float(np.mean(np.sum(steady**2, axis=1))) \
                if len(steady) else 0.0
        forces.set_offsets(prepared.offsets)
        forces.set_hand_anchors(prepared.hand_anchors)
        forces.GetMyMutableContextFromRoot(ctx).SetDiscreteState(xd)
        forces.configure(prepared.q_ref, prepared.a_ff, prepared.R_head_ref,
                         signal.acceleration, k0, n_rec, signal.steady_start)
        sim.Initialize()
        t0 = time.perf_counter()
        try:
            # One step past the last sample, so its state is recorded too.
            sim.AdvanceTo((n - 1) * h + 0.5 * h)
        except Spine5Diverged as e:
            raise RealityError(str(e)) from None
        except RuntimeError as e:
            raise RealityError(f"spine5 diverged near t = {ctx.get_time():.3f} s: {e}") from None
        wall = time.perf_counter() - t0
        pose, frc = forces.rec_pose, forces.rec_force
        t = np.arange(k0, n) * h
        P_m = pose[:, :15].reshape(-1, 5, 3)
        R_m = pose[:, 15:].reshape(-1, 5, 3, 3)
        disp = signal.displacement[k0:]
        channels = {}
        for i, seg in enumerate(MARKER_SEGMENTS):
            tr = P_m[:, i] - prepared.marker_p0[i] + disp
            rot = np.degrees(_rpy(R_m[:, i] @ prepared.marker_R0[i].T))
            for j, dof in enumerate(DOFS[:3]):
                channels[f"{seg}_{dof}"] = tr[:, j].copy()
            for j, dof in enumerate(DOFS[3:]):
                channels[f"{seg}_{dof}"] = rot[:, j].copy()
        rtf = signal.duration / wall if wall > 0 else math.inf
        rec = RealityRecord(t, signal.acceleration[k0:].copy(),
                            {c: channels[c] for c in CHANNEL_NAMES}, rtf,
                            {"reality": self.name, "wall_s": wall,
                             "effects": sorted(prepared.effects)})
        rec.check(self.name)
        return Spine5Run(rec, frc.copy(), wall)

    def run_test(self, prepared: Spine5Prepared, signal) -> RealityRecord:
        return self.simulate(prepared, signal).record
