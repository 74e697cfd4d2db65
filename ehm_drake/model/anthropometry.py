"""Segment inertial properties and the seated reference posture.

Source of the inertial data
---------------------------
de Leva P. (1996) "Adjustments to Zatsiorsky-Seluyanov's segment inertia
parameters", J. Biomechanics 29(9):1223-1230, Table 4, male column.  The table
gives, for each segment, its mass as a fraction of body mass, the centre of
mass (CoM) as a fraction of the segment length from the proximal (cranial)
end point, and three radii of gyration as fractions of the segment length.
The reference sample had stature 1.741 m and mass 73.0 kg; segment lengths
are the sample's mean lengths (Table 1).

The efficient human model (EHM) of Desai et al. has 12 segments and no arms;
de Leva's segments are mapped onto them as follows (see `SEGMENT_SOURCES`):

* pelvis + lower torso  = de Leva LPT (lower trunk, omphalion to hip joint
  centres), split at L5/S1; the lower-torso slab between L5/S1 and L4/L5 gets
  `LOWER_TORSO_FRACTION_OF_LPT` of the LPT mass.
* middle torso          = de Leva MPT (xiphoid to omphalion).
* upper torso           = de Leva UPT (cervicale to xiphoid) + both arms
  (upper arm, forearm, hand), lumped rigidly at their seated positions with
  the hands resting on the thighs.  The arms are a separate candidate effect
  in the gap diagnosis (`arms`).
* neck + head           = de Leva head (vertex to cervicale), split with
  `NECK_FRACTION_OF_HEAD` of its mass in the neck.
* thighs, lower legs (shanks), feet = de Leva thigh, shank, foot.

Frames and posture
------------------
All coordinates here are in the seat frame S, which is also the simulation's
world frame W: x fore-aft (forward), y lateral (left), z up; origin on the
seat-pan surface, mid-sagittal, in the plane of the front faces of the
backrest pads.  The reference posture is the paper's "erect posture, high
support" (Desai et al., Sec. II; Mirakhorlo et al. 2022): pan horizontal,
lower pad at the posterior superior iliac spine (PSIS), upper pad at the
inferior angle of the scapula, feet flat on the floor.  Joint centres were
placed from the de Leva segment lengths (scaled to stature 1.76 m) with
sagittal angles typical of erect sitting (lumbar lordosis, thoracic
kyphosis); the resulting sitting height (vertex above the pan) is 0.92 m,
as in the paper.

Each body frame B has its origin at the body's proximal joint centre and is
parallel to W in the reference posture, so every joint angle is zero there.

Scaling to another body
-----------------------
`build_body(BodyMeasures(mass, stature, sitting_height))` keeps de Leva's
fractions and scales the posture affinely: trunk, neck and head lengths
(z) with sitting height, leg lengths with (stature - sitting height), and
breadths/depths with sqrt(mass ratio / length ratio) so that segment
density is unchanged.  Inertias follow from scaling the second moments of
mass with the same affine map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# ---------------------------------------------------------------------------
# Source data
# ---------------------------------------------------------------------------

#: de Leva (1996) Table 4 (male) and Table 1 lengths.
#: name: (length_mm, mass_percent, com_percent_from_proximal,
#: r_sagittal_percent, r_transverse_percent, r_longitudinal_percent).
#: r_sagittal is about the antero-posterior axis, r_transverse about the
#: medio-lateral axis, r_longitudinal about the segment's long axis.
DE_LEVA_1996_MALE: dict[str, tuple[float, float, float, float, float, float]] = {
    "head": (242.9, 6.94, 50.02, 30.3, 31.5, 26.1),  # vertex - cervicale
    "upt": (242.1, 15.96, 50.66, 50.5, 32.0, 46.5),  # cervicale - xiphoid
    "mpt": (215.5, 16.33, 45.02, 48.2, 38.3, 46.8),  # xiphoid - omphalion
    "lpt": (145.7, 11.17, 61.15, 61.5, 55.1, 58.7),  # omphalion - mid hip
    "upper_arm": (281.7, 2.71, 57.72, 28.5, 26.9, 15.8),
    "forearm": (268.9, 1.62, 45.74, 27.6, 26.5, 12.1),
    "hand": (86.2, 0.61, 79.00, 62.8, 51.3, 40.1),
    "thigh": (422.2, 14.16, 40.95, 32.9, 32.9, 14.9),
    "shank": (434.0, 4.33, 44.59, 25.5, 24.9, 10.3),
    "foot": (258.1, 1.37, 44.15, 25.7, 24.5, 12.4),
}
DE_LEVA_SAMPLE_STATURE_M = 1.741
DE_LEVA_SAMPLE_MASS_KG = 73.0

#: Share of de Leva's LPT mass in the lower-torso slab between L5/S1 and
#: L4/L5: a 0.037 m slab of the 0.147 m LPT, less dense than the bony pelvis
#: and buttocks below it (reason: slab volume fraction, rounded down).
LOWER_TORSO_FRACTION_OF_LPT = 0.27
#: Share of de Leva's head(+neck) mass in the neck: neck ~1.0 kg of ~5.2 kg
#: (head alone 4.0-4.4 kg, Yoganandan et al. 2009, J Biomech 42:1177).
NECK_FRACTION_OF_HEAD = 0.20


@dataclass(frozen=True)
class BodyMeasures:
    """Whole-body anthropometry that selects the scaled model.

    Parameters
    ----------
    mass_kg : body mass in kg.
    stature_m : standing height in m.
    sitting_height_m : vertex height above the seat surface, sitting erect,
        in m.  ``None`` scales the reference sitting height with stature.
    """

    mass_kg: float = 75.3
    stature_m: float = 1.76
    sitting_height_m: float | None = None

    def resolved_sitting_height(self) -> float:
        if self.sitting_height_m is not None:
            return float(self.sitting_height_m)
        return REFERENCE.sitting_height_m * self.stature_m / REFERENCE.stature_m

    def validate(self) -> None:
        """Raise ValueError for bodies outside the range the scaling covers."""
        checks = [
            ("mass_kg", self.mass_kg, 35.0, 160.0, "kg"),
            ("stature_m", self.stature_m, 1.30, 2.10, "m"),
        ]
        for name, value, lo, hi, unit in checks:
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
            if not lo <= value <= hi:
                hint = ""
                if name == "stature_m" and 130 <= value <= 210:
                    hint = " (it looks like centimetres; give metres)"
                if name == "mass_kg" and value < lo and value * 1000 >= lo:
                    hint = " (it looks like tonnes; give kilograms)"
                raise ValueError(
                    f"{name}={value} {unit} is outside the adult range "
                    f"[{lo}, {hi}] {unit} covered by the de Leva scaling{hint}"
                )
        sh = self.resolved_sitting_height()
        ratio = sh / self.stature_m
        if not 0.45 <= ratio <= 0.58:
            raise ValueError(
                f"sitting_height_m={sh:.3f} m is {ratio:.2f} of stature; adult "
                "sitting height is 0.47-0.56 of stature (give it in metres)"
            )


REFERENCE = BodyMeasures(mass_kg=75.3, stature_m=1.76, sitting_height_m=0.92)

# ---------------------------------------------------------------------------
# Reference posture of the 50th-percentile male (seat frame, metres)
# ---------------------------------------------------------------------------
# Lengths follow de Leva scaled by 1.76/1.741 = 1.0109: thigh (HJC-KJC)
# 0.427 m, shank (KJC-lateral malleolus) 0.439 m, foot (heel-toe) 0.261 m.
# Hip joint centres 0.095 m above the compressed pan surface and 0.135 m in
# front of the back plane (SAE J826 H-point to back-line distance ~0.135 m).
_HJC_X, _HJC_Z, _HJC_Y = 0.135, 0.095, 0.085
_THIGH_PITCH = math.radians(5.0)  # knee slightly higher than hip
_SHANK_TILT = math.radians(10.0)  # shank inclined forward; knee angle ~95 deg
_L_THIGH, _L_SHANK, _L_FOOT = 0.4268, 0.4387, 0.2609
_KJC_Y = 0.095
_ANKLE_HEIGHT = 0.075  # lateral malleolus above the sole

_KJC_X = _HJC_X + _L_THIGH * math.cos(_THIGH_PITCH)
_KJC_Z = _HJC_Z + _L_THIGH * math.sin(_THIGH_PITCH)
_AJC_X = _KJC_X + _L_SHANK * math.sin(_SHANK_TILT)
_AJC_Z = _KJC_Z - _L_SHANK * math.cos(_SHANK_TILT)
_FLOOR_Z = _AJC_Z - _ANKLE_HEIGHT

#: Landmarks of the reference posture (seat frame).  Spine joint centres are
#: at the vertebral bodies; sagittal chord angles: L5/S1-L4/L5 10 deg forward
#: (lordosis), L4/L5-T12/L1 vertical, T12/L1-C7/T1 8 deg backward
#: (kyphosis), C7/T1-C0/C1 15 deg forward (cervical lordosis).
LANDMARKS_50TH: dict[str, tuple[float, float, float]] = {
    "mid_hip": (_HJC_X, 0.0, _HJC_Z),
    "hip_l": (_HJC_X, _HJC_Y, _HJC_Z),
    "hip_r": (_HJC_X, -_HJC_Y, _HJC_Z),
    "L5S1": (0.085, 0.0, 0.175),
    "L4L5": (0.0916, 0.0, 0.2124),
    "T12L1": (0.0916, 0.0, 0.3524),
    "T8": (0.0766, 0.0, 0.462),
    "C7T1": (0.0503, 0.0, 0.6465),
    "C0C1": (0.0788, 0.0, 0.7528),
    "vertex": (0.0950, 0.0, 0.920),
    "knee_l": (_KJC_X, _KJC_Y, _KJC_Z),
    "knee_r": (_KJC_X, -_KJC_Y, _KJC_Z),
    "ankle_l": (_AJC_X, _KJC_Y, _AJC_Z),
    "ankle_r": (_AJC_X, -_KJC_Y, _AJC_Z),
    # Seated arm (both sides mirror): shoulder joint centre, elbow, wrist,
    # third metacarpal head; forearms and hands rest on the thighs.
    "shoulder_l": (0.070, 0.190, 0.585),
    "elbow_l": (0.120, 0.200, 0.315),
    "wrist_l": (0.360, 0.170, 0.225),
    "hand_l": (0.440, 0.150, 0.205),
    # Backrest support landmarks on the skin (Desai et al. Sec. II).
    "psis_skin": (0.0, 0.0, 0.150),
    "scapula_angle_skin": (0.0, 0.0, 0.450),
    "floor": (_AJC_X, _KJC_Y, _FLOOR_Z),  # under the left ankle
}

#: Centres of mass of the reference posture.  Trunk CoMs lie 3-5 cm anterior
#: of the vertebral bodies (abdominal/thoracic contents), which is why the
#: erect posture drifts forward without integral control (Desai et al. IV).
#: Head CoM 0.02 m anterior and 0.035 m superior of the occipital condyles
#: (Yoganandan et al. 2009).  Limb CoMs at de Leva's longitudinal fractions.
_COM_50TH: dict[str, tuple[float, float, float]] = {
    "pelvis": (0.108, 0.0, 0.112),
    "lower_torso": (0.125, 0.0, 0.194),
    "middle_torso": (0.128, 0.0, 0.290),
    "upt": (0.112, 0.0, 0.497),
    "neck": (0.070, 0.0, 0.700),
    "head": (0.0988, 0.0, 0.7878),
}


def _lerp(a, b, t):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a + t * (b - a)


def _mirror(p):
    return (p[0], -p[1], p[2])


# ---------------------------------------------------------------------------
# Body description
# ---------------------------------------------------------------------------


@dataclass
class Ellipsoid:
    """A contact/visual ellipsoid, axes parallel to its body frame."""

    name: str
    center_W: np.ndarray  # centre in the seat frame, reference posture
    semi_axes: np.ndarray  # (a, b, c) along x, y, z


@dataclass
class Segment:
    """One rigid segment of the model, described in the reference posture."""

    name: str
    mass: float
    origin_W: np.ndarray  # body-frame origin (proximal joint centre)
    com_W: np.ndarray
    inertia_W: np.ndarray  # 3x3, about the CoM, world axes
    parent: str | None
    joint: str | None  # "free", "ball", "universal", "revolute", "ball+prismatic"
    joint_name: str | None
    group: str  # "trunk" or "leg" (which length scale applies)
    source: str
    collision: list[Ellipsoid] = field(default_factory=list)


@dataclass
class SeatGeometry:
    """Seat parts as boxes in the seat frame: name -> (centre, size)."""

    boxes: dict[str, tuple[np.ndarray, np.ndarray]]


@dataclass
class Body:
    """A complete body description, ready to be written as SDF."""

    measures: BodyMeasures
    segments: dict[str, Segment]
    landmarks: dict[str, np.ndarray]
    #: Marker frames for the outputs: name -> (segment, position in W).
    markers: dict[str, tuple[str, np.ndarray]]
    seat: SeatGeometry

    @property
    def total_mass(self) -> float:
        return sum(s.mass for s in self.segments.values())


def _radii_inertia(mass, length, r_sag, r_trans, r_long, long_axis):
    """Principal inertia from de Leva radii (percent of length).

    `long_axis` is the world axis (0=x, 1=y, 2=z) the segment's long axis is
    aligned with in the reference posture; the antero-posterior ("sagittal")
    axis of a segment lying along x (thigh, foot) is z.
    """
    i_sag = mass * (r_sag / 100 * length) ** 2
    i_trans = mass * (r_trans / 100 * length) ** 2
    i_long = mass * (r_long / 100 * length) ** 2
    if long_axis == 2:
        return np.diag([i_sag, i_trans, i_long])
    if long_axis == 0:
        return np.diag([i_long, i_trans, i_sag])
    raise ValueError(long_axis)


def _rotate_about_y(inertia, angle):
    c, s = math.cos(angle), math.sin(angle)
    R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return R @ inertia @ R.T


def _parallel_axis(mass, inertia_com, offset):
    d = np.asarray(offset, float)
    return inertia_com + mass * (d @ d * np.eye(3) - np.outer(d, d))


def _combine(parts):
    """Combine (mass, com, inertia_about_com) parts into one rigid body."""
    m = sum(p[0] for p in parts)
    com = sum(p[0] * np.asarray(p[1], float) for p in parts) / m
    inertia = sum(_parallel_axis(p[0], p[2], np.asarray(p[1]) - com) for p in parts)
    return m, com, inertia


def _box_inertia(mass, size):
    x, y, z = size
    return mass / 12.0 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])


def _reference_body(separate_arms: bool = False) -> Body:
    """The 50th-percentile male of the paper: 75.3 kg, 1.76 m, 0.92 m.

    With `separate_arms`, each arm (upper arm, forearm and hand, rigid in
    the seated pose, hand on the thigh) is its own segment on a spherical
    shoulder joint instead of being lumped into the upper torso (the `arms`
    effect of the gap diagnosis)."""
    M = REFERENCE.mass_kg
    length_scale = REFERENCE.stature_m / DE_LEVA_SAMPLE_STATURE_M
    L = {k: v[0] / 1000.0 * length_scale for k, v in DE_LEVA_1996_MALE.items()}
    frac = {k: v[1] / 100.0 for k, v in DE_LEVA_1996_MALE.items()}
    radii = {k: v[3:] for k, v in DE_LEVA_1996_MALE.items()}
    lm = {k: np.array(v, float) for k, v in LANDMARKS_50TH.items()}
    for side in ("l",):
        for name in ("shoulder", "elbow", "wrist", "hand"):
            lm[f"{name}_r"] = np.array(_mirror(lm[f"{name}_{side}"]))
    com = {k: np.array(v, float) for k, v in _COM_50TH.items()}

    def deleva(name, long_axis=2, pitch=0.0):
        m = frac[name] * M
        inertia = _radii_inertia(m, L[name], *radii[name], long_axis=long_axis)
        return m, _rotate_about_y(inertia, pitch)

    segs: dict[str, Segment] = {}

    # Pelvis and lower torso: de Leva LPT split at L5/S1.  The lower-torso
    # slab (0.037 m tall, 0.32 m broad, 0.22 m deep) is a uniform box; the
    # pelvis receives the rest of the LPT mass and inertia so that the two
    # together have exactly de Leva's LPT properties.
    m_lpt, I_lpt = deleva("lpt")
    m_lt = LOWER_TORSO_FRACTION_OF_LPT * m_lpt
    m_pel = m_lpt - m_lt
    com_lpt = (m_pel * com["pelvis"] + m_lt * com["lower_torso"]) / m_lpt
    I_lt = _box_inertia(m_lt, (0.22, 0.32, 0.037))
    # I_lpt (about com_lpt) = I_pel + I_lt, each shifted to com_lpt.
    I_pel = (
        I_lpt
        - _parallel_axis(m_lt, I_lt, com["lower_torso"] - com_lpt)
        - _parallel_axis(m_pel, np.zeros((3, 3)), com["pelvis"] - com_lpt)
    )
    segs["pelvis"] = Segment(
        "pelvis", m_pel, lm["mid_hip"], com["pelvis"], I_pel, None, "free",
        "pelvis_free", "trunk", "de Leva LPT minus lower-torso slab",
    )
    segs["lower_torso"] = Segment(
        "lower_torso", m_lt, lm["L5S1"], com["lower_torso"], I_lt, "pelvis",
        "ball", "lumbosacral_L5S1", "trunk",
        f"{LOWER_TORSO_FRACTION_OF_LPT:.0%} of de Leva LPT (box 0.22x0.32x0.037 m)",
    )

    m_mpt, I_mpt = deleva("mpt")
    segs["middle_torso"] = Segment(
        "middle_torso", m_mpt, lm["L4L5"], com["middle_torso"], I_mpt,
        "lower_torso", "ball", "lumbar_L4L5", "trunk", "de Leva MPT",
    )

    # Upper torso: UPT with both arms lumped at their seated positions (or,
    # with `separate_arms`, the arms as their own segments, see below).
    m_upt, I_upt = deleva("upt")
    parts = [(m_upt, com["upt"], I_upt)]
    arm_parts = {}
    for side in ("l", "r"):
        chain = [
            ("upper_arm", lm[f"shoulder_{side}"], lm[f"elbow_{side}"]),
            ("forearm", lm[f"elbow_{side}"], lm[f"wrist_{side}"]),
            ("hand", lm[f"wrist_{side}"], lm[f"hand_{side}"]),
        ]
        arm_parts[side] = []
        for name, prox, dist in chain:
            m = frac[name] * M
            c = _lerp(prox, dist, DE_LEVA_1996_MALE[name][2] / 100.0)
            d = dist - prox
            pitch = math.atan2(d[0], -d[2])  # angle of the long axis from -z
            inertia = _rotate_about_y(
                _radii_inertia(m, L[name], *radii[name], long_axis=2), pitch
            )
            arm_parts[side].append((m, c, inertia))
    if not separate_arms:
        parts += arm_parts["l"] + arm_parts["r"]
    m_ut, com_ut, I_ut = _combine(parts)
    com["upper_torso"] = com_ut
    segs["upper_torso"] = Segment(
        "upper_torso", m_ut, lm["T12L1"], com_ut, I_ut, "middle_torso",
        "ball+prismatic", "thoracolumbar_T12L1", "trunk",
        "de Leva UPT" + ("" if separate_arms else
                         " + both arms (upper arm, forearm, hand) lumped"),
    )

    # Neck and head: de Leva head (vertex-cervicale) split.  Neck = uniform
    # cylinder r=0.055 m, h=0.11 m; head = remainder, so together they match
    # de Leva's head segment exactly.
    m_hn, I_hn = deleva("head")
    m_neck = NECK_FRACTION_OF_HEAD * m_hn
    m_head = m_hn - m_neck
    com_hn = (m_neck * com["neck"] + m_head * com["head"]) / m_hn
    r, h = 0.055, 0.11
    I_neck = m_neck * np.diag(
        [(3 * r * r + h * h) / 12, (3 * r * r + h * h) / 12, r * r / 2]
    )
    I_head = (
        I_hn
        - _parallel_axis(m_neck, I_neck, com["neck"] - com_hn)
        - _parallel_axis(m_head, np.zeros((3, 3)), com["head"] - com_hn)
    )
    segs["neck"] = Segment(
        "neck", m_neck, lm["C7T1"], com["neck"], I_neck, "upper_torso",
        "universal", "lower_neck_C7T1", "trunk",
        f"{NECK_FRACTION_OF_HEAD:.0%} of de Leva head (cylinder r=0.055, h=0.11 m)",
    )
    segs["head"] = Segment(
        "head", m_head, lm["C0C1"], com["head"], I_head, "neck", "ball",
        "upper_neck_C0C1", "trunk", "de Leva head minus neck",
    )

    if separate_arms:
        for side in ("l", "r"):
            m, c, inertia = _combine(arm_parts[side])
            segs[f"arm_{side}"] = Segment(
                f"arm_{side}", m, lm[f"shoulder_{side}"], c, inertia, "upper_torso", "ball",
                f"shoulder_{side}", "trunk",
                "de Leva upper arm + forearm + hand, rigid in the seated pose")

    # Legs.
    for side in ("l", "r"):
        hip, knee, ankle = lm[f"hip_{side}"], lm[f"knee_{side}"], lm[f"ankle_{side}"]
        m, I = deleva("thigh", long_axis=0, pitch=-_THIGH_PITCH)
        segs[f"thigh_{side}"] = Segment(
            f"thigh_{side}", m, hip, _lerp(hip, knee, 0.4095), I, "pelvis",
            "ball", f"hip_{side}", "leg", "de Leva thigh",
        )
        m, I = deleva("shank", long_axis=2, pitch=_SHANK_TILT)
        segs[f"lower_leg_{side}"] = Segment(
            f"lower_leg_{side}", m, knee, _lerp(knee, ankle, 0.4459), I,
            f"thigh_{side}", "revolute", f"knee_{side}", "leg", "de Leva shank",
        )
        heel = ankle + np.array([-0.050, 0.0, -_ANKLE_HEIGHT + 0.030])
        toe = ankle + np.array([_L_FOOT - 0.050, 0.0, -_ANKLE_HEIGHT + 0.030])
        m, I = deleva("foot", long_axis=0)
        segs[f"foot_{side}"] = Segment(
            f"foot_{side}", m, ankle, _lerp(heel, toe, 0.4415), I,
            f"lower_leg_{side}", "revolute", f"ankle_{side}", "leg", "de Leva foot",
        )

    # Contact ellipsoids (soft tissue surfaces), reference posture.  Each
    # touches its seat part with zero penetration; the body settles into it.
    segs["pelvis"].collision.append(
        Ellipsoid("buttocks", np.array([0.105, 0.0, 0.075]), np.array([0.110, 0.170, 0.075]))
    )
    segs["pelvis"].collision.append(
        Ellipsoid("lower_back", np.array([0.055, 0.0, 0.150]), np.array([0.055, 0.120, 0.060]))
    )
    segs["upper_torso"].collision.append(
        Ellipsoid("upper_back", np.array([0.070, 0.0, 0.450]), np.array([0.070, 0.150, 0.110]))
    )
    for side, sgn in (("l", 1.0), ("r", -1.0)):
        segs[f"thigh_{side}"].collision.append(
            Ellipsoid(f"thigh_{side}", np.array([0.330, sgn * 0.090, 0.080]),
                      np.array([0.190, 0.075, 0.080]))
        )
        a = lm[f"ankle_{side}"]
        segs[f"foot_{side}"].collision.append(
            Ellipsoid(f"foot_{side}", np.array([a[0] + 0.080, sgn * 0.095, _FLOOR_Z + 0.030]),
                      np.array([0.130, 0.045, 0.030]))
        )

    markers = {
        "pelvis": ("pelvis", com["pelvis"].copy()),
        "trunk": ("upper_torso", lm["T8"].copy()),
        "head": ("head", com["head"].copy()),
        "knee_l": ("thigh_l", lm["knee_l"].copy()),
        "knee_r": ("thigh_r", lm["knee_r"].copy()),
    }
    body = Body(REFERENCE, segs, lm, markers, SeatGeometry({}))
    body.seat = _seat_for(body)
    return body


#: Seat part sizes (m): pan 0.50 deep x 0.50 wide; pads 0.30 wide x 0.10
#: tall (lower) and 0.34 x 0.12 (upper), 0.05 thick; floor 1.6 x 1.2.
PAN_DEPTH, PAN_WIDTH, PART_THICKNESS = 0.50, 0.50, 0.05
LOWER_PAD_SIZE = (0.05, 0.30, 0.10)
UPPER_PAD_SIZE = (0.05, 0.34, 0.12)


#: The subject leans against the pads ("erect posture, high support"): in the
#: reference posture the pads' faces sit this far inside the back's surface.
PAD_PRELOAD_M = 0.003


def _seat_for(body: Body) -> SeatGeometry:
    """The seat adjusted to the occupant, as the lab adjusted its pads.

    Pan top at z=0, pads' front faces at x=PAD_PRELOAD_M centred on the PSIS
    and scapular-angle heights, floor at the sole of the feet.
    """
    lm = body.landmarks
    t = PART_THICKNESS
    boxes = {
        "pan": (np.array([PAN_DEPTH / 2 - 0.02, 0.0, -t / 2]),
                np.array([PAN_DEPTH, PAN_WIDTH, t])),
        "lower_pad": (np.array([PAD_PRELOAD_M - LOWER_PAD_SIZE[0] / 2, 0.0,
                                lm["psis_skin"][2]]), np.array(LOWER_PAD_SIZE)),
        "upper_pad": (np.array([PAD_PRELOAD_M - UPPER_PAD_SIZE[0] / 2, 0.0,
                                lm["scapula_angle_skin"][2]]), np.array(UPPER_PAD_SIZE)),
        "floor": (np.array([0.5, 0.0, lm["floor"][2] - t / 2]),
                  np.array([1.6, 1.2, t])),
    }
    return SeatGeometry(boxes)


def _scale_maps(measures: BodyMeasures):
    ref = REFERENCE
    lam_m = measures.mass_kg / ref.mass_kg
    lam_trunk = measures.resolved_sitting_height() / ref.sitting_height_m
    lam_leg = (measures.stature_m - measures.resolved_sitting_height()) / (
        ref.stature_m - ref.sitting_height_m
    )
    lam_t_trunk = math.sqrt(lam_m / lam_trunk)
    lam_t_leg = math.sqrt(lam_m / lam_leg)
    S_trunk = np.diag([lam_t_trunk, lam_t_trunk, lam_trunk])
    S_leg = np.diag([lam_leg, lam_t_leg, lam_leg])
    return lam_m, S_trunk, S_leg


def build_body(measures: BodyMeasures = REFERENCE, separate_arms: bool = False,
               viscera_kg: float = 0.0) -> Body:
    """The model body for `measures`, scaled from the 50th-percentile male.

    `separate_arms` and `viscera_kg` give the extended bodies of the gap
    diagnosis' `arms` and `visceral_mass` effects.  Raises ValueError for
    anthropometry outside the adult range.
    """
    measures.validate()
    ref = _reference_body(separate_arms)
    if measures == REFERENCE:
        return with_viscera(ref, viscera_kg)
    lam_m, S_trunk, S_leg = _scale_maps(measures)

    hips = {"l": ref.landmarks["hip_l"], "r": ref.landmarks["hip_r"]}

    def map_trunk(p):
        return S_trunk @ p

    def map_leg(p, side):
        hip = hips[side]
        return S_trunk @ hip + S_leg @ (p - hip)

    def map_point(p, group, side="l"):
        return map_trunk(p) if group == "trunk" else map_leg(p, side)

    def scale_inertia(inertia, S):
        # Second moments P = tr(I)/2 * 1 - I scale as S P S (affine map).
        P = 0.5 * np.trace(inertia) * np.eye(3) - inertia
        P = lam_m * S @ P @ S
        return np.trace(P) * np.eye(3) - P

    segs = {}
    for name, s in ref.segments.items():
        side = "r" if name.endswith("_r") else "l"
        S = S_trunk if s.group == "trunk" else S_leg
        segs[name] = Segment(
            s.name, s.mass * lam_m, map_point(s.origin_W, s.group, side),
            map_point(s.com_W, s.group, side), scale_inertia(s.inertia_W, S),
            s.parent, s.joint, s.joint_name, s.group, s.source,
            [Ellipsoid(e.name, map_point(e.center_W, s.group, side), S @ e.semi_axes)
             for e in s.collision],
        )
    leg_landmarks = {"knee_l", "knee_r", "ankle_l", "ankle_r", "floor"}  # floor: the soles
    lm = {}
    for k, p in ref.landmarks.items():
        if k in leg_landmarks:
            side = "r" if k.endswith("_r") else "l"
            lm[k] = map_leg(p, side)
        else:
            lm[k] = map_trunk(p)
    markers = {
        k: (seg, map_point(p, ref.segments[seg].group, "r" if seg.endswith("_r") else "l"))
        for k, (seg, p) in ref.markers.items()
    }
    body = Body(measures, segs, lm, markers, SeatGeometry({}))
    body.seat = _seat_for(body)
    return with_viscera(body, viscera_kg)


#: Abdominal viscera centre of mass: ~4 cm anterior of the middle-torso CoM,
#: at its height (the abdominal cavity lies in front of the lumbar spine).
VISCERA_OFFSET_M = np.array([0.04, 0.0, 0.0])


def with_viscera(body: Body, mass_kg: float) -> Body:
    """`body` with `mass_kg` of abdominal viscera taken out of the middle
    torso (a point mass at its centre, removed with its parallel-axis
    inertia) and put on its own segment, a uniform sphere of radius 0.07 m
    on a vertical prismatic joint (the `visceral_mass` effect)."""
    if mass_kg <= 0:
        return body
    mt = body.segments["middle_torso"]
    if mass_kg >= 0.5 * mt.mass:
        raise ValueError(f"viscera mass {mass_kg} kg exceeds half the middle torso's "
                         f"{mt.mass:.1f} kg")
    c_v = mt.com_W + VISCERA_OFFSET_M
    m_rest = mt.mass - mass_kg
    com_rest = (mt.mass * mt.com_W - mass_kg * c_v) / m_rest
    # I_mt (about com_mt) = I_rest shifted + point mass shifted.
    I_rest = (mt.inertia_W - _parallel_axis(mass_kg, np.zeros((3, 3)), c_v - mt.com_W)
              - _parallel_axis(m_rest, np.zeros((3, 3)), com_rest - mt.com_W))
    I_v = 0.4 * mass_kg * 0.07**2 * np.eye(3)
    I_rest = I_rest - I_v  # the sphere's own inertia came out of the torso too
    segs = {}
    for name, seg in body.segments.items():
        if name == "middle_torso":
            seg = Segment(seg.name, m_rest, seg.origin_W, com_rest, I_rest, seg.parent,
                          seg.joint, seg.joint_name, seg.group,
                          seg.source + f" minus {mass_kg:g} kg viscera", seg.collision)
        segs[name] = seg
        if name == "middle_torso":
            segs["viscera"] = Segment(
                "viscera", mass_kg, c_v.copy(), c_v.copy(), I_v, "middle_torso",
                "prismatic_z", "visceral_z", "trunk", "abdominal viscera (point-like)")
    return Body(body.measures, segs, body.landmarks, body.markers, body.seat)
