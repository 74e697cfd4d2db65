"""The elementwise part of `ForceLaws`' step compiled with numba
(`ehm_drake.jit`): the NumPy expressions of
`ehm_drake.systems.forces.ForceLaws._elementwise_laws` (the contact dampers, the
restraints' limits, law and slip, the restraint constraints' force, the
PID and its integral, the passive joints) element by element in their
order, so that the numbers are the same bits
(tests/test_force_laws.py).  Used for float states with no separate
controller input, on both designs (the ball joints' cosines, sines and
tangents computed in NumPy); the products with the Jacobian and the
projections stay in NumPy, the kinematics in Drake.
"""

from __future__ import annotations

import numpy as np

from ..jit import available, kernel, maximum, minimum


def _cardan_to_generalized(tau, ball, trig):
    """`cardan_to_generalized` (N(q)^T on the ball joints) with its
    trigonometric terms given: `ball` (3 x nb: roll, pitch, yaw indices),
    `trig` (5 x nb: cos pitch, cos yaw, sin yaw, tan pitch, sin pitch)."""
    f = tau.copy()
    for b in range(ball.shape[1]):
        r, p, y = ball[0, b], ball[1, b], ball[2, b]
        cp, cy, sy, tp = trig[0, b], trig[1, b], trig[2, b], trig[3, b]
        u = tau[r] / cp + tau[y] * tp
        f[r] = cy * u - sy * tau[p]
        f[p] = sy * u + cy * tau[p]
    return f


if available():  # (called by the compiled kernel below: compiled too)
    _cardan_to_generalized = kernel(_cardan_to_generalized)


def _laws_kernel(x, PV, VV, V, n, slip, z, pos_n_contact, ball, trig, axis_prm, point_prm,
                 flags, constraint_prm, contact_prm, pid_prm, rot_q, rot_v_x, passive_prm,
                 q_index, v_x, period):
    """The elementwise part of `ForceLaws`' step on a float state with no
    separate controller input, compiled (`ehm_drake.jit`): the
    contact dampers (`contact_damping_force`), the restraints' limits, law
    and slip (`restraint_limits`, `restraint_law`, `slip_update`), the
    constraints' force at the step's start, the PID and its integral, the
    passive joints: the NumPy expressions of `_elementwise_laws` element by
    element, in their order (the same bits: tests/test_force_laws.py).
    The products with the Jacobian and the projections stay in NumPy.

    `ball`, `trig`: the ball joints' Cardan indices and their trigonometric
    terms (`_cardan_to_generalized`; none on Cardan chains);
    `axis_prm` (6 x 2n): k, c, force limit, mu, contact stiffness, k_safe;
    `point_prm` (6 x n): face, gated, k3, ref, k_lin, c_lin; `flags`:
    friction, gated, normal terms, constraints, contact dampers, implicit
    kp, implicit passive part, damping remainder, ball joints; `constraint_prm`
    (3 x 2n): stiffness, length, step damping; `contact_prm` (2 x n,
    grouped): damping, face; `pid_prm` (7 x n_rot): reference, -kp, -ki,
    -kd, bound, -bound, implicit kp; `passive_prm` (4 x n_rot + 1): -k,
    neutral, implicit part, damping.  Returns (w, slip_next, fd, pid_force,
    pid_torque, z_next, passive)."""
    n2, n3 = 2 * n, 3 * n
    friction, gated_any, normal_terms = flags[0] != 0, flags[1] != 0, flags[2] != 0
    constraints, dampers, implicit_kp = flags[3] != 0, flags[4] != 0, flags[5] != 0
    implicit, damping, balls = flags[6] != 0, flags[7] != 0, flags[8] != 0
    nc = n2 if constraints else 0
    w = np.empty(n3 + 3 * nc)
    slip_next = np.empty(n2)
    for i in range(n):
        pos_n = PV[n2 + i]
        face = point_prm[0, i]
        touching = (face - pos_n) > 0
        free = gated_any and point_prm[1, i] > 0.5 and not touching
        for a in range(2):
            j = 2 * i + a
            fm = axis_prm[2, j]
            if friction:
                fmu = axis_prm[3, j] * axis_prm[4, j] * maximum(face - pos_n, 0.0)
                if axis_prm[3, j] > 0:
                    fm = minimum(fm, fmu)
            delta = PV[j] - slip[j]
            f = minimum(maximum(-axis_prm[0, j] * delta - axis_prm[1, j] * VV[j], -fm), fm)
            if gated_any:
                f = f * (0.0 if free else 1.0)
            w[j] = f
            limit = fm / axis_prm[5, j]
            new = slip[j] + (delta - minimum(maximum(delta, -limit), limit))
            slip_next[j] = PV[j] if free else new
        if normal_terms:
            d = point_prm[3, i] - pos_n
            w[n2 + i] = (point_prm[2, i] * d * d * d + point_prm[4, i] * d
                         - point_prm[5, i] * VV[n2 + i]) * (1.0 if touching else 0.0)
        else:
            w[n2 + i] = 0.0 * pos_n
    for j in range(nc):
        r0, r1, r2 = PV[n3 + 3 * j], PV[n3 + 3 * j + 1], PV[n3 + 3 * j + 2]
        d = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        u0, u1, u2 = r0 / d, r1 / d, r2 / d
        rate = u0 * VV[n3 + 3 * j] + u1 * VV[n3 + 3 * j + 1] + u2 * VV[n3 + 3 * j + 2]
        sc = constraint_prm[0, j] * (d - constraint_prm[1, j]) + constraint_prm[2, j] * rate
        w[n3 + 3 * j] = sc * u0
        w[n3 + 3 * j + 1] = sc * u1
        w[n3 + 3 * j + 2] = sc * u2
    fd = np.empty(n if dampers else 0)
    for i in range(fd.shape[0]):
        fd[i] = -contact_prm[0, i] * V[n3 + 9 + i] * (
            1.0 if (contact_prm[1, i] - pos_n_contact[i]) > 0 else 0.0)
    m = rot_q.shape[0]
    pid_force, pid_torque, z_next = np.empty(m), np.empty(m), np.empty(m)
    for i in range(m):
        e = x[rot_q[i]] - pid_prm[0, i]
        pi = pid_prm[1, i] * e + pid_prm[2, i] * z[i]
        pid_torque[i] = pi + pid_prm[3, i] * x[rot_v_x[i]]
        pid_force[i] = pi + pid_prm[6, i] * x[rot_q[i]] if implicit_kp and not balls else pi
        z_next[i] = minimum(maximum(z[i] + period * e, pid_prm[5, i]), pid_prm[4, i])
    passive = np.empty(q_index.shape[0])
    for i in range(q_index.shape[0]):
        q = x[q_index[i]]
        t = passive_prm[0, i] * (q - passive_prm[1, i])
        if implicit:
            t = t + passive_prm[2, i] * q
        if damping and not balls:
            t = t - passive_prm[3, i] * x[v_x[i]]
        passive[i] = t
    if balls:  # `passive_torque` and the PID's mapping on ball joints
        pid_force = _cardan_to_generalized(pid_force, ball, trig)
        if damping:
            rates = np.empty(m)  # `cardan_rates`
            for i in range(m):
                rates[i] = x[v_x[i]]
            for b in range(ball.shape[1]):
                r, p, y = ball[0, b], ball[1, b], ball[2, b]
                cp, cy, sy, sp = trig[0, b], trig[1, b], trig[2, b], trig[4, b]
                wx, wy = x[v_x[r]], x[v_x[p]]
                u = (cy * wx + sy * wy) / cp
                rates[r] = u
                rates[p] = cy * wy - sy * wx
                rates[y] = x[v_x[y]] + u * sp
            for i in range(m):
                passive[i] = passive[i] - passive_prm[3, i] * rates[i]
            if passive_prm[3, m] != 0.0:
                passive[m] = passive[m] - passive_prm[3, m] * x[v_x[m]]
        passive = _cardan_to_generalized(passive, ball, trig)
    return w, slip_next, fd, pid_force, pid_torque, z_next, passive


#: `_laws_kernel` compiled, or None without numba (`ehm_drake.jit`).
compiled_laws = kernel(_laws_kernel)
#: The contact points' normal displacements where there are no contact dampers.
NO_CONTACTS = np.zeros(0)
#: The ball joints' trigonometric terms on Cardan chains (none).
NO_BALLS = np.zeros((5, 0))


def ball_trigonometry(laws, x):
    """The ball joints' trigonometric terms at plant state `x` as
    `_laws_kernel` takes them (NumPy's functions: the NumPy path's numbers)."""
    if laws._cardan_chains:
        return NO_BALLS
    q_rot = x[laws._layout.rot_q]
    p, y = q_rot[laws._ball.pitch], q_rot[laws._ball.yaw]
    return np.array([np.cos(p), np.cos(y), np.sin(y), np.tan(p), np.sin(p)])


def packed_constants(laws, c):
    """The constants of `ForceLaws` `laws` (its `_Constants` `c`) as
    `_laws_kernel` takes them, after its state arguments."""
    r, g = c.restraint, laws._geometry
    n_rot = laws._layout.num_rotational
    k = laws._constraints
    axis_prm = np.array([r["k"], r["c"], r["fmax"], r["mu"], r["k_contact"],
                         r["k_safe"]], float)
    point_prm = np.array([g.face, r["gated"], r["k3"], r["ref"], r["k_lin"],
                          r["c_lin"]], float)
    flags = np.array([r["any_friction"], r["any_gated"],
                      r["any_cubic"] or r["any_linear"], k is not None,
                      laws._contact_damping is not None,
                      laws._implicit_kp is not None, laws._implicit is not None,
                      laws._damping is not None, not laws._cardan_chains], np.int64)
    constraint_prm = (np.zeros((3, 0)) if k is None else
                      np.array([k.stiffness, k.length, k.step_damping], float))
    contact_prm = (np.zeros((2, 0)) if laws._contact_damping is None else
                   np.array([laws._contact_damping_g, laws._face_g], float))
    zero = np.zeros(n_rot)
    pid_prm = np.array([c.reference, c.neg_kp, c.neg_ki, c.neg_kd, c.bound, c.neg_bound,
                        zero if laws._implicit_kp is None else laws._implicit_kp])
    zero = np.zeros(n_rot + 1)
    passive_prm = np.array([c.neg_k, c.neutral,
                            zero if laws._implicit is None else laws._implicit,
                            zero if laws._damping is None else laws._damping])
    ball = np.array([laws._ball.roll, laws._ball.pitch, laws._ball.yaw], np.int64)
    return (ball, axis_prm, point_prm, flags, constraint_prm, contact_prm, pid_prm,
            laws._layout.rot_q, laws._rot_v_x, passive_prm, laws._q_index, laws._v_x,
            laws._period)


__all__ = ["NO_BALLS", "NO_CONTACTS", "ball_trigonometry", "compiled_laws", "packed_constants"]
