"""Model extensions: the one interface through which an optional extension
of the seated-human model (the gap diagnosis' candidate effects) adds what
it needs to the plant, the diagram and the simulation protocol.

The core (`ehm_drake.model.plant.add_seated_human`,
`ehm_drake.diagram.build_diagram`, `ehm_drake.simulation`) takes the
extensions as a mapping {name: {parameter: value}}, resolves the names
through the registry below and calls the hooks of each active extension in
registration order; it never names an extension.  Each extension is a
subclass of `ModelExtension` that overrides only the hooks it needs (the
defaults do nothing):

plant (`add_seated_human`)
    `body_options` (keyword arguments of `build_body`, e.g. extra body
    segments), `modify_body` (e.g. seat geometry changes), `seat_options`
    (keyword arguments of `seat_sdf`, e.g. a sprung seat pan),
    `add_plant_elements` (force elements, joint damping, frames: after the
    models are loaded, before the plant is finalized).
diagram (`build_diagram`)
    `restraint_options` (keyword arguments of
    `ehm_drake.systems.seat.restraint_parameters`: contact-gated parts,
    cubic normal stiffening, friction), `add_force_systems` (LeafSystems
    whose ``generalized_force`` output joins the applied generalized force;
    their ``state`` input gets the plant state), `transform_feedback` (the
    controllers' view of the body, e.g. a transport delay; not called when
    the feedback is cut open).
simulation (`ehm_drake.simulation`)
    `in_equilibrium_model` (False: left out of the model whose static
    equilibrium is solved, see `equilibrium_effects`), `initial_state` (the
    extension's own states at rest, from a state of the model without
    them), `start_run` (its states at the start of a run with a signal).

Why here.  The interface is the lowest module that the plant, the diagram
and the simulation all depend on, so none of them imports upwards (before,
the plant and the diagram imported `ehm_drake.gap.library.effects` inside their
functions): it imports nothing of the project (the types in the hooks'
signatures are for documentation only).  The implementations belong to the
gap diagnosis (`ehm_drake.gap.library.effects`: each effect's hooks next to its
parameters and plausible range) and register themselves when that module
is imported.  The package's ``__init__``, above both layers, imports it,
so the candidate effects resolve wherever the model is built; that module
stays cheap to import (it loads Drake only inside its hooks).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

if TYPE_CHECKING:  # pragma: no cover - annotations only
    import numpy as np


class ModelExtension:
    """An optional extension of the model, with its parameter values.

    Subclasses set `name`, register with `register_extension` and override
    the hooks they need; every hook's default leaves the model unchanged.
    An instance holds the validated parameter values (`values`) and no
    other state: the hooks may be called for several models.
    """

    #: Registry key (the name in an `effects` mapping).
    name: ClassVar[str] = ""
    #: False: the extension is left out of the model whose static
    #: equilibrium (the discrete fixed point) is solved, and out of the
    #: cut-open linearization (e.g. a feedback delay: its buffer holds the
    #: plant state at rest; `initial_state` fills it).
    in_equilibrium_model: ClassVar[bool] = True

    def __init__(self, values: Mapping[str, float]):
        self.values = dict(values)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.values!r})"

    @classmethod
    def validate(cls, values: Mapping[str, Any]) -> dict[str, float]:
        """The complete parameter values (defaults filled) as floats, or
        ValueError."""
        return {k: float(v) for k, v in values.items()}

    # -- plant (add_seated_human) ------------------------------------------------------

    def body_options(self) -> dict:
        """Keyword arguments for `ehm_drake.model.anthropometry.build_body`."""
        return {}

    def modify_body(self, body) -> None:
        """Change the built `Body` (segments, seat geometry) in place."""

    def seat_options(self) -> dict:
        """Keyword arguments for `ehm_drake.model.sdf_writer.seat_sdf`."""
        return {}

    def add_plant_elements(self, plant, human, seat, body) -> None:
        """Add force elements, frames, joint damping to the plant (models
        `human` and `seat` loaded, contact set, not yet finalized)."""

    # -- diagram (build_diagram) -------------------------------------------------------

    def restraint_options(self, params, points) -> dict:
        """Keyword arguments for `restraint_parameters(params, points, ...)`
        (``gated_parts``, ``cubic``, ``friction``); two extensions may not
        set the same one."""
        return {}

    def add_force_systems(self, parts: DiagramParts) -> list:
        """Add LeafSystems (with `parts.add_system`) whose output port
        ``generalized_force`` is summed into the plant's applied generalized
        force and whose input port ``state`` the core connects to the plant
        state; connect their other inputs here.  Returns the systems."""
        return []

    def transform_feedback(self, parts: DiagramParts, feedback):
        """The output port the PID and head-in-space controllers read
        (plant [q; v]), given the one they would read (`feedback`)."""
        return feedback

    # -- simulation --------------------------------------------------------------------

    def initial_state(self, model, smap, x: np.ndarray, x_plant: np.ndarray) -> None:
        """Fill, in the stacked state `x` of `model` (see
        `ehm_drake.simulation.StateMap` `smap`), the states this extension
        adds and a model without it lacks, for the body at rest in plant
        state `x_plant`."""

    def start_run(self, model, smap, x: np.ndarray, signal) -> None:
        """Set, in the stacked state `x` (from a settled state), the
        extension's states at the start of a run playing `signal`."""


@dataclass
class DiagramParts:
    """What `build_diagram` hands to the diagram hooks."""

    builder: Any  # DiagramBuilder
    hp: Any  # HumanPlant
    params: Any  # ModelParams (variant applied)
    time_step: float
    state: Any  # OutputPort: plant [q; v]
    seat_acceleration: Any  # OutputPort (3)
    seat_displacement: Any  # OutputPort (3)
    systems: dict  # name -> system, the diagram's handles (EhmDiagram.systems)

    def add_system(self, name: str, system):
        """Add `system` to the diagram under `name` and record its handle."""
        s = self.builder.AddNamedSystem(name, system)
        self.systems[name] = s
        return s


# ---------------------------------------------------------------------------
# Registry
# ---------------------------------------------------------------------------

_REGISTRY: dict[str, type[ModelExtension]] = {}


def register_extension(cls: type[ModelExtension]) -> type[ModelExtension]:
    """Register an extension class under `cls.name` (usable as a class
    decorator).  The order of registration is the order the hooks run in."""
    if not cls.name:
        raise ValueError(f"{cls.__name__} has no name")
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise ValueError(f"model extension {cls.name!r} is registered twice")
    _REGISTRY[cls.name] = cls
    return cls


def extension_names() -> tuple[str, ...]:
    """The registered extensions, in registration order."""
    return tuple(_REGISTRY)


def _extension_class(name: str) -> type[ModelExtension]:
    if name not in _REGISTRY:
        raise ValueError(f"unknown effect {name!r}; choose from {', '.join(_REGISTRY)}")
    return _REGISTRY[name]


def validate_extensions(effects: Mapping | None) -> dict:
    """Check an {name: {parameter: value}} mapping (registered names, each
    extension's `validate`); returns it with every value filled in, as
    floats, in the given order."""
    return {name: _extension_class(name).validate(vals)
            for name, vals in (effects or {}).items()}


def resolve_extensions(effects: Mapping | None) -> tuple[ModelExtension, ...]:
    """The extension objects of a validated mapping, in registration order."""
    effects = effects or {}
    for name in effects:
        _extension_class(name)
    return tuple(cls(effects[name]) for name, cls in _REGISTRY.items() if name in effects)


def equilibrium_effects(effects: Mapping | None) -> dict:
    """`effects` without the extensions left out of the static-equilibrium
    model (`ModelExtension.in_equilibrium_model`); unknown names are kept
    (validation reports them)."""
    return {k: v for k, v in (effects or {}).items()
            if k not in _REGISTRY or _REGISTRY[k].in_equilibrium_model}


def merge_options(extensions, hook: str, *args) -> dict:
    """The keyword arguments that the extensions' option hook `hook`
    returns, merged; two extensions setting the same one is an error."""
    out: dict = {}
    for ext in extensions:
        for key, value in getattr(ext, hook)(*args).items():
            if key in out:
                raise ValueError(f"model extensions both set {hook} {key!r} "
                                 f"(the second: {ext.name})")
            out[key] = value
    return out


__all__ = [
    "DiagramParts", "ModelExtension", "equilibrium_effects", "extension_names",
    "merge_options", "register_extension", "resolve_extensions", "validate_extensions",
]
