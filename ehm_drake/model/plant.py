"""Load the seated human and its seat into a MultibodyPlant.

`add_seated_human(builder, params)` parses the SDF (the 50th-percentile male
from the packaged files, or a scaled body generated from it), adds
the pelvis' free joint (roll-pitch-yaw floating, so all 31 DoFs are minimal
coordinates), the joint damping, and the contact properties of the
body-seat contact pairs, and finalizes the plant.

Passive joints (paper Sec. II, "restraint cardan"): the torsional springs
about each joint's Cardan angles and the axial spring of the spinal
compression DoF are the vectorized `ehm_drake.systems.joints.PassiveJoints`
system (its stiffness a context parameter); the matching dampers are the
joints' own damping, set when the plant is built, which the SAP solver
integrates implicitly.  Drake's BallRpyJoint and UniversalJoint apply the
first entry of their damping vector to all their axes (checked on Drake
1.51: a ball joint given (100, 1, 1) damps all three velocities at 100), so
a multi-DoF joint gets its smallest axis damping on every axis (implicit)
and `PassiveJoints` applies the rest about the Cardan rates
(`HumanPlant.damping_remainder`; docs/designs.md).  On the implicit
design every damper is split between SAP and an explicit force so that the
step is second-order accurate (`ehm_drake.model.stepping`), and the shear
restraints' linear part is a set of compliant distance constraints
(`ehm_drake.model.restraints`).  (Drake's
`LinearBushingRollPitchYaw` is the equivalent force element, but profiling
put it at 3.4 us per joint per step, a third of the step budget.)

Contact: each body collision ellipsoid touches exactly one seat part (see
`params.CONTACT_PAIRS`); all other body-seat pairs are filtered out.  The
pair's stiffness and damping are exactly the parameter values: point
contact with SAP's linear Kelvin-Voigt law f = k (x + tau xdot), tau = d/k.
No friction: shear is carried by the point restraints of
`ehm_drake.systems.seat.ShearRestraints`.

Extensions (the gap diagnosis' candidate effects) change the body, the
seat and the force elements through the hooks of
`ehm_drake.model.extensions.ModelExtension`; this module calls them and
names none.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import (
    AddCompliantHydroelasticProperties,
    AddContactMaterial,
    AddRigidHydroelasticProperties,
    CollisionFilterDeclaration,
    GeometrySet,
    ProximityProperties,
    RoleAssign,
    SceneGraph,
)
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    CoulombFriction,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import (
    BallRpyJoint,
    PdControllerGains,
    RevoluteJoint,
    RpyFloatingJoint,
    UniversalJoint,
)
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from ..params import CARDAN_JOINTS, CONTACT_PAIRS, PASSIVE_GROUPS, ModelParams
from .anthropometry import REFERENCE, Body, BodyMeasures, build_body
from .extensions import ModelExtension, merge_options, resolve_extensions, validate_extensions
from .joint_layout import (  # noqa: F401  (importable from here)
    PID_GROUP_OF,
    JointLayout,
    passive_stiffness_vector,
    pid_vectors,
)
from .restraints import RestraintConstraints, add_restraint_constraints
from .sdf_writer import (
    HUMAN_CARDAN_SDF_NAME,
    HUMAN_SDF_NAME,
    SEAT_SDF_NAME,
    cardan_joint,
    human_sdf,
    packaged_sdf,
    seat_sdf,
)
from .seats import adjust_seat_for_sink, remove_backrest
from .softening import static_sink
from .stepping import (
    SPINE_AXIAL,
    STABLE_OMEGA_H,
    central_limit,
    implicit_springs,
    sap_damping,
    segment_frequencies,
    step_damping,
    step_split,
)

#: Nominal share of body weight carried by each contact pair in the erect,
#: high-support posture (about half under the ischia, a tenth per thigh, a
#: few percent per foot and per pad; the static split of this model after
#: settling is within a few percent of it).  Used only to convert a pair's
#: linear stiffness into a hydroelastic modulus with the same tangent
#: stiffness at that load.
NOMINAL_LOAD_SHARE = {
    "pelvis_pan": 0.50,
    "thighs_pan": 0.10,
    "lower_back_pad": 0.02,
    "upper_back_pad": 0.02,
    "feet_floor": 0.06,
}
#: Point stiffness of the seat parts.  Drake combines k = k1 k2/(k1 + k2);
#: an infinite value (exactly rigid) makes SAP produce NaN in Drake 1.51, so
#: the seat is very stiff and each body ellipsoid's stiffness is raised so the
#: pair's combined stiffness is exactly its parameter value.
SEAT_POINT_STIFFNESS = 1e10


def _joint_axes(joint) -> list[int]:
    """Cardan axes (0=x, 1=y, 2=z of the joint frame) of a joint's DoFs."""
    if isinstance(joint, BallRpyJoint):
        return [0, 1, 2]
    if isinstance(joint, UniversalJoint):
        return [0, 1]
    if isinstance(joint, RevoluteJoint):
        axis = np.abs(np.asarray(joint.revolute_axis()))
        return [int(np.argmax(axis))]
    raise TypeError(type(joint))


def joint_dofs(plant: MultibodyPlant, human, name: str) -> list[tuple[int, object, int]]:
    """The DoFs of the human's joint `name` as (Cardan axis, Drake joint,
    DoF within that joint), x before y before z: one multi-DoF joint
    (reference design) or a chain of revolute joints `<name>_x`, ... (the
    implicit design; see `sdf_writer.human_sdf`)."""
    if plant.HasJointNamed(name, human):
        joint = plant.GetJointByName(name, human)
        return [(axis, joint, i) for i, axis in enumerate(_joint_axes(joint))]
    return [(axis, plant.GetJointByName(cardan_joint(name, axis), human), 0)
            for axis in range(3) if plant.HasJointNamed(cardan_joint(name, axis), human)]


@dataclass
class HumanPlant:
    """A finalized plant with handles to what the rest of the model needs."""

    plant: MultibodyPlant
    scene_graph: SceneGraph
    body: Body
    human: object  # ModelInstanceIndex
    seat: object
    layout: JointLayout
    #: collision geometry name -> (GeometryId, contact pair name)
    body_geometries: dict[str, tuple[object, str]]
    #: seat part name -> GeometryId
    seat_geometries: dict[str, object]
    contact_model: str
    time_step: float
    #: "implicit" or "reference" (`params.Simulation.design`).
    design: str = "reference"
    #: The stiffness the plant's PD-controlled joint actuators apply, about
    #: the zero (reference) position, integrated implicitly by SAP: on the
    #: implicit design where the step is too large for the spring to be
    #: explicit (`spring_is_implicit`), zeros elsewhere and on the reference
    #: design; in two parts:
    #: `implicit_passive`, the passive Cardan spring per rotational DoF of
    #: `layout` (N m/rad) then the spine's axial spring (N/m), applied instead
    #: of `PassiveJoints`; `implicit_kp`, the PID's proportional gain per
    #: rotational DoF, applied instead of `JointPid`.  Those systems apply
    #: only what differs from it.
    implicit_passive: np.ndarray | None = None
    implicit_kp: np.ndarray | None = None
    #: Joint damping per rotational DoF of `layout` (N m s/rad), then of the
    #: spinal compression (N s/m), that the plant's joints do not apply: on
    #: a ball or universal joint, each axis' damping less the joint's
    #: smallest, which the joint applies to every axis; on the implicit
    #: design, each damper's explicit part (`step_split`).  Applied by
    #: `PassiveJoints` about the Cardan rates (see `_joint_damping_vectors`).
    damping_remainder: np.ndarray | None = None
    #: Implicit design: the shear restraints' springs and SAP's part of their
    #: dampers as compliant distance constraints (`model.restraints`).
    restraint_constraints: RestraintConstraints | None = None
    #: Seat parts on a link that moves relative to the seat (`moving_seat_parts`).
    moving_seat_parts: frozenset = frozenset()
    effects: dict = field(default_factory=dict)
    #: The resolved extensions of `effects`, in registration order.
    extensions: tuple[ModelExtension, ...] = ()

    @property
    def implicit_stiffness(self) -> np.ndarray:
        """Each PD actuator's stiffness: the sum of the two parts."""
        return self.implicit_passive + np.append(self.implicit_kp, 0.0)

    @property
    def num_dofs(self) -> int:
        return self.plant.num_velocities()


def _load_models(plant: MultibodyPlant, body: Body, measures: BodyMeasures,
                 extensions: tuple[ModelExtension, ...], cardan: bool,
                 packaged_seat: bool = True):
    """The packaged SDF for the reference body without extensions, else
    SDF generated from `body` (and the extensions' seat options); with
    `cardan`, the human's joints as Cardan chains of revolute joints.
    `packaged_seat` False: the seat from `body` (its parts moved, e.g. a
    seat without backrest)."""
    # The SDFs refer to no file or `package://` URL: the parser needs no
    # package map (`configure_parser` costs 0.25 ms a build).
    parser = Parser(plant)
    if measures == REFERENCE and not extensions:
        name = HUMAN_CARDAN_SDF_NAME if cardan else HUMAN_SDF_NAME
        (human,) = parser.AddModelsFromString(packaged_sdf(name), "sdf")
        (seat,) = parser.AddModelsFromString(
            packaged_sdf(SEAT_SDF_NAME) if packaged_seat else seat_sdf(body), "sdf")
    else:
        seat_options = merge_options(extensions, "seat_options")
        (human,) = parser.AddModelsFromString(
            human_sdf(body, CARDAN_JOINTS if cardan else ()), "sdf")
        (seat,) = parser.AddModelsFromString(seat_sdf(body, **seat_options), "sdf")
    return human, seat


def add_seated_human(
    builder: DiagramBuilder,
    params: ModelParams,
    measures: BodyMeasures = REFERENCE,
    effects: dict | None = None,
    rest_params: ModelParams | None = None,
) -> HumanPlant:
    """Add the plant (+ SceneGraph) of the seated human to `builder`.

    `effects` ({name: {parameter: value}}: registered model extensions,
    the gap diagnosis' candidate effects, see `ehm_drake.gap.library.effects`)
    extends the model: each extension's plant hooks (`body_options`,
    `modify_body`, `seat_options`, `add_plant_elements`, see
    `ehm_drake.model.extensions`) change the body, the seat and the force
    elements; the others act through the diagram's systems (see
    `ehm_drake.diagram.build_diagram`).  `rest_params`: the parameters
    with the contacts' stiffness at rest, when `params` has their long-range
    stiffness (`ehm_drake.model.softening.long_range_contacts`): the seat is
    adjusted to the deeper sink (`adjust_seat_for_sink`).
    """
    effects = validate_extensions(effects)
    extensions = resolve_extensions(effects)
    body = build_body(measures, **merge_options(extensions, "body_options"))
    for ext in extensions:
        ext.modify_body(body)
    if not params.seat.backrest:
        remove_backrest(body)
    sink = static_sink(rest_params, body.total_mass * 9.81, NOMINAL_LOAD_SHARE) \
        if rest_params is not None else {}
    adjust_seat_for_sink(body, sink)
    config = MultibodyPlantConfig(
        time_step=params.simulation.time_step_s,
        discrete_contact_approximation="sap",
        contact_model="point" if params.contact.model == "point" else "hydroelastic_with_fallback",
        # Outputs are computed from the state when asked; sampling them every
        # step (reaction forces included) cost 15% of the step in profiling.
        use_sampled_output_ports=False,
    )
    plant, scene_graph = AddMultibodyPlant(config, builder)
    plant.set_name("plant")
    design = params.simulation.design
    human, seat = _load_models(plant, body, measures, extensions, design == "implicit",
                               packaged_seat=params.seat.backrest and not sink)
    pelvis = plant.GetBodyByName("pelvis", human)
    free = plant.AddJoint(RpyFloatingJoint("pelvis_free", plant.world_frame(), pelvis.body_frame()))
    free.set_default_translation(body.segments["pelvis"].origin_W)
    _set_default_joint_damping(plant, human, params)
    stiff = frozenset()
    if design == "implicit":
        stiff = implicit_springs(body, _spring_stiffness(plant, human, params),
                                 params.passive.spine_axial_stiffness,
                                 params.simulation.time_step_s)
        _add_pd_actuators(plant, human, params, stiff)
        _warn_about_the_step(params, step_damping_limits(plant, human, params, body))
    body_geoms, seat_geoms, moving_parts = _set_contact_properties(plant, scene_graph, human,
                                                                   seat, params, body)
    constraint_ids = ()
    if design == "implicit":
        constraint_ids = add_restraint_constraints(plant, body, body_geoms,
                                                   scene_graph.model_inspector(), params)
    for ext in extensions:
        ext.add_plant_elements(plant, human, seat, body)
    plant.Finalize()
    layout = _joint_layout(plant, human)
    implicit_k, implicit_kp = _pd_stiffness_vectors(plant, human, params, layout, stiff)
    if plant.num_actuators():
        _connect_pd_targets(builder, plant, human)
    return HumanPlant(
        plant=plant,
        scene_graph=scene_graph,
        body=body,
        human=human,
        seat=seat,
        layout=layout,
        body_geometries=body_geoms,
        seat_geometries=seat_geoms,
        contact_model=params.contact.model,
        time_step=params.simulation.time_step_s,
        design=design,
        implicit_passive=implicit_k,
        implicit_kp=implicit_kp,
        damping_remainder=damping_remainder(plant, human, params, layout),
        restraint_constraints=(RestraintConstraints.of(plant, constraint_ids,
                                                       params.simulation.time_step_s)
                               if constraint_ids else None),
        moving_seat_parts=moving_parts,
        effects=effects,
        extensions=extensions,
    )


def _joint_layout(plant: MultibodyPlant, human) -> JointLayout:
    entries = []
    for group, joints in PASSIVE_GROUPS.items():
        for jname in joints:
            for axis, joint, i in joint_dofs(plant, human, jname):
                entries.append((joint.velocity_start() + i, joint.position_start() + i,
                                jname, group, axis, isinstance(joint, BallRpyJoint)))
    # Joint by joint in the tree's order, x, y, z within a joint (whatever
    # the order of a Cardan chain's revolutes), so both designs list the
    # DoFs alike.
    first = {}
    for e in entries:
        first[e[2]] = min(first.get(e[2], e[0]), e[0])
    entries.sort(key=lambda e: (first[e[2]], e[4]))
    triplets = [[i, i + 1, i + 2] for i, e in enumerate(entries) if e[5] and e[4] == 0]
    spine = plant.GetJointByName("spinal_compression", human)
    return JointLayout(
        nq=plant.num_positions(),
        nv=plant.num_velocities(),
        rot_q=np.array([e[1] for e in entries]),
        rot_v=np.array([e[0] for e in entries]),
        ball_triplets=np.array(triplets, dtype=int).reshape(-1, 3),
        spine_q=spine.position_start(),
        spine_v=spine.velocity_start(),
        names=tuple(f"{e[2]}_{'xyz'[e[4]]}" for e in entries),
        joints=tuple(e[2] for e in entries),
        groups=tuple(e[3] for e in entries),
        axes=tuple(e[4] for e in entries),
    )


# ---------------------------------------------------------------------------
# Joint parameters: parameter file -> per-DoF vectors
# ---------------------------------------------------------------------------


def _joint_gains(params: ModelParams, name: str, axes) -> tuple[np.ndarray, np.ndarray]:
    """Damping (passive + PID derivative gain) and stiffness (passive + PID
    proportional gain) of the human's joint `name` about its Cardan `axes`."""
    group = next(g for g, joints in PASSIVE_GROUPS.items() if name in joints)
    passive, pid = getattr(params.passive, group), getattr(params.pid, PID_GROUP_OF[group])
    return (np.asarray(passive.damping, float)[axes] + np.asarray(pid.kd, float)[axes],
            np.asarray(passive.stiffness, float)[axes] + np.asarray(pid.kp, float)[axes])


def _joint_damping(params: ModelParams, name: str, axes) -> np.ndarray:
    """Joint damping = passive damping + the PID's derivative gain (on the
    implicit design SAP's part of it, `step_split`).

    The derivative action -Kd v is exactly a joint damper, and as joint
    damping SAP integrates it implicitly.  Applied as an explicit force it
    is unstable on the 2.3 kg lower-torso slab between L5/S1 and L4/L5 at
    1 ms (c h / I ~ 1.8 of the limit 2); so the PID applies P and I and the
    plant applies D (the PID still reports the full P+I+D torque)."""
    return step_damping(params, _joint_gains(params, name, axes)[0])


def _spring_stiffness(plant, human, params: ModelParams) -> dict:
    """{joint: stiffness (passive + PID kp) per Cardan axis x, y, z}, 0 where
    the joint has no such DoF."""
    out = {}
    for jname, _, axes in _each_joint(plant, human):
        out.setdefault(jname, np.zeros(3))[axes] = _joint_gains(params, jname, axes)[1]
    return out


def step_damping_limits(plant, human, params: ModelParams, body: Body) -> dict[str, float]:
    """The implicit design's largest time step (s) that keeps each part of
    the model second-order accurate (see `ehm_drake.model.stepping`): per
    segment and axis, the step at which its explicit springs reach
    `STABLE_OMEGA_H` (`<segment>_<x|y|z|axial>`: beyond it the stiffest of
    them become implicit, first-order); per contact pair, c / (2 k)
    (`contact <pair>`: beyond it SAP's part of the damper is clipped)."""
    freqs = segment_frequencies(body, _spring_stiffness(plant, human, params),
                                params.passive.spine_axial_stiffness)
    limits = {f"{seg}_{'xyz'[axis] if axis != 'axial' else axis}": STABLE_OMEGA_H / omega
              for (seg, axis), (omega, _) in freqs.items() if omega > 0}
    for pair in CONTACT_PAIRS:
        cp = getattr(params.contact, pair)
        limits[f"contact {pair}"] = float(central_limit(cp.damping, cp.stiffness))
    return limits


def _warn_about_the_step(params: ModelParams, limits: dict[str, float]) -> None:
    h = params.simulation.time_step_s
    beyond = sorted((limit, name) for name, limit in limits.items() if limit < h)
    if beyond:
        names = ", ".join(f"{name} ({limit * 1e3:.3g} ms)" for limit, name in beyond)
        warnings.warn(
            f"simulation.time_step_s = {h:g} s is beyond the second-order step of "
            f"{len(beyond)} part(s) of the model, where the step is first-order accurate "
            f"(stiff joint springs integrated implicitly for stability, contact dampers "
            f"clipped): {names}; a step of at most {beyond[0][0]:.3g} s keeps every part "
            "second-order accurate (ehm_drake.model.stepping)", stacklevel=3)


def _each_joint(plant, human):
    """(name, Drake joint, its Cardan axes) of the human's rotational joints
    (one entry per Drake joint: per revolute of a Cardan chain)."""
    for jname in CARDAN_JOINTS:
        dofs = joint_dofs(plant, human, jname)
        for joint in dict.fromkeys(j for _, j, _ in dofs):
            yield jname, joint, [axis for axis, j, _ in dofs if j is joint]


def _joint_damping_vectors(plant, human, params: ModelParams):
    """(Drake joint, its damping vector, the remainder per axis) of every
    joint of the human, the spinal compression last.

    Drake's BallRpyJoint and UniversalJoint apply the vector's first entry
    to all their axes, and SAP integrates that implicitly; so such a joint
    gets its smallest axis damping on every axis, and the remainder (each
    axis' damping less that) is left to `PassiveJoints`.  On the implicit
    design (revolute Cardan chains) each damper is split by `step_split`:
    SAP's part on the joint, the explicit part as the remainder."""
    for jname, joint, axes in _each_joint(plant, human):
        damping = _joint_damping(params, jname, axes)
        if len(axes) > 1:
            floor = float(np.min(damping))
            yield joint, np.full(len(axes), floor), damping - floor
        else:
            yield joint, damping, step_split(params, _joint_gains(params, jname, axes)[0])[1]
    implicit, explicit = step_split(params, params.passive.spine_axial_damping)
    yield (plant.GetJointByName("spinal_compression", human), [float(implicit)],
           np.array([float(explicit)]))


def _set_default_joint_damping(plant, human, params: ModelParams) -> None:
    for joint, damping, _ in _joint_damping_vectors(plant, human, params):
        joint.set_default_damping_vector(damping)


def damping_remainder(plant, human, params: ModelParams, layout: JointLayout) -> np.ndarray:
    """Per rotational DoF of `layout`, then for the spinal compression, the
    joint damping the Drake joint does not apply (see
    `_joint_damping_vectors`), N m s/rad and N s/m."""
    out = np.zeros(layout.num_rotational + 1)
    where = {v: i for i, v in enumerate(layout.rot_v)}
    where[layout.spine_v] = layout.num_rotational
    for joint, _, rest in _joint_damping_vectors(plant, human, params):
        for i, r in enumerate(rest):
            index = where.get(joint.velocity_start() + i)
            if index is not None:
                out[index] = r
    return out


def _joint_springs(plant, human, params: ModelParams):
    """((joint name, axis), Drake joint, stiffness) of each single-DoF joint
    of the human: the rotational joints (passive + PID kp; implicit design)
    and the spinal compression (axis "axial")."""
    for jname, joint, axes in _each_joint(plant, human):
        if len(axes) == 1:
            yield (jname, axes[0]), joint, float(_joint_gains(params, jname, axes)[1][0])
    spine = plant.GetJointByName(SPINE_AXIAL[0], human)
    yield SPINE_AXIAL, spine, params.passive.spine_axial_stiffness


def _add_pd_actuators(plant, human, params: ModelParams, stiff: frozenset) -> None:
    """Implicit design: a PD-controlled actuator (stiffness: passive spring +
    PID proportional gain, about the reference angle 0) on each joint DoF
    whose spring is in `stiff` (`stepping.implicit_springs`); SAP
    integrates its stiffness implicitly, the damping stays the joint's."""
    for key, joint, stiffness in _joint_springs(plant, human, params):
        if key in stiff and stiffness > 0:
            actuator = plant.AddJointActuator(f"{joint.name()}_pd", joint)
            actuator.set_controller_gains(PdControllerGains(p=stiffness, d=0.0))


def _connect_pd_targets(builder: DiagramBuilder, plant, human) -> None:
    """The PD actuators' set points: every joint at its reference angle (0)
    at rest; no feed-forward actuation (the slow loops act through the
    applied generalized force)."""
    port = plant.get_desired_state_input_port(human)
    target = builder.AddNamedSystem("pd_targets", ConstantVectorSource(np.zeros(port.size())))
    builder.Connect(target.get_output_port(), port)
    u = builder.AddNamedSystem("pd_feedforward",
                               ConstantVectorSource(np.zeros(plant.num_actuated_dofs())))
    builder.Connect(u.get_output_port(), plant.get_actuation_input_port())


def _pd_stiffness_vectors(plant, human, params: ModelParams, layout: JointLayout,
                          stiff: frozenset):
    """The PD actuators' stiffness per DoF of `layout` (zero where the spring
    is explicit): the passive part (rotational DoFs, then the spinal
    compression) and the PID's kp."""
    k = passive_stiffness_vector(params, layout)
    kp = pid_vectors(params, layout)["kp"]
    where = {v: i for i, v in enumerate(layout.rot_v)}
    where[layout.spine_v] = layout.num_rotational
    mask = np.zeros(layout.num_rotational + 1, bool)
    for key, joint, _ in _joint_springs(plant, human, params):
        mask[where[joint.velocity_start()]] = key in stiff
    return np.where(mask, k, 0.0), np.where(mask[:-1], kp, 0.0)


# ---------------------------------------------------------------------------
# Contact
# ---------------------------------------------------------------------------


def _hydroelastic_modulus(k: float, semi_axes, load: float) -> float:
    """Hydroelastic modulus giving tangent stiffness `k` at normal `load`.

    For an ellipsoid (a, b, c) pressed along c into a rigid plane, Drake's
    pressure field (linear in normalized depth) gives F = pi E a b d^2 / c^2,
    hence dF/dd = 2 sqrt(pi E a b F) / c and E = k^2 c^2 / (4 pi a b F).
    """
    a, b, c = semi_axes
    return k * k * c * c / (4.0 * math.pi * a * b * load)


def body_contact_properties(params: ModelParams, pair: str, semi_axes, body_weight: float,
                            seat_part_moves: bool = False):
    """ProximityProperties of a body ellipsoid of contact pair `pair`."""
    cp = getattr(params.contact, pair)
    props = ProximityProperties()
    k_body = cp.stiffness * SEAT_POINT_STIFFNESS / (SEAT_POINT_STIFFNESS - cp.stiffness)
    AddContactMaterial(
        dissipation=None,
        point_stiffness=k_body,
        friction=CoulombFriction(0.0, 0.0),
        properties=props,
    )
    # Relaxation times add up over the pair; the seat's is zero.  SAP's
    # contact force is implicit, k (x + tau xdot) at the step's end; on the
    # implicit design tau carries SAP's part of the damping, less the h k of
    # its implicit spring, and `ShearRestraints` the explicit part
    # (`model.stepping`).  Against a seat part that moves (a cushion link),
    # SAP carries the whole damper: the explicit part, applied at the body
    # point's velocity in S, would damp the body's absolute motion instead
    # of its motion relative to the part.
    split = sap_damping if seat_part_moves else step_damping
    props.AddProperty("material", "relaxation_time",
                      float(split(params, cp.damping, cp.stiffness)) / cp.stiffness)
    if params.contact.model == "hydroelastic":
        load = NOMINAL_LOAD_SHARE[pair] * body_weight
        AddCompliantHydroelasticProperties(
            resolution_hint=params.contact.hydroelastic_resolution_m,
            hydroelastic_modulus=_hydroelastic_modulus(cp.stiffness, semi_axes, load),
            properties=props,
        )
    return props


def _seat_contact_properties(params: ModelParams):
    props = ProximityProperties()
    AddContactMaterial(
        dissipation=0.0,
        point_stiffness=SEAT_POINT_STIFFNESS,
        friction=CoulombFriction(0.0, 0.0),
        properties=props,
    )
    props.AddProperty("material", "relaxation_time", 0.0)
    if params.contact.model == "hydroelastic":
        AddRigidHydroelasticProperties(properties=props)
    return props


def _collision_geometries(plant, scene_graph, instance) -> dict[str, object]:
    inspector = scene_graph.model_inspector()
    out = {}
    for b in plant.GetBodyIndices(instance):
        for gid in plant.GetCollisionGeometriesForBody(plant.get_body(b)):
            out[inspector.GetName(gid).split("::")[-1]] = gid
    return out


def moving_seat_parts(plant, seat, seat_geometries: dict, inspector) -> frozenset[str]:
    """The seat parts whose geometry sits on a link that moves relative to
    the seat (a joint with degrees of freedom: the `seat_cushion_dynamics`
    cushion); the others are fixed in S."""
    moving_bodies = {plant.get_joint(j).child_body().index()
                     for j in plant.GetJointIndices(seat)
                     if plant.get_joint(j).num_velocities() > 0}
    return frozenset(part for part, gid in seat_geometries.items()
                     if plant.GetBodyFromFrameId(inspector.GetFrameId(gid)).index()
                     in moving_bodies)


def _set_contact_properties(plant, scene_graph, human, seat, params, body: Body):
    """Contact materials of the body ellipsoids and seat parts, and the
    filter letting only the listed pairs touch.  Returns the body
    geometries, the seat geometries and the seat parts that move
    (`moving_seat_parts`)."""
    inspector = scene_graph.model_inspector()
    source = plant.get_source_id()
    body_weight = body.total_mass * 9.81
    geoms = _collision_geometries(plant, scene_graph, human)
    seat_geoms = _collision_geometries(plant, scene_graph, seat)
    body_geoms = {}
    allowed = set()
    moving = moving_seat_parts(plant, seat, seat_geoms, inspector)
    for pair, (names, part) in CONTACT_PAIRS.items():
        for name in names:
            gid = geoms[name]
            shape = inspector.GetShape(gid)
            props = body_contact_properties(params, pair, (shape.a(), shape.b(), shape.c()),
                                            body_weight, part in moving)
            scene_graph.AssignRole(source, gid, props, RoleAssign.kReplace)
            body_geoms[name] = (gid, pair)
            allowed.add((name, part))
    for gid in seat_geoms.values():
        scene_graph.AssignRole(source, gid, _seat_contact_properties(params), RoleAssign.kReplace)
    # Only the listed pairs may touch.
    manager = scene_graph.collision_filter_manager()
    for name, (gid, _) in body_geoms.items():
        for part, sid in seat_geoms.items():
            if (name, part) not in allowed:
                manager.Apply(
                    CollisionFilterDeclaration().ExcludeBetween(GeometrySet(gid), GeometrySet(sid))
                )
    return body_geoms, seat_geoms, moving
