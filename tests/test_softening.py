"""The body's softening with vibration magnitude (`ehm_drake.model.softening`,
`ehm_drake.systems.softening`, `ehm_drake.analysis.equivalent`): the law,
nothing at rest, a frozen element is a softer spring, the equivalent-linear
iteration, and the nonlinear simulation against it."""

from __future__ import annotations

import os

import numpy as np
import pytest

from ehm_drake import jit
from ehm_drake.analysis.equivalent import SeatSpectrum, equivalent_linear
from ehm_drake.analysis.linear import default_frequencies, linearize
from ehm_drake.diagram import build_diagram
from ehm_drake.model import softening as softening_law
from ehm_drake.model.softening import (
    ElementSet,
    element_spring,
    equivalent_loss,
    loss_fraction,
    tissue_movement,
)
from ehm_drake.params import ParameterError, load_params, params_from_dict
from ehm_drake.simulation import static_equilibrium
from ehm_drake.validation.run import peak_frequency

pytestmark = pytest.mark.xdist_group("softening")


def _am_peak(lin) -> float:
    f = default_frequencies(1200)
    return peak_frequency(f, lin.apparent_mass(f, "z")["z"][1])


def test_loss_law():
    # Half the maximum loss at the critical amplitude, none at rest, r at most.
    assert loss_fraction(0.0, 1e-4, 0.8) == 0.0
    assert loss_fraction(1e-4, 1e-4, 0.8) == pytest.approx(0.4)
    assert loss_fraction(1.0, 1e-4, 0.8) == pytest.approx(0.8, rel=1e-3)
    s = np.logspace(-6, -2, 30)
    assert np.all(np.diff(loss_fraction(s, 1e-4, 0.8)) > 0)


def test_tissue_in_series_with_a_seat():
    # The tissue's own movement solves s_t = s_d k_s / (k_s + k_t(s_t)) and
    # the pair's stiffness is tissue and seat in series.
    k_t0, k_s, r, sc = 2.1e5, 7.0e4, 0.88, 1e-4
    c = np.array([1 / k_s])
    for s_d in (1e-5, 1e-4, 1e-3, 5e-3):
        s_t = tissue_movement(np.array([s_d]), np.array([k_t0]), c, np.array([sc]),
                              np.array([r]), iterations=60)
        k_t = k_t0 * (1 - loss_fraction(s_t, sc, r))
        np.testing.assert_allclose(s_t, s_d * k_s / (k_s + k_t), rtol=1e-9)
    # Four iterations (the law's) are within 1% of the fixed point.
    s4 = tissue_movement(np.array([1e-3]), np.array([k_t0]), c, np.array([sc]), np.array([r]))
    s60 = tissue_movement(np.array([1e-3]), np.array([k_t0]), c, np.array([sc]),
                          np.array([r]), iterations=60)
    np.testing.assert_allclose(s4, s60, rtol=1e-2)


def test_rigid_seat_tissue_is_the_pair():
    from ehm_drake.model.softening import ElementSet

    el = ElementSet(("tissue",), ("buttocks",), np.array([2e5]), np.array([2e5]),
                    np.array([0.5]), np.array([1e-4]), np.array([2.0]))
    # On a rigid seat the tissue moves with the pair: loss = k0 r g(s).
    assert equivalent_loss(el, np.array([1e-4]))[0] == pytest.approx(2e5 * 0.25)
    assert abs(equivalent_loss(el, np.array([0.0]))[0]) < 1e-6


def test_tissue_stiffness_below_the_pair_is_refused():
    with pytest.raises(ParameterError, match="softening.tissue.pelvis_pan_stiffness"):
        params_from_dict({"softening": {"tissue": {"pelvis_pan_stiffness": 1000.0}}})
    with pytest.raises(ParameterError, match="softening.tissue.max_loss"):
        params_from_dict({"softening": {"tissue": {"max_loss": 1.2}}})
    with pytest.raises(ParameterError, match="critical_rms_m"):
        params_from_dict({"softening": {"tissue": {"critical_rms_m": 0.0}}})


@pytest.fixture(scope="module")
def default_at_rest():
    model = build_diagram(load_params(), guard=False)
    ctx, _ = static_equilibrium(model)
    return model, ctx


def test_nothing_at_rest(default_at_rest):
    # At rest the softening adds no force and, above its memory's corner
    # (0.08 Hz), the linearization is the linear model with the contacts'
    # stiffness at rest: the model without the softening system, within the
    # few percent its deeper static sink changes (the seat is adjusted to it).
    model, ctx = default_at_rest
    soft = model.systems["body_softening"]
    sctx = soft.GetMyContextFromRoot(ctx)
    assert np.max(np.abs(soft.GetOutputPort("generalized_force").Eval(sctx))) < 1e-12
    assert np.all(np.abs(soft.GetOutputPort("stiffness_loss").Eval(sctx)) < 1e-3)  # N/m
    p = load_params()
    p.softening.tissue.enabled = False
    plain = linearize(build_diagram(p, guard=False))
    soft_lin = linearize(model, ctx)
    f = default_frequencies()
    f = f[f > 1.0]
    T1, T2 = soft_lin.transmissibility_array(f, "z"), plain.transmissibility_array(f, "z")
    rel = np.abs(T1 - T2) / np.max(np.abs(T2))
    assert np.max(rel) < 0.05
    assert _am_peak(soft_lin) == pytest.approx(_am_peak(plain), rel=0.03)


def test_the_compiled_spring_is_the_law(monkeypatch):
    # Tissue on a compliant seat, on a rigid one (no series compliance) and
    # muscles, over five decades of movement: the compiled kernel (numba)
    # gives the NumPy law's numbers, and the law stands alone without it.
    el = ElementSet(("tissue", "tissue", "muscle"), ("a", "b", "c"),
                    np.array([60000.0, 250000.0, 400.0]), np.array([250000.0, 250000.0, 400.0]),
                    np.array([0.8, 0.8, 0.7]), np.array([7e-5, 7e-5, 0.0087]),
                    np.array([2.0, 2.0, 1.0]))
    s = 10.0 ** np.random.default_rng(3).uniform(-7, -1, (50, 3))
    compiled = np.array([element_spring(el, row) for row in s])
    monkeypatch.setattr(softening_law, "_spring_kernel", None)
    law = np.array([element_spring(el, row) for row in s])
    assert np.allclose(compiled, law, rtol=1e-12, atol=0.0)
    assert np.all(law[:, :2] >= 0) and np.all(law[:, 2] <= 0)
    # (numba is a dependency: the comparison above compared two paths, unless
    # the compiled kernels were switched off on purpose.)
    assert jit.available() or os.environ.get("EHM_DRAKE_NO_JIT", "") not in ("", "0")


def test_the_softening_reads_the_restraints_kinematics(default_at_rest):
    # The tissue points' normal displacements and Jacobian rows taken from
    # what the force laws computed at the state are the ones the softening
    # computes itself at a moved state: to rounding (the laws' kinematics
    # are compiled, `TreeKinematics`; the softening's own are Drake's).
    model, ctx = default_at_rest
    ctx = ctx.Clone()
    plant = model.plant
    pc = plant.GetMyMutableContextFromRoot(ctx)
    x = plant.GetPositionsAndVelocities(pc)
    x += 1e-3 * np.random.default_rng(4).standard_normal(x.size)
    plant.SetPositionsAndVelocities(pc, x)
    laws = model.systems["force_laws"]
    laws.GetOutputPort("generalized_force").Eval(laws.GetMyContextFromRoot(ctx))
    soft = model.systems["body_softening"]
    sctx = soft.GetMyContextFromRoot(ctx)
    soft._scratch.set_state(x)
    assert soft._scratch.shared("restraint normals") is not None
    d_shared, J_shared, _ = soft._calc_deformation_kin(sctx)
    soft._scratch.share("restraint normals", None)
    d_own, J_own, _ = soft._calc_deformation_kin(sctx)
    np.testing.assert_allclose(d_shared, d_own, rtol=0, atol=1e-15)  # (m; d ~ 1e-2)
    np.testing.assert_allclose(J_shared, J_own, rtol=0, atol=1e-14)  # (entries ~ 1)
    assert np.any(J_own != 0) and np.max(np.abs(d_own)) > 1e-3
    # Points measured from other anchors are not taken for its own.
    rows = dict(laws._point_rows)
    name = soft._args[3][0].name
    rows[name] = rows[name][:3] + (rows[name][3] + 1e-3,)
    assert soft._rows_in(rows) is None and soft._rows_in(laws._point_rows) is not None


@pytest.mark.parametrize("design", ["implicit", "reference"])
def test_the_compiled_softening_step_is_the_numpy_methods(design):
    # Tissue and muscle elements (Cardan chains on the implicit design, ball
    # joints on the paper's), running statistics, a frozen RMS, force
    # offsets and the forces switched off: the compiled step's force, seat
    # forces and next state are the NumPy methods' to 1e-12 of their scale.
    if not jit.available():
        pytest.skip("the compiled kernels are switched off (EHM_DRAKE_NO_JIT)")
    p = params_from_dict({"softening": {"muscle": {"enabled": True}}})
    p.simulation.design = design
    p.simulation.time_step_s = 0.005 if design == "implicit" else 0.001
    model = build_diagram(p, guard=False)
    soft = model.systems["body_softening"]
    assert soft._compiled and "muscle" in soft.elements.kinds and "tissue" in soft.elements.kinds
    ctx = model.diagram.CreateDefaultContext()
    plant = model.plant
    pc = plant.GetMyMutableContextFromRoot(ctx)
    sctx = soft.GetMyMutableContextFromRoot(ctx)
    for port in ("seat_acceleration", "seat_displacement"):
        model.diagram.GetInputPort(port).FixValue(ctx, np.zeros(3))
    x0 = plant.GetPositionsAndVelocities(pc)
    n = soft.elements.n
    rng = np.random.default_rng(6)
    touching = 0
    for trial in range(6):
        x = x0 + 2e-3 * rng.standard_normal(x0.size)
        plant.SetPositionsAndVelocities(pc, x)
        d = soft.rest_deformation(sctx)
        sctx.SetDiscreteState(soft.state_index, np.concatenate(
            [d + 1e-4 * rng.standard_normal(n), (1e-4 * rng.standard_normal(n)) ** 2]))
        soft.set_rms(sctx, None if trial % 2 == 0 else 10 ** rng.uniform(-6, -3, n))
        soft.set_force_offset(sctx, None if trial < 3 else rng.normal(scale=5.0, size=n))
        soft.set_active(sctx, trial != 5)
        if soft._n_tissue:
            laws = model.systems["force_laws"]  # (the restraint normals it shares)
            laws.GetOutputPort("generalized_force").Eval(laws.GetMyContextFromRoot(ctx))
            touching += int(np.sum(d[:soft._n_tissue] < soft._geometry.face))
        out = {}
        for compiled in (True, False):
            soft._compiled = compiled
            c = soft.GetMyContextFromRoot(ctx.Clone())  # (fresh caches)
            state = soft.AllocateDiscreteVariables()
            soft.CalcForcedDiscreteVariableUpdate(c, state)
            out[compiled] = (soft.GetOutputPort("generalized_force").Eval(c),
                             soft.GetOutputPort("seat_forces").Eval(c),
                             state.get_vector(soft.state_index).CopyToVector())
        soft._compiled = True
        for a, b, name in zip(out[True], out[False], ("force", "seat forces", "next state"),
                              strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * max(1e-12, np.max(np.abs(b))),
                                       err_msg=name)
        assert trial == 5 or np.any(out[True][0] != 0)
    assert touching > 0


def test_the_default_diagram_sums_the_laws_and_the_softening():
    model = build_diagram(load_params(), guard=False, seat_forces=False)
    adder = model.diagram.GetSubsystemByName("generalized_force_sum")
    assert adder.num_input_ports() == 2
    assert {"force_laws", "body_softening"} <= set(model.systems)


def test_frozen_softening_is_a_softer_contact():
    # On a rigid seat, a frozen softening element is the contact pair made
    # softer by its loss: the apparent-mass peaks agree within 3%.
    p = load_params("rigid_seat")
    model = build_diagram(p, guard=False)
    ctx, _ = static_equilibrium(model)
    soft = model.systems["body_softening"]
    el = soft.elements
    s = np.full(el.n, 3e-4)
    loss = equivalent_loss(el, s)
    soft.set_rms(soft.GetMyMutableContextFromRoot(ctx), s)
    frozen = _am_peak(linearize(model, ctx))
    k = {n: el.k_rest[i] - loss[i] for i, n in enumerate(el.names)}
    softer = params_from_dict({
        "seat": {"rigid": False, "backrest": False},
        "contact": {"pelvis_pan": {"stiffness": k["buttocks"], "damping": 2200.0},
                    "thighs_pan": {"stiffness": k["thigh_l"], "damping": 860.0}},
        "softening": {"tissue": {"enabled": False}}})
    linear = _am_peak(linearize(build_diagram(softer, guard=False)))
    at_rest = _am_peak(linearize(build_diagram(p, guard=False)))
    assert frozen < 0.85 * at_rest  # it does soften
    assert frozen == pytest.approx(linear, rel=0.03)


def test_equivalent_linear_softens_with_level():
    # The equivalent-linear resonance falls with the level on every seat; the
    # paper's linear model's does not move.
    for config, drop in (("rigid_seat", 0.75), ("car_seat", 0.9)):
        model = build_diagram(load_params(config), guard=False)
        ctx, _ = static_equilibrium(model)
        lo = equivalent_linear(model, SeatSpectrum.flat("z", 0.25, (0.5, 20.0)), ctx)
        hi = equivalent_linear(model, SeatSpectrum.flat("z", 2.0, (0.5, 20.0)), ctx)
        assert np.all(hi.movement_rms > 4 * lo.movement_rms)
        assert _am_peak(hi.linear) < drop * _am_peak(lo.linear), config
    model = build_diagram(load_params("paper_linear"), guard=False)
    lo = equivalent_linear(model, SeatSpectrum.flat("z", 0.25))
    hi = equivalent_linear(model, SeatSpectrum.flat("z", 2.0))
    assert lo.iterations == 1 and _am_peak(hi.linear) == pytest.approx(_am_peak(lo.linear))


def test_springs_fed_back_are_the_model_linearized_at_those_movements(default_at_rest):
    # The equivalent-linear iteration linearizes once and changes the
    # elements' springs by feeding their force back (`with_springs`): at
    # other RMS movements that is the model linearized there, to the
    # finite differences' accuracy, whichever way the springs move.
    from ehm_drake.analysis.equivalent import softening_columns, with_springs
    from ehm_drake.analysis.linear import FD_STEP
    from ehm_drake.model.softening import element_spring

    model, ctx = default_at_rest
    soft = model.systems["body_softening"]
    sctx = soft.GetMyMutableContextFromRoot(ctx)
    el = soft.elements
    f = default_frequencies()
    ports = ["channels", "softening_deformation"]
    try:
        s0 = np.full(el.n, 2e-4)
        soft.set_rms(sctx, s0)
        lin0 = linearize(model, ctx, outputs=ports)
        cols = softening_columns(model, ctx, lin0, FD_STEP)
        for s in (np.full(el.n, 1e-3), np.full(el.n, 2e-5)):
            soft.set_rms(sctx, s)
            fresh = linearize(model, ctx, outputs=ports)
            fed = with_springs(lin0, cols, element_spring(el, s) - element_spring(el, s0))
            T1, T2 = fed.transmissibility_array(f, "xz"), fresh.transmissibility_array(f, "xz")
            T0 = lin0.transmissibility_array(f, "xz")
            scale = np.max(np.abs(T2))
            assert np.max(np.abs(T0 - T2)) > 0.02 * scale  # the springs matter here
            assert np.max(np.abs(T1 - T2)) < 1e-6 * scale
    finally:
        soft.set_rms(sctx, None)


def test_spectrum_rms():
    assert SeatSpectrum.flat("z", 0.7, (0.5, 20.0)).rms[2] == pytest.approx(0.7, rel=1e-9)
    assert SeatSpectrum.sine("x", 3.0, 0.4).rms[0] == pytest.approx(0.4)
    with pytest.raises(ValueError):
        SeatSpectrum.flat("z", -1.0)


def test_the_muscle_option_softens_the_trunk():
    # Off by default; on, the trunk and hip muscles' short-range stiffness
    # is lost with their rotation: the trunk's fore-aft response at 1 m/s^2
    # peaks lower than with the muscle option off.
    p = load_params()
    assert not p.softening.muscle.enabled
    on = params_from_dict({"softening": {"muscle": {"enabled": True}}})
    f = default_frequencies(600)
    peaks = {}
    for name, params in (("off", p), ("on", on)):
        model = build_diagram(params, guard=False)
        eq = equivalent_linear(model, SeatSpectrum.flat("x", 1.0))
        if name == "on":
            kinds = model.systems["body_softening"].elements.kinds
            assert "muscle" in kinds
            muscle = np.array([k == "muscle" for k in kinds])
            assert np.all(eq.stiffness_loss[muscle] > 0)
        T = np.abs(eq.linear.transmissibility_array(f, "x")[:, 6 + 4, 0])  # trunk pitch
        peaks[name] = f[int(np.argmax(T))]
    assert peaks["on"] < peaks["off"]
