"""`ForceLaws`' step compiled with numba (`ehm_drake.jit`).

The kinematics' kernels (`ehm_drake.systems.compiled_kinematics`) and two
more do all of the step, so that no Drake query or NumPy operation runs
per step on the compiled path:
`_probe_kernel`, the contact dampers' deepest points and normal
displacements (`_ContactProbe` in NumPy), and `_step_kernel`, the rest
(the Jacobian's rows assembled, the velocities, head-in-space, the
projections, the elementwise laws of `_laws_kernel`, the sum mapped
through the Jacobian, the restraints' force per seat part).  `_laws_kernel`
is the NumPy expressions of
`ehm_drake.systems.forces.ForceLaws._elementwise_laws` element by element
in their order; the products, which NumPy hands to BLAS, are loops here,
so the step's numbers are the NumPy step's to rounding
(tests/test_force_laws.py: 1e-12).  Fewer Python operations per step cost
less in themselves and leave the CPU's caches and predictors to the
plant's contact solve, which ran about 80 us slower after the NumPy step
(`docs/history/`).  Used for float states with no separate controller
input, on both designs (the ball joints' cosines, sines and tangents
computed in NumPy); where the plant has a joint the kinematics' kernels do
not know, the kinematics are Drake's.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable

from ..jit import available, kernel, maximum, minimum
from .compiled_kinematics import TreeKinematics


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
#: `_cardan_to_generalized` compiled (for the kernels), or the Python function.
cardan_kernel = _cardan_to_generalized


def _laws_kernel(x, PV, VV, V, n, slip, z, pos_n_contact, ball, trig, axis_prm, point_prm,
                 flags, constraint_prm, contact_prm, pid_prm, rot_q, rot_v_x, passive_prm,
                 q_index, v_x, period):
    """The elementwise part of `ForceLaws`' step on a float state with no
    separate controller input, compiled (`ehm_drake.jit`): the
    contact dampers (`contact_damping_force`), the restraints' limits, law
    and slip (`restraint_limits`, `restraint_law`, `slip_update`), the
    constraints' force at the step's start, the PID and its integral, the
    passive joints: the NumPy expressions of `_elementwise_laws` element by
    element, in their order (`_step_kernel` calls it between the
    projections and the product with the Jacobian).

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


def _probe_kernel(A, axis, o_cols, tip_cols, p_BE, semi_axes, n0, points, c_cols):
    """`_ContactProbe`'s arithmetic on the probed positions `A` (3 x m):
    each contact point's deepest point of its ellipsoid against the seat
    part's normal (`deepest_points`), written into `points`' columns
    `c_cols` (where the Jacobian call reads them), and its normal
    displacement from the anchor, returned (grouped order)."""
    k = axis.shape[0]
    pos_n = np.empty(k)
    for i in range(k):
        a = axis[i]
        o = A[a, o_cols[i]]
        m0 = A[a, tip_cols[i, 0]] - o
        m1 = A[a, tip_cols[i, 1]] - o
        m2 = A[a, tip_cols[i, 2]] - o
        d0, d1, d2 = semi_axes[i, 0] * m0, semi_axes[i, 1] * m1, semi_axes[i, 2] * m2
        norm = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        c0 = p_BE[i, 0] - semi_axes[i, 0] * d0 / norm
        c1 = p_BE[i, 1] - semi_axes[i, 1] * d1 / norm
        c2 = p_BE[i, 2] - semi_axes[i, 2] * d2 / norm
        points[0, c_cols[i]] = c0
        points[1, c_cols[i]] = c1
        points[2, c_cols[i]] = c2
        pos_n[i] = o + (m0 * c0 + m1 * c1 + m2 * c2) - n0[i]
    return pos_n


def _sparse_product(indptr, indices, data, u, offset):
    """M u - offset for M in compressed rows (indptr, indices, data)."""
    out = np.empty(indptr.shape[0] - 1)
    for r in range(out.shape[0]):
        acc = 0.0
        for j in range(indptr[r], indptr[r + 1]):
            acc += data[j] * u[indices[j]]
        out[r] = acc - offset[r]
    return out


def _step_kernel(x, nq, A, p_cols, JJ, jp_rows, jc_rows, J_head, J_trunk, J_com, R_WH,
                 his_kp, his_kd, R_ref_T, m_ptr, m_idx, m_val, m0, n_pt, mass, a, slip, z,
                 pos_n_contact, rot_v, v_index, ball, trig, axis_prm, point_prm, flags,
                 constraint_prm, contact_prm, pid_prm, rot_q, rot_v_x, passive_prm, q_index,
                 v_x, period, seat, grouped_row):
    """`ForceLaws._calc_step` after the kinematics, compiled: the rows of
    J (the restraint points' rows `jp_rows` and the contact points' rows
    `jc_rows` of the probed Jacobian `JJ`, between them head, upper torso
    and centre of mass), V = J v, the head-in-space torque, the points'
    projections PV = M p - m0 and VV = M V (M in compressed rows), the
    elementwise laws (`_laws_kernel`), G and f = J^T G + the joints' PID
    and passive forces.  `A`'s columns `p_cols` are the restraint points'
    positions.  Returns (f, J, G, w, slip_next, fd, pid_force, pid_torque,
    z_next, passive, his_torque, PV, seat_forces): the last the restraints'
    and contact dampers' force per seat part (`seat`: the matrix of
    `ForceLaws._out_seat_forces`, `grouped_row` the contact point of each
    restraint point)."""
    nv = JJ.shape[1]
    n3, nc = jp_rows.shape[0], jc_rows.shape[0]
    rows = n3 + 9 + nc
    J = np.empty((rows, nv))
    for r in range(n3):
        J[r, :] = JJ[jp_rows[r], :]
    J[n3:n3 + 3, :] = J_head
    J[n3 + 3:n3 + 6, :] = J_trunk
    J[n3 + 6:n3 + 9, :] = J_com
    for r in range(nc):
        J[n3 + 9 + r, :] = JJ[jc_rows[r], :]
    V = np.empty(rows)
    for r in range(rows):
        acc = 0.0
        for k in range(nv):
            acc += J[r, k] * x[nq + k]
        V[r] = acc
    # Head-in-space: tau = -(kp e + kd w), e the roll, pitch, yaw of R_WH R_ref^T.
    R = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            R[i, j] = R_WH[i, 0] * R_ref_T[0, j] + R_WH[i, 1] * R_ref_T[1, j] \
                + R_WH[i, 2] * R_ref_T[2, j]
    e0 = math.atan2(R[2, 1], R[2, 2])
    e1 = math.atan2(-R[2, 0], math.sqrt(R[0, 0] * R[0, 0] + R[1, 0] * R[1, 0]))
    e2 = math.atan2(R[1, 0], R[0, 0])
    tau = np.empty(3)
    tau[0] = -(his_kp[0] * e0 + his_kd[0] * V[n3])
    tau[1] = -(his_kp[1] * e1 + his_kd[1] * V[n3 + 1])
    tau[2] = -(his_kp[2] * e2 + his_kd[2] * V[n3 + 2])
    # The points' projections.
    p = np.empty(3 * p_cols.shape[0])  # [x; y; z] point by point (column-major P)
    for i in range(p_cols.shape[0]):
        for d in range(3):
            p[3 * i + d] = A[d, p_cols[i]]
    PV = _sparse_product(m_ptr, m_idx, m_val, p, m0)
    VV = _sparse_product(m_ptr, m_idx, m_val, V, np.zeros(m0.shape[0]))
    w, slip_next, fd, pid_force, pid_torque, z_next, passive = compiled_laws(
        x, PV, VV, V, n_pt, slip, z, pos_n_contact, ball, trig, axis_prm, point_prm, flags,
        constraint_prm, contact_prm, pid_prm, rot_q, rot_v_x, passive_prm, q_index, v_x,
        period)
    # G: the restraints' point forces (M^T w), +tau on the head, -tau on the
    # upper torso, the inertial load -m a at the centre of mass, the contact
    # dampers' normal forces.
    G = np.zeros(rows)
    for r in range(m_ptr.shape[0] - 1):
        for j in range(m_ptr[r], m_ptr[r + 1]):
            G[m_idx[j]] += m_val[j] * w[r]
    for i in range(3):
        G[n3 + i] = tau[i]
        G[n3 + 3 + i] = -tau[i]
        G[n3 + 6 + i] = -mass * a[i]
    for r in range(nc):
        G[n3 + 9 + r] = fd[r]
    f = np.empty(nv)
    for k in range(nv):
        acc = 0.0
        for r in range(rows):
            acc += J[r, k] * G[r]
        f[k] = acc
    for i in range(rot_v.shape[0]):
        f[rot_v[i]] += pid_force[i]
    for i in range(v_index.shape[0]):
        f[v_index[i]] += passive[i]
    n2 = 2 * n_pt
    u = w[:n2 + n_pt].copy()  # tangential, then normal forces (+ the dampers')
    if flags[4]:
        for i in range(n_pt):
            u[n2 + i] += fd[grouped_row[i]]
    seat_forces = np.empty(seat.shape[0])
    for r in range(seat.shape[0]):
        acc = 0.0
        for k in range(u.shape[0]):
            acc += seat[r, k] * u[k]
        seat_forces[r] = acc
    return f, J, G, w, slip_next, fd, pid_force, pid_torque, z_next, passive, tau, PV, \
        seat_forces


#: The two step kernels compiled, or None without numba.
compiled_probe = kernel(_probe_kernel)
if available():  # (called by the compiled step kernel: compiled too)
    _sparse_product = kernel(_sparse_product)
compiled_step_kernel = kernel(_step_kernel)


class StepStructure:
    """What `compiled_step` passes the kernels that depends only on the
    model: M (`ForceLaws`' projections) in compressed rows, which columns
    and rows of the probed positions and Jacobian are the restraint and
    contact points'."""

    def __init__(self, laws):
        M = laws._M
        nz = [np.flatnonzero(row) for row in M]
        self.m_ptr = np.concatenate([[0], np.cumsum([len(c) for c in nz])]).astype(np.int64)
        self.m_idx = np.concatenate(nz).astype(np.int64)
        self.m_val = np.concatenate([row[c] for row, c in zip(M, nz, strict=True)])
        n = len(laws._points)
        probe = getattr(laws, "_probe", None)
        if laws._contact_damping is None:
            self.p_cols, self.jp_rows = np.arange(n), np.arange(3 * n)
            self.jc_rows = np.zeros(0, np.int64)
        else:
            self.p_cols, self.jp_rows, self.jc_rows = probe.p_cols, probe.jp_rows, probe.jc_rows
        # The kinematics compiled too where the kernels know every joint and
        # the points are given in body frames.
        groups = laws._geometry.groups
        self.tree = None
        if all(frame.index() == frame.body().body_frame().index() for frame, _, _ in groups):
            self.tree = TreeKinematics.of(laws._scratch.plant, laws._scratch.context,
                                          laws._instances, laws._head, laws._trunk)
        if self.tree is not None:
            body = [int(frame.body().index()) for frame, _, _ in groups]
            if laws._contact_damping is None:  # positions and Jacobians of the points
                self.probe = np.concatenate([P_B for _, P_B, _ in groups], axis=1)
                self.probe_body = np.repeat(body, [P_B.shape[1] for _, P_B, _ in groups])
                self.jac_body = self.probe_body
            else:  # `_ContactProbe`'s probes, then its [P_B | C_B]
                self.probe = np.concatenate(probe.probes, axis=1)
                self.probe_body = np.repeat(body, [P.shape[1] for P in probe.probes])
                self.jac_body = np.zeros(probe.points.shape[1], np.int64)
                for b, cols in zip(body, probe.blocks, strict=True):
                    self.jac_body[cols] = b


def compiled_step(laws, context, s):
    """`ForceLaws._calc_step` on the compiled path: the kinematics (compiled,
    or Drake's), then the two kernels; fills and returns the `_Step` `s`."""
    c = laws._constants.Eval(context)
    x = laws._state_port.Eval(context)
    st = laws._structure
    if st is None:
        st = laws._structure = StepStructure(laws)
    ctx = laws._scratch.set_state(x)  # (the state the shared scratch holds: `share`)
    if st.tree is not None:
        R_WH, J_head, J_trunk, J_com, A, JJ, pos_n_contact = _compiled_kinematics(laws, st, x)
    else:
        p, W, kv = laws._scratch.plant, laws._world, JacobianWrtVariable.kV
        R_WH = p.EvalBodyPoseInWorld(ctx, laws._head_body).rotation().matrix()
        J_head = p.CalcJacobianAngularVelocity(ctx, kv, laws._head, W, W)
        J_trunk = p.CalcJacobianAngularVelocity(ctx, kv, laws._trunk, W, W)
        J_com = p.CalcJacobianCenterOfMassTranslationalVelocity(ctx, laws._instances, kv, W, W)
        if laws._contact_damping is None:
            groups = laws._geometry.groups
            A = np.concatenate([p.CalcPointsPositions(ctx, frame, P_B, W)
                                for frame, P_B, _ in groups], axis=1)
            JJ = np.concatenate([p.CalcJacobianTranslationalVelocity(ctx, kv, frame, P_B, W, W)
                                 for frame, P_B, _ in groups])
            pos_n_contact = NO_CONTACTS
        else:
            A, JJ, pos_n_contact = laws._probe.raw(p, ctx, W)
    ball, *packed = c.packed
    (s.f, s.J, s.G, s.w, s.slip_next, fd, s.pid_force, s.pid_torque, s.z_next,
     s.passive_force, s.his_torque, PV, s.seat_forces) = compiled_step_kernel(
        x, laws._nq, A, st.p_cols, JJ, st.jp_rows, st.jc_rows, J_head, J_trunk, J_com, R_WH,
        c.his_kp, c.his_kd, c.his_R_ref_T, st.m_ptr, st.m_idx, st.m_val, laws._m0,
        len(laws._points), laws._mass, laws._a_port.Eval(context),
        laws._discrete(context, laws._slip), laws._discrete(context, laws._z), pos_n_contact,
        laws._layout.rot_v, laws._v_index, ball, ball_trigonometry(laws, x), *packed,
        laws._seat, laws._geometry.grouped_row)
    if laws._contact_damping is not None:
        s.fd = fd
    n2 = 2 * len(laws._points)
    s.pos, s.pos_n = PV[:n2], PV[n2:n2 + len(laws._points)]
    s.J_his = None
    return s


def _compiled_kinematics(laws, st, x):
    """What `compiled_step` asks Drake for, from the compiled kinematics
    (`TreeKinematics`): R_WH, the head's and upper torso's angular
    Jacobians, the centre of mass's Jacobian, the probed positions, the
    points' Jacobian and the contact points' normal displacements."""
    tree = st.tree
    R_WB, p_WB, w, o, t, A = tree.poses(x, st.probe, st.probe_body)
    if laws._contact_damping is None:
        points, pos_n_contact = st.probe, NO_CONTACTS
    else:
        probe = laws._probe
        pos_n_contact = compiled_probe(A, probe.axis, probe.o_cols, probe.tip_cols, probe.p_BE,
                                       probe.semi_axes, probe.n0, probe.points, probe.c_cols)
        points = probe.points
    JJ, J_head, J_trunk, J_com = tree.jacobians(R_WB, p_WB, w, o, t, points, st.jac_body)
    return R_WB[tree.head], J_head, J_trunk, J_com, A, JJ, pos_n_contact


#: The contact points' normal displacements where there are no contact dampers.
NO_CONTACTS = np.zeros(0)
#: The ball joints' trigonometric terms on Cardan chains (none).
NO_BALLS = np.zeros((5, 0))


def ball_trigonometry(laws, x):
    """The ball joints' trigonometric terms at plant state `x` as
    `_laws_kernel` takes them (NumPy's functions: the NumPy path's numbers)."""
    if laws._cardan_chains:
        return NO_BALLS
    return trigonometry(laws._ball, x[laws._layout.rot_q])


def trigonometry(ball, q_rot):
    """The trigonometric terms of the ball joints `ball` (`_BallIndex`) at
    rotational angles `q_rot` (5 x nb, `_cardan_to_generalized`'s `trig`)."""
    p, y = q_rot[ball.pitch], q_rot[ball.yaw]
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


__all__ = ["NO_BALLS", "NO_CONTACTS", "StepStructure", "ball_trigonometry", "cardan_kernel",
           "compiled_laws",
           "compiled_probe", "compiled_step", "compiled_step_kernel", "packed_constants",
           "trigonometry"]
