"""`SeatExcitation`: plays a `SeatSignal` (see ehm_drake.signals)."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem_

from ..signals import SeatSignal
from . import define_system


@define_system("SeatExcitation_", __name__)
def SeatExcitation_(T):
    class Impl(LeafSystem_[T]):
        """Outputs ``seat_acceleration``, ``seat_velocity``,
        ``seat_displacement`` (3 each, SI, seat axes) at the sample k =
        floor(t/h) the discrete plant uses over [t_k, t_k + h)."""

        def _construct(self, signal: SeatSignal, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._signal = signal
            for name, data in (("seat_acceleration", signal.acceleration),
                               ("seat_velocity", signal.velocity),
                               ("seat_displacement", signal.displacement)):
                self.DeclareVectorOutputPort(
                    name, 3, self._make_calc(data), prerequisites_of_calc={self.time_ticket()})

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._signal, converter=converter)

        @property
        def signal(self) -> SeatSignal:
            return self._signal

        def _make_calc(self, data: np.ndarray):
            def calc(context, output):
                t = context.get_time()
                k = self._signal.sample_index(float(t) if T is float else t.value())
                output.SetFromVector(data[k])
            return calc

    return Impl


SeatExcitation = SeatExcitation_[None]
