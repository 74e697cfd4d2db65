"""The per-step laws of `LumpedHuman` compiled (`ehm_drake.jit`, numba).

`LumpedHuman._evaluate` computes, from the bodies' poses and velocities,
the contact forces (Hunt-Crossley normal law, foam hardening, the tissue's
Jenkins elements, the elasto-plastic bristles), the forces and torques per
body at its mass centre with the seat's inertial load, the joint torques
and the signals the controller feeds back: about sixty NumPy operations on
arrays of a dozen contacts and seventeen joints, which cost far more in
NumPy's per-call overhead than in arithmetic (about 80% of this reality's
step was Python).  `laws` evaluates the same formulas, contact by contact
and joint by joint in the NumPy law's order, in one compiled call.  The
NumPy law (`LumpedHuman._laws_numpy`) stays the reference and the
fallback without numba; the two agree to rounding (their small matrix
products sum in different orders; tests/test_reality_lumped.py compares
them at disturbed states to 1e-12).  No fast-math.

Packed inputs (built once per run by `pack`): a contact table of floats,
one of indices, the body, joint and scalar tables; see `pack`.
"""

from __future__ import annotations

import math

import numpy as np

from ...jit import kernel, maximum, minimum

#: Columns of the contact table (`pack`).
_PB, _NB, _OB = 0, 3, 6
(_ON, _K, _N, _C, _FOAM, _KT0, _MU, _SK, _SC, _JK, _JX, _SEATED) = range(9, 21)
_NCOL = 21
#: Entries of the scalar table.
(_H, _STICK, _INV_SLIDE, _HARDENING, _JENKINS, _MOVING, _STIFF_ANGLE) = range(7)


def pack(system) -> tuple:
    """The constant inputs of `laws` for `system` (a `LumpedHuman`) with its
    per-run settings (hardening, Jenkins elements, seated depths) as they
    are now."""
    s = system.spec
    nc = len(s.c_body)
    C = np.zeros((nc, _NCOL))
    C[:, _PB:_PB + 3], C[:, _NB:_NB + 3], C[:, _OB:_OB + 3] = s.c_pB, s.c_nB, s.c_oB
    C[:, _ON], C[:, _K], C[:, _N], C[:, _C] = s.c_oN, s.c_k, s.c_n, s.c_c
    C[:, _FOAM], C[:, _KT0], C[:, _MU] = s.c_foam, s.c_kt0, s.c_mu
    C[:, _SK], C[:, _SC] = s.c_sk, s.c_sc
    C[:, _JK], C[:, _JX] = system.jenkins_k, system.jenkins_x
    C[:, _SEATED] = system.seated_depth
    CI = np.ascontiguousarray(np.stack([s.c_body, s.c_sup], axis=1).astype(np.int64))
    B = np.ascontiguousarray(np.concatenate([s.com_B, s.mass[:, None]], axis=1))
    A = np.ascontiguousarray(np.stack([s.A_net, s.A_body, s.A_sup]))
    Jf = np.ascontiguousarray(np.stack([s.q0, s.nz, s.k_pass]))
    Ji = np.ascontiguousarray(np.stack([s.dof_q, s.dof_v]).astype(np.int64))
    Sf = np.ascontiguousarray(np.stack([s.spring_k, s.spring_rest]).astype(float))
    Si = np.ascontiguousarray(np.stack([s.spring_q, s.spring_v]).astype(np.int64))
    lay = s.layout
    # Offsets into the discrete state: z (3 per contact), Jenkins, activation, tonic.
    off = np.array([lay.z.start, lay.jenkins.start, lay.act.start, lay.tonic.start,
                    s.head_kin, s.nq, s.nv], np.int64)
    sc = np.array([s.h, s.stick_fraction, s.inv_slide, system.hardening,
                   1.0 if system.jenkins else 0.0, 1.0 if s.moving_supports else 0.0,
                   s.stiffening_angle])
    return (C, CI, B, A, Jf, Ji, Sf, Si, np.ascontiguousarray(s.head_R0), off, sc)


def _laws(R, p, w, vv, x, xd, a_seat, C, CI, B, A, Jf, Ji, Sf, Si, head_R0, off, sc):
    """`LumpedHuman._laws_numpy`'s laws after the kinematics: returns
    (tau, T, F, z_next, ej_next, y, f, depth, fn, P); see the module
    docstring."""
    nc = C.shape[0]
    nk = B.shape[0]
    nd = Ji.shape[1]
    z0, j0, a0, t0, head, nq, nv = off[0], off[1], off[2], off[3], off[4], off[5], off[6]
    h, stick, inv_slide = sc[_H], sc[_STICK], sc[_INV_SLIDE]
    hardening, jenkins, moving = sc[_HARDENING], sc[_JENKINS] != 0.0, sc[_MOVING] != 0.0
    P = np.empty((nc, 3))
    f = np.empty((nc, 3))
    depth = np.empty(nc)
    fn_out = np.empty(nc)
    z_next = np.empty((nc, 3))
    ej_next = np.zeros(nc)
    N = np.empty(3)
    rc = np.empty(3)
    Vr = np.empty(3)
    z = np.empty(3)
    vt = np.empty(3)
    zdot = np.empty(3)
    ft = np.empty(3)
    for i in range(nc):
        b = CI[i, 0]
        for r in range(3):
            rc[r] = R[b, r, 0] * C[i, _PB] + R[b, r, 1] * C[i, _PB + 1] \
                + R[b, r, 2] * C[i, _PB + 2]
        for r in range(3):
            P[i, r] = p[b, r] + rc[r]
        for r in range(3):
            r1, r2 = (r + 1) % 3, (r + 2) % 3
            Vr[r] = vv[b, r] + (w[b, r1] * rc[r2] - w[b, r2] * rc[r1])
        for r in range(3):
            z[r] = xd[z0 + 3 * i + r]
        if moving:
            sb = CI[i, 1]
            for r in range(3):
                N[r] = R[sb, r, 0] * C[i, _NB] + R[sb, r, 1] * C[i, _NB + 1] \
                    + R[sb, r, 2] * C[i, _NB + 2]
            dep = 0.0
            for r in range(3):
                o = R[sb, r, 0] * C[i, _OB] + R[sb, r, 1] * C[i, _OB + 1] \
                    + R[sb, r, 2] * C[i, _OB + 2]
                dep += (p[sb, r] + o - P[i, r]) * N[r]
            depth[i] = dep
            for r in range(3):
                r1, r2 = (r + 1) % 3, (r + 2) % 3
                d1 = P[i, r1] - p[sb, r1]
                d2 = P[i, r2] - p[sb, r2]
                Vr[r] = Vr[r] - vv[sb, r] - (w[sb, r1] * d2 - w[sb, r2] * d1)
            zN = z[0] * N[0] + z[1] * N[1] + z[2] * N[2]
            for r in range(3):
                z[r] = z[r] - zN * N[r]
        else:
            for r in range(3):
                N[r] = C[i, _NB + r]
            depth[i] = C[i, _ON] - (P[i, 0] * N[0] + P[i, 1] * N[1] + P[i, 2] * N[2])
        vn = Vr[0] * N[0] + Vr[1] * N[1] + Vr[2] * N[2]
        d = maximum(depth[i], 0.0)
        fn = C[i, _K] * d ** C[i, _N] * maximum(1.0 - 1.5 * C[i, _C] * vn, 0.0)
        if hardening != 0.0:
            fn = fn + C[i, _FOAM] * C[i, _KT0] * hardening * (d - C[i, _SEATED]) ** 3.0 / 3.0
        if jenkins:
            ej = xd[j0 + i]
            fn = fn + C[i, _JK] * (ej - (d - C[i, _SEATED]))
            ej_next[i] = minimum(maximum(ej - h * vn, -C[i, _JX]), C[i, _JX]) if depth[i] > 0.0 \
                else 0.0
        fn = maximum(fn, 0.0)
        fn_out[i] = fn
        for r in range(3):
            vt[r] = Vr[r] - vn * N[r]
        limit = C[i, _MU] * fn
        zss = limit / C[i, _SK]
        zn = math.sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2])
        zc = minimum(zn, zss)
        scale = zc / maximum(zn, 1e-300)
        for r in range(3):
            z[r] = z[r] * scale
        inv_zss = 1.0 / maximum(zss, 1e-12)
        alpha = minimum(maximum((zc * inv_zss - stick) * inv_slide, 0.0), 1.0)
        if z[0] * vt[0] + z[1] * vt[1] + z[2] * vt[2] <= 0.0:
            alpha = 0.0
        gain = alpha * math.sqrt(vt[0] * vt[0] + vt[1] * vt[1] + vt[2] * vt[2]) * inv_zss
        for r in range(3):
            zdot[r] = vt[r] - gain * z[r]
            ft[r] = -(C[i, _SK] * z[r] + C[i, _SC] * zdot[r])
        ftn = math.sqrt(ft[0] * ft[0] + ft[1] * ft[1] + ft[2] * ft[2])
        scale = minimum(ftn, limit) / maximum(ftn, 1e-300)
        for r in range(3):
            f[i, r] = fn * N[r] + ft[r] * scale
        den = 1.0 + h * gain
        for r in range(3):
            z_next[i, r] = (z[r] + h * vt[r]) / den
        zn = math.sqrt(z_next[i, 0] * z_next[i, 0] + z_next[i, 1] * z_next[i, 1]
                       + z_next[i, 2] * z_next[i, 2])
        scale = minimum(zn, zss) / maximum(zn, 1e-300)
        for r in range(3):
            z_next[i, r] = z_next[i, r] * scale
    # Forces per body at its mass centre, the inertial load -m a.
    com = np.empty((nk, 3))
    for k in range(nk):
        for r in range(3):
            com[k, r] = p[k, r] + (R[k, r, 0] * B[k, 0] + R[k, r, 1] * B[k, 1]
                                   + R[k, r, 2] * B[k, 2])
    F = np.zeros((nk, 3))
    T = np.zeros((nk, 3))
    arm = np.empty(3)
    for k in range(nk):
        for r in range(3):
            acc = 0.0
            for i in range(nc):
                acc += A[0, k, i] * f[i, r]
            F[k, r] = acc - B[k, 3] * a_seat[r]
    for m in range(1, 3 if moving else 2):
        sign = 1.0 if m == 1 else -1.0
        for i in range(nc):
            # (the contact's body, or support, mass centre: a selection)
            for r in range(3):
                acc = 0.0
                for k in range(nk):
                    acc += A[m, k, i] * com[k, r]
                arm[r] = P[i, r] - acc
            for k in range(nk):
                a = A[m, k, i]
                if a != 0.0:
                    for r in range(3):
                        r1, r2 = (r + 1) % 3, (r + 2) % 3
                        T[k, r] += sign * a * (arm[r1] * f[i, r2] - arm[r2] * f[i, r1])
    # Joint torques: elastic with a neutral zone and exponential stiffening,
    # the activation and the tonic torque; the linear springs.
    tau = np.zeros(nv)
    sa = sc[_STIFF_ANGLE]
    for j in range(nd):
        dq = x[Ji[0, j]] - Jf[0, j]
        ex = minimum(maximum((abs(dq) - Jf[1, j]) / sa, 0.0), 6.0)
        sgn = 1.0 if dq > 0.0 else (-1.0 if dq < 0.0 else 0.0)
        tau_el = -Jf[2, j] * (dq + sgn * sa * (math.expm1(ex) - ex))
        tau[Ji[1, j]] = tau_el + xd[a0 + j] + xd[t0 + j]
    for j in range(Si.shape[1]):
        tau[Si[1, j]] -= Sf[0, j] * (x[Si[0, j]] - Sf[1, j])
    # Head in space: the small-angle error of R_WH R0^T and the head's rate.
    Rh = np.empty((3, 3))
    for r in range(3):
        for c in range(3):
            Rh[r, c] = R[head, r, 0] * head_R0[c, 0] + R[head, r, 1] * head_R0[c, 1] \
                + R[head, r, 2] * head_R0[c, 2]
    y = np.empty(2 * nd + 6)
    for j in range(nd):
        y[j] = x[Ji[0, j]]
        y[nd + j] = x[nq + Ji[1, j]]
    y[2 * nd] = 0.5 * (Rh[2, 1] - Rh[1, 2])
    y[2 * nd + 1] = 0.5 * (Rh[0, 2] - Rh[2, 0])
    y[2 * nd + 2] = 0.5 * (Rh[1, 0] - Rh[0, 1])
    for r in range(3):
        y[2 * nd + 3 + r] = w[head, r]
    return tau, T, F, z_next, ej_next, y, f, depth, fn_out, P


laws = kernel(_laws)

__all__ = ["laws", "pack"]
