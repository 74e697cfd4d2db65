"""Independent realities: seated-human simulations that are not the EHM model.

The gap diagnosis (`ehm_drake.gap`) must work on data from bodies that are not
the model's own family, as real subjects are not.  A *reality* is such a body:
a seated-human simulation written separately from the EHM plant (it imports
nothing of `ehm_drake.model`, `ehm_drake.systems`, `ehm_drake.diagram`,
`ehm_drake.simulation` or `ehm_drake.params`), with its own structure
(segmentation, joint, contact and controller laws), its own parameters from
its own sources, its own subject scatter, and its own implementation of the
eight candidate effects of `ehm_drake.gap.library.effects` (same names and meaning,
each mapped from a strength in [0, 1] to its own plausible range).

What a reality shares with the rest of the package is only the lab around
the body: the seat excitation (`ehm_drake.signals.SeatSignal`), the channel
convention below and, in `ehm_drake.gap.lab.synth`, the measurement chain (sensor
noise, H1 processing).

Channel convention (what a motion-capture lab reports, as in
`ehm_drake.analysis.formats`): for the segments pelvis, trunk (T8), head,
knee_l and knee_r, translations x, y, z (m) and rotations roll, pitch, yaw
(deg, about the seat's x, y, z), relative to the settled pose, on axes
aligned with the seat (x forward, y left, z up).  Translations are absolute:
the body's motion relative to the seat plus the seat's own displacement, so a
body moving rigidly with the seat has transmissibility 1.

A reality is a subclass of `Reality` registered with `register_reality`;
``ehm-drake synth --reality NAME`` and ``ehm-drake blind --reality NAME`` use
it.  The name ``ehm`` stands for the model itself (the default).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

#: The segments and degrees of freedom of the channels, in this order.
SEGMENTS = ("pelvis", "trunk", "head", "knee_l", "knee_r")
DOFS = ("x", "y", "z", "roll", "pitch", "yaw")
CHANNEL_NAMES = tuple(f"{s}_{d}" for s in SEGMENTS for d in DOFS)

#: The model itself (``ehm_drake.gap.lab.synth``'s own simulation).
MODEL_REALITY = "ehm"


class RealityError(ValueError):
    """A bad request to a reality (unknown name, effect or strength)."""


@dataclass
class RealityRecord:
    """One simulated test, noise-free, before the lab's measurement chain.

    t : (n,) s, uniformly sampled, starting anywhere.
    seat_acc : (n, 3) seat acceleration in m/s^2 (x, y, z of the seat).
    channels : {name: (n,) array} for every name of CHANNEL_NAMES, m or deg.
    real_time_factor : simulated time over wall time of the run.
    """

    t: np.ndarray
    seat_acc: np.ndarray
    channels: dict[str, np.ndarray]
    real_time_factor: float = float("nan")
    meta: dict[str, Any] = field(default_factory=dict)

    def check(self, who: str) -> None:
        """Shapes, names and finiteness (a reality that blew up says so)."""
        n = len(self.t)
        if self.seat_acc.shape != (n, 3):
            raise RealityError(f"{who}: seat_acc has shape {self.seat_acc.shape}, expected "
                               f"({n}, 3)")
        missing = [c for c in CHANNEL_NAMES if c not in self.channels]
        if missing:
            raise RealityError(f"{who}: missing channels {', '.join(missing)}")
        for name in CHANNEL_NAMES:
            x = np.asarray(self.channels[name])
            if x.shape != (n,):
                raise RealityError(f"{who}: channel {name} has shape {x.shape}, expected ({n},)")
            if not np.all(np.isfinite(x)):
                k = int(np.argwhere(~np.isfinite(x))[0, 0])
                raise RealityError(f"{who}: channel {name} is not finite from t = "
                                   f"{self.t[k]:.3f} s (the simulation diverged)")


class Reality:
    """A seated-human simulation that is not the EHM model.

    Subclasses set the class attributes and implement the methods.
    Everything a method returns must be picklable (tests run in worker
    processes) and deterministic given its arguments (same seed, same bytes).
    """

    #: Registry name (``--reality NAME``).
    name: ClassVar[str] = ""
    #: One line: what kind of body this is.
    description: ClassVar[str] = ""
    #: Where its structure and parameters come from (citations).
    sources: ClassVar[tuple[str, ...]] = ()
    #: Simulation time step of the seat signal it takes, s.
    time_step: ClassVar[float] = 1e-3

    def subject(self, seed: int) -> dict[str, Any]:
        """A seeded virtual subject (the reality's own inter-subject scatter),
        as JSON-able data: it goes to the key file, never to the data."""
        raise NotImplementedError

    def nominal_subject(self) -> dict[str, Any]:
        """The reality's unscattered subject, as `subject` gives it."""
        raise NotImplementedError

    def effect_values(self, name: str, strength: float) -> dict[str, float]:
        """The reality's own parameters of candidate effect `name` at
        `strength` in [0, 1] of its plausible range (0 = off)."""
        raise NotImplementedError

    def effect_names(self) -> tuple[str, ...]:
        """The candidate effects this reality implements (the own family's
        `ehm_drake.gap.library.effects.EFFECT_NAMES`, or a subset)."""
        raise NotImplementedError

    def prepare(self, subject: dict[str, Any], effects: dict[str, dict[str, float]]) -> Any:
        """Whatever the tests of one subject share (e.g. the settled state),
        picklable.  `effects` maps effect names to `effect_values`."""
        raise NotImplementedError

    def run_test(self, prepared: Any, signal) -> RealityRecord:
        """Play the seat signal (`ehm_drake.signals.SeatSignal` at
        `time_step`, with its settle and onset parts) and return the record
        of its steady part (t >= signal.steady_start)."""
        raise NotImplementedError


_REGISTRY: dict[str, type[Reality]] = {}
#: Modules that register the shipped realities (imported on first lookup).
_MODULES: tuple[str, ...] = ("ehm_drake.realities.lumped", "ehm_drake.realities.spine5")


def register_reality(cls: type[Reality]) -> type[Reality]:
    """Class decorator: make `cls` available by its name."""
    if not cls.name or cls.name == MODEL_REALITY:
        raise ValueError(f"a reality needs a name other than {MODEL_REALITY!r}")
    _REGISTRY[cls.name] = cls
    return cls


def _load_shipped() -> None:
    for m in _MODULES:
        importlib.import_module(m)


def reality_names() -> tuple[str, ...]:
    """``ehm`` (the model itself) and the registered realities."""
    _load_shipped()
    return (MODEL_REALITY, *sorted(_REGISTRY))


def get_reality(name: str) -> Reality:
    """An instance of the reality called `name` (not ``ehm``)."""
    _load_shipped()
    if name not in _REGISTRY:
        raise RealityError(f"unknown reality {name!r}; choose from "
                           f"{', '.join(reality_names())}")
    return _REGISTRY[name]()
