"""Seat-side LeafSystems: the seat motion's inertial load and the shear
point restraints.

Seat motion.  The simulation runs in the seat frame S (= the plant's world
frame), which translates with the seat's acceleration a_S(t) and does not
rotate (the paper's excitations are translational).  In S every body feels
the inertial force -m_i a_S at its centre of mass, exactly; summed over the
bodies, the generalized force is -M J_com^T a_S (`SeatInertialLoad`).  A
body moving rigidly with the seat thus has zero motion relative to S and
absolute motion equal to the seat's.

Shear restraints (Desai et al. Sec. II).  Friction is removed from the seat
contacts; shear is carried by point restraints acting orthogonal to the
contact normal: per tangential axis, a linear spring-damper between a body
point and its seat anchor whose force is limited.  When the elastic force
exceeds the limit the anchor slides, keeping the force at the limit (the
contact slips); the slip is a discrete state.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector_, LeafSystem_, ValueProducer

from ..model.restraints import (  # noqa: F401  (re-exported: the seat's parts and points)
    SEAT_PART_NAMES,
    SEAT_PARTS,
    RestraintConstraints,
    RestraintPoint,
    contact_points_B,
    restraint_points,
)
from ..model.stepping import step_split
from ..params import CONTACT_PAIRS, ModelParams
from . import PlantScratch, define_system

#: Blocks of the packed parameter vector of ShearRestraints (n values each).
RESTRAINT_PARAMETERS = ("stiffness", "damping", "force_limit", "contact_gated",
                        "normal_cubic_stiffness", "normal_reference", "normal_linear_stiffness",
                        "normal_linear_damping", "friction_coefficient", "contact_stiffness")


def restraint_parameters(params: ModelParams, points, gated_parts=(), cubic=None,
                         friction=None) -> np.ndarray:
    """Packed parameter vector (see RESTRAINT_PARAMETERS), per restraint point:

    * shear stiffness (N/m), damping (N s/m) and force limit (N) of its pair;
    * contact_gated: 1 where the restraint acts only in contact (points on
      the parts in `gated_parts`);
    * normal_cubic_stiffness (N/m^3, `cubic`, default 0) and
      normal_reference (m, set at the static equilibrium): an extra normal
      force k3 d^3 with d the compression beyond the reference;
    * normal_linear_stiffness (N/m) and normal_linear_damping (N s/m): an
      extra linear normal spring-damper about the reference, in contact
      (0 in the model; the gap diagnosis' equivalent linearizations use it);
    * friction_coefficient (`friction`, default 0 = unused): the shear
      force is also limited to mu N, N = contact_stiffness x penetration
      the point's current normal force (Coulomb friction at the cover);
    * contact_stiffness: the pair's normal contact stiffness (N/m).
    """
    r = [getattr(params.restraints, p.pair) for p in points]
    c = [getattr(params.contact, p.pair) for p in points]
    n = len(points)

    def per_point(v):
        return np.zeros(n) if v is None else np.broadcast_to(np.asarray(v, float), (n,))

    return np.concatenate([[x.stiffness for x in r], [x.damping for x in r],
                           [x.force_limit for x in r],
                           [1.0 if p.part in gated_parts else 0.0 for p in points],
                           per_point(cubic), np.zeros(n), np.zeros(n), np.zeros(n),
                           per_point(friction), [x.stiffness for x in c]])


def contact_explicit_damping(params: ModelParams, points,
                             moving_parts: frozenset = frozenset()) -> np.ndarray:
    """Per restraint point, the explicit part of its contact pair's damping
    (N s/m; `step_split`: zero on the reference design, and against a seat
    part in `moving_parts`, whose contact damping SAP carries whole: the
    explicit part acts at the point's velocity in S, not relative to the
    part)."""
    return np.array([0.0 if CONTACT_PAIRS[p.pair][1] in moving_parts else
                     float(step_split(params, getattr(params.contact, p.pair).damping,
                                      getattr(params.contact, p.pair).stiffness)[1])
                     for p in points])


def restraint_block(vector: np.ndarray, name: str) -> np.ndarray:
    """View of block `name` of a packed restraint parameter vector."""
    nb = len(RESTRAINT_PARAMETERS)
    return np.asarray(vector).reshape(nb, -1)[RESTRAINT_PARAMETERS.index(name)]


def check_restraint_parameters(vector: np.ndarray, n: int) -> None:
    """ValueError unless `vector` holds every block of `RESTRAINT_PARAMETERS`
    for `n` points."""
    if np.asarray(vector).size != len(RESTRAINT_PARAMETERS) * n:
        raise ValueError(f"restraint parameters: expected {len(RESTRAINT_PARAMETERS)} "
                         f"blocks of {n}, got {np.asarray(vector).size} values")


class RestraintGeometry:
    """The restraint points' fixed geometry, for the vectorized force law
    (`ShearRestraints`, `ehm_drake.systems.forces.ForceLaws`): the points
    grouped per body (one Jacobian per body), the projections of the
    stacked point vectors (3n) onto the tangential axes (2n) and the
    normals (n), in point order and body by body, and the sum of the point
    forces per seat part.  `plant`: the plant (of the system's scalar type)
    whose kinematics `kinematics` evaluates."""

    def __init__(self, plant, points):
        self.points = list(points)
        n = len(points)
        self.n = n
        # Points grouped per body: (frame, 3xk points, rows in the list).
        groups = {}
        for i, pt in enumerate(points):
            groups.setdefault(pt.body, []).append(i)
        self.groups = [(plant.GetBodyByName(b).body_frame(),
                        np.array([points[i].p_BP for i in rows]).T, rows)
                       for b, rows in groups.items()]
        self.order = np.concatenate([rows for _, _, rows in self.groups])
        # Where each point (in point order) sits in the grouped order.
        self.grouped_row = np.empty(n, dtype=int)
        self.grouped_row[self.order] = np.arange(n)
        self.p_SA = np.array([pt.p_SA for pt in points])
        A = np.zeros((2 * n, 3 * n))
        Nm = np.zeros((n, 3 * n))
        for i, pt in enumerate(points):
            A[2 * i:2 * i + 2, 3 * i:3 * i + 3] = pt.axes
            Nm[i, 3 * i:3 * i + 3] = pt.normal
        self.A, self.N = A, Nm
        # The same for points stacked body by body, and the anchor terms.
        perm = (3 * self.order[:, None] + np.arange(3)).reshape(-1)
        self.A_grouped, self.N_grouped = A[:, perm], Nm[:, perm]
        self.a0, self.n0 = A @ self.p_SA.reshape(-1), Nm @ self.p_SA.reshape(-1)
        self.face = np.array([pt.face_offset for pt in points])
        self.part_of = np.array([SEAT_PART_NAMES.index(pt.part) for pt in points])
        # Sum of point forces per seat part: (12, 3n).
        P = np.zeros((3 * len(SEAT_PART_NAMES), 3 * n))
        for i, k in enumerate(self.part_of):
            P[3 * k:3 * k + 3, 3 * i:3 * i + 3] = np.eye(3)
        self.sum_parts = P
        self.axis_of = np.repeat(np.arange(n), 2)
        self.world = plant.world_frame()
        # The contact ellipsoids, body by body (`contact_kinematics`).
        self.bodies = [plant.GetBodyByName(b) for b in groups]
        self.counts = [len(rows) for _, _, rows in self.groups]
        self.splits = np.cumsum(self.counts)[:-1]
        self.p_BE = np.array([points[i].p_BE for i in self.order])
        self.semi_axes = np.array([points[i].semi_axes for i in self.order])
        self.normal_grouped = np.array([points[i].normal for i in self.order])

    def kinematics(self, plant, context, v):
        """Stacked point Jacobian J (3n x nv, rows body by body);
        displacement and velocity along the tangential axes (2n each) and
        the normals (n each); the points' positions and velocities in point
        order (n x 3), at the plant `context` with generalized velocities
        `v`."""
        pos, J = self._positions_and_jacobian(plant, context)
        vel = J @ v
        # Rows are grouped per body; the projection matrices are permuted
        # to match once at construction.
        p_pts, v_pts = np.empty((self.n, 3), dtype=pos.dtype), np.empty((self.n, 3),
                                                                        dtype=vel.dtype)
        p_pts[self.order], v_pts[self.order] = pos.reshape(-1, 3), vel.reshape(-1, 3)
        return (J, self.A_grouped @ pos - self.a0, self.A_grouped @ vel,
                self.N_grouped @ pos - self.n0, self.N_grouped @ vel, p_pts, v_pts)

    def normal_kinematics(self, plant, context):
        """The points' displacement along their normals from the anchors
        (n, as `kinematics`) and the normal rows of their Jacobian (n x nv),
        at the plant `context`: the part of `kinematics` a normal law needs."""
        pos, J = self._positions_and_jacobian(plant, context)
        return self.N_grouped @ pos - self.n0, self.N_grouped @ J

    def _positions_and_jacobian(self, plant, context):
        """The points' stacked positions (3n, body by body) and translational
        Jacobian (3n x nv), in the world."""
        kv = JacobianWrtVariable.kV
        world = self.world
        pos = np.concatenate([plant.CalcPointsPositions(context, frame, P_B, world).T.reshape(-1)
                              for frame, P_B, _ in self.groups])
        J = np.concatenate([plant.CalcJacobianTranslationalVelocity(context, kv, frame, P_B,
                                                                    world, world)
                            for frame, P_B, _ in self.groups])
        return pos, J

    def contact_points(self, plant, context) -> list:
        """Each group's contact points in its body's frame (3 x k), at
        the plant `context` (`contact_points_B`)."""
        R = np.repeat(np.array([plant.EvalBodyPoseInWorld(context, b).rotation().matrix()
                                for b in self.bodies]), self.counts, axis=0)
        C = contact_points_B(R, self.p_BE, self.semi_axes, self.normal_grouped).T
        return np.split(C, self.splits, axis=1)

    def contact_kinematics(self, plant, context, v):
        """Where each contact ellipsoid touches its seat part
        (`contact_points_B`, moving over the ellipsoid as the body turns):
        the points' stacked Jacobian (3n x nv, rows body by body, as
        `kinematics`), their displacement along the normal from the
        anchors and their velocity along it (n each, point order)."""
        kv = JacobianWrtVariable.kV
        world = self.world
        C_B = self.contact_points(plant, context)
        pos = np.concatenate([plant.CalcPointsPositions(context, frame, c, world).T.reshape(-1)
                              for (frame, _, _), c in zip(self.groups, C_B, strict=True)])
        J = np.vstack([plant.CalcJacobianTranslationalVelocity(context, kv, frame, c, world,
                                                               world)
                       for (frame, _, _), c in zip(self.groups, C_B, strict=True)])
        return J, self.N_grouped @ pos - self.n0, self.N_grouped @ (J @ v)


def restraint_axis_parameters(vector, axis_of) -> dict:
    """Per-axis stiffness, damping, force limit and slip threshold, and the
    per-point normal terms, from a packed parameter vector (derived once per
    parameter value, not every step)."""
    g = vector.reshape(len(RESTRAINT_PARAMETERS), -1)
    k, c, fmax = g[:3, axis_of]
    gated = g[3] > 0.5
    mu = g[8]
    return {
        "k": k, "c": c, "fmax": fmax, "gated": gated, "any_gated": bool(gated.any()),
        "k3": g[4], "ref": g[5], "any_cubic": bool(np.any(g[4] != 0)),
        "k_lin": g[6], "c_lin": g[7], "any_linear": bool(np.any(g[6:8] != 0)),
        "mu": mu[axis_of], "k_contact": g[9][axis_of],
        "any_friction": bool(np.any(mu > 0)),
        "k_safe": np.where(k > 0, k, 1.0)}


def in_contact(face, pos_n):
    """True where the point penetrates its seat part."""
    return np.asarray((face - pos_n) > 0, dtype=bool)


def restraint_limits(prm: dict, face, pos_n):
    """Force limit per axis: the restraint's own, and mu N with friction (N:
    the contact's elastic normal force at the point)."""
    fmax = prm["fmax"]
    if prm["any_friction"]:
        pen = np.repeat(np.maximum(face - pos_n, 0.0), 2)
        fmu = prm["mu"] * prm["k_contact"] * pen
        fmax = np.where(prm["mu"] > 0, np.minimum(fmax, fmu), fmax)
    return fmax


def restraint_law(prm: dict, face, pos, vel, pos_n, vel_n, slip, fmax=None):
    """(tangential force per axis (2n), normal force per point (n)): the
    force-limited shear spring-damper beyond the slipped anchor (gated by
    contact where asked) and the extra normal forces about the reference
    compression.  `fmax`: the force limits (`restraint_limits`) if already
    computed."""
    fmax = restraint_limits(prm, face, pos_n) if fmax is None else fmax
    f = np.minimum(np.maximum(-prm["k"] * (pos - slip) - prm["c"] * vel, -fmax), fmax)
    contact = None
    if prm["any_gated"]:
        contact = np.where(prm["gated"], in_contact(face, pos_n), True)
        f = f * np.repeat(contact, 2)
    fn = 0.0 * pos_n
    if prm["any_cubic"] or prm["any_linear"]:
        # About the reference compression, in contact only.
        d = prm["ref"] - pos_n  # extra compression (m)
        touching = in_contact(face, pos_n)
        fn = (prm["k3"] * d * d * d + prm["k_lin"] * d - prm["c_lin"] * vel_n) * touching
    return f, fn


def contact_damping_force(contact_damping, face, pos_n, vel_n):
    """The explicit part of the contact dampers (implicit design,
    `contact_damping` per point, N s/m): a normal force per point (n, N)
    while the ellipsoid penetrates its seat part, from the normal
    displacement and velocity of its contact point
    (`RestraintGeometry.contact_kinematics`), where SAP applies the rest
    of the damper."""
    return -contact_damping * vel_n * in_contact(face, pos_n)


def constraint_point_forces(constraints: RestraintConstraints, axis_of, p_pts, v_pts):
    """The restraint constraints' force on each point (n x 3, in S) at the
    step's start: -(k (d - L) + c ddot) along the unit vector from the
    anchor, c the damping SAP applies at the step's end."""
    c = constraints
    r = p_pts[axis_of] - c.p_SQ
    d = np.sqrt(np.sum(r * r, axis=1))
    u = r / d[:, None]
    d_dot = np.sum(u * v_pts[axis_of], axis=1)
    f = -(c.stiffness * (d - c.length) + c.step_damping * d_dot)[:, None] * u
    return f.reshape(len(p_pts), 2, 3).sum(axis=1)


def slip_update(prm: dict, face, pos, pos_n, slip, fmax=None):
    """The anchors' slip after a step: the elastic deflection may not exceed
    fmax/k, beyond it the anchor slides; a gated point out of contact has
    its anchor follow it (it re-attaches unloaded where the body touches
    again).  `fmax` as for `restraint_law`."""
    limit = (restraint_limits(prm, face, pos_n) if fmax is None else fmax) / prm["k_safe"]
    delta = pos - slip
    new = slip + (delta - np.minimum(np.maximum(delta, -limit), limit))
    if prm["any_gated"]:
        free = np.repeat(prm["gated"] & ~in_contact(face, pos_n), 2)
        new = np.where(free, pos, new)
    return new


@define_system("ShearRestraints_", __name__)
def ShearRestraints_(T):
    class Impl(LeafSystem_[T]):
        """The seat interface beyond Drake's contact: shear point restraints
        (per tangential axis a spring-damper with a force limit and slip),
        optionally acting only while the point is in contact (`contact_gated`:
        a unilateral back support), optionally limited by Coulomb friction
        mu N; and optional extra normal forces about a reference (static)
        compression: cubic stiffening and a linear spring-damper.

        Input ``state``; outputs ``generalized_force`` (nv),
        ``point_forces`` (3 per point, N, in S), ``seat_forces`` (force on
        the body summed per seat part: pan, floor, lower_pad, upper_pad, 3
        each), ``normal_displacement`` (per point, m, along the seat
        normal; negative = compressed) and ``deflection`` (2 per point, m,
        elastic shear deflection beyond the slipped anchor).  Discrete
        state: slip of each anchor along its two axes (m).  Numeric
        parameter: the packed vector of `RESTRAINT_PARAMETERS`.

        Implicit design (`ehm_drake.model.stepping`): `constraints`, the
        plant's restraint constraints (`HumanPlant.restraint_constraints`),
        which apply each axis' linear spring-damper implicitly; the
        generalized force is then the force law minus their force
        evaluated here at the step's start.  `contact_damping` (per point,
        N s/m): the explicit part of the contact pair's damping, applied
        along the normal at the contact point, the ellipsoid's point
        deepest into its seat part (`contact_points_B`: where SAP applies
        the rest of the damper), while it penetrates (reported in the
        point and seat forces: it is part of the contact force).  (The
        implicit design's diagram uses `ForceLaws`, which applies this law
        with the others in one system.)"""

        def _construct(self, plant, points, parameters, period, constraints=None,
                       contact_damping=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._args = (plant, list(points), np.array(parameters, float), float(period),
                          constraints, None if contact_damping is None
                          else np.array(contact_damping, float))
            self._points = self._args[1]
            self._constraints = constraints
            self._contact_damping = (self._args[5] if self._args[5] is not None
                                     and np.any(self._args[5]) else None)
            n = len(points)
            self._n = n
            check_restraint_parameters(self._args[2], n)
            self._scratch = PlantScratch(plant, T)
            p = self._scratch.plant
            self._geometry = RestraintGeometry(p, points)
            self._nq, self._nv = p.num_positions(), p.num_velocities()
            self._state_port = self.DeclareVectorInputPort("state", self._nq + self._nv)
            self._param = self.DeclareNumericParameter(BasicVector_[T](self._args[2]))
            self._slip = self.DeclareDiscreteState(2 * n)
            self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
            self._kin = self.DeclareCacheEntry(
                "restraint kinematics",
                ValueProducer(allocate=lambda: AbstractValue.Make((None,) * 7),
                              calc=self._calc_kinematics),
                prerequisites_of_calc={self.input_port_ticket(self._state_port.get_index())},
            )
            self._contact_kin = self.DeclareCacheEntry(
                "contact point kinematics",
                ValueProducer(allocate=lambda: AbstractValue.Make((None,) * 3),
                              calc=self._calc_contact_kinematics),
                prerequisites_of_calc={self.input_port_ticket(self._state_port.get_index())},
            )
            # Per-axis stiffness, damping, force limit and slip threshold,
            # derived from the parameters once (not every step).
            self._axis_params = self.DeclareCacheEntry(
                "per-axis restraint parameters",
                ValueProducer(allocate=lambda: AbstractValue.Make(None),
                              calc=self._calc_axis_params),
                prerequisites_of_calc={self.all_parameters_ticket()},
            )
            # The force law's result, computed once per state for the plant's
            # input and the logged seat forces.
            self._law = self.DeclareCacheEntry(
                "restraint forces",
                ValueProducer(allocate=lambda: AbstractValue.Make((None, None)),
                              calc=lambda context, value: value.set_value(
                                  self._calc_forces(context))))
            self._force_port = self.DeclareVectorOutputPort(
                "point_forces", 3 * n, self._calc_point_forces)
            self.DeclareVectorOutputPort("generalized_force", self._nv, self._calc_force)
            self.DeclareVectorOutputPort("seat_forces", 3 * len(SEAT_PART_NAMES),
                                         self._calc_seat_forces)
            self.DeclareVectorOutputPort("normal_displacement", n, self._calc_normal)
            self.DeclareVectorOutputPort("deflection", 2 * n, self._calc_deflection)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._args, converter=converter)

        @property
        def points(self):
            return self._points

        @property
        def slip_state_index(self):
            return self._slip

        @property
        def parameter_index(self):
            return self._param

        def axis_deflection(self, context) -> np.ndarray:
            """Displacement of each point from its anchor along each axis
            (2n, m), before slip."""
            return self._kin.Eval(context)[1]

        def normal_displacement(self, context) -> np.ndarray:
            return self._kin.Eval(context)[3]

        def _calc_kinematics(self, context, value):
            x = self._state_port.Eval(context)
            ctx = self._scratch.set_state(x)
            value.set_value(self._geometry.kinematics(self._scratch.plant, ctx, x[self._nq:]))

        def _calc_contact_kinematics(self, context, value):
            x = self._state_port.Eval(context)
            ctx = self._scratch.set_state(x)
            value.set_value(self._geometry.contact_kinematics(self._scratch.plant, ctx,
                                                              x[self._nq:]))

        def _contact_damping_force(self, context):
            """The explicit contact dampers' normal force per point (n), at
            the contact points (None without them)."""
            if self._contact_damping is None:
                return None
            _, pos_n, vel_n = self._contact_kin.Eval(context)
            return contact_damping_force(self._contact_damping, self._geometry.face, pos_n,
                                         vel_n)

        def _calc_axis_params(self, context, value):
            value.set_value(restraint_axis_parameters(
                context.get_numeric_parameter(self._param).CopyToVector(),
                self._geometry.axis_of))

        def _forces(self, context):
            """(tangential force per axis (2n), normal force per point (n))."""
            return self._law.Eval(context)

        def _calc_forces(self, context):
            _, pos, vel, pos_n, vel_n, _, _ = self._kin.Eval(context)
            return restraint_law(self._axis_params.Eval(context), self._geometry.face, pos, vel,
                                 pos_n, vel_n,
                                 context.get_discrete_state(self._slip).CopyToVector())

        def _calc_point_forces(self, context, output):
            # The contact dampers' force is reported with the point's (it is
            # part of the contact force on that seat part).
            f, fn = self._forces(context)
            fd = self._contact_damping_force(context)
            output.SetFromVector(self._geometry.A.T @ f
                                 + self._geometry.N.T @ (fn if fd is None else fn + fd))

        def _calc_force(self, context, output):
            kin = self._kin.Eval(context)
            g = self._geometry
            f, fn = self._forces(context)
            F = g.A_grouped.T @ f + g.N_grouped.T @ fn
            if self._constraints is not None:  # the plant applies them
                F = F - constraint_point_forces(self._constraints, g.axis_of, kin[5],
                                                kin[6])[g.order].reshape(-1)
            force = kin[0].T @ F
            fd = self._contact_damping_force(context)
            if fd is not None:  # at the contact points
                force = force + self._contact_kin.Eval(context)[0].T @ (g.N_grouped.T @ fd)
            output.SetFromVector(force)

        def _calc_seat_forces(self, context, output):
            output.SetFromVector(self._geometry.sum_parts @ self._force_port.Eval(context))

        def _calc_normal(self, context, output):
            output.SetFromVector(self._kin.Eval(context)[3])

        def _calc_deflection(self, context, output):
            pos = self._kin.Eval(context)[1]
            output.SetFromVector(pos - context.get_discrete_state(self._slip).CopyToVector())

        def _update(self, context, discrete_state):
            _, pos, _, pos_n, _, _, _ = self._kin.Eval(context)
            discrete_state.get_mutable_vector(self._slip).SetFromVector(slip_update(
                self._axis_params.Eval(context), self._geometry.face, pos, pos_n,
                context.get_discrete_state(self._slip).CopyToVector()))

    return Impl


ShearRestraints = ShearRestraints_[None]


@define_system("SeatInertialLoad_", __name__)
def SeatInertialLoad_(T):
    class Impl(LeafSystem_[T]):
        """Inputs ``state`` and ``seat_acceleration`` (3, m/s^2, in S);
        output ``generalized_force`` = -M J_com^T a_S: the inertial force
        -m_i a_S at the centre of mass of every body of the given model
        instance(s), the seat frame being accelerated by a_S."""

        def _construct(self, plant, model_instances, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._args = (plant, model_instances)
            self._scratch = PlantScratch(plant, T)
            p = self._scratch.plant
            self._instances = (list(model_instances) if isinstance(model_instances, (list, tuple))
                               else [model_instances])
            self._mass = p.CalcTotalMass(self._scratch.context, self._instances)
            self._world = p.world_frame()
            self._nv = p.num_velocities()
            self._state_port = self.DeclareVectorInputPort(
                "state", p.num_positions() + p.num_velocities())
            self._a = self.DeclareVectorInputPort("seat_acceleration", 3)
            self.DeclareVectorOutputPort("generalized_force", self._nv, self._calc)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._args, converter=converter)

        def _calc(self, context, output):
            a = self._a.Eval(context)
            ctx = self._scratch.set_state(self._state_port.Eval(context))
            J = self._scratch.plant.CalcJacobianCenterOfMassTranslationalVelocity(
                ctx, self._instances, JacobianWrtVariable.kV, self._world, self._world)
            output.SetFromVector(-self._mass * (J.T @ a))

    return Impl


SeatInertialLoad = SeatInertialLoad_[None]
