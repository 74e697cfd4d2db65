"""LeafSystems of the model: joints (passive, PID), head-in-space, seat
(inertial load, shear restraints), excitation, measurements.

Conventions shared by the systems here:

* The dynamic systems are `TemplateSystem`s instantiated for float and
  AutoDiffXd (`SCALARS`), so the diagram converts to AutoDiffXd for
  linearization.  Symbolic Expression is left out on purpose: with it, Drake
  probes every output symbolically at Build() to find feedthrough, which
  costs seconds and tells nothing the port declarations don't.
* Force-producing systems take the plant state [q; v] as input and output
  generalized forces (nv), which one Adder sums into the plant.  Where they
  need kinematics they evaluate it in C++ on a private scratch context of
  the plant (`PlantScratch`): one call returns a Jacobian, where reading the
  plant's pose ports from Python would convert every body's pose.  In
  profiling this made the Python side of a time step 4x cheaper.  A system
  is not thread-safe while stepping (its scratch context is shared state);
  parallel studies use processes.
"""

from __future__ import annotations

from pydrake.autodiffutils import AutoDiffXd

SCALARS = (float, AutoDiffXd)

_converted_plants: dict = {}


class PlantScratch:
    """A plant of the system's scalar type and a scratch context for it."""

    def __init__(self, plant, T):
        if T is float:
            self.plant = plant
        else:
            key = (id(plant), T)
            if key not in _converted_plants:
                _converted_plants[key] = (plant, plant.ToScalarType[T]())
            self.plant = _converted_plants[key][1]
        self.context = self.plant.CreateDefaultContext()

    def set_state(self, x):
        self.plant.SetPositionsAndVelocities(self.context, x)
        return self.context
