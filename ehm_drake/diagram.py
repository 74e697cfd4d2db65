"""Assemble the seated-human Diagram.

The signal flow::

    excitation --a--> force laws: seat inertial load --+
    plant --state-->              passive joints       |
                                  joint PID            +--> plant.applied_generalized_force
                                  shear restraints     |    (through a sum when
                                  head-in-space      --+     extensions add forces)
                 --> extensions' forces ---------------+
    plant --state--> body channels (+ seat displacement) --> "channels"

On both designs one system, `ForceLaws` ("force_laws"), applies the five
laws in one pass; `EhmDiagram.systems` holds its `LawView` views under the five
names (``joint_pid``, ``head_in_space``, ...).  `separate_force_systems`
builds the same laws as one LeafSystem each (`PassiveJoints`, `JointPid`,
`ShearRestraints`, `HeadInSpace`, `SeatInertialLoad`): the readable form,
which `ForceLaws` equals to rounding (tests/test_force_laws.py) at about
half the cost per step.

`build_diagram(params, ...)` returns an `EhmDiagram` holding the Diagram and
handles to every subsystem.  Without a signal, the diagram exports the
input ports ``seat_acceleration`` and ``seat_displacement`` (3 each) so it
can be driven or linearized; with one, the signal's samples drive them
(`ehm_drake.systems.excitation`).
Exported outputs: ``channels`` (30), ``seat_forces`` (12), ``state``
(plant [q; v]), ``joint_torques`` (24 gimbal torques of the PID),
``his_torque`` (3), ``seat_acceleration``, ``seat_displacement``,
``restraint_normal_displacement`` and ``restraint_deflection`` (per
restraint point; see `ShearRestraints`).

Model extensions (`effects`: the gap diagnosis' candidate effects) enter
through the hooks of `ehm_drake.model.extensions.ModelExtension`: the
plant's (`add_seated_human`), the shear restraints' options, extra force
systems summed into the generalized force, and a transform of the
controllers' feedback; this module calls them and names none.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Adder, Multiplexer, PassThrough, VectorLogSink

from .model.anthropometry import REFERENCE, BodyMeasures
from .model.extensions import (
    DiagramParts,
    ModelExtension,
    merge_options,
    validate_extensions,
)
from .model.plant import (
    HumanPlant,
    add_seated_human,
    passive_stiffness_vector,
    pid_vectors,
    step_damping_limits,
)
from .model.seats import apply_seat
from .model.softening import element_set, long_range_contacts
from .params import (
    IMPLICIT_TIME_STEP_S,
    ModelParams,
    ParameterError,
    apply_variant,
    validate,
    with_design,
)
from .signals import SeatSignal
from .systems.contact_forces import ContactDecomposition
from .systems.excitation import add_seat_excitation
from .systems.forces import ForceLaws
from .systems.his import HeadInSpace
from .systems.joints import JointPid, PassiveJoints
from .systems.outputs import (
    CHANNEL_NAMES,
    SEGMENTS,
    BodyChannels,
    DivergenceGuard,
    SeatForces,
)
from .systems.seat import (
    SEAT_PART_NAMES,
    SeatInertialLoad,
    ShearRestraints,
    contact_explicit_damping,
    restraint_parameters,
    restraint_points,
)
from .systems.softening import BodySoftening

SEAT_FORCE_NAMES = tuple(f"{p}_f{a}" for p in SEAT_PART_NAMES for a in "xyz")


class LoggedOutput:
    """One logged output port: its rows of the diagram's single log sink.
    `FindLog(root_context)` returns a log with `sample_times()` and
    `data()` (size x samples), as Drake's `VectorLog`."""

    def __init__(self, sink: VectorLogSink, rows: slice):
        self.sink, self.rows = sink, rows

    def FindLog(self, root_context):  # noqa: N802  (Drake's name)
        return _LogRows(self.sink.FindLog(root_context), self.rows)


class DerivedChannelsLog:
    """The ``channels`` log, derived after the run from the logged plant
    state and seat displacement by the body-channels system itself
    (`BodyChannels.channels_of_log`, the same bits as logging its output):
    `FindLog(root_context)` as `LoggedOutput`'s."""

    def __init__(self, channels, state: LoggedOutput, displacement: LoggedOutput):
        self.channels, self.state, self.displacement = channels, state, displacement

    def FindLog(self, root_context):  # noqa: N802  (Drake's name)
        return _DerivedRows(self, root_context)


class _DerivedRows:
    def __init__(self, derived: DerivedChannelsLog, root_context):
        self._state = derived.state.FindLog(root_context)
        d = derived.displacement.FindLog(root_context).data()
        system = derived.channels
        self._data = system.channels_of_log(system.GetMyContextFromRoot(root_context),
                                            self._state.data(), d)

    def sample_times(self) -> np.ndarray:
        return self._state.sample_times()

    def data(self) -> np.ndarray:
        return self._data


class DerivedSeatForcesLog:
    """The ``seat_forces`` log, derived after the run: the restraints' and
    tissue's part as logged, plus the contacts' from the logged human's
    generalized contact forces and plant positions
    (`ehm_drake.systems.contact_forces`; `SeatForces`' numbers to
    rounding, without walking the contact results every step).
    `FindLog(root_context)` as `LoggedOutput`'s."""

    def __init__(self, decomposition: ContactDecomposition, state: LoggedOutput,
                 tau_contact: LoggedOutput, restraints: LoggedOutput, nq: int):
        self.decomposition, self.state, self.nq = decomposition, state, nq
        self.tau_contact, self.restraints = tau_contact, restraints

    def FindLog(self, root_context):  # noqa: N802  (Drake's name)
        return _DerivedSeatForces(self, root_context)


class _DerivedSeatForces:
    def __init__(self, derived: DerivedSeatForcesLog, root_context):
        self._restraints = derived.restraints.FindLog(root_context)
        q = derived.state.FindLog(root_context).data()[:derived.nq]
        tau = derived.tau_contact.FindLog(root_context).data()
        self._data = self._restraints.data() + derived.decomposition.contact_forces(
            q.T, tau.T).T

    def sample_times(self) -> np.ndarray:
        return self._restraints.sample_times()

    def data(self) -> np.ndarray:
        return self._data


class _LogRows:
    def __init__(self, log, rows: slice):
        self._log, self._rows = log, rows

    def sample_times(self) -> np.ndarray:
        return self._log.sample_times()

    def data(self) -> np.ndarray:
        return self._log.data()[self._rows]


@dataclass
class EhmDiagram:
    """The built diagram and handles to its parts."""

    diagram: Diagram
    hp: HumanPlant
    params: ModelParams
    variant: str
    measures: BodyMeasures
    systems: dict = field(default_factory=dict)
    loggers: dict = field(default_factory=dict)
    signal: SeatSignal | None = None
    effects: dict = field(default_factory=dict)

    @property
    def plant(self):
        return self.hp.plant

    @property
    def extensions(self) -> tuple[ModelExtension, ...]:
        """The model extensions of `effects` (see `ehm_drake.model.extensions`)."""
        return self.hp.extensions

    def plant_context(self, root_context):
        return self.hp.plant.GetMyContextFromRoot(root_context)

    def subcontext(self, name: str, root_context):
        return self.systems[name].GetMyContextFromRoot(root_context)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.hp.layout.names


def _marker_list(hp: HumanPlant):
    plant = hp.plant
    out = []
    for seg in SEGMENTS:
        frame = plant.GetFrameByName(f"{seg}_marker", hp.human)
        out.append((frame.body().name(), frame.GetFixedPoseInBodyFrame().translation()))
    return out


def build_diagram(
    params: ModelParams,
    measures: BodyMeasures = REFERENCE,
    signal: SeatSignal | None = None,
    variant: str = "default",
    log_period: float | None = None,
    guard: bool = True,
    seat_forces: bool = True,
    effects: dict | None = None,
    controller_input: bool = False,
) -> EhmDiagram:
    """Build the closed-loop diagram of the seated human on its seat.

    Parameters
    ----------
    params : model parameters (see `ehm_drake.params`); `variant` is applied.
    measures : anthropometry of the body (default: 50th-percentile male).
    signal : seat excitation to play; None exports the seat input ports.
    variant : "default", "no-integrator" or "high-stiffness".
    log_period : if given, one VectorLogSink records the seat motion, seat
        forces, torques and plant state at this period (s);
        `EhmDiagram.loggers` gives each output's rows (`LoggedOutput`), the
        channels derived from the logged state (`DerivedChannelsLog`) and,
        on the model's own seat, the seat forces derived from the logged
        generalized contact forces (`DerivedSeatForcesLog`).
    guard : add the `DivergenceGuard` (blow-up detection).
    seat_forces : add the `SeatForces` measurement (contact results: a
        second contact solve per evaluation; linearizations that only need
        the body channels leave it out, as does AutoDiff, which it blocks).
    effects : model extensions to add, {name: {parameter: value}} (the
        candidate unmodelled effects of `ehm_drake.gap.library.effects`; default
        none).
    controller_input : export an input port ``controller_state`` (plant
        [q; v]) that the PID and head-in-space controllers read instead of
        the plant state (the feedback loop cut open, for the gap
        diagnosis' delayed-feedback linearization; the extensions'
        feedback transforms are then left out).
    """
    at_rest = apply_seat(apply_variant(params, variant))
    # The plant's contacts carry the body with the tissue's long-range
    # stiffness; the short-range part is the softening system's
    # (`ehm_drake.model.softening`).
    params = long_range_contacts(at_rest)
    effects = validate_extensions(effects)
    h = params.simulation.time_step_s
    builder = DiagramBuilder()
    hp = add_seated_human(builder, params, measures, effects, rest_params=at_rest)
    extensions = hp.extensions
    plant = hp.plant
    layout = hp.layout
    sys = {}

    # Seat motion source (or exported inputs).
    if signal is not None:
        if abs(signal.time_step - h) > 1e-12:
            raise ValueError(f"signal time step {signal.time_step} differs from the model's {h}")
        motion = add_seat_excitation(builder, signal)
        accel_out, disp_out = motion["seat_acceleration"], motion["seat_displacement"]
    else:
        a_in = builder.AddNamedSystem("seat_acceleration_input", PassThrough(3))
        d_in = builder.AddNamedSystem("seat_displacement_input", PassThrough(3))
        builder.ExportInput(a_in.get_input_port(), "seat_acceleration")
        builder.ExportInput(d_in.get_input_port(), "seat_displacement")
        accel_out, disp_out = a_in.get_output_port(), d_in.get_output_port()

    state = plant.get_state_output_port()
    parts = DiagramParts(builder, hp, params, h, state, accel_out, disp_out, sys)
    # One system for the five laws (see `ForceLaws`); it reads the
    # controllers' view of the body on its own input when that may differ
    # from the plant state.
    laws = builder.AddNamedSystem("force_laws", _force_laws(
        hp, params, h, controller_input or _transforms_feedback(extensions)))
    builder.Connect(accel_out, laws.GetInputPort("seat_acceleration"))
    forces = [laws]
    sys.update(laws.views)
    sys["force_laws"] = laws
    law_ports = {"joint_torques": laws.GetOutputPort("joint_torques"),
                 "his_torque": laws.GetOutputPort("his_torque"),
                 "restraint_seat_forces": laws.GetOutputPort("restraint_seat_forces"),
                 "restraint_normal_displacement": laws.GetOutputPort("normal_displacement"),
                 "restraint_deflection": laws.GetOutputPort("deflection")}
    # The body's softening with its own movement (`model.softening`).
    softening = _body_softening(hp, at_rest, h)
    if softening is not None:
        forces.append(builder.AddNamedSystem("body_softening", softening))
        sys["body_softening"] = forces[-1]
    # The extensions' force systems (their "state" input is connected below).
    for ext in extensions:
        forces += ext.add_force_systems(parts)
    applied = plant.get_applied_generalized_force_input_port()
    if len(forces) > 1:
        adder = builder.AddNamedSystem("generalized_force_sum", Adder(len(forces), layout.nv))
        builder.Connect(adder.get_output_port(), applied)
        applied = None
    # The controllers' view of the body: the plant state, as the extensions
    # transform it (e.g. delayed), or an exported input (the loop cut open).
    feedback = state
    if controller_input:
        fb_in = builder.AddNamedSystem("controller_state_input", PassThrough(layout.nq + layout.nv))
        builder.ExportInput(fb_in.get_input_port(), "controller_state")
        feedback = fb_in.get_output_port()
    else:
        for ext in extensions:
            feedback = ext.transform_feedback(parts, feedback)
    forces_on_body = list(forces)
    for i, s in enumerate(forces):
        builder.Connect(state, s.GetInputPort("state"))
        if s.HasInputPort("controller_state"):
            builder.Connect(feedback, s.GetInputPort("controller_state"))
        builder.Connect(s.GetOutputPort("generalized_force"),
                        adder.get_input_port(i) if applied is None else applied)

    # Measurements.
    channels = builder.AddNamedSystem("body_channels", BodyChannels(plant, _marker_list(hp)))
    builder.Connect(state, channels.GetInputPort("state"))
    builder.Connect(disp_out, channels.GetInputPort("seat_displacement"))
    sys["body_channels"] = channels
    if seat_forces:
        candidates = len(hp.scene_graph.model_inspector().GetCollisionCandidates())
        forces = builder.AddNamedSystem("seat_forces",
                                        SeatForces(plant, hp.seat_geometries, candidates))
        builder.Connect(plant.get_contact_results_output_port(),
                        forces.GetInputPort("contact_results"))
        restraint_forces = law_ports["restraint_seat_forces"]
        # The tissue's softening acts between body and seat.
        soft = [p for s in forces_on_body if (p := _seat_force_port(s)) is not None]
        if soft:
            total = builder.AddNamedSystem("seat_force_sum",
                                           Adder(1 + len(soft), restraint_forces.size()))
            builder.Connect(restraint_forces, total.get_input_port(0))
            for i, port in enumerate(soft, 1):
                builder.Connect(port, total.get_input_port(i))
            restraint_forces = total.get_output_port()
        builder.Connect(restraint_forces, forces.GetInputPort("restraint_forces"))
        sys["seat_forces"] = forces
        law_ports["seat_restraint_forces"] = restraint_forces
    if guard:
        g = builder.AddNamedSystem("divergence_guard", DivergenceGuard(
            hp, level_ms2=0.0 if signal is None else signal.level()))
        builder.Connect(state, g.GetInputPort("state"))
        sys["divergence_guard"] = g

    outputs = {
        "channels": channels.GetOutputPort("channels"),
        "state": plant.get_state_output_port(),
        "joint_torques": law_ports["joint_torques"],
        "his_torque": law_ports["his_torque"],
        "restraint_normal_displacement": law_ports["restraint_normal_displacement"],
        "restraint_deflection": law_ports["restraint_deflection"],
        "seat_acceleration": accel_out,
        "seat_displacement": disp_out,
    }
    if seat_forces:
        outputs["seat_forces"] = sys["seat_forces"].GetOutputPort("seat_forces")
    if "body_softening" in sys:
        outputs["softening_deformation"] = sys["body_softening"].GetOutputPort("deformation")
    for name, port in outputs.items():
        builder.ExportOutput(port, name)
    loggers = {}
    if log_period is not None:
        # One sink for all of them (a Multiplexer in front): every sink is a
        # publish event per period, about 20 us each at a 5 ms step.  The
        # channels are not logged: they are derived from the logged state
        # and seat displacement after the run (`DerivedChannelsLog`).
        # The seat forces, where `ContactDecomposition` holds, are derived
        # from two vectors Drake computes in C++ (`DerivedSeatForcesLog`).
        decomposition = ContactDecomposition.of(hp) if seat_forces else None
        logged = dict(outputs)
        if decomposition is not None:
            del logged["seat_forces"]
            logged["tau_contact"] = plant.get_generalized_contact_forces_output_port(hp.human)
            logged["seat_restraint_forces"] = law_ports["seat_restraint_forces"]
        names = [n for n in ("seat_forces", "seat_restraint_forces", "tau_contact",
                             "joint_torques", "his_torque", "seat_acceleration",
                             "seat_displacement", "state") if n in logged]
        sizes = [logged[n].size() for n in names]
        mux = builder.AddNamedSystem("logged_outputs", Multiplexer(sizes))
        for i, name in enumerate(names):
            builder.Connect(logged[name], mux.get_input_port(i))
        sink = builder.AddNamedSystem("log", VectorLogSink(sum(sizes), log_period))
        builder.Connect(mux.get_output_port(), sink.get_input_port())
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        loggers = {name: LoggedOutput(sink, slice(offsets[i], offsets[i + 1]))
                   for i, name in enumerate(names)}
        loggers["channels"] = DerivedChannelsLog(channels, loggers["state"],
                                                 loggers["seat_displacement"])
        if decomposition is not None:
            loggers["seat_forces"] = DerivedSeatForcesLog(
                decomposition, loggers["state"], loggers.pop("tau_contact"),
                loggers.pop("seat_restraint_forces"), plant.num_positions())
    diagram = builder.Build()
    diagram.set_name("ehm_seated_human")
    return EhmDiagram(diagram, hp, params, variant, measures, sys, loggers, signal, effects)


def accurate_step(params: ModelParams, measures: BodyMeasures = REFERENCE,
                  variant: str = "default", effects: dict | None = None) -> ModelParams:
    """`params` on the implicit design at the step chosen by accuracy: the
    largest that divides the output period, is at most
    `IMPLICIT_TIME_STEP_S` and keeps every part of this body and variant
    second-order accurate (`ehm_drake.model.plant.step_damping_limits`:
    no stiff spring integrated implicitly, no contact damper clipped).  The
    default body gets 5 ms; the high-stiffness variant, whose lower-torso
    springs need 2.19 ms, gets 5/3 ms (at 5 ms its step error was 27% in
    the worst bin; docs/designs.md)."""
    p = params.copy()
    p.simulation.design = "implicit"
    p.simulation.time_step_s = IMPLICIT_TIME_STEP_S
    p_variant = apply_variant(validate(p), variant)
    with warnings.catch_warnings():  # (the 5 ms step's own warning: the step is chosen here)
        warnings.simplefilter("ignore", UserWarning)
        # The plant as `build_diagram` makes it (contacts at their long-range
        # stiffness, `model.softening`).
        p_plant = long_range_contacts(apply_seat(p_variant))
        hp = add_seated_human(DiagramBuilder(), p_plant, measures, validate_extensions(effects),
                              rest_params=apply_seat(p_variant))
    limit = min(step_damping_limits(hp.plant, hp.human, p_plant, hp.body).values(),
                default=IMPLICIT_TIME_STEP_S)
    period = 1.0 / p.simulation.output_rate_hz
    n = max(1, math.ceil(period / min(limit, IMPLICIT_TIME_STEP_S) - 1e-9))
    p.simulation.time_step_s = period / n
    return validate(p)


def on_design(params: ModelParams, design: str | None = None, time_step_s: float | None = None,
              measures: BodyMeasures = REFERENCE, variant: str = "default",
              output_every: int | None = None) -> ModelParams:
    """`params` on `design` at `time_step_s` (the command line's ``--design``
    and ``--time-step``; None keeps the parameters').  Switching to the
    implicit design without a step gives the step chosen by accuracy for
    this body and variant (`accurate_step`); otherwise `params.with_design`.

    `output_every` (``--output-every``): the outputs every that many steps
    of the resulting step h, at exactly 1 / (output_every h), in place of
    the parameters' rate (whose period must be a whole number of steps: a
    6 ms step cannot have 200 Hz outputs, and 1/0.006 Hz cannot be typed)."""
    if output_every is not None:
        if isinstance(output_every, bool) or int(output_every) != output_every \
                or output_every < 1:
            raise ParameterError(f"output every {output_every!r} steps: must be a whole "
                                 "number >= 1")
        if time_step_s is None:
            time_step_s = on_design(params, design, None, measures,
                                    variant).simulation.time_step_s
        params = params.copy()
        params.simulation.output_rate_hz = 1.0 / (int(output_every) * time_step_s)
        return with_design(params, design, time_step_s)
    if design is None and time_step_s is None:
        return params
    switched = design is not None and design != params.simulation.design
    if switched and design == "implicit" and time_step_s is None:
        return accurate_step(params, measures, variant)
    return with_design(params, design, time_step_s)


def separate_force_systems(builder, hp: HumanPlant, params: ModelParams, h: float, accel_out,
                           sys: dict):
    """The five force laws as one LeafSystem each (their ``state`` inputs
    connected by the caller), recorded in `sys`; returns them and the ports
    of the joint and head-in-space torques and the restraints' seat forces,
    normal displacements and deflections.  `build_diagram` uses `ForceLaws`
    instead, which equals their sum to rounding at about half the Python
    cost per step; this is the form it is checked against."""
    layout, plant = hp.layout, hp.plant
    # Joint torques: passive Cardan springs + PID.
    k = passive_stiffness_vector(params, layout)
    passive = builder.AddNamedSystem(
        "passive_joints",
        PassiveJoints(layout, k, np.zeros(len(k)), hp.implicit_passive, hp.damping_remainder))
    gains = pid_vectors(params, layout)
    pid = builder.AddNamedSystem(
        "joint_pid",
        JointPid(layout, gains["kp"], gains["ki"], gains["kd"], gains["integral_limit"],
                 np.zeros(layout.num_rotational), h, implicit_kp=hp.implicit_kp))
    if pid.HasInputPort("plant_state"):  # PD actuators, ball joints: the plant's own q
        builder.Connect(plant.get_state_output_port(), pid.GetInputPort("plant_state"))
    # Seat: inertial load of the seat motion, shear restraints.
    inertial = builder.AddNamedSystem("seat_inertial_load",
                                      SeatInertialLoad(plant, [hp.human, hp.seat]))
    builder.Connect(accel_out, inertial.GetInputPort("seat_acceleration"))
    points = restraint_points(hp)
    restraints = builder.AddNamedSystem(
        "shear_restraints",
        ShearRestraints(plant, points, _restraint_vector(params, points, hp.extensions), h,
                        hp.restraint_constraints,
                        contact_explicit_damping(params, points, hp.moving_seat_parts)))
    # Head-in-space control.
    gain = 1.0 if params.his.enabled else 0.0
    his = builder.AddNamedSystem(
        "head_in_space",
        HeadInSpace(plant, "head", "upper_torso", gain * np.array(params.his.kp),
                    gain * np.array(params.his.kd)))
    sys.update(passive_joints=passive, joint_pid=pid, seat_inertial_load=inertial,
               shear_restraints=restraints, head_in_space=his)
    return [passive, pid, restraints, his, inertial], {
        "joint_torques": pid.GetOutputPort("torque"),
        "his_torque": his.GetOutputPort("torque"),
        "restraint_seat_forces": restraints.GetOutputPort("seat_forces"),
        "restraint_normal_displacement": restraints.GetOutputPort("normal_displacement"),
        "restraint_deflection": restraints.GetOutputPort("deflection")}


def _force_laws(hp: HumanPlant, params: ModelParams, h: float, feedback_input: bool):
    """`ForceLaws`, with the same laws and parameters as
    `separate_force_systems` builds one by one."""
    layout = hp.layout
    k = passive_stiffness_vector(params, layout)
    gains = pid_vectors(params, layout)
    points = restraint_points(hp)
    gain = 1.0 if params.his.enabled else 0.0
    return ForceLaws(
        hp.plant, layout,
        passive=(k, np.zeros(len(k)), hp.implicit_passive, hp.damping_remainder),
        pid=(gains["kp"], gains["ki"], gains["kd"], gains["integral_limit"],
             np.zeros(layout.num_rotational), hp.implicit_kp),
        his=("head", "upper_torso", gain * np.array(params.his.kp),
             gain * np.array(params.his.kd)),
        restraints=(points, _restraint_vector(params, points, hp.extensions),
                    hp.restraint_constraints,
                    contact_explicit_damping(params, points, hp.moving_seat_parts)),
        inertial_instances=[hp.human, hp.seat], period=h, feedback_input=feedback_input)


def _seat_force_port(system):
    """A softening system's force on the body per seat part (None for the
    other force systems)."""
    if hasattr(system, "rest_deformation"):
        return system.GetOutputPort("seat_forces")
    return None


def _body_softening(hp: HumanPlant, params: ModelParams, h: float):
    """The `BodySoftening` system of the enabled softening elements (None
    when `params.softening` enables none); `params` with the contacts'
    stiffness at rest."""
    points = restraint_points(hp)
    elements = element_set(params, points, hp.layout)
    if not elements.n:
        return None
    tissue = [p for p in points if p.name in elements.names[:elements.kinds.count("tissue")]]
    muscle = [hp.layout.names.index(n) for k, n in zip(elements.kinds, elements.names,
                                                       strict=True) if k == "muscle"]
    return BodySoftening(hp.plant, hp.layout, elements, tissue, muscle, h)


def _transforms_feedback(extensions: tuple[ModelExtension, ...]) -> bool:
    """Whether an extension may give the controllers another view of the
    body than the plant state (it implements `transform_feedback`)."""
    return any(type(ext).transform_feedback is not ModelExtension.transform_feedback
               for ext in extensions)


def _restraint_vector(params: ModelParams, points,
                      extensions: tuple[ModelExtension, ...]) -> np.ndarray:
    """The shear restraints' parameters with the extensions' options."""
    return restraint_parameters(params, points,
                                **merge_options(extensions, "restraint_options", params, points))


__all__ = ["EhmDiagram", "build_diagram", "CHANNEL_NAMES", "SEAT_FORCE_NAMES"]
