"""Transmissibility and apparent mass of the model (analysis issue):
the rigid-body check through the whole pipeline, and the paper's claim that
high joint stiffness lowers the rotational gains."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from ehm_drake.analysis.apparent_mass import apparent_mass_table
from ehm_drake.analysis.spectral import transmissibility
from ehm_drake.diagram import build_diagram
from ehm_drake.params import params_from_dict
from ehm_drake.signals import make_seat_signal
from ehm_drake.simulation import (
    SimulationResult,
    StateMap,
    static_equilibrium,
)

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
    })


def _run_rigid(direction: str) -> SimulationResult:
    """The body with every joint locked (a rigid body) on the stiff seat."""
    params = _rigid_params()
    eq, smap = static_equilibrium(build_diagram(params, guard=False))
    x0 = smap.get(eq)
    sig = make_seat_signal("random", direction, 0.5, 45.0, 2, settle_time=0.5, onset_time=0.5)
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
