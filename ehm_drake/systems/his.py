"""Head-in-space (HIS) controller (Desai et al., Fig. 2).

A vestibular/visual PD law on the head's orientation in the world (seat)
frame: tau_W = -(Kp * e + Kd * w_WH), where e are the roll, pitch, yaw
(about the world x, y, z axes) of the rotation R_WH R_ref^T that takes the
reference head orientation to the current one, and w_WH is the head's
angular velocity.  The torque acts at the neck: +tau on the head and -tau on
the upper torso, the torque pair of the neck muscles spanning C7/T1 to
C0/C1; as generalized force f = (J_w,head - J_w,trunk)^T tau.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector_, LeafSystem_, ValueProducer

from . import PlantScratch, define_system
from .rotations import rotation_from_rpy, rpy_from_rotation


def head_in_space_torque(kp, kd, R_WH, R_ref_T, w_WH):
    """tau_W = -(Kp e + Kd w_WH), e the roll, pitch, yaw of R_WH R_ref^T
    (`R_ref_T`: the reference head orientation, transposed)."""
    return -(kp * rpy_from_rotation(R_WH @ R_ref_T) + kd * w_WH)


@define_system("HeadInSpace_", __name__)
def HeadInSpace_(T):
    class Impl(LeafSystem_[T]):
        """Input ``state`` (plant [q; v]); outputs ``generalized_force``
        (nv) and ``torque`` (tau_W, 3, N m).  Numeric parameter ``gains``:
        kp (3), kd (3) about the world x, y, z, and the reference head
        orientation as roll, pitch, yaw (3)."""

        def _construct(self, plant, head_name, trunk_name, kp, kd,
                       reference_rpy=(0.0, 0.0, 0.0), converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._args = (plant, head_name, trunk_name, np.array(kp, float),
                          np.array(kd, float), np.array(reference_rpy, float))
            self._scratch = PlantScratch(plant, T)
            p = self._scratch.plant
            self._head = p.GetBodyByName(head_name).body_frame()
            self._trunk = p.GetBodyByName(trunk_name).body_frame()
            self._world = p.world_frame()
            self._head_body = p.GetBodyByName(head_name)
            nq, nv = p.num_positions(), p.num_velocities()
            self._nq, self._nv = nq, nv
            self._state_port = self.DeclareVectorInputPort("state", nq + nv)
            self._param = self.DeclareNumericParameter(
                BasicVector_[T](np.concatenate(self._args[3:6])))
            # The torque and its generalized force, computed once per state
            # for both outputs (the logged torque and the plant's input).
            self._cache = self.DeclareCacheEntry(
                "head-in-space torque",
                ValueProducer(allocate=lambda: AbstractValue.Make((None, None)),
                              calc=self._calc_cache))
            self._torque_port = self.DeclareVectorOutputPort("torque", 3, self._calc_torque)
            self.DeclareVectorOutputPort("generalized_force", nv, self._calc_force)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._args, converter=converter)

        @property
        def parameter_index(self):
            return self._param

        def _kinematics(self, context):
            x = self._state_port.Eval(context)
            ctx = self._scratch.set_state(x)
            p = self._scratch.plant
            R_WH = p.EvalBodyPoseInWorld(ctx, self._head_body).rotation().matrix()
            kv = JacobianWrtVariable.kV
            J = (p.CalcJacobianAngularVelocity(ctx, kv, self._head, self._world, self._world),
                 p.CalcJacobianAngularVelocity(ctx, kv, self._trunk, self._world, self._world))
            return x, R_WH, J

        def _tau(self, context, x, R_WH, J_head):
            g = context.get_numeric_parameter(self._param).CopyToVector()
            return head_in_space_torque(g[0:3], g[3:6], R_WH, rotation_from_rpy(g[6:9]).T,
                                        J_head @ x[self._nq:])

        def _calc_cache(self, context, value):
            x, R_WH, (J_head, J_trunk) = self._kinematics(context)
            tau = self._tau(context, x, R_WH, J_head)
            value.set_value((tau, (J_head - J_trunk).T @ tau))

        def _calc_torque(self, context, output):
            output.SetFromVector(self._cache.Eval(context)[0])

        def _calc_force(self, context, output):
            output.SetFromVector(self._cache.Eval(context)[1])

    return Impl


HeadInSpace = HeadInSpace_[None]
