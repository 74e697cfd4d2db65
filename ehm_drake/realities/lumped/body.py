"""The body plan of the `lumped` reality: segments, joints, contact points,
markers and seat surfaces of one subject in the initial seated posture
(pure numpy; the Drake plant is built from it in `plant.py`).

Coordinates are the seat frame S (x forward, y left, z up), origin on the
rigid pan surface under the midpoint of the ischial tuberosities.  Each
segment's body frame sits at its proximal joint centre, oriented along the
segment's anatomical axes in the initial posture, so every joint angle is
zero there.

Structure (default: 8 bodies with mass, 10 massless links between the
revolutes of the 3-DoF joints, 23 DoF):

* pelvis: floating (6 DoF) on the seat through its contacts;
* abdomen: 3-DoF joint at L4-L5 (flexion, lateral bending, axial rotation,
  a chain of revolutes in that anatomical order);
* thorax (arms lumped in, hands on the lap): 3-DoF joint at T12-L1;
* head-neck as one body: 3-DoF joint at C7-T1;
* thighs: 3-DoF hips; shank+foot as one body on a revolute knee.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def rot_y(deg: float) -> np.ndarray:
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def cylinder_inertia(m: float, a: float, b: float, length: float) -> np.ndarray:
    """Central inertia of an elliptic cylinder (semi-axes a along x, b along
    y, long axis z) in its own axes (Hanavan's trunk solids)."""
    return m * np.diag([b * b / 4 + length**2 / 12, a * a / 4 + length**2 / 12,
                        (a * a + b * b) / 4])


def rod_inertia(m: float, rg_transverse: float, r_long: float, axis: np.ndarray) -> np.ndarray:
    """Central inertia in S of a limb segment along unit `axis`: transverse
    radius of gyration rg_transverse, a solid cylinder of radius r_long
    about the long axis."""
    axis = axis / np.linalg.norm(axis)
    it, il = m * rg_transverse**2, 0.5 * m * r_long**2
    return it * np.eye(3) + (il - it) * np.outer(axis, axis)


def parallel_axis(m: float, r: np.ndarray) -> np.ndarray:
    return m * (float(r @ r) * np.eye(3) - np.outer(r, r))


@dataclass
class Segment:
    """One rigid body: proximal joint centre `origin` and orientation `R`
    in S at the initial posture; mass, mass centre and central inertia in
    S."""

    name: str
    parent: str | None
    origin: np.ndarray
    R: np.ndarray
    mass: float
    com: np.ndarray
    inertia: np.ndarray

    def combine(self, m: float, com: np.ndarray, inertia: np.ndarray) -> None:
        """Lump another rigid part into this body."""
        M = self.mass + m
        c = (self.mass * self.com + m * com) / M
        self.inertia = (self.inertia + parallel_axis(self.mass, self.com - c)
                        + inertia + parallel_axis(m, com - c))
        self.mass, self.com = M, c


@dataclass
class JointDef:
    """A joint of revolute DoFs (a chain about `axes`, in the child's
    frame) or one floating joint; per-DoF laws in the same order."""

    name: str
    parent: str
    child: str
    axes: tuple  # unit vectors in the child frame, the chain order
    group: str  # lumbar, thoracolumbar, neck, hip, knee, shoulder, elbow
    stiffness: tuple
    damping: float
    neutral_zone: float
    kp: tuple = ()
    kd: tuple = ()
    tonic: bool = False  # adapts a postural torque while settling
    cocontraction: bool = False


@dataclass
class ContactDef:
    """A body point `p_B` (body frame) against a support plane."""

    name: str
    body: str
    p_B: np.ndarray
    support: str  # pan, floor, lower_pad, upper_pad, thigh_l/r (hands)
    group: str  # it, buttock, thigh, back, foot, hand


@dataclass
class BodyPlan:
    segments: dict[str, Segment]
    joints: list[JointDef]
    contacts: list[ContactDef]
    #: Support planes in S (point, unit normal pointing at the body).
    planes: dict[str, tuple[np.ndarray, np.ndarray]]
    #: Channel markers: segment -> (body, point in S at the initial posture).
    markers: dict[str, tuple[str, np.ndarray]]
    #: Named points in S (for reports and effects).
    landmarks: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def total_mass(self) -> float:
        return sum(s.mass for s in self.segments.values())

    def to_body(self, body: str, p_S: np.ndarray) -> np.ndarray:
        s = self.segments[body]
        return s.R.T @ (np.asarray(p_S, float) - s.origin)


X, Y, Z = np.eye(3)
SPINE_AXES = (Y, X, Z)  # flexion-extension, lateral bending, axial rotation
#: Hip axes with the thigh horizontal: flexion (y), abduction (z), rotation
#: about the femur (x).
HIP_AXES = (Y, Z, X)


def make_plan(v: dict, arms: dict | None = None, viscera_kg: float = 0.0) -> BodyPlan:
    """The body plan for parameter values `v` (see `parameters.PARAMETERS`).

    `arms` (the arms effect: shoulder_stiffness, elbow_stiffness,
    elbow_damping) makes the arms their own bodies; `viscera_kg` > 0 takes
    that mass out of the abdomen onto its own body (visceral_mass effect).
    """
    separate_arms = arms is not None
    H, M = v["stature"], v["body_mass"]
    seg: dict[str, Segment] = {}
    lm: dict[str, np.ndarray] = {}
    R_tr = rot_y(-v["trunk_recline"])
    e_sp, e_ant = R_tr[:, 2], R_tr[:, 0]
    # Pelvis: frame at the hip-joint midpoint, aligned with S.
    it_drop = 0.014  # the tuberosity skin starts 14 mm into the pan (near its seated depth)
    hjc = np.array([v["hjc_ahead_of_it"], 0.0, v["hjc_above_it"] - it_drop])
    l4l5 = hjc + np.array([-v["l4l5_behind_hjc"], 0.0, v["l4l5_above_hjc"]])
    m = v["m_pelvis"] * M
    com = l4l5 + v["com_pelvis"] * (hjc - l4l5)
    height = float(np.linalg.norm(hjc - l4l5)) + v["hjc_above_it"]
    inertia = v["i_pelvis"] * cylinder_inertia(m, v["pelvis_depth"] / 2, v["hip_breadth"] / 2,
                                               height)
    seg["pelvis"] = Segment("pelvis", None, hjc, np.eye(3), m, com, inertia)
    # Abdomen and thorax along the reclined spine line.
    L_ab, L_th = v["l_abdomen"] * H, v["l_thorax"] * H
    t12 = l4l5 + L_ab * e_sp
    c7 = t12 + L_th * e_sp
    m_ab = v["m_abdomen"] * M - viscera_kg
    com = l4l5 + v["com_abdomen"] * L_ab * e_sp + v["com_anterior_abdomen"] * e_ant
    inertia = v["i_abdomen"] * R_tr @ cylinder_inertia(
        m_ab, v["waist_depth"] / 2, v["waist_breadth"] / 2, L_ab) @ R_tr.T
    seg["abdomen"] = Segment("abdomen", "pelvis", l4l5, R_tr, m_ab, com, inertia)
    if viscera_kg > 0:
        # The viscera's own body (its mass centre where the abdomen's is).
        r = 0.06
        seg["viscera"] = Segment("viscera", "abdomen", com.copy(), R_tr, viscera_kg, com.copy(),
                                 0.4 * viscera_kg * r * r * np.eye(3))
    m = v["m_thorax"] * M
    com = c7 - v["com_thorax"] * L_th * e_sp + v["com_anterior_thorax"] * e_ant
    inertia = v["i_thorax"] * R_tr @ cylinder_inertia(
        m, v["chest_depth"] / 2, v["chest_breadth"] / 2, L_th) @ R_tr.T
    seg["thorax"] = Segment("thorax", "abdomen", t12, R_tr, m, com, inertia)
    # Head and neck as one body, frame aligned with S (gaze horizontal).
    L_hn = v["l_head_neck"] * H
    a = math.radians(v["neck_forward"])
    tragion = c7 + L_hn * np.array([math.sin(a), 0.0, math.cos(a)])
    m = v["m_head_neck"] * M
    com = c7 + v["com_head_neck"] * (tragion - c7)
    inertia = v["i_head_neck"] * m * (v["rg_head_neck"] * L_hn) ** 2 * np.diag([1.0, 1.0, 0.75])
    seg["head"] = Segment("head", "thorax", c7, np.eye(3), m, com, inertia)
    lm.update(hjc=hjc, l4l5=l4l5, t12l1=t12, c7=c7, tragion=tragion,
              t8=c7 - 0.625 * L_th * e_sp)
    # Legs.
    L_thigh, L_sh, L_f = v["l_thigh"] * H, v["l_shank"] * H, v["l_foot"] * H
    h_ank = v["h_ankle"] * H
    phi, psi = math.radians(v["thigh_slope"]), math.radians(v["shank_forward"])
    e_thigh = np.array([math.cos(phi), 0.0, -math.sin(phi)])
    e_shank = np.array([math.sin(psi), 0.0, -math.cos(psi)])
    feet_z = []
    for side, sgn in (("l", 1.0), ("r", -1.0)):
        h = hjc + np.array([0.0, sgn * v["hjc_width"] / 2, 0.0])
        knee = h + L_thigh * e_thigh
        m = v["m_thigh"] * M
        inertia = v["i_thigh"] * rod_inertia(m, v["rg_thigh"] * L_thigh, v["thigh_radius"],
                                             e_thigh)
        seg[f"thigh_{side}"] = Segment(f"thigh_{side}", "pelvis", h, np.eye(3), m,
                                       h + v["com_thigh"] * L_thigh * e_thigh, inertia)
        ankle = knee + L_sh * e_shank
        m = v["m_shank_foot"] * M
        inertia = v["i_shank_foot"] * rod_inertia(m, v["rg_shank_foot"] * L_sh,
                                                  v["shank_radius"], e_shank)
        seg[f"shank_{side}"] = Segment(f"shank_{side}", f"thigh_{side}", knee, np.eye(3), m,
                                       knee + v["com_shank_foot"] * L_sh * e_shank, inertia)
        lm.update({f"hjc_{side}": h, f"knee_{side}": knee, f"ankle_{side}": ankle,
                   f"heel_{side}": ankle + np.array([-0.2 * L_f, 0.0, -h_ank]),
                   f"ball_{side}": ankle + np.array([0.55 * L_f, 0.0, -h_ank]),
                   # The thigh's underside rests on the pan (the soft tissue
                   # under the femur is as thick as the subject's hip height
                   # makes it), 12 mm into it like the tuberosities.
                   f"thigh_pt_{side}": np.array([*(h + 0.45 * L_thigh * e_thigh)[:2],
                                                 -0.012]),
                   f"it_{side}": np.array([0.0, sgn * v["it_width"] / 2, -it_drop]),
                   # The buttock's tissue beside the tuberosity, at its depth.
                   f"buttock_{side}": np.array([0.0, sgn * v["buttock_contact_width"] / 2,
                                                -it_drop])})
        feet_z.append(lm[f"heel_{side}"][2])
    # Arms: upper arm hanging from the shoulder, forearm forward and down to
    # the hand resting on the thigh.
    arm_parts = {}
    for side, sgn in (("l", 1.0), ("r", -1.0)):
        gh = c7 + R_tr @ np.array([0.02, sgn * v["shoulder_half_width"],
                                   -v["shoulder_below_c7"]])
        b = math.radians(v["upper_arm_forward"])
        L_ua, L_fa = v["l_upper_arm"] * H, v["l_forearm"] * H
        elbow = gh + L_ua * np.array([math.sin(b), 0.0, -math.cos(b)]) \
            + np.array([0.0, sgn * 0.02, 0.0])
        c = math.radians(v["forearm_down"])
        dy = sgn * 0.12 - elbow[1]  # the hand over the thigh, 12 cm from the midline
        horiz = math.sqrt(max((L_fa * math.cos(c)) ** 2 - dy * dy, 1e-6))
        e_fa = np.array([horiz, dy, -L_fa * math.sin(c)]) / L_fa
        wrist = elbow + L_fa * e_fa
        m_ua, m_fh = v["m_upper_arm"] * M, v["m_forearm_hand"] * M
        e_ua = (elbow - gh) / np.linalg.norm(elbow - gh)
        arm_parts[side] = {
            "upper": (gh, m_ua, gh + v["com_upper_arm"] * (elbow - gh),
                      v["i_arm"] * rod_inertia(m_ua, v["rg_upper_arm"] * L_ua,
                                               v["arm_radius"], e_ua)),
            "fore": (elbow, m_fh, elbow + v["com_forearm_hand"] * L_fa * e_fa,
                     v["i_arm"] * rod_inertia(m_fh, v["rg_forearm_hand"] * L_fa,
                                              v["arm_radius"], e_fa)),
        }
        lm.update({f"shoulder_{side}": gh, f"elbow_{side}": elbow, f"wrist_{side}": wrist,
                   f"hand_{side}": wrist + 0.4 * v["l_hand"] * H * e_fa})
    if separate_arms:
        for side, parts in arm_parts.items():
            o, m, c, inertia = parts["upper"]
            seg[f"upper_arm_{side}"] = Segment(f"upper_arm_{side}", "thorax", o, np.eye(3), m,
                                               c, inertia)
            o, m, c, inertia = parts["fore"]
            seg[f"forearm_{side}"] = Segment(f"forearm_{side}", f"upper_arm_{side}", o,
                                             np.eye(3), m, c, inertia)
    else:
        for parts in arm_parts.values():
            for _, m, c, inertia in parts.values():
                seg["thorax"].combine(m, c, inertia)

    # Joints.
    def tup(x):
        return tuple(x) if isinstance(x, tuple) else (x,)

    joints = [
        JointDef("lumbar", "pelvis", "abdomen", SPINE_AXES, "lumbar", tup(v["k_lumbar"]),
                 v["d_lumbar"], v["nz_spine"], tup(v["kp_lumbar"]), tup(v["kd_lumbar"]),
                 tonic=True, cocontraction=True),
        JointDef("thoracolumbar", "abdomen", "thorax", SPINE_AXES, "thoracolumbar",
                 tup(v["k_thoracolumbar"]), v["d_thoracolumbar"], v["nz_spine"],
                 tup(v["kp_thoracolumbar"]), tup(v["kd_thoracolumbar"]), tonic=True,
                 cocontraction=True),
        JointDef("neck", "thorax", "head", SPINE_AXES, "neck", tup(v["k_neck"]), v["d_neck"],
                 v["nz_neck"], tup(v["kp_neck"]), tup(v["kd_neck"]), tonic=True,
                 cocontraction=True),
    ]
    for side in ("l", "r"):
        joints.append(JointDef(f"hip_{side}", "pelvis", f"thigh_{side}", HIP_AXES, "hip",
                               tup(v["k_hip"]), v["d_hip"], v["nz_leg"], tup(v["kp_hip"]),
                               tup(v["kd_hip"]), tonic=True, cocontraction=True))
        joints.append(JointDef(f"knee_{side}", f"thigh_{side}", f"shank_{side}", (Y,), "knee",
                               tup(v["k_knee"]), v["d_knee"], v["nz_leg"], tup(v["kp_knee"]),
                               tup(v["kd_knee"])))
    if separate_arms:
        k_sh, k_el = arms["shoulder_stiffness"], arms["elbow_stiffness"]
        for side in ("l", "r"):
            # Relaxed arms: passive only (no postural feedback), damping
            # ratio ~0.3 on the arm's inertia about the shoulder (~0.1 kg m^2).
            joints.append(JointDef(f"shoulder_{side}", "thorax", f"upper_arm_{side}",
                                   SPINE_AXES, "shoulder", (k_sh,) * 3,
                                   0.6 * math.sqrt(k_sh * 0.1), 0.5))
            joints.append(JointDef(f"elbow_{side}", f"upper_arm_{side}", f"forearm_{side}",
                                   (Y,), "elbow", (k_el,), arms["elbow_damping"], 0.5))

    # Contacts: pan (tuberosities, thighs), floor (heel, ball), back pads.
    contacts = []
    for side, sgn in (("l", 1.0), ("r", -1.0)):
        contacts.append(ContactDef(f"it_{side}", "pelvis", None, "pan", "it"))
        contacts.append(ContactDef(f"buttock_{side}", "pelvis", None, "pan", "buttock"))
        contacts.append(ContactDef(f"thigh_{side}", f"thigh_{side}", None, "pan", "thigh"))
        for pt in ("heel", "ball"):
            contacts.append(ContactDef(f"{pt}_{side}", f"shank_{side}", None, "floor", "foot"))
        lm[f"lumbar_back_{side}"] = l4l5 + 0.06 * e_sp - 0.08 * e_ant + sgn * 0.05 * Y
        lm[f"upper_back_{side}"] = c7 - 0.10 * e_sp - 0.09 * e_ant + sgn * 0.07 * Y
        contacts.append(ContactDef(f"lumbar_back_{side}", "abdomen", None, "lower_pad", "back"))
        contacts.append(ContactDef(f"upper_back_{side}", "thorax", None, "upper_pad", "back"))
    pts = {"it": "it", "buttock": "buttock", "thigh": "thigh_pt", "heel": "heel",
           "ball": "ball", "lumbar_back": "lumbar_back", "upper_back": "upper_back"}
    for c in contacts:
        kind, side = c.name.rsplit("_", 1)
        c.p_B = lm[f"{pts[kind]}_{side}"]  # in S until converted below

    # Support planes, adjusted to the subject: the floor under the feet and
    # the pads behind the back, each with its design compression.
    beta = math.radians(v["backrest_recline"])
    n_back = np.array([math.cos(beta), 0.0, math.sin(beta)])
    pad_d = v["pad_preload_mm"] * 1e-3
    planes = {
        "pan": (np.zeros(3), Z.copy()),
        "floor": (np.array([0.0, 0.0, min(feet_z) + v["foot_preload_mm"] * 1e-3]), Z.copy()),
        "lower_pad": (lm["lumbar_back_l"] * np.array([1, 0, 1]) + pad_d * n_back, n_back),
        "upper_pad": (lm["upper_back_l"] * np.array([1, 0, 1]) + pad_d * n_back, n_back),
    }
    if separate_arms:
        for side in ("l", "r"):
            # The palm on the thigh's upper surface: a plane fixed on the
            # thigh through the hand point (touching, unloaded).
            planes[f"thigh_{side}"] = (lm[f"hand_{side}"].copy(), Z.copy())
            contacts.append(ContactDef(f"hand_{side}", f"forearm_{side}", lm[f"hand_{side}"],
                                       f"thigh_{side}", "hand"))
    for c in contacts:
        c.p_B = seg[c.body].R.T @ (np.asarray(c.p_B) - seg[c.body].origin)

    markers = {"pelvis": ("pelvis", hjc.copy()), "trunk": ("thorax", lm["t8"].copy()),
               "head": ("head", tragion.copy()),
               "knee_l": ("thigh_l", lm["knee_l"].copy()),
               "knee_r": ("thigh_r", lm["knee_r"].copy())}
    return BodyPlan(seg, joints, contacts, planes, markers, lm)
