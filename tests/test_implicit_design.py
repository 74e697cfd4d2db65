"""The implicit design (`simulation.design: implicit`): the human's joints as
Cardan chains of revolute joints whose stiff feedback SAP integrates
implicitly.  It must be the same body as the reference design (kinematics,
posture, the split of the joint torques between plant and Python systems)
and respond like it, so that its step can be chosen by accuracy."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from pydrake.systems.framework import DiagramBuilder

from ehm_drake.analysis.linear import linearize
from ehm_drake.diagram import build_diagram
from ehm_drake.model.plant import (
    add_seated_human,
    passive_stiffness_vector,
    pid_vectors,
    step_damping,
    step_damping_limits,
    step_split,
)
from ehm_drake.model.softening import long_range_contacts
from ehm_drake.model.stepping import segment_frequencies
from ehm_drake.params import CONTACT_PAIRS, apply_variant, load_params, reference_design
from ehm_drake.signals import make_seat_signal
from ehm_drake.simulation import settle, static_equilibrium, vibrate
from ehm_drake.systems.joints import _BallIndex, cardan_rates, rpy_rate_matrices
from ehm_drake.systems.outputs import CHANNEL_NAMES
from ehm_drake.systems.rotations import rotation_from_rpy


def implicit(h: float = 0.001):
    p = load_params()
    p.simulation.design = "implicit"
    p.simulation.time_step_s = h
    return p


def _plant(params):
    """The plant as `build_diagram` makes it: the contacts at their
    long-range stiffness (`ehm_drake.model.softening`)."""
    builder = DiagramBuilder()
    hp = add_seated_human(builder, long_range_contacts(params), rest_params=params)
    diagram = builder.Build()
    return hp, diagram


def test_cardan_chain_is_the_ball_joint_kinematics():
    """The same Cardan angles put every body in the same pose."""
    ref, _ = _plant(reference_design(load_params()))
    imp, _ = _plant(implicit())
    assert ref.layout.names == imp.layout.names
    assert imp.layout.ball_triplets.size == 0  # no ball joint left
    rng = np.random.default_rng(3)
    angles = rng.uniform(-0.3, 0.3, ref.layout.num_rotational)
    poses = []
    for hp in (ref, imp):
        ctx = hp.plant.CreateDefaultContext()
        q = hp.plant.GetPositions(ctx)
        q[hp.layout.rot_q] = angles
        q[hp.layout.spine_q] = -0.004
        hp.plant.SetPositions(ctx, q)
        poses.append({hp.plant.get_body(b).name(): hp.plant.EvalBodyPoseInWorld(
            ctx, hp.plant.get_body(b)).GetAsMatrix4() for b in hp.plant.GetBodyIndices(hp.human)})
    common = set(poses[0]) & set(poses[1])
    assert len(common) == 13  # the 12 segments and the spine slider
    for name in common:
        np.testing.assert_allclose(poses[1][name], poses[0][name], atol=1e-12, err_msg=name)


@pytest.mark.parametrize(("variant", "step"), [("default", 0.001), ("high-stiffness", 0.005)])
def test_springs_are_applied_once_and_the_plant_carries_half_of_each_damper(variant, step):
    """The implicit design applies each joint spring once: at the step's
    start (`PassiveJoints` and the PID's proportional part) or, where the
    step is too large for that (`stepping.implicit_springs`), as a SAP PD
    actuator, which the systems then leave out; and it splits every joint
    damper between the plant's joint damping and `PassiveJoints`."""
    params = implicit(step)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = build_diagram(params, variant=variant, guard=False, seat_forces=False)
    params = model.params  # the variant's
    hp, L = model.hp, model.hp.layout
    k = passive_stiffness_vector(params, L)
    kp = pid_vectors(params, L)["kp"]
    pd = {hp.plant.get_joint_actuator(a).joint().velocity_start():
          hp.plant.get_joint_actuator(a).get_controller_gains().p
          for a in hp.plant.GetJointActuatorIndices()}
    assert (len(pd) == 0) == (variant == "default")
    np.testing.assert_allclose([pd.get(v, 0.0) for v in L.rot_v], hp.implicit_stiffness[:-1])
    ctx = model.diagram.CreateDefaultContext()
    pc = model.plant_context(ctx)
    q = model.plant.GetPositions(pc)
    q[L.rot_q] = np.linspace(-0.1, 0.1, L.num_rotational)
    q[L.spine_q] = -0.003
    model.plant.SetPositions(pc, q)
    f = sum(s.GetOutputPort("generalized_force").Eval(s.GetMyContextFromRoot(ctx))
            for s in (model.systems["passive_joints"], model.systems["joint_pid"]))
    f[L.rot_v] -= hp.implicit_stiffness[:-1] * q[L.rot_q]  # the PD actuators' part
    np.testing.assert_allclose(f[L.rot_v], -(k[:-1] + kp) * q[L.rot_q], rtol=1e-12)
    assert f[L.spine_v] == pytest.approx(-k[-1] * q[L.spine_q], rel=1e-12)
    spine = hp.plant.GetJointByName("spinal_compression", hp.human)
    c = params.passive.spine_axial_damping
    assert spine.GetDampingVector(pc)[0] == pytest.approx(c / 2)
    assert hp.damping_remainder[-1] == pytest.approx(c / 2)


def test_step_split_makes_each_damper_central():
    """Half of each damper at the step's end (SAP), half at its start; a
    spring SAP integrates itself (the contact's) adds h k at the end, which
    comes off SAP's half (`model.stepping`)."""
    p = implicit(0.005)
    c, k = 17.0, 540.0
    assert step_split(p, c) == (pytest.approx(c / 2), pytest.approx(c / 2))
    sap, explicit = step_split(p, c, k)
    assert sap + 0.005 * k == pytest.approx(c / 2) and explicit == pytest.approx(c / 2)
    sap, explicit = step_split(p, c, 2000.0)  # c / 2 < h k: SAP's part clipped
    assert sap == 0.0 and explicit == pytest.approx(c - 0.005 * 2000.0)
    assert step_split(p, c, 4000.0) == (0.0, 0.0)  # c < h k: over-damped
    assert step_split(reference_design(p), c, k) == (c, 0.0)
    assert step_damping(p, c, k) == step_split(p, c, k)[0]


def test_a_step_beyond_the_second_order_one_is_warned_about():
    """Beyond h = c / (2 k) SAP's part of a contact damper is clipped at
    zero, and beyond omega h = STABLE_OMEGA_H a segment's stiffest springs
    become implicit: that part of the model is then first-order accurate;
    the build says which and the largest step that keeps it."""
    p = implicit(0.005)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        hp, _ = _plant(p)  # every part of the parameter file's body allows 5 ms
    limits = step_damping_limits(hp.plant, hp.human, long_range_contacts(p), hp.body)
    assert {f"contact {pair}" for pair in CONTACT_PAIRS} <= set(limits)
    # The first to go: the lower-torso slab's pitch, against L5/S1 and L4/L5.
    first = min(limits, key=limits.get)
    assert first == "lower_torso_y" and 0.005 < limits[first] < 0.0065
    p.contact.feet_floor.damping = 240.0  # c / 2k = 3 ms
    with pytest.warns(UserWarning, match=r"contact feet_floor \(3 ms\).*at most 0.003 s"):
        _plant(p)
    assert step_split(p, 240.0, p.contact.feet_floor.stiffness)[0] == 0.0


def test_segment_frequencies_are_the_local_spring_modes():
    """A segment turns against its joint's spring and its child joints'
    springs: the lower torso's pitch frequency is sqrt((k_L5S1 + k_L4L5) /
    I_y), I_y about the L5/S1 centre; a spring made implicit drops out."""
    p = implicit(0.005)
    hp, _ = _plant(p)
    body = hp.body
    k = {"lumbosacral_L5S1": np.array(p.passive.lumbar.stiffness) + np.array(p.pid.spine.kp),
         "lumbar_L4L5": np.array(p.passive.lumbar.stiffness) + np.array(p.pid.spine.kp)}
    seg = body.segments["lower_torso"]
    r = seg.com_W - seg.origin_W
    I_y = seg.inertia_W[1, 1] + seg.mass * (r[0] ** 2 + r[2] ** 2)
    f = segment_frequencies(body, k, 0.0)
    omega, springs = f[("lower_torso", 1)]
    assert omega == pytest.approx(np.sqrt((k["lumbosacral_L5S1"][1] + k["lumbar_L4L5"][1]) / I_y))
    assert set(springs) == {("lumbosacral_L5S1", 1), ("lumbar_L4L5", 1)}
    omega, _ = segment_frequencies(body, k, 0.0, {("lumbar_L4L5", 1)})[("lower_torso", 1)]
    assert omega == pytest.approx(np.sqrt(k["lumbosacral_L5S1"][1] / I_y))


@pytest.mark.parametrize(("variant", "step", "stiff"), [
    ("default", 0.005, 0), ("default", 0.0075, 2), ("high-stiffness", 0.005, 8)])
def test_stiff_springs_go_implicit_and_keep_the_step_stable(variant, step, stiff):
    """With every spring explicit the linearized closed loop diverges at
    7.5 ms on the default body and at 3 ms on the high-stiffness variant
    (the lower-torso slab's pitch and yaw, a period-2 mode); with the
    stiffest springs made SAP PD actuators (`stepping.implicit_springs`)
    the step map's eigenvalues stay inside the unit circle."""
    p = implicit(step)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # beyond the second-order step, as the build says
        model = build_diagram(p, variant=variant, guard=False, seat_forces=False)
    assert model.plant.num_actuators() == stiff
    ctx, _ = static_equilibrium(model)
    lam = linearize(model, ctx, method="fd").eig()[0]
    assert np.max(np.abs(lam)) < 1.0


def test_posture_is_held_at_a_5_ms_step():
    params = implicit(0.005)
    settled = settle(params, settle_time=2.0)
    assert settled.summary["max_joint_error_deg"] < 1e-6
    s = params.simulation
    signal = make_seat_signal("random", "xyz", 0.5, 3.0, 2, s.time_step_s, 2.0, 0.5)
    result = vibrate(params, settled, signal)
    assert np.all(np.isfinite(result.channels))
    assert np.max(np.abs(np.degrees(result.joint_torques))) > 0  # it moved


def _parameter_damping(params, layout):
    """Passive damping + PID derivative gain per rotational DoF: the
    parameter file's joint damping about each Cardan axis."""
    from ehm_drake.model.joint_layout import PID_GROUP_OF
    return np.array([getattr(params.passive, g).damping[a]
                     + getattr(params.pid, PID_GROUP_OF[g]).kd[a]
                     for g, a in zip(layout.groups, layout.axes, strict=True)])


@pytest.mark.parametrize("design", ["reference", "implicit"])
def test_every_axis_gets_its_own_damping(design):
    """Drake's ball and universal joints apply their first damping entry to
    every axis; so the plant gives them their smallest axis damping, and
    `PassiveJoints` the rest, about the Cardan rates.  Near the reference
    posture the damping on each DoF is then the parameter file's."""
    params = load_params()
    params.simulation.design = design
    model = build_diagram(params, guard=False, seat_forces=False)
    hp, L = model.hp, model.hp.layout
    ctx = model.diagram.CreateDefaultContext()
    pc = model.plant_context(ctx)
    joint_damping = np.zeros(model.plant.num_velocities())
    for j in model.plant.GetJointIndices(hp.human):
        joint = model.plant.get_joint(j)
        d = joint.GetDampingVector(pc)
        if joint.num_velocities() > 1:  # one value for all axes
            assert np.ptp(d) == 0.0, joint.name()
        joint_damping[joint.velocity_start():joint.velocity_start() + len(d)] = d
    expected = _parameter_damping(params, L)
    if design == "reference":
        assert np.count_nonzero(hp.damping_remainder) >= 12  # spine, hips, neck
        assert hp.damping_remainder[-1] == 0.0  # the spinal compression's is the joint's
    else:
        # Each damper split half and half between SAP and PassiveJoints.
        np.testing.assert_allclose(hp.damping_remainder[:-1], expected / 2, rtol=1e-12)
    # The damping force of PassiveJoints at the reference posture, for a
    # velocity of 1 rad/s on every rotational DoF.
    v = model.plant.GetVelocities(pc)
    v[:] = 0.0
    v[L.rot_v] = 1.0
    model.plant.SetVelocities(pc, v)
    s = model.systems["passive_joints"]
    f = s.GetOutputPort("generalized_force").Eval(s.GetMyContextFromRoot(ctx))
    np.testing.assert_allclose(joint_damping[L.rot_v] - f[L.rot_v], expected, rtol=1e-12)


def test_cardan_rates_are_the_rpy_rate_mapping():
    params = reference_design(load_params())
    hp, _ = _plant(params)
    L = hp.layout
    rng = np.random.default_rng(7)
    q = rng.uniform(-0.6, 0.6, L.num_rotational)
    w = rng.normal(size=L.num_rotational)
    rates = cardan_rates(_BallIndex(L), q, w)
    b = L.ball_triplets
    assert len(b) >= 3
    expected = w.copy()
    expected[b] = np.einsum("nij,nj->ni", rpy_rate_matrices(q[b]), w[b])
    np.testing.assert_allclose(rates, expected, rtol=1e-13, atol=1e-13)


def _transmissibility(params, freqs):
    model = build_diagram(params, guard=False, seat_forces=False)
    ctx, _ = static_equilibrium(model)
    return np.abs(linearize(model, ctx, method="fd").transmissibility_array(freqs))


def _responds(T):
    """Bins where a channel responds to the input: gain at least a tenth of
    the channel's peak, and the channel's peak at least a tenth of the
    largest of its kind (translation or rotation) under that input (the
    symmetric body's cross-axis channels are near zero: their ratios are
    numerical noise)."""
    peak = T.max(axis=0)
    rotation = np.array([n.endswith(("roll", "pitch", "yaw")) for n in CHANNEL_NAMES])
    strong = np.zeros_like(peak, bool)
    for kind in (rotation, ~rotation):
        strong[kind] = peak[kind] >= 0.1 * peak[kind].max(axis=0, keepdims=True)
    return (T >= 0.1 * peak[None]) & strong[None]


@pytest.mark.parametrize("variant", ["default", "no-integrator"])
def test_designs_are_the_same_model(variant):
    """Linearized where both have converged in the step (the reference
    design, first-order, at 0.1 ms; the implicit one, second-order, at
    1 ms), the two designs give the same transmissibility: within 0.3%
    median and 3% in every bin of every channel that responds to x, y or z
    (`_responds`; measured 0.13% / 1.8% default, 0.19% / 1.7% without
    integrator).  Three differences were found and removed this way: Drake's
    one damping value per ball joint (the median was 9%, head pitch under x
    45% off), the reference PID's torques on the ball joints' angular
    velocities instead of the Cardan axes (default worst bin 4.6%) and the
    implicit design's explicit contact damper at the restraint point
    instead of the contact point (no-integrator 6.7%, knee pitch under z)."""
    freqs = np.linspace(0.5, 12.0, 24)
    reference = apply_variant(reference_design(load_params()), variant)
    reference.simulation.time_step_s = 0.0001
    T = {name: _transmissibility(params, freqs) for name, params in
         (("ref", reference), ("imp", apply_variant(implicit(0.001), variant)))}
    ratio = np.abs(T["imp"] / T["ref"] - 1.0)
    responds = _responds(T["ref"])
    assert np.median(ratio[responds]) < 0.003
    worst = np.unravel_index(np.argmax(np.where(responds, ratio, 0.0)), ratio.shape)
    assert ratio[worst] < 0.03, (freqs[worst[0]], CHANNEL_NAMES[worst[1]], "xyz"[worst[2]],
                                 ratio[worst])


def test_the_implicit_design_is_left_right_symmetric():
    """The body and seat are mirror-symmetric, so excitation in the
    sagittal plane (x, z) moves no midline segment sideways, in roll or in
    yaw, and lateral excitation (y) none in x, z or pitch: those paths are
    zero to the linearization's rounding on both designs, and the fit
    leaves out the same ones (`structural_zeros`).  The implicit design's
    restraint constraints once broke it: their lateral anchors, all on one
    side 2 m away, tilted by the settled offset, coupled vertical motion into
    trunk roll at 3e-4 of its pitch, and the fit then fitted those paths'
    noise (`model.restraints.CONSTRAINT_LENGTH_M`)."""
    from ehm_drake.identification.evaluation import structural_zeros

    freqs = np.linspace(0.5, 12.0, 24)
    zeros = {}
    for name, params in (("ref", load_params()), ("imp", implicit(0.005))):
        model = build_diagram(params, guard=False, seat_forces=False)
        ctx, _ = static_equilibrium(model)
        T = linearize(model, ctx, method="fd", outputs=["channels"]).transmissibility_array(
            freqs, "xyz")
        zeros[name] = structural_zeros(T, "xyz")
    midline = ("pelvis", "trunk", "head")
    mirror = {(d, f"{s}_{c}") for s in midline
              for d, cs in (("x", ("y", "roll", "yaw")), ("z", ("y", "roll", "yaw")),
                            ("y", ("x", "z", "pitch"))) for c in cs}
    assert mirror <= zeros["ref"]
    assert zeros["imp"] == zeros["ref"]


def _step_errors(steps, freqs):
    """|T(h) / T(converged) - 1| of the implicit design's linearization over
    the responding bins of x, y and z, for each step h (converged: 0.5 ms)."""
    truth = _transmissibility(implicit(0.0005), freqs)
    responds = _responds(truth)
    return [np.abs(_transmissibility(implicit(h), freqs) / truth - 1.0)[responds]
            for h in steps]


def test_the_implicit_step_is_second_order():
    """`model.stepping` makes every spring act at the step's start and every
    damper at the mean of its start and end velocity: the step is then
    second-order accurate.  Halving the step from 5 to 2.5 ms divides the
    transmissibility error by about four (measured: 4.1 at the median, 3.4
    at the 90th percentile; 2 for the all-implicit step it replaced, whose
    error at 5 ms was 2.7% median, 44% worst; the worst bin, 2.6, carries
    the explicit head-in-space and integral terms), and at 5 ms it stays
    within 1% median and 6% in the worst bin (measured: 0.33%, 4.1%)."""
    freqs = np.linspace(0.5, 12.0, 24)
    e5, e25 = _step_errors((0.005, 0.0025), freqs)
    assert np.median(e5) < 0.01 and np.max(e5) < 0.06
    assert np.median(e5) / np.median(e25) > 3.5
    assert np.percentile(e5, 90) / np.percentile(e25, 90) > 3.0


def test_restraint_constraints_sit_at_the_restraint_points():
    """On the implicit design each shear restraint axis is a compliant
    distance constraint from the restraint's body point to an anchor
    behind its seat anchor, carrying half of the restraint's damping (and
    a token stiffness); and the static equilibrium is the reference
    design's (`ShearRestraints` cancels the constraints' force at the
    step's start)."""
    from ehm_drake.model.restraints import CONSTRAINT_LENGTH_M, CONSTRAINT_STIFFNESS
    from ehm_drake.systems.seat import restraint_points

    p = implicit(0.005)
    model = build_diagram(p, guard=False, seat_forces=False)
    rc = model.hp.restraint_constraints
    points = restraint_points(model.hp)
    assert len(rc.length) == 2 * len(points)
    for i, pt in enumerate(points):
        r = getattr(p.restraints, pt.pair)
        for a, axis in enumerate(pt.axes):
            j = 2 * i + a
            np.testing.assert_allclose(rc.p_SQ[j] + rc.length[j] * axis, pt.p_SA, atol=1e-9)
            assert rc.length[j] == CONSTRAINT_LENGTH_M and rc.stiffness[j] == CONSTRAINT_STIFFNESS
            assert rc.step_damping[j] == pytest.approx(r.damping / 2)
    ref = build_diagram(reference_design(p), guard=False, seat_forces=False)
    x = {}
    for name, m in (("imp", model), ("ref", ref)):
        ctx, _ = static_equilibrium(m)
        s = m.systems["body_channels"]
        x[name] = np.array(s.marker_poses(m.plant.GetPositionsAndVelocities(
            m.plant_context(ctx)))[2][0])  # head marker position
    np.testing.assert_allclose(x["imp"], x["ref"], atol=2e-5)


def test_contact_points_are_the_ellipsoids_deepest_points():
    """`contact_points_B`: the point of the ellipsoid whose outward normal
    is against the seat part's (the deepest into it), for any orientation;
    in the reference posture the restraint's attachment point."""
    from ehm_drake.model.restraints import contact_points_B

    rng = np.random.default_rng(4)
    semi = rng.uniform(0.03, 0.2, (20, 3))
    centre = rng.normal(scale=0.1, size=(20, 3))
    normal = np.tile([0.0, 0.0, 1.0], (20, 1))
    R = np.array([rotation_from_rpy(rng.uniform(-0.4, 0.4, 3)) for _ in range(20)])
    C = contact_points_B(R, centre, semi, normal)
    d = (C - centre) / semi
    np.testing.assert_allclose(np.sum(d * d, axis=1), 1.0, rtol=1e-12)  # on the surface
    outward = np.einsum("kij,kj->ki", R, (C - centre) / semi**2)  # its normal, in S
    np.testing.assert_allclose(outward / np.linalg.norm(outward, axis=1)[:, None], -normal,
                               atol=1e-12)
    C0 = contact_points_B(np.tile(np.eye(3), (20, 1, 1)), centre, semi, normal)
    np.testing.assert_allclose(C0, centre - semi * normal, atol=1e-15)


@pytest.mark.parametrize("variant", ["default", "no-integrator"])
def test_the_explicit_contact_damper_acts_where_sap_touches(variant):
    """The implicit design splits each contact damper between SAP, which
    applies it at the contact point, and `ForceLaws`: its explicit half acts
    at the ellipsoid's deepest point, on the line of Drake's contact point
    along the normal (only the tangential position sets a normal force's
    moment; measured 0.002-0.48 mm off it against the seat's half-spaces,
    0.003-0.53 mm against its boxes before stop 48), not at the restraint's
    body-fixed point,
    which the body's rotation carries off it (0.5-3.8 mm in the default
    posture, 1.6-24 mm where the no-integrator posture turns trunk and
    legs).  Until stop
    40 it acted at the restraint point, and the no-integrator variant's two
    designs differed by 6.7% (knee pitch under z; now 1.7%)."""
    p = apply_variant(implicit(0.005), variant)
    model = build_diagram(p, guard=False, seat_forces=False)
    ctx, _ = static_equilibrium(model)
    plant, pc = model.plant, model.plant_context(ctx)
    geometry = model.systems["force_laws"]._geometry
    C_B = np.concatenate(geometry.contact_points(plant, pc), axis=1)
    P_B = np.concatenate([P for _, P, _ in geometry.groups], axis=1)
    inspector = model.hp.scene_graph.model_inspector()
    results = plant.get_contact_results_output_port().Eval(pc)
    drake = {}
    for i in range(results.num_point_pair_contacts()):
        info = results.point_pair_contact_info(i)
        name = inspector.GetName(info.point_pair().id_A).split("::")[-1]
        drake[name] = info.contact_point()
    # Every ellipsoid touches (the no-integrator body leaves its upper pad).
    assert set(drake) == {pt.name for pt in geometry.points} - (
        {"upper_back"} if variant == "no-integrator" else set())
    off = {}
    for k, row in enumerate(geometry.order):
        point = geometry.points[row]
        if point.name not in drake:
            continue
        X_WB = plant.EvalBodyPoseInWorld(pc, plant.GetBodyByName(point.body))
        tangential = np.eye(3) - np.outer(point.normal, point.normal)
        d_C = tangential @ (X_WB.multiply(C_B[:, k]) - drake[point.name])
        d_P = tangential @ (X_WB.multiply(P_B[:, k]) - drake[point.name])
        assert np.linalg.norm(d_C) < 1e-3, (point.name, d_C)
        off[point.name] = np.linalg.norm(d_P)
    assert max(off.values()) > (1e-2 if variant == "no-integrator" else 3e-3), off


def test_unknown_design_is_refused_by_name():
    from ehm_drake.params import ParameterError, params_from_dict

    with pytest.raises(ParameterError, match=r"simulation.design = 'fast'.*'implicit' or "
                                             r"'reference'"):
        params_from_dict({"simulation": {"design": "fast"}})


def test_the_benchmark_books_every_python_part_of_a_step_and_restores_the_systems(
        monkeypatch):
    # `bench/bench_simulate.py`'s step split times the methods Drake calls by
    # name: each must exist (a renamed one would drop out of the split
    # unnoticed), each part must be met in a short run, and the systems'
    # methods are the originals afterwards.
    import importlib

    from bench_scripts import bench_script

    bench = bench_script("bench_simulate")
    originals = {}
    for _part, (module, name, methods) in bench.PARTS.items():
        cls = getattr(importlib.import_module(module), name)
        for m in methods:
            assert m in vars(cls), f"{name}.{m} is gone: update bench_simulate.PARTS"
            originals[(cls, m)] = vars(cls)[m]
    p = load_params()
    p.simulation.design, p.simulation.time_step_s = "implicit", 0.005
    p.simulation.settle_time_s = p.simulation.onset_time_s = 0.2
    settled = settle(p)
    s = p.simulation
    signal = make_seat_signal("random", "xyz", 0.2, 0.3, 1, s.time_step_s, s.settle_time_s,
                              s.onset_time_s)
    split = bench.step_split(p, settled, signal)
    for part in ("force laws", "softening", "seat forces (derived from the log)"):
        assert split[part] > 0, part
    # Where the seat forces are summed from the contact results each step.
    import ehm_drake.diagram as diagram_module

    monkeypatch.setattr(diagram_module.ContactDecomposition, "of",
                        classmethod(lambda cls, hp: None))
    split = bench.step_split(p, settled, signal)
    for part in ("seat forces (logged)", "plant's step (under the logged seat forces)"):
        assert split[part] > 0, part
    assert all((cls, m) in originals and vars(cls)[m] is fn for (cls, m), fn in originals.items())
