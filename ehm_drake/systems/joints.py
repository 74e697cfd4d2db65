"""Joint-space LeafSystems: passive Cardan restraints and the PID controller.

Both act on the 24 rotational joint DoFs of the model (see
`ehm_drake.model.plant.JointLayout`).

Passive joints are MADYMO-style Cardan restraints (Desai et al., Sec. II):
torsional springs on the joint's roll-pitch-yaw (Cardan) angles.  For a
`BallRpyJoint` the generalized velocity is the angular velocity w_FM_F, not
the angle rates, so a Cardan torque tau maps to the generalized force
f = N(q)^T tau, where N(q) maps w_FM_F to the angle rates; this keeps the
springs conservative at any angle.  Their dampers are the plant's joint
damping (implicit in SAP), except what a ball or universal joint cannot
carry (Drake applies its first damping entry to every axis) and, on the
implicit design, the explicit half of every damper (`model.stepping`):
that remainder acts here about the Cardan rates, rpy_dot = N(q) w, mapped
back by N^T.

The PID acts on the joint angles q (error against the reference posture)
and the joint velocities v.  Its torques are Cardan torques, as the
springs' are: on the implicit design's Cardan chains the generalized forces
themselves; on the reference design's ball joints mapped by N(q)^T at the
plant's own configuration.  (In a first version they acted on the ball joints'
angular-velocity coordinates: the same at the reference posture, but a
joint holding a static torque -- the integral action under the body's
weight -- got a stiffness ~10% off in yaw and roll, and the two designs
differed by up to 4.6% in transmissibility; see docs/history/speed.md, "Two designs".)

Both are template systems (`TemplateSystem`; float, AutoDiffXd).
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector_, LeafSystem_, ValueProducer

from ..model.joint_layout import JointLayout
from . import define_system


def rpy_rate_matrices(rpy):
    """N(q) for space-fixed x-y-z angles: rpy_dot = N @ w_FM_F.

    `rpy` has shape (n, 3); returns (n, 3, 3).  (Reference form of the
    mapping; `cardan_to_generalized` uses it expanded.)
    """
    p, y = rpy[:, 1], rpy[:, 2]
    cp, cy, sy = np.cos(p), np.cos(y), np.sin(y)
    tp = np.sin(p) / cp
    zero, one = 0.0 * p, 0.0 * p + 1.0
    return np.stack(
        [
            np.stack([cy / cp, sy / cp, zero], axis=-1),
            np.stack([-sy, cy, zero], axis=-1),
            np.stack([cy * tp, sy * tp, one], axis=-1),
        ],
        axis=-2,
    )


class _BallIndex:
    """Precomputed index arrays of the ball joints' roll, pitch, yaw."""

    def __init__(self, layout: JointLayout):
        b = layout.ball_triplets
        self.roll, self.pitch, self.yaw = b[:, 0].copy(), b[:, 1].copy(), b[:, 2].copy()


def cardan_to_generalized(ball: _BallIndex, q_rot, tau):
    """f = N(q)^T tau on the ball joints (identity on the other DoFs; `tau`
    itself when there is no ball joint)."""
    if not len(ball.roll):
        return tau
    p = q_rot[ball.pitch]
    y = q_rot[ball.yaw]
    cp, cy, sy = np.cos(p), np.cos(y), np.sin(y)
    tr, tp_, ty = tau[ball.roll], tau[ball.pitch], tau[ball.yaw]
    f = tau.copy()
    u = tr / cp + ty * np.tan(p)  # common factor of the roll and yaw terms
    f[ball.roll] = cy * u - sy * tp_
    f[ball.pitch] = sy * u + cy * tp_
    return f


def cardan_rates(ball: _BallIndex, q_rot, v_rot):
    """The Cardan angle rates of the rotational DoFs: N(q) w on the ball
    joints (whose generalized velocities are w_FM_F), v elsewhere (`v_rot`
    itself when there is no ball joint)."""
    if not len(ball.roll):
        return v_rot
    p = q_rot[ball.pitch]
    y = q_rot[ball.yaw]
    cp, cy, sy = np.cos(p), np.cos(y), np.sin(y)
    wx, wy = v_rot[ball.roll], v_rot[ball.pitch]
    u = (cy * wx + sy * wy) / cp  # common factor of the roll and yaw rates
    rates = v_rot.copy()
    rates[ball.roll] = u
    rates[ball.pitch] = cy * wy - sy * wx
    rates[ball.yaw] = v_rot[ball.yaw] + u * np.sin(p)
    return rates


def passive_torque(stiffness_and_neutral, q, v_rot, v_spine, ball: _BallIndex, implicit=None,
                   damping=None):
    """The passive restraints' generalized force on the rotational DoFs and
    the spinal compression (in `PassiveJoints`' layout: the rotational DoFs,
    then the spine): Cardan springs about their neutral angles (less the
    part `implicit` that the plant's PD actuators apply about 0) and the
    damping remainder `damping` about the Cardan rates, mapped by N(q)^T.
    `q`: the DoFs' positions in that layout; `v_rot`, `v_spine`: their
    generalized velocities."""
    n = len(q)
    tau = -stiffness_and_neutral[:n] * (q - stiffness_and_neutral[n:])
    if implicit is not None:
        tau = tau + implicit * q
    if damping is not None:
        m = len(v_rot)
        rates = cardan_rates(ball, q[:m], v_rot)
        tau[:m] = tau[:m] - damping[:m] * rates
        if damping[m] != 0.0:
            tau[m] = tau[m] - damping[m] * v_spine
    return cardan_to_generalized(ball, q, tau)


@define_system("PassiveJoints_", __name__)
def PassiveJoints_(T):
    class Impl(LeafSystem_[T]):
        """Cardan torsional springs on the rotational joints and the axial
        spring of the spinal compression DoF.

        Input ``state`` (plant [q; v]); output ``generalized_force``.
        Numeric parameter ``stiffness_and_neutral``: per rotational DoF the
        stiffness (N m/rad), then the axial stiffness (N/m); then the
        spring-free positions in the same layout (rad, m).

        `implicit` (same layout as the stiffness; implicit design): the
        stiffness about position 0 that the plant's PD actuators already
        apply (`HumanPlant.implicit_passive`, zero where the spring is
        explicit); the output is the springs' force minus that.

        `damping_remainder` (one value per rotational DoF, N m s/rad, then
        one for the spinal compression, N s/m): the joint damping the
        plant's joints do not apply (`HumanPlant.damping_remainder`: the
        ball and universal joints' per-axis excess, the implicit design's
        explicit part of each damper), applied here as -c rpy_dot about the
        Cardan rates and -c v on the spinal compression.
        """

        def _construct(self, layout: JointLayout, stiffness, neutral, implicit=None,
                       damping_remainder=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._layout = layout
            self._implicit = None if implicit is None or not np.any(implicit) \
                else np.asarray(implicit, float)
            self._damping = None if damping_remainder is None or not np.any(damping_remainder) \
                else np.asarray(damping_remainder, float)
            assert self._damping is None or self._damping.shape == (layout.num_rotational + 1,)
            self._ball = _BallIndex(layout)
            n = layout.num_rotational + 1
            stiffness = np.asarray(stiffness, float)
            neutral = np.asarray(neutral, float)
            assert stiffness.shape == (n,) and neutral.shape == (n,)
            self._init = np.concatenate([stiffness, neutral])
            self._q_index = np.append(layout.rot_q, layout.spine_q)
            self._v_index = np.append(layout.rot_v, layout.spine_v)
            self._state_port = self.DeclareVectorInputPort("state", layout.nq + layout.nv)
            self._param = self.DeclareNumericParameter(BasicVector_[T](self._init))
            self.DeclareVectorOutputPort("generalized_force", layout.nv, self._calc)

        def _construct_copy(self, other, converter=None):
            n = len(other._init) // 2
            Impl._construct(self, other._layout, other._init[:n], other._init[n:],
                            other._implicit, other._damping, converter=converter)

        @property
        def parameter_index(self):
            return self._param

        def _calc(self, context, output):
            x = self._state_port.Eval(context)
            L = self._layout
            tau = passive_torque(context.get_numeric_parameter(self._param).CopyToVector(),
                                 x[self._q_index], x[L.nq + L.rot_v], x[L.nq + L.spine_v],
                                 self._ball, self._implicit, self._damping)
            f = np.zeros(L.nv, dtype=tau.dtype)
            f[self._v_index] = tau
            output.SetFromVector(f)

    return Impl


PassiveJoints = PassiveJoints_[None]

PID_PARAMETERS = ("kp", "ki", "kd", "integral_limit", "reference")


@define_system("JointPid_", __name__)
def JointPid_(T):
    class Impl(LeafSystem_[T]):
        """Vectorized PID on every rotational joint DoF (Desai et al.).

        tau = -(Kp e + Ki z + Kd v), e = q - q_ref, where q_ref are the
        relative joint angles of the initial posture.  The integral z is a
        discrete state updated every `period` s by forward Euler; anti-windup
        keeps |Ki z| within the integral torque limit by stopping the
        integration there.

        Input ``state``; outputs ``generalized_force`` (nv) and ``torque``
        (one per rotational DoF, N m, for logging).  Numeric parameter
        ``gains``: kp, ki, kd, integral_limit, reference, each one value per
        rotational DoF, concatenated in that order (`PID_PARAMETERS`).

        The plant applies the derivative part as joint damping
        (`derivative_in_plant`) and, on the implicit design, the
        proportional part `implicit_kp` about angle 0 in its PD actuators;
        the generalized force is the PID torque minus those, mapped to the
        ball joints' coordinates by N(q)^T.  With `implicit_kp` or ball
        joints, an input ``plant_state`` gives the plant's own state (the
        PID's ``state`` may be delayed): the state the actuators see and
        the configuration at which a ball joint's torque acts.
        """

        def _construct(self, layout: JointLayout, kp, ki, kd, integral_limit, reference,
                       period: float, derivative_in_plant: bool = True, implicit_kp=None,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._layout = layout
            self._derivative_in_plant = bool(derivative_in_plant)
            self._implicit_kp = None if implicit_kp is None or not np.any(implicit_kp) \
                else np.asarray(implicit_kp, float)
            n = layout.num_rotational
            parts = [np.asarray(a, float) for a in (kp, ki, kd, integral_limit, reference)]
            for a in parts:
                assert a.shape == (n,)
            self._init = np.concatenate(parts)
            self._period = float(period)
            self._state_port = self.DeclareVectorInputPort("state", layout.nq + layout.nv)
            self._ball = _BallIndex(layout)
            if self._implicit_kp is not None or len(self._ball.roll):
                self._plant_port = self.DeclareVectorInputPort("plant_state",
                                                               layout.nq + layout.nv)
            self._param = self.DeclareNumericParameter(BasicVector_[T](self._init))
            # The integral bound |z| <= limit/ki, derived once from the gains.
            self._bound = self.DeclareCacheEntry(
                "integral bound",
                ValueProducer(allocate=lambda: AbstractValue.Make(None), calc=self._calc_bound),
                prerequisites_of_calc={self.all_parameters_ticket()},
            )
            self._z_index = self.DeclareDiscreteState(n)
            self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._update)
            self._torque_port = self.DeclareVectorOutputPort("torque", n, self._calc_torque)
            self.DeclareVectorOutputPort("generalized_force", layout.nv, self._calc_force)

        def _construct_copy(self, other, converter=None):
            n = other._layout.num_rotational
            parts = [other._init[i * n:(i + 1) * n] for i in range(5)]
            Impl._construct(self, other._layout, *parts, other._period,
                            other._derivative_in_plant, other._implicit_kp, converter=converter)

        @property
        def parameter_index(self):
            return self._param

        @property
        def integral_state_index(self):
            return self._z_index

        def _calc_torque(self, context, output):
            L = self._layout
            n = L.num_rotational
            x = self._state_port.Eval(context)
            g = context.get_numeric_parameter(self._param).CopyToVector()
            z = context.get_discrete_state(self._z_index).CopyToVector()
            e = x[L.rot_q] - g[4 * n:]
            output.SetFromVector(-(g[:n] * e + g[n:2 * n] * z + g[2 * n:3 * n] * x[L.nq + L.rot_v]))

        def _calc_force(self, context, output):
            L = self._layout
            tau = self._torque_port.Eval(context)
            if self._derivative_in_plant:
                n = L.num_rotational
                g = context.get_numeric_parameter(self._param).CopyToVector()
                x = self._state_port.Eval(context)
                tau = tau + g[2 * n:3 * n] * x[L.nq + L.rot_v]  # the plant applies -Kd v
            if self._implicit_kp is not None:  # the plant applies -Kp q
                tau = tau + self._implicit_kp * self._plant_port.Eval(context)[L.rot_q]
            if len(self._ball.roll):
                tau = cardan_to_generalized(self._ball, self._plant_port.Eval(context)[L.rot_q],
                                            tau)
            f = np.zeros(L.nv, dtype=tau.dtype)
            f[L.rot_v] = tau
            output.SetFromVector(f)

        def _calc_bound(self, context, value):
            n = self._layout.num_rotational
            g = context.get_numeric_parameter(self._param).CopyToVector()
            ki, limit = g[n:2 * n], g[3 * n:4 * n]
            # |ki z| <= limit; a joint without integral action keeps z = 0.
            bound = limit / np.where(ki > 0, ki, np.inf)
            value.set_value((bound, -bound, g[4 * n:]))

        def _update(self, context, discrete_state):
            L = self._layout
            x = self._state_port.Eval(context)
            bound, neg_bound, reference = self._bound.Eval(context)
            z = context.get_discrete_state(self._z_index).CopyToVector()
            z = z + self._period * (x[L.rot_q] - reference)
            discrete_state.get_mutable_vector(self._z_index).SetFromVector(
                np.minimum(np.maximum(z, neg_bound), bound))

    return Impl


JointPid = JointPid_[None]


@define_system("CoContraction_", __name__)
def CoContraction_(T):
    class Impl(LeafSystem_[T]):
        """Muscle co-contraction rising with the vibration level (the
        `cocontraction` effect of the gap diagnosis): extra active joint
        stiffness c * a_rms * kp on the trunk, neck and hip DoFs, where a_rms
        is the running RMS of the seat acceleration (exponential average of
        |a|^2 with time constant `tau_s`).

        Inputs ``state``, ``seat_acceleration``; output
        ``generalized_force``; discrete state: the running mean square.
        Numeric parameter: [c (1/(m/s^2)), then kp per rotational DoF (0
        where the effect does not act)]."""

        def _construct(self, layout: JointLayout, c, kp, period: float, tau_s: float = 2.0,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._args = (layout, float(c), np.asarray(kp, float), float(period), float(tau_s))
            self._layout = layout
            self._alpha = float(period) / float(tau_s)
            self._state_port = self.DeclareVectorInputPort("state", layout.nq + layout.nv)
            self._a_port = self.DeclareVectorInputPort("seat_acceleration", 3)
            self._param = self.DeclareNumericParameter(
                BasicVector_[T](np.concatenate([[c], self._args[2]])))
            self._ms = self.DeclareDiscreteState(1)
            self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
            self.DeclareVectorOutputPort("generalized_force", layout.nv, self._calc)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._args, converter=converter)

        def _update(self, context, discrete_state):
            a = self._a_port.Eval(context)
            ms = context.get_discrete_state(self._ms).CopyToVector()
            discrete_state.get_mutable_vector(self._ms).SetFromVector(
                ms + self._alpha * (a @ a - ms))

        def _calc(self, context, output):
            L = self._layout
            x = self._state_port.Eval(context)
            g = context.get_numeric_parameter(self._param).CopyToVector()
            ms = context.get_discrete_state(self._ms).CopyToVector()[0]
            rms = np.sqrt(ms + 1e-30)
            f = np.zeros(L.nv, dtype=x.dtype)
            f[L.rot_v] = -g[0] * rms * g[1:] * x[L.rot_q]
            output.SetFromVector(f)

    return Impl


CoContraction = CoContraction_[None]
