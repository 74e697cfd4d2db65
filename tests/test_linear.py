"""Linearization, modes and the linear frequency response (modal issue)."""

from __future__ import annotations

import numpy as np
import pytest
from rigs import chain_rig, continuous_modes

from ehm_drake.analysis.linear import default_frequencies, linearize, linearize_system
from ehm_drake.diagram import build_diagram
from ehm_drake.params import params_from_dict

#: Module fixtures: the module's tests stay on one xdist worker (built once).
pytestmark = pytest.mark.xdist_group("linear")


def _rig_modes(masses, kg, cg, ks=(), cs=(), method="fd"):
    diagram, plant, ctx = chain_rig(masses, kg, cg, ks, cs)
    lm = linearize_system(diagram, ctx, ["state"], 1e-5, method=method,
                          state_names=[f"q:{i}" for i in range(len(masses))]
                          + [f"v:{i}" for i in range(len(masses))])
    return lm, [m for m in lm.modes() if m.kind == "oscillatory"]


def test_one_dof_spring_mass_damper_exact():
    m, k, c = 12.0, 3.0e4, 150.0
    _, modes = _rig_modes([m], k, c)
    assert len(modes) == 1
    wn, zeta = np.sqrt(k / m), c / (2 * np.sqrt(k * m))
    assert modes[0].freq_hz * 2 * np.pi == pytest.approx(wn, rel=1e-4)
    assert modes[0].damping_ratio == pytest.approx(zeta, abs=5e-4)


def test_two_dof_chain_exact():
    masses, kg, cg, ks, cs = [20.0, 8.0], 4.0e4, 300.0, [1.2e4], [60.0]
    _, modes = _rig_modes(masses, kg, cg, ks, cs)
    wn, zeta = continuous_modes(masses, kg, cg, ks, cs)
    assert len(modes) == 2
    for mode, w, z in zip(modes, wn, zeta, strict=True):
        assert mode.freq_hz * 2 * np.pi == pytest.approx(w, rel=1e-4)
        assert mode.damping_ratio == pytest.approx(z, abs=5e-4)


def test_autodiff_and_finite_differences_agree():
    args = ([20.0, 8.0], 4.0e4, 300.0, [1.2e4], [60.0])
    ad, _ = _rig_modes(*args, method="autodiff")
    fd, _ = _rig_modes(*args, method="fd")
    assert ad.method == "autodiff" and fd.method == "fd"
    for M1, M2 in ((ad.A, fd.A), (ad.B, fd.B), (ad.C, fd.C)):
        assert np.max(np.abs(M1 - M2)) <= 1e-4 * np.max(np.abs(M1))


@pytest.fixture(scope="module")
def human(params):
    model = build_diagram(params, guard=False)
    return model, linearize(model)


def test_full_model_linearizes_with_fd_and_is_stable(human):
    _, lm = human
    assert lm.method == "fd"  # Drake's ellipsoid contact is not AutoDiff-capable
    # Plant 62, PID 24, restraint slip 14, the softening's running means and
    # variances 10 (5 tissue points).
    assert lm.A.shape == (110, 110)
    assert lm.is_stable
    assert np.max(lm.continuous_eigenvalues().real) < 0
    modes = lm.modes()
    kinds = {m.kind for m in modes}
    assert {"oscillatory", "integrator", "slip"} <= kinds
    # Integrator and slip modes are labelled, not dropped.
    assert sum(m.kind == "slip" for m in modes) == 14
    osc = [m for m in modes if m.kind == "oscillatory" and 0.5 < m.freq_hz < 12]
    assert len(osc) >= 6
    assert all(0 < m.damping_ratio < 1 for m in osc)


def test_symmetric_body_has_sagittal_and_lateral_modes(human):
    _, lm = human
    labels = [m.label for m in lm.modes() if m.kind == "oscillatory" and m.freq_hz < 12]
    assert any("(sagittal)" in s for s in labels) and any("(lateral)" in s for s in labels)


def test_linear_frequency_response_in_the_data_format(human):
    # Its speed (target < 20 ms) is measured in bench/bench_linear.py.
    _, lm = human
    f = default_frequencies()
    frf = lm.transmissibility(f)
    assert len(frf) == 3 * 30 * 240
    T = lm.transmissibility_array(f)
    c = 6 * 2 + 2  # head z
    assert np.allclose(frf.get("z", "head", "z")[1], np.abs(T[:, c, 2]))


def test_rigid_limit_of_the_transmissibility(human):
    """At 0.05 Hz the body follows the seat: translational gains -> 1."""
    _, lm = human
    T = lm.transmissibility_array([0.05])
    for j, d in enumerate("xyz"):
        for seg in range(5):
            assert abs(T[0, 6 * seg + "xyz".index(d), j]) == pytest.approx(1.0, abs=0.02)


def test_unstable_gains_are_reported_with_the_mode(params):
    # Integral action 250x faster than the default on the neck (Ki > c K / I,
    # the Routh limit of a PI-controlled inertia): the head oscillates and grows.
    bad = params_from_dict({"pid": {"neck": {"integral_time_s": 0.004}}})
    model = build_diagram(bad, guard=False)
    lm = linearize(model)
    assert not lm.is_stable
    unstable = [m for m in lm.modes() if m.kind == "unstable"]
    assert unstable
    assert any(("head" in m.label or "neck" in m.label) for m in unstable)
    assert all(m.label.startswith("UNSTABLE") for m in unstable)
