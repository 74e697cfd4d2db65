"""Where a time step of `simulate` goes: the force laws (one `ForceLaws`
system on both designs), the whole discrete update (plant contact solve +
forces + the controllers' updates), the logged outputs, and the body
channels (derived from the logged state after a run, per sample).

    python bench/bench_step_parts.py [time_step_s [design]]

Each figure is the best of five repeats of 400 evaluations at the settled
state, the state nudged before every evaluation so no cached value is
reused; CPU time of this thread (so that other processes on the machine
inflate it less than wall time); one core.  The figures are the cost of
each part evaluated alone, with the plant's kinematics recomputed for it:
in a run the systems share them (`ehm_drake.systems.PlantScratch`), and
every Python part runs slower than here, after the contact solve has
evicted its data from the CPU caches (`bench_simulate.py` gives the whole
run).
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from ehm_drake.diagram import build_diagram
from ehm_drake.params import load_params
from ehm_drake.simulation import StateMap, settle


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

    def cost(f, before=None, n=400) -> float:
        """CPU us of f() at a fresh state (after `before()`, untimed)."""
        best = np.inf
        for _ in range(5):
            total = 0.0
            for i in range(n):
                x = x0.copy()
                x[-1] += 1e-9 * (i + 1)
                plant.SetPositionsAndVelocities(pc, x)
                if before is not None:
                    before()
                t0 = time.thread_time()
                f()
                total += time.thread_time() - t0
            best = min(best, total / n)
        return best * 1e6

    def port(name, port_name):
        system = model.diagram.GetSubsystemByName(name)
        sub, p = system.GetMyContextFromRoot(ctx), system.GetOutputPort(port_name)
        return lambda: p.Eval(sub)

    design = params.simulation.design
    print(f"{design} design, time step {params.simulation.time_step_s * 1e3:g} ms; CPU us per "
          "evaluation at the settled state:")
    forces = port("force_laws", "generalized_force")
    print(f"  {'force_laws (5 laws)':26s} {cost(forces):7.1f}")
    update = lambda: model.diagram.EvalUniquePeriodicDiscreteUpdate(ctx)  # noqa: E731
    print(f"  {'whole discrete update':26s} {cost(update):7.1f}  (contact solve + forces + PID "
          "and restraint updates)")
    print(f"  {'  of which the plant':26s} {cost(update, forces):7.1f}  (forces already "
          "computed)")
    contacts = lambda: plant.get_contact_results_output_port().Eval(pc)  # noqa: E731
    print(f"  {'contact results (logged)':26s} {cost(contacts, update):7.1f}  (after the step's "
          "contact solve, which they reuse)")
    print(f"  {'seat_forces (logged)':26s} "
          f"{cost(port('seat_forces', 'seat_forces'), lambda: (update(), contacts())):7.1f}"
          "  (contact results and restraint forces computed)")
    print(f"  {'body_channels (derived)':26s} {cost(port('body_channels', 'channels')):7.1f}")
    guard = model.systems["divergence_guard"]
    guard_ctx = guard.GetMyContextFromRoot(ctx)
    print(f"  {'divergence_guard check':26s} {cost(lambda: guard._check(guard_ctx)):7.1f}"
          f"  (every {guard.PERIOD_S * 1e3:g} ms)")
    print("the plant's step alone: see bench_simulate.py (ceiling line)")


if __name__ == "__main__":
    main()
