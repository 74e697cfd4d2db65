"""The one LeafSystem of the `lumped` reality: seat contact, joint laws,
neuromuscular control and the seat's inertial load.

Input ``state`` (the plant's [q; v]); outputs ``generalized_force`` (nv) and
``spatial_forces`` (a list of ExternallyAppliedSpatialForce, one per body
with mass, applied at its mass centre).  Everything is computed once per
time step in `_evaluate` and shared by both outputs and the discrete
update: the bodies' kinematics from the plant, then the laws below in one
compiled call (`kernel.laws`, numba), or in NumPy over contacts and joint
DoFs without numba (`_laws_numpy`, the reference: the same to rounding).

Laws:

* Contact: Hunt-Crossley normal force F = k d^n (1 + 1.5 c d') at body
  points against support planes (pan, floor, back pads; a hand against its
  thigh; the pan on the cushion body), and an elasto-plastic bristle in
  shear (Dupont et al.): purely elastic below `stick_fraction` of the
  Coulomb limit mu F, sliding at it, a linear transition between.  The
  bristle deflections are discrete state.  Optional foam hardening
  + k_t H (d - d_s)^3 / 3 about each point's seated compression d_s.
  Tissue friction (the subject's own softening with vibration magnitude):
  a share of the tissue's tangent stiffness at the tuberosities and thighs
  is a Jenkins element, a spring k_J in series with a Coulomb slider that
  slips at k_J x_J, in place of as much of the elastic law about the seated
  compression d_s: normal force + k_J (e - (d - d_s)).  The spring's
  deflection e (discrete state, zero at the seated state) follows the
  compression while |e| < x_J and stays at +-x_J while the slider slips.
  Stuck at small compressions (the tissue as stiff as its elastic law),
  slipping at larger ones (up to k_J less stiffness, friction loss): the
  equivalent stiffness falls with amplitude.
* Joints: per revolute DoF an elastic torque with a neutral zone and
  exponential stiffening beyond it (viscous damping is the Drake joint's,
  implicit in the solver); linear springs on the viscera and cushion
  joints.
* Control: the active torque is an activation state a' = (e - a) / T_act
  driven by e = -Kp (q - q0) - Kd q' of the joint angles delayed by the
  neural delay (a shift register of the fed-back signals in the discrete
  state, so the system is time-invariant), plus on the neck a vestibular head-in-space term on the
  head's orientation and rate; a tonic torque (adapted only while the
  subject settles) holds the spine and neck; co-contraction scales Kp by
  (1 + c a_rms) with a running mean square of the seat acceleration.
* Seat motion: the plant's world is the seat frame, which translates with
  the seat; every body carries the inertial load -m a_seat at its mass
  centre.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.systems.framework import LeafSystem

from .. import RealityError
from .kernel import laws, pack

#: Joint angle (rad) and pelvis excursion (m) beyond which a run is deemed
#: to have diverged.
MAX_ANGLE = 1.2
MAX_EXCURSION = 0.25


_NEXT, _PREV = [1, 2, 0], [2, 0, 1]


def _cross(a, b):
    """Row-wise cross product of (n, 3) arrays: column i is a[i+1] b[i+2] -
    a[i+2] b[i+1], the same products as np.cross in four whole-array
    operations (np.cross, or three columns stacked, cost 2-3 times more for
    a few rows)."""
    return a[:, _NEXT] * b[:, _PREV] - a[:, _PREV] * b[:, _NEXT]


def _rot(R, x):
    """R[i] @ x[i] for (n, 3, 3) and (n, 3)."""
    return (R @ x[:, :, None])[:, :, 0]


def _dot(a, b):
    return (a * b).sum(axis=1)


class LumpedHuman(LeafSystem):
    """See the module docstring.  `spec` is the `plant.SystemSpec` of index
    arrays and coefficients made by `plant.build`."""

    def __init__(self, plant, spec):
        super().__init__()
        self._plant = plant
        self._ctx = plant.CreateDefaultContext()
        self.spec = s = spec
        self.h = s.h
        self._bodies = [plant.get_body(i) for i in s.kin_body_index]
        nk = len(self._bodies)
        # Kinematics buffers (the world is the extra last entry).
        self._R = np.zeros((nk + 1, 3, 3))
        self._R[nk] = np.eye(3)
        self._p = np.zeros((nk + 1, 3))
        self._w = np.zeros((nk + 1, 3))
        self._v = np.zeros((nk + 1, 3))
        self._X34 = np.zeros((nk, 3, 4))
        self._V6 = np.zeros((nk, 6))
        self._efs = []
        for i, com in zip(s.force_kin, s.com_B, strict=True):
            f = ExternallyAppliedSpatialForce()
            f.body_index = self._bodies[i].index()
            f.p_BoBq_B = com
            self._efs.append(f)
        self._nx = plant.num_positions() + plant.num_velocities()
        self._state_in = self.DeclareVectorInputPort("state", self._nx)
        self._n_act = len(s.dof_q)
        self._layout = s.layout
        self._dstate = self.DeclareDiscreteState(s.layout.size)
        self.DeclarePeriodicDiscreteUpdateEvent(s.h, 0.0, self._update)
        self.DeclareVectorOutputPort("generalized_force", plant.num_velocities(),
                                     self._calc_tau, {self.all_sources_ticket()})
        self.DeclareAbstractOutputPort(
            "spatial_forces", lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]),
            self._calc_forces, {self.all_sources_ticket()})
        # Per-run settings (set by the runner before simulating).
        self.seat_acc = None  # (N, 3) seat acceleration samples at h, or None
        self.adapt_tonic = False
        self.hardening = 0.0  # foam hardening H (1/m^2), on the foam contacts
        # Tissue friction (Jenkins elements): spring k_J (N/m) and slip
        # displacement x_J (m) per contact, zero where there is none; set
        # by the runner from the seated depths (`simulate.run`).
        self.jenkins_k = np.zeros(len(s.c_body))
        self.jenkins_x = np.zeros(len(s.c_body))
        self.jenkins = False
        self.seated_depth = np.zeros(len(s.c_body))
        self.log = None  # dict of preallocated arrays (see start_log)
        self._key = None
        self._out = None
        self._zero3 = np.zeros(3)
        self._packed = None  # (settings, `kernel.pack`'s constants), made when used

    # ------------------------------------------------------------------ run
    def start_log(self, n: int, positions: bool = False) -> None:
        """Record n samples of the markers' poses and the support forces
        (and, if asked, the plant's generalized positions)."""
        nm = len(self.spec.marker_kin)
        self.log = {"p": np.full((n, nm, 3), np.nan), "R": np.full((n, nm, 3, 3), np.nan),
                    "support": np.full((n, len(self.spec.support_names), 3), np.nan)}
        if positions:
            self.log["q"] = np.full((n, self.spec.nq), np.nan)

    def invalidate(self) -> None:
        """Forget the last evaluation and the packed constants (after a
        change of the per-run settings)."""
        self._key = None
        self._packed = None

    # ---------------------------------------------------------- computation
    def _evaluate(self, context):
        t = context.get_time()
        x = self._state_in.Eval(context)
        xd = context.get_discrete_state_vector().get_value()
        key = (t, x.tobytes(), xd.tobytes(), self.hardening, self.adapt_tonic, self.jenkins)
        if self._key == key:
            return self._out
        s = self.spec
        k = int(round(t / self.h))
        if not np.isfinite(x).all():
            raise RealityError(f"lumped: the state is not finite at t = {t:.3f} s "
                               "(the simulation diverged)")
        q = x[:s.nq]
        qa = q[s.dof_q]
        bad = np.abs(qa) > MAX_ANGLE
        if bad.any():
            j = int(np.argmax(bad))
            raise RealityError(f"lumped: joint {s.dof_names[j]} at {np.degrees(qa[j]):.0f} deg "
                               f"at t = {t:.3f} s (the simulation diverged)")
        dp = q[s.pelvis_xyz] - s.pelvis_xyz0
        exc = math.sqrt(dp @ dp)  # (np.linalg.norm's arithmetic, without its overhead)
        if exc > MAX_EXCURSION:
            raise RealityError(f"lumped: the pelvis moved {exc:.2f} m from its seat at "
                               f"t = {t:.3f} s (the simulation diverged)")
        plant, ctx = self._plant, self._ctx
        plant.SetPositionsAndVelocities(ctx, x)
        R, p, w, vv = self._R, self._p, self._w, self._v
        X34, V6 = self._X34, self._V6
        for i, b in enumerate(self._bodies):
            X34[i] = plant.EvalBodyPoseInWorld(ctx, b).GetAsMatrix34()
            V6[i] = plant.EvalBodySpatialVelocityInWorld(ctx, b).get_coeffs()
        R[:-1] = X34[:, :, :3]
        p[:-1] = X34[:, :, 3]
        w[:-1] = V6[:, :3]
        vv[:-1] = V6[:, 3:]
        a_seat = self._zero3
        if self.seat_acc is not None and k < len(self.seat_acc):
            a_seat = self.seat_acc[k]
        if laws is not None:
            # Packed again whenever a per-run setting is replaced (the pack
            # holds the objects it was made from, so none is reused unseen).
            settings = (self.hardening, self.jenkins, self.jenkins_k, self.jenkins_x,
                        self.seated_depth, s.c_kt0)
            packed = self._packed
            if packed is None or any(a is not b
                                     for a, b in zip(settings, packed[0], strict=True)):
                self._packed = (settings, pack(self))
            tau, T, F, z_next, ej_next, y, f, depth, fn, P = laws(R, p, w, vv, x, xd, a_seat,
                                                                  *self._packed[1])
            if not self.jenkins:
                ej_next = None
        else:
            tau, T, F, z_next, ej_next, y, f, depth, fn, P = self._laws_numpy(x, xd, a_seat)
        # ---- log
        if self.log is not None and k < len(self.log["p"]):
            mk = s.marker_kin
            self.log["p"][k] = p[mk] + _rot(R[mk], s.marker_B)
            self.log["R"][k] = R[mk]
            self.log["support"][k] = s.A_support @ f
            if "q" in self.log:
                self.log["q"][k] = q
        self._out = {"tau": tau, "T": T, "F": F, "z_next": z_next, "ej_next": ej_next, "y": y,
                     "a_seat": a_seat, "f": f, "depth": depth, "fn": fn, "P": P}
        self._key = key
        return self._out

    def _laws_numpy(self, x, xd, a_seat):
        """The laws after the kinematics (the bodies' poses and velocities
        in the buffers) in NumPy: (tau, T, F, z_next, ej_next, y, f, depth,
        fn, P).  The reference of the compiled `kernel.laws` and its
        fallback without numba."""
        s = self.spec
        q, v = x[:s.nq], x[s.nq:]
        qa = q[s.dof_q]
        R, p, w, vv = self._R, self._p, self._w, self._v
        # ---- contacts
        lay = self._layout
        cb = s.c_body
        rc = _rot(R[cb], s.c_pB)
        P = p[cb] + rc
        Vr = vv[cb] + _cross(w[cb], rc)
        z = xd[lay.z].reshape(-1, 3)
        if s.moving_supports:
            sb = s.c_sup
            Rs = R[sb]
            N = _rot(Rs, s.c_nB)
            depth = _dot(p[sb] + _rot(Rs, s.c_oB) - P, N)
            Vr = Vr - vv[sb] - _cross(w[sb], P - p[sb])
            z = z - _dot(z, N)[:, None] * N
        else:
            N = s.c_nB
            depth = s.c_oN - _dot(P, N)
        vn = _dot(Vr, N)
        d = np.maximum(depth, 0.0)
        fn = s.c_k * d ** s.c_n * np.maximum(1.0 - 1.5 * s.c_c * vn, 0.0)
        if self.hardening:
            fn = fn + s.c_foam * s.c_kt0 * self.hardening * (d - self.seated_depth) ** 3 / 3.0
        if self.jenkins:
            # Jenkins element in place of as much elastic stiffness about the
            # seated depth: k_J (e - (d - d_s)); the next deflection follows the
            # compression rate (-vn) inside the stick range +-x_J and
            # stays at its edge while the slider slips (relaxed when the
            # contact opens).
            ej = xd[lay.jenkins]
            fn = fn + self.jenkins_k * (ej - (d - self.seated_depth))
            ej_next = np.where(depth > 0.0, np.minimum(np.maximum(
                ej - self.h * vn, -self.jenkins_x), self.jenkins_x), 0.0)
        else:
            ej_next = None
        fn = np.maximum(fn, 0.0)
        vt = Vr - vn[:, None] * N
        # Elasto-plastic bristle (Dupont): z is the elastic shear deflection,
        # within zss = mu fn / k_shear; sliding sets in from stick_fraction.
        limit = s.c_mu * fn
        zss = limit / s.c_sk
        zn = np.sqrt(_dot(z, z))
        zc = np.minimum(zn, zss)
        z = z * (zc / np.maximum(zn, 1e-300))[:, None]
        inv_zss = 1.0 / np.maximum(zss, 1e-12)
        alpha = np.minimum(np.maximum((zc * inv_zss - s.stick_fraction) * s.inv_slide, 0.0),
                           1.0)  # (np.clip's result; np.clip costs several times more)
        alpha[_dot(z, vt) <= 0.0] = 0.0  # unloading is elastic
        gain = alpha * np.sqrt(_dot(vt, vt)) * inv_zss
        zdot = vt - gain[:, None] * z
        ft = -(s.c_sk[:, None] * z + s.c_sc[:, None] * zdot)
        ftn = np.sqrt(_dot(ft, ft))
        ft *= (np.minimum(ftn, limit) / np.maximum(ftn, 1e-300))[:, None]
        f = fn[:, None] * N + ft
        # Next bristle state (implicit in the sliding term), within mu N.
        z_next = (z + self.h * vt) / (1.0 + self.h * gain)[:, None]
        zn = np.sqrt(_dot(z_next, z_next))
        z_next *= (np.minimum(zn, zss) / np.maximum(zn, 1e-300))[:, None]
        # ---- forces per body (at its mass centre) incl. the inertial load
        com_W = p[:-1] + _rot(R[:-1], s.com_B)
        F = s.A_net @ f - np.outer(s.mass, a_seat)
        T = s.A_body @ _cross(P - s.A_body.T @ com_W, f)
        if s.moving_supports:
            T -= s.A_sup @ _cross(P - s.A_sup.T @ com_W, f)
        # ---- joint torques
        dq = qa - s.q0
        ex = (np.abs(dq) - s.nz) / s.stiffening_angle
        ex = np.minimum(np.maximum(ex, 0.0), 6.0)
        tau_el = -s.k_pass * (dq + np.sign(dq) * s.stiffening_angle * (np.expm1(ex) - ex))
        tau = np.zeros(s.nv)
        tau[s.dof_v] = tau_el + xd[lay.act] + xd[lay.tonic]
        if len(s.spring_q):
            tau[s.spring_v] -= s.spring_k * (q[s.spring_q] - s.spring_rest)
        # ---- head in space (vestibular input)
        Rh = R[s.head_kin] @ s.head_R0.T
        err = 0.5 * np.array([Rh[2, 1] - Rh[1, 2], Rh[0, 2] - Rh[2, 0], Rh[1, 0] - Rh[0, 1]])
        y = np.concatenate([qa, v[s.dof_v], err, w[s.head_kin]])
        return tau, T, F, z_next, ej_next, y, f, depth, fn, P

    def _calc_tau(self, context, output):
        output.SetFromVector(self._evaluate(context)["tau"])

    def _calc_forces(self, context, output):
        out = self._evaluate(context)
        TF = np.concatenate([out["T"], out["F"]], axis=1)  # one conversion per body
        for ef, tf in zip(self._efs, TF, strict=True):
            ef.F_Bq_W = SpatialForce(tf)
        output.set_value(self._efs)

    def _update(self, context, discrete_state):
        out = self._evaluate(context)
        s, lay = self.spec, self._layout
        xd = context.get_discrete_state_vector().get_value()
        xn = xd.copy()
        # The delay line holds [y(k-1), ..., y(k-D)] (a shift register).
        D = lay.depth
        buf = xd[lay.buf].reshape(D, -1)
        yd = buf[s.delay_steps - 1] if s.delay_steps > 0 else out["y"]
        nb = xn[lay.buf].reshape(D, -1)
        nb[1:] = buf[:-1]
        nb[0] = out["y"]
        na = self._n_act
        ms = xd[lay.ms][0]
        kp = s.kp * (1.0 + s.cocontraction * s.cc_mask * math.sqrt(max(ms, 0.0)))
        e = -kp * (yd[:na] - s.q0) - s.kd * yd[na:2 * na]
        e += s.vest_map @ (-s.kv * yd[2 * na:2 * na + 3] - s.dv * yd[2 * na + 3:])
        act = xd[lay.act]
        xn[lay.act] = act + (self.h / s.activation_time) * (e - act)
        if self.adapt_tonic:
            xn[lay.tonic] = xd[lay.tonic] - self.h * s.ki * (out["y"][:na] - s.q0)
        xn[lay.z] = out["z_next"].ravel()
        if out["ej_next"] is not None:
            xn[lay.jenkins] = out["ej_next"]
        a2 = float(out["a_seat"] @ out["a_seat"])
        xn[lay.ms] = ms + self.h / s.cc_tau * (a2 - ms)
        discrete_state.get_mutable_vector().SetFromVector(xn)


class StateLayout:
    """Slices of the LumpedHuman discrete state."""

    def __init__(self, n_act: int, n_y: int, depth: int, n_contacts: int):
        self.depth = depth
        i = 0

        def take(n):
            nonlocal i
            sl = slice(i, i + n)
            i += n
            return sl

        self.act = take(n_act)
        self.tonic = take(n_act)
        self.buf = take(depth * n_y)
        self.z = take(3 * n_contacts)
        self.ms = take(1)
        self.jenkins = take(n_contacts)
        self.size = i
        self.n_y = n_y

