"""The force system of the spine5 reality: contact, passive joints, muscles and
inertial load of `Spine5Model` in one LeafSystem (see `model` for the laws)."""

from __future__ import annotations

import math

import numpy as np
from pydrake.multibody.tree import (
    JacobianWrtVariable,
    MultibodyForces,
)
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem

from . import kernel
from .model import (
    FOAM_MAX_FACTOR,
    MARKER_SEGMENTS,
    POSE_BODIES,
    Spine5Diverged,
    Spine5Model,
)


class Spine5Forces(LeafSystem):
    """Contact, passive joints, muscles and inertial load (see the module
    docstring).  Discrete state layout: see `layout`."""

    def __init__(self, model: Spine5Model):
        super().__init__()
        self.m = model
        plant = model.plant
        self.plant = plant
        self.h = model.h
        self.ctx = plant.CreateDefaultContext()
        self.nq, self.nv = model.nq, model.nv
        v = model.v
        ef = model.effects
        d = model.dofs
        self.nj = len(d.names)
        # Delay buffer: baseline + extra delay (whole steps).
        extra = ef.get("reflex_delay", {}).get("extra_delay_s", 0.0)
        self.delay_steps = max(1, int(round((v["delay"] + extra) / self.h)))
        self.L = self.delay_steps + 1
        self.ncol = 2 * self.nj + 6
        # Contact points, contiguous per body (blocks for the Drake calls).
        pts = model.body.points
        self.npts = len(pts)
        segs = model.body.segments
        surf = model.body.surfaces
        self.blocks = []
        i = 0
        while i < self.npts:
            j = i
            while j < self.npts and pts[j].body == pts[i].body:
                j += 1
            r = np.array([pts[k].p - segs[pts[i].body].origin for k in range(i, j)]).T
            self.blocks.append((plant.GetBodyByName(pts[i].body).body_frame(),
                                slice(i, j), slice(3 * i, 3 * j), r))
            i = j
        if len({p.body for p in pts}) != len(self.blocks):
            raise ValueError("contact points must be contiguous per body")
        self.N = np.array([surf[p.surface].normal for p in pts])
        self.off = np.array([surf[p.surface].offset for p in pts])
        ey = np.array([0.0, 1.0, 0.0])
        self.T1 = np.cross(ey, self.N)
        self.B = np.stack([self.N, self.T1, np.tile(ey, (self.npts, 1))], axis=1)
        self.BT = np.ascontiguousarray(np.transpose(self.B, (0, 2, 1)))
        self.group = np.array([p.group for p in pts])
        self.is_pan = (self.group == "pelvis") | (self.group == "thigh")
        self.is_back = self.group == "back"
        self.is_foot = self.group == "foot"
        kn = {"pelvis": v["k_pelvis"], "thigh": v["k_thigh"], "back": v["k_back"],
              "foot": v["k_foot"]}
        cn = {"pelvis": v["c_pelvis"], "thigh": v["c_thigh"], "back": v["c_back"],
              "foot": v["c_foot"]}
        self.kn = np.array([kn[g] for g in self.group])
        self.cn = np.array([cn[g] for g in self.group])
        self.kt = self.kn * v["shear_ratio"]
        self.ct = self.cn * v["shear_damping"]
        self.kt2 = self.kt[:, None]
        self.ct2 = self.ct[:, None]
        mu_seat = ef.get("seat_friction", {}).get("mu", v["mu_seat"])
        self.mu = np.where(self.is_foot, v["mu_floor"], mu_seat)
        foam = ef.get("seat_foam_stiffening", {})
        self.gamma = np.where(self.is_foot, 0.0, foam.get("gamma_per_mm2", 0.0) * 1e6)
        self.foam_alpha = self.h / foam.get("tau_slow_s", 1.5)
        # The seat tissue's short-range share: the subject's own plus the
        # softening effect's extra (not at the feet: shoe soles).
        s_soft = v["soft_fraction"] + ef.get("softening", {}).get(
            "extra_short_range_fraction", 0.0)
        if not 0.0 <= s_soft < 1.0:
            raise ValueError(f"spine5: the tissue's short-range share must be in [0, 1), got "
                             f"{s_soft:.3g} (soft_fraction + softening)")
        self.soft_s = np.where(self.is_foot, 0.0, s_soft)
        self.soft_dc = v["soft_range"]
        self.softening = bool(np.any(self.soft_s > 0))
        self.iq_cushion = (plant.GetJointByName("cushion_z").position_start()
                           if "cushion" in segs else None)
        self.k_cushion = ef.get("seat_cushion_dynamics", {}).get("stiffness", 0.0)
        self.cushion_z0 = 0.0
        cc = ef.get("cocontraction", {})
        self.c_cc = cc.get("c_per_ms2", 0.0)
        self.cc_alpha = self.h / cc.get("tau_s", 3.0)
        self.alpha_act = 1.0 - math.exp(-self.h / v["tau_act"])
        self.kp_vest, self.kd_vest = v["kp_vest"], v["kd_vest"]
        self.M_total = plant.CalcTotalMass(self.ctx)
        # Palm on thigh (arms effect): a 3D soft-tissue spring-damper between
        # the palm point of each forearm and its anchor on the thigh, with a
        # vertical preload (the thigh carries part of the forearm weight).
        # The anchors are where the palms rest in the settled posture
        # (statics: `hand_anchors_from_state`).
        self.hands = []
        if model.body.arms_separate:
            e = ef["arms"]
            self.k_hand = e["hand_k"]
            for side, (p_hand, share) in model.body.hand_points.items():
                m_fa = segs[f"forearm_{side}"].mass
                self.hands.append({
                    "fa": plant.GetBodyByName(f"forearm_{side}").body_frame(),
                    "th": plant.GetBodyByName(f"thigh_{side}").body_frame(),
                    "i_th": POSE_BODIES.index(f"thigh_{side}"),
                    "r_palm": (p_hand - segs[f"forearm_{side}"].origin).reshape(3, 1),
                    "r_anchor": (p_hand - segs[f"thigh_{side}"].origin).reshape(3, 1),
                    "F0": np.array([0.0, 0.0, share]),
                    "c": 2 * 0.3 * math.sqrt(self.k_hand * m_fa),
                    "P": np.zeros(3), "A": np.zeros(3),
                    "Jp": np.zeros((3, self.nv)), "Ja": np.zeros((3, self.nv))})
        # Marker bodies (POSE_BODIES, in MARKER_SEGMENTS order) and points.
        self.pose_bodies = [plant.GetBodyByName(n) for n in POSE_BODIES]
        assert [model.body.markers[s][0] for s in MARKER_SEGMENTS] == list(POSE_BODIES)
        self.marker_r = np.array([model.body.markers[s][1]
                                  - segs[model.body.markers[s][0]].origin
                                  for s in MARKER_SEGMENTS])
        self.i_head = POSE_BODIES.index("head")
        self.head = plant.GetBodyByName("head")
        # Per-step work arrays (no allocation in the hot path beyond numpy
        # temporaries).
        self.R = np.zeros((len(POSE_BODIES), 3, 3))
        self.p = np.zeros((len(POSE_BODIES), 3))
        self.P = np.zeros((self.npts, 3))
        self.Jp = np.zeros((3 * self.npts, self.nv))
        self.floc = np.zeros((self.npts, 3))
        self.W = plant.world_frame()
        # Settled-state data (set by `configure`).
        self.q_ref = np.zeros(self.nj)
        self.a_ff = np.zeros(self.nj)
        self.R_head_ref = np.eye(3)
        self.accel = np.zeros((1, 3))
        self.t_cc_start = 0.0
        self.k0 = 0
        self.n_rec = 0
        self.rec_pose = np.zeros((0, 60))
        self.rec_force = np.zeros((0, 9))
        self.check_limits = True
        self.pelvis0 = model.body.segments["pelvis"].origin.copy()
        # Layout of the discrete state.
        sizes = [("q_d", self.nj), ("act", self.nj), ("buf", self.L * self.ncol),
                 ("anchor", 2 * self.npts), ("dslow", self.npts), ("ms", 1)]
        self.layout, o = {}, 0
        for name, n in sizes:
            self.layout[name] = slice(o, o + n)
            o += n
        self.nx = o
        self.DeclareVectorInputPort("plant_state", BasicVector(self.nq + self.nv))
        self.DeclareVectorOutputPort("generalized_force", BasicVector(self.nv), self._calc_tau)
        self.DeclareDiscreteState(self.nx)
        # An unrestricted update, like the discrete plant's own step: both are
        # computed from the same pre-step context.
        self.DeclarePeriodicUnrestrictedUpdateEvent(self.h, 0.0, self._update)
        self._memo_t = None
        self._memo_x = None
        self._memo = None
        self._packed = None  # (settings, `kernel.pack`'s tables), made when used
        self._packed_muscles = None  # (q_ref, a_ff, `kernel.pack_muscles`' tables)

    # ------------------------------------------------------------ utilities
    def set_offsets(self, off):
        """Seat surface offset per contact point (plane N . p = off)."""
        self.off = np.asarray(off, float).copy()

    def configure(self, q_ref, a_ff, R_head_ref, accel=None, k0=0, n_rec=0,
                  t_cc_start=0.0):
        self.q_ref = np.asarray(q_ref, float).copy()
        self.a_ff = np.asarray(a_ff, float).copy()
        self.R_head_ref = np.asarray(R_head_ref, float).copy()
        self.accel = np.zeros((1, 3)) if accel is None else np.asarray(accel, float)
        self.k0, self.n_rec = int(k0), int(n_rec)
        self.t_cc_start = float(t_cc_start)
        self.rec_pose = np.zeros((self.n_rec, 60))
        self.rec_force = np.zeros((self.n_rec, 9))
        self._memo_t = None

    def kinematics(self, x):
        """Contact points (positions, Jacobians) and marker-body poses at
        plant state x."""
        plant, ctx = self.plant, self.ctx
        plant.SetPositionsAndVelocities(ctx, x)
        kV, W = JacobianWrtVariable.kV, self.W
        for frame, sl, sl3, r in self.blocks:
            self.P[sl] = plant.CalcPointsPositions(ctx, frame, r, W).T
            self.Jp[sl3] = plant.CalcJacobianTranslationalVelocity(ctx, kV, frame, r, W, W)
        for i, b in enumerate(self.pose_bodies):
            X = plant.EvalBodyPoseInWorld(ctx, b)
            self.R[i] = X.rotation().matrix()
            self.p[i] = X.translation()
        for hd in self.hands:
            hd["P"] = plant.CalcPointsPositions(ctx, hd["fa"], hd["r_palm"], W)[:, 0]
            hd["A"] = plant.CalcPointsPositions(ctx, hd["th"], hd["r_anchor"], W)[:, 0]
            hd["Jp"] = plant.CalcJacobianTranslationalVelocity(ctx, kV, hd["fa"], hd["r_palm"],
                                                               W, W)
            hd["Ja"] = plant.CalcJacobianTranslationalVelocity(ctx, kV, hd["th"],
                                                               hd["r_anchor"], W, W)

    def hand_anchors_from_state(self, x):
        """Put the palm anchors where the palms are at plant state x (the
        spring then carries only its preload there)."""
        self.kinematics(x)
        for hd in self.hands:
            i = hd["i_th"]
            hd["r_anchor"] = (self.R[i].T @ (hd["P"] - self.p[i])).reshape(3, 1)
        self.kinematics(x)

    def hand_anchors(self):
        return np.array([hd["r_anchor"][:, 0] for hd in self.hands]).reshape(-1)

    def set_hand_anchors(self, anchors):
        for hd, a in zip(self.hands, np.asarray(anchors).reshape(-1, 3), strict=True):
            hd["r_anchor"] = np.array(a, float).reshape(3, 1)

    def hand_forces(self, v):
        """Generalized forces of the palm-thigh springs (kinematics evaluated)."""
        tau = np.zeros(self.nv)
        for hd in self.hands:
            F = self.k_hand * (hd["A"] - hd["P"]) + hd["c"] * ((hd["Ja"] - hd["Jp"]) @ v) \
                + hd["F0"]
            tau += hd["Jp"].T @ F - hd["Ja"].T @ F
        return tau

    def markers(self):
        """Marker positions (5, 3) of the evaluated kinematics."""
        return self.p + np.matmul(self.R, self.marker_r[:, :, None])[:, :, 0]

    def contact(self, x, anchors, dslow):
        """Contact forces at plant state x (kinematics already evaluated);
        `dslow` None: at rest (no dynamic foam compression).  Returns (tau,
        F per point (n,3), new anchors (n,2), d (n,), slipping mask).  The
        compiled law (`kernel.contact`) where numba is, else the NumPy one."""
        if kernel.contact is None:
            return self._contact_numpy(x, anchors, dslow)
        # Packed again whenever a setting is replaced (the offsets by
        # `set_offsets`, the cushion's rest position by the statics).
        settings = (self.off, self.cushion_z0)
        packed = self._packed
        if packed is None or packed[0][0] is not self.off or packed[0][1] != self.cushion_z0:
            packed = self._packed = (settings, kernel.pack(self))
        dynamic = dslow is not None
        return kernel.contact(np.ascontiguousarray(x), self.P, self.Jp,
                              np.ascontiguousarray(anchors),
                              np.ascontiguousarray(dslow) if dynamic else self.off, dynamic,
                              *packed[1])

    def _contact_numpy(self, x, anchors, dslow):
        """`contact`'s NumPy law: the reference of the compiled one and its
        fallback without numba."""
        nq = self.nq
        q, v = x[:nq], x[nq:]
        P = self.P
        Vp = (self.Jp @ v).reshape(-1, 3)
        off = self.off
        if self.iq_cushion is not None:
            zc, vc = q[self.iq_cushion], v[self.iq_cushion]
            off = off + self.is_pan * self.N[:, 2] * zc
            Vp[:, 2] -= self.is_pan * vc
        Q = np.matmul(self.B, P[:, :, None])[:, :, 0]  # normal, tangential (2)
        Qd = np.matmul(self.B, Vp[:, :, None])[:, :, 0]
        d = off - Q[:, 0]
        inside = d > 0
        if dslow is None:
            Fn = self.kn * d - self.cn * Qd[:, 0]
        else:
            # Foam stiffening with the dynamic compression: tangent factor
            # 1 + 3 gamma dyn^2 for small dyn, saturating at FOAM_MAX_FACTOR.
            dyn = d - dslow
            g2 = self.gamma * dyn * dyn
            Fn = self.kn * (d + dyn * g2 / (1.0 + g2 / (FOAM_MAX_FACTOR - 1.0))) \
                - self.cn * Qd[:, 0]
            if self.softening:
                # The short-range part of the tissue's stiffness saturates:
                # tangent kn (1 - s tanh^2(dyn / dc)) about the slow mean.
                dc = self.soft_dc
                Fn = Fn - self.kn * self.soft_s * (dyn - dc * np.tanh(dyn / dc))
        Fn = np.where(inside, np.maximum(Fn, 0.0), 0.0)
        Pt = Q[:, 1:]
        fs = self.kt2 * (anchors - Pt)
        lim = self.mu * Fn
        nfs = np.hypot(fs[:, 0], fs[:, 1])
        slip = nfs > lim
        fs *= np.where(slip, lim / np.maximum(nfs, 1e-300), 1.0)[:, None]
        new_anchor = np.where(inside[:, None], Pt + fs / self.kt2, Pt)
        ft = fs - np.where(slip[:, None], 0.0, self.ct2 * Qd[:, 1:])
        nft = np.hypot(ft[:, 0], ft[:, 1])
        ft *= np.minimum(1.0, lim / np.maximum(nft, 1e-300))[:, None]
        floc = self.floc
        floc[:, 0] = Fn
        floc[:, 1:] = ft
        F = np.matmul(self.BT, floc[:, :, None])[:, :, 0]
        tau = self.Jp.T @ F.reshape(-1)
        if self.iq_cushion is not None:
            tau[self.iq_cushion] -= float(np.sum(F[self.is_pan, 2])) \
                + self.k_cushion * (q[self.iq_cushion] - self.cushion_z0)
        return tau, F, new_anchor, d, slip

    def tangential_points(self, x):
        """The points' tangential coordinates at plant state x (anchors of
        relaxed shear)."""
        self.kinematics(x)
        return np.matmul(self.B, self.P[:, :, None])[:, 1:, 0]

    def head_signals(self):
        """Head-in-space rotation (small-angle vector, S axes) from the
        settled head orientation, and angular velocity."""
        Rr = self.R[self.i_head] @ self.R_head_ref.T
        phi = 0.5 * np.array([Rr[2, 1] - Rr[1, 2], Rr[0, 2] - Rr[2, 0], Rr[1, 0] - Rr[0, 1]])
        w = self.plant.EvalBodySpatialVelocityInWorld(self.ctx, self.head).rotational()
        return phi, w

    def passive_torque(self, th, q_d):
        d = self.m.dofs
        return -d.k_par * th - d.k_mx * (th - q_d)

    # ------------------------------------------------------------ the step
    def _evaluate(self, context):
        t = context.get_time()
        x = self.get_input_port(0).Eval(context)
        if self._memo_t == t and np.array_equal(x, self._memo_x):
            return self._memo
        xd = context.get_discrete_state_vector().get_value()
        out = self._compute(t, x, xd)
        self._memo_t, self._memo_x, self._memo = t, x.copy(), out
        return out

    def _compute(self, t, x, xd):
        lay = self.layout
        d = self.m.dofs
        nq = self.nq
        q, v = x[:nq], x[nq:]
        k = int(round(t / self.h))
        if self.check_limits:
            self._check(t, q, v)
        self.kinematics(x)
        anchors = xd[lay["anchor"]].reshape(-1, 2)
        dslow = xd[lay["dslow"]]
        tau, F, new_anchor, dpen, _ = self.contact(x, anchors, dslow)
        if self.hands:
            tau += self.hand_forces(v)
        # Inertial load of the seat acceleration.
        a_s = self.accel[min(k, len(self.accel) - 1)]
        if a_s.any():
            Jc = self.plant.CalcJacobianCenterOfMassTranslationalVelocity(
                self.ctx, JacobianWrtVariable.kV, self.W, self.W)
            tau -= self.M_total * (Jc.T @ a_s)
        phi, w = self.head_signals()
        cc_on = t >= self.t_cc_start - 0.5 * self.h
        if kernel.muscles is None:
            T, xn = self._muscles_numpy(k, x, xd, a_s, phi, w, dpen, new_anchor, cc_on)
        else:
            packed = self._packed_muscles  # (again when `configure` replaced a setting)
            if packed is None or packed[0] is not self.q_ref or packed[1] is not self.a_ff:
                packed = self._packed_muscles = (self.q_ref, self.a_ff,
                                                 kernel.pack_muscles(self))
            T, xn = kernel.muscles(k, np.ascontiguousarray(x), np.ascontiguousarray(xd),
                                   np.ascontiguousarray(a_s), phi, np.ascontiguousarray(w), dpen,
                                   new_anchor, cc_on, *packed[2])
        tau[d.iv] += T
        return tau, xn, F, k

    def _muscles_numpy(self, k, x, xd, a_s, phi, w, dpen, new_anchor, cc_on):
        """The joints' passive and muscle torques T (per DoF) and the next
        discrete state (Maxwell states, activations, the delay line's new
        row, anchors, the foam's slow compression, the running mean square
        of the seat acceleration): the NumPy law, reference of the compiled
        `kernel.muscles` and its fallback without numba."""
        lay = self.layout
        d = self.m.dofs
        q, v = x[:self.nq], x[self.nq:]
        th = q[d.iq]
        thd = v[d.iv]
        q_d = xd[lay["q_d"]]
        act = xd[lay["act"]]
        buf = xd[lay["buf"]].reshape(self.L, self.ncol)
        ms = xd[lay["ms"]][0]
        dslow = xd[lay["dslow"]]
        gain = 1.0 + self.c_cc * math.sqrt(max(ms, 0.0)) * d.cc_mask
        # Muscle torque: saturating, of the activation and the intrinsic
        # (instantaneous) stiffness.
        T = self.passive_torque(th, q_d) + d.tmax * np.tanh(
            act - gain * d.ki * (th - self.q_ref) / d.tmax)
        # Delayed proprioceptive and vestibular signals -> next activation.
        delayed = buf[(k - self.delay_steps) % self.L]
        nj = self.nj
        e, ed, ph, wh = delayed[:nj], delayed[nj:2 * nj], delayed[-6:-3], delayed[-3:]
        u = -(d.kp * e + d.kd * ed) * gain
        u[self.m.vest_rows] -= 0.5 * (self.kp_vest * ph[self.m.vest_cols]
                                      + self.kd_vest * wh[self.m.vest_cols])
        a_next = act + self.alpha_act * (self.a_ff + u / d.tmax - act)
        xn = xd.copy()
        xn[lay["q_d"]] = th + (q_d - th) * d.decay
        xn[lay["act"]] = a_next
        bn = xn[lay["buf"]].reshape(self.L, self.ncol)
        row = bn[k % self.L]
        row[:nj] = th - self.q_ref
        row[nj:2 * nj] = thd
        row[-6:-3] = phi
        row[-3:] = w
        xn[lay["anchor"]] = new_anchor.reshape(-1)
        inside = dpen > 0
        xn[lay["dslow"]] = np.where(inside, dslow + self.foam_alpha * (dpen - dslow), dpen)
        if cc_on:
            xn[lay["ms"]] = ms + self.cc_alpha * (float(a_s @ a_s) - ms)
        return T, xn

    def _check(self, t, q, v):
        """Stop a run that left the physical range (cheap on the good path)."""
        d = self.m.dofs
        dq = np.abs(q[d.iq] - self.q_ref)
        dp = np.abs(q[self.m.iq_float[3:]] - self.pelvis0)
        av = np.abs(v)
        if dq.max() <= 1.0 and dp.max() <= 0.25 and av.max() <= 200.0:
            return  # (NaN fails the comparisons and falls through)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            i = int(np.argwhere(~np.isfinite(np.concatenate([q, v])))[0, 0]) % self.nq
            bad = f"state not finite (coordinate {self._coord_label(i)})"
        elif dq.max() > 1.0:
            i = int(np.argmax(dq))
            bad = f"joint {d.labels[i]} deflected {math.degrees(dq[i]):.0f} deg"
        elif dp.max() > 0.25:
            bad = f"pelvis moved {dp.max() * 100:.0f} cm relative to the seat"
        else:
            i = int(np.argmax(av))
            bad = f"velocity of {self._coord_label(i)} is {v[i]:.3g}"
        raise Spine5Diverged(f"spine5 diverged at t = {t:.3f} s: {bad}")

    def _coord_label(self, i):
        plant = self.plant
        for j in plant.GetJointIndices():
            joint = plant.get_joint(j)
            if joint.num_velocities() and joint.velocity_start() <= i < \
                    joint.velocity_start() + joint.num_velocities():
                return f"{joint.name()} (body {joint.child_body().name()})"
        return f"#{i}"

    def _calc_tau(self, context, output):
        output.SetFromVector(self._evaluate(context)[0])

    def _update(self, context, state):
        tau, xn, F, k = self._evaluate(context)
        state.get_mutable_discrete_state().get_mutable_vector().SetFromVector(xn)
        r = k - self.k0
        if 0 <= r < self.n_rec:
            row = self.rec_pose[r]
            row[:15] = self.markers().reshape(-1)
            row[15:] = self.R.reshape(-1)
            fr = self.rec_force[r]
            fr[0:3] = F[self.is_pan].sum(axis=0)
            fr[3:6] = F[self.is_back].sum(axis=0)
            fr[6:9] = F[self.is_foot].sum(axis=0)

    # ------------------------------------------------------------ statics
    def static_generalized_forces(self, x, anchors, plant_context):
        """Generalized forces at rest (v = 0) without the muscles: force
        elements (gravity, springs, bushings) + contact + passive joints
        (Maxwell branch relaxed).  Returns (tau, F, new anchors, d, slip)."""
        plant = self.plant
        self.kinematics(x)
        plant.SetPositionsAndVelocities(plant_context, x)
        forces = MultibodyForces(plant)
        plant.CalcForceElementsContribution(plant_context, forces)
        tau = plant.CalcGeneralizedForces(plant_context, forces)
        tc, F, an, dpen, slip = self.contact(x, anchors, None)
        tau = tau + tc
        if self.hands:
            tau += self.hand_forces(np.zeros(self.nv))
        th = x[:self.nq][self.m.dofs.iq]
        tau[self.m.dofs.iv] += self.passive_torque(th, th)
        return tau, F, an, dpen, slip


def build_diagram(model: Spine5Model):
    """The plant of `model` with its force system in a diagram;
    `model.forces` is then the force system."""
    builder = DiagramBuilder()
    builder.AddSystem(model.plant)
    forces = builder.AddSystem(Spine5Forces(model))
    builder.Connect(model.plant.get_state_output_port(), forces.get_input_port(0))
    builder.Connect(forces.get_output_port(0),
                    model.plant.get_applied_generalized_force_input_port())
    model.forces = forces
    return builder.Build()
