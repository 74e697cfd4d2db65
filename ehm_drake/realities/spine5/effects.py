"""The eight candidate effects as `spine5` implements them: names and
meaning as in `ehm_drake.gap.library.effects`, ranges and laws of this reality's own.

Each effect maps a strength s in [0, 1] to its parameters; s = 0 is the
base body exactly (the structural effects add no body at s = 0: their
``on`` flag is 0).

* reflex_delay -- extra neural transport delay on top of the baseline
  (30 ms, params.DELAY) in both the proprioceptive and the vestibular loops:
  0 -> 30 ms (short- plus medium-latency reflex components reach 50-70 ms
  in total; here the total stays within 60 ms).
* seat_foam_stiffening -- every pan and back-pad point's normal force
  k (d + gamma (d - d_slow)^3): the foam stiffens with its dynamic
  compression about the slowly creeping operating point d_slow (time
  constant 1.5 s: the static preload is carried by the relaxed foam);
  gamma 0 -> 1.2 /mm^2: tangent stiffness x2.2 at 0.58 mm and x4.6 at 1 mm of
  dynamic compression; the cubic term saturates (secant stiffness at most
  x6: densifying polyurethane foam stiffens several-fold); the dynamic
  compression here is 0.3-0.6 mm RMS under the pelvis in vertical tests at
  0.3-0.6 m/s^2 and ~1 mm at the pads in fore-aft tests, so the stiffening
  grows with the level.
* seat_friction -- Coulomb limit mu N of the elastic-plastic (stick-slip)
  tangential springs at the pan and pads: mu 0.8 (woven fabric against
  clothing, base) -> 0.12 (coated fabric or smooth leather against
  polyester/nylon clothing, 0.1-0.3), log-wise.  The base pads already slip
  at their peaks in fore-aft tests; at mu 0.12 the pan slips at the peaks of
  0.6 m/s^2 fore-aft tests (pan shear/normal up to ~0.17) and rarely at
  0.3 m/s^2.
* backrest_separation -- the pads sit further back than the subject's
  posture: the subject holds the trunk more upright (a flexion offset at
  L5/S1 and T12/L1, ~6 deg at full strength, solved in the statics; the
  muscles' tone holds it) so that the pads carry only a fraction of the base
  fore-aft preload: 1 -> 0.08 (~5 N, on the lumbar pad only; the thoracic
  pads are just out of reach and the unilateral contacts open and close as
  the trunk sways).
* arms -- upper arm and forearm-hand per side on a 3-DoF shoulder and a
  revolute elbow (muscle torque generators with intrinsic stiffness half the
  reflex stiffness, passive SLS, joint damping 0.05 s x the joint's static
  stiffness: `Spine5Model._arm_gains`), the palm resting on the
  thigh through a soft-tissue 3D spring-damper preloaded with its share of
  the forearm weight; shoulder reflex stiffness 300 -> 12 N m/rad (arms held
  firm -> relaxed; elbow half of it) and palm-thigh stiffness 300 ->
  2.5e4 N/m (barely touching -> forearm resting: soft tissue 1e4-5e4 N/m),
  log-wise.  At s = 0 the arms stay lumped in the upper thorax.
* visceral_mass -- abdominal mass 0 -> 4 kg taken out of the lumbar body
  onto fore-aft and vertical spring-dampers (4.2 Hz vertical, 6 Hz fore-aft,
  damping ratio 0.25): the viscera (liver, stomach, intestines ~4-6 kg) move
  against the spine; abdominal-wall resonances are reported at 4-8 Hz.
* cocontraction -- intrinsic stiffness, reflex stiffness and reflex rate gain
  of the spine, neck and hip muscles multiplied by (1 + c a_rms) (antagonist
  co-activation raises short-range stiffness and reflex gain together),
  a_rms the running RMS of the seat
  acceleration magnitude (time constant 3 s; the subject is adapted when
  the steady part starts); c 0 -> 1.2 per m/s^2 (x1.7 at 0.6 m/s^2).
* softening -- extra short-range share of the seat tissue's stiffness on top
  of the subject's own (params soft_fraction, soft_range: every subject
  softens with vibration magnitude as people do): 0 -> 0.45.
* seat_cushion_dynamics -- the pan as a 3.5 kg cushion on a vertical
  spring-damper to the seat frame under the pelvis and thigh points:
  stiffness 3e6 N/m (rigid) -> 5e4 N/m (soft automotive cushion: with the
  occupant's pan load, ~86 % of the body mass here, a 4.2 Hz seat mode),
  log-wise, damping ratio 0.15 of the loaded cushion (PU foam 0.1-0.2).
"""

from __future__ import annotations

import math

from .. import RealityError

#: name -> [(param, off, full, log)], fixed values.
SPECS: dict[str, tuple[list[tuple[str, float, float, bool]], dict[str, float]]] = {
    "reflex_delay": ([("extra_delay_s", 0.0, 0.030, False)], {}),
    "seat_foam_stiffening": ([("gamma_per_mm2", 0.0, 1.2, False)], {"tau_slow_s": 1.5}),
    "seat_friction": ([("mu", 0.8, 0.12, True)], {}),
    "backrest_separation": ([("preload_fraction", 1.0, 0.08, False)], {}),
    "arms": ([("shoulder_kp", 300.0, 12.0, True), ("hand_k", 300.0, 2.5e4, True)], {}),
    "visceral_mass": ([("mass_kg", 0.0, 4.0, False)],
                      {"freq_z_hz": 4.2, "freq_x_hz": 6.0, "damping_ratio": 0.25}),
    "cocontraction": ([("c_per_ms2", 0.0, 1.2, False)], {"tau_s": 3.0}),
    "seat_cushion_dynamics": ([("stiffness", 3.0e6, 5.0e4, True)],
                              {"mass_kg": 3.5, "damping_ratio": 0.15}),
    # Softening beyond the typical subject's: every subject's seat tissue
    # already loses a short-range share s (params soft_fraction, 0.32-0.48
    # with the scatter) of its stiffness beyond ~soft_range of dynamic
    # compression about the slow mean (`forces.Spine5Forces.contact`); the
    # effect adds 0 -> 0.45 to s (x0.92 -> ~x0.83 of the seat-to-pelvis
    # vertical resonance from 0.3 to 0.6 m/s^2 r.m.s.; Loram, Maganaris &
    # Lakie 2007, J Physiol 584:661-675: the calf's short-range stiffness is
    # up to 81% of its stiffness at 0.03 deg).  A memoryless law about the
    # slow mean, unlike the EHM model's running-RMS one.
    "softening": ([("extra_short_range_fraction", 0.0, 0.45, False)], {}),
}

EFFECT_NAMES = tuple(SPECS)
#: Effects that add bodies: an "on" flag (1 for s > 0).
STRUCTURAL = ("arms", "seat_cushion_dynamics")


def effect_values(name: str, strength: float) -> dict[str, float]:
    if name not in SPECS:
        raise RealityError(f"spine5: unknown effect {name!r}; choose from "
                           f"{', '.join(EFFECT_NAMES)}")
    if isinstance(strength, bool) or not isinstance(strength, (int, float)) \
            or not math.isfinite(strength) or not 0.0 <= strength <= 1.0:
        raise RealityError(f"spine5: strength of {name} must be in [0, 1], got {strength!r}")
    params, fixed = SPECS[name]
    out = dict(fixed)
    for p, off, full, log in params:
        out[p] = off * (full / off) ** strength if log else off + (full - off) * strength
    if name in STRUCTURAL:
        out["on"] = 1.0 if strength > 0 else 0.0
    return {k: float(v) for k, v in out.items()}


def validate_effects(effects) -> dict[str, dict[str, float]]:
    """{name: {param: value}} with the fixed values and off values filled."""
    if effects is None:
        return {}
    if not isinstance(effects, dict):
        raise RealityError(f"spine5: effects must be a mapping, got {type(effects).__name__}")
    out = {}
    for name, vals in effects.items():
        base = effect_values(name, 0.0)
        vals = dict(vals or {})
        bad = set(vals) - set(base)
        if bad:
            raise RealityError(f"spine5: effect {name}: unknown parameter(s) "
                               f"{', '.join(sorted(bad))} (known: {', '.join(sorted(base))})")
        full = {**base, **vals}
        for k, v in full.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0:
                raise RealityError(f"spine5: effect {name}.{k} must be a finite non-negative "
                                   f"number, got {v!r}")
        out[name] = {k: float(v) for k, v in full.items()}
    return out
