"""Reality `lumped`: an independent seated human on Drake, built separately
from the EHM model (nothing of its code, structure or parameter files).

Structure: pelvis (floating on the seat), abdomen, thorax with the arms
lumped in (hands on the lap), one head-neck body, thighs and shank+foot
bodies: 8 bodies, 23 DoF; 3-DoF joints (revolute chains: flexion-extension,
lateral bending, axial rotation) at L4-L5, T12-L1, C7-T1 and the hips,
revolute knees.  Anthropometry: Dempster's segment data as tabulated by
Winter, Drillis & Contini's length fractions, Pheasant's seated dimensions
(50th-percentile male, 77 kg, 1.75 m).  Passive joints: neutral zone plus
exponential stiffening, viscous damping.  Seat: Hunt-Crossley point contact
(n = 1.5) at the ischial tuberosities and beside them under the buttocks,
thighs, lumbar and upper back (two pads) and heels and balls of the feet,
with elasto-plastic (regularized Coulomb) shear.  Control: delayed (20 ms)
PD of the joint angles through first-order activation (40 ms), a
vestibular head-in-space term on the neck, and a tonic torque adapted
while the subject settles.  The seat moves the body through the inertial
load -m a_seat on every body in the seat frame.

All values with their sources: `parameters.PARAMETERS`; the effects' own
ranges: `parameters.EFFECT_RANGES`.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from .. import Reality, RealityError, RealityRecord, register_reality
from . import parameters as par
from .body import make_plan


def _finite_strength(name: str, strength) -> float:
    if isinstance(strength, bool) or not isinstance(strength, (int, float)) \
            or not math.isfinite(strength) or not 0.0 <= strength <= 1.0:
        raise RealityError(f"strength of {name} must be a number in [0, 1], got {strength!r}")
    return float(strength)


def effect_is_off(name: str, values: dict) -> bool:
    """True when every scaled parameter of the effect is at its 'off' value."""
    return all(math.isclose(values[p], r.off, rel_tol=1e-12, abs_tol=0.0)
               for p, r in par.EFFECT_RANGES[name].items())


@register_reality
class LumpedReality(Reality):
    name: ClassVar[str] = "lumped"
    description: ClassVar[str] = (
        "8-body, 23-DoF seated human on Drake (Dempster/Winter anthropometry, "
        "lumped spine joints with neutral-zone stiffening, Hunt-Crossley seat "
        "contact with elasto-plastic friction, delayed PD with activation "
        "dynamics and vestibular head stabilization)")
    sources: ClassVar[tuple[str, ...]] = (
        "D. A. Winter, Biomechanics and Motor Control of Human Movement, 4th ed. 2009 "
        "(Dempster segment data, Drillis & Contini lengths)",
        "S. Pheasant, C. Haslegrave, Bodyspace, 3rd ed. 2006 (seated dimensions)",
        "E. P. Hanavan, AMRL-TR-64-102, 1964 (trunk solids)",
        "S. McGill et al., Spine 19 (1994) 696 and Clin. Biomech. 9 (1994) 193 "
        "(lumbar and neck passive stiffness)",
        "M. Panjabi, J. Spinal Disord. 5 (1992) (neutral zone)",
        "R. Riener, T. Edrich, J. Biomech. 32 (1999) 539 (passive leg joints)",
        "K. Hunt, F. Crossley, J. Appl. Mech. 42 (1975) 440 (contact damping)",
        "P. Dupont et al., IEEE TAC 47 (2002) 787 (elasto-plastic friction)",
        "A. Goodworth, R. Peterka, J. Neurophysiol. 102 (2009) 496 (trunk control)",
        "G. Peng, T. Hain, B. Peterson, Biol. Cybern. 75 (1996) (head stabilization)",
        "T. Fairley, M. Griffin, J. Biomech. 22 (1989) 81 (seated apparent mass)",
    )
    time_step: ClassVar[float] = 1e-3

    def subject(self, seed: int) -> dict[str, Any]:
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise RealityError(f"subject seed must be a non-negative integer, got {seed!r}")
        return self._subject(int(seed), par.SPREAD, par.draw_factors(int(seed)))

    def nominal_subject(self) -> dict[str, Any]:
        """The unscattered subject (every factor 1)."""
        return self._subject(None, 0.0, {k: 1.0 for k in par.scattered_names()})

    def _subject(self, seed, spread: float, factors: dict) -> dict[str, Any]:
        values = par.apply_factors(factors)
        return {"reality": self.name, "seed": seed, "spread": spread, "factors": factors,
                "values": {k: list(values[k]) if isinstance(values[k], tuple) else values[k]
                           for k in factors},
                "body_mass_kg": float(make_plan(values).total_mass)}

    def effect_names(self) -> tuple[str, ...]:
        return tuple(par.EFFECT_RANGES)

    def effect_values(self, name: str, strength: float) -> dict[str, float]:
        if name not in par.EFFECT_RANGES:
            raise RealityError(f"unknown effect {name!r}; choose from "
                               f"{', '.join(par.EFFECT_RANGES)}")
        s = _finite_strength(name, strength)
        out = dict(par.EFFECT_FIXED.get(name, {}))
        for p, r in par.EFFECT_RANGES[name].items():
            out[p] = r.off * (r.full / r.off) ** s if r.log else r.off + (r.full - r.off) * s
        return out

    def _values(self, subject: dict) -> dict:
        factors = subject.get("factors") if isinstance(subject, dict) else None
        if not isinstance(factors, dict) or set(factors) != set(par.scattered_names()):
            raise RealityError("lumped: the subject must come from LumpedReality.subject()")
        return par.apply_factors({k: float(v) for k, v in factors.items()})

    def prepare(self, subject: dict[str, Any], effects: dict[str, dict[str, float]]):
        from .simulate import prepare

        values = self._values(subject)
        active = {}
        for name, vals in (effects or {}).items():
            if name not in par.EFFECT_RANGES:
                raise RealityError(f"unknown effect {name!r}; choose from "
                                   f"{', '.join(par.EFFECT_RANGES)}")
            full = {**par.EFFECT_FIXED.get(name, {}), **vals}
            missing = set(par.EFFECT_RANGES[name]) - set(full)
            if missing:
                raise RealityError(f"effect {name} lacks {', '.join(sorted(missing))}")
            if not effect_is_off(name, full):
                active[name] = {k: float(v) for k, v in full.items()}
        return prepare(values, active, self.time_step)

    def run_test(self, prepared, signal) -> RealityRecord:
        from .simulate import record_from_output, run

        return record_from_output(self, prepared, run(prepared, signal), signal)
