"""How the implicit design splits each spring-damper between SAP's implicit
solve and explicit forces, so that its time step is second-order accurate.

SAP advances v+ = v + h M^-1 f, q+ = q + h N(q) v+ (symplectic Euler), with
its own elements (joint damping, contact, compliant constraints, PD
actuators) evaluated at the step's end.  A spring evaluated at the step's
start, q (symplectic Euler), is second-order accurate; a damper is not.
Evaluated at v+ it lags half a step: to first order it is the damper plus
an inerter c h / 2 (on a 5 Hz mode with damping ratio 0.3 at 5 ms, -12% of
transmissibility above resonance); evaluated at v, as an explicit force,
it leads by as much.  A spring SAP integrates implicitly, -k (q + h v+),
adds a damper h k at v+ (first order again).

So the implicit design applies each spring at the step's start and each
damper at the mean of the step's start and end velocity,
-k q - c (v + v+) / 2 (Crank-Nicolson for the damper, unconditionally
stable for damping alone):

* a joint, spine or restraint spring is an explicit force
  (`PassiveJoints`, `JointPid`, `ShearRestraints`); SAP gets half of its
  damper (joint damping; the restraints' compliant distance constraints,
  `model.restraints`) and the explicit force the other half;
* an explicit spring is stable while omega h < 2 for the fastest mode it
  drives.  Where a segment's local frequency on its explicit springs
  (`segment_frequencies`: the segment turning against its joint's and its
  child joints' springs, the lower-torso slab between L5/S1 and L4/L5
  being the fastest) reaches omega h >= `STABLE_OMEGA_H`, its stiffest
  springs become SAP PD-controlled actuators (`implicit_springs`),
  -k (q + h v+): stable at any step, and damped h k more than the model
  there (first order).  On the default body at 5 ms no spring is;
  the high-stiffness variant's trunk and neck springs are (with explicit
  springs it diverges at 3 ms; the default body at 7.5 ms);
* the contact's spring is always SAP's, k (x + tau xdot): tau = (c / 2 -
  h k) / k, clipped at zero, with the explicit part in `ShearRestraints`.

An implicit spring whose h k were taken off its damper would be the
explicit spring exactly; the PD actuators (each one a SAP constraint, about
15% of a 5 ms step's cost for all 25 DoFs) are added only where the
explicit spring would be unstable.  `ehm_drake.model.plant.step_damping_limits`
gives each spring-damper's limit and the build warns beyond it.
Measured on the linearized model against a 0.5 ms step
(`tests/test_implicit_design.py`): 0.33% median transmissibility error at
5 ms, 4.1% in the worst bin, where damping at the step's end (the design's
first version) gave 2.7% and 44%.
"""

from __future__ import annotations

import numpy as np

from ..params import ModelParams


def step_split(params: ModelParams, damping, implicit_stiffness=0.0
               ) -> tuple[np.ndarray, np.ndarray]:
    """(damping to give SAP, damping to apply explicitly at v) of a damper
    `damping`, on the implicit design; its spring is explicit, or SAP's own
    with `implicit_stiffness`.  (damping, 0) on the reference design, whose
    dampers are SAP's."""
    c = np.asarray(damping, float)
    if params.simulation.design != "implicit":
        return c, np.zeros_like(c)
    hk = params.simulation.time_step_s * np.asarray(implicit_stiffness, float)
    implicit = np.maximum(0.5 * c - hk, 0.0)
    explicit = np.maximum(c - hk - implicit, 0.0)
    return implicit, explicit


#: The spinal compression's axial spring, as `segment_frequencies` and
#: `implicit_springs` name it (the plant's prismatic joint).
SPINE_AXIAL = ("spinal_compression", "axial")

#: The largest omega h at which a joint spring stays explicit: 2 is the
#: explicit spring's limit; `joint_frequencies` is an estimate, hence the
#: margin (on the default body the lower-torso slab's pitch spring reaches
#: it at 5.9 ms; the linearized closed loop diverges at 7.5 ms).
STABLE_OMEGA_H = 1.6


def segment_frequencies(body, stiffness: dict, axial_stiffness: float,
                        implicit=frozenset()) -> dict:
    """Local angular frequency (rad/s) of each segment of `body`
    (`ehm_drake.model.anthropometry.Body`, reference posture, link frames
    parallel to S) on its explicit springs: the segment turning about its
    joint centre, axis by axis, against its own joint's spring and its
    child joints' springs on that axis, sqrt(sum k / I) (the lower-torso
    slab between L5/S1 and L4/L5 is the fastest); and the spinal
    compression's child translating against its axial spring,
    sqrt(k (1 / m_child + 1 / m_parent)).

    `stiffness`: {joint name: stiffness per Cardan axis x, y, z, 0 where the
    joint has no such DoF}; springs in `implicit` ({(joint, axis)},
    `SPINE_AXIAL` for the spinal compression) are left out.  Returns
    {(segment, axis): (omega, [the springs, as (joint, axis)])}."""
    segments = body.segments
    children = {}
    for seg in segments.values():
        if seg.parent is not None:
            children.setdefault(seg.parent, []).append(seg)
    out = {}
    for seg in segments.values():
        if seg.joint == "ball+prismatic":
            key = SPINE_AXIAL
            k = 0.0 if key in implicit else axial_stiffness
            out[(seg.name, "axial")] = (float(np.sqrt(k * (1.0 / seg.mass
                                                            + 1.0 / segments[seg.parent].mass))),
                                        [key] if k > 0 else [])
        if seg.joint_name not in stiffness:
            continue
        r = seg.com_W - seg.origin_W
        inertia = seg.inertia_W + seg.mass * (r @ r * np.eye(3) - np.outer(r, r))
        joints = [seg.joint_name] + [c.joint_name for c in children.get(seg.name, [])
                                     if c.joint_name in stiffness]
        for axis in range(3):
            springs = [(j, axis) for j in joints
                       if stiffness[j][axis] > 0 and (j, axis) not in implicit]
            k = sum(stiffness[j][axis] for j, _ in springs)
            out[(seg.name, axis)] = (float(np.sqrt(k / inertia[axis, axis])), springs)
    return out


def implicit_springs(body, stiffness: dict, axial_stiffness: float, time_step: float
                     ) -> frozenset:
    """The joint springs to integrate implicitly at `time_step` so that every
    segment's explicit springs keep omega h < `STABLE_OMEGA_H`
    (`segment_frequencies`): the stiffest spring on the fastest segment,
    one at a time.  Empty for the default body at 5 ms."""
    implicit = set()
    while True:
        freqs = segment_frequencies(body, stiffness, axial_stiffness, frozenset(implicit))
        omega, springs = max(freqs.values(), key=lambda v: v[0])
        if omega * time_step < STABLE_OMEGA_H or not springs:
            return frozenset(implicit)
        implicit.add(max(springs, key=lambda js: axial_stiffness if js[1] == "axial"
                         else stiffness[js[0]][js[1]]))


def step_damping(params: ModelParams, damping, implicit_stiffness=0.0) -> np.ndarray:
    """The damping to give SAP (`step_split`'s first part)."""
    return step_split(params, damping, implicit_stiffness)[0]


def sap_damping(params: ModelParams, damping, implicit_stiffness=0.0) -> np.ndarray:
    """The whole of a damper given to SAP, less the h k its implicit spring
    adds on the implicit design (first-order accurate): for a damper whose
    explicit part could not be applied at the right velocity (a contact on
    a seat part that moves, whose velocity the explicit laws do not read)."""
    c = np.asarray(damping, float)
    if params.simulation.design != "implicit":
        return c
    return np.maximum(c - params.simulation.time_step_s * np.asarray(implicit_stiffness, float),
                      0.0)


def central_limit(damping, implicit_stiffness) -> np.ndarray:
    """The largest step (s) at which `step_split` need not clip SAP's part
    of a damper whose spring SAP integrates, c / (2 k): beyond it that
    damper is first-order accurate, and beyond c / k over-damped."""
    k = np.asarray(implicit_stiffness, float)
    return np.asarray(damping, float) / (2.0 * np.where(k > 0, k, np.nan))
