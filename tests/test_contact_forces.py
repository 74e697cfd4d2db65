"""The logged seat forces derived from the plant's generalized contact forces
(`ehm_drake.systems.contact_forces`) against the contact results' sum
(`SeatForces`), which the diagram logs where the derivation does not hold."""

from __future__ import annotations

import numpy as np
import pytest

import ehm_drake.diagram as diagram
from ehm_drake import jit
from ehm_drake.diagram import DerivedSeatForcesLog, LoggedOutput, build_diagram, on_design
from ehm_drake.params import COMMAND_DESIGN
from ehm_drake.signals import make_seat_signal
from ehm_drake.simulation import settle, vibrate

pytestmark = pytest.mark.skipif(not jit.available(), reason="the derivation needs numba")


def _both(params, settled, monkeypatch, level=2.0, duration=3.0):
    s = params.simulation
    signal = make_seat_signal("random", "xyz", level, duration, 7, s.time_step_s,
                              s.settle_time_s, s.onset_time_s)
    derived = vibrate(params, settled, signal)
    with monkeypatch.context() as m:
        m.setattr(diagram.ContactDecomposition, "of", classmethod(lambda cls, hp: None))
        summed = vibrate(params, settled, signal)
    return derived, summed


@pytest.mark.parametrize("design", ["reference", COMMAND_DESIGN])
def test_derived_seat_forces_are_the_contact_results_to_rounding(params, settled_default,
                                                                  design, monkeypatch):
    p = params if design == params.simulation.design else on_design(params, design)
    settled = settled_default if p is params else settle(p)
    # 2 m/s^2 in x, y and z: contacts open and close during the run.
    derived, summed = _both(p, settled, monkeypatch)
    F, F0 = derived.seat_forces, summed.seat_forces
    assert F.shape == F0.shape
    assert np.abs(F - F0).max() <= 1e-9 * np.abs(F0).max()
    # The same samples at exactly zero (a part whose contacts are all open,
    # in an axis no restraint acts along) and the pan carrying the body.
    assert (F0 == 0).sum() > 0 and np.array_equal(F == 0, F0 == 0)
    assert F0[:, 2].mean() > 300.0
    # Nothing else moved: the logs are the same bits.
    for name in ("channels", "positions", "joint_torques", "his_torque"):
        assert np.array_equal(getattr(derived, name), getattr(summed, name)), name


def test_the_derivation_serves_the_models_seat_only(params):
    built = build_diagram(params, log_period=0.005)
    assert isinstance(built.loggers["seat_forces"], DerivedSeatForcesLog)
    # Where the contacts are not the frictionless point contacts of the
    # body's ellipsoids on the seat's half-spaces, the contact results' sum.
    hydro = params.copy()
    hydro.contact.model = "hydroelastic"
    cushion = {"seat_cushion_dynamics": {}}
    for model in (build_diagram(hydro, log_period=0.005),
                  build_diagram(params, log_period=0.005, effects=cushion)):
        assert isinstance(model.loggers["seat_forces"], LoggedOutput)
    assert "seat_forces" not in build_diagram(params, log_period=0.005,
                                              seat_forces=False).loggers


def test_contacts_acting_alike_get_least_squares_forces(params, monkeypatch):
    """Two contacts whose unit forces move the body alike (a singular
    normal matrix): the least-squares forces, no error from NumPy."""
    from ehm_drake.systems import contact_forces

    d = build_diagram(params, log_period=0.005).loggers["seat_forces"].decomposition
    nv, k = d.tree.nv, len(d.body)
    column = np.random.default_rng(1).normal(size=nv)

    def alike(Q, *args):
        cols = np.zeros((len(Q), k, nv))
        cols[:, 0] = cols[:, 1] = column
        return cols, np.ones((len(Q), k))

    monkeypatch.setattr(contact_forces, "_compiled_columns", alike)
    F = d.contact_forces(np.zeros((3, d.tree.nv)), np.tile(2.0 * column, (3, 1)))
    # 2 = lambda_0 + lambda_1, shared equally (the minimum-norm solution).
    expected = np.zeros((len(contact_forces.SEAT_PART_NAMES), 3))
    for i in (0, 1):
        expected[d.part[i]] += 1.0 * d.normal[i]
    assert np.allclose(F, expected.reshape(-1), atol=1e-12)


def test_long_runs_are_derived_in_bounded_passes_with_the_same_numbers(params):
    d = build_diagram(params, log_period=0.005).loggers["seat_forces"].decomposition
    plant = build_diagram(params).plant
    rng = np.random.default_rng(2)
    Q = plant.GetPositions(plant.CreateDefaultContext()) + 0.01 * rng.normal(
        size=(40, plant.num_positions()))
    tau = rng.normal(size=(40, d.tree.nv))
    whole = d.contact_forces(Q, tau)
    d.CHUNK = 7
    assert np.array_equal(d.contact_forces(Q, tau), whole)
    with pytest.raises(ValueError, match=r"positions \(5, \d+\) and generalized contact"):
        d.contact_forces(Q[:5], tau[:4])
