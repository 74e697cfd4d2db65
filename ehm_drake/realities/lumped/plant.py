"""Build the Drake plant and diagram of the `lumped` reality from a body
plan, the subject's parameter values and the active effects."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    PrismaticJoint,
    RevoluteJoint,
    RotationalInertia,
    RpyFloatingJoint,
    SpatialInertia,
)
from pydrake.systems.framework import DiagramBuilder

from .. import RealityError
from .body import BodyPlan, make_plan
from .system import LumpedHuman, StateLayout

GRAVITY = 9.81
#: Share of the body weight on the pan, used to preload the cushion spring
#: so the seated height does not depend on the cushion stiffness (static
#: seat-pan force of seated subjects with feet supported: 0.7-0.8 of body
#: weight, Fairley-Griffin).
PAN_SHARE = 0.75
#: Contact laws per group: (Hunt-Crossley k, c; shear stiffness, damping;
#: friction coefficient key; foam hardening applies).
_GROUPS = {
    "it": ("k_it", "c_it", "shear_k_it", "shear_c_it", "mu_seat", True),
    "buttock": ("k_it", "c_it", "shear_k_it", "shear_c_it", "mu_seat", True),
    "thigh": ("k_thigh", "c_thigh", "shear_k_thigh", "shear_c_thigh", "mu_seat", True),
    "back": ("k_back", "c_back", "shear_k_back", "shear_c_back", "mu_seat", True),
    "foot": ("k_foot", "c_foot", "shear_k_foot", "shear_c_foot", "mu_floor", False),
}
#: The hand resting on the thigh (arms effect): tissue on tissue.
HAND_CONTACT = {"c": 1.0, "shear_k": 2000.0, "shear_c": 20.0, "mu": 0.8}
SUPPORTS = ("pan", "floor", "back")


@dataclass
class SystemSpec:
    """Index arrays and coefficients of the LumpedHuman system."""

    h: float
    nq: int
    nv: int
    kin_body_index: list
    force_kin: np.ndarray
    com_B: np.ndarray
    mass: np.ndarray
    c_body: np.ndarray
    c_sup: np.ndarray
    c_pB: np.ndarray
    c_oB: np.ndarray
    c_nB: np.ndarray
    c_k: np.ndarray
    c_n: np.ndarray
    c_c: np.ndarray
    c_sk: np.ndarray
    c_sc: np.ndarray
    c_mu: np.ndarray
    c_foam: np.ndarray
    c_kt0: np.ndarray
    c_jenkins: np.ndarray
    c_names: tuple
    c_oN: np.ndarray
    moving_supports: bool
    inv_slide: float
    stick_fraction: float
    A_body: np.ndarray
    A_sup: np.ndarray
    A_net: np.ndarray
    A_support: np.ndarray
    support_names: tuple
    dof_q: np.ndarray
    dof_v: np.ndarray
    dof_names: tuple
    q0: np.ndarray
    k_pass: np.ndarray
    nz: np.ndarray
    stiffening_angle: float
    kp: np.ndarray
    kd: np.ndarray
    ki: np.ndarray
    cc_mask: np.ndarray
    vest_map: np.ndarray
    kv: np.ndarray
    dv: np.ndarray
    spring_q: np.ndarray
    spring_v: np.ndarray
    spring_k: np.ndarray
    spring_rest: np.ndarray
    head_kin: int
    head_R0: np.ndarray
    pelvis_xyz: np.ndarray
    pelvis_xyz0: np.ndarray
    marker_kin: np.ndarray
    marker_B: np.ndarray
    delay_steps: int
    activation_time: float
    cocontraction: float
    cc_tau: float
    layout: StateLayout


@dataclass
class Built:
    diagram: object
    plant: MultibodyPlant
    system: LumpedHuman
    spec: SystemSpec
    plan: BodyPlan


def _inertia(seg):
    I_B = seg.R.T @ seg.inertia @ seg.R
    com_B = seg.R.T @ (seg.com - seg.origin)
    rot = RotationalInertia(I_B[0, 0], I_B[1, 1], I_B[2, 2], I_B[0, 1], I_B[0, 2], I_B[1, 2])
    return SpatialInertia.MakeFromCentralInertia(seg.mass, com_B, rot), com_B


def build(v: dict, effects: dict, h: float) -> Built:
    """The diagram for parameter values `v` and effects {name: values}."""
    if not 0.0 < v["buttock_share"] < 1.0:
        raise RealityError(f"lumped: buttock_share must be in (0, 1) (each side's pan tissue "
                           f"at its tuberosity and buttock points), got {v['buttock_share']!r}")
    arms = None
    if "arms" in effects:
        e = effects["arms"]
        arms = {"shoulder_stiffness": e["shoulder_stiffness"],
                "elbow_stiffness": e["elbow_stiffness"], "elbow_damping": e["elbow_damping"]}
    viscera = effects.get("visceral_mass", {}).get("mass_kg", 0.0)
    plan = make_plan(v, arms, viscera)
    builder = DiagramBuilder()
    plant = builder.AddSystem(MultibodyPlant(h))
    plant.set_name("plant")
    plant.SetUseSampledOutputPorts(False)
    bodies, com_B = {}, {}
    for name, seg in plan.segments.items():
        M, com_B[name] = _inertia(seg)
        bodies[name] = plant.AddRigidBody(name, M)
    world = plant.world_frame()
    springs = []  # (joint, stiffness, rest)

    def massless(name):
        return plant.AddRigidBody(name, SpatialInertia.Zero()).body_frame()

    cushion = effects.get("seat_cushion_dynamics")
    if cushion is not None:
        m_c = cushion["mass_kg"]
        bodies["cushion"] = plant.AddRigidBody("cushion", SpatialInertia.MakeFromCentralInertia(
            m_c, np.zeros(3), RotationalInertia(0.05, 0.05, 0.1)))
        com_B["cushion"] = np.zeros(3)
        kz = cushion["stiffness"]
        kx = cushion["shear_ratio"] * kz
        m_eff = m_c + PAN_SHARE * plan.total_mass
        link = massless("cushion_link")
        for axis, k, child, rest in (
                ((1.0, 0.0, 0.0), kx, link, 0.0),
                ((0.0, 0.0, 1.0), kz, bodies["cushion"].body_frame(), m_eff * GRAVITY / kz)):
            j = plant.AddJoint(PrismaticJoint(
                f"cushion_{'xz'[axis[2] > 0]}", world if child is link else link, child,
                np.array(axis), damping=2 * cushion["damping_ratio"] * math.sqrt(k * m_eff)))
            springs.append((j, k, rest))

    pelvis = plan.segments["pelvis"]
    free = plant.AddJoint(RpyFloatingJoint("pelvis_free", world, bodies["pelvis"].body_frame()))
    free.set_default_angles(np.zeros(3))
    free.set_default_translation(pelvis.origin)
    chains = []
    for jd in plan.joints:
        P, C = plan.segments[jd.parent], plan.segments[jd.child]
        X = RigidTransform(RotationMatrix(P.R.T @ C.R), P.R.T @ (C.origin - P.origin))
        frame = plant.AddFrame(FixedOffsetFrame(f"{jd.name}_on_parent",
                                                bodies[jd.parent].body_frame(), X))
        js = []
        for i, axis in enumerate(jd.axes):
            last = i == len(jd.axes) - 1
            child = bodies[jd.child].body_frame() if last else massless(f"{jd.name}_link{i}")
            js.append(plant.AddJoint(RevoluteJoint(f"{jd.name}_{i}", frame, child,
                                                   np.asarray(axis, float), jd.damping)))
            frame = child
        chains.append((jd, js))
    if viscera > 0:
        fx = effects["visceral_mass"]
        seg = plan.segments["viscera"]
        ab = plan.segments["abdomen"]
        X = RigidTransform(RotationMatrix(ab.R.T @ seg.R), ab.R.T @ (seg.origin - ab.origin))
        frame = plant.AddFrame(FixedOffsetFrame("viscera_on_abdomen",
                                                bodies["abdomen"].body_frame(), X))
        g_B = seg.R.T @ np.array([0.0, 0.0, -GRAVITY])
        for i in range(3):
            f_hz = fx["freq_z_hz"] if i == 2 else fx["freq_xy_hz"]
            w = 2 * math.pi * f_hz
            k = viscera * w * w
            child = bodies["viscera"].body_frame() if i == 2 else massless(f"viscera_link{i}")
            j = plant.AddJoint(PrismaticJoint(f"viscera_{'xyz'[i]}", frame, child, np.eye(3)[i],
                                              damping=2 * fx["damping_ratio"] * viscera * w))
            # Preloaded: at rest the viscera sit where they were placed.
            springs.append((j, k, -viscera * g_B[i] / k))
            frame = child
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, -GRAVITY])
    plant.Finalize()

    # ---- kinematic bodies: every body with mass, then the world
    names = list(bodies)
    index = {n: i for i, n in enumerate(names)}
    nk = len(names)
    contacts = plan.contacts
    nc = len(contacts)
    planes = dict(plan.planes)
    sep = effects.get("backrest_separation")
    if sep is not None:
        for pad in ("lower_pad", "upper_pad"):
            o, n = planes[pad]
            planes[pad] = (o - sep["offset_mm"] * 1e-3 * n, n)
    mu_seat = effects.get("seat_friction", {}).get("mu", v["mu_seat"])
    c_body, c_sup, pB, oB, nB = [], [], [], [], []
    k, n_exp, c, sk, sc, mu, foam, jenkins = ([] for _ in range(8))
    A_support = np.zeros((len(SUPPORTS), nc))
    for i, cd in enumerate(contacts):
        c_body.append(index[cd.body])
        pB.append(cd.p_B)
        o, n = planes[cd.support]
        sup_body = None
        if cd.support == "pan" and cushion is not None:
            sup_body = "cushion"
        elif cd.support.startswith("thigh_"):
            sup_body = cd.support
        if sup_body is None:
            c_sup.append(nk)
            oB.append(o)
            nB.append(n)
        else:
            s = plan.segments.get(sup_body)
            R0, o0 = (np.eye(3), np.zeros(3)) if s is None else (s.R, s.origin)
            c_sup.append(index[sup_body])
            oB.append(R0.T @ (o - o0))
            nB.append(R0.T @ n)
        if cd.group == "hand":
            k.append(effects["arms"]["hand_contact_k"])
            c.append(HAND_CONTACT["c"])
            sk.append(HAND_CONTACT["shear_k"])
            sc.append(HAND_CONTACT["shear_c"])
            mu.append(HAND_CONTACT["mu"])
            foam.append(0.0)
            jenkins.append(0.0)
        else:
            kk, cc, ss, sd, mk, fm = _GROUPS[cd.group]
            # Each side's pan tissue split between its tuberosity and buttock
            # points (Hunt-Crossley damping is per unit of force: not split).
            share = {"it": 1.0 - v["buttock_share"], "buttock": v["buttock_share"]}.get(
                cd.group, 1.0)
            k.append(share * v[kk])
            c.append(v[cc])
            sk.append(share * v[ss])
            sc.append(share * v[sd])
            mu.append(mu_seat if mk == "mu_seat" else v[mk])
            foam.append(1.0 if fm else 0.0)
            part = {"it": "pan", "buttock": "pan", "thigh": "pan", "foot": "floor",
                    "back": "back"}[cd.group]
            # Tissue friction in the seat-pan tissue under the pelvis and
            # thighs (not the back pads' foam nor the heel pads).
            jenkins.append(1.0 if part == "pan" else 0.0)
            A_support[SUPPORTS.index(part), i] = 1.0
        n_exp.append(v["hc_exponent"])
    A_body = np.zeros((nk, nc))
    A_sup = np.zeros((nk, nc))
    for i in range(nc):
        A_body[c_body[i], i] = 1.0
        if c_sup[i] < nk:
            A_sup[c_sup[i], i] = 1.0

    # ---- joint DoFs
    dof_q, dof_v, dof_names, kpass, nz, kp, kd, ki, ccm, vest = ([] for _ in range(10))
    for jd, js in chains:
        for i, j in enumerate(js):
            dof_q.append(j.position_start())
            dof_v.append(j.velocity_start())
            dof_names.append(j.name())
            kpass.append(jd.stiffness[i])
            nz.append(jd.neutral_zone)
            kp.append(jd.kp[i] if jd.kp else 0.0)
            kd.append(jd.kd[i] if jd.kd else 0.0)
            ki.append((kpass[-1] + kp[-1]) / v["tonic_adaptation_time"] if jd.tonic else 0.0)
            ccm.append(1.0 if jd.cocontraction else 0.0)
            vest.append(np.asarray(jd.axes[i], float) if jd.group == "neck" else np.zeros(3))
    n_act = len(dof_q)
    extra = effects.get("reflex_delay", {}).get("extra_delay_s", 0.0)
    delay_steps = int(round((v["neural_delay"] + extra) / h))
    layout = StateLayout(n_act, 2 * n_act + 6, max(delay_steps, 1), nc)
    cc = effects.get("cocontraction", {})
    spec = SystemSpec(
        h=h, nq=plant.num_positions(), nv=plant.num_velocities(),
        kin_body_index=[bodies[n].index() for n in names],
        force_kin=np.arange(nk), com_B=np.array([com_B[n] for n in names]),
        mass=np.array([bodies[n].default_mass() for n in names]),
        c_body=np.array(c_body), c_sup=np.array(c_sup), c_pB=np.array(pB), c_oB=np.array(oB),
        c_nB=np.array(nB), c_k=np.array(k), c_n=np.array(n_exp), c_c=np.array(c),
        c_sk=np.array(sk), c_sc=np.array(sc), c_mu=np.array(mu), c_foam=np.array(foam),
        c_kt0=np.zeros(nc), c_jenkins=np.array(jenkins), c_names=tuple(cd.name for cd in contacts),
        c_oN=np.einsum("ni,ni->n", np.array(oB), np.array(nB)),
        moving_supports=bool(np.any(np.array(c_sup) < nk)),
        inv_slide=1.0 / (1.0 - v["stick_fraction"]),
        stick_fraction=v["stick_fraction"], A_body=A_body, A_sup=A_sup, A_net=A_body - A_sup,
        A_support=A_support,
        support_names=SUPPORTS,
        dof_q=np.array(dof_q), dof_v=np.array(dof_v), dof_names=tuple(dof_names),
        q0=np.zeros(n_act), k_pass=np.array(kpass), nz=np.array(nz),
        stiffening_angle=v["stiffening_angle"], kp=np.array(kp), kd=np.array(kd),
        ki=np.array(ki), cc_mask=np.array(ccm), vest_map=np.array(vest),
        kv=np.asarray(v["kv_head"], float), dv=np.asarray(v["dv_head"], float),
        spring_q=np.array([j.position_start() for j, _, _ in springs], int),
        spring_v=np.array([j.velocity_start() for j, _, _ in springs], int),
        spring_k=np.array([kk for _, kk, _ in springs]),
        spring_rest=np.array([r for _, _, r in springs]),
        head_kin=index["head"], head_R0=np.eye(3),
        pelvis_xyz=np.arange(3) + free.position_start() + 3, pelvis_xyz0=pelvis.origin.copy(),
        marker_kin=np.array([index[b] for b, _ in plan.markers.values()]),
        marker_B=np.array([plan.to_body(b, p) for b, p in plan.markers.values()]),
        delay_steps=delay_steps, activation_time=v["activation_time"],
        cocontraction=cc.get("gain_per_ms2", 0.0), cc_tau=cc.get("tau_s", 2.0),
        layout=layout)
    system = builder.AddSystem(LumpedHuman(plant, spec))
    system.set_name("lumped_human")
    builder.Connect(plant.get_state_output_port(), system.get_input_port(0))
    builder.Connect(system.GetOutputPort("generalized_force"),
                    plant.get_applied_generalized_force_input_port())
    builder.Connect(system.GetOutputPort("spatial_forces"),
                    plant.get_applied_spatial_force_input_port())
    diagram = builder.Build()
    return Built(diagram, plant, system, spec, plan)
