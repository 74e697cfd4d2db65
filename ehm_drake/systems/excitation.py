"""The seat excitation: plays a `SeatSignal` (see ehm_drake.signals).

Built from Drake's C++ primitives, not a Python system: a
`TrajectorySource` holding the signal's samples (a zero-order hold) and a
`Demultiplexer` into ``seat_acceleration``, ``seat_velocity`` and
``seat_displacement`` (3 each, SI, seat axes).  Over [t_k, t_k + h) they
give sample k = floor(t/h + 1e-6), the one the discrete plant uses
(`SeatSignal.sample_index`; the hold's breaks sit at (k - 1e-6) h).  As a
Python system its two outputs read every step cost about 12 us of a 5 ms
step.  The hold is a B-spline of order 1, whose control points
are the samples themselves: a `PiecewisePolynomial` zero-order hold gives
the same values but keeps a polynomial object per sample and axis (120 MB
for 65 s at 1 ms, against 13 MB)."""

from __future__ import annotations

import numpy as np
from pydrake.math import BsplineBasis
from pydrake.systems.primitives import Demultiplexer, TrajectorySource
from pydrake.trajectories import BsplineTrajectory

from ..signals import SeatSignal

#: The excitation's outputs, in the order of the held vector.
OUTPUTS = ("seat_acceleration", "seat_velocity", "seat_displacement")


def add_seat_excitation(builder, signal: SeatSignal, name: str = "seat_excitation") -> dict:
    """Add the systems playing `signal` to `builder` (the source named
    `name`, its demultiplexer ``<name>_axes``); returns {output name: output
    port} for `OUTPUTS`."""
    samples = np.hstack([signal.acceleration, signal.velocity, signal.displacement])
    n, h = signal.num_samples, signal.time_step
    breaks = (np.arange(n + 1) - 1e-6) * h
    hold = BsplineTrajectory(BsplineBasis(1, breaks), samples.T.copy())
    source = builder.AddNamedSystem(name, TrajectorySource(hold))
    axes = builder.AddNamedSystem(f"{name}_axes", Demultiplexer([3] * len(OUTPUTS)))
    builder.Connect(source.get_output_port(), axes.get_input_port())
    return {out: axes.get_output_port(i) for i, out in enumerate(OUTPUTS)}
