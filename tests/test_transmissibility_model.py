"""Transmissibility and apparent mass of the model (analysis issue):
the rigid-body check through the whole pipeline, and the paper's claim that
high joint stiffness lowers the rotational gains."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from ehm_drake.analysis.apparent_mass import apparent_mass_table
from ehm_drake.analysis.transmissibility import transmissibility
from ehm_drake.diagram import build_diagram
from ehm_drake.params import params_from_dict
from ehm_drake.signals import make_seat_signal
from ehm_drake.simulation import (
    SimulationResult,
    StateMap,
    static_equilibrium,
)

#: Module fixtures: the module's tests stay on one xdist worker (built once).
pytestmark = pytest.mark.xdist_group("transmissibility_model")

PAN = ("pelvis_pan", "thighs_pan")
OFF = ("feet_floor", "lower_back_pad", "upper_back_pad")


def _rigid_params():
    """A rigid seat pan (contact and shear modes above 100 Hz) carrying the
    body alone: floor and backrest contacts are made negligible (1 N/m), so
    the pan force is the whole seat force, as for a rigid mass on a pan."""
    return params_from_dict({
        "contact": {**{k: {"stiffness": 6e8, "damping": 4e4} for k in PAN},
                    **{k: {"stiffness": 1.0, "damping": 0.0} for k in OFF}},
        "restraints": {**{k: {"stiffness": 3e7, "damping": 5e3, "force_limit": 1e5}
                          for k in PAN},
                       **{k: {"stiffness": 0.0, "damping": 0.0} for k in OFF}},
        # A rigid body: nothing softens.
        "softening": {"tissue": {"enabled": False}},
    })


def _run_rigid(direction: str) -> SimulationResult:
    """The body with every joint locked (a rigid body) on the stiff seat."""
    params = _rigid_params()
    eq, smap = static_equilibrium(build_diagram(params, guard=False))
    x0 = smap.get(eq)
    sig = make_seat_signal("random", direction, 0.5, 25.0, 2, settle_time=0.5, onset_time=0.5)
    model = build_diagram(params, signal=sig, guard=False, log_period=0.005)
    ctx = model.diagram.CreateDefaultContext()
    StateMap(model).set(ctx, x0)
    pctx = model.plant_context(ctx)
    plant = model.plant
    for j in plant.GetJointIndices(model.hp.human):
        joint = plant.get_joint(j)
        if joint.num_velocities() and joint.name() != "pelvis_free":
            joint.Lock(pctx)
    ch = model.systems["body_channels"]
    ch.GetMyMutableContextFromRoot(ctx).get_mutable_numeric_parameter(
        ch.settled_pose_parameter_index).SetFromVector(
        ch.settled_pose_vector(plant.GetPositionsAndVelocities(pctx)))
    ctx.SetTime(sig.settle_time)
    Simulator(model.diagram, ctx).AdvanceTo(sig.duration)
    logs = {k: v.FindLog(ctx) for k, v in model.loggers.items()}
    return SimulationResult(
        logs["channels"].sample_times(), logs["seat_acceleration"].data().T,
        logs["seat_displacement"].data().T, logs["channels"].data().T,
        logs["seat_forces"].data().T, logs["joint_torques"].data().T,
        logs["his_torque"].data().T, model.joint_names,
        {"signal": sig.meta, "variant": "rigid"}).after(sig.steady_start)


@pytest.mark.parametrize("direction", ["x", "z"])
def test_rigid_body_on_rigid_seat(direction):
    r = _run_rigid(direction)
    frf = transmissibility(r.to_timeseries())
    for seg in ("pelvis", "trunk", "head", "knee_l"):
        f, gain, phase, coh = frf.get(direction, seg, direction)
        band = (f > 0.5) & (f <= 12.0)
        np.testing.assert_allclose(gain[band], 1.0, atol=0.02, err_msg=seg)
        assert np.max(np.abs(phase[band])) < 2.0
    am = apparent_mass_table(r.seat_acceleration, r.pan_force(), r.sample_rate, direction)
    f, mod, _, _ = am.select(direction)
    band = (f > 0.5) & (f <= 12.0)
    np.testing.assert_allclose(mod[band], 1.0, atol=0.02)
    # The pan carries the whole body.
    assert am.static_mass_kg == pytest.approx(75.3, rel=0.01)


# ---------------------------------------------------------------------------
# The default model against the paper's high-stiffness variant and against
# published seated-human data (linear model about the settled equilibrium;
# it matches the nonlinear simulation within 10%: test_linear_vs_nonlinear.py)
# ---------------------------------------------------------------------------

#: Published ranges for seated adults (upright, vertical vibration):
#: * apparent mass: primary resonance 4-6 Hz, normalized modulus at resonance
#:   1.3-2.0 (Fairley & Griffin 1989, J. Biomech. 22(2):81-94, 60 subjects, no
#:   backrest: mean ~5 Hz, ~1.5; Toward & Griffin 2009, J. Sound Vib.
#:   327:657-669: a backrest moves the resonance by < 1 Hz);
#: * seat-to-head vertical transmissibility: primary resonance 4-6 Hz with a
#:   gain of 1.2-2.2 (Paddan & Griffin 1998, J. Sound Vib. 215(4):863-882,
#:   review of 46 studies).
LITERATURE = {"apparent_mass_z": {"f_hz": (4.0, 6.0), "peak": (1.3, 2.0)},
              "head_z": {"f_hz": (4.0, 6.0), "peak": (1.2, 2.2)}}
FREQS = np.linspace(0.2, 12.0, 591)


@pytest.fixture(scope="module")
def linear_variants():
    from ehm_drake.analysis.equivalent import SeatSpectrum, equivalent_linear
    from ehm_drake.params import apply_variant, load_params
    from ehm_drake.signals import PAPER_RMS

    p = load_params()
    out = {}
    # The body softens with the vibration: each variant linearized at the
    # paper's level (0.19 m/s^2, random 0.1-12 Hz, vertical).
    spectrum = SeatSpectrum.flat("z", PAPER_RMS)
    for v in ("default", "high-stiffness"):
        model = build_diagram(apply_variant(p, v) if v != "default" else p)
        eq, _ = static_equilibrium(model)
        out[v] = equivalent_linear(model, spectrum, eq).linear
        if v == "default":
            # The middle of the laboratory studies' range of levels.
            out["default at 1 m/s2"] = equivalent_linear(
                model, SeatSpectrum.flat("z", 1.0), eq).linear
    return out


def test_vertical_resonance_is_in_the_published_range(linear_variants):
    # The published ranges come from studies at 0.25-2 m/s^2: the model at
    # 1 m/s^2 (at the paper's 0.19 m/s^2 it resonates higher, 5.7 Hz for the
    # apparent mass and 6.3 Hz at the head: the body softens with level).
    lm = linear_variants["default at 1 m/s2"]
    f, mod, _ = lm.apparent_mass(FREQS, "z")["z"]
    i = int(np.argmax(mod))
    lo, hi = LITERATURE["apparent_mass_z"]["f_hz"]
    assert lo <= f[i] <= hi  # model: 4.7 Hz
    lo, hi = LITERATURE["apparent_mass_z"]["peak"]
    assert lo <= mod[i] <= hi  # model: 1.50
    assert mod[np.argmin(np.abs(f - 0.5))] == pytest.approx(1.0, abs=0.08)
    head = np.abs(lm.transmissibility_array(FREQS)[:, 6 * 2 + 2, 2])
    j = int(np.argmax(head))
    lo, hi = LITERATURE["head_z"]["f_hz"]
    assert lo <= FREQS[j] <= hi  # model: 5.0 Hz
    lo, hi = LITERATURE["head_z"]["peak"]
    assert lo <= head[j] <= hi  # model: 1.67


def test_high_stiffness_lowers_the_low_frequency_rotational_gains(linear_variants):
    """The paper (Sec. IV): high joint stiffness decreases the gains,
    particularly the rotational ones.  In this model it does so below 2.5 Hz
    (by 50-75%), where the compliant default trunk and head rotate most; above
    it, the stiffened resonances move up and raise the gain (see the note of the
    analysis issue)."""
    T = {v: np.abs(lm.transmissibility_array(FREQS)) for v, lm in linear_variants.items()}
    low = FREQS < 2.5
    # (direction, segment index, dof index): the sagittal rotations in x and z,
    # the lateral ones in y.
    for j, seg, k in ((0, 1, 4), (0, 2, 4), (2, 1, 4), (2, 2, 4), (1, 1, 3), (1, 2, 3),
                      (1, 2, 5)):
        r_low = T["high-stiffness"][FREQS < 1.0, 6 * seg + k, j].mean() / \
            T["default"][FREQS < 1.0, 6 * seg + k, j].mean()
        assert r_low < 0.7, (j, seg, k, r_low)
        if j != 1:
            r = T["high-stiffness"][low, 6 * seg + k, j].mean() / \
                T["default"][low, 6 * seg + k, j].mean()
            assert r < 0.6, (j, seg, k, r)
