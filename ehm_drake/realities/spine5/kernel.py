"""The contact and muscle laws of `Spine5Forces` compiled (`ehm_drake.jit`, numba).

`Spine5Forces.contact` turns the contact points' positions and Jacobians
into forces: the normal spring-damper with the foam's stiffening and the
tissue's short-range softening about the slow compression, the
elasto-plastic shear anchors within mu N, and the generalized forces J^T F;
about forty NumPy operations on arrays of a few dozen points, which cost
more in NumPy's per-call overhead than in arithmetic (a fifth of this
reality's step).  `contact` evaluates the same formulas point by point in the
NumPy law's order in one compiled call; `muscles` does the same for the
joints' passive and muscle torques and the next discrete state (Maxwell
states, activations, the delay line, anchors, the foam's slow compression).
The NumPy laws (`Spine5Forces._contact_numpy`, `Spine5Forces._muscles_numpy`)
stay the reference and the fallback without numba; the two agree to rounding
(the products J v and J^T F sum in another order, tanh may differ in its last
bit; tests/test_reality_spine5.py compares them to 1e-12).  No fast-math.

Packed inputs (built once per force system by `pack` and `pack_muscles`):
tables of floats and indices and the scalars; see those.
"""

from __future__ import annotations

import math

import numpy as np

from ...jit import kernel, maximum, minimum

#: Columns of the point table (`pack`): the basis rows (normal, two
#: tangents) of each point, its surface offset and normal's z, its laws.
_B = 0  # 9 entries, row-major
_OFF, _NZ, _PAN, _KN, _CN, _KT, _CT, _MU, _GAMMA, _SOFT = range(9, 19)
_NCOL = 19
#: Entries of the scalar table.
_DC, _FOAM_MAX, _SOFTENING, _IQ_CUSHION, _K_CUSHION, _Z0_CUSHION, _NQ = range(7)


def pack(forces) -> tuple:
    """The constant inputs of `contact` for `forces` (a `Spine5Forces`) as
    its settings are now (offsets, cushion rest position)."""
    from .model import FOAM_MAX_FACTOR

    n = forces.npts
    T = np.zeros((n, _NCOL))
    T[:, _B:_B + 9] = forces.B.reshape(n, 9)
    T[:, _OFF], T[:, _NZ] = forces.off, forces.N[:, 2]
    T[:, _PAN] = forces.is_pan
    T[:, _KN], T[:, _CN], T[:, _KT], T[:, _CT] = forces.kn, forces.cn, forces.kt, forces.ct
    T[:, _MU], T[:, _GAMMA], T[:, _SOFT] = forces.mu, forces.gamma, forces.soft_s
    iq = -1 if forces.iq_cushion is None else forces.iq_cushion
    sc = np.array([forces.soft_dc, FOAM_MAX_FACTOR, 1.0 if forces.softening else 0.0,
                   float(iq), forces.k_cushion, forces.cushion_z0, float(forces.nq)])
    return (np.ascontiguousarray(T), sc)


def _contact(x, P, Jp, anchors, dslow, dynamic, T, sc):
    """`Spine5Forces._contact_numpy`'s law: returns (tau, F (n, 3), new
    anchors (n, 2), d (n,), slipping (n,)); `dynamic` False: at rest (no
    dynamic foam compression, `dslow` unused)."""
    n = P.shape[0]
    nq = int(sc[_NQ])
    nv = Jp.shape[1]
    iq = int(sc[_IQ_CUSHION])
    dc = sc[_DC]
    fmax1 = sc[_FOAM_MAX] - 1.0
    softening = sc[_SOFTENING] != 0.0
    zc = 0.0
    vc = 0.0
    if iq >= 0:
        zc = x[iq]
        vc = x[nq + iq]
    F = np.empty((n, 3))
    new_anchor = np.empty((n, 2))
    d_out = np.empty(n)
    slip_out = np.empty(n, np.bool_)
    Vp = np.empty(3)
    Q = np.empty(3)
    Qd = np.empty(3)
    for i in range(n):
        # The point's velocity J v (the cushion's own motion taken off).
        for r in range(3):
            s = 0.0
            row = 3 * i + r
            for k in range(nv):
                s += Jp[row, k] * x[nq + k]
            Vp[r] = s
        off = T[i, _OFF]
        if iq >= 0:
            off = off + T[i, _PAN] * T[i, _NZ] * zc
            Vp[2] -= T[i, _PAN] * vc
        for r in range(3):
            Q[r] = T[i, 3 * r] * P[i, 0] + T[i, 3 * r + 1] * P[i, 1] + T[i, 3 * r + 2] * P[i, 2]
            Qd[r] = T[i, 3 * r] * Vp[0] + T[i, 3 * r + 1] * Vp[1] + T[i, 3 * r + 2] * Vp[2]
        d = off - Q[0]
        kn = T[i, _KN]
        if not dynamic:
            fn = kn * d - T[i, _CN] * Qd[0]
        else:
            dyn = d - dslow[i]
            g2 = T[i, _GAMMA] * dyn * dyn
            fn = kn * (d + dyn * g2 / (1.0 + g2 / fmax1)) - T[i, _CN] * Qd[0]
            if softening:
                fn = fn - kn * T[i, _SOFT] * (dyn - dc * math.tanh(dyn / dc))
        inside = d > 0
        fn = maximum(fn, 0.0) if inside else 0.0
        kt = T[i, _KT]
        fs0 = kt * (anchors[i, 0] - Q[1])
        fs1 = kt * (anchors[i, 1] - Q[2])
        lim = T[i, _MU] * fn
        nfs = math.hypot(fs0, fs1)
        slip = nfs > lim
        if slip:
            g = lim / maximum(nfs, 1e-300)
            fs0 *= g
            fs1 *= g
        if inside:
            new_anchor[i, 0] = Q[1] + fs0 / kt
            new_anchor[i, 1] = Q[2] + fs1 / kt
        else:
            new_anchor[i, 0] = Q[1]
            new_anchor[i, 1] = Q[2]
        ft0, ft1 = fs0, fs1  # a slipping point's shear damping is off
        if not slip:
            ft0 = fs0 - T[i, _CT] * Qd[1]
            ft1 = fs1 - T[i, _CT] * Qd[2]
        nft = math.hypot(ft0, ft1)
        g = minimum(1.0, lim / maximum(nft, 1e-300))
        ft0 *= g
        ft1 *= g
        # F = B^T (fn, ft0, ft1).
        for c in range(3):
            F[i, c] = T[i, c] * fn + T[i, 3 + c] * ft0 + T[i, 6 + c] * ft1
        d_out[i] = d
        slip_out[i] = slip
    tau = np.zeros(nv)
    for k in range(nv):
        s = 0.0
        for i in range(n):
            for r in range(3):
                s += Jp[3 * i + r, k] * F[i, r]
        tau[k] = s
    if iq >= 0:
        pan = 0.0
        for i in range(n):
            if T[i, _PAN] != 0.0:
                pan += F[i, 2]
        tau[iq] -= pan + sc[_K_CUSHION] * (x[iq] - sc[_Z0_CUSHION])
    return tau, F, new_anchor, d_out, slip_out


contact = kernel(_contact)

#: Rows of the joint table (`pack_muscles`).
(_QREF, _AFF, _KPAR, _KMX, _TMAX, _KI, _KP, _KD, _CCMASK, _DECAY) = range(10)
#: Entries of the muscles' integer table: state offsets, then sizes.
(_O_QD, _O_ACT, _O_BUF, _O_ANCHOR, _O_DSLOW, _O_MS, _M_NQ, _M_DELAY, _M_L, _M_NCOL,
 _M_NPTS) = range(11)
#: Entries of the muscles' scalars.
_C_CC, _ALPHA_ACT, _KP_VEST, _KD_VEST, _FOAM_ALPHA, _CC_ALPHA = range(6)


def pack_muscles(forces) -> tuple:
    """The constant inputs of `muscles` for `forces` (a `Spine5Forces`) as
    configured now (set points and feed-forward activations)."""
    d = forces.m.dofs
    J = np.ascontiguousarray(np.stack([forces.q_ref, forces.a_ff, d.k_par, d.k_mx, d.tmax,
                                       d.ki, d.kp, d.kd, d.cc_mask, d.decay]).astype(float))
    Ji = np.ascontiguousarray(np.stack([d.iq, d.iv]).astype(np.int64))
    Vi = np.ascontiguousarray(np.stack([forces.m.vest_rows, forces.m.vest_cols]).astype(np.int64))
    lay = forces.layout
    oi = np.array([lay["q_d"].start, lay["act"].start, lay["buf"].start, lay["anchor"].start,
                   lay["dslow"].start, lay["ms"].start, forces.nq, forces.delay_steps, forces.L,
                   forces.ncol, forces.npts], np.int64)
    sc = np.array([forces.c_cc, forces.alpha_act, forces.kp_vest, forces.kd_vest,
                   forces.foam_alpha, forces.cc_alpha])
    return (J, Ji, Vi, oi, sc)


def _muscles(k, x, xd, a_s, phi, w, dpen, new_anchor, cc_on, J, Ji, Vi, oi, sc):
    """`Spine5Forces._muscles_numpy`'s law: returns (T per joint DoF, the
    next discrete state); see the module docstring."""
    nj = J.shape[1]
    nq = oi[_M_NQ]
    L = oi[_M_L]
    ncol = oi[_M_NCOL]
    o_qd, o_act, o_buf = oi[_O_QD], oi[_O_ACT], oi[_O_BUF]
    ms = xd[oi[_O_MS]]
    cg = sc[_C_CC] * math.sqrt(0.0 if 0.0 > ms else ms)  # (Python's max(ms, 0.0))
    read = o_buf + ((k - oi[_M_DELAY]) % L) * ncol  # the delayed row
    T = np.empty(nj)
    u = np.empty(nj)
    for j in range(nj):
        th = x[Ji[0, j]]
        gain = 1.0 + cg * J[_CCMASK, j]
        tmax = J[_TMAX, j]
        passive = -J[_KPAR, j] * th - J[_KMX, j] * (th - xd[o_qd + j])
        T[j] = passive + tmax * math.tanh(xd[o_act + j]
                                          - gain * J[_KI, j] * (th - J[_QREF, j]) / tmax)
        u[j] = -(J[_KP, j] * xd[read + j] + J[_KD, j] * xd[read + nj + j]) * gain
    for r in range(Vi.shape[1]):
        c = Vi[1, r]
        u[Vi[0, r]] -= 0.5 * (sc[_KP_VEST] * xd[read + ncol - 6 + c]
                              + sc[_KD_VEST] * xd[read + ncol - 3 + c])
    xn = xd.copy()
    write = o_buf + (k % L) * ncol
    for j in range(nj):
        th = x[Ji[0, j]]
        act = xd[o_act + j]
        xn[o_act + j] = act + sc[_ALPHA_ACT] * (J[_AFF, j] + u[j] / J[_TMAX, j] - act)
        xn[o_qd + j] = th + (xd[o_qd + j] - th) * J[_DECAY, j]
        xn[write + j] = th - J[_QREF, j]
        xn[write + nj + j] = x[nq + Ji[1, j]]
    for r in range(3):
        xn[write + ncol - 6 + r] = phi[r]
        xn[write + ncol - 3 + r] = w[r]
    o_anchor, o_dslow = oi[_O_ANCHOR], oi[_O_DSLOW]
    for i in range(oi[_M_NPTS]):
        xn[o_anchor + 2 * i] = new_anchor[i, 0]
        xn[o_anchor + 2 * i + 1] = new_anchor[i, 1]
        dp = dpen[i]
        ds = xd[o_dslow + i]
        xn[o_dslow + i] = ds + sc[_FOAM_ALPHA] * (dp - ds) if dp > 0 else dp
    if cc_on:
        xn[oi[_O_MS]] = ms + sc[_CC_ALPHA] * ((a_s[0] * a_s[0] + a_s[1] * a_s[1]
                                                + a_s[2] * a_s[2]) - ms)
    return T, xn


muscles = kernel(_muscles)

__all__ = ["contact", "muscles", "pack", "pack_muscles"]
