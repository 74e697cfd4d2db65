"""Candidate unmodelled effects: each a real extension of the Drake model
with 1-3 physical parameters, off by default.

`strength` in [0, 1] is a fraction of the effect's physiologically
plausible range (0 = off, 1 = the largest plausible size); `values(name,
strength)` gives its parameters.  The model extensions themselves are
built by `ehm_drake.model.plant.add_seated_human` (bodies, joints, contact)
and `ehm_drake.diagram.build_diagram` (systems) from an `effects` mapping
{name: {parameter: value}}.

Ranges (strength 1) and reasons:

* reflex_delay: tau = 30 ms transport delay in the PID (P and I) and
  head-in-space feedback (short-latency stretch reflexes 20-40 ms; the
  derivative action stays instantaneous as intrinsic muscle damping, as
  does the passive tissue).  Beyond ~40 ms this model's neck loop loses
  stability (linear analysis: a 7 Hz head mode with damping ratio 0.02 at
  40 ms, unstable at 45 ms), so 30 ms is the largest plausible value here.
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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


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


EFFECTS: dict[str, Effect] = {e.name: e for e in [
    Effect("reflex_delay", "neural transport delay in the PID and head-in-space feedback",
           (EffectParam("tau_s", "s", 0.0, 0.03, bounds=(0.0, 0.04)),),
           "delay", False,
           "phase lag growing with frequency; lower, sharper head/trunk peaks; no level "
           "dependence"),
    Effect("seat_foam_stiffening", "stiffening seat pan and backrest contact",
           (EffectParam("gamma_per_mm2", "1/mm^2", 0.0, 3.0, bounds=(0.0, 20.0)),),
           "level", True,
           "seat-body resonances move UP with vibration level"),
    Effect("seat_friction", "Coulomb stick-slip shear at the seat (limit mu N)",
           (EffectParam("mu", "-", 2.0, 0.2, log=True, bounds=(0.1, 4.0)),),
           "level", True,
           "stiff shear at low level, slip at high level: fore-aft/lateral pelvis modes "
           "move DOWN and damp with level; coherence loss"),
    Effect("backrest_separation", "unilateral back contact with low preload",
           (EffectParam("offset_mm", "mm", 0.0, 4.0, bounds=(0.0, 8.0)),),
           "level", True,
           "back support fades with level: fore-aft trunk/head gains rise and peaks move "
           "down with level; coherence loss in x"),
    Effect("arms", "arms resting on the thighs, attached at the shoulders",
           (EffectParam("shoulder_stiffness", "N m/rad", 2000.0, 20.0, log=True,
                        bounds=(5.0, 5000.0)),
            EffectParam("hand_stiffness", "N/m", 50.0, 2.0e4, log=True,
                        bounds=(20.0, 1.0e5))),
           "linear", False,
           "an extra trunk-arm mode (absorber) splitting the trunk pitch/roll peaks; "
           "no level dependence"),
    Effect("visceral_mass", "abdominal wobbling mass coupled to the torso",
           (EffectParam("mass_kg", "kg", 0.0, 5.0, bounds=(0.0, 6.0)),),
           "linear", False,
           "an extra vertical mode near 5 Hz: a notch/second peak in trunk/head z; "
           "no level dependence",
           fixed={"freq_hz": 5.0, "damping_ratio": 0.3}),
    Effect("cocontraction", "joint stiffness rising with vibration level",
           (EffectParam("c_per_ms2", "1/(m/s^2)", 0.0, 1.5, bounds=(0.0, 6.0)),),
           "level", True,
           "trunk/head rotational peaks move UP and drop with level (stiffer at higher "
           "level)",
           fixed={"tau_s": 2.0}),
    Effect("seat_cushion_dynamics", "the cushion as its own mass-spring-damper",
           (EffectParam("stiffness", "N/m", 5.0e6, 4.0e4, log=True, bounds=(1.0e4, 1.0e7)),),
           "linear", False,
           "an extra vertical seat mode: pelvis z resonance lower and a second peak; "
           "no level dependence",
           fixed={"mass_kg": 4.0, "damping_ratio": 0.2}),
]}

EFFECT_NAMES = tuple(EFFECTS)


def effect_values(name: str, strength: float) -> dict[str, float]:
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; choose from {', '.join(EFFECT_NAMES)}")
    return EFFECTS[name].values(strength)


def validate_effects(effects: dict | None) -> dict:
    """Check an {effect: {param: value}} mapping; fill fixed values."""
    out = {}
    for name, vals in (effects or {}).items():
        if name not in EFFECTS:
            raise ValueError(f"unknown effect {name!r}; choose from {', '.join(EFFECT_NAMES)}")
        e = EFFECTS[name]
        known = {p.name for p in e.params} | set(e.fixed)
        bad = set(vals) - known
        if bad:
            raise ValueError(f"effect {name}: unknown parameter(s) {', '.join(sorted(bad))} "
                             f"(known: {', '.join(sorted(known))})")
        full = {**e.fixed, **{p.name: p.off for p in e.params}, **vals}
        for k, v in full.items():
            if not (isinstance(v, (int, float)) and math.isfinite(v)) or v < 0:
                raise ValueError(f"effect {name}.{k} must be a finite non-negative number, "
                                 f"got {v!r}")
        out[name] = {k: float(v) for k, v in full.items()}
    return out
