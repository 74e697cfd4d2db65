"""`ForceLaws`: the per-step force laws in one system (both designs).

The plant's own step costs about 200 us, and five Python force systems
summed by an Adder (passive joints, joint PID, head-in-space, shear
restraints, seat inertial load) cost about as much again: each read the
state, set up its kinematics, evaluated its ports and parameters, and the
PID and the restraints each had an update event.  `ForceLaws` applies the
same five laws in one pass (the functions it calls are those of the
separate systems, `ehm_drake.systems.joints`, `.his`, `.seat`): the state,
the parameters and the discrete states are read once per step, the
kinematics set up once, the generalized forces summed into one output,
and the PID integral and the restraints' slip advance in one update event
(the reference design at 1 ms: 2.0x -> 2.5x real time, 498 -> 401 us per
step; the implicit design at 5 ms: 5.7-5.9x -> 8.3x).

The laws are unchanged; the sum is ordered differently: the forces differ
from the five systems' sum by rounding (tests: 1e-12 at random states).

On float states with no separate controller input the step runs compiled
(`ehm_drake.systems.compiled_laws`, numba, and its kinematics
`.compiled_kinematics`: the same numbers to rounding), else in NumPy.

The parts keep their identities for the code that reads or changes them
in a context (the static equilibrium, the gap diagnosis' families and
extensions, tests): `ForceLaws.views` holds one `LawView` per former
system, under its name (``passive_joints``, ``joint_pid``,
``head_in_space``, ``shear_restraints``, ``seat_inertial_load``), with its
parameter index, its discrete state index, its ports
(``generalized_force``: that law's part alone, for tests and diagnosis)
and the methods the former system had.  Each view's numeric parameter has
that system's layout.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector_, LeafSystem_, ValueProducer

from ..model.joint_layout import JointLayout
from ..model.restraints import deepest_points
from . import PlantScratch, define_system
from .compiled_laws import (
    NO_CONTACTS,
    compiled_laws,
    compiled_probe,
    compiled_step,
    packed_constants,
)
from .his import head_in_space_torque
from .joints import PID_PARAMETERS, _BallIndex, cardan_to_generalized, passive_torque
from .rotations import rotation_from_rpy
from .seat import (
    SEAT_PART_NAMES,
    RestraintGeometry,
    check_restraint_parameters,
    contact_damping_force,
    restraint_axis_parameters,
    restraint_law,
    restraint_limits,
    slip_update,
)

#: What `ForceLaws` shares on the plant's scratch context at each state
#: (`PlantScratch.share`): ({point name: (index, first row in J, normal,
#: normal offset of the anchor)}, normal
#: displacement per point (point order, m), J (its first 3n rows the points'
#: translational Jacobian, body by body)).
RESTRAINT_NORMALS = "restraint normals"

#: The former force systems, in the order their parts are reported.
LAWS = ("passive_joints", "joint_pid", "head_in_space", "shear_restraints",
        "seat_inertial_load")


class LawView:
    """One law of a `ForceLaws` system under its former system's name: its
    context is the `ForceLaws` system's (`GetMyContextFromRoot`), its
    ``generalized_force`` port that law's part alone, and its parameter
    and state indices those of the law's own numeric parameter and
    discrete state group (None where it has none)."""

    def __init__(self, system, name: str, parameter_index=None, state_index=None,
                 ports: dict | None = None):
        self.system = system
        self._name = name
        self._parameter_index = parameter_index
        self._state_index = state_index
        self._ports = {"generalized_force": f"{name}_generalized_force", **(ports or {})}

    def get_name(self) -> str:
        return self._name

    @property
    def parameter_index(self):
        return self._parameter_index

    def GetMyContextFromRoot(self, root_context):  # noqa: N802  (Drake's name)
        return self.system.GetMyContextFromRoot(root_context)

    def GetMyMutableContextFromRoot(self, root_context):  # noqa: N802
        return self.system.GetMyMutableContextFromRoot(root_context)

    def HasOutputPort(self, name: str) -> bool:  # noqa: N802
        return name in self._ports

    def GetOutputPort(self, name: str):  # noqa: N802
        if name not in self._ports:
            raise RuntimeError(f"{self._name} (part of {self.system.get_name()}) has no output "
                               f"port {name!r}; it has {', '.join(sorted(self._ports))}")
        return self.system.GetOutputPort(self._ports[name])


class PidView(LawView):
    @property
    def integral_state_index(self):
        return self._state_index


class RestraintView(LawView):
    @property
    def slip_state_index(self):
        return self._state_index

    @property
    def points(self):
        return self.system.restraint_points

    def axis_deflection(self, context) -> np.ndarray:
        """Displacement of each point from its anchor along each axis
        (2n, m), before slip (`context`: the ForceLaws system's)."""
        return self.system.restraint_displacements(context)[0]

    def normal_displacement(self, context) -> np.ndarray:
        return self.system.restraint_displacements(context)[1]


class _ContactProbe:
    """The restraint points and the contact points (`contact_points_B`)
    in the same plant calls as the restraint points alone: per body one
    position query of [P_B | origin | unit tips], whose differences give
    each contact ellipsoid's normal in its body frame, m = R_WB^T n (a
    normal is a coordinate axis of S: m is a row of R_WB), and one Jacobian
    query of [P_B | C_B].  Returns the restraint points' positions (3 x n)
    and Jacobian (3n x nv), both grouped by body as in `RestraintGeometry`,
    and for each contact point (grouped order) the normal row of its
    Jacobian (n x nv) and its displacement along the normal from the
    anchor (n).  Poses and `contact_points_B` (`ShearRestraints`' form)
    give the same to rounding, at about three times the cost."""

    def __init__(self, geometry: RestraintGeometry):
        g = geometry
        axis = np.array([int(np.argmax(np.abs(pt.normal))) for pt in g.points])
        assert all(np.array_equal(pt.normal, np.eye(3)[a]) for pt, a in zip(g.points, axis,
                                                                           strict=True))
        self.probes, p_cols, o_cols, tip_cols, jp_rows, jc_rows, c_cols = \
            [], [], [], [], [], [], []
        # [P_B | C_B] of every group side by side, column-major: each group's
        # block is a contiguous view, and one assignment updates every C_B.
        self.points = np.zeros((3, 2 * g.n), order="F")
        self.blocks = []
        col = row = 0
        for (_, P_B, rows), k in zip(g.groups, g.counts, strict=True):
            self.probes.append(np.concatenate([P_B, np.zeros((3, 1)), np.eye(3)], axis=1))
            start = 2 * (row // 6)
            self.points[:, start:start + k] = P_B
            self.blocks.append(slice(start, start + 2 * k))
            c_cols += range(start + k, start + 2 * k)
            p_cols += range(col, col + k)
            o_cols += [col + k] * k
            tip_cols += [[col + k + 1, col + k + 2, col + k + 3]] * k
            jp_rows += range(row, row + 3 * k)
            jc_rows += [row + 3 * (k + i) + axis[r] for i, r in enumerate(rows)]
            col, row = col + k + 4, row + 6 * k
        self.c_cols = np.array(c_cols)
        self.views = [self.points[:, b] for b in self.blocks]
        self.p_cols, self.o_cols = np.array(p_cols), np.array(o_cols)
        self.tip_cols = np.array(tip_cols)
        self.jp_rows, self.jc_rows = np.array(jp_rows), np.array(jc_rows)
        self.axis = axis[g.order]
        self.p_BE, self.semi_axes = g.p_BE, g.semi_axes
        self.n0 = g.n0[g.order]
        self.frames = [frame for frame, _, _ in g.groups]

    def raw(self, plant, context, world):
        """(A, JJ, normal displacements): the probed positions and the
        Jacobian of every probed point as Drake gives them, the arithmetic
        compiled (`compiled_probe`); `compiled_step` selects the rows."""
        A = self._positions(plant, context, world)
        pos_n = compiled_probe(A, self.axis, self.o_cols, self.tip_cols, self.p_BE,
                               self.semi_axes, self.n0, self.points, self.c_cols)
        return A, self._jacobian(plant, context, world, self.views), pos_n

    def _positions(self, plant, context, world):
        """The probed points' positions, every group side by side (3 x m)."""
        return np.concatenate([plant.CalcPointsPositions(context, frame, probe, world)
                               for frame, probe in zip(self.frames, self.probes, strict=True)],
                              axis=1)

    def _jacobian(self, plant, context, world, points):
        """The translational Jacobian of each group's [P_B | C_B] `points`,
        stacked."""
        kv = JacobianWrtVariable.kV
        return np.concatenate([plant.CalcJacobianTranslationalVelocity(context, kv, frame, b,
                                                                        world, world)
                               for frame, b in zip(self.frames, points, strict=True)])

    def __call__(self, plant, context, world):
        A = self._positions(plant, context, world)
        o = A[self.axis, self.o_cols]  # the body origins' coordinate along the normal
        m = A[self.axis[:, None], self.tip_cols] - o[:, None]
        C = deepest_points(m, self.p_BE, self.semi_axes)
        if C.dtype == float:
            self.points[:, self.c_cols] = C.T
            points = self.views
        else:  # AutoDiffXd: no float buffer
            both = self.points.astype(object)
            both[:, self.c_cols] = C.T
            points = [both[:, b] for b in self.blocks]
        JJ = self._jacobian(plant, context, world, points)
        return (A[:, self.p_cols], JJ[self.jp_rows], JJ[self.jc_rows],
                o + np.add.reduce(m * C, axis=1) - self.n0)


class _Constants:
    """What the laws derive from the numeric parameters, once per value."""

    __slots__ = ("passive", "neg_k", "neutral", "neg_kp", "neg_ki", "neg_kd", "reference",
                 "bound", "neg_bound", "his_kp", "his_kd", "his_R_ref_T", "restraint", "packed")


class _Step:
    """The laws at one state: the generalized force and what the outputs
    and the update read (``w``: the restraints' tangential, normal and
    constraint forces, stacked as the rows of `ForceLaws`' point product;
    ``fd``: the explicit contact dampers' normal force per point, grouped
    by body, acting at the contact points, whose Jacobian's normal rows are
    the last rows of ``J``, as ``fd`` is the end of ``G``)."""

    __slots__ = ("f", "J", "G", "pid_torque", "pid_force", "passive_force", "his_torque",
                 "J_his", "w", "pos", "pos_n", "z_next", "slip_next", "fd", "seat_forces")


@define_system("ForceLaws_", __name__)
def ForceLaws_(T):
    class Impl(LeafSystem_[T]):
        """Inputs ``state`` (plant [q; v]), ``seat_acceleration`` (3,
        m/s^2) and, with `feedback_input`, ``controller_state`` (the plant
        state as the PID and head-in-space controllers see it, e.g.
        delayed; without it they read ``state``).

        Outputs ``generalized_force`` (nv: the sum of the five laws),
        ``joint_torques`` (the PID's torque per rotational DoF, N m),
        ``his_torque`` (3, N m), ``restraint_seat_forces`` (the restraints'
        force on the body per seat part, 12, N), ``point_forces``,
        ``normal_displacement``, ``deflection`` (per restraint point, as
        `ShearRestraints`), and ``<law>_generalized_force`` per law.

        Numeric parameters (one per law, each in its former system's
        layout): passive stiffness and neutral positions
        (`PassiveJoints`), PID gains (`JointPid`, `PID_PARAMETERS`),
        head-in-space gains and reference (`HeadInSpace`), the packed
        restraint vector (`ShearRestraints`).  Discrete states: the PID
        integral and the restraints' slip, advanced every `period` s.

        Arguments: `layout` (`HumanPlant.layout`); `passive` = (stiffness,
        neutral, implicit part, damping remainder) as `PassiveJoints`
        takes them; `pid` = (kp, ki, kd, integral_limit, reference,
        implicit kp) as `JointPid`; `his` = (head body, trunk body, kp, kd)
        as `HeadInSpace`; `restraints` = (points, packed parameters,
        constraints, contact damping) as `ShearRestraints`;
        `inertial_instances`: the model instances that feel the seat's
        acceleration (`SeatInertialLoad`).  The PID's derivative is the
        plant's joint damping (it is reported in ``joint_torques``).
        """

        def _construct(self, plant, layout: JointLayout, passive, pid, his, restraints,
                       inertial_instances, period: float, feedback_input: bool = False,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._args = (plant, layout, passive, pid, his, restraints, inertial_instances,
                          float(period), bool(feedback_input))
            self._layout = L = layout
            self._period = float(period)
            self._scratch = PlantScratch(plant, T)
            p = self._scratch.plant
            nq, nv = p.num_positions(), p.num_velocities()
            assert (nq, nv) == (L.nq, L.nv)
            self._nq, self._nv = nq, nv
            n_rot = L.num_rotational
            self._world = p.world_frame()
            self._ball = _BallIndex(L)

            # Passive joints.
            stiffness, neutral, implicit, damping = passive
            k_init = np.concatenate([np.asarray(stiffness, float), np.asarray(neutral, float)])
            assert k_init.shape == (2 * (n_rot + 1),)
            self._implicit = (None if implicit is None or not np.any(implicit)
                              else np.asarray(implicit, float))
            self._damping = (None if damping is None or not np.any(damping)
                             else np.asarray(damping, float))
            assert self._damping is None or self._damping.shape == (n_rot + 1,)
            self._q_index = np.append(L.rot_q, L.spine_q)
            self._v_index = np.append(L.rot_v, L.spine_v)
            self._rot_v_x = nq + L.rot_v  # the rotational velocities in [q; v]
            self._spine_v_x = nq + L.spine_v
            self._v_x = nq + self._v_index
            self._cardan_chains = not len(self._ball.roll)
            # The compiled step (`compiled_step`: two kernels) where it applies.
            self._compiled = compiled_laws is not None and T is float and not feedback_input
            self._structure = None  # (`compiled_step`'s, made at its first step)

            # Joint PID.
            *gains, implicit_kp = pid
            gains = [np.asarray(a, float) for a in gains]
            assert len(gains) == len(PID_PARAMETERS) and all(a.shape == (n_rot,) for a in gains)
            self._implicit_kp = (None if implicit_kp is None or not np.any(implicit_kp)
                                 else np.asarray(implicit_kp, float))

            # Head-in-space.
            head, trunk, his_kp, his_kd = his
            his_init = np.concatenate([np.asarray(his_kp, float), np.asarray(his_kd, float),
                                       np.zeros(3)])
            self._head_body = p.GetBodyByName(head)
            self._head = self._head_body.body_frame()
            self._trunk = p.GetBodyByName(trunk).body_frame()

            # Shear restraints.
            points, r_params, constraints, contact_damping = restraints
            r_params = np.asarray(r_params, float)
            check_restraint_parameters(r_params, len(points))
            self._points = list(points)
            self._geometry = g = RestraintGeometry(p, points)
            # Per point name: its index (point order), its three rows in J and
            # what its normal displacement is measured from (normal, n0).
            self._point_rows = {pt.name: (i, 3 * int(g.grouped_row[i]), tuple(pt.normal),
                                          float(g.n0[i]))
                                for i, pt in enumerate(points)}
            self._constraints = constraints
            self._contact_damping = (None if contact_damping is None
                                     or not np.any(contact_damping)
                                     else np.asarray(contact_damping, float))
            if self._contact_damping is not None:  # (in the grouped order)
                self._probe = _ContactProbe(g)
                self._contact_damping_g = self._contact_damping[g.order]
                self._face_g = g.face[g.order]
            # The restraints' force per seat part straight from the law's
            # axis and normal forces, stacked.
            self._seat = np.hstack([g.sum_parts @ g.A.T, g.sum_parts @ g.N.T])
            # Points stacked body by body ("grouped"): their displacements
            # along the axes and normals, [A; N] p - [a0; n0], and with the
            # plant's constraints (two per point, in point order) each
            # constraint's point less its anchor, S p - p_SQ (S selects
            # coordinates: exact), in one product.  Its transpose maps the
            # tangential, normal and constraint forces, stacked, to the
            # grouped point forces (summing a point's two constraints).
            n = g.n
            rows, offsets = [g.A_grouped, g.N_grouped], [g.a0, g.n0]
            if constraints is not None:
                S = np.zeros((6 * n, 3 * n))
                for j, row in enumerate(g.grouped_row[g.axis_of]):
                    S[3 * j:3 * j + 3, 3 * row:3 * row + 3] = np.eye(3)
                rows.append(S)
                offsets.append(constraints.p_SQ.reshape(-1))
            self._M = np.vstack(rows)
            # (Its transpose stored contiguous: the product is ~1 us faster.)
            self._M_T = np.ascontiguousarray(self._M.T)
            self._m0 = np.concatenate(offsets)

            # Seat inertial load.
            self._instances = list(inertial_instances)
            self._mass = p.CalcTotalMass(self._scratch.context, self._instances)

            # Ports, parameters, states.
            self._state_port = self.DeclareVectorInputPort("state", nq + nv)
            self._feedback_port = (self.DeclareVectorInputPort("controller_state", nq + nv)
                                   if feedback_input else None)
            self._a_port = self.DeclareVectorInputPort("seat_acceleration", 3)
            self._passive_param = self.DeclareNumericParameter(BasicVector_[T](k_init))
            self._pid_param = self.DeclareNumericParameter(
                BasicVector_[T](np.concatenate(gains)))
            self._his_param = self.DeclareNumericParameter(BasicVector_[T](his_init))
            self._restraint_param = self.DeclareNumericParameter(BasicVector_[T](r_params))
            self._z = self.DeclareDiscreteState(n_rot)
            self._slip = self.DeclareDiscreteState(2 * len(points))
            self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._update)
            self._constants = self.DeclareCacheEntry(
                "constants of the laws",
                ValueProducer(allocate=lambda: AbstractValue.Make(None),
                              calc=self._calc_constants),
                prerequisites_of_calc={self.all_parameters_ticket()})
            # Everything at one state, once per step for the plant's input,
            # the logged outputs and the update.
            self._step = self.DeclareCacheEntry(
                "the laws at this state",
                ValueProducer(allocate=lambda: AbstractValue.Make(None), calc=self._calc_step))
            self._displacements = self.DeclareCacheEntry(
                "restraint displacements",
                ValueProducer(allocate=lambda: AbstractValue.Make((None, None)),
                              calc=self._calc_displacements),
                prerequisites_of_calc={self.input_port_ticket(self._state_port.get_index())})
            n = len(points)
            for name, size, calc in (
                    ("generalized_force", nv, self._out_force),
                    ("joint_torques", n_rot, self._out_pid_torque),
                    ("his_torque", 3, self._out_his_torque),
                    ("restraint_seat_forces", 3 * len(SEAT_PART_NAMES), self._out_seat_forces),
                    ("point_forces", 3 * n, self._out_point_forces),
                    ("normal_displacement", n, self._out_normal),
                    ("deflection", 2 * n, self._out_deflection)):
                self.DeclareVectorOutputPort(name, size, calc)
            for law in LAWS:
                self.DeclareVectorOutputPort(f"{law}_generalized_force", nv,
                                             self._law_output(law))
            self.views = {
                "passive_joints": LawView(self, "passive_joints", self._passive_param),
                "joint_pid": PidView(self, "joint_pid", self._pid_param, self._z,
                                     {"torque": "joint_torques"}),
                "head_in_space": LawView(self, "head_in_space", self._his_param,
                                         ports={"torque": "his_torque"}),
                "shear_restraints": RestraintView(
                    self, "shear_restraints", self._restraint_param, self._slip,
                    {"seat_forces": "restraint_seat_forces", "point_forces": "point_forces",
                     "normal_displacement": "normal_displacement",
                     "deflection": "deflection"}),
                "seat_inertial_load": LawView(self, "seat_inertial_load"),
            }

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._args, converter=converter)

        def _discrete(self, context, group):
            """Discrete state group `group` (a read-only view on floats; a
            copy for AutoDiffXd, whose object arrays cannot be viewed)."""
            value = context.get_discrete_state(group)
            return value.get_value() if T is float else value.CopyToVector()

        # -- what other code reads ----------------------------------------------------

        def discrete_state_view(self, group: int) -> LawView:
            """The law whose discrete state is group `group` (see
            `ehm_drake.simulation.StateMap`)."""
            return self.views["joint_pid" if group == self._z else "shear_restraints"]

        @property
        def restraint_points(self):
            return self._points

        def restraint_displacements(self, context):
            """(displacement of each restraint point from its anchor along
            each axis (2n), along the normal (n)) at the context's state (m;
            see `RestraintGeometry.kinematics`).  From a cache entry that
            depends on the state input only, as `ShearRestraints`' did: code
            that reads it between taking a mutable parameter or state
            reference and writing through it (the equilibrium's seating-in,
            the gap families' equivalent directions) leaves nothing cached
            that depends on what it then writes."""
            return self._displacements.Eval(context)

        def _calc_displacements(self, context, value):
            x = self._state_port.Eval(context)
            kin = self._geometry.kinematics(self._scratch.plant, self._scratch.set_state(x),
                                            x[self._nq:])
            value.set_value((kin[1], kin[3]))

        # -- the laws -----------------------------------------------------------------

        def _calc_constants(self, context, value):
            c = _Constants()
            c.passive = context.get_numeric_parameter(self._passive_param).CopyToVector()
            n = self._layout.num_rotational
            c.neg_k, c.neutral = -c.passive[:n + 1], c.passive[n + 1:]
            g = context.get_numeric_parameter(self._pid_param).CopyToVector()
            kp, ki, kd, limit, c.reference = (g[i * n:(i + 1) * n] for i in range(5))
            # Negated once here: the torque -(kp e + ki z + kd v) is then sums
            # of products (negation is exact: the same bits, fewer operations).
            c.neg_kp, c.neg_ki, c.neg_kd = -kp, -ki, -kd
            # |ki z| <= limit; a joint without integral action keeps z = 0.
            c.bound = limit / np.where(ki > 0, ki, np.inf)
            c.neg_bound = -c.bound
            h = context.get_numeric_parameter(self._his_param).CopyToVector()
            c.his_kp, c.his_kd, c.his_R_ref_T = h[0:3], h[3:6], rotation_from_rpy(h[6:9]).T
            c.restraint = restraint_axis_parameters(
                context.get_numeric_parameter(self._restraint_param).CopyToVector(),
                self._geometry.axis_of)
            c.packed = packed_constants(self, c) if self._compiled else None
            value.set_value(c)

        def _calc_step(self, context, value):
            """The five laws at the context's state, with one Jacobian for
            every point and body they act on (rows: the restraint points
            body by body, head and upper-torso angular velocity, centre of
            mass), so that all velocities are one product with v and the
            generalized force one product with J^T."""
            s = _Step()
            if self._compiled:  # the same in two compiled kernels
                compiled_step(self, context, s)
                self._scratch.share(RESTRAINT_NORMALS, (self._point_rows, s.pos_n, s.J))
                value.set_value(s)
                return
            c = self._constants.Eval(context)
            x = self._state_port.Eval(context)
            xf = x if self._feedback_port is None else self._feedback_port.Eval(context)
            L = self._layout
            nq = self._nq
            p = self._scratch.plant
            kv = JacobianWrtVariable.kV
            W = self._world
            if self._feedback_port is not None:
                # Head-in-space on the controllers' view of the body first:
                # the scratch context then moves to the plant state.
                ctx = self._scratch.set_state(xf)
                R_WH = p.EvalBodyPoseInWorld(ctx, self._head_body).rotation().matrix()
                J_head = p.CalcJacobianAngularVelocity(ctx, kv, self._head, W, W)
                J_trunk = p.CalcJacobianAngularVelocity(ctx, kv, self._trunk, W, W)
            ctx = self._scratch.set_state(x)
            if self._feedback_port is None:
                R_WH = p.EvalBodyPoseInWorld(ctx, self._head_body).rotation().matrix()
                J_head = p.CalcJacobianAngularVelocity(ctx, kv, self._head, W, W)
                J_trunk = p.CalcJacobianAngularVelocity(ctx, kv, self._trunk, W, W)
            geometry = self._geometry
            groups = geometry.groups
            J_com = p.CalcJacobianCenterOfMassTranslationalVelocity(ctx, self._instances, kv, W, W)
            # (np.concatenate: np.vstack and np.hstack cost 1-1.5 us more in
            # Python on these small blocks.)
            if self._contact_damping is None:
                s.J = J = np.concatenate([
                    *(p.CalcJacobianTranslationalVelocity(ctx, kv, frame, P_B, W, W)
                      for frame, P_B, _ in groups), J_head, J_trunk, J_com])
                P = np.concatenate([p.CalcPointsPositions(ctx, frame, P_B, W)
                                    for frame, P_B, _ in groups], axis=1)
                pos_n_contact = NO_CONTACTS
            else:
                # The restraint points and, in the same calls, the contact
                # points, where the explicit half of each contact damper acts.
                # Their Jacobian's normal rows go last in J (velocities and
                # forces in the same products).
                P, J_P, J_contact, pos_n_contact = self._probe(p, ctx, W)
                s.J = J = np.concatenate([J_P, J_head, J_trunk, J_com, J_contact])
            V = J @ x[nq:]
            n3 = 3 * len(self._points)
            # Head-in-space.
            w_WH = V[n3:n3 + 3] if self._feedback_port is None else J_head @ xf[nq:]
            s.his_torque = tau = head_in_space_torque(c.his_kp, c.his_kd, R_WH, c.his_R_ref_T,
                                                      w_WH)
            s.J_his = J_head - J_trunk if self._feedback_port is not None else None
            # Shear restraints: the law less the plant's constraints' part.
            n2 = 2 * len(self._points)
            PV = self._M @ P.ravel(order="F") - self._m0
            VV = self._M @ V[:n3]
            s.pos, s.pos_n = PV[:n2], PV[n2:n3]
            # The points' normal displacements and Jacobian at this state for
            # the body's softening (`BodySoftening`), which would compute them
            # again.
            self._scratch.share(RESTRAINT_NORMALS, (self._point_rows, s.pos_n, J))
            slip = self._discrete(context, self._slip)
            z = self._discrete(context, self._z)
            self._elementwise_laws(s, c, x, xf, V, PV, VV, slip, z, pos_n_contact)
            F = self._M_T @ s.w
            # The sum: restraints, head-in-space (+tau on the head, -tau on
            # the trunk), inertial load -m a at the centre of mass, joints.
            s.G = np.concatenate([F, tau, -tau, -self._mass * self._a_port.Eval(context)]
                                 if self._contact_damping is None else
                                 [F, tau, -tau, -self._mass * self._a_port.Eval(context), s.fd])
            if self._feedback_port is not None:  # head-in-space mapped at xf
                s.G[n3:n3 + 6] = 0.0
                f = J.T @ s.G + s.J_his.T @ tau
            else:
                f = J.T @ s.G
            f[L.rot_v] += s.pid_force
            f[self._v_index] += s.passive_force
            s.f = f
            value.set_value(s)

        def _elementwise_laws(self, s, c, x, xf, V, PV, VV, slip, z, pos_n_contact):
            """The laws of `_calc_step` point by point and joint by joint, in
            NumPy (AutoDiffXd, a separate controller input, or no numba;
            `compiled_laws` is the same in one compiled call): the contact
            dampers, the restraints and constraints (``s.w``), the slip,
            the PID and its integral, the passive joints."""
            L = self._layout
            n2, n3 = 2 * len(self._points), 3 * len(self._points)
            pos, pos_n = s.pos, s.pos_n
            if self._contact_damping is not None:
                s.fd = contact_damping_force(self._contact_damping_g, self._face_g,
                                             pos_n_contact, V[n3 + 9:])
            face = self._geometry.face
            fmax = restraint_limits(c.restraint, face, pos_n)
            f_t, f_n = restraint_law(c.restraint, face, pos, VV[:n2], pos_n, VV[n2:n3], slip,
                                     fmax)
            if self._constraints is not None:
                # + the constraints' force at the step's start, s u (see
                # `constraint_point_forces`).
                k = self._constraints
                r = PV[n3:].reshape(-1, 3)
                d = np.sqrt(np.add.reduce(r * r, axis=1))
                u = r / d[:, None]
                sc = k.stiffness * (d - k.length) + k.step_damping * np.add.reduce(
                    u * VV[n3:].reshape(-1, 3), axis=1)
                s.w = np.concatenate([f_t, f_n, (sc[:, None] * u).reshape(-1)])
            else:
                s.w = np.concatenate([f_t, f_n])
            s.slip_next = slip_update(c.restraint, face, pos, pos_n, slip, fmax)
            # Joint PID (its derivative is the plant's joint damping; the
            # plant's PD actuators apply implicit_kp about 0) and the update
            # of its integral.  Its torques are Cardan torques, as the
            # springs': on ball joints mapped by N(q)^T at the plant's q.
            e = xf[L.rot_q] - c.reference
            s.pid_force = pi = c.neg_kp * e + c.neg_ki * z
            s.pid_torque = pi + c.neg_kd * xf[self._rot_v_x]
            if not self._cardan_chains:
                s.pid_force = cardan_to_generalized(self._ball, x[L.rot_q], pi)
            elif self._implicit_kp is not None:
                s.pid_force = pi + self._implicit_kp * x[L.rot_q]
            s.z_next = np.minimum(np.maximum(z + self._period * e, c.neg_bound), c.bound)
            # Passive joints.  On Cardan chains (no ball joint) the Cardan
            # rates are the generalized velocities and the torques the
            # generalized forces: `passive_torque` in three products.
            if self._cardan_chains:
                q = x[self._q_index]
                passive = c.neg_k * (q - c.neutral)
                if self._implicit is not None:
                    passive = passive + self._implicit * q
                if self._damping is not None:
                    passive = passive - self._damping * x[self._v_x]
                s.passive_force = passive
            else:
                s.passive_force = passive_torque(c.passive, x[self._q_index], x[self._rot_v_x],
                                                 x[self._spine_v_x], self._ball, self._implicit,
                                                 self._damping)

        def _update(self, context, discrete_state):
            s = self._step.Eval(context)
            discrete_state.set_value(self._z, s.z_next)
            discrete_state.set_value(self._slip, s.slip_next)

        # -- outputs ------------------------------------------------------------------

        def _out_force(self, context, output):
            output.SetFromVector(self._step.Eval(context).f)

        def _out_pid_torque(self, context, output):
            output.SetFromVector(self._step.Eval(context).pid_torque)

        def _out_his_torque(self, context, output):
            output.SetFromVector(self._step.Eval(context).his_torque)

        def _normal_forces(self, s):
            """The restraints' normal force per point with the explicit
            contact dampers' (part of the contact force on that seat part)."""
            n2 = 2 * len(self._points)
            f_n = s.w[n2:n2 + len(self._points)]
            return f_n if self._contact_damping is None else f_n + s.fd[self._geometry.grouped_row]

        def _out_seat_forces(self, context, output):
            s = self._step.Eval(context)
            n2 = 2 * len(self._points)  # (the compiled step's own product where compiled)
            output.SetFromVector(s.seat_forces if self._compiled else
                                 self._seat @ np.concatenate([s.w[:n2], self._normal_forces(s)]))

        def _out_point_forces(self, context, output):
            s = self._step.Eval(context)
            n2 = 2 * len(self._points)
            output.SetFromVector(self._geometry.A.T @ s.w[:n2]
                                 + self._geometry.N.T @ self._normal_forces(s))

        def _out_normal(self, context, output):
            output.SetFromVector(self._step.Eval(context).pos_n)

        def _out_deflection(self, context, output):
            output.SetFromVector(self._step.Eval(context).pos
                                 - self._discrete(context, self._slip))

        def _law_output(self, law: str):
            n3 = 3 * len(self._points)
            shear = (slice(0, n3) if self._contact_damping is None else
                     np.r_[0:n3, n3 + 9:n3 + 9 + len(self._points)])  # + contact dampers
            rows = {"shear_restraints": shear, "head_in_space": slice(n3, n3 + 6),
                    "seat_inertial_load": slice(n3 + 6, n3 + 9)}.get(law)

            def calc(context, output):
                s = self._step.Eval(context)
                if rows is not None:
                    f = s.J[rows].T @ s.G[rows]
                    if law == "head_in_space" and s.J_his is not None:
                        f = s.J_his.T @ s.his_torque
                else:
                    f = np.zeros(self._nv, dtype=s.f.dtype)
                    if law == "joint_pid":
                        f[self._layout.rot_v] = s.pid_force
                    else:
                        f[self._v_index] = s.passive_force
                output.SetFromVector(f)
            return calc

    return Impl


ForceLaws = ForceLaws_[None]
