"""Geometry and mass properties of the `spine5` subject in its seated
reference pose (pure numpy; no Drake).

Everything is expressed in the seat frame S (x forward, y left, z up), its
origin on the line where the pan plane meets the back-rest plane.  Each body
frame sits at the body's proximal joint with axes parallel to S in the
reference pose, so every joint angle is zero there.

Bodies: pelvis, lumbar (L1-L5), lower thorax (T7-T12), upper thorax (T1-T6,
with the shoulder girdle and, unless the `arms` effect separates them, the
arms), cervical (C1-C7), head, thighs, shanks, feet; with the effects also
upper arms and forearm-hands, a visceral mass and a seat cushion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

G = 9.81
EY = np.array([0.0, 1.0, 0.0])


@dataclass
class Segment:
    name: str
    parent: str | None  # None: floating (pelvis) or seat-mounted (cushion)
    joint: str  # "floating", "ball", "revolute_y", "ankle", "prismatic_xz", "prismatic_z"
    origin: np.ndarray  # joint centre = body frame origin, in S
    mass: float
    com: np.ndarray  # in S
    inertia: np.ndarray  # 3x3 about the COM, S axes


@dataclass
class ContactPoint:
    body: str
    p: np.ndarray  # unloaded skin point in S (reference pose)
    surface: str
    group: str  # pelvis | thigh | back | foot


@dataclass
class Surface:
    name: str
    normal: np.ndarray  # unit, pointing out of the seat into the body
    offset: float  # plane: normal . p = offset
    kind: str  # pan | back | floor


@dataclass
class BodyModel:
    segments: dict[str, Segment]
    points: list[ContactPoint]
    surfaces: dict[str, Surface]
    landmarks: dict[str, np.ndarray]
    markers: dict[str, tuple[str, np.ndarray]]  # channel segment -> (body, point in S)
    total_mass: float
    arms_separate: bool = False
    hand_points: dict[str, tuple[np.ndarray, float]] = field(default_factory=dict)


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _incl(deg_from_vertical: float) -> np.ndarray:
    """Unit vector in the x-z plane inclined backwards (top rearward) by the
    angle from vertical (negative: forwards)."""
    a = math.radians(deg_from_vertical)
    return np.array([-math.sin(a), 0.0, math.cos(a)])


def rod_inertia(m: float, axis, rho_t: float, rho_l: float) -> np.ndarray:
    """Inertia about the COM of a slender segment along `axis`: transverse
    and longitudinal radii of gyration (m)."""
    u = _unit(axis)
    uu = np.outer(u, u)
    return m * (rho_t**2 * (np.eye(3) - uu) + rho_l**2 * uu)


def cylinder_inertia(m: float, axis, depth: float, breadth: float, height: float) -> np.ndarray:
    """Uniform elliptic cylinder (HANAVAN): semi-axes depth/2 (x, turned with
    the axis in the sagittal plane) and breadth/2 (y), along `axis`."""
    u = _unit(axis)
    a, b = depth / 2, breadth / 2
    ex = _unit(np.cross(EY, u))  # sagittal, perpendicular to the axis
    R = np.column_stack([ex, EY, u])
    local = np.diag([m * (b**2 / 4 + height**2 / 12), m * (a**2 / 4 + height**2 / 12),
                     m * (a**2 + b**2) / 4])
    return R @ local @ R.T


def combine(parts):
    """Mass, COM and inertia about the COM of rigidly joined (m, com, I)."""
    m = sum(p[0] for p in parts)
    c = sum(p[0] * p[1] for p in parts) / m
    inertia = np.zeros((3, 3))
    for mi, ci, Ii in parts:
        d = ci - c
        inertia += Ii + mi * (d @ d * np.eye(3) - np.outer(d, d))
    return m, c, inertia


def build_body(v: dict[str, float], effects: dict[str, dict[str, float]]) -> BodyModel:
    """The seated subject of parameter values `v` (see params.PARAMS) with
    the structural effects (arms, visceral_mass, seat_cushion_dynamics)."""
    H = v["stature"]
    sL = H / 1.756  # length scale for small unparameterised offsets
    a_pan, a_back = math.radians(v["pan_angle"]), math.radians(v["back_angle"])
    n_pan = np.array([-math.sin(a_pan), 0.0, math.cos(a_pan)])
    t_pan = np.array([math.cos(a_pan), 0.0, math.sin(a_pan)])
    n_back = np.array([math.cos(a_back), 0.0, math.sin(a_back)])

    # Hip centre (mid-point of the hip joint centres): its distances to the
    # back-rest and pan planes.
    A = np.array([[n_back[0], n_back[2]], [n_pan[0], n_pan[2]]])
    hx, hz = np.linalg.solve(A, [v["hip_depth"], v["hip_height"]])
    hip = np.array([hx, 0.0, hz])
    lm: dict[str, np.ndarray] = {"hip": hip}
    lm["L5S1"] = hip + np.array([-v["l5s1_back"], 0.0, v["l5s1_up"]])
    lm["T12L1"] = lm["L5S1"] + v["len_lumbar"] * _incl(v["incl_lumbar"])
    lm["T6T7"] = lm["T12L1"] + v["len_lower_thorax"] * _incl(v["incl_lower_thorax"])
    lm["C7T1"] = lm["T6T7"] + v["len_upper_thorax"] * _incl(v["incl_upper_thorax"])
    lm["C0C1"] = lm["C7T1"] + v["len_cervical"] * _incl(v["incl_cervical"])

    def anterior(a, b):  # unit vector perpendicular to the chord a->b, forwards
        d = b - a
        return _unit([d[2], 0.0, -d[0]])

    segs: dict[str, Segment] = {}
    M = {k[5:]: v[k] for k in v if k.startswith("mass_")}
    ktr, khd, klb = v["inertia_trunk"], v["inertia_head"], v["inertia_limbs"]

    # Pelvis: COM behind and above the hip centre (sacrum, pelvic ring,
    # gluteal mass); cylinder from the pan to L5/S1.
    pel_com = hip + sL * np.array([-0.035, 0.0, 0.03])
    pel_I = cylinder_inertia(M["pelvis"], [0, 0, 1], v["waist_depth"], v["hip_breadth"],
                             0.20 * sL) * ktr
    segs["pelvis"] = Segment("pelvis", None, "floating", hip.copy(), M["pelvis"], pel_com, pel_I)

    def trunk_seg(name, parent, a, b, mass, ant, depth, breadth):
        c = 0.5 * (a + b) + ant * anterior(a, b)
        inertia = cylinder_inertia(mass, b - a, depth, breadth, np.linalg.norm(b - a)) * ktr
        return Segment(name, parent, "ball", a.copy(), mass, c, inertia)

    segs["lumbar"] = trunk_seg("lumbar", "pelvis", lm["L5S1"], lm["T12L1"], M["lumbar"],
                               0.010 * sL, v["waist_depth"], v["waist_breadth"])
    segs["lower_thorax"] = trunk_seg("lower_thorax", "lumbar", lm["T12L1"], lm["T6T7"],
                                     M["lower_thorax"], 0.050 * sL, v["chest_depth"],
                                     v["chest_breadth"])
    segs["upper_thorax"] = trunk_seg("upper_thorax", "lower_thorax", lm["T6T7"], lm["C7T1"],
                                     M["upper_thorax"], 0.040 * sL, v["chest_depth"],
                                     v["chest_breadth"])
    segs["cervical"] = trunk_seg("cervical", "upper_thorax", lm["C7T1"], lm["C0C1"],
                                 M["neck"], 0.015 * sL, 0.11 * sL, 0.11 * sL)
    head_com = lm["C0C1"] + sL * np.array([0.020, 0.0, 0.035])
    rg = np.array([0.0689, 0.0718, 0.0585]) * sL  # BEIER radii of gyration
    segs["head"] = Segment("head", "cervical", "ball", lm["C0C1"].copy(), M["head"], head_com,
                           np.diag(M["head"] * rg**2) * khd)

    # Legs.
    L_th, L_sh = 0.245 * H, 0.246 * H
    tp, st = math.radians(v["thigh_pitch"]), math.radians(v["shank_tilt"])
    ankle_h, foot_len = 0.039 * H, 0.152 * H
    for side, sg in (("l", 1.0), ("r", -1.0)):
        hjc = hip + np.array([0.0, sg * v["hip_half_width"], 0.0])
        knee = hjc + np.array([L_th * math.cos(tp), sg * (v["knee_half_width"]
                                                           - v["hip_half_width"]),
                               L_th * math.sin(tp)])
        ankle = knee + L_sh * np.array([math.sin(st), 0.0, -math.cos(st)])
        lm[f"hip_{side}"], lm[f"knee_{side}"], lm[f"ankle_{side}"] = hjc, knee, ankle
        th_c = hjc + 0.433 * (knee - hjc)  # DEMPSTER
        segs[f"thigh_{side}"] = Segment(
            f"thigh_{side}", "pelvis", "ball", hjc, M["thigh"], th_c,
            rod_inertia(M["thigh"], knee - hjc, 0.323 * L_th, 0.075 * sL / math.sqrt(2)) * klb)
        sh_c = knee + 0.433 * (ankle - knee)
        segs[f"shank_{side}"] = Segment(
            f"shank_{side}", f"thigh_{side}", "revolute_y", knee, M["shank"], sh_c,
            rod_inertia(M["shank"], ankle - knee, 0.302 * L_sh, 0.05 * sL / math.sqrt(2)) * klb)
        ball = ankle + np.array([0.72 * foot_len - 0.05 * sL, 0.0, -ankle_h])
        ft_c = 0.5 * (ankle + ball) + np.array([0.0, 0.0, 0.01 * sL])
        segs[f"foot_{side}"] = Segment(
            f"foot_{side}", f"shank_{side}", "ankle", ankle, M["foot"], ft_c,
            rod_inertia(M["foot"], [1, 0, 0], 0.475 * foot_len, 0.035 * sL) * klb)
        lm[f"ball_{side}"] = ball

    # Arms: shoulder below/in front of C7/T1; upper arm forward-down; the
    # forearm reaches the palm resting on the thigh (at 60 % of its length,
    # on its upper surface).  Lumped into the upper thorax unless separated.
    L_ua, L_fa = 0.186 * H, 0.146 * H
    palm = 0.35 * 0.108 * H
    arm_parts = []
    arms = effects.get("arms", {})
    arms_separate = bool(arms.get("on", 0.0) > 0)
    hand_points = {}
    for side, sg in (("l", 1.0), ("r", -1.0)):
        gh = lm["C7T1"] + np.array([0.02 * sL, sg * v["shoulder_half_width"],
                                    -v["shoulder_below_c7"]])
        hjc, knee = lm[f"hip_{side}"], lm[f"knee_{side}"]
        hand = hjc + 0.6 * (knee - hjc) + np.array([0.0, 0.0, 0.075 * sL])
        hand[1] = sg * (v["knee_half_width"] + v["hip_half_width"]) / 2
        # Elbow on the circle of radius L_ua about the shoulder at distance
        # L_fa + palm from the hand: bisect the upper-arm forward angle.
        lo, hi = 0.0, 1.5
        for _ in range(60):
            ang = 0.5 * (lo + hi)
            elbow = gh + L_ua * np.array([math.sin(ang), 0.0, -math.cos(ang)])
            elbow[1] = gh[1] + 0.3 * (hand[1] - gh[1])
            if np.linalg.norm(hand - elbow) > L_fa + palm:
                lo = ang
            else:
                hi = ang
        lm[f"shoulder_{side}"], lm[f"elbow_{side}"], lm[f"hand_{side}"] = gh, elbow, hand
        ua_c = gh + 0.436 * (elbow - gh)
        fa_axis = hand - elbow
        fa_c = elbow + 0.682 * L_fa * _unit(fa_axis)
        ua = (M["upper_arm"], ua_c, rod_inertia(M["upper_arm"], elbow - gh, 0.322 * L_ua,
                                                0.045 * sL / math.sqrt(2)) * klb)
        fa = (M["forearm_hand"], fa_c, rod_inertia(M["forearm_hand"], fa_axis, 0.468 * L_fa,
                                                   0.035 * sL / math.sqrt(2)) * klb)
        if arms_separate:
            segs[f"upper_arm_{side}"] = Segment(f"upper_arm_{side}", "upper_thorax", "ball",
                                                gh, *ua)
            segs[f"forearm_{side}"] = Segment(f"forearm_{side}", f"upper_arm_{side}",
                                              "revolute_y", elbow, *fa)
            # Static share of the forearm-hand weight carried by the thigh:
            # a beam on the elbow and the palm (moment about the elbow).
            share = M["forearm_hand"] * G * (fa_c[0] - elbow[0]) / (hand[0] - elbow[0])
            hand_points[side] = (hand, float(share))
        else:
            arm_parts += [ua, fa]
    if arm_parts:
        ut = segs["upper_thorax"]
        m, c, inertia = combine([(ut.mass, ut.com, ut.inertia), *arm_parts])
        segs["upper_thorax"] = Segment("upper_thorax", ut.parent, ut.joint, ut.origin, m, c,
                                       inertia)

    # Visceral mass: taken out of the lumbar body at the abdominal centre
    # (mid-lumbar, 9 cm anterior of the spine), on x-z prismatic joints.
    vis = effects.get("visceral_mass", {})
    if vis.get("mass_kg", 0.0) > 0:
        mv = vis["mass_kg"]
        lb = segs["lumbar"]
        p_v = 0.5 * (lm["L5S1"] + lm["T12L1"]) + 0.09 * sL * anterior(lm["L5S1"], lm["T12L1"])
        # The rest keeps the lumbar body's shape: COM of the remainder, inertia
        # scaled with its mass.
        m = lb.mass - mv
        c = (lb.mass * lb.com - mv * p_v) / m
        segs["lumbar"] = Segment("lumbar", lb.parent, lb.joint, lb.origin, m, c,
                                 lb.inertia * (m / lb.mass))
        r = 0.06 * sL  # the visceral block's own inertia: a sphere of 6 cm radius
        segs["viscera"] = Segment("viscera", "lumbar", "prismatic_xz", p_v.copy(), mv,
                                  p_v.copy(), np.eye(3) * 0.4 * mv * r**2)

    # Contact points and seat surfaces.
    pts: list[ContactPoint] = []
    surf: dict[str, Surface] = {}
    # Unloaded skin points on the surfaces; statics.fit_seat sets each
    # group's compression (the contoured seat fits the subject).
    d_pel = d_th = d_back = d_foot = 0.0
    surf["pan"] = Surface("pan", n_pan, 0.0, "pan")

    def on_pan(p, depth):  # project onto the pan plane, then sink by depth
        return p - (n_pan @ p) * n_pan - depth * n_pan

    wy = v["hip_breadth"] / 0.365
    c_pel = hip + np.array([-0.03 * sL, 0.0, 0.0])
    for dx in (-0.07, 0.0, 0.07):
        for dy in (-0.065, 0.0, 0.065):
            p = on_pan(c_pel + dx * sL * t_pan + dy * wy * EY, d_pel)
            pts.append(ContactPoint("pelvis", p, "pan", "pelvis"))
    for side in ("l", "r"):
        hjc, knee = lm[f"hip_{side}"], lm[f"knee_{side}"]
        for f in (0.30, 0.475, 0.65):
            c = hjc + f * (knee - hjc)
            for dy in (-0.035, 0.035):
                p = on_pan(c + dy * sL * EY, d_th)
                pts.append(ContactPoint(f"thigh_{side}", p, "pan", "thigh"))
    # Back: skin points posterior of the spine; one pad plane each
    # (parallel to the back-rest plane, contoured back-rest).
    back = [("lumbar", "L5S1", "T12L1", 0.5, 0.075, 0.05, "lumbar_pad"),
            ("lower_thorax", "T12L1", "T6T7", 0.6, 0.085, 0.06, "thoracic_pad"),
            ("upper_thorax", "T6T7", "C7T1", 0.5, 0.080, 0.08, "shoulder_pad")]
    for body, a, b, f, dpost, dy, pad in back:
        pa, pb = lm[a], lm[b]
        c = pa + f * (pb - pa) - dpost * sL * anterior(pa, pb)
        pp = [c + s * dy * sL * EY for s in (1.0, -1.0)]
        for p in pp:
            pts.append(ContactPoint(body, p, pad, "back"))
        surf[pad] = Surface(pad, n_back, float(np.mean([n_back @ p for p in pp])) - d_back,
                            "back")
    # Feet: heel and two points under the metatarsal heads per foot.
    soles = []
    for side, sg in (("l", 1.0), ("r", -1.0)):
        ankle, ball = lm[f"ankle_{side}"], lm[f"ball_{side}"]
        heel = ankle + np.array([-0.045 * sL, 0.0, -ankle_h])
        med = ball + np.array([0.01 * sL, -sg * 0.030 * sL, 0.0])
        lat = ball + np.array([-0.015 * sL, sg * 0.040 * sL, 0.0])
        for p in (heel, med, lat):
            pts.append(ContactPoint(f"foot_{side}", p, "floor", "foot"))
            soles.append(p[2])
    surf["floor"] = Surface("floor", np.array([0.0, 0.0, 1.0]), float(np.mean(soles)) + d_foot,
                            "floor")

    if effects.get("seat_cushion_dynamics", {}).get("on", 0.0) > 0:
        mc = effects["seat_cushion_dynamics"]["mass_kg"]
        segs["cushion"] = Segment("cushion", None, "prismatic_z", np.zeros(3), mc,
                                  np.array([0.2, 0.0, -0.04]),
                                  np.diag([0.05, 0.05, 0.1]) * mc)

    markers = {
        "pelvis": ("pelvis", segs["pelvis"].com.copy()),
        "trunk": ("lower_thorax", lm["T6T7"].copy()),
        "head": ("head", segs["head"].com.copy()),
        "knee_l": ("thigh_l", lm["knee_l"].copy()),
        "knee_r": ("thigh_r", lm["knee_r"].copy()),
    }
    total = sum(s.mass for s in segs.values() if s.name != "cushion")
    return BodyModel(segs, pts, surf, lm, markers, total, arms_separate, hand_points)
