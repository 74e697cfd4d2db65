"""Model parameters: typed dataclasses loaded from YAML or JSON and validated.

The values live in one place, the packaged parameter file
`ehm_drake/data/default_params.yaml`, where each carries its source or
reason.  A user file (YAML or JSON) may give any subset of the keys; it is
merged over the defaults.

Typing and merging are Drake's: `pydrake.common.yaml.yaml_load_typed` reads
the file into the dataclasses below, over the (cached) default instance, and
rejects unknown keys and wrong types.  Admissibility is one table, `RANGES`
(plus `CHOICES`), checked by `validate`.  Every error is a ParameterError of
one line naming the key (and, from `load_params`, the file) and, for a value
out of range, the allowed range.

Units: SI throughout; angles in rad, torques in N m, stiffness in N m/rad
(rotational) or N/m (translational), damping in N m s/rad or N s/m.
"""

from __future__ import annotations

import copy
import dataclasses
import fnmatch
import functools
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from importlib import resources
from pathlib import Path

import yaml

from .typed_mapping import (  # noqa: F401  (ParameterError: re-exported, the package's name)
    ParameterError,
    _changes,
    _expand,
    _freeze,
    _is_number,
    _refused_key,
    _schema,
)

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
#: The human's own rotational joints (the Cardan restraints of the paper):
#: those the implicit design writes as Cardan chains of revolute joints.
CARDAN_JOINTS: tuple[str, ...] = tuple(j for joints in PASSIVE_GROUPS.values() for j in joints)
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
    #: "implicit": Cardan joint chains, every spring at the step's start and
    #: every damper half in the plant's SAP solve (implicit), half explicit,
    #: so the step is second-order accurate and set by accuracy
    #: (`ehm_drake.model.stepping`); "reference": the paper's 1 ms design
    #: with spherical joints, explicit springs and implicit damping
    #: (`reference_design`).
    design: str
    time_step_s: float
    settle_time_s: float
    onset_time_s: float
    output_rate_hz: float


@dataclass
class Seat:
    """The seat's kind (`apply_seat`): the paper's car seat, or a laboratory
    seat (`ehm_drake/data/configurations`)."""

    #: False: a seat without backrest: the back pads stand clear of the body
    #: and carry nothing, and the trunk holds itself (`apply_seat`).
    backrest: bool
    #: True: a rigid seat: each body-seat contact is the tissue alone
    #: (`softening.tissue.<pair>_stiffness`), no cushion in series.
    rigid: bool


@dataclass
class TissueSoftening:
    """The soft tissue (skin, fat, muscle) between the body and the seat under
    the pelvis and thighs and at the back pads, softening with its own
    recent movement (`ehm_drake.model.softening`)."""

    enabled: bool
    #: The tissue's own normal stiffness at rest at each contact pair (N/m):
    #: the pair's contact stiffness on a rigid seat; on a compliant seat the
    #: contact stiffness is this in series with the seat's.
    pelvis_pan_stiffness: float
    thighs_pan_stiffness: float
    lower_back_pad_stiffness: float
    upper_back_pad_stiffness: float
    #: Fraction of the tissue stiffness lost when its movement is far above
    #: the critical amplitude.
    max_loss: float
    #: RMS tissue deformation (m) at which half of `max_loss` is lost.
    critical_rms_m: float
    #: Memory of the movement measure (s): its running mean and variance
    #: follow the deformation with this time constant.
    time_constant_s: float


@dataclass
class MuscleSoftening:
    """Short-range stiffness of the trunk and hip muscles (the PID's active
    stiffness kp), softening with the joints' own recent movement."""

    enabled: bool
    max_loss: float
    #: RMS joint rotation (rad) at which half of `max_loss` is lost.
    critical_rms_rad: float
    time_constant_s: float


@dataclass
class Softening:
    tissue: TissueSoftening
    muscle: MuscleSoftening


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
    seat: Seat
    softening: Softening

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
# Admissible ranges: the one table validate() checks against
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Range:
    """Admissible values of the parameters whose dotted key matches `pattern`
    (`fnmatch`: `*` stands for a group name; the components of a vector share
    its range).  Every number must be finite and not negative in any case; the
    range may restrict that further."""

    pattern: str
    unit: str
    lo: float = 0.0
    #: Upper bound, or a function of the parameters (a bound that depends on
    #: another key).
    hi: float | Callable[[ModelParams], float] = math.inf
    #: True: `lo` itself is not allowed ("> lo"; lo = 0: "must be positive").
    lo_open: bool = False
    #: Why, for the message (source or hint).
    reason: str = ""
    #: The range holds only under this condition: (text, test(params, group)),
    #: group being the key's parent ("restraints.pelvis_pan"); the text may
    #: name it as "{group}".  Otherwise only the "not negative" rule holds.
    when: tuple[str, Callable[[ModelParams, str], bool]] | None = None


def _dotted(obj, path: str):
    for name in path.split("."):
        obj = getattr(obj, name)
    return obj


_IF_INTEGRATOR = ("pid.integrator is true", lambda p, group: p.pid.integrator)
_IF_STIFF = ("{group}.stiffness > 0", lambda p, group: _dotted(p, group).stiffness > 0)

#: Physical admissibility of every parameter, first match wins (the last row
#: catches any key without its own).  These are the limits of a model that
#: can be built and simulated, not physiological plausibility: the plausible
#: ranges that bound a fit are in `data/fit_parameters.yaml` (each within
#: these; tests/test_params.py checks it).
RANGES: tuple[Range, ...] = (
    Range("passive.*.stiffness", "N m/rad"),
    Range("passive.*.damping", "N m s/rad"),
    Range("passive.spine_axial_stiffness", "N/m"),
    Range("passive.spine_axial_damping", "N s/m"),
    Range("pid.*.kp", "N m/rad"),
    Range("pid.*.kd", "N m s/rad"),
    Range("pid.*.integral_time_s", "s", lo_open=True, when=_IF_INTEGRATOR,
          reason="Ki = (kp + passive k)/integral_time_s"),
    Range("pid.*.integral_torque_limit", "N m"),
    Range("his.kp", "N m/rad"),
    Range("his.kd", "N m s/rad"),
    Range("contact.*.stiffness", "N/m", lo_open=True,
          reason="a contact pair without stiffness does not carry the body"),
    Range("contact.*.damping", "N s/m"),
    Range("contact.hydroelastic_resolution_m", "m", lo_open=True,
          reason="mesh resolution of the compliant ellipsoids"),
    Range("restraints.*.stiffness", "N/m"),
    Range("restraints.*.damping", "N s/m"),
    Range("restraints.*.force_limit", "N", lo_open=True, when=_IF_STIFF,
          reason="beyond this force the restraint slips"),
    Range("simulation.time_step_s", "s", 1e-5, 0.01,
          reason="1 ms as in the paper; give seconds, not milliseconds"),
    Range("simulation.settle_time_s", "s"),
    Range("simulation.onset_time_s", "s"),
    Range("simulation.output_rate_hz", "Hz", 100.0, lambda p: 1.0 / p.simulation.time_step_s,
          reason="at least 100 Hz, at most the simulation rate 1/simulation.time_step_s"),
    Range("variants.high_stiffness_factor", "", 1.0,
          reason="factor raising the passive joint stiffness"),
    Range("softening.tissue.*_stiffness", "N/m", lo_open=True,
          reason="the tissue's own stiffness at rest; at least the pair's contact stiffness"),
    Range("softening.*.max_loss", "fraction", 0.0, 0.95,
          reason="fraction of the stiffness that movement can take away"),
    Range("softening.tissue.critical_rms_m", "m", lo_open=True,
          reason="RMS deformation at which half the loss is reached"),
    Range("softening.muscle.critical_rms_rad", "rad", lo_open=True,
          reason="RMS rotation at which half the loss is reached"),
    Range("softening.*.time_constant_s", "s", lo_open=True,
          reason="memory of the running movement measure"),
    Range("*", ""),
)

#: The allowed values of the text parameters.
CHOICES: dict[str, tuple[str, ...]] = {"contact.model": ("point", "hydroelastic"),
                                       "simulation.design": ("implicit", "reference")}


@functools.cache
def range_of(key: str) -> Range:
    """The row of RANGES for a dotted key (without a vector index)."""
    return next(r for r in RANGES if fnmatch.fnmatchcase(key, r.pattern))


def _allowed(r: Range, params: ModelParams, applies: bool) -> str:
    """The allowed range as text, e.g. "1e-05..0.01 s", "> 0 N", ">= 1"."""
    if not applies:
        text = ">= 0"
    else:
        hi = r.hi(params) if callable(r.hi) else r.hi
        text = (f"{'>' if r.lo_open else '>='} {r.lo:g}" if hi == math.inf
                else f"{r.lo:g}..{hi:g}")
    return f"{text} {r.unit}".rstrip()


def _range_error(key: str, base: str, v: float, params: ModelParams) -> str | None:
    """The message if `v` (at `key`, whose vector is `base`) is out of its range."""
    r = range_of(base)
    group = base.rpartition(".")[0]
    applies = r.when is None or r.when[1](params, group)
    hi = r.hi(params) if callable(r.hi) else r.hi
    if v >= 0 and (not applies or (v > r.lo if r.lo_open else v >= r.lo) and v <= hi):
        return None
    allowed = _allowed(r, params, applies)
    why = f": {r.reason}" if r.reason else ""
    if v < 0:
        return f"{key} = {v!r}: must not be negative (allowed {allowed}{why})"
    if r.when is not None:
        what = "positive" if r.lo == 0 and r.lo_open and hi == math.inf else f"within {allowed}"
        return (f"{key} must be {what} when {r.when[0].format(group=group)}, got {v!r} "
                f"(allowed {allowed}{why})")
    return f"{key} = {v!r}: allowed {allowed}" + (f" ({r.reason})" if r.reason else "")


def _walk_values(obj, path=""):
    """(key, vector key, value) of every leaf value, in file order."""
    if dataclasses.is_dataclass(obj):
        for f in fields(obj):
            yield from _walk_values(getattr(obj, f.name), f"{path}.{f.name}" if path else f.name)
    elif isinstance(obj, tuple):
        for i, v in enumerate(obj):
            yield f"{path}[{i}]", path, v
    else:
        yield path, path, obj


def validate(params: ModelParams) -> ModelParams:
    """Check every value against RANGES and CHOICES (and finiteness); raise
    ParameterError naming the key, the value and the allowed range."""
    values = list(_walk_values(params))
    for key, base, v in values:
        if _is_number(v) and not math.isfinite(v):
            r = range_of(base)
            applies = r.when is None or r.when[1](params, base.rpartition(".")[0])
            raise ParameterError(f"{key}: must be finite, got {v} "
                                 f"(allowed {_allowed(r, params, applies)})")
    for key, base, v in values:
        if _is_number(v):
            msg = _range_error(key, base, v, params)
            if msg:
                raise ParameterError(msg)
        elif isinstance(v, str) and base in CHOICES and v not in CHOICES[base]:
            raise ParameterError(f"{key} = {v!r}: allowed "
                                 + " or ".join(repr(c) for c in CHOICES[base]))
    # The outputs are the discrete state sampled every k steps: an output
    # period between steps would repeat a held sample at irregular times
    # (a 2 ms step at 200 Hz: samples 1 ms stale every other time, which
    # moved a transmissibility bin by up to 35% in bench_step_accuracy).
    # The tissue's own stiffness is the contact pair's on a rigid seat and
    # more on a compliant one (the seat in series); never less.
    tissue = params.softening.tissue
    pairs = ("pelvis_pan", "thighs_pan", "lower_back_pad", "upper_back_pad")
    for pair in pairs if tissue.enabled else ():
        k_t = getattr(tissue, f"{pair}_stiffness")
        k_c = getattr(params.contact, pair).stiffness
        if k_t < k_c * (1.0 - 1e-12):
            raise ParameterError(
                f"softening.tissue.{pair}_stiffness = {k_t!r}: must be at least "
                f"contact.{pair}.stiffness ({k_c:g} N/m; the tissue alone is at least as "
                "stiff as tissue and seat in series; equal on a rigid seat)")
    sim = params.simulation
    k = 1.0 / (sim.output_rate_hz * sim.time_step_s)
    if abs(k - round(k)) > 1e-6 * k:
        raise ParameterError(
            f"simulation.output_rate_hz = {sim.output_rate_hz:g}: the output period must be a "
            f"whole number of time steps ({sim.time_step_s:g} s); it is {k:.4g} steps")
    return params


# ---------------------------------------------------------------------------
# Loading: Drake's yaml_load_typed does the typing and the merge over the defaults
# ---------------------------------------------------------------------------


def _typed(data: Mapping, *, over_defaults: bool = True) -> ModelParams:
    """`data` typed by Drake and validated: merged over the defaults, or
    (over_defaults=False, for the defaults themselves) complete."""
    from pydrake.common.yaml import yaml_load_typed

    data = _expand(data, ModelParams, "")
    defaults = _defaults() if over_defaults else None
    if over_defaults:
        data = _changes(data, _default_dict())
    text = json.dumps(data, default=repr)
    try:
        # pydrake's yaml_load_typed reads text (JSON is YAML), not a mapping.
        loaded = yaml_load_typed(schema=_schema(ModelParams), data=text, defaults=defaults,
                                 allow_schema_with_no_yaml=over_defaults)
    except (RuntimeError, ValueError, TypeError, OverflowError) as e:
        raise ParameterError(_refused_key(data, ModelParams)
                             or " ".join(str(e).split())) from None
    return validate(_freeze(loaded, ModelParams))


def default_params_path() -> Path:
    return Path(str(resources.files("ehm_drake") / "data" / "default_params.yaml"))


@functools.cache
def _defaults() -> ModelParams:
    """The packaged defaults, parsed once per process (copies are handed out)."""
    try:
        return _typed(read_params_mapping(default_params_path()), over_defaults=False)
    except ParameterError as e:
        raise ParameterError(f"{default_params_path()}: {e}") from None


@functools.cache
def _default_dict() -> dict:
    return _defaults().to_dict()


def read_params_mapping(path: Path) -> dict:
    """The raw mapping of a YAML/JSON parameter file (a fit result's
    "params" unwrapped); errors name the file, on one line."""
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"parameter file not found: {path} (or name a configuration: "
                             f"{', '.join(configuration_names())})")
    text = path.read_text()
    is_json = path.suffix.lower() == ".json"
    try:
        data = json.loads(text) if is_json else yaml.safe_load(text)
    except json.JSONDecodeError as e:
        raise ParameterError(f"{path}: not valid JSON: {e}") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        what = ", ".join(filter(None, (getattr(e, "context", None), getattr(e, "problem", None))))
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise ParameterError(f"{path}: not valid YAML: {where}"
                             + " ".join((what or str(e)).split())) from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ParameterError(f"{path}: expected a mapping of parameter groups at top level")
    # A fit result file keeps the parameters under "params".
    if set(data) == {"params"} or ("params" in data and "ehm_drake_fit" in data):
        data = data["params"]
    return data


def params_from_dict(data: dict) -> ModelParams:
    """`data` (any subset of the keys) over the defaults, typed and validated;
    errors (ParameterError) name the key."""
    return _typed(data)


def configuration_names() -> tuple[str, ...]:
    """The packaged configurations (`ehm_drake/data/configurations`): the
    paper's car seat, the laboratory seats, the paper's linear model."""
    folder = resources.files("ehm_drake") / "data" / "configurations"
    return tuple(sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml")))


def configuration_path(name: str) -> Path:
    """The parameter file of the packaged configuration `name`."""
    if name not in configuration_names():
        raise ParameterError(f"unknown configuration {name!r}; choose from "
                             f"{', '.join(configuration_names())}")
    return Path(str(resources.files("ehm_drake") / "data" / "configurations" / f"{name}.yaml"))


def resolve_params_path(path: str | Path) -> Path:
    """`path` if it is a file, else the packaged configuration of that name
    (``rigid_seat``, ...); a one-line error otherwise."""
    p = Path(path)
    if p.is_file() or str(path) not in configuration_names():
        return p
    return configuration_path(str(path))


def load_params(path: str | Path | None = None) -> ModelParams:
    """Default parameters, or those of the YAML/JSON file at `path` (or of the
    packaged configuration of that name, `configuration_names`) merged over
    the defaults.  Errors name the file and the key."""
    if path is None:
        return _defaults().copy()
    path = resolve_params_path(path)
    data = read_params_mapping(Path(path))
    try:
        return params_from_dict(data)
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


#: Time step of the reference design (the paper's 1 ms).
REFERENCE_TIME_STEP_S = 0.001


#: Time step of the implicit design, chosen by accuracy: its linearized
#: transmissibility is within 0.34% median, 4.3% worst bin of its converged
#: step at 5 ms (docs/designs.md, `tests/test_implicit_design.py`).  A
#: body or variant whose springs need less gets less from the command line
#: (`ehm_drake.diagram.accurate_step`).
IMPLICIT_TIME_STEP_S = 0.005


def with_design(params: ModelParams, design: str | None = None,
                time_step_s: float | None = None) -> ModelParams:
    """A validated copy of `params` on `design` ("reference" or "implicit";
    None keeps the parameters') with `time_step_s` (None: the parameters'
    step if they are already on that design, else the design's own step:
    `REFERENCE_TIME_STEP_S` or `IMPLICIT_TIME_STEP_S`)."""
    p = params.copy()
    if design is not None:
        if design not in CHOICES["simulation.design"]:
            raise ParameterError(f"simulation.design: {design!r} is not one of "
                                 f"{', '.join(CHOICES['simulation.design'])}")
        if design != p.simulation.design and time_step_s is None:
            time_step_s = (IMPLICIT_TIME_STEP_S if design == "implicit"
                           else REFERENCE_TIME_STEP_S)
        p.simulation.design = design
    if time_step_s is not None:
        p.simulation.time_step_s = float(time_step_s)
    return validate(p)


#: The design the commands run when neither ``--design`` nor the parameter
#: file names one: the implicit design at its accurate step (about three
#: times faster than the paper's design, and nearer the converged response:
#: docs/designs.md).  `load_params()` itself keeps the parameter file's
#: design (the paper's reference design in the packaged defaults).
COMMAND_DESIGN = "implicit"


#: The ``simulation`` keys that choose how a model is stepped: a file (or a
#: sweep spec) that states one keeps its design (`names_stepping`).
STEPPING_KEYS = ("design", "time_step_s")


def names_stepping(path: str | Path | None) -> bool:
    """Whether the parameter file at `path` states ``simulation.design`` or
    ``simulation.time_step_s`` (None: the packaged defaults, which the
    commands do not count as a choice): a step chosen for one design is
    kept on it."""
    if path is None:
        return False
    data = read_params_mapping(resolve_params_path(path))
    sim = data.get("simulation")
    return isinstance(sim, dict) and any(k in sim for k in STEPPING_KEYS)


def command_design(path: str | Path | None, design: str | None) -> str | None:
    """The design a command runs: `design` (``--design``) when given, else
    the parameter file's when it states its design or step (None: keep
    them), else `COMMAND_DESIGN`."""
    if design is not None or names_stepping(path):
        return design
    return COMMAND_DESIGN


def reference_design(params: ModelParams) -> ModelParams:
    """A copy of `params` on the reference design: spherical joints with the
    feedback explicit, at the paper's 1 ms step (the accuracy reference of
    the implicit design, `bench/bench_step_accuracy.py`)."""
    p = params.copy()
    p.simulation.design = "reference"
    p.simulation.time_step_s = REFERENCE_TIME_STEP_S
    return p


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
