"""Gap diagnosis: effects, localization statistics, synthetic lab data,
the diagnose CLI's errors, the effects in the nonlinear model.  The
diagnosis end to end (a short blind run with the issue's acceptance
assertions) is in test_gap_blind.py."""

from __future__ import annotations

import numpy as np
import pytest

from ehm_drake.gap.lab.synth import SynthError, SynthSpec, synthesize
from ehm_drake.gap.library.effects import EFFECT_NAMES, EFFECTS, effect_values, validate_effects
from ehm_drake.gap.single.localize import BANDS, Rows, band_index, localize, relative_variance
from ehm_drake.systems.outputs import CHANNEL_NAMES

#: Module fixtures: the module's tests stay on one xdist worker (built once).
pytestmark = pytest.mark.xdist_group("gap")

# ---------------------------------------------------------------------------
# Effects
# ---------------------------------------------------------------------------


def test_the_issue_effects_exist_with_1_to_3_parameters_and_off_at_zero():
    for name in ("reflex_delay", "seat_foam_stiffening", "seat_friction",
                 "backrest_separation", "arms", "visceral_mass", "cocontraction",
                 "seat_cushion_dynamics"):
        assert name in EFFECT_NAMES
        e = EFFECTS[name]
        assert 1 <= len(e.params) <= 3
        v0, v1 = effect_values(name, 0.0), effect_values(name, 1.0)
        assert v0 != v1  # strength moves the parameters


def test_bad_effect_parameters_are_refused_with_the_name():
    with pytest.raises(ValueError, match="unknown effect"):
        validate_effects({"levitation": {}})
    with pytest.raises(ValueError, match="tau_s"):
        validate_effects({"reflex_delay": {"tau_s": -0.01}})
    with pytest.raises(ValueError, match="gamma"):
        validate_effects({"seat_foam_stiffening": {"gamma_per_mm2": float("nan")}})
    with pytest.raises(ValueError, match=r"tau_s .*allowed >= 0 s\), got True"):
        validate_effects({"reflex_delay": {"tau_s": True}})  # a flag is not a delay


# ---------------------------------------------------------------------------
# Localization statistics (no model: known truth, known noise)
# ---------------------------------------------------------------------------


def _rows(rng, coherence=0.9, n_avg=10, directions=("z",)):
    chans = ["pelvis_z", "trunk_x", "head_pitch"]
    f = np.round(np.arange(0.1, 12.0 + 1e-9, 0.1), 6)
    parts = []
    for d in directions:
        for c in chans:
            seg, dof = c.split("_")
            H = (1.0 + 0.5j) / (1 + 1j * f / 6.0)
            parts.append((d, seg, dof, CHANNEL_NAMES.index(c), f, H))
    n = sum(len(p[4]) for p in parts)
    cat = lambda k: np.concatenate([np.broadcast_to(p[k], len(p[4])) for p in parts])  # noqa
    coh = np.full(n, coherence)
    nav = np.full(n, float(n_avg))
    rv = relative_variance(coh, nav, 0.0)
    H_true = cat(5)
    sd = np.sqrt(rv) * np.abs(H_true)
    H_meas = H_true + sd * (rng.standard_normal(n) + 1j * rng.standard_normal(n))
    freq = cat(4)
    rows = Rows(cat(0).astype(str), cat(1).astype(str), cat(2).astype(str), cat(3).astype(int),
                freq, np.full(n, 0.6), band_index(freq), H_meas, coh, nav, rv)
    return rows, H_true


def _chi(rows, H_model):
    from ehm_drake.gap.single.localize import chi2_rows

    return chi2_rows(rows, H_model)


def test_noise_at_its_stated_uncertainty_is_not_called_a_gap():
    false = 0
    for seed in range(20):
        rows, H = _rows(np.random.default_rng(seed))
        false += any(c["significant"] for c in localize(rows, _chi(rows, H)))
    assert false <= 1  # Bonferroni at p = 0.01: ~0.2 expected in 20 datasets


def test_an_unmodelled_resonance_is_localized_to_its_channel_and_band():
    rows, H = _rows(np.random.default_rng(3))
    # The model misses a 10 Hz resonance of the head pitch channel.
    m = (rows.segment == "head") & (rows.dof == "pitch")
    extra = 1.0 + 0.6 / (1 - (rows.freq / 10.0) ** 2 + 2j * 0.1 * rows.freq / 10.0)
    rows.H[m] = rows.H[m] * extra[m]
    cells = localize(rows, _chi(rows, H))
    top = cells[0]
    assert (top["segment"], top["dof"], top["f_lo_hz"]) == ("head", "pitch", 8.0)
    assert top["significant"] and top["share"] > 0.5
    sig = [c for c in cells if c["significant"]]
    assert all(c["segment"] == "head" for c in sig)


def _entry(effect, delta_bic, heldout_share, k=1, level_dependent=False):
    return {"effect": effect, "delta_bic": delta_bic, "gap_reduction_heldout": heldout_share,
            "n_effect_params": k, "level_dependent": level_dependent}


def test_an_effect_spread_below_every_cell_s_threshold_is_named_on_the_joint_test():
    """The own-family blind run (seed 2026) had two visceral-mass trials with no
    significant cell where the candidate removed 77% and 65% of the held-out gap
    (delta BIC -728 and -632 on 12,240 rows); its no-effect and undetectable trials
    reached at most 40% (delta BIC -370).  The numbers are those trials'."""
    from ehm_drake.gap.single.verdict import decide, joint_test

    rows, n_cand = 12240, 8
    thin = [_entry("visceral_mass", -728.0, 0.77), _entry("backrest_separation", -30.0, 0.01, 3)]
    d = decide(0, thin, rows, n_cand, {})
    assert (d["verdict"], d["best"]["effect"], d["jointly"]) == \
        ("explained", "visceral_mass", True)
    # The statistic: the held-out chi^2 improvement without the BIC penalty.
    j = joint_test(thin[0], rows, n_cand)
    assert j["delta_chi2_heldout"] == pytest.approx(728.0 + np.log(2 * rows))
    assert j["dof"] == 1 and j["threshold"] == pytest.approx(10.4, abs=0.05)
    # An undetectable friction effect: significant improvement, 40% of the gap.
    assert decide(0, [_entry("seat_friction", -370.0, 0.40, 2)], rows, n_cand,
                  {})["verdict"] == "no_significant_gap"
    # A small improvement that removes most of a tiny gap is not named either: below its
    # BIC penalty 2 ln(2n) = 20.2, and on 100 rows below the test's 13.2 for 2 parameters.
    small = _entry("seat_friction", 3.0, 0.9, 2)
    assert decide(0, [small], rows, n_cand, {})["verdict"] == "no_significant_gap"
    few = _entry("seat_friction", 2 * np.log(200) - 12.0, 0.9, 2)
    assert few["delta_bic"] < 0 and not joint_test(few, 100, n_cand)["significant"]
    assert decide(0, [few], 100, n_cand, {})["verdict"] == "no_significant_gap"
    # With significant cells the rule is the one it always was (the joint test plays no part).
    d = decide(3, [_entry("seat_friction", -172.0, 0.11, 2)], rows, n_cand, {})
    assert (d["verdict"], d["jointly"]) == ("unexplained", False)
    d = decide(3, [_entry("arms", -900.0, 0.95), _entry("visceral_mass", -800.0, 0.93)],
               rows, n_cand, {})
    assert d["verdict"] == "ambiguous" and [e["effect"] for e in d["close"]] == ["visceral_mass"]


def test_the_bands_are_the_issue_bands():
    assert BANDS == ((0.1, 1.0), (1.0, 2.5), (2.5, 5.0), (5.0, 8.0), (8.0, 12.0))
    assert list(band_index(np.array([0.05, 0.1, 1.0, 7.99, 12.0, 12.1]))) == [-1, 0, 1, 3, 4, -1]


# ---------------------------------------------------------------------------
# Synthetic lab data
# ---------------------------------------------------------------------------


def test_the_first_two_bins_of_a_welch_grid_are_not_analysed():
    """Their Hann main lobes reach below the excited band (tests/test_spectral.py measures
    the bias): the diagnosis drops them, per channel and level, and keeps a table that
    starts higher."""
    from ehm_drake.analysis.formats import FrfData
    from ehm_drake.gap.single.localize import rows_from_frf

    def table(freqs, level):
        n = len(freqs)
        return FrfData(direction=np.full(n, "z"), segment=np.full(n, "head"),
                       dof=np.full(n, "pitch"), freq_hz=np.asarray(freqs, float),
                       gain=np.ones(n), phase_deg=np.zeros(n), coherence=np.full(n, 0.9),
                       level_rms=np.full(n, level), n_averages=np.full(n, 4.0))

    welch = np.arange(1, 121) * 0.1  # 10 s segments: 0.1 ... 12 Hz
    trimmed = np.arange(5, 121) * 0.1  # a lab's table from 0.5 Hz
    frf = FrfData.concat([table(welch, 0.3), table(trimmed, 0.6), table(welch / 2, 1.0)])
    lowest_bins = frf.lowest_welch_bins()
    assert lowest_bins.sum() == 4
    assert sorted(frf.freq_hz[lowest_bins]) == pytest.approx([0.05, 0.1, 0.1, 0.2])
    rows = rows_from_frf(frf)
    for level, lowest in ((0.3, 0.3), (0.6, 0.5), (1.0, 0.15)):
        assert rows.freq[rows.level == level].min() == pytest.approx(lowest)


def test_synth_refuses_bad_requests(tmp_path):
    with pytest.raises(SynthError, match="strength"):
        SynthSpec({"arms": 1.5}, 1).validate()
    with pytest.raises(SynthError, match="m/s\\^2"):
        SynthSpec({}, 1, levels=(300.0,)).validate()
    with pytest.raises(SynthError, match="directions"):
        SynthSpec({}, 1, directions="zz").validate()
    with pytest.raises(SynthError, match="key"):
        synthesize(SynthSpec({}, 1, directions="z"), tmp_path / "d", tmp_path / "d" / "k.json")


# ---------------------------------------------------------------------------
# The diagnose CLI (the end-to-end blind run is in test_gap_blind.py)
# ---------------------------------------------------------------------------


def test_diagnose_cli_refuses_bad_data_with_a_clear_message(tmp_path, capsys):
    from ehm_drake.cli import main

    assert main(["diagnose", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")]) == 2
    assert "nowhere" in capsys.readouterr().err
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "frf.csv").write_text(
        "direction,segment,dof,freq_hz,gain,phase_deg,coherence,level_rms\n"
        "z,head,z,1.0,nan,0,0.9,0.6\n")
    assert main(["diagnose", str(bad), "--out", str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err
    assert "gain" in err and "Traceback" not in err
    assert main(["synth", "--effect", "arms", "--strength", "2", "--seed", "1", "--out",
                 str(tmp_path / "s"), "--key", str(tmp_path / "k.json")]) == 2
    assert "[0, 1]" in capsys.readouterr().err


# ---------------------------------------------------------------------------
# The effects in the nonlinear model (statics and a short run)
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def settled_effects():
    from ehm_drake.params import load_params
    from ehm_drake.simulation import settle

    p = load_params()
    out = {"none": settle(p, settle_time=0.5)}
    for name in EFFECT_NAMES:
        out[name] = settle(p, settle_time=0.5, effects={name: effect_values(name, 1.0)})
    return p, out


def _support(s):
    return s.summary["pan_force_n"] + s.summary["floor_force_n"]


@pytest.mark.slow
def test_effects_change_the_statics_only_where_physics_says(settled_effects):
    _, st = settled_effects
    base = st["none"]
    g = 9.81
    # The abdominal wobbling mass (5 kg at strength 1) and the arms are parts of the
    # same 75.3 kg body (taken from the torso), so the seat and floor carry the same
    # weight; the total weight is carried (pan + floor + backrest's vertical share).
    for name in ("visceral_mass", "arms"):
        assert _support(st[name]) == pytest.approx(_support(base), rel=0.02), name
    assert _support(base) == pytest.approx(75.3 * g, rel=0.05)
    # Moving the pads 4 mm back unloads the backrest.
    assert st["backrest_separation"].summary["backrest_force_n"]["total"] < \
        0.7 * base.summary["backrest_force_n"]["total"]
    # Effects that act only under vibration leave the static support unchanged.
    for name in ("reflex_delay", "seat_foam_stiffening", "seat_friction", "cocontraction",
                 "seat_cushion_dynamics"):
        assert _support(st[name]) == pytest.approx(_support(base), rel=0.01), name
    for name, s in st.items():
        assert s.summary["max_joint_error_deg"] < 0.5, name
        assert abs(s.summary["head_pitch_deg"]) < 3.0, name


@pytest.mark.slow
def test_every_effect_runs_in_the_time_domain(settled_effects):
    from ehm_drake.signals import make_seat_signal
    from ehm_drake.simulation import vibrate

    p, st = settled_effects
    s = p.simulation
    sig = make_seat_signal("random", "z", 0.6, 2.0, 3, s.time_step_s, 0.5, 0.5)
    ref = vibrate(p, st["none"], sig)
    head_ref = np.std(ref.channel("head", "z"))
    for name in EFFECT_NAMES:
        r = vibrate(p, st[name], sig, effects={name: effect_values(name, 1.0)})
        head = r.channel("head", "z")
        assert np.all(np.isfinite(head)), name
        assert 0.3 * head_ref < np.std(head) < 3.0 * head_ref, name


@pytest.mark.slow
def test_every_effect_acts_the_same_on_the_implicit_design(settled_effects):
    """Each effect's change of the 30 body channels (the run with it less
    the run without it, 2 s of z excitation) on the implicit design at its
    5 ms step is the reference design's: correlation > 0.98, size within
    10%.  Before the fixes, the cushion's was 0.70 of it (the explicit half
    of the pan contacts' damping acted on the body's absolute velocity, not
    relative to the moving cushion) and the reflex delay's 1.20 (a
    30 ms delay was 35 ms at 5 ms)."""
    from ehm_drake.params import with_design
    from ehm_drake.signals import at_time_step, make_seat_signal
    from ehm_drake.simulation import settle, vibrate

    p, st = settled_effects
    q = with_design(p, "implicit")
    sig = make_seat_signal("random", "z", 0.6, 2.0, 3, p.simulation.time_step_s, 0.5, 0.5)
    sig_q = at_time_step(sig, q.simulation.time_step_s)

    def channels(name, params, settled, signal):
        effects = None if name == "none" else {name: effect_values(name, 1.0)}
        return vibrate(params, settled, signal, effects=effects).channels

    ref_none = channels("none", p, st["none"], sig)
    q_none = channels("none", q, settle(q, settle_time=0.5), sig_q)
    assert ref_none.shape == q_none.shape
    judged = []
    for name in EFFECT_NAMES:
        a = channels(name, p, st[name], sig) - ref_none
        q_settled = settle(q, settle_time=0.5, effects={name: effect_values(name, 1.0)})
        b = channels(name, q, q_settled, sig_q) - q_none
        if np.linalg.norm(a) < 0.005 * np.linalg.norm(ref_none - ref_none[0]):
            continue  # no change worth comparing under z (friction, backrest)
        judged.append(name)
        corr = np.sum(a * b) / (np.linalg.norm(a) * np.linalg.norm(b))
        assert corr > 0.98, (name, corr)
        assert np.linalg.norm(b) / np.linalg.norm(a) == pytest.approx(1.0, abs=0.1), name
    assert {"reflex_delay", "seat_cushion_dynamics", "arms"} <= set(judged)


def test_the_reflex_delay_fit_stops_where_the_loop_is_still_stable():
    """The closed loop linearized with its delay buffer (implicit design,
    5 ms): stable at the largest delay the diagnosis may fit, unstable at
    40 ms (the bound before: a fit there described a loop that cannot be
    measured)."""
    from ehm_drake.analysis.linear import linearize
    from ehm_drake.diagram import build_diagram, on_design
    from ehm_drake.params import load_params

    p = on_design(load_params(), "implicit")
    bound = EFFECTS["reflex_delay"].params[0].bounds[1]

    def radius(tau):
        lm = linearize(build_diagram(p, effects={"reflex_delay": {"tau_s": tau}}), method="fd")
        k = lm._reduced()
        return np.abs(np.linalg.eigvals(lm.A[np.ix_(k, k)])).max()

    assert radius(bound) < 1.0
    assert radius(0.04) > 1.0


def test_a_delay_of_n_steps_lags_the_plant_state_by_n_steps():
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import (
        Multiplexer,
        TrajectorySource,
        VectorLogSink,
        ZeroOrderHold,
    )
    from pydrake.trajectories import PiecewisePolynomial

    from ehm_drake.gap.library.effects import delay_system

    h = 0.005
    for steps in (1, 2, 6):
        b = DiagramBuilder()
        ramp = b.AddSystem(TrajectorySource(PiecewisePolynomial.FirstOrderHold(
            [0.0, 1.0], np.array([[0.0, 1.0]]))))
        state = b.AddSystem(ZeroOrderHold(h, 1))  # a discrete state, as the plant's
        delay = b.AddSystem(delay_system(steps, h, 1))
        mux = b.AddSystem(Multiplexer([1, 1]))
        log = b.AddSystem(VectorLogSink(2, h))
        b.Connect(ramp.get_output_port(), state.get_input_port())
        b.Connect(state.get_output_port(), delay.get_input_port())
        b.Connect(state.get_output_port(), mux.get_input_port(0))
        b.Connect(delay.get_output_port(), mux.get_input_port(1))
        b.Connect(mux.get_output_port(), log.get_input_port())
        sim = Simulator(b.Build())
        sim.AdvanceTo(0.2)
        x = log.FindLog(sim.get_context()).data()
        lag = x[0, 20:] - x[1, 20:]  # the ramp's value is its time
        assert np.allclose(lag, steps * h, atol=1e-12), (steps, lag[:3])


# ---------------------------------------------------------------------------
# Equivalent linearization of slipping restraints (Maxwell element)
# ---------------------------------------------------------------------------


def test_maxwell_equivalent_matches_the_describing_function():
    from ehm_drake.gap.library.models import jenkins_factors, maxwell_equivalent

    w = 2 * np.pi * 3.0
    for r in (0.3, 1.0, 3.0):
        gk, gh = jenkins_factors(np.array([r]))
        k_m, lam = maxwell_equivalent(gk, gh, w)
        K = k_m * 1j * w / (lam + 1j * w)  # complex stiffness / k at w
        assert K.real == pytest.approx(gk, rel=1e-9)
        assert K.imag == pytest.approx(gh, rel=1e-9)
    # Below the limit (no slip): the restraint unchanged, no creep.
    k_m, lam = maxwell_equivalent(1.0, 0.0, w)
    assert k_m == 1.0 and lam == 0.0


def test_creeping_slip_lets_the_body_slide_below_its_rate():
    """A 10 kg mass on one restraint axis (k = 1e4 N/m) under a force: with
    the slip state added at rate lam the mass slides under a slow force (its
    displacement far beyond F/k; the spring's own deflection stays F/k, as in
    a Maxwell element), while well above lam the restraint holds as before."""
    from types import SimpleNamespace

    from ehm_drake.gap.library.family import response
    from ehm_drake.gap.library.models import Predictor

    m, k, h, lam = 10.0, 1e4, 1e-3, 2 * np.pi * 1.0
    # Symplectic Euler of m x'' = -k (x - s) + F: state [x, v].
    A = np.array([[1 - h * h * k / m, h], [-h * k / m, 1.0]])
    Bu = np.array([[h * h / m], [h / m]])  # per N of force
    coupling = np.array([[h * h * k / m, 0.0], [h * k / m, 0.0]])  # dx+/ds, two axes
    # Outputs: the position, then the deflection of both axes (axis 1 idle).
    C = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    fake = SimpleNamespace(
        family=SimpleNamespace(K=np.zeros((1, 2)), h=h, directions=["k_shear:pelvis"],
                               output_groups={"restraint_deflection": slice(1, 3)},
                               family=SimpleNamespace(nominal=SimpleNamespace(
                                   slip_coupling=coupling))),
        _group_of=np.array(["pelvis"]))
    mats = (A, Bu, np.zeros((2, 1)), C)
    lam_groups = np.zeros(5)
    same = Predictor._with_creep(fake, mats, lam_groups, np.zeros(1))
    assert all(np.array_equal(a, b) for a, b in zip(same[:4], mats, strict=True))
    lam_groups[0] = lam
    A2, Bu2, Bw2, C2, K2 = Predictor._with_creep(fake, mats, lam_groups, np.zeros(1))
    assert A2.shape == (4, 4) and C2.shape == (3, 4) and K2.shape == (1, 4)  # 2 slip states
    f = np.array([0.02, 20.0])
    H0 = np.abs(response(A, Bu, np.zeros((2, 1)), C, np.zeros((1, 2)), h, f, [0]))[:, :, 0]
    H1 = np.abs(response(A2, Bu2, Bw2, C2, K2, h, f, [0]))[:, :, 0]
    assert H0[0, 0] == pytest.approx(1 / k, rel=0.01)  # stuck: x = F / k
    assert H1[0, 0] > 20 / k  # creeping: the mass slides
    assert H1[0, 1] == pytest.approx(1 / k, rel=0.01)  # the spring carries F
    assert H1[1, 0] == pytest.approx(H0[1, 0], rel=0.02)  # well above lam: unchanged


def _sdof(f, fn, zeta=0.3):
    """Base-excited single-DoF transmissibility with natural frequency fn."""
    r = f / fn
    return (1 + 2j * zeta * r) / (1 - r * r + 2j * zeta * r)


def _level_rows(fn_data, fn_model, levels=(0.3, 0.6), rng=None):
    """Vertical rows of pelvis, trunk and head at two levels with resonances
    `fn_data` (per level; measured with 1% noise when `rng`) and the model's
    prediction with `fn_model`."""
    f = np.round(np.arange(0.1, 12.0 + 1e-9, 0.1), 6)
    parts, Hm = [], []
    for lv, fd, fm in zip(levels, fn_data, fn_model, strict=True):
        for seg in ("pelvis", "trunk", "head"):
            H = _sdof(f, fd)
            if rng is not None:
                noise = rng.standard_normal(len(f)) + 1j * rng.standard_normal(len(f))
                H = H * (1 + 0.01 * noise)
            parts.append((seg, CHANNEL_NAMES.index(f"{seg}_z"), lv, H))
            Hm.append(_sdof(f, fm))
    n = len(f) * len(parts)
    cat = lambda k: np.concatenate([np.broadcast_to(p[k], len(f)) for p in parts])  # noqa
    freq = np.tile(f, len(parts))
    coh = np.full(n, 0.95)
    nav = np.full(n, 20.0)
    rows = Rows(np.full(n, "z"), cat(0).astype(str), np.full(n, "z"), cat(1).astype(int), freq,
                cat(2).astype(float), band_index(freq), cat(3), coh, nav,
                relative_variance(coh, nav, 0.0))
    return rows, np.concatenate(Hm)


def test_peak_frequency_finds_a_resonance_between_bins():
    from ehm_drake.gap.single.resonance import peak_frequency

    f = np.round(np.arange(0.1, 12.0 + 1e-9, 0.1), 6)
    for fn in (4.03, 4.55, 5.71):
        # The SDOF gain peaks a little below fn: find its true maximum finely.
        fine = np.linspace(1, 12, 200001)
        true = fine[np.argmax(np.abs(_sdof(fine, fn)))]
        assert peak_frequency(f, _sdof(f, fn)) == pytest.approx(true, abs=0.02)
    assert np.isnan(peak_frequency(np.array([0.5, 0.6]), np.array([1.0, 2.0])))


def test_resonance_shift_compares_the_subjects_softening_with_the_models():
    """A subject whose vertical resonance falls 5 -> 4 Hz from 0.3 to 0.6
    m/s^2 (x0.8 per doubling) softens more than a model that falls
    5 -> 4.6 Hz (x0.92), and less than one that falls 5 -> 3.5 Hz; equal
    shifts read "as much as", with measurement noise."""
    from ehm_drake.gap.single.resonance import resonance_shift

    rng = np.random.default_rng(4)
    for fn_model, word in (((5.0, 4.6), "more than"), ((5.0, 3.5), "less than"),
                           ((5.2, 4.16), "as much as")):
        rows, Hm = _level_rows((5.0, 4.0), fn_model, rng=rng)
        e = resonance_shift(rows, Hm)["z"]
        assert e["levels"] == [0.3, 0.6]
        assert e["data_per_doubling"] == pytest.approx(0.8, abs=0.015)
        assert e["model_per_doubling"] == pytest.approx(fn_model[1] / fn_model[0], abs=0.015)
        assert e["compared"] == word, (fn_model, e)
    # Without the model's prediction: the data's shift alone; one level: nothing.
    rows, _ = _level_rows((5.0, 4.0), (5.0, 4.0))
    e = resonance_shift(rows)["z"]
    assert "compared" not in e and "model" not in e["segments"]["pelvis"]
    assert resonance_shift(rows.take(rows.level == 0.3)) == {}
    # A segment not measured is left out (no NaN in the report).
    e = resonance_shift(rows.take(rows.segment != "head"))["z"]
    assert set(e["segments"]) == {"pelvis", "trunk"}
    assert e["data_per_doubling"] == pytest.approx(0.8, abs=0.005)


def test_frequency_scale_maps_one_level_onto_the_other():
    """Resonances 5 -> 4 Hz from 0.3 to 0.6 m/s^2 in every segment: the
    whole resonance region scales x0.8, with 1% noise per bin; a segment
    whose gain also drops 20% does not change it (the gain is profiled
    out); shifts beyond the searched range give NaN, not an edge value."""
    from ehm_drake.gap.single.resonance import _curves, frequency_scale, resonance_shift

    rng = np.random.default_rng(3)
    rows, Hm = _level_rows((5.0, 4.0), (5.0, 4.6), rng=rng)
    e = resonance_shift(rows, Hm)["z"]["scale"]
    assert e["data_per_doubling"] == pytest.approx(0.8, abs=0.005)
    assert e["model_per_doubling"] == pytest.approx(0.92, abs=0.005)
    segs = ["pelvis", "trunk", "head"]
    lo, hi = _curves(rows, "z", 0.3, segs), _curves(rows, "z", 0.6, segs)
    quieter = [(lf, la - 0.2, va, vm) for lf, la, va, vm in hi]
    assert frequency_scale(lo, quieter, (2.0, 10.0), 1.0) == pytest.approx(
        frequency_scale(lo, hi, (2.0, 10.0), 1.0), abs=1e-9)
    rows, _ = _level_rows((5.0, 2.5), (5.0, 4.6))
    assert resonance_shift(rows)["z"]["scale"]["data_per_doubling"] is None


def test_shift_noise_is_the_scatter_that_measurement_noise_gives_the_scale():
    """The data's frequency scale per doubling, measured again and again with
    1% noise per component (coherence and averages stating that error),
    scatters as much as `shift_noise` predicts from one measurement; stated
    noise ten times larger gives a standard deviation several times larger."""
    from ehm_drake.gap.single.resonance import resonance_shift, shift_noise

    rng = np.random.default_rng(11)
    factors, predicted = [], []
    for _ in range(30):
        rows, Hm = _level_rows((5.0, 4.0), (5.0, 4.6), rng=rng)
        # (1 - g2) / (2 n g2) = 1e-4 per component, n = 20 averages.
        rows.coherence[:] = 1.0 / (1.0 + 40e-4)
        rows.n_averages[:] = 20.0
        e = resonance_shift(rows, Hm)["z"]["scale"]
        factors.append(e["data_per_doubling"])
        predicted.append(e["data_std"])
    scatter = np.std(factors)
    assert 0.6 < np.median(predicted) / scatter < 1.6, (np.median(predicted), scatter)
    rows.coherence[:] = 1.0 / (1.0 + 40e-2)
    noisier = shift_noise(rows, "z", 0.3, 0.6, ["pelvis", "trunk", "head"])
    assert 5.0 < noisier / np.median(predicted) < 25.0, (noisier, np.median(predicted))


def test_level_rule_names_softening_beyond_the_models_own():
    """One subject at two levels: the level rule names softening when the
    vertical resonance falls clearly more than the refitted model's (x0.80
    against x0.92), not when it falls as much (x0.80 against x0.804) or less,
    not when the noise stated by the data could make the difference, and not
    over an effect already named; the report says so."""
    from ehm_drake.gap.report import _resonance_lines
    from ehm_drake.gap.single.resonance import (
        SOFTENING_SHIFT,
        apply_softening_rule,
        resonance_shift,
        softening_rule,
    )

    rng = np.random.default_rng(5)
    for fn_model, named in (((5.0, 4.6), True), ((5.0, 4.02), False), ((5.0, 3.8), False)):
        rows, Hm = _level_rows((5.0, 4.0), fn_model, rng=rng)
        rule = softening_rule(resonance_shift(rows, Hm))
        assert rule["named"] is named, (fn_model, rule)
        assert rule["difference"] == pytest.approx(0.8 - fn_model[1] / fn_model[0], abs=0.005)
        assert rule["threshold"] == -SOFTENING_SHIFT
    # The same shift with data whose stated error is 30% per component: not named.
    rows, Hm = _level_rows((5.0, 4.0), (5.0, 4.6), rng=rng)
    rows.coherence[:] = 0.3
    rows.n_averages[:] = 4.0
    rule = softening_rule(resonance_shift(rows, Hm))
    assert rule["noise_std"] > -rule["difference"] / 3 and not rule["named"]
    # Without the model or a vertical test at two levels: no rule.
    rows, Hm = _level_rows((5.0, 4.0), (5.0, 4.6), rng=rng)
    assert softening_rule(resonance_shift(rows)) is None
    assert softening_rule(resonance_shift(rows.take(rows.level == 0.3), Hm)) is None

    resonance = resonance_shift(rows, Hm)

    def report(verdict, best=None):
        return {"verdict": verdict, "best_effect": best, "best_candidate": best,
                "explanation": "the model-form gap dominates", "evidence": {
                    "resonance": resonance},
                "ranking": [{"effect": "softening", "gap_reduction_heldout": 0.02}],
                "structural": {"ranking": [{"effect": "softening", "effect_share": 0.01}]}}

    r = report("structural")
    assert apply_softening_rule(r, ["arms", "softening"])
    assert (r["verdict"], r["best_effect"]) == ("explained", "softening")
    assert r["explanation"].startswith("level rule") and "removes 1% of the held-out gap" in \
        r["explanation"]
    assert "softening named" in "\n".join(_resonance_lines(resonance, r["level_rule"]))
    # Without a structural pass the ordinary ranking's share is quoted, worse or not,
    # and what the diagnosis said without the rule is kept.
    r = report("no_significant_gap")
    del r["structural"]
    r["ranking"][0]["gap_reduction_heldout"] = -0.5
    apply_softening_rule(r, ["softening"])
    assert r["best_effect"] == "softening" and "does not reduce the held-out gap (it grows " \
        "by 50%)" in r["explanation"]
    assert r["explanation"].endswith("Without the rule: the model-form gap dominates")
    for verdict, best, names in (("explained", "arms", ["arms", "softening"]),
                                 ("structural", None, ["arms"])):
        r = report(verdict, best)
        assert not apply_softening_rule(r, names)
        assert (r["verdict"], r["best_effect"]) == (verdict, best)
        assert r["level_rule"]["named"]


# ---------------------------------------------------------------------------
# The softening candidate acts on the pan's tissue
# ---------------------------------------------------------------------------


def test_the_softening_candidate_softens_the_pan_tissue_and_leaves_the_back_pads():
    """In the linear family the candidate's extra loss lowers the normal
    stiffness of the pelvis and thigh points on the pan by the loss at
    their movement, r x / (1 + x) with x the movement over the critical
    amplitude, and leaves the back pads' (where a separating back acts)
    and the feet's as they are."""
    from types import SimpleNamespace

    from ehm_drake.gap.library.family import EQUIVALENT_DIRECTIONS, GROUP_NAMES
    from ehm_drake.gap.library.models import Predictor
    from ehm_drake.model.softening import ElementSet

    n = len(GROUP_NAMES)  # one point per restraint group
    info = SimpleNamespace(
        names=[f"{g}_point" for g in GROUP_NAMES], groups=np.array(GROUP_NAMES),
        parts=np.array(["pan", "pan", "lower_pad", "upper_pad", "floor"]),
        k_contact=np.full(n, 2e5), force_limit=np.full(n, 1e3), k_shear=np.full(n, 1e4),
        penetration=np.full(n, 4e-3), deflection=np.zeros((n, 2)))
    pred = object.__new__(Predictor)
    critical = 7e-5
    movement = 1.4e-4  # twice the critical amplitude: the loss is 2/3 of r
    pred.statics = SimpleNamespace(info=info, separation_slope=np.zeros(n))
    pred.candidate = SimpleNamespace(values=lambda c: {"softening": {"extra_loss": c[0]}})
    pred.tests = [SimpleNamespace(level=0.6)]
    pred.sigmas = [{"normal": np.full(n, movement), "deflection": np.full(2 * n, 1e-6),
                    "deflection_rate": np.full(2 * n, 1e-5)}]
    pred._eq_names = list(EQUIVALENT_DIRECTIONS)
    pred._group_of = info.groups
    pred._tissue = (np.zeros(n, bool), ElementSet((), (), *[np.zeros(0)] * 5))
    pred._critical = critical
    off = pred._equivalent(0, [0.0])
    on = pred._equivalent(0, [0.45])
    k = {g: EQUIVALENT_DIRECTIONS.index(f"k_normal:{g}") for g in GROUP_NAMES}
    for g in ("pelvis", "thighs"):
        assert on[k[g]] - off[k[g]] == pytest.approx(-0.45 * 2 / 3, rel=1e-12), g
    for g in ("lower_pad", "upper_pad", "feet"):
        assert on[k[g]] == off[k[g]], g
    # Nothing else moves: the candidate acts through the pan's normal stiffness
    # alone (no shear, damping or creep direction).
    rest = [i for i in range(len(on)) if i not in (k["pelvis"], k["thighs"])]
    np.testing.assert_array_equal(on[rest], off[rest])


def test_the_softening_candidate_adds_elements_at_the_pan_points_only():
    """In the time domain the candidate's system ("softening") holds one
    element per restraint point on the pan, the pelvis's and the thighs',
    with the model's critical amplitude, and none at the back pads or the
    feet."""
    from ehm_drake.diagram import build_diagram
    from ehm_drake.model.restraints import restraint_points
    from ehm_drake.params import load_params

    p = load_params()
    model = build_diagram(p, effects={"softening": effect_values("softening", 1.0)})
    el = model.systems["softening"].elements
    pan = [q.name for q in restraint_points(model.hp) if q.pair in ("pelvis_pan", "thighs_pan")]
    assert list(el.names) == pan == ["buttocks", "thigh_l", "thigh_r"]
    others = {q.name for q in restraint_points(model.hp)} - set(pan)
    assert others and not others & set(el.names)
    np.testing.assert_array_equal(el.max_loss, 0.5)
    np.testing.assert_array_equal(el.critical, p.softening.tissue.critical_rms_m)
