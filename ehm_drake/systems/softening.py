"""`BodySoftening`: the body's tissue and muscle stiffness falling with
their own recent movement (the law: `ehm_drake.model.softening`).

Elements: the seated tissue under the pelvis and thighs (one per restraint
point of those contact pairs, acting along the pan's normal at the point)
and the trunk and hip muscles (one per rotational DoF of those joint
groups, about its Cardan angle).  Each holds a running mean and variance of
its deformation (discrete state) and applies the stiffness that its RMS
movement takes away, about the running mean (so nothing at rest).

A `TemplateSystem` (float, AutoDiffXd).  Inputs ``state``; outputs
``generalized_force`` (nv), ``deformation`` (per element, m or rad),
``seat_forces`` (the tissue elements' force on the body summed per seat
part, 12, N, as the restraints' ``seat_forces``),
``movement_rms`` (per element: the RMS of its
deformation, m or rad) and ``stiffness_loss`` (per element, N/m or
N m/rad).  Discrete state: the running means, then the running variances.
Numeric parameter: ``rms_fixed`` per element, the RMS movement to use in
place of the running one when >= 0 (the equivalent-linear models freeze it
at a test's level; -1 = the running value), then ``active`` (1; 0 while the
static equilibrium is solved, when the running means are not yet where the
body rests), then ``force_offset`` per element (N or N m, 0: a force added
to the element's law, which the equivalent-linear iteration perturbs to
find how the element's force moves the body, `ehm_drake.analysis.equivalent`).

On float states one compiled call (`_softening_kernel`, numba) gives
the step's force, seat forces and next state, the NumPy methods' numbers to
rounding; AutoDiffXd and a machine without numba use the methods.

Each element applies, about its running mean, the stiffness
`element_spring` gives: a tissue element its short-range stiffness on the
contact's long-range one, a muscle element minus what it has lost
(`ehm_drake.model.softening`, "Short range on long range").
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import (
    BasicVector_,
    DiscreteStateIndex,
    LeafSystem_,
    NumericParameterIndex,
    ValueProducer,
)

from ..jit import kernel
from ..model.joint_layout import JointLayout
from ..model.softening import (
    ElementSet,
    element_spring,
    equivalent_loss,
    spring_kernel,
    stationary_rms,
)
from . import PlantScratch, define_system
from .compiled_laws import NO_BALLS, cardan_kernel, trigonometry
from .forces import RESTRAINT_NORMALS
from .joints import _BallIndex, cardan_to_generalized
from .seat import SEAT_PART_NAMES, RestraintGeometry, in_contact


@define_system("BodySoftening_", __name__)
def BodySoftening_(T):
    class Impl(LeafSystem_[T]):
        """See the module docstring.  Arguments: the plant, its
        `JointLayout`, the `ElementSet` (tissue elements first, in the
        order of `points`), the restraint points of the tissue elements,
        the muscle elements' indices into the rotational DoFs, the period."""

        def _construct(self, plant, layout: JointLayout, elements: ElementSet, points,
                       muscle_dofs, period: float, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._args = (plant, layout, elements, list(points), np.asarray(muscle_dofs, int),
                          float(period))
            self._layout = layout
            self._elements = elements
            self._scratch = PlantScratch(plant, T)
            p = self._scratch.plant
            self._nq, self._nv = p.num_positions(), p.num_velocities()
            self._n_tissue = len(points)
            self._muscle = self._args[4]
            assert self._n_tissue + len(self._muscle) == elements.n
            self._geometry = RestraintGeometry(p, points) if len(points) else None
            self._ball = _BallIndex(layout)
            self._alpha = float(period) / elements.time_constant
            self._last_spring = (None, None)
            self._shared_rows = (None, None, None)
            n = elements.n
            self._state_port = self.DeclareVectorInputPort("state", self._nq + self._nv)
            self._param = self.DeclareNumericParameter(
                BasicVector_[T](np.concatenate([np.full(n, -1.0), [1.0], np.zeros(n)])))
            self._stats = self.DeclareDiscreteState(2 * n)
            self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
            # The kinematics once per state (the force, the seat forces and the
            # update all read them).
            self._kin = self.DeclareCacheEntry(
                "softening kinematics",
                ValueProducer(allocate=lambda: AbstractValue.Make((None, None, None)),
                              calc=lambda context, value: value.set_value(
                                  self._calc_deformation_kin(context))),
                prerequisites_of_calc={self.input_port_ticket(self._state_port.get_index())})
            # The springs once per step (they depend on the running variances
            # and the parameters only).
            self._springs = self.DeclareCacheEntry(
                "softening springs",
                ValueProducer(allocate=lambda: AbstractValue.Make((None, None)),
                              calc=lambda context, value: value.set_value(
                                  self._calc_spring(context))),
                prerequisites_of_calc={
                    self.discrete_state_ticket(DiscreteStateIndex(self._stats)),
                    self.numeric_parameter_ticket(NumericParameterIndex(self._param))})
            # On float states every step's numbers in one compiled call
            # (`_softening_kernel`): the force, the seat forces and the update.
            self._compiled = T is float and _compiled_softening is not None
            if self._compiled:
                g = self._geometry
                ball = np.array([self._ball.roll, self._ball.pitch, self._ball.yaw], np.int64)
                self._kernel_constants = (
                    np.zeros(0) if g is None else np.asarray(g.face, float),
                    np.asarray(layout.rot_q, np.int64)[self._muscle],
                    np.zeros((3 * len(SEAT_PART_NAMES), 0)) if g is None else
                    np.ascontiguousarray(g.sum_parts @ g.N.T),
                    *elements._kernel_arguments,
                    np.ascontiguousarray(np.broadcast_to(self._alpha, (elements.n,)), float),
                    np.asarray(layout.rot_v, np.int64), np.asarray(self._muscle, np.int64),
                    ball, layout.num_rotational)
                self._compiled_step = self.DeclareCacheEntry(
                    "softening step", ValueProducer(
                        allocate=lambda: AbstractValue.Make(None),
                        calc=lambda context, value: value.set_value(
                            self._calc_compiled(context))))
            self.DeclareVectorOutputPort("generalized_force", self._nv, self._calc_force)
            self.DeclareVectorOutputPort("deformation", n, self._calc_deformation)
            self.DeclareVectorOutputPort("seat_forces", 3 * len(SEAT_PART_NAMES),
                                         self._calc_seat_forces)
            self.DeclareVectorOutputPort("movement_rms", n, self._calc_rms)
            self.DeclareVectorOutputPort("stiffness_loss", n, self._calc_loss)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._args, converter=converter)

        @property
        def elements(self) -> ElementSet:
            return self._elements

        @property
        def parameter_index(self):
            return self._param

        @property
        def state_index(self):
            return self._stats

        def set_active(self, context, active: bool) -> None:
            """Switch the forces on or off in this system's `context`."""
            prm = context.get_mutable_numeric_parameter(self._param)
            v = prm.CopyToVector()
            v[self._elements.n] = 1.0 if active else 0.0
            prm.SetFromVector(v)

        def set_rms(self, context, rms) -> None:
            """Freeze the RMS movement at `rms` per element (None: the running
            value) in this system's `context`."""
            prm = context.get_mutable_numeric_parameter(self._param)
            v = prm.CopyToVector()
            v[:self._elements.n] = -1.0 if rms is None else np.asarray(rms, float)
            prm.SetFromVector(v)

        def set_force_offset(self, context, offset) -> None:
            """Add `offset` (per element, N or N m; None: none) to each
            element's force in this system's `context`."""
            prm = context.get_mutable_numeric_parameter(self._param)
            v = prm.CopyToVector()
            n = self._elements.n
            v[n + 1:] = 0.0 if offset is None else np.asarray(offset, float)
            prm.SetFromVector(v)

        def rest_deformation(self, context) -> np.ndarray:
            """Each element's deformation at the context's state (`context`:
            this system's)."""
            return self._deformation(context)[0]

        def _deformation(self, context):
            """(deformation per element, the tissue points' normal Jacobian
            rows or None, in-contact flags): the tissue points' displacement
            along the seat's normal (m; negative = compressed), then the
            muscle DoFs' Cardan angles (rad)."""
            return self._kin.Eval(context)

        def _calc_deformation_kin(self, context):
            x = self._state_port.Eval(context)
            parts, Jn, touching = [], None, None
            if self._geometry is not None:
                pos_n, Jn, rows = self._normal_kinematics(x)
                if rows is not None:  # the restraints' at this state (same bits)
                    index, j_rows, sign = rows
                    pos_n, Jn = pos_n[index], sign * Jn[j_rows]
                parts.append(pos_n)
                touching = in_contact(self._geometry.face, pos_n)
            if len(self._muscle):
                parts.append(x[self._layout.rot_q][self._muscle])
            return np.concatenate(parts), Jn, touching

        def _normal_kinematics(self, x):
            """(normal displacements, Jacobian's normal rows, rows) at plant
            state x: what `ForceLaws` shared at x, with `rows` (`_rows_in`)
            saying where the tissue points are in it, or the tissue points'
            own, computed here, with `rows` None."""
            ctx = self._scratch.set_state(x)
            shared = self._scratch.shared(RESTRAINT_NORMALS)
            rows = None if shared is None else self._rows_in(shared[0])
            if rows is not None:
                return shared[1], shared[2], rows
            return (*self._geometry.normal_kinematics(self._scratch.plant, ctx), None)

        def _rows_in(self, point_rows: dict):
            """Where the tissue points' normal displacements and Jacobian
            rows lie in what `ForceLaws` shares (`RESTRAINT_NORMALS`, whose
            `point_rows` maps its points): (indices, Jacobian rows, normal
            signs (n x 1)), or None when it lacks one of them.  Each normal
            is a coordinate axis, so the rows are those of the normal
            projection exactly."""
            key = id(point_rows)
            if self._shared_rows[0] != key:
                found = None
                points = self._args[3]
                at = [point_rows.get(pt.name) for pt in points]
                normal = np.array([pt.normal for pt in points], float)
                axis = np.argmax(np.abs(normal), axis=1)
                # The same points, measured from the same anchors, along axes.
                if (all(a is not None and a[2] == tuple(pt.normal) and a[3] == n0
                        for a, pt, n0 in zip(at, points, self._geometry.n0, strict=True))
                        and np.array_equal(np.abs(normal), np.eye(3)[axis])):
                    found = (np.array([a[0] for a in at]), np.array([a[1] for a in at]) + axis,
                             normal[np.arange(len(axis)), axis][:, None])
                # (the dict is kept alive with its key: ids are not reused)
                self._shared_rows = (key, found, point_rows)
            return self._shared_rows[1]

        def _rms(self, context):
            """(RMS movement per element, running means, active, force
            offsets)."""
            n = self._elements.n
            stats = context.get_discrete_state(self._stats).CopyToVector()
            prm = context.get_numeric_parameter(self._param).CopyToVector()
            fixed = prm[:n]
            running = stationary_rms(stats[n:])
            return np.where(fixed >= 0, fixed, running), stats[:n], prm[n], prm[n + 1:]

        def active(self, context) -> float:
            """1 while the forces act, 0 while they are off (`set_active`), in
            this system's `context`."""
            return self._rms(context)[2]

        def _loss(self, context):
            rms, mean, _, _ = self._rms(context)
            return equivalent_loss(self._elements, rms), mean

        def _spring(self, context):
            """(stiffness about the running mean per element, the means, the
            force offsets)."""
            return self._springs.Eval(context)

        def _calc_spring(self, context):
            rms, mean, active, offset = self._rms(context)
            # The springs of the last RMS movements again (a linearization
            # freezes them, and moves the state, which the cache follows).
            key = (rms.tobytes(), active) if T is float else None
            if key is None or key != self._last_spring[0]:
                self._last_spring = (key, active * element_spring(self._elements, rms))
            return self._last_spring[1], mean, offset

        def _calc_compiled(self, context):
            """(force, seat forces, next discrete state) at the context's
            state on the compiled path."""
            x = self._state_port.Eval(context)
            nv = self._nv
            if self._geometry is not None:
                pos_n, J, rows = self._normal_kinematics(x)
                if rows is not None:  # the restraints' at this state
                    index, j_rows, sign = rows[0], rows[1], rows[2][:, 0]
                else:
                    index = j_rows = np.arange(len(pos_n))
                    sign = np.ones(len(pos_n))
            else:
                pos_n, J = np.zeros(0), np.zeros((0, nv))
                index = j_rows = np.zeros(0, np.int64)
                sign = np.zeros(0)
            trig = (trigonometry(self._ball, x[self._layout.rot_q])
                    if len(self._muscle) and len(self._ball.roll) else NO_BALLS)
            return _compiled_softening(
                x, pos_n, J, index, j_rows, sign,
                context.get_discrete_state(self._stats).get_value(),
                context.get_numeric_parameter(self._param).get_value(), nv, trig,
                *self._kernel_constants)

        def _calc_force(self, context, output):
            if self._compiled:
                output.SetFromVector(self._compiled_step.Eval(context)[0])
                return
            d, Jn, touching = self._deformation(context)
            k, mean, offset = self._spring(context)
            f_el = offset - k * (d - mean)
            force = np.zeros(self._nv, dtype=f_el.dtype)
            nt = self._n_tissue
            if nt:  # (Jn's rows and the forces in point order)
                force = force + Jn.T @ (f_el[:nt] * touching)
            if len(self._muscle):
                tau = np.zeros(self._layout.num_rotational, dtype=f_el.dtype)
                tau[self._muscle] = f_el[nt:]
                q_rot = self._state_port.Eval(context)[self._layout.rot_q]
                force[self._layout.rot_v] += cardan_to_generalized(self._ball, q_rot, tau)
            output.SetFromVector(force)

        def _tissue_forces(self, context):
            """The tissue elements' normal force on the body (point order)."""
            d, _, touching = self._deformation(context)
            k, mean, offset = self._spring(context)
            nt = self._n_tissue
            return (offset[:nt] - k[:nt] * (d[:nt] - mean[:nt])) * touching

        def _calc_seat_forces(self, context, output):
            if self._compiled:
                output.SetFromVector(self._compiled_step.Eval(context)[1])
                return
            if not self._n_tissue:
                output.SetFromVector(np.zeros(3 * len(SEAT_PART_NAMES)))
                return
            g = self._geometry
            output.SetFromVector(g.sum_parts @ (g.N.T @ self._tissue_forces(context)))

        def _calc_deformation(self, context, output):
            output.SetFromVector(self._deformation(context)[0])

        def _calc_rms(self, context, output):
            output.SetFromVector(self._rms(context)[0])

        def _calc_loss(self, context, output):
            output.SetFromVector(self._loss(context)[0])

        def _update(self, context, discrete_state):
            if self._compiled:
                discrete_state.get_mutable_vector(self._stats).SetFromVector(
                    self._compiled_step.Eval(context)[2])
                return
            n = self._elements.n
            d = self._deformation(context)[0]
            stats = context.get_discrete_state(self._stats).CopyToVector()
            mean, var = stats[:n], stats[n:]
            e = d - mean
            a = self._alpha
            discrete_state.get_mutable_vector(self._stats).SetFromVector(
                np.concatenate([mean + a * e, var + a * (e * e - var)]))

    return Impl


BodySoftening = BodySoftening_[None]


def _softening_kernel(x, pos_n, J, index, j_rows, sign, stats, prm, nv, trig, face, muscle_q,
                      seat_sum, k_rest, k_tissue, compliance, k_long, critical, max_loss, tissue,
                      iterations, alpha, rot_v, muscle, ball, n_rot):
    """`BodySoftening`'s step on a float state, compiled: the deformation
    (the tissue points' normal displacements `pos_n[index]` and Jacobian
    rows `sign J[j_rows]`, shared by `ForceLaws`; the muscle DoFs' angles),
    the springs at the RMS movement (`element_spring`), the elements'
    forces about the running means mapped to the generalized force, the
    tissue's forces summed per seat part (`seat_sum`: sum_parts N^T) and
    the running means and variances advanced.  The NumPy methods'
    operations; their products are loops here (the same numbers to
    rounding: tests/test_softening.py).  Returns (force, seat forces, next
    state)."""
    n = stats.shape[0] // 2
    nt = index.shape[0]
    d = np.empty(n)
    for i in range(nt):
        d[i] = pos_n[index[i]]
    for j in range(n - nt):
        d[nt + j] = x[muscle_q[j]]
    s = np.empty(n)
    for i in range(n):
        s[i] = prm[i] if prm[i] >= 0 else np.sqrt(max(stats[n + i], 0.0) + 1e-30)
    k = spring_kernel(s, k_rest, k_tissue, compliance, k_long, critical, max_loss, tissue,
                      iterations)
    active = prm[n]
    force = np.zeros(nv)
    tissue_force = np.empty(nt)
    for i in range(nt):
        f_el = prm[n + 1 + i] - active * k[i] * (d[i] - stats[i])
        fi = f_el * (1.0 if (face[i] - d[i]) > 0 else 0.0)
        tissue_force[i] = fi
        for c in range(nv):
            force[c] += sign[i] * J[j_rows[i], c] * fi
    if n > nt:
        tau = np.zeros(n_rot)
        for j in range(n - nt):
            tau[muscle[j]] = prm[n + 1 + nt + j] - active * k[nt + j] * (d[nt + j] - stats[nt + j])
        if ball.shape[1]:
            tau = cardan_kernel(tau, ball, trig)
        for i in range(n_rot):
            force[rot_v[i]] += tau[i]
    seat = np.zeros(seat_sum.shape[0])
    for r in range(seat_sum.shape[0]):
        for i in range(nt):
            seat[r] += seat_sum[r, i] * tissue_force[i]
    nxt = np.empty(2 * n)
    for i in range(n):
        e = d[i] - stats[i]
        nxt[i] = stats[i] + alpha[i] * e
        nxt[n + i] = stats[n + i] + alpha[i] * (e * e - stats[n + i])
    return force, seat, nxt


#: `_softening_kernel` compiled, or None without numba (the NumPy methods serve).
_compiled_softening = kernel(_softening_kernel)


def softening_initial_state(elements: ElementSet, deformation) -> np.ndarray:
    """The system's discrete state at rest at `deformation` (per element):
    the means there, no variance."""
    return np.concatenate([np.asarray(deformation, float), np.zeros(elements.n)])


__all__ = ["BodySoftening", "BodySoftening_", "softening_initial_state"]
