"""What the logged outputs cost per time step: the same vibration run built
with and without the log, the seat forces and the divergence guard.

    python bench/bench_outputs_cost.py [--duration 6] [--repeats 4]
        [--design implicit|reference]

Each variant plays the same 3D random seat excitation (0.1941 m/s^2 RMS per
axis) from the settled state; the figure is the best of `repeats` runs of
CPU time of this thread per step (other processes on the machine inflate
wall time more than CPU time), one core.  Variants:

- ``full``: as `ehm_drake.simulation.vibrate` records it (seat forces,
  joint and head-in-space torques, seat motion, plant state; the channels
  derived from the logged state after the run, included in the figure);
- ``no seat forces``: the same without `SeatForces` (whose contact results
  trigger the SAP solve that the step then reuses);
- ``no log``: nothing recorded (the divergence guard still checks the
  state every 50 ms, `DivergenceGuard.PERIOD_S`);
- ``bare``: no log, no seat forces, no divergence guard: the plant, the
  force laws and the excitation alone.
"""

from __future__ import annotations

import argparse
import os
import time

from pydrake.systems.analysis import Simulator

from ehm_drake.diagram import accurate_step, build_diagram
from ehm_drake.params import load_params
from ehm_drake.signals import make_seat_signal
from ehm_drake.simulation import StateMap, set_normal_reference, settle

#: name: (the outputs logged at the output rate, `build_diagram` options).
VARIANTS = {
    "full": (True, {}),
    "no seat forces": (True, {"seat_forces": False}),
    "no log": (False, {}),
    "bare": (False, {"seat_forces": False, "guard": False}),
}


def cpu_us_per_step(params, settled, signal, log: bool, options: dict) -> float:
    period = 1.0 / params.simulation.output_rate_hz if log else None
    model = build_diagram(params, signal=signal, log_period=period, **options)
    ctx = model.diagram.CreateDefaultContext()
    StateMap(model).set(ctx, settled.state)
    set_normal_reference(model, ctx)
    ctx.SetTime(signal.settle_time)
    sim = Simulator(model.diagram, ctx)
    sim.Initialize()
    t0 = time.thread_time()
    sim.AdvanceTo(signal.duration)
    for logged in model.loggers.values():  # the channels are derived here
        logged.FindLog(ctx).data()
    return (time.thread_time() - t0) / sim.get_num_steps_taken() * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=6.0)
    ap.add_argument("--repeats", type=int, default=4)
    ap.add_argument("--design", choices=("implicit", "reference"), default="implicit")
    args = ap.parse_args()
    if not (args.duration > 0 and args.repeats >= 1):
        ap.error(f"--duration must be > 0 s and --repeats >= 1, got {args.duration} and "
                 f"{args.repeats}")
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    params = load_params()
    if args.design == "implicit":
        params = accurate_step(params)
    settled = settle(params)
    h = params.simulation.time_step_s
    signal = make_seat_signal(direction="xyz", rms=0.1941, duration=5.0 + args.duration,
                              seed=0, time_step=h)
    best = {name: float("inf") for name in VARIANTS}
    for _ in range(args.repeats):  # interleaved: the machine's drift hits every variant
        for name, (log, options) in VARIANTS.items():
            best[name] = min(best[name], cpu_us_per_step(params, settled, signal, log, options))
    print(f"{args.design} design, {h * 1e3:g} ms step, {args.duration:g} s of 3D excitation, "
          f"best of {args.repeats} (CPU us per step; real-time factor):")
    for name, us in best.items():
        print(f"  {name:15s} {us:7.0f} us  {h * 1e6 / us:5.2f}x")


if __name__ == "__main__":
    main()
