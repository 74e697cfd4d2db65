"""Parameter table of the `lumped` reality, with a source or reason for each value.

Every number the body, seat and controller are built from is here, as
``P(value, unit, source, scatter)``; `scatter` names the group a subject's
random factor belongs to (None: the same for every subject).  Nothing is
taken from the EHM model's parameter files: the anthropometry is Dempster's
(as tabulated by Winter) with Drillis & Contini's length fractions and
seated dimensions from Pheasant & Haslegrave; the joint, tissue and seat
values are orders of magnitude from the biomechanics literature named
beside them.

References (short names used below):

* Winter: D. A. Winter, Biomechanics and Motor Control of Human Movement,
  4th ed., Wiley 2009, Table 4.1 (Dempster 1955 segment data) and Fig. 4.1
  (segment lengths as fractions of stature, Drillis & Contini 1966).
* Pheasant: S. Pheasant & C. Haslegrave, Bodyspace, 3rd ed., 2006
  (50th-percentile British male, 19-65 y: stature 1740 mm, sitting height
  910, sitting shoulder height 595, sitting elbow height 245, hip breadth
  360, chest depth 250 mm).
* Hanavan: E. P. Hanavan, A mathematical model of the human body,
  AMRL-TR-64-102, 1964 (trunk segments as elliptic cylinders).
* Reed: M. P. Reed, M. A. Manary, L. W. Schneider, Methods for measuring and
  representing automobile occupant posture, SAE 1999-01-0959 (hip joint and
  lumbar landmarks of seated people).
* McGill-L: S. McGill, J. Seguin, G. Bennett, Passive stiffness of the lumbar
  torso in flexion, extension, lateral bending and axial rotation, Spine
  19 (1994) 696-704.
* McGill-N: S. McGill, K. Jones, G. Bennett, P. Bishop, Passive stiffness of
  the human neck in flexion, extension and lateral bending, Clin. Biomech.
  9 (1994) 193-198.
* Panjabi: M. M. Panjabi, The stabilizing system of the spine, part II:
  neutral zone and instability hypothesis, J. Spinal Disord. 5 (1992).
* Riener: R. Riener, T. Edrich, Identification of passive elastic joint
  moments in the lower extremities, J. Biomech. 32 (1999) 539-544.
* Cholewicki: J. Cholewicki, A. Simons, A. Radebold, Effects of external
  trunk loads on lumbar spine stability, J. Biomech. 33 (2000) 1377-1385.
* Goodworth: A. Goodworth, R. Peterka, Contribution of sensorimotor
  integration to spinal stabilization in humans, J. Neurophysiol. 102
  (2009) 496-512.
* Peng: G. Peng, T. Hain, B. Peterson, A dynamical model for reflex
  activated head movements in the horizontal plane, Biol. Cybern. 75 (1996).
* Zajac: F. Zajac, Muscle and tendon: properties, models, scaling,
  Crit. Rev. Biomed. Eng. 17 (1989) (activation time constants 10-50 ms).
* Hunt-Crossley: K. Hunt, F. Crossley, Coefficient of restitution
  interpreted as damping in vibroimpact, J. Appl. Mech. 42 (1975) 440.
* Dupont: P. Dupont et al., Single state elastoplastic friction models,
  IEEE Trans. Autom. Control 47 (2002) 787-792.
* Fairley-Griffin: T. Fairley, M. Griffin, The apparent mass of the seated
  human body: vertical vibration, J. Biomech. 22 (1989) 81-94.
* Todd-Thacker: B. Todd, J. Thacker, Three-dimensional computer model of the
  human buttocks, in vivo, J. Rehabil. Res. Dev. 31 (1994) 111-119.
* Ebe-Griffin: K. Ebe, M. Griffin, Factors affecting static seat cushion
  comfort, Ergonomics 44 (2001) 901-921 (foam load-deflection).
* Aerts: P. Aerts et al., The mechanical properties of the human heel pad,
  J. Biomech. 28 (1995) 1299-1308.
* Nawayseh-Griffin: N. Nawayseh, M. Griffin, Tri-axial forces at the seat
  and backrest during whole-body fore-and-aft vibration, J. Sound Vib. 281
  (2005) 921-942.
* Huang-Griffin: Y. Huang, M. Griffin, Effect of voluntary periodic muscular
  activity on nonlinearity in the apparent mass of the seated human body
  during vertical random whole-body vibration, J. Sound Vib. 298 (2006)
  824-840 (the principal resonance falls with vibration magnitude).
* Liu-Qiu: C. Liu, Y. Qiu, Nonlinearity in the localised apparent masses of
  the seated human body exposed to vertical vibration, Mech. Syst. Signal
  Process. 135 (2020) 106394 (the buttock and thigh contact in the
  nonlinearity; models fitted at 0.25, 0.5 and 1.0 m/s^2).
* Shetty-Allen: D. Shetty, M. Allen, Fast simulation of a single
  degree-of-freedom system consisting of an Iwan element using the method
  of averaging, J. Vib. Acoust. 142 (2020) 051107 (Iwan models: parallel
  Jenkins elements, spring plus Coulomb slider, amplitude-dependent stiffness
  and friction damping).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class P(NamedTuple):
    value: float | tuple
    unit: str
    source: str
    scatter: str | None = None


#: Scatter groups (each scattered parameter has its own factor; the groups
#: name what kind of quantity it is).
SCATTER_GROUPS = ("mass", "inertia", "length", "stiffness", "gain")
#: Inter-subject spread: uniform factor in [1 - SPREAD, 1 + SPREAD].
SPREAD = 0.20

PARAMETERS: dict[str, P] = {
    # --- whole body -------------------------------------------------------
    "body_mass": P(77.0, "kg", "50th-percentile adult male (Pheasant: 75 kg British; "
                   "US adult men ~78 kg)"),
    "stature": P(1.75, "m", "50th-percentile adult male (Pheasant: 1.74 m)"),
    # --- segment mass fractions (Winter, Table 4.1, Dempster) ---------------
    "m_head_neck": P(0.081, "-", "Winter: head and neck, C7-T1 to ear canal", "mass"),
    "m_thorax": P(0.216, "-", "Winter: thorax, C7-T1 to T12-L1", "mass"),
    "m_abdomen": P(0.139, "-", "Winter: abdomen, T12-L1 to L4-L5", "mass"),
    "m_pelvis": P(0.142, "-", "Winter: pelvis, L4-L5 to greater trochanter", "mass"),
    "m_thigh": P(0.100, "-", "Winter: thigh", "mass"),
    "m_shank_foot": P(0.061, "-", "Winter: foot and leg", "mass"),
    "m_upper_arm": P(0.028, "-", "Winter: upper arm", "mass"),
    "m_forearm_hand": P(0.022, "-", "Winter: forearm and hand", "mass"),
    # --- mass centres, fraction of segment length from the proximal end -----
    "com_thorax": P(0.82, "-", "Winter: thorax, from C7-T1"),
    "com_abdomen": P(0.44, "-", "Winter: abdomen, from T12-L1"),
    "com_pelvis": P(0.105, "-", "Winter: pelvis, from L4-L5 towards the hip joints"),
    "com_thigh": P(0.433, "-", "Winter: thigh, from the hip"),
    "com_shank_foot": P(0.606, "-", "Winter: foot and leg, from the knee"),
    "com_upper_arm": P(0.436, "-", "Winter: upper arm, from the shoulder"),
    "com_forearm_hand": P(0.682, "-", "Winter: forearm and hand, from the elbow (of the "
                          "forearm length)"),
    "com_head_neck": P(1.0, "-", "Winter: head and neck, mass centre at the ear canal"),
    "com_anterior_thorax": P(0.05, "m", "Dempster gives the long-axis position only; the mass "
                             "centre lies near the middle of the 0.25 m chest depth "
                             "(Pheasant), ~5 cm anterior of the vertebral bodies"),
    "com_anterior_abdomen": P(0.045, "m", "as above for the ~0.22 m abdominal depth"),
    # --- radii of gyration about the mass centre, fraction of length ---------
    "rg_head_neck": P(0.495, "-", "Winter: head and neck"),
    "rg_thigh": P(0.323, "-", "Winter: thigh"),
    "rg_shank_foot": P(0.416, "-", "Winter: foot and leg"),
    "rg_upper_arm": P(0.322, "-", "Winter: upper arm"),
    "rg_forearm_hand": P(0.468, "-", "Winter: forearm and hand"),
    # inertia scale per segment (subject scatter acts on it independently of mass)
    "i_head_neck": P(1.0, "-", "scale of the head-neck inertia", "inertia"),
    "i_thorax": P(1.0, "-", "scale of the thorax inertia", "inertia"),
    "i_abdomen": P(1.0, "-", "scale of the abdomen inertia", "inertia"),
    "i_pelvis": P(1.0, "-", "scale of the pelvis inertia", "inertia"),
    "i_thigh": P(1.0, "-", "scale of the thigh inertia", "inertia"),
    "i_shank_foot": P(1.0, "-", "scale of the shank-foot inertia", "inertia"),
    "i_arm": P(1.0, "-", "scale of the arm segments' inertia", "inertia"),
    # --- trunk and limb cross-sections (Hanavan's geometric solids) ---------
    "chest_breadth": P(0.32, "m", "Pheasant: chest breadth, 50th male (~320-330 mm)"),
    "chest_depth": P(0.25, "m", "Pheasant: chest depth 250 mm"),
    "waist_breadth": P(0.30, "m", "Pheasant: waist breadth ~300 mm"),
    "waist_depth": P(0.22, "m", "Pheasant: abdominal depth ~220-250 mm"),
    "hip_breadth": P(0.36, "m", "Pheasant: hip breadth sitting 360 mm"),
    "pelvis_depth": P(0.22, "m", "Hanavan-style ellipse, ~0.6 of hip breadth"),
    "thigh_radius": P(0.075, "m", "mean thigh radius (circumference ~0.47 m), for the "
                      "inertia about the femur"),
    "shank_radius": P(0.045, "m", "mean calf radius (circumference ~0.28 m)"),
    "arm_radius": P(0.04, "m", "mean upper-arm/forearm radius"),
    # --- lengths, fractions of stature (Winter Fig. 4.1, Drillis & Contini) --
    "l_thigh": P(0.245, "-", "Winter Fig. 4.1: hip to knee 0.245 H", "length"),
    "l_shank": P(0.246, "-", "Winter Fig. 4.1: knee to ankle 0.246 H", "length"),
    "h_ankle": P(0.039, "-", "Winter Fig. 4.1: ankle height 0.039 H"),
    "l_foot": P(0.152, "-", "Winter Fig. 4.1: foot length 0.152 H"),
    "l_upper_arm": P(0.186, "-", "Winter Fig. 4.1: shoulder to elbow 0.186 H", "length"),
    "l_forearm": P(0.146, "-", "Winter Fig. 4.1: elbow to wrist 0.146 H", "length"),
    "l_hand": P(0.108, "-", "Winter Fig. 4.1: hand 0.108 H"),
    "l_abdomen": P(0.074, "-", "T12-L1 to L4-L5 (three lumbar levels ~0.13 m): sitting "
                   "cervicale height ~0.64 m (Pheasant) minus the pelvis and thorax", "length"),
    "l_thorax": P(0.171, "-", "C7-T1 to T12-L1, thoracic spine ~0.30 m", "length"),
    "l_head_neck": P(0.097, "-", "C7 to ear canal ~0.17 m: sitting eye height 790 mm "
                     "(Pheasant) minus cervicale height, head carried forward", "length"),
    # --- seated pelvis geometry (m) -----------------------------------------
    "hjc_above_it": P(0.095, "m", "hip joint centre ~9-10 cm above the ischial tuberosity "
                      "skin contact (Reed; SAE J826 H-point)", "length"),
    "hjc_ahead_of_it": P(0.04, "m", "hip joint centre 3-5 cm anterior of the tuberosity "
                         "(Reed)", "length"),
    "hjc_width": P(0.17, "m", "inter-hip-joint distance of men 0.16-0.18 m"),
    "it_width": P(0.12, "m", "inter-tuberosity distance of men 0.10-0.13 m"),
    "buttock_contact_width": P(0.27, "m", "span between the two lateral buttock contacts: "
                               "the seated buttocks bear load across the hip breadth sitting "
                               "(360 mm, Pheasant) less their rounded sides, each side's "
                               "lateral point at 3/8 of it from the midline; with the "
                               "tuberosity points the load has the second moment of a "
                               "contact from the tuberosity to the buttock's side, which "
                               "gives the pelvis its roll support on the pan"),
    "buttock_share": P(0.5, "-", "share of each side's pan tissue (stiffness, shear "
                       "stiffness and damping) at the lateral buttock point, the rest under "
                       "the tuberosity: no source for the split; a pressure map peaks under "
                       "the tuberosities and spreads over the buttocks, and the equal split "
                       "keeps the vertical and fore-aft laws of one point per side (the same "
                       "total at the same depth)"),
    "l4l5_behind_hjc": P(0.075, "m", "L4-L5 disc ~7-8 cm posterior of the hip joints when "
                         "seated (Reed)", "length"),
    "l4l5_above_hjc": P(0.12, "m", "L4-L5 disc ~12 cm above the hip joints when seated (Reed)",
                        "length"),
    "shoulder_below_c7": P(0.075, "m", "glenohumeral joint below C7: sitting shoulder height "
                           "595 mm (Pheasant) minus ~3 cm to the joint"),
    "shoulder_half_width": P(0.18, "m", "half the bi-glenohumeral distance (~0.36 m)"),
    # --- posture (deg; the initial, upright seated posture) ------------------
    "trunk_recline": P(15.0, "deg", "spine line L4-L5 to C7 reclined against the "
                       "backrest, leaning on it"),
    "neck_forward": P(20.0, "deg", "C7 to ear canal inclined forward (head carried ahead of "
                      "C7, gaze horizontal)"),
    "thigh_slope": P(5.0, "deg", "thighs sloping slightly down to the knees on a flat pan"),
    "shank_forward": P(15.0, "deg", "feet placed slightly ahead of the knees"),
    "upper_arm_forward": P(15.0, "deg", "upper arms hanging, elbows slightly forward"),
    "forearm_down": P(18.0, "deg", "forearms from the elbow down to the hands on the thighs"),
    # --- seat ---------------------------------------------------------------
    "backrest_recline": P(15.0, "deg", "laboratory backrest reclined 15 deg (upright car "
                          "and office seats: 10-25 deg), parallel to the back"),
    "pad_preload_mm": P(8.0, "mm", "design compression of the back at the pads when the seat "
                        "is adjusted to the subject (pads touch the back)"),
    "foot_preload_mm": P(2.0, "mm", "footrest height adjusted so the feet bear the lower legs"),
    # --- contact: Hunt-Crossley F = k d^n (1 + 1.5 c d'), n = 1.5 ------------
    "hc_exponent": P(1.5, "-", "Hertz-like exponent of soft-tissue indentation (Hunt-Crossley)"),
    "k_it": P(1.6e5, "N/m^1.5", "buttock tissue of each side (its tuberosity and lateral "
              "points together, `buttock_share`): ~210 N at ~12 mm "
              "compression, tangent ~26 kN/m per side (Todd-Thacker indentation; the seated "
              "body's vertical resonance near 5 Hz, Fairley-Griffin)", "stiffness"),
    "k_thigh": P(1.0e5, "N/m^1.5", "thigh underside on the pan: ~105 N at ~10 mm, tangent "
                 "~15 kN/m, softer than under the tuberosities (Todd-Thacker)", "stiffness"),
    "k_back": P(8.0e4, "N/m^1.5", "back tissue in series with backrest foam pads: tangent "
                "6-8 kN/m per contact at 13-21 N, 3-4 mm (Ebe-Griffin foam load-deflection)",
                "stiffness"),
    "k_foot": P(4.0e5, "N/m^1.5", "heel pad and shoe sole: tangent 20-25 kN/m per point at "
                "10-30 N (Aerts: heel pad 100-200 kN/m at running loads)", "stiffness"),
    "c_it": P(1.6, "s/m", "Hunt-Crossley damping: linearized 1.5 c F ~ 450 N s/m per side, "
              "a damping ratio ~0.4 of the seated vertical mode (Fairley-Griffin models)"),
    "c_thigh": P(1.6, "s/m", "thigh tissue, as under the tuberosities"),
    "c_back": P(4.0, "s/m", "back tissue and foam: loss factor ~0.3-0.4 at 3-5 Hz (polyurethane "
                "foam and soft tissue are lossy)"),
    "c_foot": P(1.0, "s/m", "heel pad (Aerts: high hysteresis)"),
    # --- shear: elasto-plastic (Dupont) bristle, regularized Coulomb ----------
    "shear_k_it": P(4000.0, "N/m", "buttock soft-tissue shear stiffness per side, giving the "
                    "fore-aft seat modes of 1-3 Hz (Nawayseh-Griffin)", "stiffness"),
    "shear_k_thigh": P(3000.0, "N/m", "thigh tissue shear", "stiffness"),
    "shear_k_back": P(2000.0, "N/m", "back tissue and pad shear", "stiffness"),
    "shear_k_foot": P(1.0e4, "N/m", "shoe on the floor", "stiffness"),
    "shear_c_it": P(150.0, "N s/m", "shear damping, damping ratio ~0.3"),
    "shear_c_thigh": P(100.0, "N s/m", "shear damping"),
    "shear_c_back": P(60.0, "N s/m", "shear damping"),
    "shear_c_foot": P(100.0, "N s/m", "shear damping"),
    "mu_seat": P(0.6, "-", "clothed buttocks/back on a fabric cover: 0.5-0.8"),
    "mu_floor": P(0.8, "-", "shoe sole on a floor plate"),
    "stick_fraction": P(0.7, "-", "Dupont: pure elastic presliding below 70% of the Coulomb "
                        "limit (no drift under vibration below it)"),
    # --- passive joints: neutral zone + exponential stiffening (Panjabi) ----
    # (flexion-extension, lateral bending, axial rotation) about the initial posture
    "k_lumbar": P((80.0, 100.0, 60.0), "N m/rad", "L4-L5 joint lumping L3-S1: lumbar torso "
                  "passive stiffness near neutral ~1-2 N m/deg (McGill-L) per half of the "
                  "lumbar spine", "stiffness"),
    "k_thoracolumbar": P((100.0, 120.0, 80.0), "N m/rad", "T12-L1 joint lumping L1-L3 and the "
                         "lower thorax (McGill-L)", "stiffness"),
    "k_neck": P((20.0, 20.0, 12.0), "N m/rad", "C7 joint lumping the cervical spine: passive "
                "neck stiffness 0.2-0.4 N m/deg near neutral (McGill-N)", "stiffness"),
    "k_hip": P((30.0, 60.0, 25.0), "N m/rad", "hip flexion/adduction/rotation mid-range passive "
               "moments of a few N m over 10 deg (Riener)", "stiffness"),
    "k_knee": P(20.0, "N m/rad", "knee mid-range passive stiffness (Riener)", "stiffness"),
    "nz_spine": P(0.10, "rad", "neutral zone half-width of the lumped spinal joints "
                  "(Panjabi: a few degrees per level)"),
    "nz_neck": P(0.15, "rad", "neck neutral zone"),
    "nz_leg": P(0.35, "rad", "hip and knee mid-range where passive moments are small "
                "(Riener)"),
    "stiffening_angle": P(0.08, "rad", "e-folding angle of the exponential stiffening beyond "
                          "the neutral zone (Riener's double-exponential fits: 0.05-0.15 rad)"),
    "d_lumbar": P(15.0, "N m s/rad", "intrinsic trunk damping 5-30 N m s/rad (Cholewicki)"),
    "d_thoracolumbar": P(15.0, "N m s/rad", "intrinsic trunk damping, as at L4-L5"),
    "d_neck": P(3.0, "N m s/rad", "intrinsic neck damping (tissue and co-active muscle): a head "
                "pitch damping ratio ~0.4-0.5, the broad 2-4 Hz head resonances of seated "
                "subjects"),
    "d_hip": P(3.0, "N m s/rad", "hip damping (Riener)"),
    "d_knee": P(1.5, "N m s/rad", "knee damping (Riener)"),
    # --- active control: delayed PD of the joint angles, activation dynamics -
    "kp_lumbar": P((300.0, 300.0, 150.0), "N m/rad", "active trunk stiffness of seated "
                   "subjects ~2-3 x the gravity stiffness m g h ~100 N m/rad (Goodworth; "
                   "Cholewicki: 1000+ with co-contraction)", "gain"),
    "kd_lumbar": P((15.0, 15.0, 8.0), "N m s/rad", "active trunk damping ~0.1 x stiffness "
                   "(Goodworth)", "gain"),
    "kp_thoracolumbar": P((300.0, 300.0, 150.0), "N m/rad", "active trunk stiffness, as at "
                         "L4-L5 (Goodworth)", "gain"),
    "kd_thoracolumbar": P((15.0, 15.0, 8.0), "N m s/rad", "active trunk damping, as at L4-L5 "
                         "(Goodworth)", "gain"),
    "kp_neck": P((15.0, 15.0, 10.0), "N m/rad", "cervicocollic reflex stiffness ~1-2 x head "
                 "gravity stiffness (~10 N m/rad) (Peng)", "gain"),
    "kd_neck": P((1.5, 1.5, 1.0), "N m s/rad", "reflex neck damping ~0.1 x stiffness (Peng)",
                 "gain"),
    "kp_hip": P((40.0, 40.0, 20.0), "N m/rad", "postural hip stiffness, legs supported by the "
                "seat", "gain"),
    "kd_hip": P((4.0, 4.0, 2.0), "N m s/rad", "postural hip damping", "gain"),
    "kp_knee": P(30.0, "N m/rad", "postural knee stiffness", "gain"),
    "kd_knee": P(2.0, "N m s/rad", "postural knee damping", "gain"),
    "kv_head": P((20.0, 20.0, 10.0), "N m/rad", "vestibulocollic head-in-space stiffness "
                 "(roll, pitch, yaw), ~2 x the head's gravity stiffness (Peng)", "gain"),
    "dv_head": P((2.0, 2.0, 1.0), "N m s/rad", "vestibulocollic damping (Peng)", "gain"),
    "activation_time": P(0.040, "s", "first-order excitation-activation lag 10-50 ms (Zajac)"),
    "neural_delay": P(0.020, "s", "short-latency stretch/vestibular reflex loop ~20 ms"),
    "tonic_adaptation_time": P(0.25, "s", "time constant of the tonic (postural) torque that "
                               "holds the spine and neck at the initial posture while the "
                               "subject settles; frozen for the tests"),
    # --- tissue friction: the seated body's softening with vibration magnitude
    # (appended last: the subjects' scatter draws of the entries above stay
    # as they were).  A Jenkins element (spring k_J in series with a Coulomb
    # slider slipping at k_J x_J; Iwan's elements, e.g. Shetty-Allen) in
    # parallel with the tissue at the tuberosities and thighs, relaxed at the
    # seated state: stuck at small dynamic compressions, slipping at larger
    # ones, so the tissue's equivalent stiffness falls and its friction loss
    # rises with the vibration magnitude, as the seated body's resonance does
    # (Fairley-Griffin: ~6 Hz at 0.25 m/s^2 to ~4 Hz at 2 m/s^2 r.m.s.;
    # Huang-Griffin; Liu-Qiu fitted models of the buttock and thigh contact
    # at 0.25-1.0 m/s^2).  Only a share of the tissue's stiffness is
    # frictional: stuck, the tissue is as stiff as its elastic law; slipping,
    # it loses up to that share.
    "tissue_friction_share": P(0.4, "-", "share of the pan tissue's Hunt-Crossley tangent "
                               "stiffness at the seated compression that is frictional (k_J; the "
                               "elastic law loses as much about the seated compression, so "
                               "the stuck tissue is as stiff as before): chosen so that the "
                               "seat-to-pelvis vertical resonance falls ~x0.93 from 0.3 to "
                               "0.6 m/s^2 (Fairley-Griffin ~x0.87 per doubling)", "stiffness"),
    "tissue_friction_slip": P(3.0e-4, "m", "stick range x_J of the tissue friction: of the "
                              "order of the dynamic compression under the pelvis at "
                              "0.3-0.6 m/s^2 r.m.s. (0.2-0.4 mm r.m.s. in this body), so that "
                              "the element goes from mostly stuck to mostly slipping between "
                              "these magnitudes"),
}


# ---------------------------------------------------------------------------
# Effects: own ranges (strength 0 = off, 1 = the largest plausible size)
# ---------------------------------------------------------------------------


class EffectRange(NamedTuple):
    off: float
    full: float
    log: bool
    unit: str
    reason: str


EFFECT_RANGES: dict[str, dict[str, EffectRange]] = {
    "reflex_delay": {"extra_delay_s": EffectRange(
        0.0, 0.030, False, "s",
        "extra transport delay on top of the 20 ms baseline in all active feedback (joint PD "
        "and vestibular): long-latency reflexes 40-60 ms in total")},
    "seat_foam_stiffening": {"hardening_per_mm2": EffectRange(
        0.0, 1.5, False, "1/mm^2",
        "pan and backrest foam hardening about the seated compression: elastic force + k_t "
        "h d^3 / 3, tangent stiffness x(1 + h d^2), d in mm (densifying polyurethane foam: "
        "x2-3 at the 1 mm dynamic compressions of 0.3-1 m/s^2 vibration)")},
    "seat_friction": {"mu": EffectRange(
        0.6, 0.12, True, "-",
        "Coulomb coefficient at the pan and backrest cover from the base 0.6 (fabric) down "
        "to 0.12 (smooth synthetic clothing on vinyl or leather, 0.1-0.3): the thighs and back "
        "slip at vibration peaks (stick-slip); the tuberosities' tissue shear still holds")},
    "backrest_separation": {"offset_mm": EffectRange(
        0.0, 10.0, False, "mm",
        "both pads moved back: the design back compression of 8 mm (40-60 N per pad) drops "
        "to near zero, the back leaves the pads as the trunk sways")},
    "arms": {"shoulder_stiffness": EffectRange(
        3000.0, 20.0, True, "N m/rad",
        "upper arm on a 3-DoF shoulder and forearm-hand on a revolute elbow instead of being "
        "lumped into the thorax: shoulder from held rigid (3000) to relaxed (20)"),
        "elbow_stiffness": EffectRange(
        800.0, 5.0, True, "N m/rad", "elbow from held rigid to relaxed (forearm on the thigh)"),
        "hand_contact_k": EffectRange(
        2.0e3, 1.0e5, True, "N/m^1.5",
        "hand/forearm resting on the thigh through soft tissue (Hunt-Crossley): from barely "
        "touching to a tangent ~10-20 kN/m")},
    "visceral_mass": {"mass_kg": EffectRange(
        0.0, 4.0, False, "kg",
        "abdominal viscera (liver, stomach, intestines: 4-6 kg) taken out of the abdomen onto "
        "a 3-axis spring-damper: 5 Hz vertical, 4 Hz horizontal, damping ratio 0.25")},
    "cocontraction": {"gain_per_ms2": EffectRange(
        0.0, 2.0, False, "1/(m/s^2)",
        "active trunk, neck and hip stiffness x(1 + c a_rms), a_rms the running RMS seat "
        "acceleration (2 s): x2.2 at 0.6 m/s^2 (trunk EMG rises with vibration magnitude)")},
    "seat_cushion_dynamics": {"stiffness": EffectRange(
        2.0e6, 6.0e4, True, "N/m",
        "the pan as a 3.5 kg cushion on a vertical spring (shear 0.4 x) to the seat frame: "
        "from rigid to a soft cushion whose occupant mode is ~5 Hz")},
    "softening": {"extra_friction_share": EffectRange(
        0.0, 0.2, False, "-",
        "softening beyond the typical subject's tissue friction (tissue_friction_share 0.4, "
        "tissue_friction_slip 0.3 mm): a further share of the pan tissue's tangent stiffness "
        "at the seated compression is frictional (0.4 -> 0.6 for the nominal subject)"),
        "slip_factor": EffectRange(
        1.0, 0.67, False, "-",
        "with it, the tissue friction's stick range narrows (0.3 -> 0.2 mm), so it slips from "
        "smaller compressions: the stuck tissue is as stiff, it loses more stiffness as the "
        "level rises (seat-to-pelvis resonance of subject 3 x0.82 from 0.3 to 0.6 m/s^2 "
        "instead of x0.93; people ~x0.87 per doubling, Fairley-Griffin; a larger share at "
        "the same range mostly adds friction damping that flattens the resonance)")},
}

#: Fixed values of the effects (not scaled by strength).
EFFECT_FIXED: dict[str, dict[str, float]] = {
    "visceral_mass": {"freq_z_hz": 5.0, "freq_xy_hz": 4.0, "damping_ratio": 0.25},
    "cocontraction": {"tau_s": 2.0},
    "seat_cushion_dynamics": {"mass_kg": 3.5, "damping_ratio": 0.15, "shear_ratio": 0.4},
    "arms": {"elbow_damping": 0.3},
}


def nominal_values() -> dict:
    """The parameter values of the nominal subject."""
    return {k: p.value for k, p in PARAMETERS.items()}


def scattered_names() -> tuple[str, ...]:
    return tuple(k for k, p in PARAMETERS.items() if p.scatter)


def draw_factors(seed: int, spread: float = SPREAD) -> dict[str, float]:
    """One seeded uniform factor in [1 - spread, 1 + spread] per scattered
    parameter (the left and right sides share each parameter, hence its
    factor)."""
    names = scattered_names()
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x1A3B]))
    f = 1.0 + rng.uniform(-spread, spread, len(names))
    return {n: float(x) for n, x in zip(names, f, strict=True)}


def apply_factors(factors: dict[str, float]) -> dict:
    """Parameter values with the factors applied (tuples element-wise)."""
    out = nominal_values()
    for name, f in factors.items():
        v = out[name]
        out[name] = tuple(float(x) * f for x in v) if isinstance(v, tuple) else float(v) * f
    return out
