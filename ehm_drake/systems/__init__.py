"""LeafSystems of the model: joints (passive, PID), head-in-space, seat
(inertial load, shear restraints), measurements; and the excitation, which
is built from Drake's C++ primitives (`excitation.add_seat_excitation`).

Conventions shared by the systems here:

* The dynamic systems are template systems (`TemplateSystem`) instantiated for float and
  AutoDiffXd (`SCALARS`), so the diagram converts to AutoDiffXd for
  linearization.  Symbolic Expression is left out on purpose: with it, Drake
  probes every output symbolically at Build() to find feedthrough, which
  costs seconds and tells nothing the port declarations don't.
* Force-producing systems take the plant state [q; v] as input and output
  generalized forces (nv), which one Adder sums into the plant.  Where they
  need kinematics they evaluate it in C++ on a scratch context of the plant
  (`PlantScratch`, one per plant shared by its systems, so the kinematics
  are computed once per state): one call returns a Jacobian, where reading
  the plant's pose ports from Python would convert every body's pose.  In
  profiling this made the Python side of a time step 4x cheaper.  The
  systems are not thread-safe while stepping (the scratch context is shared
  state); parallel studies use processes.
"""

from __future__ import annotations

import sys
from collections import OrderedDict

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common import cpp_template as _cpp_template
from pydrake.systems.scalar_conversion import TemplateSystem

SCALARS = (float, AutoDiffXd)


def _module_of_frame(frame: int = 2):
    """What pydrake's `cpp_template._get_module_from_stack` returns (the
    module of the frame `frame` levels up), from the frame's globals instead
    of `inspect.stack()`, which reads the source file of every frame on the
    stack: each instantiation of a `TemplateSystem` (for float at import,
    for AutoDiffXd at a linearization) makes two `TemplateMethod` objects that ask
    for it, 25-60 ms each, 0.7 s of importing the systems."""
    f = sys._getframe(frame)
    module = sys.modules.get(f.f_globals.get("__name__"))
    return module if module is not None else _module_from_stack(frame + 1)


_module_from_stack = getattr(_cpp_template, "_get_module_from_stack", None)
if _module_from_stack is not None:
    _cpp_template._get_module_from_stack = _module_of_frame


def define_system(name: str, module: str):
    """`TemplateSystem.define(name, T_list=SCALARS)` for a system of module
    `module` (its ``__name__``), with the scope given: without it pydrake
    finds the module through `inspect.stack()`, which reads the source of
    every frame on the stack (15-55 ms per system at import, most of the
    systems' import time)."""
    return TemplateSystem.define(name, T_list=SCALARS, scope=sys.modules[module])

_converted_plants: dict = {}
#: (plant id, float) -> (plant, its shared scratch context, [the bytes of the
#: state it holds, what the systems computed there and share]), the most
#: recently built plants only (the systems keep their
#: context; the plant is kept so that its id is not reused meanwhile).
_shared_contexts: OrderedDict = OrderedDict()
_SHARED_CONTEXTS_KEPT = 8


class PlantScratch:
    """A plant of the system's scalar type and a scratch context for it.

    For float, the systems of one plant share one scratch context, and
    `set_state` leaves it alone when the state is the one it holds: the
    plant's kinematics are then computed once per state for all of them
    (in profiling, the force systems and the measurements each recomputed
    them every step)."""

    def __init__(self, plant, T):
        key = (id(plant), T)
        if T is float:
            self.plant = plant
            if key not in _shared_contexts:
                _shared_contexts[key] = (plant, plant.CreateDefaultContext(), [None, {}])
                while len(_shared_contexts) > _SHARED_CONTEXTS_KEPT:
                    _shared_contexts.popitem(last=False)
            _shared_contexts.move_to_end(key)
            _, self.context, self._held = _shared_contexts[key]
        else:
            if key not in _converted_plants:
                _converted_plants[key] = (plant, plant.ToScalarType[T]())
            self.plant = _converted_plants[key][1]
            self.context = self.plant.CreateDefaultContext()
            self._held = None

    def set_state(self, x):
        """The scratch context at plant state x."""
        if self._held is None:
            self.plant.SetPositionsAndVelocities(self.context, x)
            return self.context
        key = np.ascontiguousarray(x, float).tobytes()
        if key != self._held[0]:
            self.plant.SetPositionsAndVelocities(self.context, x)
            self._held[0] = key
            self._held[1].clear()
        return self.context

    def share(self, name: str, value) -> None:
        """Leave `value` for the other systems of this plant, valid while
        the scratch context holds the state of the last `set_state` (float
        only; AutoDiffXd contexts are not shared)."""
        if self._held is not None:
            self._held[1][name] = value

    def shared(self, name: str):
        """What a system of this plant left under `name` (`share`) at the
        state of the last `set_state`, or None: call `set_state` first."""
        return None if self._held is None else self._held[1].get(name)
