"""Settle and vibrate: the paper's simulation protocol (Desai et al. Sec. III).

* `static_equilibrium(model)` solves for the fixed point of the discrete
  closed-loop dynamics (plant + PID integrators) with no excitation: the body
  at rest, joints at their reference angles, integrators holding the static
  joint torques.  Since the SAP contact force at rest is exactly k times the
  penetration, this is the static equilibrium of the continuous equations too.
* `settle(model)` starts from that equilibrium (the paper's restart
  technique replaces the 5 s settle of every run) and simulates the settle
  time without excitation for the requested variant: the default variant
  stays put; without integrator the body drifts (paper Fig. 5).  The settled
  state is saved and reused by later runs (`SettledState.save/load`).
* `vibrate(model, settled, signal)` plays a seat signal from the settled
  state and records the body channels, seat forces and joint torques.

A blow-up (NaN, falling through the seat, lost posture, runaway energy)
stops with `SimulationDiverged`, naming the time and the body.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator

from .analysis.formats import TimeSeriesData
from .diagram import SEAT_FORCE_NAMES, EhmDiagram, build_diagram
from .model.anthropometry import REFERENCE, BodyMeasures
from .model.extensions import equilibrium_effects
from .params import PASSIVE_GROUPS, ModelParams
from .progress import Progress
from .signals import SeatSignal, make_seat_signal
from .systems.outputs import CHANNEL_NAMES, SimulationDiverged
from .systems.rotations import rpy_from_rotation
from .systems.seat import restraint_block


class EquilibriumError(RuntimeError):
    """The static equilibrium could not be found."""


# ---------------------------------------------------------------------------
# Discrete state of the whole diagram as one vector
# ---------------------------------------------------------------------------


class StateMap:
    """The diagram's discrete state groups (plant, PID, restraints) as one
    stacked vector, in the order of the diagram's own discrete values.

    A group is named by its system; a system with several groups
    (`ForceLaws`) names each by the part it belongs to
    (`discrete_state_view(group)`, e.g. ``joint_pid``)."""

    def __init__(self, model):
        """`model`: an EhmDiagram or any Drake Diagram with discrete states."""
        self.diagram = model.diagram if isinstance(model, EhmDiagram) else model
        groups = [(s, g) for s in self.diagram.GetSystems()
                  for g in range(s.num_discrete_state_groups())]
        # Find the diagram's group order by tagging each subsystem's state.
        ctx = self.diagram.CreateDefaultContext()
        for i, (s, g) in enumerate(groups):
            sub = s.GetMyMutableContextFromRoot(ctx).get_mutable_discrete_state()
            sub.get_mutable_vector(g).SetFromVector(np.full(sub.get_vector(g).size(), i + 0.5))
        root = ctx.get_discrete_state()
        order = [int(root.get_vector(g).GetAtIndex(0)) for g in range(root.num_groups())]
        #: The owner of each group (a system, or the part of one), in order.
        self.systems = [s.discrete_state_view(g) if s.num_discrete_state_groups() > 1 else s
                        for s, g in (groups[i] for i in order)]
        self.sizes = [root.get_vector(g).size() for g in range(root.num_groups())]
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)]).astype(int)
        self.size = int(self.offsets[-1])
        self._index = {s.get_name(): g for g, s in enumerate(self.systems)}

    def slice(self, name: str) -> slice:
        g = self._index[name]
        return slice(int(self.offsets[g]), int(self.offsets[g + 1]))

    def get(self, root_context) -> np.ndarray:
        ds = root_context.get_discrete_state()
        return np.concatenate([ds.get_vector(g).CopyToVector() for g in range(ds.num_groups())])

    def transfer(self, other: StateMap, x_other: np.ndarray, x_default: np.ndarray) -> np.ndarray:
        """This map's state vector with the groups of `other`'s state
        `x_other` copied by system name; groups `other` lacks keep
        `x_default`."""
        x = np.array(x_default, float)
        for name in self._index:
            if name in other._index:
                x[self.slice(name)] = x_other[other.slice(name)]
        return x

    def set(self, root_context, x) -> None:
        ds = root_context.get_mutable_discrete_state()
        for g in range(ds.num_groups()):
            ds.get_mutable_vector(g).SetFromVector(x[self.offsets[g]:self.offsets[g + 1]])

    def step(self, root_context) -> np.ndarray:
        """The discrete update map x+ = F(x) at the current context."""
        values = self.diagram.EvalUniquePeriodicDiscreteUpdate(root_context)
        return np.concatenate([values.get_vector(g).CopyToVector()
                               for g in range(values.num_groups())])


# ---------------------------------------------------------------------------
# Settled state (restart file)
# ---------------------------------------------------------------------------


def model_fingerprint(params: ModelParams, measures: BodyMeasures, variant: str,
                      effects: dict | None = None) -> str:
    items = [params.to_dict(), [measures.mass_kg, measures.stature_m,
                                measures.resolved_sitting_height()], variant]
    if effects:
        items.append(effects)
    blob = json.dumps(items, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


@dataclass
class SettledState:
    """The state at the end of settling, and what it says about posture."""

    state: np.ndarray  # stacked discrete state (see StateMap)
    fingerprint: str
    variant: str
    summary: dict = field(default_factory=dict)
    #: Where the plant's [q; v] sits in `state`: (start, nq, nv).
    plant_layout: tuple = (0, 0, 0)
    #: The design and time step (s) it was settled on ("" and 0: not recorded).
    design: str = ""
    time_step_s: float = 0.0

    @property
    def positions(self) -> np.ndarray:
        """The plant's generalized positions q (rad, m) in the settled state."""
        start, nq, _ = self.plant_layout
        if nq == 0:
            raise ValueError("this settled state does not record the plant layout")
        return self.state[start:start + nq]

    @property
    def velocities(self) -> np.ndarray:
        start, nq, nv = self.plant_layout
        if nq == 0:
            raise ValueError("this settled state does not record the plant layout")
        return self.state[start + nq:start + nq + nv]

    def save(self, path: str | Path) -> None:
        np.savez(path, state=self.state, fingerprint=self.fingerprint, variant=self.variant,
                 summary=json.dumps(self.summary), plant_layout=np.array(self.plant_layout),
                 design=self.design, time_step_s=self.time_step_s)

    @classmethod
    def load(cls, path: str | Path) -> SettledState:
        with np.load(path, allow_pickle=False) as f:
            layout = tuple(int(v) for v in f["plant_layout"]) if "plant_layout" in f \
                else (0, 0, 0)
            return cls(f["state"], str(f["fingerprint"]), str(f["variant"]),
                       json.loads(str(f["summary"])), layout,
                       str(f["design"]) if "design" in f else "",
                       float(f["time_step_s"]) if "time_step_s" in f else 0.0)


def _fixed_inputs(model: EhmDiagram, context) -> None:
    d = model.diagram
    for name in ("seat_acceleration", "seat_displacement"):
        if d.HasInputPort(name):
            d.GetInputPort(name).FixValue(context, np.zeros(3))


def static_equilibrium(model: EhmDiagram, tol: float = 1e-7, max_iterations: int = 30,
                       seat_in: bool = True):
    """Fixed point of the discrete closed-loop dynamics without excitation.

    Unknowns: the plant positions q and the PID integrals z (v = 0); the
    equations: v+ = 0 (no motion after a step; as the net generalized force
    M v+ / h, tolerance `tol` in N or N m) and q - q_ref = 0 on the
    integrating joints (the integrators are at rest; tolerance `tol` rad).
    Newton iterations with a finite-difference Jacobian of the discrete step.

    With `seat_in`, the vertical shear of the backrest pads is relaxed as the
    body sinks into the seat (the anchors slip, as the back slides down the
    backrest when one sits down); the pan and floor restraints keep what
    balance needs.  Returns (root_context, StateMap).
    """
    if model.signal is not None:
        raise ValueError("static_equilibrium needs a diagram built without a signal")
    smap = StateMap(model)
    ctx = model.diagram.CreateDefaultContext()
    _fixed_inputs(model, ctx)
    x = smap.get(ctx)
    plant = model.plant
    nq = plant.num_positions()
    ps = smap.slice("plant")
    pid = model.systems["joint_pid"]
    zs = smap.slice("joint_pid")
    integrating = model.params.pid.integrator
    layout = model.hp.layout
    h = model.params.simulation.time_step_s
    unknown = np.r_[np.arange(ps.start, ps.start + nq),
                    np.arange(zs.start, zs.stop) if integrating else np.array([], int)]
    # Scale the residual: velocities in m/s and rad/s, joint errors in rad.
    gains = pid.GetMyContextFromRoot(ctx).get_numeric_parameter(pid.parameter_index)
    reference = gains.CopyToVector()[4 * layout.num_rotational:]

    pctx = model.plant_context(ctx)

    def residual(xv):
        # Net generalized force M (v+ - 0)/h: scaled by the inertia, the
        # Jacobian is ~ the stiffness matrix, far better conditioned than that
        # of the accelerations (tiny inertias of the neck and feet).
        smap.set(ctx, xv)
        xn = smap.step(ctx)
        r = [plant.CalcMassMatrix(pctx) @ xn[ps][nq:] / h]
        if integrating:
            r.append(xv[ps][layout.rot_q] - reference)
        return np.concatenate(r)

    restraints = model.systems["shear_restraints"]
    ss = smap.slice("shear_restraints")
    pad_z = np.array([2 * i + 1 for i, p in enumerate(restraints.points) if "pad" in p.part])

    def jacobian(x, r):
        J = np.empty((len(r), len(unknown)))
        for j, k in enumerate(unknown):
            eps = 1e-7 * max(1.0, abs(x[k]))
            xp = x.copy()
            xp[k] += eps
            J[:, j] = (residual(xp) - r) / eps
        return J

    # The Jacobian (one residual per unknown) is kept between iterations and
    # between the seating-in re-solves while its steps halve the residual
    # (chord steps); a chord step that does not is redone with a fresh
    # Jacobian, and a fresh one that does not is kept (Newton) but its
    # Jacobian is not reused (it would step back: a cycle across a kink).
    # The seating-in re-solves then cost a few residuals instead of a
    # Jacobian each (908 -> 182 residuals for the default model).
    jac = [None]

    def solve(x):
        r = residual(x)
        fresh_jacobians = 0
        while not np.max(np.abs(r)) < tol:  # (a NaN residual is not converged)
            fresh = jac[0] is None
            if fresh:
                if fresh_jacobians == max_iterations:
                    raise EquilibriumError(
                        f"static equilibrium not found in {max_iterations} Newton iterations "
                        f"(residual {np.max(np.abs(r)):.3g})")
                jac[0] = jacobian(x, r)
                fresh_jacobians += 1
            dx = np.linalg.lstsq(jac[0], -r, rcond=None)[0]
            # Damped step: never move a coordinate by more than 1 cm / 0.01 rad.
            xn = x.copy()
            xn[unknown] += min(1.0, 0.01 / max(np.max(np.abs(dx[:nq])), 1e-12)) * dx
            rn = residual(xn)
            halved = np.linalg.norm(rn) < 0.5 * np.linalg.norm(r)
            if fresh or halved:
                x, r = xn, rn
            if not halved:
                # A fresh Newton step that did not halve the residual (damped,
                # or across a contact's kink) is kept, as plain Newton does,
                # but its Jacobian is not reused.
                jac[0] = None
        return x

    # Extra normal forces about the static compression (foam stiffening, the
    # diagnosis' equivalent springs) are zero at equilibrium: solve without
    # them, then put their reference at the equilibrium compression.
    rctx = restraints.GetMyMutableContextFromRoot(ctx)
    prm = rctx.get_mutable_numeric_parameter(restraints.parameter_index)
    full = prm.CopyToVector()
    # The body's softening acts about the running means, which are set where
    # the body rests once it is found (`set_normal_reference`).
    for softening in softening_systems(model):
        softening.set_active(softening.GetMyMutableContextFromRoot(ctx), False)
    about_reference = full.copy()
    for block in ("normal_cubic_stiffness", "normal_linear_stiffness", "normal_linear_damping"):
        restraint_block(about_reference, block)[:] = 0.0
    prm.SetFromVector(about_reference)
    try:
        x0 = x.copy()
        x = solve(x)
    except EquilibriumError:
        # The SDF's pose has the body just touching the pan and floor, its
        # weight on nothing: the first Jacobian has no vertical stiffness,
        # and its least-squares step can take the body off the seat, where
        # the next ones find no support either (on the implicit design at
        # 7-8 ms steps, against the seat's half-spaces).  Start again with
        # the body lowered 5 mm into the seat, about its static compression.
        x = x0
        x[ps.start + plant.GetJointByName("pelvis_free").position_start() + 5] -= 0.005
        jac[0] = None
        x = solve(x)
    if seat_in and len(pad_z):
        # Seating-in: anchor the pads' vertical restraints where the back is,
        # re-solve, until the anchors stop moving (a contraction: the pads'
        # shear stiffness is a fraction of the seat's vertical stiffness).
        rctx = restraints.GetMyContextFromRoot(ctx)
        for _ in range(30):
            smap.set(ctx, x)
            new = restraints.axis_deflection(rctx)[pad_z]
            change = np.max(np.abs(x[ss][pad_z] - new))
            x[ss.start + pad_z] = new
            x = solve(x)
            if change < 1e-8:
                break
    smap.set(ctx, x)
    prm.SetFromVector(full)
    set_normal_reference(model, ctx)
    for softening in softening_systems(model):
        softening.set_active(softening.GetMyMutableContextFromRoot(ctx), True)
    return ctx, smap


def set_normal_reference(model: EhmDiagram, root_context) -> None:
    """Reference of the restraints' extra normal forces := the current
    normal displacement of each point, and the body's softening at rest
    there (its running means at the current deformation, no variance);
    call at rest."""
    restraints = model.systems["shear_restraints"]
    rctx = restraints.GetMyMutableContextFromRoot(root_context)
    prm = rctx.get_mutable_numeric_parameter(restraints.parameter_index)
    v = prm.CopyToVector()
    restraint_block(v, "normal_reference")[:] = restraints.normal_displacement(rctx)
    prm.SetFromVector(v)
    for softening in softening_systems(model):
        from .systems.softening import softening_initial_state

        sctx = softening.GetMyMutableContextFromRoot(root_context)
        rest = softening_initial_state(softening.elements,
                                       softening.rest_deformation(sctx))
        sctx.get_mutable_discrete_state(softening.state_index).SetFromVector(rest)


def softening_systems(model: EhmDiagram) -> list:
    """The model's softening systems (`BodySoftening`: the body's own, and
    a candidate effect's)."""
    return [s for s in model.systems.values() if hasattr(s, "rest_deformation")]


# ---------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------


@dataclass
class SimulationResult:
    """Time series of one run, SI units (rotations in rad)."""

    times: np.ndarray
    seat_acceleration: np.ndarray  # (N, 3)
    seat_displacement: np.ndarray  # (N, 3)
    channels: np.ndarray  # (N, 30), CHANNEL_NAMES; m and rad
    seat_forces: np.ndarray  # (N, 12), SEAT_FORCE_NAMES; N
    joint_torques: np.ndarray  # (N, 24); N m
    his_torque: np.ndarray  # (N, 3); N m
    joint_names: tuple[str, ...]
    meta: dict = field(default_factory=dict)
    #: (N, 31) plant generalized positions q (for 3D replay), in S.
    positions: np.ndarray | None = None

    channel_names = CHANNEL_NAMES
    seat_force_names = SEAT_FORCE_NAMES

    def channel(self, segment: str, dof: str) -> np.ndarray:
        return self.channels[:, CHANNEL_NAMES.index(f"{segment}_{dof}")]

    def after(self, t0: float) -> SimulationResult:
        """The part of the run from time t0 on."""
        k = self.times >= t0 - 1e-9
        return SimulationResult(self.times[k], self.seat_acceleration[k],
                                self.seat_displacement[k], self.channels[k],
                                self.seat_forces[k], self.joint_torques[k],
                                self.his_torque[k], self.joint_names, dict(self.meta),
                                None if self.positions is None else self.positions[k])

    @property
    def sample_rate(self) -> float:
        return 1.0 / float(np.median(np.diff(self.times)))

    def to_timeseries(self) -> TimeSeriesData:
        """The run in the measured-data format (channels in m and deg), with
        the excitation direction and level as metadata."""
        rot = np.array([name.split("_")[-1] in ("roll", "pitch", "yaw")
                        for name in CHANNEL_NAMES])
        ch = self.channels.copy()
        ch[:, rot] = np.degrees(ch[:, rot])
        sig = self.meta.get("signal", {})
        meta = {k: sig[k] for k in ("direction",) if k in sig}
        if "rms" in sig and sig.get("kind") != "csv":
            meta["level_rms"] = sig["rms"]
        return TimeSeriesData(self.times, self.seat_acceleration,
                              dict(zip(CHANNEL_NAMES, ch.T, strict=True)), meta)

    def pan_force(self) -> np.ndarray:
        """(N, 3) force of the seat pan on the body, N."""
        i = SEAT_FORCE_NAMES.index("pan_fx")
        return self.seat_forces[:, i:i + 3]

    def write_csv(self, directory: str | Path) -> list[Path]:
        """timeseries.csv (lab format), seat_forces.csv, joint_torques.csv."""
        directory = Path(directory)
        paths = [directory / "timeseries.csv", directory / "seat_forces.csv",
                 directory / "joint_torques.csv"]
        self.to_timeseries().to_csv(paths[0])
        _write_csv(paths[1], ["t", *SEAT_FORCE_NAMES],
                   np.column_stack([self.times, self.seat_forces]))
        _write_csv(paths[2], ["t", *[f"torque_{n}" for n in self.joint_names],
                              "his_tx", "his_ty", "his_tz"],
                   np.column_stack([self.times, self.joint_torques, self.his_torque]))
        return paths


def _write_csv(path: Path, names, data) -> None:
    with open(path, "w") as f:
        f.write(",".join(names) + "\n")
        np.savetxt(f, data, delimiter=",", fmt="%.9g")


# ---------------------------------------------------------------------------
# Running
# ---------------------------------------------------------------------------


def _advance(simulator: Simulator, t_end: float, progress: Progress | None,
             guard=None, chunk: float = 0.25) -> None:
    """Advance in chunks, updating the progress display between chunks (a
    Ctrl-C lands between or inside chunks and propagates to the caller).
    When a time step fails inside Drake, the model's divergence `guard`
    (if any) checks the last completed state: a blow-up that grew past
    Drake's solvers between two of its checks is reported as
    `SimulationDiverged` too (`DivergenceGuard.check_after_failure`)."""
    t0 = t = simulator.get_context().get_time()
    while t < t_end - 1e-12:
        t = min(t + chunk, t_end)
        try:
            simulator.AdvanceTo(t)
        except RuntimeError as e:
            if guard is not None and not isinstance(e, SimulationDiverged):
                guard.check_after_failure(simulator.get_context(), e)
            raise
        if progress is not None:
            progress.update(t - t0)


def _simulator(model: EhmDiagram, root_context) -> Simulator:
    simulator = Simulator(model.diagram, root_context)
    simulator.Initialize()
    return simulator


def posture_summary(model: EhmDiagram, root_context) -> dict:
    """Posture: joint errors against the reference per group (deg), head
    orientation in space (deg), trunk (T8) forward displacement from the
    reference posture (m), seat normal forces (N)."""
    plant = model.plant
    pctx = model.plant_context(root_context)
    q = plant.GetPositions(pctx)
    layout = model.hp.layout
    err = np.degrees(q[layout.rot_q])
    groups = {}
    for g in PASSIVE_GROUPS:
        sel = [i for i, gg in enumerate(layout.groups) if gg == g]
        groups[g] = float(np.max(np.abs(err[sel])))
    head = plant.GetBodyByName("head", model.hp.human)
    R = plant.EvalBodyPoseInWorld(pctx, head).rotation().matrix()
    head_rpy = np.degrees(rpy_from_rotation(R))
    trunk = plant.GetFrameByName("trunk_marker", model.hp.human)
    p_T8 = trunk.CalcPoseInWorld(pctx).translation()
    forces = model.diagram.GetOutputPort("seat_forces").Eval(root_context).reshape(-1, 3)
    parts = dict(zip(("pan", "floor", "lower_pad", "upper_pad"), forces, strict=True))
    t8_ref = model.hp.body.markers["trunk"][1]
    return {
        "settle_posture_error_deg": groups,
        "max_joint_error_deg": float(np.max(np.abs(err))),
        "head_pitch_deg": float(head_rpy[1]),
        "head_orientation_rpy_deg": head_rpy.tolist(),
        "trunk_T8_forward_drift_m": float(p_T8[0] - t8_ref[0]),
        "backrest_force_n": {
            "lower_pad": float(parts["lower_pad"][0]),
            "upper_pad": float(parts["upper_pad"][0]),
            "total": float(parts["lower_pad"][0] + parts["upper_pad"][0]),
        },
        "pan_force_n": float(parts["pan"][2]),
        "floor_force_n": float(parts["floor"][2]),
        "back_in_contact": bool(parts["lower_pad"][0] > 1.0 and parts["upper_pad"][0] > 1.0),
    }


def initial_state(model: EhmDiagram, x_plant_and_controllers: np.ndarray,
                  source: StateMap) -> np.ndarray:
    """The full state of `model` from a state of a diagram of the same plant
    without the extensions left out of the static equilibrium (`source`):
    their states as each extension's `initial_state` sets them for the body
    at rest (e.g. a delay buffer holding the plant state throughout), other
    extra groups their defaults."""
    vmap = StateMap(model)
    ctx = model.diagram.CreateDefaultContext()
    x = vmap.transfer(source, x_plant_and_controllers, vmap.get(ctx))
    xp = x_plant_and_controllers[source.slice("plant")]
    for ext in model.extensions:
        ext.initial_state(model, vmap, x, xp)
    return x


def settle(params: ModelParams, measures: BodyMeasures = REFERENCE,
           variant: str = "default", settle_time: float | None = None,
           progress: bool = False, effects: dict | None = None) -> SettledState:
    """Settle the body on the seat for `variant` (see module doc), with the
    candidate `effects` (see `ehm_drake.gap.library.effects`) if given."""
    eq_model = build_diagram(params, measures, None, "default", guard=False,
                             effects=equilibrium_effects(effects))
    ctx, smap = static_equilibrium(eq_model)
    x_eq = smap.get(ctx)
    T = params.simulation.settle_time_s if settle_time is None else settle_time
    model = build_diagram(params, measures, None, variant, effects=effects)
    vctx = model.diagram.CreateDefaultContext()
    _fixed_inputs(model, vctx)
    vmap = StateMap(model)
    x0 = initial_state(model, x_eq, smap)
    if variant != "default":
        # Same equilibrium pose; without integrator there is no integral torque.
        x0[vmap.slice("joint_pid")] = 0.0
    vmap.set(vctx, x0)
    set_normal_reference(model, vctx)
    start = posture_summary(model, vctx)
    simulator = _simulator(model, vctx)
    prog = Progress(f"settle ({variant})", T, progress) if progress else None
    _advance(simulator, T, prog, model.systems.get("divergence_guard"))
    summary = posture_summary(model, vctx)
    summary["head_pitch_drift_deg"] = summary["head_pitch_deg"] - start["head_pitch_deg"]
    summary["settle_time_s"] = T
    plant = vmap.slice("plant")
    return SettledState(vmap.get(vctx), model_fingerprint(params, measures, variant, effects),
                        variant, summary, (plant.start, model.plant.num_positions(),
                                           model.plant.num_velocities()),
                        params.simulation.design, params.simulation.time_step_s)


def vibrate(params: ModelParams, settled: SettledState, signal: SeatSignal,
            measures: BodyMeasures = REFERENCE, variant: str | None = None,
            progress: bool = False, effects: dict | None = None) -> SimulationResult:
    """Play `signal` from the settled state; record at the output rate.

    The signal's settle time is skipped: the run starts from the settled
    state at t = signal.settle_time.  The model extensions set their own
    states for the run (`ModelExtension.start_run`, e.g. a running RMS of
    the seat acceleration starting at the signal's level).
    """
    variant = variant or settled.variant
    if settled.fingerprint != model_fingerprint(params, measures, variant, effects):
        sim = params.simulation
        if settled.design and (settled.design, settled.time_step_s) != (sim.design,
                                                                        sim.time_step_s):
            raise ValueError(f"the settled state was computed on the {settled.design} design "
                             f"at a {settled.time_step_s * 1e3:g} ms step, this run is on the "
                             f"{sim.design} design at {sim.time_step_s * 1e3:g} ms: run it "
                             f"with --design {settled.design} (and --time-step "
                             f"{settled.time_step_s:g}), or settle again")
        raise ValueError("the settled state was computed for other parameters, body, "
                         "variant, effects or design; settle again (or run it on the design "
                         "it was settled on: --design reference|implicit)")
    period = 1.0 / params.simulation.output_rate_hz
    model = build_diagram(params, measures, signal, variant, log_period=period, effects=effects)
    ctx = model.diagram.CreateDefaultContext()
    smap = StateMap(model)
    x = np.array(settled.state, float)
    for ext in model.extensions:
        ext.start_run(model, smap, x, signal)
    smap.set(ctx, x)
    set_normal_reference(model, ctx)
    ctx.SetTime(signal.settle_time)
    # Outputs are relative to the settled pose.
    channels = model.systems["body_channels"]
    cctx = channels.GetMyMutableContextFromRoot(ctx)
    x_plant = model.plant.GetPositionsAndVelocities(model.plant_context(ctx))
    cctx.get_mutable_numeric_parameter(channels.settled_pose_parameter_index).SetFromVector(
        channels.settled_pose_vector(x_plant))
    simulator = _simulator(model, ctx)
    prog = (Progress(f"vibrate ({variant})", signal.duration - signal.settle_time)
            if progress else None)
    wall0 = time.perf_counter()
    interrupted = False
    try:
        _advance(simulator, signal.duration, prog, model.systems.get("divergence_guard"))
    except KeyboardInterrupt:
        interrupted = True
    # The wall time includes reading the logs: the channels are derived
    # from the logged state there (`diagram.DerivedChannelsLog`).
    logs = {k: v.FindLog(ctx) for k, v in model.loggers.items()}
    wall = time.perf_counter() - wall0
    t = logs["channels"].sample_times()
    result = SimulationResult(
        times=t,
        seat_acceleration=logs["seat_acceleration"].data().T,
        seat_displacement=logs["seat_displacement"].data().T,
        channels=logs["channels"].data().T,
        seat_forces=logs["seat_forces"].data().T,
        joint_torques=logs["joint_torques"].data().T,
        his_torque=logs["his_torque"].data().T,
        joint_names=model.joint_names,
        positions=logs["state"].data().T[:, :model.plant.num_positions()],
        meta={
            "variant": variant,
            "effects": model.effects,
            "signal": signal.meta,
            "simulated_s": float(t[-1] - t[0]) if len(t) else 0.0,
            "wall_s": wall,
            "real_time_factor": float((ctx.get_time() - signal.settle_time) / wall)
            if wall > 0 else math.inf,
            "interrupted": interrupted,
        },
    )
    if interrupted:
        raise SimulationInterrupted(result)
    return result


class SimulationInterrupted(KeyboardInterrupt):
    """Ctrl-C during a run; `.result` holds what was recorded so far."""

    def __init__(self, result: SimulationResult):
        super().__init__("simulation interrupted")
        self.result = result


def simulate(params: ModelParams, measures: BodyMeasures = REFERENCE, variant: str = "default",
             signal: SeatSignal | None = None, direction: str = "z", rms: float = 0.1941,
             duration: float = 60.0, seed: int = 0, settled: SettledState | None = None,
             progress: bool = False, effects: dict | None = None):
    """Settle (or reuse `settled`) and vibrate.  Returns (SettledState,
    SimulationResult)."""
    if settled is None:
        settled = settle(params, measures, variant, progress=progress, effects=effects)
    if signal is None:
        s = params.simulation
        signal = make_seat_signal("random", direction, rms, duration, seed, s.time_step_s,
                                  s.settle_time_s, s.onset_time_s)
    return settled, vibrate(params, settled, signal, measures, variant, progress=progress,
                            effects=effects)


__all__ = [
    "EquilibriumError", "SettledState", "SimulationDiverged", "SimulationInterrupted",
    "SimulationResult", "StateMap", "settle", "simulate", "static_equilibrium", "vibrate",
]
