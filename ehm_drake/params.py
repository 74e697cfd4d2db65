"""Model parameters: typed dataclasses loaded from YAML or JSON and validated.

The values live in one place, the packaged parameter file
`ehm_drake/data/default_params.yaml`, where each carries its source or
reason.  A user file (YAML or JSON) may give any subset of the keys; it is
merged over the defaults.  Unknown keys, wrong types, NaN and negative
stiffness/damping/gains are rejected with an error that names the key.

Units: SI throughout; angles in rad, torques in N m, stiffness in N m/rad
(rotational) or N/m (translational), damping in N m s/rad or N s/m.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import typing
from dataclasses import dataclass, fields
from importlib import resources
from pathlib import Path

import yaml

Vec3 = tuple[float, float, float]

#: Joint groups of the passive (Cardan) restraints and the joints in each.
PASSIVE_GROUPS: dict[str, tuple[str, ...]] = {
    "lumbar": ("lumbosacral_L5S1", "lumbar_L4L5"),
    "thoracic": ("thoracolumbar_T12L1",),
    "neck": ("lower_neck_C7T1", "upper_neck_C0C1"),
    "hips": ("hip_l", "hip_r"),
    "knees": ("knee_l", "knee_r"),
    "ankles": ("ankle_l", "ankle_r"),
}
#: Joint groups of the PID controllers (the issue's spine/neck/hips/knees/ankles).
PID_GROUPS: dict[str, tuple[str, ...]] = {
    "spine": PASSIVE_GROUPS["lumbar"] + PASSIVE_GROUPS["thoracic"],
    "neck": PASSIVE_GROUPS["neck"],
    "hips": PASSIVE_GROUPS["hips"],
    "knees": PASSIVE_GROUPS["knees"],
    "ankles": PASSIVE_GROUPS["ankles"],
}
#: Body-seat contact pairs: name -> (body collision geometries, seat part).
CONTACT_PAIRS: dict[str, tuple[tuple[str, ...], str]] = {
    "pelvis_pan": (("buttocks",), "pan"),
    "thighs_pan": (("thigh_l", "thigh_r"), "pan"),
    "lower_back_pad": (("lower_back",), "lower_pad"),
    "upper_back_pad": (("upper_back",), "upper_pad"),
    "feet_floor": (("foot_l", "foot_r"), "floor"),
}
VARIANTS = ("default", "no-integrator", "high-stiffness")


class ParameterError(ValueError):
    """A parameter file or value is invalid; the message names the key."""


@dataclass
class PassiveGroup:
    """Cardan restraint of a joint group: torsional springs and dampers about
    the joint's x (roll), y (pitch), z (yaw) axes.  A revolute joint uses the
    component about its axis (y); the universal neck joint uses x and y."""

    stiffness: Vec3
    damping: Vec3


@dataclass
class PassiveJoints:
    lumbar: PassiveGroup
    thoracic: PassiveGroup
    neck: PassiveGroup
    hips: PassiveGroup
    knees: PassiveGroup
    ankles: PassiveGroup
    #: Axial spring-damper of the spinal compression DoF (T12/L1), N/m, N s/m.
    spine_axial_stiffness: float
    spine_axial_damping: float


@dataclass
class PidGroup:
    """PID gains of one joint group (per joint, about x, y, z)."""

    kp: Vec3
    kd: Vec3
    #: Integral action time constant tau_I (s): Ki = (kp + passive k)/tau_I.
    integral_time_s: float
    #: Anti-windup: |Ki * integral| is kept below this torque (N m).
    integral_torque_limit: Vec3


@dataclass
class Pid:
    integrator: bool
    spine: PidGroup
    neck: PidGroup
    hips: PidGroup
    knees: PidGroup
    ankles: PidGroup


@dataclass
class HeadInSpace:
    enabled: bool
    kp: Vec3
    kd: Vec3


@dataclass
class ContactPair:
    stiffness: float
    damping: float


@dataclass
class Contact:
    model: str  # "point" or "hydroelastic"
    pelvis_pan: ContactPair
    thighs_pan: ContactPair
    lower_back_pad: ContactPair
    upper_back_pad: ContactPair
    feet_floor: ContactPair
    hydroelastic_resolution_m: float


@dataclass
class Restraint:
    """Shear point restraint: per tangential axis a spring-damper whose
    elastic force is limited; beyond the limit the contact slips."""

    stiffness: float
    damping: float
    force_limit: float


@dataclass
class Restraints:
    pelvis_pan: Restraint
    thighs_pan: Restraint
    lower_back_pad: Restraint
    upper_back_pad: Restraint
    feet_floor: Restraint


@dataclass
class Simulation:
    time_step_s: float
    settle_time_s: float
    onset_time_s: float
    output_rate_hz: float


@dataclass
class Variants:
    #: Factor on all passive joint stiffnesses in the `high-stiffness` variant.
    high_stiffness_factor: float


@dataclass
class ModelParams:
    passive: PassiveJoints
    pid: Pid
    his: HeadInSpace
    contact: Contact
    restraints: Restraints
    simulation: Simulation
    variants: Variants

    def to_dict(self) -> dict:
        return _to_builtin(dataclasses.asdict(self))

    def copy(self) -> ModelParams:
        return copy.deepcopy(self)


def _to_builtin(x):
    if isinstance(x, dict):
        return {k: _to_builtin(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_to_builtin(v) for v in x]
    return x


# ---------------------------------------------------------------------------
# Loading and validation
# ---------------------------------------------------------------------------


def _build(cls, data, path: str):
    if not isinstance(data, dict):
        raise ParameterError(f"{path or 'parameters'}: expected a mapping, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in fields(cls)]
    unknown = sorted(set(data) - set(names))
    if unknown:
        where = f"{path}." if path else ""
        raise ParameterError(
            f"unknown parameter key(s): {', '.join(where + u for u in unknown)} "
            f"(known here: {', '.join(names)})"
        )
    missing = [n for n in names if n not in data]
    if missing:
        where = f"{path}." if path else ""
        raise ParameterError(f"missing parameter key(s): {', '.join(where + m for m in missing)}")
    kwargs = {}
    for name in names:
        key = f"{path}.{name}" if path else name
        kwargs[name] = _convert(hints[name], data[name], key)
    return cls(**kwargs)


def _convert(tp, value, key):
    if dataclasses.is_dataclass(tp):
        return _build(tp, value, key)
    if tp is bool:
        if not isinstance(value, bool):
            raise ParameterError(f"{key}: expected true/false, got {value!r}")
        return value
    if tp is float:
        return _number(value, key)
    if tp is str:
        if not isinstance(value, str):
            raise ParameterError(f"{key}: expected a string, got {value!r}")
        return value
    if typing.get_origin(tp) is tuple:
        n = len(typing.get_args(tp))
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = [value] * n
        if not isinstance(value, (list, tuple)) or len(value) != n:
            raise ParameterError(f"{key}: expected a list of {n} numbers, got {value!r}")
        return tuple(_number(v, f"{key}[{i}]") for i, v in enumerate(value))
    raise TypeError(tp)  # pragma: no cover


def _number(value, key) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{key}: expected a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ParameterError(f"{key}: must be finite, got {value}")
    return value


def _walk_numbers(obj, path=""):
    if dataclasses.is_dataclass(obj):
        for f in fields(obj):
            yield from _walk_numbers(getattr(obj, f.name), f"{path}.{f.name}" if path else f.name)
    elif isinstance(obj, tuple):
        for i, v in enumerate(obj):
            yield f"{path}[{i}]", v
    elif isinstance(obj, float):
        yield path, obj


def validate(params: ModelParams) -> ModelParams:
    """Check physical admissibility; raise ParameterError naming the key."""
    for key, v in _walk_numbers(params):
        if v < 0:
            raise ParameterError(f"{key} = {v}: must not be negative")
    s = params.simulation
    if not 1e-5 <= s.time_step_s <= 0.01:
        raise ParameterError(
            f"simulation.time_step_s = {s.time_step_s}: expected 1e-5..0.01 s "
            "(1 ms as in the paper; give seconds, not milliseconds)"
        )
    if s.output_rate_hz < 100 or s.output_rate_hz > 1.0 / s.time_step_s:
        raise ParameterError(
            f"simulation.output_rate_hz = {s.output_rate_hz}: expected 100 Hz up to "
            f"the simulation rate {1.0 / s.time_step_s:g} Hz"
        )
    if params.contact.model not in ("point", "hydroelastic"):
        raise ParameterError(
            f"contact.model = {params.contact.model!r}: expected 'point' or 'hydroelastic'"
        )
    for name in CONTACT_PAIRS:
        pair = getattr(params.contact, name)
        if pair.stiffness <= 0:
            raise ParameterError(f"contact.{name}.stiffness must be positive")
        r = getattr(params.restraints, name)
        if r.stiffness > 0 and r.force_limit <= 0:
            raise ParameterError(f"restraints.{name}.force_limit must be positive")
    for group in PID_GROUPS:
        g = getattr(params.pid, group)
        if params.pid.integrator and g.integral_time_s <= 0:
            raise ParameterError(
                f"pid.{group}.integral_time_s must be positive when pid.integrator is true"
            )
    if params.contact.hydroelastic_resolution_m <= 0:
        raise ParameterError("contact.hydroelastic_resolution_m must be positive")
    if params.variants.high_stiffness_factor < 1:
        raise ParameterError("variants.high_stiffness_factor must be >= 1")
    return params


def _merge(base: dict, over: dict, path="") -> dict:
    out = dict(base)
    for k, v in over.items():
        key = f"{path}.{k}" if path else k
        if k not in base:
            known = ", ".join(base) if isinstance(base, dict) else ""
            raise ParameterError(f"unknown parameter key: {key} (known here: {known})")
        if isinstance(base[k], dict):
            if not isinstance(v, dict):
                raise ParameterError(f"{key}: expected a mapping, got {v!r}")
            out[k] = _merge(base[k], v, key)
        else:
            out[k] = v
    return out


def default_params_path() -> Path:
    return Path(str(resources.files("ehm_drake") / "data" / "default_params.yaml"))


def _read_mapping(path: Path) -> dict:
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"parameter file not found: {path}")
    text = path.read_text()
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            data = yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as e:
        raise ParameterError(f"{path}: not valid {'JSON' if path.suffix == '.json' else 'YAML'}: {e}") from e
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ParameterError(f"{path}: expected a mapping of parameter groups at top level")
    # A fit result file keeps the parameters under "params".
    if set(data) == {"params"} or ("params" in data and "ehm_drake_fit" in data):
        data = data["params"]
    return data


def params_from_dict(data: dict) -> ModelParams:
    """Merge `data` over the defaults, build and validate."""
    base = _read_mapping(default_params_path())
    return validate(_build(ModelParams, _merge(base, data), ""))


def load_params(path: str | Path | None = None) -> ModelParams:
    """Default parameters, or those of the YAML/JSON file at `path` merged
    over the defaults."""
    if path is None:
        return params_from_dict({})
    try:
        return params_from_dict(_read_mapping(Path(path)))
    except ParameterError as e:
        raise ParameterError(f"{path}: {e}") from None


def save_params(params: ModelParams, path: str | Path) -> None:
    """Write the complete parameter set as YAML (or JSON by suffix)."""
    path = Path(path)
    data = params.to_dict()
    if path.suffix.lower() == ".json":
        path.write_text(json.dumps(data, indent=2))
    else:
        path.write_text(yaml.safe_dump(data, sort_keys=False))


def apply_variant(params: ModelParams, variant: str) -> ModelParams:
    """The paper's model variants (Desai et al., Sec. IV, Fig. 5-8).

    * ``default``: PID with integrator + head-in-space control.
    * ``no-integrator``: PID without integral action.
    * ``high-stiffness``: no integrator, all passive joint stiffnesses raised
      by `variants.high_stiffness_factor`, enough to hold the posture.
    """
    if variant not in VARIANTS:
        raise ParameterError(f"unknown variant {variant!r}; choose one of {', '.join(VARIANTS)}")
    p = params.copy()
    if variant in ("no-integrator", "high-stiffness"):
        p.pid.integrator = False
    if variant == "high-stiffness":
        f = p.variants.high_stiffness_factor
        for g in PASSIVE_GROUPS:
            grp = getattr(p.passive, g)
            grp.stiffness = tuple(f * k for k in grp.stiffness)
    return p
