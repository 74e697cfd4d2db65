"""Parameter table of the `spine5` reality: every value with its unit and its
source or reason, and the subject scatter.

Sources (short keys used in the table):

* ANSUR88 -- Gordon C.C. et al. (1989) 1988 Anthropometric Survey of U.S. Army
  Personnel (NATICK/TR-89/044), male means, rounded.
* DEMPSTER -- Dempster W.T. (1955) Space requirements of the seated operator
  (WADC-TR-55-159), segment mass fractions, centre-of-mass ratios and radii of
  gyration as tabulated by Winter D.A. (2009) Biomechanics and Motor Control of
  Human Movement, 4th ed., Table 4.1.
* DRILLIS -- Drillis R. & Contini R. (1966) segment lengths as fractions of
  stature H (Winter 2009, Fig. 4.1).
* PEARSALL -- Pearsall D.J., Reid J.G., Livingston L.A. (1996) Segmental
  inertial parameters of the human trunk as determined from computed
  tomography, Ann. Biomed. Eng. 24:198-210: mass per vertebral level rising
  from 1.1 % body mass at T1 to 2.6 % at L5; centres of mass anterior to the
  vertebral centroids (up to 5 cm in the lower thoracic region, ~1 cm at
  L3/L4, ~4 cm at T7/T8 for the upper trunk).
* BEIER -- Beier G. et al. (1980) Center of gravity and moments of inertia of
  human heads (IRCOBI): 21 cadaver heads of 3.7-5.8 kg, radii of gyration
  6.89, 7.18, 5.85 cm about x, y, z.
* HANAVAN -- Hanavan E.P. (1964) A mathematical model of the human body
  (AMRL-TR-64-102): segments as uniform solids (here elliptic cylinders of
  the ANSUR88 depths and breadths) for the inertias the tables do not give.
* PANJABI -- Panjabi M.M. et al. (1976, 1994), Oxland T.R. (1992): in-vitro
  intervertebral flexibility, ligamentous motion segments of order 1-2 N m/deg
  (lumbar), 2-3 N m/deg (thoracic with rib cage), 0.3-0.5 N m/deg (cervical)
  near neutral; McGILL -- McGill S.M., Seguin J., Bennett G. (1994) Passive
  stiffness of the lumbar torso (Spine 19:696): the in-vivo passive torso is
  several times stiffer than the ligamentous spine.
* RELAX -- stress relaxation of spinal motion segments and soft tissue:
  fast components with time constants of 0.1-1 s (e.g. Oza & Adams; Li,
  Patwardhan et al. 1995 viscoelastic lumbar segments), slow ones of minutes
  (not modelled: a test lasts a minute, the slow part is a static offset).
* TMAX -- maximum voluntary isometric moments, males: trunk extension
  200-300 N m, flexion 120-180 N m, lateral bending 100-150 N m, axial
  rotation 60-100 N m (e.g. McGill 1991; Marras et al.); neck extension
  30-50 N m, flexion 15-30 N m (Vasavada, Li & Delp 2001); hip 150-250 N m,
  knee 150-250 N m, ankle 50-150 N m (Anderson et al. 2007).
* ACT -- excitation-contraction (activation) time constants 20-60 ms
  (Winters & Stark 1985; Zajac 1989).
* DELAY -- short-latency stretch-reflex latencies of trunk and neck muscles
  25-40 ms (e.g. Zedka et al. 1998: erector spinae 20-30 ms; Cholewicki et al.
  2000); vestibulocollic latencies are shorter (~10-20 ms) but the
  orientation estimate adds processing time: one delay is used for both.
* SOFT -- the seated body's vertical resonance falls with vibration
  magnitude: ~6 Hz at 0.25 m/s^2 to ~4 Hz at 2.0 m/s^2 r.m.s. (Fairley &
  Griffin 1989, J. Biomech. 22:81-94), x0.87 per doubling; short-range
  stiffness of muscle and soft tissue lost beyond small strains (Loram,
  Maganaris & Lakie 2007, J. Physiol. 584:661-675: the calf's stiffness falls
  81 % from 0.03 to 7 deg).
* SEAT -- seat and tissue stiffness: the vertical seated-body resonance near
  5 Hz on a rigid seat is carried by buttock-thigh tissue of total vertical
  stiffness of order 5e4-1e5 N/m with damping of order 1-2e3 N s/m (lumped
  apparent-mass models, e.g. Wei & Griffin 1998, J. Sound Vib. 212:855);
  backrest foam + back tissue 1-3e4 N/m (e.g. Mandapuram, Rakheja et al.
  seat-back dynamic stiffness); shoe sole + heel pad 2-5e4 N/m per point at
  low load; fabric/clothing friction 0.5-0.9 (coated fabric or leather with
  smooth clothing 0.2-0.4).

The subject: every entry flagged ``scatter`` is scaled by its own seeded
factor uniform in [0.8, 1.2] (one factor per entry, used for both sides:
the subject stays left-right symmetric).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Inter-subject scatter: factors uniform in [1 - SPREAD, 1 + SPREAD].
SPREAD = 0.20


@dataclass(frozen=True)
class P:
    value: float
    unit: str
    source: str
    scatter: bool = True


_M = 78.5  # body mass, kg (ANSUR88 male mean)
#: Pearsall per-level trunk masses: linear from 1.1 % (T1) to 2.6 % (L5) of
#: body mass over the 17 levels T1..L5; the remainder of Pearsall's trunk
#: (41.6 %) is the pelvis.  The four trunk bodies take these shares of
#: Dempster's trunk mass (49.7 %, which includes the shoulder girdle).
_LEVEL = [1.1 + (2.6 - 1.1) * i / 16 for i in range(17)]
_UPPER_T, _LOWER_T, _LUMBAR = sum(_LEVEL[0:6]), sum(_LEVEL[6:12]), sum(_LEVEL[12:17])
_PELVIS = 41.6 - _UPPER_T - _LOWER_T - _LUMBAR
_TRUNK = 0.497 * _M


def _trunk_share(part: float) -> float:
    return round(_TRUNK * part / 41.6, 3)


PARAMS: dict[str, P] = {
    # ---------------------------------------------------------- masses (kg)
    "mass_pelvis": P(_trunk_share(_PELVIS), "kg",
                     "DEMPSTER trunk 49.7 % x PEARSALL share below L5 (10.2/41.6)"),
    "mass_lumbar": P(_trunk_share(_LUMBAR), "kg",
                     "DEMPSTER trunk x PEARSALL share of L1-L5 (12.1/41.6)"),
    "mass_lower_thorax": P(_trunk_share(_LOWER_T), "kg",
                           "DEMPSTER trunk x PEARSALL share of T7-T12 (11.4/41.6)"),
    "mass_upper_thorax": P(_trunk_share(_UPPER_T), "kg",
                           "DEMPSTER trunk x PEARSALL share of T1-T6 (8.0/41.6); arms "
                           "added when lumped"),
    "mass_head": P(4.5, "kg", "BEIER: heads of 3.7-5.8 kg; 4.5 kg for a 78.5 kg male"),
    "mass_neck": P(round(0.081 * _M - 4.5, 3), "kg",
                   "DEMPSTER head+neck 8.1 % minus the head"),
    "mass_upper_arm": P(round(0.028 * _M, 3), "kg", "DEMPSTER upper arm 2.8 %"),
    "mass_forearm_hand": P(round(0.022 * _M, 3), "kg", "DEMPSTER forearm and hand 2.2 %"),
    "mass_thigh": P(round(0.100 * _M, 3), "kg", "DEMPSTER thigh 10.0 %"),
    "mass_shank": P(round(0.0465 * _M, 3), "kg", "DEMPSTER leg 4.65 %"),
    "mass_foot": P(round(0.0145 * _M, 3), "kg", "DEMPSTER foot 1.45 %"),
    # ------------------------------------------- inertia scale factors (-)
    # One factor per body on the inertia tensor (beyond the mass): the shape
    # scatter the mass and length factors do not cover.
    "inertia_trunk": P(1.0, "-", "scale on the trunk bodies' inertia (HANAVAN shapes)"),
    "inertia_head": P(1.0, "-", "scale on the head inertia (BEIER radii of gyration)"),
    "inertia_limbs": P(1.0, "-", "scale on limb inertias (DEMPSTER radii of gyration)"),
    # ------------------------------------------------- geometry (m, deg)
    "stature": P(1.756, "m", "ANSUR88 male mean stature; limb lengths by DRILLIS"),
    "hip_depth": P(0.135, "m",
                   "hip joint centre to the back-rest plane: ANSUR88 buttock-knee length "
                   "0.616 m minus thigh length (DRILLIS 0.245 H) minus ~0.05 m knee depth"),
    "hip_height": P(0.095, "m",
                    "hip joint centre above the pan: ischial tuberosity ~0.075 m below the "
                    "joint centre plus ~0.02 m compressed tissue"),
    "hip_half_width": P(0.085, "m",
                        "half distance of the hip joint centres (~0.36 x inter-ASIS 0.24 m, "
                        "Bell et al. 1990)"),
    "l5s1_back": P(0.040, "m",
                   "L5/S1 behind the hip joint centres in sitting (posterior pelvic tilt; cf. "
                   "Reed, Manary & Schneider 1999 seated pelvis landmarks)"),
    "l5s1_up": P(0.100, "m", "L5/S1 above the hip joint centres in sitting (ibid.)"),
    "len_lumbar": P(0.180, "m", "L1-L5: 5 x (27 mm body + 9 mm disc), PANJABI 1992 lumbar "
                                "anatomy"),
    "len_lower_thorax": P(0.155, "m", "T7-T12: 6 x (21 mm body + 5 mm disc), PANJABI 1991"),
    "len_upper_thorax": P(0.130, "m", "T1-T6: 6 x (17 mm body + 4.5 mm disc), PANJABI 1991"),
    "len_cervical": P(0.120, "m", "C1-C7 with discs (cervical lordosis chord ~0.11-0.13 m)"),
    "incl_lumbar": P(10.0, "deg", "seated lumbar chord reclined ~10 deg (flattened "
                                  "lordosis against a lumbar pad)", False),
    "incl_lower_thorax": P(20.0, "deg", "lower thoracic chord reclined with the back-rest",
                           False),
    "incl_upper_thorax": P(3.0, "deg", "thoracic kyphosis brings the upper chord upright",
                           False),
    "incl_cervical": P(-15.0, "deg", "cervical chord inclined forward (head over the "
                                     "shoulders, gaze horizontal)", False),
    "chest_depth": P(0.245, "m", "ANSUR88 chest depth (HANAVAN cylinder of the thorax)"),
    "chest_breadth": P(0.330, "m", "ANSUR88 chest breadth"),
    "waist_depth": P(0.220, "m", "ANSUR88 waist depth (lumbar cylinder)"),
    "waist_breadth": P(0.300, "m", "ANSUR88 waist breadth"),
    "hip_breadth": P(0.365, "m", "ANSUR88 hip breadth, sitting (pelvis cylinder)"),
    "thigh_pitch": P(8.0, "deg", "thigh rising 8 deg toward the knee (pan tilt plus "
                                 "popliteal clearance)", False),
    "shank_tilt": P(15.0, "deg", "shank inclined forward: knee angle ~97 deg", False),
    "knee_half_width": P(0.100, "m", "knees slightly apart (thighs abducted ~2 deg)"),
    "shoulder_half_width": P(0.175, "m", "glenohumeral centres ~0.35 m apart (0.2 H)"),
    "shoulder_below_c7": P(0.090, "m", "glenohumeral centre below and in front of C7/T1"),
    # --------------------------------------------------- seat geometry
    "pan_angle": P(6.0, "deg", "pan tilted up at the front (typical 5-8 deg)", False),
    "back_angle": P(15.0, "deg", "back-rest recline from vertical (lab seat)", False),
    "share_floor": P(0.12, "-", "static floor load / body weight with the feet flat on the "
                                "floor (the shank and foot weight, 11 %, plus a little of "
                                "the thighs'; pan loads of 0.7-0.8 body weight are typical "
                                "with supported feet); the seat is fitted to it", False),
    # --------------------------------------------- contact (per point)
    "k_pelvis": P(6000.0, "N/m", "SEAT: 9 points under the buttocks (14 x 20 cm grid), "
                                 "5.4e4 N/m; with the thighs' 9e4 N/m under ~67 kg on the "
                                 "pan: the 5 Hz whole-body vertical mode"),
    "c_pelvis": P(90.0, "N s/m", "SEAT: 810 N s/m under the pelvis, vertical damping ratio "
                                 "~0.3 (apparent-mass peak ~1.5)"),
    "k_thigh": P(3000.0, "N/m", "SEAT: 6 points per thigh, 3.6e4 N/m both"),
    "c_thigh": P(45.0, "N s/m", "SEAT: as the pelvis, per unit stiffness"),
    "k_back": P(3000.0, "N/m", "SEAT: 6 pad points, 1.8e4 N/m (back-rest foam and back "
                               "tissue 1-3e4 N/m)"),
    "c_back": P(90.0, "N s/m", "SEAT: damping ratio ~0.3 of the trunk (~20 kg) on the pads"),
    "k_foot": P(3.0e4, "N/m", "SEAT: shoe sole and heel pad at low load, 3 points per foot"),
    "c_foot": P(150.0, "N s/m", "SEAT: damping ratio ~0.5 of the foot on its sole"),
    "shear_ratio": P(0.3, "-", "tangential/normal stiffness and damping of tissue and "
                               "cover: shear modulus G = E/3 for nearly incompressible "
                               "tissue, and a thin layer's confined compression is stiffer "
                               "still"),
    "shear_damping": P(0.5, "-", "tangential/normal damping: the shear loss of tissue, "
                                 "clothing and cover (micro-slip at the interfaces) is "
                                 "higher than in compression; also damps the body's rocking "
                                 "on the pan"),
    "mu_seat": P(0.8, "-", "SEAT: woven fabric cover against clothing", False),
    "mu_floor": P(0.6, "-", "shoe on floor", False),
    # --------------------------------------- passive joints: SLS per DoF
    # k_par: parallel spring; k_mx: Maxwell spring; tau: its relaxation time.
    # Per 3-DoF joint: (flexion-extension y, lateral bending x, axial z).
    "k_lumbar": P(60.0, "N m/rad", "PANJABI/McGILL: ~3 lumbar motion segments in series "
                                   "per joint (20-40 N m/rad ligamentous) plus passive "
                                   "muscle and fascia"),
    "k_thoracic": P(150.0, "N m/rad", "PANJABI: thoracic segments with the rib cage, 6 in "
                                      "series, plus passive tissue"),
    "k_neck": P(12.0, "N m/rad", "PANJABI: ~3.5 cervical segments per joint "
                                "(0.3-0.5 N m/deg each) plus passive muscle"),
    "k_hip": P(20.0, "N m/rad", "passive hip moment near mid-range (Yoon & Mansour 1982 "
                                "order 10-30 N m/rad)"),
    "k_knee": P(10.0, "N m/rad", "passive knee near 90 deg flexion"),
    "k_ankle": P(20.0, "N m/rad", "passive ankle (triceps surae) near neutral"),
    "maxwell_ratio": P(1.0, "-", "RELAX: instantaneous stiffness about twice the relaxed"),
    "tau_spine": P(0.5, "s", "RELAX: fast relaxation of spinal segments 0.1-1 s"),
    "tau_neck": P(0.3, "s", "RELAX"),
    "tau_limb": P(0.4, "s", "RELAX: muscle-tendon soft tissue"),
    "axis_lateral": P(1.2, "-", "lateral bending / flexion stiffness ratio (PANJABI)",
                      False),
    "axis_axial": P(1.5, "-", "axial rotation / flexion stiffness ratio (PANJABI)", False),
    # Joint damping (intrinsic muscle + tissue, instantaneous): N m s/rad.
    # SAP treats it implicitly.
    "b_lumbar": P(60.0, "N m s/rad", "trunk damping: effective trunk damping identified from "
                                     "perturbations is of order 10-40 N m s/rad (e.g. "
                                     "Moorhouse & Granata 2005); per joint ~3x (3 joints in "
                                     "series: ~20 N m s/rad for the trunk), giving the "
                                     "unsupported ~1.2 Hz trunk-sway mode a damping ratio "
                                     "~0.3"),
    "b_thoracic": P(60.0, "N m s/rad", "ibid."),
    "b_neck": P(2.5, "N m s/rad", "neck damping: head-neck models use 0.5-3 N m s/rad "
                                  "(passive tissue plus muscle viscosity); head pitch "
                                  "damping ratio ~0.4 over the two neck joints"),
    "b_hip": P(20.0, "N m s/rad", "hip muscle viscosity: damps the pelvis-and-trunk "
                                  "rocking over the thighs (damping ratio ~0.4)"),
    "b_knee": P(2.0, "N m s/rad", "knee muscle viscosity (order 1-3 N m s/rad)"),
    "b_ankle": P(1.5, "N m s/rad", "ankle muscle viscosity (order 1-2 N m s/rad)"),
    # ------------- muscle torque generators: intrinsic (short-range) stiffness
    # Instantaneous, inside the saturation; scales with co-contraction.
    "ki_lumbar": P(700.0, "N m/rad", "intrinsic trunk stiffness: in vivo trunk flexion "
                                     "stiffness is of order 1e3 N m/rad, mostly intrinsic "
                                     "(Cholewicki et al. 2000; Moorhouse & Granata 2007); 3 "
                                     "joints in series give ~300 N m/rad, twice the trunk's "
                                     "gravitational load (m g h ~ 130 N m/rad) so that it "
                                     "balances without the back-rest"),
    "ki_thoracic": P(700.0, "N m/rad", "ibid."),
    "ki_neck": P(10.0, "N m/rad", "intrinsic neck muscle stiffness at low tone (of the "
                                  "order of the passive neck)"),
    "ki_hip": P(100.0, "N m/rad", "intrinsic hip muscle stiffness at sitting tone"),
    "ki_knee": P(40.0, "N m/rad", "ibid. knee"),
    "ki_ankle": P(40.0, "N m/rad", "ibid. ankle"),
    # -------------------------- muscle torque generators (reflexive PD)
    # Delayed (30-60 ms) and low-passed by the activation: with these delays a
    # reflex loop destabilises the joints' local modes (5-20 Hz) unless its
    # gain stays well below the intrinsic stiffness and its rate gain below
    # the joint damping (checked at the 60 ms of full reflex_delay).
    "kp_lumbar": P(150.0, "N m/rad", "reflexive trunk stiffness, ~20 % of the intrinsic "
                                     "(reflexes add a minor share of trunk stiffness at "
                                     "these delays, Moorhouse & Granata 2007)"),
    "kd_lumbar": P(40.0, "N m s/rad", "reflexive rate gain (spindle velocity sensitivity): "
                                      "damps the slow trunk sway, below b_lumbar"),
    "kp_thoracic": P(150.0, "N m/rad", "ibid."),
    "kd_thoracic": P(40.0, "N m s/rad", "ibid."),
    "kp_neck": P(6.0, "N m/rad", "neck stretch reflex, half the passive neck (delay-limited)"),
    "kd_neck": P(0.2, "N m s/rad", "ibid."),
    "kp_vest": P(10.0, "N m/rad", "vestibulocollic head-in-space stiffness (Peng et al. "
                                  "1996 order 10-40 N m/rad; the low end: delay-limited), "
                                  "split over C0/C1 and C7/T1"),
    "kd_vest": P(0.8, "N m s/rad", "vestibulocollic rate gain (canal velocity signal)"),
    "kp_hip": P(100.0, "N m/rad", "postural hip reflex stiffness"),
    "kd_hip": P(10.0, "N m s/rad", "ibid."),
    "kp_knee": P(50.0, "N m/rad", "postural knee stiffness (feet on the floor)"),
    "kd_knee": P(1.5, "N m s/rad", "ibid."),
    "kp_ankle": P(30.0, "N m/rad", "postural ankle stiffness"),
    "kd_ankle": P(1.0, "N m s/rad", "ibid."),
    "tmax_lumbar": P(200.0, "N m", "TMAX trunk (flexion-extension mean)"),
    "tmax_thoracic": P(150.0, "N m", "TMAX"),
    "tmax_neck": P(30.0, "N m", "TMAX neck"),
    "tmax_hip": P(180.0, "N m", "TMAX hip"),
    "tmax_knee": P(150.0, "N m", "TMAX knee"),
    "tmax_ankle": P(80.0, "N m", "TMAX ankle (dorsi/plantar mean)"),
    "tau_act": P(0.040, "s", "ACT first-order activation"),
    "delay": P(0.030, "s", "DELAY baseline neural transport delay"),
    # ------------------ seat tissue softening with vibration magnitude (SOFT)
    # (appended last: the subjects' scatter draws of the entries above stay
    # as they were).  Every subject's seat tissue (pan and back-rest points)
    # has a short-range part of its normal stiffness that saturates with the
    # dynamic compression about its slow mean: tangent
    # k (1 - s tanh^2(dyn / dc)) (`forces.Spine5Forces.contact`); the
    # `softening` effect adds to s.
    "soft_fraction": P(0.40, "-", "SOFT: short-range share s of the seat tissue's stiffness; "
                                  "with soft_range it puts the nominal subject's seat-to-pelvis "
                                  "vertical resonance at x0.92 from 0.3 to 0.6 m/s^2 r.m.s. "
                                  "(people: x0.87 per doubling, Fairley & Griffin 1989)"),
    "soft_range": P(4.0e-4, "m", "SOFT: dynamic compression dc over which the short-range "
                                 "stiffness is lost: of the order of the 0.25-0.5 mm r.m.s. "
                                 "under the pelvis at 0.3-0.6 m/s^2 r.m.s., so the loss grows "
                                 "between these levels (at 0.03 mm it is saturated at both and "
                                 "the resonance no longer moves with level; at 1 mm the slope "
                                 "is x0.94 at s = 0.6)", False),
}


def nominal_values() -> dict[str, float]:
    return {k: float(p.value) for k, p in PARAMS.items()}


def scatter_factors(seed: int, spread: float = SPREAD) -> dict[str, float]:
    """Seeded factors uniform in [1 - spread, 1 + spread], one per scattered
    entry, in the table's order (deterministic)."""
    names = [k for k, p in PARAMS.items() if p.scatter]
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5E1E5]))
    f = 1.0 + rng.uniform(-spread, spread, len(names))
    return {n: float(x) for n, x in zip(names, f, strict=True)}


def subject_values(factors: dict[str, float]) -> dict[str, float]:
    vals = nominal_values()
    for k, f in factors.items():
        vals[k] *= f
    return vals


def table_markdown() -> str:
    """The table as Markdown (for reports)."""
    lines = ["| parameter | value | unit | source / reason |", "|---|---|---|---|"]
    for k, p in PARAMS.items():
        v = f"{p.value:.4g}"
        lines.append(f"| {k} | {v} | {p.unit} | {p.source}{'' if p.scatter else ' (fixed)'} |")
    return "\n".join(lines)


def deg(x: float) -> float:
    return math.radians(x)
