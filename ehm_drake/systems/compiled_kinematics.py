"""The plant's kinematics for the compiled force-law step (numba).

`compiled_step` (`ehm_drake.systems.compiled_laws`) needs, at each step,
the head's orientation, the angular-velocity Jacobians of head and upper
torso, the centre of mass's translational Jacobian and the positions and
translational Jacobians of the restraint and contact points.  Asked of
Drake from Python these were 17 calls a step, about 70 us in a running
simulation (docs/history/), more than the force laws' arithmetic.
`TreeKinematics` reads the plant's tree once (joints ordered from the
root, their fixed frames, axes and coordinate indices, the bodies' masses
and centres of mass) and two kernels compute the same quantities from q:
forward kinematics body by body (X_WC = X_WP X_PF X_FM(q) X_MC), then each
point's Jacobian as the sum over the mobilities on its body's path to the
world of w_k x (p_WQ - p_WMk) + t_k, w_k and t_k the mobility's angular
and translational velocity per unit speed.  The numbers are Drake's to
rounding (tests/test_force_laws.py compares them at random states of both
designs).  Joints: weld, revolute, prismatic, ball (roll-pitch-yaw),
universal and roll-pitch-yaw floating; a plant with any other joint keeps
Drake's calls (`TreeKinematics.of` returns None).
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import kernel

#: The joint types the kernels know, by Drake's `type_name()`.
JOINT_TYPES = {"weld": 0, "revolute": 1, "prismatic": 2, "ball_rpy": 3, "rpy_floating": 4,
               "universal": 5}


def _rpy(r, p, y, R):
    """R = Drake's RollPitchYaw(r, p, y).ToRotationMatrix(): Rz(y) Ry(p) Rx(r)."""
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), \
        math.cos(y), math.sin(y)
    R[0, 0], R[0, 1], R[0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
    R[1, 0], R[1, 1], R[1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
    R[2, 0], R[2, 1], R[2, 2] = -sp, cp * sr, cp * cr


def _angle_axis(a, theta, R):
    """R = the rotation by `theta` about the unit vector `a` (Rodrigues)."""
    c, s = math.cos(theta), math.sin(theta)
    t = 1.0 - c
    R[0, 0], R[0, 1], R[0, 2] = c + t * a[0] * a[0], t * a[0] * a[1] - s * a[2], \
        t * a[0] * a[2] + s * a[1]
    R[1, 0], R[1, 1], R[1, 2] = t * a[0] * a[1] + s * a[2], c + t * a[1] * a[1], \
        t * a[1] * a[2] - s * a[0]
    R[2, 0], R[2, 1], R[2, 2] = t * a[0] * a[2] - s * a[1], t * a[1] * a[2] + s * a[0], \
        c + t * a[2] * a[2]


def _mm(A, B, C):
    """C = A B for 3 x 3 matrices (loops: no BLAS call, no allocation)."""
    for i in range(3):
        for k in range(3):
            C[i, k] = A[i, 0] * B[0, k] + A[i, 1] * B[1, k] + A[i, 2] * B[2, k]


def _mv(A, v, p, out):
    """out = p + A v for a 3 x 3 matrix and 3-vectors."""
    for i in range(3):
        out[i] = p[i] + (A[i, 0] * v[0] + A[i, 1] * v[1] + A[i, 2] * v[2])


def _add_column(w, o, t, k, p, scale, J, row):
    """J[row:row + 3, k] += scale (w_k x (p - o_k) + t_k): the velocity of
    the point p per unit speed of mobility k (w_k, t_k its angular and
    translational velocity per unit speed, o_k its origin), weighted."""
    r0, r1, r2 = p[0] - o[k, 0], p[1] - o[k, 1], p[2] - o[k, 2]
    J[row, k] += scale * (w[k, 1] * r2 - w[k, 2] * r1 + t[k, 0])
    J[row + 1, k] += scale * (w[k, 2] * r0 - w[k, 0] * r2 + t[k, 1])
    J[row + 2, k] += scale * (w[k, 0] * r1 - w[k, 1] * r0 + t[k, 2])


def _poses_kernel(q, jtype, parent, child, R_PF, p_PF, R_MC, p_MC, axis, q0, v0, nb, nv,
                  probe, probe_body):
    """Forward kinematics at q: the bodies' poses (R_WB, nb x 3 x 3; p_WB,
    nb x 3), each mobility's angular velocity per unit speed `w`, the point
    it acts about `o` and its translational velocity per unit speed `t`
    (nv x 3 each, in W), and the positions in W of the points `probe`
    (3 x m, each in the frame of body `probe_body`)."""
    R_WB = np.zeros((nb, 3, 3))
    p_WB = np.zeros((nb, 3))
    for i in range(3):
        R_WB[0, i, i] = 1.0
    w = np.zeros((nv, 3))
    o = np.zeros((nv, 3))
    t = np.zeros((nv, 3))
    zero = np.zeros(3)
    R_WF, R_FM, R_WM = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    p_WF, p_FM, p_WM, u = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    for j in range(jtype.shape[0]):
        P, C = parent[j], child[j]
        _mm(R_WB[P], R_PF[j], R_WF)
        _mv(R_WB[P], p_PF[j], p_WB[P], p_WF)
        kind, iq, iv = jtype[j], q0[j], v0[j]
        p_FM[:] = 0.0
        if kind == 1:  # revolute
            _angle_axis(axis[j], q[iq], R_FM)
            _mv(R_WF, axis[j], zero, w[iv])
            o[iv] = p_WF
        elif kind == 3 or kind == 4:  # ball, floating: v = w_FM_F (then v_FM_F)
            _rpy(q[iq], q[iq + 1], q[iq + 2], R_FM)
            if kind == 4:
                for i in range(3):
                    p_FM[i] = q[iq + 3 + i]
                    t[iv + 3 + i] = R_WF[:, i]
            _mv(R_WF, p_FM, p_WF, p_WM)
            for i in range(3):
                w[iv + i] = R_WF[:, i]
                o[iv + i] = p_WM
        elif kind == 5:  # universal: about F's x by q0, then the rotated y by q1
            c0, s0, c1, s1 = math.cos(q[iq]), math.sin(q[iq]), math.cos(q[iq + 1]), \
                math.sin(q[iq + 1])
            R_FM[0, 0], R_FM[0, 1], R_FM[0, 2] = c1, 0.0, s1
            R_FM[1, 0], R_FM[1, 1], R_FM[1, 2] = s0 * s1, c0, -s0 * c1
            R_FM[2, 0], R_FM[2, 1], R_FM[2, 2] = -c0 * s1, s0, c0 * c1
            w[iv] = R_WF[:, 0]
            u[0], u[1], u[2] = 0.0, c0, s0
            _mv(R_WF, u, zero, w[iv + 1])
            o[iv] = p_WF
            o[iv + 1] = p_WF
        else:  # weld, prismatic
            R_FM[:, :] = 0.0
            for i in range(3):
                R_FM[i, i] = 1.0
            if kind == 2:
                for i in range(3):
                    p_FM[i] = axis[j, i] * q[iq]
                _mv(R_WF, axis[j], zero, t[iv])
        _mm(R_WF, R_FM, R_WM)
        _mv(R_WF, p_FM, p_WF, p_WM)
        _mm(R_WM, R_MC[j], R_WB[C])
        _mv(R_WM, p_MC[j], p_WM, p_WB[C])
    A = np.empty((3, probe.shape[1]))
    for c in range(probe.shape[1]):
        _mv(R_WB[probe_body[c]], probe[:, c], p_WB[probe_body[c]], A[:, c])
    return R_WB, p_WB, w, o, t, A


def _jacobians_kernel(R_WB, p_WB, w, o, t, on_path, points, point_body, head, trunk, mass,
                      p_BBcm, total_mass):
    """The translational Jacobian of each column of `points` (3 x m, each in
    the frame of body `point_body`), stacked point by point (3m x nv, as
    Drake's CalcJacobianTranslationalVelocity); the angular-velocity
    Jacobians of bodies `head` and `trunk` (3 x nv); the translational
    Jacobian of the centre of mass of the bodies with `mass` > 0 (3 x nv,
    over `total_mass`).  `on_path` (nb x nv): the mobilities between each
    body and the world."""
    nv = w.shape[0]
    m = points.shape[1]
    JJ = np.zeros((3 * m, nv))
    p = np.empty(3)
    for c in range(m):
        b = point_body[c]
        _mv(R_WB[b], points[:, c], p_WB[b], p)
        for k in range(nv):
            if on_path[b, k]:
                _add_column(w, o, t, k, p, 1.0, JJ, 3 * c)
    J_head = np.zeros((3, nv))
    J_trunk = np.zeros((3, nv))
    for k in range(nv):
        if on_path[head, k]:
            J_head[:, k] = w[k]
        if on_path[trunk, k]:
            J_trunk[:, k] = w[k]
    J_com = np.zeros((3, nv))
    for b in range(mass.shape[0]):
        if mass[b] <= 0.0:
            continue
        _mv(R_WB[b], p_BBcm[b], p_WB[b], p)
        for k in range(nv):
            if on_path[b, k]:
                _add_column(w, o, t, k, p, mass[b], J_com, 0)
    for i in range(3):
        for k in range(nv):
            J_com[i, k] /= total_mass
    return JJ, J_head, J_trunk, J_com


if kernel(_mm) is not None:  # (called by the compiled kernels: compiled too)
    _rpy, _angle_axis, _mm, _mv = kernel(_rpy), kernel(_angle_axis), kernel(_mm), kernel(_mv)
    _add_column = kernel(_add_column)
poses_kernel = kernel(_poses_kernel) or _poses_kernel
jacobians_kernel = kernel(_jacobians_kernel) or _jacobians_kernel


class TreeKinematics:
    """The tree of `plant` as the kernels take it, the masses and centres
    of mass from `context` (the bodies of `instances`), and the bodies of
    the head and trunk frames.  `of` builds it, or returns None when the
    plant has a joint the kernels do not know."""

    @classmethod
    def of(cls, plant, context, instances, head_frame, trunk_frame):
        joints = [plant.get_joint(j) for j in plant.GetJointIndices()]
        if any(j.type_name() not in JOINT_TYPES for j in joints):
            return None
        return cls(plant, context, instances, joints, head_frame, trunk_frame)

    def __init__(self, plant, context, instances, joints, head_frame, trunk_frame):
        nb, nv = plant.num_bodies(), plant.num_velocities()
        ordered, placed = [], {0}
        while len(ordered) < len(joints):  # parents before children
            before = len(ordered)
            for j in joints:
                if j not in ordered and int(j.parent_body().index()) in placed:
                    ordered.append(j)
                    placed.add(int(j.child_body().index()))
            if len(ordered) == before:
                raise ValueError("the plant's joints do not form a tree rooted at the world")
        n = len(ordered)
        self.jtype = np.array([JOINT_TYPES[j.type_name()] for j in ordered], np.int64)
        self.parent = np.array([int(j.parent_body().index()) for j in ordered], np.int64)
        self.child = np.array([int(j.child_body().index()) for j in ordered], np.int64)
        self.R_PF, self.R_MC = np.zeros((n, 3, 3)), np.zeros((n, 3, 3))
        self.p_PF, self.p_MC = np.zeros((n, 3)), np.zeros((n, 3))
        self.axis = np.zeros((n, 3))
        for i, j in enumerate(ordered):
            X_PF = j.frame_on_parent().GetFixedPoseInBodyFrame()
            X_MC = j.frame_on_child().GetFixedPoseInBodyFrame().inverse()
            self.R_PF[i], self.p_PF[i] = X_PF.rotation().matrix(), X_PF.translation()
            self.R_MC[i], self.p_MC[i] = X_MC.rotation().matrix(), X_MC.translation()
            if j.type_name() == "revolute":
                self.axis[i] = j.revolute_axis()
            elif j.type_name() == "prismatic":
                self.axis[i] = j.translation_axis()
        self.q0 = np.array([j.position_start() for j in ordered], np.int64)
        self.v0 = np.array([j.velocity_start() for j in ordered], np.int64)
        self.nb, self.nv = nb, nv
        self.on_path = np.zeros((nb, nv), np.bool_)
        for i, j in enumerate(ordered):  # a child's path: its parent's and its joint's
            c = self.child[i]
            self.on_path[c] = self.on_path[self.parent[i]]
            self.on_path[c, j.velocity_start():j.velocity_start() + j.num_velocities()] = True
        self.mass, self.p_BBcm = np.zeros(nb), np.zeros((nb, 3))
        for instance in instances:
            for b in plant.GetBodyIndices(instance):
                body = plant.get_body(b)
                self.mass[int(b)] = body.get_mass(context)
                self.p_BBcm[int(b)] = body.CalcCenterOfMassInBodyFrame(context)
        self.total_mass = float(self.mass.sum())
        self.head = self.body_of(head_frame)
        self.trunk = self.body_of(trunk_frame)

    @staticmethod
    def body_of(frame) -> int:
        """The index of the body `frame` is fixed to (any frame: an angular
        velocity is its body's)."""
        return int(frame.body().index())

    def poses(self, q, probe, probe_body):
        """`_poses_kernel` at q for the points `probe` on `probe_body`."""
        return poses_kernel(q, self.jtype, self.parent, self.child, self.R_PF, self.p_PF,
                            self.R_MC, self.p_MC, self.axis, self.q0, self.v0, self.nb,
                            self.nv, probe, probe_body)

    def jacobians(self, R_WB, p_WB, w, o, t, points, point_body):
        """`_jacobians_kernel` for the points `points` on `point_body`."""
        return jacobians_kernel(R_WB, p_WB, w, o, t, self.on_path, points, point_body,
                                self.head, self.trunk, self.mass, self.p_BBcm,
                                self.total_mass)
