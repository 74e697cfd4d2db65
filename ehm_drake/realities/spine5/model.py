"""The `spine5` plant and its one force system.

The plant is a discrete `MultibodyPlant` (1 ms, SAP; no geometry: all
contact is this module's own) expressed in the seat frame S, which
translates with the seat: every body feels the inertial load -m a_seat
(generalized force -M J_com^T a_seat), so the seat motion needs no body of
its own and the motion relative to the seat is exact.

`Spine5Forces` (one Python `LeafSystem`, its contact and muscle laws compiled
by numba in `kernel` with the NumPy laws as reference and fallback) computes,
once per step, from the plant state and its own discrete state:

* seat contact: unilateral linear spring-dampers normal to the pan, the
  back-rest pads and the floor at 33 skin points, with elastic-plastic
  tangential springs (stick-slip Coulomb friction, anchors in the state),
  optionally stiffening with dynamic compression (foam) and with the pan on
  a cushion body;
* passive joints: a standard linear solid per revolute DoF, k_par q +
  k_mx (q - q_d) with the Maxwell dashpot state q_d relaxing with time
  constant tau; plus the joint damping, which SAP treats implicitly;
* muscle torque generators: T = T_max tanh(a - k_i e / T_max), e the joint
  angle from its set point, k_i the intrinsic (short-range, instantaneous)
  muscle stiffness; first-order activation a -> a_ff + u / T_max (a_ff holds
  the settled posture, time constant tau_act), u a PD command on the joint
  angles and rates delayed by the neural delay, plus the vestibular
  head-in-space PD (delayed) on the C0/C1 and C7/T1 joints; k_i, k_p, k_d
  scaled by co-contraction;
* the palm-thigh soft-tissue springs of the `arms` effect and the cushion
  spring of `seat_cushion_dynamics`;
* the inertial load of the seat acceleration.

The force system's discrete state (Maxwell states, activations, the delay
ring buffer, friction anchors, the foam's slow compression, the running mean
square of the seat acceleration) is updated by an unrestricted periodic
event, like the plant's own step, so both read the same pre-step state; the
forces are computed once per step (memoized for the update).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.plant import DiscreteContactApproximation, MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    PrismaticJoint,
    PrismaticSpring,
    RevoluteJoint,
    RigidBody,
    RotationalInertia,
    RpyFloatingJoint,
    SpatialInertia,
)

from .body import BodyModel, G, build_body

TIME_STEP = 1.0e-3
#: Axes of a 3-DoF joint (three revolutes, gimbal), parent to child, along the
#: seat axes in the reference pose: y (flexion-extension), x (spine: lateral
#: bending; hip: rotation about the thigh), z (spine: axial rotation; hip:
#: ab-adduction).
BALL_AXES = (("y", (0.0, 1.0, 0.0)), ("x", (1.0, 0.0, 0.0)), ("z", (0.0, 0.0, 1.0)))
#: Joint group of each body's proximal joint.
GROUP = {"lumbar": "lumbar", "lower_thorax": "lumbar", "upper_thorax": "thoracic",
         "cervical": "neck", "head": "neck", "thigh_l": "hip", "thigh_r": "hip",
         "shank_l": "knee", "shank_r": "knee", "foot_l": "ankle", "foot_r": "ankle",
         "upper_arm_l": "shoulder", "upper_arm_r": "shoulder", "forearm_l": "elbow",
         "forearm_r": "elbow"}
#: Anatomical joint names (for messages).
JOINT_LABEL = {"lumbar": "L5/S1", "lower_thorax": "T12/L1", "upper_thorax": "T6/T7",
               "cervical": "C7/T1", "head": "C0/C1", "thigh_l": "hip_l", "thigh_r": "hip_r",
               "shank_l": "knee_l", "shank_r": "knee_r", "foot_l": "ankle_l",
               "foot_r": "ankle_r", "upper_arm_l": "shoulder_l", "upper_arm_r": "shoulder_r",
               "forearm_l": "elbow_l", "forearm_r": "elbow_r", "viscera": "viscera",
               "cushion": "cushion"}
COCONTRACTION_GROUPS = ("lumbar", "thoracic", "neck", "hip")
#: Largest stiffening of the seat foam (secant factor at large dynamic
#: compression): densified polyurethane foam stiffens several-fold.
FOAM_MAX_FACTOR = 6.0
#: The channels' segments and the bodies carrying their markers (whose poses
#: the force system evaluates each step; the head's also feeds the vestibular
#: loop).
MARKER_SEGMENTS = ("pelvis", "trunk", "head", "knee_l", "knee_r")
POSE_BODIES = ("pelvis", "lower_thorax", "head", "thigh_l", "thigh_r")


#: Arm joint damping per unit of the joint's static stiffness, s (see
#: `Spine5Model._arm_gains`).
ARM_DAMPING_PER_STIFFNESS_S = 0.05


class Spine5Diverged(RuntimeError):
    """The simulation left the physical range (time, body, quantity)."""


@dataclass
class JointDofs:
    """Per revolute DoF (muscle-driven) arrays, in plant velocity order."""

    names: list
    labels: list
    iq: np.ndarray
    iv: np.ndarray
    group: list
    k_par: np.ndarray
    k_mx: np.ndarray
    decay: np.ndarray  # exp(-h / tau) of the Maxwell element
    ki: np.ndarray  # intrinsic (instantaneous) muscle stiffness
    kp: np.ndarray
    kd: np.ndarray
    tmax: np.ndarray
    cc_mask: np.ndarray


def _spatial_inertia(seg) -> SpatialInertia:
    """Inertia of a segment about its body origin (the joint centre)."""
    c = seg.com - seg.origin
    inertia = seg.inertia
    I = RotationalInertia(inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1],
                          inertia[0, 2], inertia[1, 2])
    return SpatialInertia.MakeFromCentralInertia(seg.mass, c, I)


class Spine5Model:
    """The plant of one subject with its effects, and its force system."""

    def __init__(self, values: dict[str, float], effects: dict[str, dict[str, float]]):
        self.v = dict(values)
        self.effects = effects
        self.body: BodyModel = build_body(values, effects)
        self.h = TIME_STEP
        self._build_plant()
        self._build_dofs()

    def _arm_gains(self, group: str) -> dict[str, float]:
        """Joint gains of a shoulder or elbow DoF (`arms` effect): reflex
        stiffness kp from the effect (the elbow half the shoulder's),
        intrinsic stiffness ki half of it, reflex rate gain kd 0.08 kp;
        passive capsule k_par 5 (3) N m/rad; T_max 60 (50) N m (TMAX).

        Joint damping b proportional to the joint's static stiffness,
        b = 0.05 s x (k_par + ki + kp): muscle viscosity rises with the
        stiffness (Dolan et al. 1993, IEEE SMC 23:698: joint damping follows
        joint stiffness and inertia; two-joint arm models take B = 0.05 K,
        e.g. PMC2784227 Table 1).  At the relaxed end (kp 12) b is 1.2 N m s/rad
        at the shoulder, at the firm end (kp 300) 23.  With a fixed 0.4 N m
        s/rad the delayed reflex loop (kd and kp through the 30 ms delay and
        the activation) was unstable on many subjects: a ~5 Hz shoulder
        abduction-rotation mode grew at ~4/s from rest (5 of the 8 arms
        trials of the blind runs with seeds 2034-2036 diverged)."""
        kp_s = self.effects["arms"]["shoulder_kp"]
        if group == "shoulder":
            k_par, kp, tmax = 5.0, kp_s, 60.0
        else:
            k_par, kp, tmax = 3.0, 0.5 * kp_s, 50.0
        ki = 0.5 * kp
        return {"k_par": k_par, "kp": kp, "ki": ki, "kd": 0.08 * kp, "tmax": tmax,
                "b": ARM_DAMPING_PER_STIFFNESS_S * (k_par + ki + kp)}

    # ------------------------------------------------------------------ plant
    def _build_plant(self):
        plant = MultibodyPlant(self.h)
        plant.set_discrete_contact_approximation(DiscreteContactApproximation.kSap)
        segs = self.body.segments
        self.rb: dict[str, RigidBody] = {}
        for name, seg in segs.items():
            self.rb[name] = plant.AddRigidBody(name, _spatial_inertia(seg))
        self.joints: dict[str, list] = {}  # body -> [(joint name, axis letter)]
        world = plant.world_frame()
        v = self.v

        def damping(group):
            if group in ("shoulder", "elbow"):
                return self._arm_gains(group)["b"]
            return {"lumbar": v["b_lumbar"], "thoracic": v["b_thoracic"], "neck": v["b_neck"],
                    "hip": v["b_hip"], "knee": v["b_knee"], "ankle": v["b_ankle"]}[group]

        for name, seg in segs.items():
            child = self.rb[name]
            if seg.joint == "floating":
                plant.AddJoint(RpyFloatingJoint(f"{name}_float", world, child.body_frame()))
                self.joints[name] = [(f"{name}_float", "float")]
                continue
            if seg.joint == "prismatic_z":  # the cushion, from the seat frame
                j = plant.AddJoint(PrismaticJoint(f"{name}_z", world, child.body_frame(),
                                                  [0.0, 0.0, 1.0]))
                self.joints[name] = [(j.name(), "z")]
                continue
            parent = self.rb[seg.parent]
            X_PJ = RigidTransform(seg.origin - segs[seg.parent].origin)
            frame = plant.AddFrame(FixedOffsetFrame(f"{name}_jf", parent.body_frame(), X_PJ))
            if seg.joint == "ball":
                axes = BALL_AXES
            elif seg.joint == "revolute_y":
                axes = BALL_AXES[:1]
            elif seg.joint == "ankle":
                axes = BALL_AXES[:2]
            elif seg.joint == "prismatic_xz":
                axes = (("x", (1.0, 0.0, 0.0)), ("z", (0.0, 0.0, 1.0)))
            else:
                raise ValueError(seg.joint)
            prev = frame
            self.joints[name] = []
            for i, (letter, axis) in enumerate(axes):
                last = i == len(axes) - 1
                nxt = child if last else plant.AddRigidBody(f"{name}_g{i}", SpatialInertia.Zero())
                jn = f"{name}_{letter}"
                if seg.joint == "prismatic_xz":
                    plant.AddJoint(PrismaticJoint(jn, prev, nxt.body_frame(), axis))
                else:
                    plant.AddJoint(RevoluteJoint(jn, prev, nxt.body_frame(), axis,
                                                 damping(GROUP[name])))
                self.joints[name].append((jn, letter))
                prev = nxt.body_frame()
        self._add_effect_elements(plant)
        plant.Finalize()
        self.plant = plant
        self.nq, self.nv = plant.num_positions(), plant.num_velocities()
        assert self.nq == self.nv
        self.float_joint = plant.GetJointByName("pelvis_float")
        self.iq_float = np.arange(self.float_joint.position_start(),
                                  self.float_joint.position_start() + 6)
        self.passive_names = [jn for b in ("viscera", "cushion") if b in self.joints
                              for jn, _ in self.joints[b]]
        self.iq_passive = np.array([plant.GetJointByName(n).position_start()
                                    for n in self.passive_names], dtype=int)
        self.total_mass = float(sum(s.mass for s in self.body.segments.values()))

    def _add_effect_elements(self, plant):
        segs = self.body.segments
        ef = self.effects
        if "viscera" in segs:
            e = ef["visceral_mass"]
            m = segs["viscera"].mass
            for letter, f in (("x", e["freq_x_hz"]), ("z", e["freq_z_hz"])):
                j = plant.GetJointByName(f"viscera_{letter}")
                w = 2 * math.pi * f
                k = m * w * w
                # Preloaded in z: at q = 0 the spring carries the mass.
                q0 = m * G / k if letter == "z" else 0.0
                plant.AddForceElement(PrismaticSpring(j, q0, k))
                j.set_default_damping(2 * e["damping_ratio"] * m * w)
        if "cushion" in segs:
            e = ef["seat_cushion_dynamics"]
            j = plant.GetJointByName("cushion_z")
            k = e["stiffness"]
            # The spring itself is in the force system (its preload is set
            # after the statics, see set_cushion_preload).
            m_eff = segs["cushion"].mass + 0.85 * self.body.total_mass  # pan share
            j.set_default_damping(2 * e["damping_ratio"] * math.sqrt(k * m_eff))

    def set_cushion_preload(self, forces, load_n: float):
        """Spring free position so that the cushion carries `load_n` plus its
        own weight at q = 0."""
        k = self.effects["seat_cushion_dynamics"]["stiffness"]
        m = self.body.segments["cushion"].mass
        forces.cushion_z0 = (load_n + m * G) / k

    # ------------------------------------------------------------------ dofs
    def _build_dofs(self):
        v, plant = self.v, self.plant
        names, labels, iq, iv, group = [], [], [], [], []
        kpar, kmx, tau, ki, kp, kd, tmax = [], [], [], [], [], [], []
        ratio = {"y": 1.0, "x": v["axis_lateral"], "z": v["axis_axial"]}
        tscale = {"y": 1.0, "x": 0.8, "z": 0.5}
        for body, js in self.joints.items():
            if body in ("pelvis", "viscera", "cushion"):
                continue
            g = GROUP[body]
            for jn, letter in js:
                j = plant.GetJointByName(jn)
                names.append(jn)
                labels.append(f"{JOINT_LABEL[body]} {letter}")
                iq.append(j.position_start())
                iv.append(j.velocity_start())
                group.append(g)
                if g in ("shoulder", "elbow"):
                    a = self._arm_gains(g)
                    kpar.append(a["k_par"])
                    kmx.append(a["k_par"])
                    tau.append(v["tau_limb"])
                    ki.append(a["ki"])
                    kp.append(a["kp"])
                    kd.append(a["kd"])
                    tmax.append(a["tmax"])
                    continue
                r = ratio[letter] if js[0][1] == "y" and len(js) == 3 else 1.0
                k0 = v[f"k_{g}"] * r
                kpar.append(k0)
                kmx.append(k0 * v["maxwell_ratio"])
                tau.append(v["tau_spine"] if g in ("lumbar", "thoracic") else
                           v["tau_neck"] if g == "neck" else v["tau_limb"])
                ki.append(v[f"ki_{g}"])
                kp.append(v[f"kp_{g}"])
                kd.append(v[f"kd_{g}"])
                tmax.append(v[f"tmax_{g}"] * (tscale[letter] if len(js) == 3 else 1.0))
        self.dofs = JointDofs(
            names, labels, np.array(iq), np.array(iv), group, np.array(kpar), np.array(kmx),
            np.exp(-self.h / np.array(tau)), np.array(ki), np.array(kp), np.array(kd),
            np.array(tmax),
            np.array([g in COCONTRACTION_GROUPS for g in group], float))
        # Vestibular: head-in-space rotation (S axes) onto the C0/C1 and C7/T1
        # DoFs, half each.
        idx = {n: i for i, n in enumerate(names)}
        self.vest_rows = np.array([idx[f"{b}_{a}"] for b in ("head", "cervical")
                                   for a in ("y", "x", "z")])
        self.vest_cols = np.array([1, 0, 2, 1, 0, 2])

    # ------------------------------------------------------------------ states
    def reference_positions(self) -> np.ndarray:
        """All joint angles zero, the pelvis at its reference pose."""
        q = np.zeros(self.nq)
        q[self.iq_float[3:]] = self.body.segments["pelvis"].origin
        return q
