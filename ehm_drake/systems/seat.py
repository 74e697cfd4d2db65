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

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector_, LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from ..model.plant import HumanPlant
from ..params import CONTACT_PAIRS, ModelParams
from . import SCALARS, PlantScratch

#: Seat parts, their outward normal in S, and the tangential restraint axes.
SEAT_PARTS = {
    "pan": (np.array([0.0, 0.0, 1.0]), np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])),
    "floor": (np.array([0.0, 0.0, 1.0]), np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])),
    "lower_pad": (np.array([1.0, 0.0, 0.0]), np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])),
    "upper_pad": (np.array([1.0, 0.0, 0.0]), np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])),
}
SEAT_PART_NAMES = tuple(SEAT_PARTS)


@dataclass(frozen=True)
class RestraintPoint:
    """One shear restraint: a body point, its seat anchor and two axes."""

    name: str  # the body ellipsoid's name
    pair: str  # contact pair (parameter group)
    part: str  # seat part
    body: str  # body name
    p_BP: np.ndarray  # attachment point in the body frame
    p_SA: np.ndarray  # anchor in the seat frame (before slip)
    axes: np.ndarray  # (2, 3) tangential unit vectors in S


def restraint_points(hp: HumanPlant) -> list[RestraintPoint]:
    """Restraints at each contact ellipsoid's point nearest its seat part.

    The attachment point is the ellipsoid's extreme point against the seat
    part's normal; the anchor is that point in the reference posture.
    """
    inspector = hp.scene_graph.model_inspector()
    plant = hp.plant
    context = plant.CreateDefaultContext()
    points = []
    for pair, (names, part) in CONTACT_PAIRS.items():
        normal, axes = SEAT_PARTS[part]
        for name in names:
            gid, _ = hp.body_geometries[name]
            shape = inspector.GetShape(gid)
            semi = np.array([shape.a(), shape.b(), shape.c()])
            body = plant.GetBodyFromFrameId(inspector.GetFrameId(gid))
            # Ellipsoid axes are parallel to the body frame, which is parallel
            # to S in the reference posture: extreme point along -normal.
            p_BP = inspector.GetPoseInFrame(gid).translation() - semi * normal
            X_SB = plant.EvalBodyPoseInWorld(context, body)
            points.append(RestraintPoint(name, pair, part, body.name(), p_BP,
                                         X_SB.multiply(p_BP), axes))
    return points


def restraint_parameters(params: ModelParams, points) -> np.ndarray:
    """Packed parameter vector: stiffness (n), damping (n), force limit (n)."""
    r = [getattr(params.restraints, p.pair) for p in points]
    return np.concatenate([[x.stiffness for x in r], [x.damping for x in r],
                           [x.force_limit for x in r]])


@TemplateSystem.define("ShearRestraints_", T_list=SCALARS)
def ShearRestraints_(T):
    class Impl(LeafSystem_[T]):
        """Input ``state``; outputs ``generalized_force`` (nv) and
        ``seat_forces`` (restraint force on the body summed per seat part:
        pan, floor, lower_pad, upper_pad, 3 each, N, in S).  Discrete state:
        slip of each anchor along its two axes (m).  Numeric parameter
        ``restraints``: stiffness, damping, force_limit, one value per
        restraint each (both axes)."""

        def _construct(self, plant, points, parameters, period, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._args = (plant, list(points), np.array(parameters, float), float(period))
            self._points = self._args[1]
            n = len(points)
            self._n = n
            self._scratch = PlantScratch(plant, T)
            p = self._scratch.plant
            # Points grouped per body: (frame, 3xk points, rows in the list).
            groups = {}
            for i, pt in enumerate(points):
                groups.setdefault(pt.body, []).append(i)
            self._groups = [(p.GetBodyByName(b).body_frame(),
                             np.array([points[i].p_BP for i in rows]).T, rows)
                            for b, rows in groups.items()]
            self._order = np.concatenate([rows for _, _, rows in self._groups])
            self._p_SA = np.array([pt.p_SA for pt in points])
            # Projection of the stacked point vectors (3n) onto the axes (2n).
            A = np.zeros((2 * n, 3 * n))
            for i, pt in enumerate(points):
                A[2 * i:2 * i + 2, 3 * i:3 * i + 3] = pt.axes
            self._A = A
            # The same projection for points stacked body by body, and the
            # anchor term: A p_all - A p_SA.
            perm = (3 * self._order[:, None] + np.arange(3)).reshape(-1)
            self._A_grouped = A[:, perm]
            self._a0 = A @ self._p_SA.reshape(-1)
            self._part_of = np.array([SEAT_PART_NAMES.index(pt.part) for pt in points])
            # Sum of point forces per seat part: (12, 3n).
            P = np.zeros((3 * len(SEAT_PART_NAMES), 3 * n))
            for i, k in enumerate(self._part_of):
                P[3 * k:3 * k + 3, 3 * i:3 * i + 3] = np.eye(3)
            self._sum_parts = P
            self._world = p.world_frame()
            self._nq, self._nv = p.num_positions(), p.num_velocities()
            self._state_port = self.DeclareVectorInputPort("state", self._nq + self._nv)
            self._param = self.DeclareNumericParameter(BasicVector_[T](self._args[2]))
            self._slip = self.DeclareDiscreteState(2 * n)
            self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
            self._kin = self.DeclareCacheEntry(
                "restraint kinematics",
                ValueProducer(allocate=lambda: AbstractValue.Make((None, None, None)),
                              calc=self._calc_kinematics),
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
            self._axis_of = np.repeat(np.arange(n), 2)
            self._force_port = self.DeclareVectorOutputPort(
                "point_forces", 3 * n, self._calc_point_forces)
            self.DeclareVectorOutputPort("generalized_force", self._nv, self._calc_force)
            self.DeclareVectorOutputPort("seat_forces", 3 * len(SEAT_PART_NAMES),
                                         self._calc_seat_forces)

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

        def _calc_kinematics(self, context, value):
            """Stacked point Jacobian J (3n x nv), and the deflection and
            velocity along the axes (2n each), before slip."""
            x = self._state_port.Eval(context)
            ctx = self._scratch.set_state(x)
            p = self._scratch.plant
            kv = JacobianWrtVariable.kV
            world = self._world
            pos = np.concatenate([p.CalcPointsPositions(ctx, frame, P_B, world).T.reshape(-1)
                                  for frame, P_B, _ in self._groups])
            J = np.vstack([p.CalcJacobianTranslationalVelocity(ctx, kv, frame, P_B, world, world)
                           for frame, P_B, _ in self._groups])
            # Rows are grouped per body; the projection matrix is permuted to
            # match once at construction (self._A_grouped).
            value.set_value((J, self._A_grouped @ pos - self._a0,
                             self._A_grouped @ (J @ x[self._nq:])))

        def _calc_axis_params(self, context, value):
            g = context.get_numeric_parameter(self._param).CopyToVector().reshape(3, -1)
            k, c, fmax = g[:, self._axis_of]
            limit = fmax / np.where(k > 0, k, 1.0)
            value.set_value((k, c, fmax, -fmax, limit, -limit))

        def _axis_forces(self, context):
            """Restraint force along each axis (2n), limited."""
            _, pos, vel = self._kin.Eval(context)
            k, c, fmax, neg_fmax, _, _ = self._axis_params.Eval(context)
            slip = context.get_discrete_state(self._slip).CopyToVector()
            return np.minimum(np.maximum(-k * (pos - slip) - c * vel, neg_fmax), fmax)

        def _calc_point_forces(self, context, output):
            output.SetFromVector(self._A.T @ self._axis_forces(context))

        def _calc_force(self, context, output):
            J = self._kin.Eval(context)[0]
            output.SetFromVector(J.T @ (self._A_grouped.T @ self._axis_forces(context)))

        def _calc_seat_forces(self, context, output):
            output.SetFromVector(self._sum_parts @ self._force_port.Eval(context))

        def _update(self, context, discrete_state):
            _, pos, _ = self._kin.Eval(context)
            *_, limit, neg_limit = self._axis_params.Eval(context)
            slip = context.get_discrete_state(self._slip).CopyToVector()
            # The elastic deflection may not exceed fmax/k: the anchor slides.
            delta = pos - slip
            discrete_state.get_mutable_vector(self._slip).SetFromVector(
                slip + (delta - np.minimum(np.maximum(delta, neg_limit), limit)))

    return Impl


ShearRestraints = ShearRestraints_[None]


@TemplateSystem.define("SeatInertialLoad_", T_list=SCALARS)
def SeatInertialLoad_(T):
    class Impl(LeafSystem_[T]):
        """Inputs ``state`` and ``seat_acceleration`` (3, m/s^2, in S);
        output ``generalized_force`` = -M J_com^T a_S: the inertial force
        -m_i a_S at every body's centre of mass, the seat frame being
        accelerated by a_S."""

        def _construct(self, plant, model_instance, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._args = (plant, model_instance)
            self._scratch = PlantScratch(plant, T)
            p = self._scratch.plant
            self._instances = [model_instance]
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
