"""The seat parts' contact forces from the plant's generalized contact forces.

`SeatForces` sums, for every logged sample, the point contacts of Drake's
`ContactResults`: the plant computes the results (about 28 us a step) and
Python walks the seven contacts (about 25 us), a tenth of a 5 ms step.  On
the model's own seat the same forces follow from one vector that the plant
computes with its contact solve anyway and that a C++ logger records: the
human's generalized contact forces tau_c = sum_i J_i^T f_i (J_i the
translational Jacobian of contact point i).  The contacts are frictionless
(shear is the restraints'), so f_i = lambda_i n_i along the seat part's
normal, and tau_c (nv = 31 values) determines the 7 lambda_i by least
squares.  The point where Drake applies f_i is FCL's ellipsoid-half-space
contact point: on the segment from the ellipsoid's centre to its deepest
point, at the penetration's mid-depth (`_contact_columns_kernel`); any
point on the normal through it gives the same generalized force.  With
that point the forces are the contact results' to rounding (within 1e-13
of the largest force; tests/test_contact_forces.py), computed after the run
from the logged state in compiled passes of bounded memory
(`ContactDecomposition.of` says when this holds; elsewhere the diagram logs
`SeatForces`)."""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Ellipsoid, HalfSpace
from pydrake.multibody.plant import CalcContactFrictionFromSurfaceProperties, ContactModel

from .. import jit
from .compiled_kinematics import TreeKinematics, _add_column, poses_kernel
from .seat import SEAT_PART_NAMES, restraint_points


def _contact_columns_kernel(Q, jtype, parent, child, R_PF, p_PF, R_MC, p_MC, axis, q0, v0,
                            nb, nv, on_path, body, R_BE, p_BE, radii, normal, offset):
    """For each sample q (rows of Q) and contact i: the generalized force of
    a unit force along the seat part's normal `normal[i]` (in W) at FCL's
    contact point of ellipsoid i (on `body[i]`, pose R_BE, p_BE, semi-axes
    `radii`) against the half-space {x: normal . x <= offset}, and the
    penetration depth (negative: apart).  Returns (columns (N, k, nv),
    depths (N, k))."""
    n, k = Q.shape[0], body.shape[0]
    cols = np.zeros((n, k, nv))
    depth = np.empty((n, k))
    probe = np.zeros((3, 0))
    probe_body = np.zeros(0, np.int64)
    nE, sv, p, pw = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    J = np.zeros((3, nv))
    for s in range(n):
        R_WB, p_WB, w, o, t, _ = poses_kernel(Q[s], jtype, parent, child, R_PF, p_PF, R_MC,
                                              p_MC, axis, q0, v0, nb, nv, probe, probe_body)
        for i in range(k):
            b = body[i]
            # The half-space in the ellipsoid's frame E: normal nE, and the
            # centre's height above the face.
            c2 = 0.0
            for a in range(3):
                na = 0.0
                for r in range(3):
                    Rw = 0.0
                    for j in range(3):
                        Rw += R_WB[b, j, r] * normal[i, j]  # (R_WB^T n)_r
                    na += R_BE[i, r, a] * Rw  # (R_BE^T R_WB^T n)_a
                nE[a] = na
                c2 += na * na * radii[i, a] * radii[i, a]
            c = np.sqrt(c2)
            height = -offset[i]
            for j in range(3):
                pe = p_WB[b, j]
                for r in range(3):
                    pe += R_WB[b, j, r] * p_BE[i, r]
                height += normal[i, j] * pe
            d = c - height
            depth[s, i] = d
            if d < 0.0:
                continue
            # FCL: the support vector s = r^2 nE / c (n . s = c); the point
            # s (d / (2 c) - 1) in E, at mid-depth on the centre's ray.
            scale = 0.5 * d / c - 1.0
            for a in range(3):
                sv[a] = radii[i, a] * radii[i, a] * nE[a] / c * scale
            for r in range(3):  # in B, then W
                pw[r] = p_BE[i, r]
                for a in range(3):
                    pw[r] += R_BE[i, r, a] * sv[a]
            for j in range(3):
                p[j] = p_WB[b, j]
                for r in range(3):
                    p[j] += R_WB[b, j, r] * pw[r]
            # The point's Jacobian (`_add_column`, as `jacobians_kernel`),
            # then along the normal.
            for m in range(nv):
                if on_path[b, m]:
                    J[0, m] = J[1, m] = J[2, m] = 0.0
                    _add_column(w, o, t, m, p, 1.0, J, 0)
                    cols[s, i, m] = (normal[i, 0] * J[0, m] + normal[i, 1] * J[1, m]
                                     + normal[i, 2] * J[2, m])
    return cols, depth


_compiled_columns = jit.kernel(_contact_columns_kernel)


class ContactDecomposition:
    """The seat parts' contact forces from logged generalized contact forces
    (see the module docstring).  `of(hp)` builds it for a finalized
    `HumanPlant` whose contacts allow it, else returns None."""

    @classmethod
    def of(cls, hp):
        """The decomposition for `hp`, or None unless: numba compiles the
        kernel, point contact, every collision candidate is a body contact
        ellipsoid against its restraint point's seat part (a half-space on
        a link welded to the world), no friction, and the kernels know the
        plant's joints."""
        plant = hp.plant
        if _compiled_columns is None or plant.get_contact_model() != ContactModel.kPoint:
            return None
        if plant.num_velocities(hp.human) != plant.num_velocities():
            return None  # the seat moves (a cushion link)
        inspector = hp.scene_graph.model_inspector()
        points = restraint_points(hp)
        pairs = {frozenset((hp.body_geometries[pt.name][0], hp.seat_geometries[pt.part]))
                 for pt in points}
        candidates = {frozenset(pair) for pair in inspector.GetCollisionCandidates()}
        if len(pairs) != len(points) or candidates != pairs:
            return None
        for pair in pairs:
            props = [inspector.GetProximityProperties(g) for g in pair]
            if not all(p is not None and p.HasProperty("material", "coulomb_friction")
                       for p in props):
                return None
            frictions = [p.GetProperty("material", "coulomb_friction") for p in props]
            mu = CalcContactFrictionFromSurfaceProperties(*frictions)
            if mu.static_friction() != 0.0 or mu.dynamic_friction() != 0.0:
                return None
        context = plant.CreateDefaultContext()
        tree = TreeKinematics.of(plant, context, [hp.human], plant.world_frame(),
                                 plant.world_frame())
        if tree is None:
            return None
        return cls(hp, points, tree, context)

    def __init__(self, hp, points, tree: TreeKinematics, context):
        plant, inspector = hp.plant, hp.scene_graph.model_inspector()
        k = len(points)
        self.tree = tree
        self.body = np.zeros(k, np.int64)
        self.R_BE, self.p_BE = np.zeros((k, 3, 3)), np.zeros((k, 3))
        self.radii, self.normal, self.offset = np.zeros((k, 3)), np.zeros((k, 3)), np.zeros(k)
        self.part = np.array([SEAT_PART_NAMES.index(pt.part) for pt in points])
        for i, pt in enumerate(points):
            gid = hp.body_geometries[pt.name][0]
            shape = inspector.GetShape(gid)
            if not isinstance(shape, Ellipsoid):
                raise ValueError(f"contact geometry {pt.name!r} is not an ellipsoid")
            self.body[i] = int(plant.GetBodyFromFrameId(inspector.GetFrameId(gid)).index())
            X_BE = inspector.GetPoseInFrame(gid)
            self.R_BE[i], self.p_BE[i] = X_BE.rotation().matrix(), X_BE.translation()
            self.radii[i] = (shape.a(), shape.b(), shape.c())
            # The part's half-space: normal +z of its frame, through its origin.
            sid = hp.seat_geometries[pt.part]
            if not isinstance(inspector.GetShape(sid), HalfSpace):
                raise ValueError(f"seat part {pt.part!r} is not a half-space")
            seat_body = plant.GetBodyFromFrameId(inspector.GetFrameId(sid))
            X_WG = plant.EvalBodyPoseInWorld(context, seat_body).multiply(
                inspector.GetPoseInFrame(sid))
            self.normal[i] = X_WG.rotation().matrix()[:, 2]
            self.offset[i] = float(self.normal[i] @ X_WG.translation())

    #: Samples per compiled pass: the columns of a pass take CHUNK x 7 x nv
    #: doubles (about 28 MB), whatever the run's length.
    CHUNK = 16384

    def contact_forces(self, positions: np.ndarray, tau_contact: np.ndarray) -> np.ndarray:
        """The force each seat part's contacts exert on the body (N; samples
        x [pan, floor, lower_pad, upper_pad] x [x, y, z] flattened, as
        `SeatForces` without the restraints), from the plant's positions
        (samples x nq) and the human's generalized contact forces (samples
        x nv) logged at the same samples."""
        Q = np.ascontiguousarray(positions, float)
        tau = np.asarray(tau_contact, float)
        if Q.ndim != 2 or tau.ndim != 2 or len(Q) != len(tau) or tau.shape[1] != self.tree.nv:
            raise ValueError(f"positions {Q.shape} and generalized contact forces {tau.shape}: "
                             f"expected (samples, nq) and (samples, {self.tree.nv})")
        out = np.zeros((len(Q), 3 * len(SEAT_PART_NAMES)))
        for a in range(0, len(Q), self.CHUNK):
            out[a:a + self.CHUNK] = self._chunk(Q[a:a + self.CHUNK], tau[a:a + self.CHUNK])
        return out

    def _chunk(self, Q, tau):
        t = self.tree
        cols, depth = _compiled_columns(
            Q, t.jtype, t.parent, t.child, t.R_PF, t.p_PF, t.R_MC, t.p_MC, t.axis, t.q0, t.v0,
            t.nb, t.nv, t.on_path, self.body, self.R_BE, self.p_BE, self.radii, self.normal,
            self.offset)
        apart = depth < 0.0  # (their columns are zero: lambda = 0 exactly)
        M = cols @ cols.transpose(0, 2, 1)
        idx = np.arange(len(self.body))
        M[:, idx, idx] += apart
        try:
            lam = np.linalg.solve(M, cols @ tau[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:  # two contacts acting alike: least squares per sample
            lam = np.stack([np.linalg.lstsq(a.T, f, rcond=None)[0]
                            for a, f in zip(cols, tau, strict=True)])
        out = np.zeros((len(Q), len(SEAT_PART_NAMES), 3))
        for i, part in enumerate(self.part):
            out[:, part] += lam[:, i, None] * self.normal[i]
        return out.reshape(len(Q), 3 * len(SEAT_PART_NAMES))


__all__ = ["ContactDecomposition"]
