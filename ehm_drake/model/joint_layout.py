"""Where the human's joint DoFs sit in the plant's state, and the per-DoF
gain vectors (passive stiffness, PID gains) the joint systems, the
softening elements and the linear analyses read from the parameters."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import PASSIVE_GROUPS, PID_GROUPS, ModelParams


@dataclass(frozen=True)
class JointLayout:
    """Where the rotational joint DoFs (and the spinal compression DoF) sit
    in the plant's q and v, for the vectorized joint systems."""

    nq: int
    nv: int
    rot_q: np.ndarray  # (n,) indices into q of the rotational DoFs
    rot_v: np.ndarray  # (n,) indices into v
    #: (m, 3) indices into the rotational-DoF vector of each BallRpyJoint's
    #: roll, pitch, yaw (they need the Cardan rate mapping).
    ball_triplets: np.ndarray
    spine_q: int
    spine_v: int
    names: tuple[str, ...]  # "<joint>_<x|y|z>"
    joints: tuple[str, ...]
    groups: tuple[str, ...]  # passive group of each rotational DoF
    axes: tuple[int, ...]  # 0/1/2 = x/y/z Cardan axis of each rotational DoF

    @property
    def num_rotational(self) -> int:
        return len(self.rot_q)


def _per_dof(layout: JointLayout, group_of, attr: str) -> np.ndarray:
    """Value of `attr` ([x, y, z] per group) for each rotational DoF."""
    return np.array([getattr(group_of(g), attr)[axis]
                     for g, axis in zip(layout.groups, layout.axes, strict=True)])


def passive_stiffness_vector(params: ModelParams, layout: JointLayout) -> np.ndarray:
    """Cardan spring stiffness per rotational DoF, then the spinal axial one."""
    k = _per_dof(layout, lambda g: getattr(params.passive, g), "stiffness")
    return np.append(k, params.passive.spine_axial_stiffness)


#: PID group of each passive group.
PID_GROUP_OF = {g: pg for pg, joints in PID_GROUPS.items()
                for g, gj in PASSIVE_GROUPS.items() if set(gj) <= set(joints)}


def pid_vectors(params: ModelParams, layout: JointLayout) -> dict[str, np.ndarray]:
    """Per-DoF PID gains: kp, kd, ki and the integral torque limit.

    ki = (kp + passive k) / tau_I, so a joint under a constant load returns
    to its set point with time constant tau_I (paper: "about 3 s" to reach
    it = 3 tau_I); ki = 0 without integrator.
    """
    def grp(g):
        return getattr(params.pid, PID_GROUP_OF[g])

    kp = _per_dof(layout, grp, "kp")
    kd = _per_dof(layout, grp, "kd")
    limit = _per_dof(layout, grp, "integral_torque_limit")
    tau_i = np.array([grp(g).integral_time_s for g in layout.groups])
    if params.pid.integrator:
        ki = (kp + passive_stiffness_vector(params, layout)[:-1]) / tau_i
    else:
        ki = np.zeros_like(kp)
    return {"kp": kp, "ki": ki, "kd": kd, "integral_limit": limit}
