"""`ForceLaws`: the five force laws in one system.  It must
be the five separate systems (passive joints, joint PID, head-in-space,
shear restraints, seat inertial load) to rounding: the same generalized
force, torques, seat forces and discrete updates at any state, for the
paper's variants and with every optional branch of the restraint law; and
it must keep the parts addressable under their old names."""

from __future__ import annotations

import os

import numpy as np
import pytest
from pydrake.systems.framework import BasicVector, DiagramBuilder
from pydrake.systems.primitives import PassThrough

from ehm_drake.diagram import _force_laws, build_diagram, separate_force_systems
from ehm_drake.model.plant import add_seated_human
from ehm_drake.params import apply_variant, load_params, reference_design
from ehm_drake.simulation import StateMap, static_equilibrium
from ehm_drake.systems.forces import LAWS, LawView
from ehm_drake.systems.rotations import rotation_from_rpy, rpy_from_rotation
from ehm_drake.systems.seat import restraint_block

#: Forces agree to this fraction of the largest force (rounding of a
#: reordered sum of terms up to ~1e3 N).
RTOL = 1e-12
RESTRAINT_OUTPUTS = ("point_forces", "normal_displacement", "deflection")


#: The laws of `ForceLaws` are those of the paper's linear model; the body's
#: softening is a system of its own (`tests/test_softening.py`).
PAPER = "paper_linear"


def implicit(h: float = 0.005):
    p = load_params(PAPER)
    p.simulation.design = "implicit"
    p.simulation.time_step_s = h
    return p


class Rig:
    """The plant with both the five systems and `ForceLaws` on it, fed the
    same plant state, controller state (an exported input, so it can
    differ from the plant's, as under a feedback delay) and seat
    acceleration."""

    def __init__(self, params, variant="default"):
        params = apply_variant(params, variant)
        h = params.simulation.time_step_s
        builder = DiagramBuilder()
        self.hp = hp = add_seated_human(builder, params)
        accel = builder.AddSystem(PassThrough(3))
        feedback = builder.AddSystem(PassThrough(hp.layout.nq + hp.layout.nv))
        builder.ExportInput(accel.get_input_port(), "seat_acceleration")
        builder.ExportInput(feedback.get_input_port(), "controller_state")
        state = hp.plant.get_state_output_port()
        self.old = {}
        forces, _ = separate_force_systems(builder, hp, params, h, accel.get_output_port(),
                                             self.old)
        for s in forces:
            controller = s in (self.old["joint_pid"], self.old["head_in_space"])
            builder.Connect(feedback.get_output_port() if controller else state,
                            s.GetInputPort("state"))
        self.laws = builder.AddSystem(_force_laws(hp, params, h, feedback_input=True))
        builder.Connect(state, self.laws.GetInputPort("state"))
        builder.Connect(feedback.get_output_port(), self.laws.GetInputPort("controller_state"))
        builder.Connect(accel.get_output_port(), self.laws.GetInputPort("seat_acceleration"))
        self.diagram = builder.Build()
        self.ctx = self.diagram.CreateDefaultContext()
        hp.plant.get_applied_generalized_force_input_port().FixValue(
            hp.plant.GetMyMutableContextFromRoot(self.ctx), np.zeros(hp.layout.nv))
        self.x0 = hp.plant.GetPositionsAndVelocities(hp.plant.CreateDefaultContext())

    def sub(self, system):
        return system.GetMyMutableContextFromRoot(self.ctx)

    def randomize(self, rng, delayed: bool):
        """A random state near the reference posture: plant state, the
        controllers' view of it, seat acceleration, PID integral and slip
        (the same in both implementations)."""
        hp, L = self.hp, self.hp.layout
        x = self.x0.copy()
        x[L.rot_q] += rng.uniform(-0.1, 0.1, L.num_rotational)
        x[L.spine_q] += rng.uniform(-3e-3, 3e-3)
        x[:L.nq][~np.isin(np.arange(L.nq), np.append(L.rot_q, L.spine_q))] += \
            rng.uniform(-5e-3, 5e-3, L.nq - L.num_rotational - 1)
        x[L.nq:] = rng.normal(scale=0.3, size=L.nv)
        hp.plant.SetPositionsAndVelocities(hp.plant.GetMyMutableContextFromRoot(self.ctx), x)
        xf = x + (rng.normal(scale=0.01, size=x.shape) if delayed else 0.0)
        self.diagram.GetInputPort("controller_state").FixValue(self.ctx, xf)
        self.diagram.GetInputPort("seat_acceleration").FixValue(self.ctx,
                                                                rng.normal(scale=0.5, size=3))
        z = rng.normal(scale=0.05, size=L.num_rotational)
        slip = rng.normal(scale=2e-3, size=2 * len(self.laws.restraint_points))
        for system, index, value in (
                (self.old["joint_pid"], self.old["joint_pid"].integral_state_index, z),
                (self.laws, self.laws.views["joint_pid"].integral_state_index, z),
                (self.old["shear_restraints"], self.old["shear_restraints"].slip_state_index,
                 slip),
                (self.laws, self.laws.views["shear_restraints"].slip_state_index, slip)):
            self.sub(system).SetDiscreteState(index, value)

    def set_restraint_parameters(self, change):
        """Apply `change(vector)` to both implementations' packed restraint
        parameters."""
        for system, index in ((self.old["shear_restraints"],
                               self.old["shear_restraints"].parameter_index),
                              (self.laws, self.laws.views["shear_restraints"].parameter_index)):
            prm = self.sub(system).get_mutable_numeric_parameter(index)
            v = prm.CopyToVector()
            change(v)
            prm.SetFromVector(v)

    def old_output(self, name, port="generalized_force"):
        s = self.old[name]
        return s.GetOutputPort(port).Eval(self.sub(s))

    def new_output(self, port):
        return self.laws.GetOutputPort(port).Eval(self.sub(self.laws))


def _close(new, old, scale=None):
    scale = np.max(np.abs(old)) if scale is None else scale
    np.testing.assert_allclose(new, old, rtol=0, atol=RTOL * max(scale, 1e-300))


def _compare(rig: Rig):
    total_old = sum(rig.old_output(name) for name in LAWS)
    scale = max(np.max(np.abs(rig.old_output(name))) for name in LAWS)
    _close(rig.new_output("generalized_force"), total_old, scale)
    for name in LAWS:
        _close(rig.new_output(f"{name}_generalized_force"), rig.old_output(name), scale)
    np.testing.assert_array_equal(rig.new_output("joint_torques"),
                                  rig.old_output("joint_pid", "torque"))
    _close(rig.new_output("his_torque"), rig.old_output("head_in_space", "torque"))
    _close(rig.new_output("restraint_seat_forces"),
           rig.old_output("shear_restraints", "seat_forces"))
    for port in RESTRAINT_OUTPUTS:
        _close(rig.new_output(port), rig.old_output("shear_restraints", port))
    # The discrete update: PID integral and slip (and the plant's, equal).
    update = rig.diagram.EvalUniquePeriodicDiscreteUpdate(rig.ctx)
    smap = StateMap(rig.diagram)
    x = np.concatenate([update.get_vector(g).CopyToVector()
                        for g in range(update.num_groups())])
    groups = {}
    for owner, size, start in zip(smap.systems, smap.sizes, smap.offsets, strict=False):
        groups[owner.get_name(), isinstance(owner, LawView)] = x[start:start + size]
    for name in ("joint_pid", "shear_restraints"):
        _close(groups[name, True], groups[name, False])


@pytest.mark.parametrize(("design", "variant"), [
    ("implicit", "default"), ("implicit", "no-integrator"), ("implicit", "high-stiffness"),
    ("reference", "default"), ("reference", "no-integrator"), ("reference", "high-stiffness")])
def test_the_merged_laws_are_the_separate_systems(design, variant):
    """At random states (and a controller view differing from the plant's,
    as under a feedback delay) the generalized force is the five systems'
    sum, each law's part its system's force, and torques, seat forces and
    the updates of the PID integral and the slip theirs, to 1e-12 of the
    largest force.  The high-stiffness variant has stiff springs as SAP PD
    actuators (their part left out of both); the reference design's ball
    joints take the Cardan mapping."""
    params = implicit() if design == "implicit" else reference_design(load_params(PAPER))
    if variant == "high-stiffness" and design == "implicit":
        with pytest.warns(UserWarning, match="beyond the second-order step"):
            rig = Rig(params, variant)
        assert rig.hp.implicit_kp is not None and np.any(rig.hp.implicit_kp)
    else:
        rig = Rig(params, variant)
    rng = np.random.default_rng(11)
    for i in range(12):
        rig.randomize(rng, delayed=i % 2 == 1)
        _compare(rig)


def _every_branch(v, points):
    """Switch on every branch of the restraint law in the packed parameter
    vector `v` of `points`: contact gating (the pads), cubic and linear
    normal forces, friction (elsewhere), small force limits (anchors slip)."""
    n = len(points)
    pads = np.array([p.part.endswith("pad") for p in points])
    restraint_block(v, "contact_gated")[:] = pads
    restraint_block(v, "normal_cubic_stiffness")[:] = 1e9
    restraint_block(v, "normal_reference")[:] = -1e-3
    restraint_block(v, "normal_linear_stiffness")[:] = np.linspace(0, 1e4, n)
    restraint_block(v, "normal_linear_damping")[:] = 50.0
    restraint_block(v, "friction_coefficient")[:] = np.where(pads, 0.0, 0.3)
    restraint_block(v, "force_limit")[:] = 5.0


def test_every_branch_of_the_restraint_law_agrees():
    """Contact gating, cubic and linear normal forces, Coulomb friction and
    a slipping anchor (deflection beyond the force limit) in both."""
    rig = Rig(implicit())
    rig.set_restraint_parameters(lambda v: _every_branch(v, rig.laws.restraint_points))
    rng = np.random.default_rng(5)
    for i in range(8):
        rig.randomize(rng, delayed=i % 2 == 1)
        _compare(rig)


@pytest.mark.parametrize("design", ["reference", "implicit"])
def test_the_parts_keep_their_names_parameters_and_states(design):
    """Each design's diagram has one force system, with its five laws under
    their old names: their parameters in their old layouts, the PID
    integral and the slip as state groups ``joint_pid`` and
    ``shear_restraints`` (the order of the separate systems' groups, so a
    settled state keeps its layout), and the plant fed without an Adder."""
    params = implicit() if design == "implicit" else load_params(PAPER)
    assert params.simulation.design == design
    model = build_diagram(params, guard=False, seat_forces=False)
    laws = model.systems["force_laws"]
    assert not model.diagram.HasSubsystemNamed("generalized_force_sum")
    assert {n: model.systems[n].system for n in LAWS} == {n: laws for n in LAWS}
    smap = StateMap(model)
    assert [s.get_name() for s in smap.systems] == ["plant", "joint_pid", "shear_restraints"]
    ctx = model.diagram.CreateDefaultContext()
    pid = model.systems["joint_pid"]
    n = model.hp.layout.num_rotational
    gains = pid.GetMyContextFromRoot(ctx).get_numeric_parameter(pid.parameter_index)
    assert gains.size() == 5 * n
    with pytest.raises(RuntimeError, match="joint_pid.*no output port 'seat_forces'"):
        pid.GetOutputPort("seat_forces")
    # Changing a part's parameter in the context changes that law.
    model.diagram.GetInputPort("seat_acceleration").FixValue(ctx, np.zeros(3))
    pc = model.plant_context(ctx)
    q = model.plant.GetPositions(pc)
    L = model.hp.layout
    q[L.rot_q] += 0.01
    model.plant.SetPositions(pc, q)
    port = pid.GetOutputPort("generalized_force")
    before = port.Eval(pid.GetMyContextFromRoot(ctx))[L.rot_v].copy()
    prm = pid.GetMyMutableContextFromRoot(ctx).get_mutable_numeric_parameter(pid.parameter_index)
    v = prm.CopyToVector()
    v[:n] *= 2.0
    prm.SetFromVector(v)
    after = port.Eval(pid.GetMyContextFromRoot(ctx))[L.rot_v]
    np.testing.assert_allclose(after, 2 * before, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("design", ["reference", "implicit"])
def test_the_pid_torque_is_a_cardan_torque(design):
    """The PID's torques act about the Cardan axes, as the springs' do (the
    paper's Cardan restraints): on the reference design's ball joints the
    generalized force f = N(q)^T tau, so that its power on the joint
    velocities is the torques' power on the Cardan angle rates, at joint
    angles of up to 0.4 rad and with an integral torque held.  (Until stop
    40 f = tau on the ball joints' angular velocities: this power was then
    3% to 280% off on these states.)"""
    from ehm_drake.systems.joints import _BallIndex, cardan_rates

    params = implicit() if design == "implicit" else load_params(PAPER)
    model = build_diagram(params, guard=False, seat_forces=False)
    laws, L = model.systems["force_laws"], model.hp.layout
    ctx = model.diagram.CreateDefaultContext()
    model.diagram.GetInputPort("seat_acceleration").FixValue(ctx, np.zeros(3))
    rng = np.random.default_rng(7)
    pc = model.plant_context(ctx)
    q = model.plant.GetPositions(pc)
    q[L.rot_q] += rng.uniform(-0.4, 0.4, L.num_rotational)
    model.plant.SetPositions(pc, q)  # at rest: the derivative part is zero
    lc = laws.GetMyMutableContextFromRoot(ctx)
    lc.SetDiscreteState(laws.views["joint_pid"].integral_state_index,
                        rng.normal(scale=0.05, size=L.num_rotational))
    tau = laws.GetOutputPort("joint_torques").Eval(lc)
    f = laws.GetOutputPort("joint_pid_generalized_force").Eval(lc)[L.rot_v]
    ball = _BallIndex(L)
    assert len(ball.roll) == (0 if design == "implicit" else 6)  # spine, upper neck, hips
    for _ in range(5):
        w = rng.standard_normal(L.num_rotational)
        assert f @ w == pytest.approx(tau @ cardan_rates(ball, q[L.rot_q], w), rel=1e-12)


def test_the_equilibrium_is_that_of_the_separate_systems():
    """The static equilibrium of the implicit design (found through the
    views: PID integral, restraint parameters, seating-in) is the one the
    five separate systems give: the same body positions and integrals."""
    params = implicit()
    model = build_diagram(params, guard=False, seat_forces=False)
    ctx, smap = static_equilibrium(model)
    rig = Rig(params)
    # The separate systems at that state: no net force, no integral change.
    x = smap.get(ctx)
    hp = rig.hp
    hp.plant.SetPositionsAndVelocities(hp.plant.GetMyMutableContextFromRoot(rig.ctx),
                                       x[smap.slice("plant")])
    rig.diagram.GetInputPort("controller_state").FixValue(rig.ctx, x[smap.slice("plant")])
    rig.diagram.GetInputPort("seat_acceleration").FixValue(rig.ctx, np.zeros(3))
    for name, index in (("joint_pid", "integral_state_index"),
                        ("shear_restraints", "slip_state_index")):
        value = x[smap.slice(name)]
        rig.sub(rig.old[name]).SetDiscreteState(getattr(rig.old[name], index), value)
        rig.sub(rig.laws).SetDiscreteState(getattr(rig.laws.views[name], index), value)
    for name in ("shear_restraints",):
        prm = model.systems[name].GetMyContextFromRoot(ctx).get_numeric_parameter(
            model.systems[name].parameter_index).CopyToVector()
        rig.set_restraint_parameters(lambda v, prm=prm: v.__setitem__(slice(None), prm))
    # Driven by the separate systems' forces, the body stays at rest.  (The
    # force is fixed before anything is evaluated: re-fixing a subsystem's
    # input leaves the diagram's cached update stale in Drake 1.51.)
    hp.plant.get_applied_generalized_force_input_port().FixValue(
        hp.plant.GetMyMutableContextFromRoot(rig.ctx), sum(rig.old_output(n) for n in LAWS))
    _compare(rig)
    update = rig.diagram.EvalUniquePeriodicDiscreteUpdate(rig.ctx)
    v_next = update.get_vector(0).CopyToVector()[hp.layout.nq:]
    assert np.max(np.abs(v_next)) < 1e-6  # m/s, rad/s


@pytest.mark.parametrize("design", ["reference", "implicit"])
def test_body_channels_are_bit_for_bit_the_per_marker_computation(design):
    """The channels computed for all markers at once are exactly (not just
    to rounding) those of the per-marker computation: the reference
    design's outputs must not change by a bit."""
    params = load_params(PAPER) if design == "reference" else implicit()
    model = build_diagram(params, guard=False, seat_forces=False)
    channels = model.systems["body_channels"]
    ctx = model.diagram.CreateDefaultContext()
    cc = channels.GetMyMutableContextFromRoot(ctx)
    pc = model.plant.GetMyMutableContextFromRoot(ctx)
    x0 = model.plant.GetPositionsAndVelocities(pc)
    model.diagram.GetInputPort("seat_acceleration").FixValue(ctx, np.zeros(3))
    rng = np.random.default_rng(3)
    out = BasicVector(30)
    for _ in range(200):
        x = x0 + rng.normal(scale=0.05, size=x0.shape)
        model.plant.SetPositionsAndVelocities(pc, x)
        settled = rng.normal(scale=0.1, size=30)
        cc.get_mutable_numeric_parameter(channels.settled_pose_parameter_index).SetFromVector(
            settled)
        d = rng.normal(scale=0.01, size=3)
        model.diagram.GetInputPort("seat_displacement").FixValue(ctx, d)
        channels.GetOutputPort("channels").Eval(cc)  # (the port's own path)
        channels._calc(cc, out)
        ref = settled.reshape(-1, 6)
        expected = np.concatenate([
            np.concatenate([p - ref[i, :3] + d,
                            rpy_from_rotation(R @ rotation_from_rpy(ref[i, 3:]).T)])
            for i, (p, R) in enumerate(channels.marker_poses(x))])
        assert np.array_equal(out.CopyToVector(), expected)


def test_a_parameter_written_after_reading_the_displacements_takes_effect():
    """Code that takes a mutable parameter (or state) reference, reads the
    restraint displacements and then writes through the reference (the
    equilibrium's seating-in and normal reference, the gap families'
    equivalent directions) gets the law with what it wrote: reading the
    displacements caches nothing that depends on the parameters."""
    model = build_diagram(implicit(), guard=False, seat_forces=False)
    view = model.systems["shear_restraints"]

    def restraint_force(write_after_read: bool):
        ctx = model.diagram.CreateDefaultContext()
        for port in ("seat_acceleration", "seat_displacement"):
            model.diagram.GetInputPort(port).FixValue(ctx, np.zeros(3))
        pc = model.plant_context(ctx)
        q = model.plant.GetPositions(pc)
        q[model.hp.layout.nq - 1] -= 1e-3  # (any motion against the anchors)
        model.plant.SetPositions(pc, q)
        rctx = view.GetMyMutableContextFromRoot(ctx)
        view.GetOutputPort("generalized_force").Eval(rctx)  # everything cached
        prm = rctx.get_mutable_numeric_parameter(view.parameter_index)
        new = prm.CopyToVector()
        restraint_block(new, "stiffness")[:] *= 2.0
        if write_after_read:
            view.axis_deflection(rctx)
            view.normal_displacement(rctx)
        prm.SetFromVector(new)
        return view.GetOutputPort("generalized_force").Eval(rctx).copy()

    np.testing.assert_array_equal(restraint_force(True), restraint_force(False))


def test_the_merged_laws_convert_to_autodiff():
    """A TemplateSystem like the systems it merges: its AutoDiffXd copy
    gives the same force, and derivatives that match central differences."""
    from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff

    model = build_diagram(implicit(), guard=False, seat_forces=False)
    laws = model.systems["force_laws"]
    ctx = model.diagram.CreateDefaultContext()
    a = np.array([0.3, -0.2, 0.5])
    model.diagram.GetInputPort("seat_acceleration").FixValue(ctx, a)
    pc = model.plant.GetMyMutableContextFromRoot(ctx)
    L = model.hp.layout
    x = model.plant.GetPositionsAndVelocities(pc)
    x[L.rot_q] += np.linspace(-0.02, 0.02, L.num_rotational)
    pelvis = model.plant.GetJointByName("pelvis_free").position_start()  # rpy, then xyz
    x[pelvis + 3] -= 4e-3  # back and down: every restraint point in contact, where
    x[pelvis + 5] -= 4e-3  # the law is smooth (its contact gating is a step)
    x[L.nq:] = 0.1

    def force(x):
        model.plant.SetPositionsAndVelocities(pc, x)
        return laws.GetOutputPort("generalized_force").Eval(laws.GetMyContextFromRoot(ctx)).copy()

    ad = laws.ToAutoDiffXd()
    actx = ad.CreateDefaultContext()
    ad.GetInputPort("state").FixValue(actx, InitializeAutoDiff(x).reshape(-1))
    ad.GetInputPort("seat_acceleration").FixValue(actx, np.array([AutoDiffXd(v) for v in a]))
    f_ad = ad.GetOutputPort("generalized_force").Eval(actx)
    f = force(x)
    _close(ExtractValue(f_ad).reshape(-1), f)
    gradient = ExtractGradient(f_ad)
    for j in (L.rot_q[3], L.spine_q, L.nq + L.rot_v[5], pelvis + 5):  # joint, spine, rate, z
        e = np.zeros_like(x)
        e[j] = 1e-6
        fd = (force(x + e) - force(x - e)) / 2e-6
        np.testing.assert_allclose(gradient[:, j], fd, rtol=0, atol=1e-6 * np.max(np.abs(fd)))


def _step_both_ways(laws, context):
    """`ForceLaws`' step at `context` compiled (`compiled_step`) and in
    NumPy."""
    from pydrake.common.value import AbstractValue

    out = []
    for compiled in (True, False):
        laws._compiled = compiled
        value = AbstractValue.Make(None)
        laws._calc_step(context, value)
        out.append(value.get_value())
    laws._compiled = True
    return out


@pytest.mark.parametrize("design", ["implicit", "reference"])
@pytest.mark.parametrize("branches", [False, True])
def test_the_compiled_step_is_the_numpy_step(design, branches):
    """On the implicit design (Cardan chains, restraint constraints, contact
    dampers) and the reference design (ball joints, their damping
    remainder) the compiled step gives the NumPy step's numbers at random
    states to 1e-12 of each quantity's scale (its products are loops, not
    BLAS, and its kinematics its own: the last bits differ), with every branch of
    the restraint law switched on (gating, cubic and linear normal forces,
    friction, slipping anchors) or the model's own."""
    from ehm_drake import jit

    if not jit.available():  # (numba is a dependency; EHM_DRAKE_NO_JIT=1 is tested below)
        assert os.environ.get("EHM_DRAKE_NO_JIT", "") not in ("", "0")
        pytest.skip("the compiled laws are switched off (EHM_DRAKE_NO_JIT)")
    params = implicit() if design == "implicit" else reference_design(load_params(PAPER))
    model = build_diagram(params, guard=False, seat_forces=False)
    laws = model.systems["force_laws"]
    assert laws._compiled
    ctx = model.diagram.CreateDefaultContext()
    lctx = laws.GetMyMutableContextFromRoot(ctx)
    n = len(laws.restraint_points)
    if branches:
        prm = lctx.get_mutable_numeric_parameter(laws.views["shear_restraints"].parameter_index)
        v = prm.CopyToVector()
        _every_branch(v, laws.restraint_points)
        prm.SetFromVector(v)
    plant, L = model.plant, laws._layout
    pc = plant.GetMyMutableContextFromRoot(ctx)
    x0 = plant.GetPositionsAndVelocities(pc)
    rng = np.random.default_rng(8)
    for _ in range(10):
        x = x0.copy()
        x[L.rot_q] += rng.uniform(-0.1, 0.1, L.num_rotational)
        x[L.nq:] = rng.normal(scale=0.3, size=L.nv)
        plant.SetPositionsAndVelocities(pc, x)
        for port, value in (("seat_acceleration", rng.normal(scale=0.5, size=3)),
                            ("seat_displacement", np.zeros(3))):
            model.diagram.GetInputPort(port).FixValue(ctx, value)
        lctx.SetDiscreteState(laws.views["joint_pid"].integral_state_index,
                              rng.normal(scale=0.05, size=L.num_rotational))
        lctx.SetDiscreteState(laws.views["shear_restraints"].slip_state_index,
                              rng.normal(scale=2e-3, size=2 * n))
        a, b = _step_both_ways(laws, lctx)
        tree, laws._structure.tree = laws._structure.tree, None  # Drake's kinematics
        drake, _ = _step_both_ways(laws, lctx)
        laws._structure.tree = tree
        assert tree is not None
        names = ["f", "w", "slip_next", "z_next", "pid_force", "pid_torque", "passive_force",
                 "his_torque", "pos", "pos_n"]
        seat = laws._seat @ np.concatenate([b.w[:2 * n], laws._normal_forces(b)])
        for compiled in (a, drake):  # the compiled step on either kinematics
            for name in names + (["fd"] if design == "implicit" else []):
                want = getattr(b, name)
                np.testing.assert_allclose(getattr(compiled, name), want, rtol=0, err_msg=name,
                                           atol=1e-12 * max(1.0, np.max(np.abs(want))))
            np.testing.assert_allclose(compiled.J, b.J, rtol=0,
                                       atol=1e-12 * np.max(np.abs(b.J)))
            np.testing.assert_allclose(compiled.seat_forces, seat, rtol=0,
                                       atol=1e-12 * max(1.0, np.max(np.abs(seat))))
            np.testing.assert_allclose(compiled.G, b.G, rtol=0,
                                       atol=1e-12 * np.max(np.abs(b.G)))
        np.testing.assert_array_equal(drake.J, b.J)  # Drake's calls, as the NumPy step's
        assert np.any(a.slip_next != 0)
        assert np.any(a.fd != 0) if design == "implicit" else len(laws._ball.roll) > 0


@pytest.mark.parametrize("design", ["implicit", "reference"])
def test_the_compiled_kinematics_are_drakes(design):
    """`TreeKinematics` (revolute, prismatic, floating and weld joints on the
    implicit design; ball and universal joints on the reference design)
    gives Drake's body poses, point positions, point Jacobians, angular
    Jacobians and centre-of-mass Jacobian at random states to 1e-13 of
    their scale, and declines a plant with a joint it does not know."""
    from pydrake.multibody.plant import MultibodyPlant
    from pydrake.multibody.tree import BodyIndex, JacobianWrtVariable, SpatialInertia

    from ehm_drake.systems.compiled_kinematics import TreeKinematics

    params = implicit() if design == "implicit" else reference_design(load_params(PAPER))
    laws = build_diagram(params, guard=False, seat_forces=False).systems["force_laws"]
    plant = laws._scratch.plant
    ctx, W, kv = plant.CreateDefaultContext(), plant.world_frame(), JacobianWrtVariable.kV
    tree = TreeKinematics.of(plant, ctx, laws._instances, laws._head, laws._trunk)
    kinds = {plant.get_joint(j).type_name() for j in plant.GetJointIndices()}
    assert kinds >= ({"revolute", "rpy_floating", "prismatic", "weld"} if design == "implicit"
                     else {"ball_rpy", "universal", "rpy_floating"})
    groups = laws._geometry.groups
    P = np.concatenate([P_B for _, P_B, _ in groups], axis=1)
    body = np.repeat([int(f.body().index()) for f, _, _ in groups],
                     [P_B.shape[1] for _, P_B, _ in groups])
    rng = np.random.default_rng(3)

    def close(a, b):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-13 * max(1.0, np.max(np.abs(b))))

    for _ in range(5):
        q = plant.GetPositions(ctx) + rng.uniform(-0.5, 0.5, plant.num_positions())
        plant.SetPositions(ctx, q)
        R_WB, p_WB, w, o, t, A = tree.poses(q, P, body)
        JJ, J_head, J_trunk, J_com = tree.jacobians(R_WB, p_WB, w, o, t, P, body)
        for b in range(plant.num_bodies()):
            X = plant.EvalBodyPoseInWorld(ctx, plant.get_body(BodyIndex(b)))
            close(R_WB[b], X.rotation().matrix())
            close(p_WB[b], X.translation())
        close(A, np.concatenate([plant.CalcPointsPositions(ctx, f, P_B, W)
                                 for f, P_B, _ in groups], axis=1))
        close(JJ, np.concatenate([plant.CalcJacobianTranslationalVelocity(ctx, kv, f, P_B, W, W)
                                  for f, P_B, _ in groups]))
        close(J_head, plant.CalcJacobianAngularVelocity(ctx, kv, laws._head, W, W))
        close(J_trunk, plant.CalcJacobianAngularVelocity(ctx, kv, laws._trunk, W, W))
        close(J_com, plant.CalcJacobianCenterOfMassTranslationalVelocity(
            ctx, laws._instances, kv, W, W))
    free = MultibodyPlant(0.0)
    ball = free.AddRigidBody("ball", SpatialInertia.SolidSphereWithMass(1.0, 0.1))
    free.Finalize()  # a quaternion floating joint
    assert TreeKinematics.of(free, free.CreateDefaultContext(), [ball.model_instance()],
                             ball.body_frame(), ball.body_frame()) is None


def test_a_kernels_division_by_zero_is_nan_as_in_numpy():
    """A diverging state can zero a denominator (the contact probe's
    ellipsoid normal when the positions lose their digits): the compiled
    kernels then give NaN, as NumPy does, for the divergence guard to
    report, instead of raising ZeroDivisionError from inside a step."""
    from ehm_drake import jit
    from ehm_drake.systems.compiled_laws import compiled_probe

    if not jit.available():
        pytest.skip("the compiled laws are switched off (EHM_DRAKE_NO_JIT)")
    A = np.zeros((3, 4))  # the body origin and its three unit tips in one place
    pos_n = compiled_probe(A, np.array([2]), np.array([0]), np.array([[1, 2, 3]]),
                           np.zeros((1, 3)), np.ones((1, 3)), np.zeros(1), np.zeros((3, 2)),
                           np.array([1]))
    assert np.isnan(pos_n).all()


def test_without_numba_the_numpy_laws_give_the_same_forces():
    """With EHM_DRAKE_NO_JIT=1 (as where numba is not installed) nothing is
    compiled and the default implicit model's forces are those of the
    compiled laws to 1e-12."""
    import json
    import os
    import subprocess
    import sys

    code = (
        "import json, numpy as np\n"
        "from ehm_drake import jit\n"
        "from ehm_drake.diagram import build_diagram\n"
        "from ehm_drake.params import load_params\n"
        "p = load_params(); p.simulation.design = 'implicit'; p.simulation.time_step_s = 0.005\n"
        "m = build_diagram(p, guard=False, seat_forces=False)\n"
        "ctx = m.diagram.CreateDefaultContext()\n"
        "pc = m.plant.GetMyMutableContextFromRoot(ctx)\n"
        "x = m.plant.GetPositionsAndVelocities(pc)\n"
        "x[m.plant.num_positions():] = np.linspace(-0.3, 0.3, m.plant.num_velocities())\n"
        "m.plant.SetPositionsAndVelocities(pc, x)\n"
        "m.diagram.GetInputPort('seat_acceleration').FixValue(ctx, [0.3, -0.2, 0.5])\n"
        "m.diagram.GetInputPort('seat_displacement').FixValue(ctx, [0.0, 0.0, 0.0])\n"
        "f = m.plant.get_applied_generalized_force_input_port().Eval(pc)\n"
        "print(json.dumps({'jit': jit.available(), 'compiled': m.systems['force_laws']._compiled,"
        " 'f': f.tolist()}))\n")
    out = {}
    for flag in ("0", "1"):
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           env=dict(os.environ, EHM_DRAKE_NO_JIT=flag), check=True)
        out[flag] = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["0"]["jit"] and out["0"]["compiled"]
    assert not out["1"]["jit"] and not out["1"]["compiled"]
    f0, f1 = np.array(out["0"]["f"]), np.array(out["1"]["f"])
    np.testing.assert_allclose(f1, f0, rtol=0, atol=1e-12 * np.max(np.abs(f0)))
    assert np.max(np.abs(f0)) > 1.0
