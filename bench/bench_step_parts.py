"""Where a time step of `simulate` goes: the cost of each force-producing
system, of the whole discrete update (plant contact solve + controllers)
and of the logged outputs (the plant's own step alone: the ceiling line of
`bench_simulate.py`).

    python bench/bench_step_parts.py [time_step_s [design]]

Each figure is the best of five repeats of 400 evaluations at the settled
state, the state nudged before every evaluation so no cached value is
reused; one core.  The real-time factor at 1 ms is 1000 us divided by the
per-step total (discrete update + framework + outputs at 200 Hz).
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from ehm_drake.diagram import build_diagram
from ehm_drake.params import load_params
from ehm_drake.simulation import StateMap, settle

FORCE_SYSTEMS = ("passive_joints", "joint_pid", "shear_restraints", "head_in_space",
                 "seat_inertial_load")


def main() -> None:
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    params = load_params()
    if len(sys.argv) > 1:
        params.simulation.time_step_s = float(sys.argv[1])
    if len(sys.argv) > 2:
        params.simulation.design = sys.argv[2]
    settled = settle(params)
    model = build_diagram(params)
    ctx = model.diagram.CreateDefaultContext()
    StateMap(model).set(ctx, settled.state)
    model.diagram.GetInputPort("seat_acceleration").FixValue(ctx, np.full(3, 0.1))
    model.diagram.GetInputPort("seat_displacement").FixValue(ctx, np.zeros(3))
    plant, pc = model.plant, model.plant.GetMyMutableContextFromRoot(ctx)
    x0 = plant.GetPositionsAndVelocities(pc)

    def cost(f, n=400) -> float:
        best = np.inf
        for _ in range(5):
            t0 = time.perf_counter()
            for i in range(n):
                x = x0.copy()
                x[-1] += 1e-9 * (i + 1)
                plant.SetPositionsAndVelocities(pc, x)
                f()
            best = min(best, (time.perf_counter() - t0) / n)
        return best * 1e6

    def port(name, port_name):
        system = model.diagram.GetSubsystemByName(name)
        sub, p = system.GetMyContextFromRoot(ctx), system.GetOutputPort(port_name)
        return lambda: p.Eval(sub)

    base = cost(lambda: None)
    print("per evaluation (us), at the settled state:")
    for name in FORCE_SYSTEMS:
        print(f"  {name:22s} {cost(port(name, 'generalized_force')) - base:7.1f}")
    forces = cost(port("generalized_force_sum", "sum")) - base
    print(f"  {'all forces (summed)':22s} {forces:7.1f}")
    update = cost(lambda: model.diagram.EvalUniquePeriodicDiscreteUpdate(ctx)) - base
    print(f"  {'whole discrete update':22s} {update:7.1f}  (contact solve + forces + PID and "
          f"restraint updates)")
    print(f"  {'body_channels (logged)':22s} {cost(port('body_channels', 'channels')) - base:7.1f}")
    print(f"  {'seat_forces (logged)':22s} {cost(port('seat_forces', 'seat_forces')) - base:7.1f}"
          "  (contact results at this state: the coming step's contact solve, which the step"
          " then reuses from the cache; not an extra cost in a run)")
    print("the plant's step alone: see bench_simulate.py (ceiling line)")


if __name__ == "__main__":
    main()
