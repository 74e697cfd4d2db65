"""Real-time factor of `simulate`: 60 s of 3D seat excitation (0.1941 m/s^2
RMS per axis, random 0.1-12 Hz), outputs logged at 200 Hz, one core.

    python bench/bench_simulate.py [--duration 60] [--design implicit|reference]
        [--time-step S] [--output-every K]

The design and step are those `ehm-drake simulate` runs (the implicit design
at 5 ms unless ``--design reference``, the paper's 1 ms design).

Prints the settle time (static equilibrium + 5 s settling), the real-time
factor of the vibration run (simulated seconds per wall second), where a
step's time goes (`step_split`: a second run, up to 20 s, with the Python
parts timed: force laws, softening, the seat forces (derived after the run
from the logged generalized contact forces on the model's own seat; else
logged from the contact results, with the plant's contact solve that this
triggers), the divergence guard, the rest) and two
ceilings set by the plant's own discrete step (SAP contact solve, no Python
systems, no logging): the plant sitting in its settled state with the
controllers' torques frozen at their settled values, and the plant
vibrating: replaying the generalized forces that the closed loop applied
during 5 s of the same excitation (zero-order hold, a C++ source), where
SAP needs more iterations per step than at rest.  No controller or output
code can make `simulate` faster than the vibrating ceiling at this step.
It names the libraries preloaded (``LD_PRELOAD``: a faster memory allocator,
docs/guide.md "Simulation").
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator, SimulatorConfig
from pydrake.systems.framework import DiagramBuilder, EventStatus
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from ehm_drake.cli_common import preloaded_libraries
from ehm_drake.diagram import build_diagram, on_design
from ehm_drake.model.plant import add_seated_human
from ehm_drake.params import ParameterError, command_design, load_params
from ehm_drake.signals import make_seat_signal
from ehm_drake.simulation import StateMap, set_normal_reference, settle, vibrate

#: The Python parts of a step, by class: the methods that Drake calls (ports,
#: cache entries, events) whose time `step_split` books to each part.
PARTS = {
    "force laws": ("ehm_drake.systems.forces", "ForceLaws",
                   ("_calc_constants", "_calc_step", "_calc_displacements", "_update",
                    "_out_force", "_out_pid_torque", "_out_his_torque", "_out_seat_forces",
                    "_out_point_forces", "_out_normal", "_out_deflection")),
    "softening": ("ehm_drake.systems.softening", "BodySoftening",
                  ("_calc_compiled", "_calc_deformation_kin", "_calc_spring", "_calc_force",
                   "_calc_seat_forces",
                   "_calc_deformation", "_calc_rms", "_calc_loss", "_update")),
    "seat forces (logged)": ("ehm_drake.systems.outputs", "SeatForces", ("_calc",)),
    "seat forces (derived from the log)": ("ehm_drake.diagram", "_DerivedSeatForces",
                                           ("__init__",)),
    "divergence guard": ("ehm_drake.systems.outputs", "DivergenceGuard", ("_check",)),
}


class _Clock:
    """Exclusive wall time per part: a part's time less that of the parts
    called inside it (the plant's step runs inside whichever port first
    asks for it)."""

    def __init__(self):
        self.total = {}
        self._stack = []

    def timed(self, part: str, fn):
        import functools

        @functools.wraps(fn)
        def call(*args, **kwargs):
            self._stack.append(0)
            t0 = time.perf_counter_ns()
            try:
                return fn(*args, **kwargs)
            finally:
                dt = time.perf_counter_ns() - t0
                inner = self._stack.pop()
                self.total[part] = self.total.get(part, 0) + dt - inner
                if self._stack:
                    self._stack[-1] += dt
        return call


def step_split(params, settled, signal) -> dict:
    """Wall time per step (us) of each Python part of `simulate`'s run
    (`PARTS`), of the plant's contact solve where the logged seat forces
    trigger it (every logged step; the others' solve is in the rest), and
    of the rest (the plant's step elsewhere, Drake's framework: events,
    primitives, logging), from one run of `signal` with the parts' methods
    timed (about 0.3 us of timer per call is in the parts).  The parts sum
    to the run's time per step ("total")."""
    import importlib

    clock = _Clock()
    saved = []
    for part, (module, name, methods) in PARTS.items():
        cls = getattr(importlib.import_module(module), name)
        for m in methods:
            if m in vars(cls):
                saved.append((cls, m, vars(cls)[m]))
                setattr(cls, m, clock.timed(part, vars(cls)[m]))
    seat = saved_calc = None
    for cls, _, fn in saved:
        if cls.__name__ == "SeatForces":
            seat, saved_calc = cls, fn

    if seat is not None:  # the contact solve that the seat forces' input triggers
        timed_solve = clock.timed("plant's step (under the logged seat forces)",
                                  lambda self, context: self._contacts.Eval(context))
        timed_calc = clock.timed("seat forces (logged)", saved_calc)

        def calc(self, context, output):
            timed_solve(self, context)
            timed_calc(self, context, output)
        seat._calc = calc
    try:
        result = vibrate(params, settled, signal)
    finally:
        for cls, m, fn in saved:
            setattr(cls, m, fn)
    steps = round((signal.duration - signal.settle_time) / params.simulation.time_step_s)
    us = {k: v / 1e3 / steps for k, v in clock.total.items()}
    total = result.meta["wall_s"] * 1e6 / steps
    us["rest (plant's step elsewhere, framework, logging)"] = total - sum(us.values())
    us["total"] = total
    return us


def plant_only_real_time_factor(params, settled, duration: float = 5.0) -> float:
    """Real-time factor of the plant alone from the settled state, its
    applied generalized force fixed at the settled closed loop's value."""
    closed = build_diagram(params, guard=False, seat_forces=False)
    ctx = closed.diagram.CreateDefaultContext()
    StateMap(closed).set(ctx, settled.state)
    for name in ("seat_acceleration", "seat_displacement"):
        closed.diagram.GetInputPort(name).FixValue(ctx, np.zeros(3))
    tau = closed.plant.get_applied_generalized_force_input_port().Eval(
        closed.plant_context(ctx)).copy()
    builder = DiagramBuilder()
    hp = add_seated_human(builder, params)
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    pc = hp.plant.GetMyMutableContextFromRoot(root)
    hp.plant.SetPositionsAndVelocities(
        pc, closed.plant.GetPositionsAndVelocities(closed.plant_context(ctx)))
    hp.plant.get_applied_generalized_force_input_port().FixValue(pc, tau)
    sim = Simulator(diagram, root)
    sim.Initialize()
    t0 = time.perf_counter()
    sim.AdvanceTo(duration)
    return duration / (time.perf_counter() - t0)


def closed_loop_forces(params, settled, signal, duration: float):
    """(times, generalized forces (nv x N), end positions, start state) of
    the closed loop during the first `duration` s of `signal` from
    `settled`, the forces as the plant received them at each step."""
    closed = build_diagram(params, signal=signal, guard=False, seat_forces=False)
    ctx = closed.diagram.CreateDefaultContext()
    StateMap(closed).set(ctx, settled.state)
    set_normal_reference(closed, ctx)
    ctx.SetTime(signal.settle_time)
    pc = closed.plant_context(ctx)
    applied = closed.plant.get_applied_generalized_force_input_port()
    x_start = closed.plant.GetPositionsAndVelocities(pc).copy()
    times, forces = [], []

    def record(context):
        times.append(context.get_time())
        forces.append(applied.Eval(pc).copy())
        return EventStatus.Succeeded()

    sim = Simulator(closed.diagram, ctx)
    sim.set_monitor(record)
    sim.Initialize()
    sim.AdvanceTo(signal.settle_time + duration)
    return np.array(times), np.array(forces).T, closed.plant.GetPositions(pc).copy(), x_start


def replay(params, times, F, x_start, time_step: float | None = None,
           accuracy: float | None = None):
    """(real-time factor, steps, wall s, end positions) of the plant alone
    replaying the forces F recorded at `times` (`closed_loop_forces`), from
    `x_start`: on its discrete step (`time_step`, default the parameters';
    a zero-order hold, as in the closed loop), or with `time_step` 0 as a
    continuous plant on Drake's `cenic` at `accuracy` (a first-order hold)."""
    h = params.simulation.time_step_s
    p = params.copy()
    if time_step is not None:
        p.simulation.time_step_s = time_step
    builder = DiagramBuilder()
    hp = add_seated_human(builder, p)
    continuous = p.simulation.time_step_s == 0
    traj = (PiecewisePolynomial.FirstOrderHold(times, F) if continuous else
            PiecewisePolynomial.ZeroOrderHold(np.append(times, times[-1] + h),
                                              np.hstack([F, F[:, -1:]])))
    source = builder.AddSystem(TrajectorySource(traj))
    builder.Connect(source.get_output_port(), hp.plant.get_applied_generalized_force_input_port())
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    root.SetTime(times[0])
    pc = hp.plant.GetMyMutableContextFromRoot(root)
    hp.plant.SetPositionsAndVelocities(pc, x_start)
    sim = Simulator(diagram, root)
    if continuous:
        ApplySimulatorConfig(SimulatorConfig(integration_scheme="cenic", accuracy=accuracy,
                                             max_step_size=0.01, use_error_control=True), sim)
    sim.Initialize()
    t0 = time.perf_counter()
    sim.AdvanceTo(times[-1])
    wall = time.perf_counter() - t0
    steps = (sim.get_integrator().get_num_steps_taken() if continuous
             else int(round((times[-1] - times[0]) / p.simulation.time_step_s)))
    return (times[-1] - times[0]) / wall, steps, wall, hp.plant.GetPositions(pc).copy()


def plant_replay_real_time_factor(params, settled, signal, duration: float = 5.0) -> float:
    """Real-time factor of the plant alone replaying the generalized forces
    the closed loop applies during the first `duration` s of `signal`."""
    times, F, _, x_start = closed_loop_forces(params, settled, signal, duration)
    return replay(params, times, F, x_start)[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--time-step", type=float, default=None)
    ap.add_argument("--design", choices=("reference", "implicit"), default=None,
                    help="the design (default: the commands', implicit at its accurate step)")
    ap.add_argument("--output-every", type=int, default=None, metavar="K",
                    help="outputs every K steps (simulation.output_rate_hz = 1 / (K h), "
                         "exactly; default: the parameter file's rate, whose period must be a "
                         "whole number of steps: 200 Hz at 5 ms, not at 6 ms)")
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    try:  # the design and step `ehm-drake simulate` runs, with its checks
        params = on_design(load_params(), command_design(None, args.design), args.time_step,
                           output_every=args.output_every)
    except ParameterError as e:
        raise SystemExit(f"bench_simulate: {e}") from None
    s = params.simulation
    t0 = time.perf_counter()
    settled = settle(params)
    t_settle = time.perf_counter() - t0
    signal = make_seat_signal("random", "xyz", 0.1941, args.duration, 1, s.time_step_s,
                              s.settle_time_s, s.onset_time_s)
    result = vibrate(params, settled, signal)
    print(f"{s.design} design, time step {s.time_step_s * 1e3:g} ms, outputs at "
          f"{s.output_rate_hz:g} Hz")
    preloaded = preloaded_libraries()
    print(f"preloaded (LD_PRELOAD): {', '.join(preloaded)}" if preloaded
          else "memory allocator: the system's (nothing preloaded)")
    print(f"settle (equilibrium + {s.settle_time_s:g} s): {t_settle:.1f} s wall")
    print(f"vibrate {args.duration:g} s of 3D excitation: {result.meta['wall_s']:.1f} s wall, "
          f"real-time factor {result.meta['real_time_factor']:.2f}")
    print(f"  ({result.meta['wall_s'] / (args.duration / s.time_step_s) * 1e6:.0f} us per "
          "step)")
    split_s = min(args.duration, 20.0)
    split = step_split(params, settled, make_seat_signal(
        "random", "xyz", 0.1941, split_s, 1, s.time_step_s, s.settle_time_s, s.onset_time_s))
    print(f"per step, a second run of {split_s:g} s with the Python parts timed "
          f"({split['total']:.0f} us per step):")
    for part, us in split.items():
        if part != "total":
            print(f"  {part:<52} {us:6.0f} us  {100 * us / split['total']:3.0f}%")
    ceiling = plant_only_real_time_factor(params, settled)
    print(f"ceiling: the plant alone (contact solve, no controllers, no logging) runs at "
          f"{ceiling:.2f}x real time at rest ({s.time_step_s / ceiling * 1e6:.0f} us per step)")
    vibrating = plant_replay_real_time_factor(params, settled, signal)
    print(f"         and {vibrating:.2f}x vibrating, replaying the closed loop's forces "
          f"({s.time_step_s / vibrating * 1e6:.0f} us per step)")
    if "plant's step (under the logged seat forces)" not in split:
        # The plant's step is in the split's rest: what the rest holds beyond it.
        rest = split["rest (plant's step elsewhere, framework, logging)"]
        print(f"the split's rest less the plant's own vibrating step: "
              f"{rest - s.time_step_s / vibrating * 1e6:.0f} us (the framework, the log, and "
              "the plant's step slowed beside Python)")


if __name__ == "__main__":
    main()
