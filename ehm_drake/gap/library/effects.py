"""Candidate unmodelled effects: each a real extension of the Drake model
with 1-3 physical parameters, off by default.

`strength` in [0, 1] is a fraction of the effect's physiologically
plausible range (0 = off, 1 = the largest plausible size); `values(name,
strength)` gives its parameters.  Each effect is a `ModelExtension`
(`ehm_drake.model.extensions`: the hook interface of the plant, diagram and
simulation) implemented here next to its parameters and registered under
its name; the model is built from an `effects` mapping {name: {parameter:
value}} by `ehm_drake.model.plant.add_seated_human` (bodies, joints,
contact), `ehm_drake.diagram.build_diagram` (systems) and
`ehm_drake.simulation` (settle, vibrate), which call the hooks without
naming any effect.  This module is imported with the package (that
registers the effects) and by the command line's light paths, so Drake and
the model's systems are imported inside the hooks, when a model is built.

Ranges (strength 1) and reasons:

* reflex_delay: tau = 30 ms transport delay in the PID (P and I) and
  head-in-space feedback (short-latency stretch reflexes 20-40 ms; the
  derivative action stays instantaneous as intrinsic muscle damping, as
  does the passive tissue).  Beyond ~35 ms this model's neck loop loses
  stability (the linearized closed loop with its delay buffer: the 7-8 Hz
  head mode's damping ratio at 35 ms is 0.006 on the implicit design at
  5 ms and 0.04 on the paper's design; at 40 ms it is unstable on both,
  -0.031 and -0.005), so 30 ms is the largest plausible value here and the
  fit stops at 35 ms.
* seat_foam_stiffening: gamma = 3 /mm^2: the pan and backrest contact
  tangent stiffness k (1 + 3 gamma d^2) rises by 3x at 0.6 mm of dynamic
  compression d about the static preload (polyurethane foam stiffens
  progressively; at whole-body-vibration levels d is 0.1-1 mm).
* seat_friction: Coulomb friction at the cover of the pan and backrest:
  each restraint's shear force is also limited to mu N with N the point's
  current normal force (stick-slip; the base restraints' limits are fixed
  forces).  strength maps mu log-wise from 2.0 (sticky: the fixed limits
  govern, = no effect) to 0.2 (slippery vinyl or leather under smooth
  clothing; fabric covers give 0.3-0.8).
* backrest_separation: the pads sit 4 mm further back: the static preload
  at the pads drops from 3-6 mm of tissue compression to 0-2 mm, so the back
  loses contact as the trunk sways (unilateral contact; the pad shear
  restraints act only in contact).
* arms: upper arm, forearm and hand of each side as one segment (rigid in
  the seated pose) on a spherical shoulder joint instead of being lumped
  into the upper torso, the hand resting on the thigh through a 3D
  spring-damper (soft tissue).  strength maps, log-wise, the shoulder
  stiffness from 2000 N m/rad (arm held rigidly to the trunk, = lumped) to
  20 N m/rad (relaxed shoulder) and the hand-thigh contact stiffness from
  50 N/m (barely touching) to 2e4 N/m (forearm and hand resting on the
  thigh: soft-tissue contact 1e4-5e4 N/m).
* visceral_mass: up to 5 kg of abdominal viscera (liver, stomach,
  intestines: 4-6 kg move relative to the spine) taken out of the middle
  torso (12.3 kg) onto a vertical spring-damper, 5 Hz, damping ratio 0.3
  (abdominal-wall resonance 4-8 Hz).
* cocontraction: active joint stiffness (trunk, neck, hips) rising with the
  running RMS of the seat acceleration (time constant 2 s), kp (1 + c
  a_rms), c = 1.5 per m/s^2 (x1.9 at 0.6 m/s^2).
* seat_cushion_dynamics: the pan as a 4 kg cushion on a vertical spring-
  damper to the seat frame, stiffness from 5e6 N/m (rigid) down to 4e4 N/m
  (soft automotive cushion with the occupant's share ~40 kg: 5 Hz), damping
  ratio 0.2.
* softening: the seated tissue on the pan (under the ischial tuberosities
  and the thighs; `SOFTENING_PAIRS`) loses, beyond the
  model's own softening (`ehm_drake.model.softening`), up to 50% of its
  contact's long-range stiffness as it moves (half of it at the model's
  critical amplitude, 0.07 mm RMS): the size of the nonlinearity varies
  between people and with muscle tension (Matsumoto & Griffin 2002: the
  resonance fell 19% between 0.35 and 1.4 m/s^2 with normal tension, 12%
  with the buttocks tensed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ...model.extensions import ModelExtension, register_extension, validate_extensions


@dataclass(frozen=True)
class EffectParam:
    name: str
    unit: str
    off: float  # value that means "no effect"
    full: float  # value at strength 1
    log: bool = False  # interpolate log-wise
    bounds: tuple[float, float] = (0.0, 1.0)  # range allowed when fitting


@dataclass(frozen=True)
class Effect:
    name: str
    description: str
    params: tuple[EffectParam, ...]
    #: "linear": a linear extension (extra dynamics); "level": acts through
    #: level-dependent (equivalent-linear) parameters; "delay": feedback delay.
    kind: str
    nonlinear: bool
    #: Plain-words signature, for the report.
    signature: str
    fixed: dict = field(default_factory=dict)

    def values(self, strength: float) -> dict[str, float]:
        if not 0.0 <= strength <= 1.0 or not math.isfinite(strength):
            raise ValueError(f"strength of {self.name} must be in [0, 1], got {strength!r}")
        out = dict(self.fixed)
        for p in self.params:
            if p.log:
                out[p.name] = p.off * (p.full / p.off) ** strength
            else:
                out[p.name] = p.off + (p.full - p.off) * strength
        return out

    def validate(self, vals: dict) -> dict[str, float]:
        """Check one effect's {param: value}; fill the fixed values and the
        "off" values of the parameters not given."""
        known = {p.name for p in self.params} | set(self.fixed)
        bad = set(vals) - known
        if bad:
            raise ValueError(f"effect {self.name}: unknown parameter(s) "
                             f"{', '.join(sorted(bad))} (known: {', '.join(sorted(known))})")
        full = {**self.fixed, **{p.name: p.off for p in self.params}, **vals}
        units = {p.name: p.unit for p in self.params}
        for k, v in full.items():
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v)) \
                    or v < 0:
                unit = f" {units[k]}" if units.get(k, "-") != "-" else ""
                raise ValueError(f"effect {self.name}.{k} must be a finite non-negative "
                                 f"number (allowed >= 0{unit}), got {v!r}")
        return {k: float(v) for k, v in full.items()}


class CandidateEffect(ModelExtension):
    """A candidate effect's model extension; `effect` is its parameter
    specification (the class is registered by `_candidate`)."""

    effect: ClassVar[Effect]

    @classmethod
    def validate(cls, values) -> dict[str, float]:
        return cls.effect.validate(values)


_DEFINED: list[Effect] = []


def _candidate(effect: Effect):
    """Class decorator: bind `effect` to the extension class and register
    both (the order of definition is `EFFECT_NAMES`)."""
    def deco(cls):
        cls.effect = effect
        cls.name = effect.name
        register_extension(cls)
        _DEFINED.append(effect)
        return cls
    return deco


#: Seat parts whose contact the seat_foam_stiffening / seat_friction /
#: backrest_separation effects act on.
SEAT_SURFACES = ("pan", "lower_pad", "upper_pad")
BACK_PADS = ("lower_pad", "upper_pad")
#: Joint groups whose active stiffness rises with co-contraction.
COCONTRACTION_GROUPS = ("lumbar", "thoracic", "neck", "hips")
#: The contact pairs whose tissue the `softening` candidate softens: those on
#: the pan.  The back's tissue (the pads) is left out: a back pad losing
#: stiffness as the trunk sways is what `backrest_separation` describes, and
#: on the pads the candidate's fore-and-aft signature is mostly theirs (the
#: trunk's fore-and-aft motion under vertical excitation changes four times
#: more than with the pan's tissue alone), so the two candidates could not
#: be told apart.  The body's own softening keeps every tissue pair.
SOFTENING_PAIRS = ("pelvis_pan", "thighs_pan")


# ---------------------------------------------------------------------------
# reflex_delay: a transport delay in the controllers' feedback
# ---------------------------------------------------------------------------


def reflex_delay_steps(tau: float, h: float) -> int:
    """The delay in whole time steps (at least one)."""
    return max(1, int(round(tau / h)))


def delay_system(steps: int, h: float, size: int):
    """A discrete system whose output lags its input, the plant's discrete
    state, by `steps` time steps: a `ZeroOrderHold` for one, else a
    `DiscreteTimeDelay` of steps - 1 (its buffer of n adds one step to n
    when it reads a discrete state: 35 ms for 6 x 5 ms, measured).  Before
    this was found a 30 ms delay was 31 ms at 1 ms and 35 ms at 5 ms, and
    the effect 20% larger on the implicit design at 5 ms than at 1 ms."""
    from pydrake.systems.primitives import DiscreteTimeDelay, ZeroOrderHold

    if steps < 1:
        raise ValueError(f"a delay of {steps} steps")
    return ZeroOrderHold(h, size) if steps == 1 else DiscreteTimeDelay(h, steps - 1, size)


@_candidate(Effect(
    "reflex_delay", "neural transport delay in the PID and head-in-space feedback",
    (EffectParam("tau_s", "s", 0.0, 0.03, bounds=(0.0, 0.035)),),
    "delay", False,
    "phase lag growing with frequency; lower, sharper head/trunk peaks; no level "
    "dependence"))
class ReflexDelay(CandidateEffect):
    """The PID and head-in-space controllers read the plant state through a
    delay of round(tau / h) steps (`delay_system`, system "reflex_delay").  Left out of the static
    equilibrium: at rest its buffer holds the plant state."""

    in_equilibrium_model = False

    def transform_feedback(self, parts, feedback):
        tau = self.values["tau_s"]
        if not tau > 0:
            return feedback
        h = parts.time_step
        layout = parts.hp.layout
        steps = reflex_delay_steps(tau, h)
        delay = parts.add_system(self.name, delay_system(steps, h, layout.nq + layout.nv))
        parts.builder.Connect(parts.state, delay.get_input_port())
        return delay.get_output_port()

    def initial_state(self, model, smap, x, x_plant) -> None:
        if self.name in model.systems:
            sl = smap.slice(self.name)
            x[sl] = np.tile(x_plant, (sl.stop - sl.start) // len(x_plant))


# ---------------------------------------------------------------------------
# Seat effects on the shear restraints and the contact
# ---------------------------------------------------------------------------


@_candidate(Effect(
    "seat_foam_stiffening", "stiffening seat pan and backrest contact",
    (EffectParam("gamma_per_mm2", "1/mm^2", 0.0, 3.0, bounds=(0.0, 20.0)),),
    "level", True,
    "seat-body resonances move UP with vibration level"))
class SeatFoamStiffening(CandidateEffect):
    """A cubic normal force at the seat surfaces' restraint points."""

    def restraint_options(self, params, points) -> dict:
        # k3 = k gamma (gamma per mm^2 -> per m^2): k (1 + 3 gamma d^2) tangent.
        gamma = self.values["gamma_per_mm2"] * 1e6
        return {"cubic": [getattr(params.contact, p.pair).stiffness * gamma
                          if p.part in SEAT_SURFACES else 0.0 for p in points]}


@_candidate(Effect(
    "seat_friction", "Coulomb stick-slip shear at the seat (limit mu N)",
    (EffectParam("mu", "-", 2.0, 0.2, log=True, bounds=(0.1, 4.0)),),
    "level", True,
    "stiff shear at low level, slip at high level: fore-aft/lateral pelvis modes "
    "move DOWN and damp with level; coherence loss"))
class SeatFriction(CandidateEffect):
    """The seat surfaces' restraints also limited to mu N."""

    def restraint_options(self, params, points) -> dict:
        mu = self.values["mu"]
        return {"friction": [mu if p.part in SEAT_SURFACES else 0.0 for p in points]}


@_candidate(Effect(
    "backrest_separation", "unilateral back contact with low preload",
    (EffectParam("offset_mm", "mm", 0.0, 4.0, bounds=(0.0, 8.0)),),
    "level", True,
    "back support fades with level: fore-aft trunk/head gains rise and peaks move "
    "down with level; coherence loss in x"))
class BackrestSeparation(CandidateEffect):
    """The pads moved back; their shear restraints act only in contact."""

    def modify_body(self, body) -> None:
        offset = self.values["offset_mm"] * 1e-3
        for pad in BACK_PADS:
            c, size = body.seat.boxes[pad]
            body.seat.boxes[pad] = (c - np.array([offset, 0.0, 0.0]), size)

    def restraint_options(self, params, points) -> dict:
        return {"gated_parts": BACK_PADS}


# ---------------------------------------------------------------------------
# Effects that add bodies, joints and force elements
# ---------------------------------------------------------------------------


@_candidate(Effect(
    "arms", "arms resting on the thighs, attached at the shoulders",
    (EffectParam("shoulder_stiffness", "N m/rad", 2000.0, 20.0, log=True,
                 bounds=(5.0, 5000.0)),
     EffectParam("hand_stiffness", "N/m", 50.0, 2.0e4, log=True, bounds=(20.0, 1.0e5))),
    "linear", False,
    "an extra trunk-arm mode (absorber) splitting the trunk pitch/roll peaks; "
    "no level dependence"))
class Arms(CandidateEffect):
    """Separate arm segments: a spring-damper at each shoulder (spherical
    joint) and between each hand and thigh."""

    def body_options(self) -> dict:
        return {"separate_arms": True}

    def add_plant_elements(self, plant, human, seat, body) -> None:
        from pydrake.math import RigidTransform, RollPitchYaw
        from pydrake.multibody.tree import FixedOffsetFrame, LinearBushingRollPitchYaw

        zero = np.zeros(3)
        k_sh = self.values["shoulder_stiffness"]
        k_h = self.values["hand_stiffness"]
        for side in ("l", "r"):
            joint = plant.GetJointByName(f"shoulder_{side}", human)
            arm = body.segments[f"arm_{side}"]
            p_hand = body.landmarks[f"hand_{side}"]
            thigh = body.segments[f"thigh_{side}"]
            # Statics of the placed arm (the reference pose is its rest
            # position for every stiffness): the thigh carries the hand
            # vertically with the force balancing the arm's weight moment in
            # pitch about the shoulder; the shoulder the remaining moment.
            # Both springs are preloaded accordingly (their rest positions
            # are offset), so only their stiffness changes the dynamics.
            r_c, r_h = arm.com_W - arm.origin_W, p_hand - arm.origin_W
            weight = np.array([0.0, 0.0, -9.81 * arm.mass])
            F_hand = np.array([0.0, 0.0, arm.mass * 9.81 * r_c[0] / r_h[0]])
            T_shoulder = -(np.cross(r_c, weight) + np.cross(r_h, F_hand))
            # Damping ratio 0.2 on the arm's pitch inertia about the shoulder.
            I_sh = arm.inertia_W[1, 1] + arm.mass * float(np.sum(r_c[[0, 2]] ** 2))
            rest = plant.AddFrame(FixedOffsetFrame(
                f"shoulder_spring_rest_{side}", joint.frame_on_parent(),
                RigidTransform(RollPitchYaw(T_shoulder / k_sh), np.zeros(3))))
            plant.AddForceElement(LinearBushingRollPitchYaw(
                rest, joint.frame_on_child(), np.full(3, k_sh),
                np.full(3, 0.4 * np.sqrt(k_sh * I_sh)), zero, zero))
            # The hand on the thigh: a 3D spring-damper (damping ratio 0.3
            # on the arm mass).
            fa = plant.AddFrame(FixedOffsetFrame(
                f"hand_on_thigh_{side}", plant.GetBodyByName(f"thigh_{side}", human).body_frame(),
                RigidTransform(p_hand - thigh.origin_W + F_hand / k_h)))
            fc = plant.AddFrame(FixedOffsetFrame(
                f"hand_{side}", plant.GetBodyByName(f"arm_{side}", human).body_frame(),
                RigidTransform(p_hand - arm.origin_W)))
            c_h = 0.6 * np.sqrt(k_h * arm.mass)
            plant.AddForceElement(LinearBushingRollPitchYaw(
                fa, fc, zero, zero, np.full(3, k_h), np.full(3, c_h)))


@_candidate(Effect(
    "visceral_mass", "abdominal wobbling mass coupled to the torso",
    (EffectParam("mass_kg", "kg", 0.0, 5.0, bounds=(0.0, 6.0)),),
    "linear", False,
    "an extra vertical mode near 5 Hz: a notch/second peak in trunk/head z; "
    "no level dependence",
    fixed={"freq_hz": 5.0, "damping_ratio": 0.3}))
class VisceralMass(CandidateEffect):
    """The viscera body (taken from the middle torso) on its vertical joint,
    with a spring and the joint's damping."""

    def body_options(self) -> dict:
        return {"viscera_kg": self.values["mass_kg"]}

    def add_plant_elements(self, plant, human, seat, body) -> None:
        from pydrake.multibody.tree import LinearBushingRollPitchYaw

        if not self.values["mass_kg"] > 0:
            return
        zero = np.zeros(3)
        v = self.values
        m, w = v["mass_kg"], 2 * np.pi * v["freq_hz"]
        joint = plant.GetJointByName("visceral_z", human)
        joint.set_default_damping_vector([2 * v["damping_ratio"] * m * w])
        plant.AddForceElement(LinearBushingRollPitchYaw(
            joint.frame_on_parent(), joint.frame_on_child(), zero, zero,
            np.array([0.0, 0.0, m * w * w]), zero))


# ---------------------------------------------------------------------------
# cocontraction: active stiffness rising with the vibration level
# ---------------------------------------------------------------------------


def cocontraction_gains(params, layout) -> np.ndarray:
    """Active stiffness kp per rotational DoF that co-contraction scales
    (trunk, neck and hip DoFs; 0 elsewhere)."""
    from ...model.plant import pid_vectors

    kp = pid_vectors(params, layout)["kp"]
    return np.where([g in COCONTRACTION_GROUPS for g in layout.groups], kp, 0.0)


@_candidate(Effect(
    "cocontraction", "joint stiffness rising with vibration level",
    (EffectParam("c_per_ms2", "1/(m/s^2)", 0.0, 1.5, bounds=(0.0, 6.0)),),
    "level", True,
    "trunk/head rotational peaks move UP and drop with level (stiffer at higher "
    "level)",
    fixed={"tau_s": 2.0}))
class Cocontraction(CandidateEffect):
    """A `CoContraction` system (named "cocontraction") adding c a_rms kp
    of active stiffness; a run starts adapted to its signal's level."""

    def add_force_systems(self, parts) -> list:
        from ...systems.joints import CoContraction

        layout = parts.hp.layout
        cc = parts.add_system(self.name, CoContraction(
            layout, self.values["c_per_ms2"], cocontraction_gains(parts.params, layout),
            parts.time_step, self.values["tau_s"]))
        parts.builder.Connect(parts.seat_acceleration, cc.GetInputPort("seat_acceleration"))
        return [cc]

    def start_run(self, model, smap, x, signal) -> None:
        # The running mean square starts at the signal's over its steady
        # part (the subject has adapted to the level when recording starts).
        if self.name in model.systems:
            steady = signal.acceleration[int(round((signal.settle_time + signal.onset_time)
                                                   / signal.time_step)):]
            ms = float(np.mean(np.sum(steady**2, axis=1))) if len(steady) else 0.0
            x[smap.slice(self.name)] = ms


# ---------------------------------------------------------------------------
# seat_cushion_dynamics: the pan on its own spring-damper
# ---------------------------------------------------------------------------


@_candidate(Effect(
    "seat_cushion_dynamics", "the cushion as its own mass-spring-damper",
    (EffectParam("stiffness", "N/m", 5.0e6, 4.0e4, log=True, bounds=(1.0e4, 1.0e7)),),
    "linear", False,
    "an extra vertical seat mode: pelvis z resonance lower and a second peak; "
    "no level dependence",
    fixed={"mass_kg": 4.0, "damping_ratio": 0.2}))
class SeatCushionDynamics(CandidateEffect):
    """The pan as a cushion link on a vertical joint (seat SDF), with a
    preloaded spring and the joint's damping."""

    def seat_options(self) -> dict:
        return {"cushion_mass_kg": self.values["mass_kg"]}

    def add_plant_elements(self, plant, human, seat, body) -> None:
        from pydrake.math import RigidTransform
        from pydrake.multibody.tree import FixedOffsetFrame, LinearBushingRollPitchYaw

        from ...model.plant import NOMINAL_LOAD_SHARE

        if not self.values["mass_kg"] > 0:
            return
        zero = np.zeros(3)
        c = self.values
        k = c["stiffness"]
        # The cushion carries its own mass and the occupant's pan share.
        m_eff = c["mass_kg"] + NOMINAL_LOAD_SHARE["pelvis_pan"] * body.total_mass \
            + 2 * NOMINAL_LOAD_SHARE["thighs_pan"] * body.total_mass
        joint = plant.GetJointByName("cushion_z", seat)
        joint.set_default_damping_vector([2 * c["damping_ratio"] * np.sqrt(k * m_eff)])
        # Preloaded so that under the nominal occupant the cushion surface
        # sits where the rigid pan's does (the model's seat geometry is the
        # loaded seat): the spring's free position is m_eff g / k higher.
        lift = m_eff * 9.81 / k
        rest = plant.AddFrame(FixedOffsetFrame(
            "cushion_spring_rest", joint.frame_on_parent(), RigidTransform([0.0, 0.0, lift])))
        plant.AddForceElement(LinearBushingRollPitchYaw(
            rest, joint.frame_on_child(), zero, zero, np.array([0.0, 0.0, k]), zero))


# ---------------------------------------------------------------------------
# softening: the tissue losing more stiffness with movement than the model's
# ---------------------------------------------------------------------------


@_candidate(Effect(
    "softening", "the tissue on the pan losing more stiffness with movement than the model's",
    (EffectParam("extra_loss", "-", 0.0, 0.5, bounds=(0.0, 0.9)),),
    "level", True,
    "body-on-seat resonances (vertical pelvis, trunk and head; the apparent mass) move DOWN "
    "with level beyond the model's own softening; no extra mode"))
class Softening(CandidateEffect):
    """A second `BodySoftening` system (named "softening") on the pan
    tissue's contact points (`SOFTENING_PAIRS`): each loses up to `extra_loss` of its contact's
    long-range stiffness as it moves, with the model's critical amplitude
    and memory (`ehm_drake.model.softening`); a subject whose nonlinearity
    is larger than the model's (its size varies between people and with
    their muscle tension: Matsumoto & Griffin 2002, J Sound Vib 253(1):77-92)."""

    def add_force_systems(self, parts) -> list:
        from ...model.restraints import restraint_points
        from ...model.softening import ElementSet
        from ...systems.softening import BodySoftening

        r = self.values["extra_loss"]
        if not r > 0:
            return []
        pts = [p for p in restraint_points(parts.hp) if p.pair in SOFTENING_PAIRS]
        t = parts.params.softening.tissue
        k = np.array([getattr(parts.params.contact, p.pair).stiffness for p in pts])
        n = len(pts)
        elements = ElementSet(("extra",) * n, tuple(p.name for p in pts), k, k,
                              np.full(n, r), np.full(n, t.critical_rms_m),
                              np.full(n, t.time_constant_s))
        return [parts.add_system(self.name, BodySoftening(
            parts.hp.plant, parts.hp.layout, elements, pts, [], parts.time_step))]


# ---------------------------------------------------------------------------
# The library
# ---------------------------------------------------------------------------

EFFECTS: dict[str, Effect] = {e.name: e for e in _DEFINED}

EFFECT_NAMES = tuple(EFFECTS)


def effect_values(name: str, strength: float) -> dict[str, float]:
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; choose from {', '.join(EFFECT_NAMES)}")
    return EFFECTS[name].values(strength)


def validate_effects(effects: dict | None) -> dict:
    """Check an {effect: {param: value}} mapping; fill fixed values."""
    return validate_extensions(effects)
