"""The implicit design (`simulation.design: implicit`): the human's joints as
Cardan chains of revolute joints whose stiff feedback SAP integrates
implicitly.  It must be the same body as the reference design (kinematics,
posture, the split of the joint torques between plant and Python systems)
and respond like it, so that its step can be chosen by accuracy."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.framework import DiagramBuilder

from ehm_drake.analysis.linear import linearize
from ehm_drake.diagram import build_diagram
from ehm_drake.model.plant import (
    add_seated_human,
    joint_dofs,
    passive_stiffness_vector,
    pid_vectors,
    step_damping,
)
from ehm_drake.params import load_params, reference_design
from ehm_drake.signals import make_seat_signal
from ehm_drake.simulation import settle, static_equilibrium, vibrate


def implicit(h: float = 0.001):
    p = load_params()
    p.simulation.design = "implicit"
    p.simulation.time_step_s = h
    return p


def _plant(params):
    builder = DiagramBuilder()
    hp = add_seated_human(builder, params)
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


def test_pd_actuators_carry_the_stiffness_and_the_systems_only_the_rest():
    params = implicit()
    hp, _ = _plant(params)
    L = hp.layout
    k = passive_stiffness_vector(params, L)
    kp = pid_vectors(params, L)["kp"]
    np.testing.assert_allclose(hp.implicit_stiffness, np.append(k[:-1] + kp, k[-1]))
    np.testing.assert_allclose(hp.implicit_kp, kp)
    gains = {hp.plant.get_joint_actuator(a).joint().name():
             hp.plant.get_joint_actuator(a).get_controller_gains().p
             for a in hp.plant.GetJointActuatorIndices()}
    for i, (name, axis) in enumerate(zip(L.joints, L.axes, strict=True)):
        (_, joint, _), = [d for d in joint_dofs(hp.plant, hp.human, name) if d[0] == axis]
        assert gains.get(joint.name(), 0.0) == pytest.approx(hp.implicit_stiffness[i])
    assert gains["spinal_compression"] == pytest.approx(params.passive.spine_axial_stiffness)
    # Away from the reference posture (integrals at zero), the Python joint
    # systems add nothing: the plant's PD actuators apply it all.
    model = build_diagram(params, guard=False, seat_forces=False)
    ctx = model.diagram.CreateDefaultContext()
    pc = model.plant_context(ctx)
    q = model.plant.GetPositions(pc)
    q[L.rot_q] = np.linspace(-0.1, 0.1, L.num_rotational)
    q[L.spine_q] = -0.003
    model.plant.SetPositions(pc, q)
    for name in ("passive_joints", "joint_pid"):
        s = model.systems[name]
        f = s.GetOutputPort("generalized_force").Eval(s.GetMyContextFromRoot(ctx))
        assert np.max(np.abs(f)) < 1e-12, name
    # ... while the PID still reports its full torque.
    pid = model.systems["joint_pid"]
    tau = pid.GetOutputPort("torque").Eval(pid.GetMyContextFromRoot(ctx))
    np.testing.assert_allclose(tau, -kp * q[L.rot_q], atol=1e-12)


def test_step_damping_removes_what_the_implicit_step_adds():
    p = implicit(0.005)
    assert step_damping(p, 17.0, 540.0) == pytest.approx(17.0 - 0.005 * 540.0)
    assert step_damping(p, 1.0, 540.0) == 0.0  # never negative
    assert step_damping(reference_design(p), 17.0, 540.0) == 17.0
    hp, diagram = _plant(p)
    ctx = hp.plant.GetMyContextFromRoot(diagram.CreateDefaultContext())
    spine = hp.plant.GetJointByName("spinal_compression", hp.human)
    assert spine.GetDampingVector(ctx)[0] == pytest.approx(
        p.passive.spine_axial_damping - 0.005 * p.passive.spine_axial_stiffness)


def test_posture_is_held_at_a_5_ms_step():
    params = implicit(0.005)
    settled = settle(params, settle_time=2.0)
    assert settled.summary["max_joint_error_deg"] < 1e-6
    s = params.simulation
    signal = make_seat_signal("random", "xyz", 0.5, 3.0, 2, s.time_step_s, 2.0, 0.5)
    result = vibrate(params, settled, signal)
    assert np.all(np.isfinite(result.channels))
    assert np.max(np.abs(np.degrees(result.joint_torques))) > 0  # it moved


@pytest.mark.slow
def test_implicit_design_responds_like_the_reference_at_1_ms():
    """Linearized at the same 1 ms step, the two designs give the same
    vertical (seat to pelvis and head) and lateral (head) transmissibility
    within a few percent over 1-10 Hz."""
    freqs = np.linspace(1.0, 10.0, 19)
    T = {}
    for name, params in (("ref", reference_design(load_params())), ("imp", implicit())):
        model = build_diagram(params, guard=False, seat_forces=False)
        ctx, _ = static_equilibrium(model)
        T[name] = np.abs(linearize(model, ctx, method="fd").transmissibility_array(freqs))
    from ehm_drake.systems.outputs import CHANNEL_NAMES
    for channel, axis, tol in (("pelvis_z", 2, 0.03), ("head_z", 2, 0.04),
                               ("head_y", 1, 0.06), ("trunk_roll", 1, 0.06)):
        c = CHANNEL_NAMES.index(channel)
        err = np.abs(T["imp"][:, c, axis] / T["ref"][:, c, axis] - 1.0)
        assert np.max(err) < tol, (channel, np.round(err, 3))


def test_unknown_design_is_refused_by_name():
    from ehm_drake.params import ParameterError, params_from_dict

    with pytest.raises(ParameterError, match=r"simulation.design = 'fast'.*'implicit' or "
                                             r"'reference'"):
        params_from_dict({"simulation": {"design": "fast"}})
