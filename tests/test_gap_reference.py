"""Diagnosis against a reference group (`ehm_drake.gap.reference_group.reference`).

Fast: the group's statistics (geometric mean of gain and phase, deviations,
leave-one-out), the protocol check and the profiled scatter term (its chi^2
equals the one under the full covariance).  Slow: a short blind run on the
`lumped` reality (z at two levels, 30 s) with a reference group of 4
subjects: the model-form gap located, no effect named on a no-effect
subject, every candidate with its threshold from the group.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from bench_scripts import bench_script

from ehm_drake.gap.library.models import TestInput as _TestInput
from ehm_drake.gap.reference_group.group import MIN_SUBJECTS, ReferenceGroup, level_pairs
from ehm_drake.gap.reference_group.reference import profile_nuisance
from ehm_drake.gap.single.diagnose import DiagnosisError, LabData
from ehm_drake.gap.single.localize import Rows, band_index
from ehm_drake.params import load_params


def _lab(H_of_row, tests=(("z", 0.3), ("z", 0.6)), name="s"):
    """A subject's LabData on 2 tests x 2 channels x 40 bins, H given per row."""
    f = np.round(np.arange(0.3, 12.0, 0.3), 6)
    recs = [(d, seg, dof, ch, fi, lv) for d, lv in tests
            for seg, dof, ch in (("pelvis", "z", 2), ("head", "pitch", 16)) for fi in f]
    d, seg, dof, ch, fr, lv = (np.array(c) for c in zip(*recs, strict=True))
    fr, lv = fr.astype(float), lv.astype(float)
    n = len(fr)
    rows = Rows(d, seg, dof, ch.astype(int), fr, lv, band_index(fr), H_of_row(fr, lv, ch),
                np.full(n, 0.95), np.full(n, 10.0), np.full(n, 0.03**2))
    return LabData(None, rows, [_TestInput.flat(t, v) for t, v in tests], name)


def _subjects(K, seed=0):
    rng = np.random.default_rng(seed)
    labs, shifts = [], []
    for k in range(K):
        a, b = rng.normal(0, 0.2), rng.normal(0, 0.3)
        shifts.append(a + 1j * b)

        def H(f, lv, ch, a=a, b=b):
            # Phases near +-pi, so an average that does not wrap would fail.
            return (1 + f / 5) * np.exp(a + 1j * (np.pi - 0.05 + b))
        labs.append(_lab(H, name=f"s{k}"))
    return labs, np.array(shifts)


def test_group_mean_is_the_geometric_mean_of_gain_and_wrapped_phase():
    labs, shifts = _subjects(6)
    g = ReferenceGroup.from_labs(labs)
    f = g.rows.freq
    s = shifts.mean()
    expected = np.log(1 + f / 5) + s.real + 1j * (np.pi - 0.05 + s.imag)
    d = g.mean_log - expected
    d = d.real + 1j * np.angle(np.exp(1j * d.imag))
    assert np.max(np.abs(d)) < 1e-12
    # Each subject's deviation is its own shift less the mean; they sum to 0.
    dev = shifts - s
    assert np.allclose(g.deviations, dev[:, None] * np.ones(len(f)), atol=1e-12)
    assert np.allclose(g.deviations.sum(axis=0), 0, atol=1e-12)
    # The variance of a row is that of the shifts (constant, so smoothing keeps it).
    assert np.allclose(g.variance, np.sum(np.abs(dev) ** 2) / 5, rtol=1e-12)


def test_leaving_one_subject_out_is_the_group_of_the_others():
    labs, _ = _subjects(6, seed=3)
    g = ReferenceGroup.from_labs(labs)
    for j in (0, 4):
        a = g.without(j)
        b = ReferenceGroup.from_labs([lab for i, lab in enumerate(labs) if i != j])
        assert a.size == b.size == 5
        assert np.allclose(a.mean_log, b.mean_log, atol=1e-12)
        assert np.allclose(a.deviations, b.deviations, atol=1e-12)
        assert np.allclose(a.variance, b.variance, rtol=1e-10)
        # The left-out subject's own response is unchanged (phase modulo 2 pi).
        assert np.allclose(np.exp(g.subject_log(j)), labs[j].rows.H, rtol=1e-12)


def test_protocol_checks():
    labs, _ = _subjects(5)
    with pytest.raises(DiagnosisError, match=f"at least {MIN_SUBJECTS}"):
        ReferenceGroup.from_labs(labs[:MIN_SUBJECTS - 1])
    g = ReferenceGroup.from_labs(labs)
    one_test = _lab(lambda f, lv, ch: np.ones(len(f), complex), tests=(("z", 0.3),), name="x")
    with pytest.raises(DiagnosisError, match="same tests"):
        g.align(one_test)
    other = _lab(lambda f, lv, ch: np.ones(len(f), complex), tests=(("x", 0.3), ("x", 0.6)))
    with pytest.raises(DiagnosisError, match="one protocol"):
        ReferenceGroup.from_labs([*labs, other])
    # A subject given twice (a folder and a link to it): its data twice
    # would narrow the scatter; an error naming both.
    twice = LabData(None, labs[2].rows, labs[2].tests, "link_to_s2")
    with pytest.raises(DiagnosisError, match="link_to_s2 holds the same data as s2"):
        ReferenceGroup.from_labs([*labs, twice])
    # A subject with a zero gain: a clear error before any model work.
    from ehm_drake.gap.reference_group.reference import diagnose_with_reference
    bad = _lab(lambda f, lv, ch: np.where(f > 6, 0.0, 1.0) + 0j, name="bad")
    with pytest.raises(DiagnosisError, match="zero or non-finite"):
        diagnose_with_reference(bad, g, progress=False)
    # A subject with the rows in another order aligns row for row.
    lab = labs[2]
    perm = np.random.default_rng(1).permutation(len(lab.rows))
    shuffled = LabData(None, lab.rows.take(perm), lab.tests, "shuffled")
    idx = g.align(shuffled)
    assert np.array_equal(shuffled.rows.H[idx], lab.rows.H)


def test_profiled_scatter_gives_the_chi2_of_the_full_covariance():
    rng = np.random.default_rng(7)
    n, K = 50, 6
    x = rng.normal(size=n) + 1j * rng.normal(size=n)
    A = rng.normal(size=(n, K)) + 1j * rng.normal(size=(n, K))
    every = np.ones(n, bool)
    u = profile_nuisance(x, A, every)
    profiled = np.sum(np.abs(x - A @ u) ** 2) + u @ u
    y = np.concatenate([x.real, x.imag])
    At = np.vstack([A.real, A.imag])
    full = y @ np.linalg.solve(np.eye(2 * n) + At @ At.T, y)
    assert profiled == pytest.approx(full, rel=1e-10)
    # A residual along the scatter costs less than the same size across it.
    along = A[:, 0] * 3
    across = rng.normal(size=n) + 1j * rng.normal(size=n)
    across *= np.linalg.norm(along) / np.linalg.norm(across)

    def chi(z):
        v = profile_nuisance(z, A, every)
        return np.sum(np.abs(z - A @ v) ** 2) + v @ v
    assert chi(along) < 0.2 * chi(across)


def _stub_scorer(group, sig_of, upper, statics=None):
    """A `_Scorer` on `group` whose every candidate has the one-coordinate
    signature `sig_of` on [0, upper] (no response statistics to refresh);
    with `statics` (`models.Statics`), the pads' static facts of a
    backrest separation (default: no pad point ever unloads)."""
    from ehm_drake.gap.library.models import Statics
    from ehm_drake.gap.reference_group.reference import _Scorer

    scorer = object.__new__(_Scorer)
    scorer.tests = group.tests
    scorer.test_masks = [group.rows.test_mask(t.direction, t.level) for t in group.tests]
    scorer.statics = statics or Statics(SimpleNamespace(parts=[], penetration=np.zeros(0)),
                                        np.zeros(0))
    scorer.signature_fn = lambda cand: (sig_of, lambda c: None, np.array([0.0]),
                                        scorer.separation_reach(cand, np.array([upper])))
    scorer.level_pairs = level_pairs(group.rows)
    return scorer


def test_a_signature_flat_along_the_strength_path_is_still_fitted():
    """The pads stay in contact up to the plausible offset, so a backrest
    separation's signature is flat along the whole strength path and rises
    only beyond it: the candidate's fit starts at the far end of its bounds
    too, and finds a separation there (from the strength path and the
    effect off alone the descent never moves and the gain is 0)."""
    from ehm_drake.gap.library.models import Candidate
    from ehm_drake.gap.reference_group.reference import _gain

    labs, _ = _subjects(6, seed=5)
    g = ReferenceGroup.from_labs(labs)
    f = g.rows.freq
    shape = np.exp(-0.5 * ((f - 1.0) / 0.4) ** 2) * (0.8 - 0.3j)

    def sig_of(c):  # offset in mm: nothing below 5, then a growing sway
        return shape * max(float(c[0]) - 5.0, 0.0)

    scorer = _stub_scorer(g, sig_of, 8.0)
    name = "backrest_separation"
    assert max(c[0] for c in Candidate((name,)).start_grid()) < 5.0
    res = scorer.score(sig_of([7.0]), g, [name])
    assert res[name]["coords"][0] == pytest.approx(7.0, abs=0.05)
    assert _gain(res[name], res["none"]) > 100


def test_a_separation_reaches_the_offset_where_the_anchors_pads_unload():
    """A body that leans on its backrest harder than the model: the
    anchor's pads carry 5 and 9 mm and unload at 7.8 and 16.7 mm of offset,
    beyond the model's 8 mm bound.  The signature first dips (one pad
    unloading) and rises only once the back support is gone: the fit
    reaches a 21 mm separation through the pads' unloading starts and the
    raised bound, and is named with a large gain.  With the model's bound
    and starts alone it stays near "off" with no gain (the stop-31 fit on
    `spine5`'s separation trials)."""
    from ehm_drake.gap.library.models import Statics
    from ehm_drake.gap.reference_group.reference import SEPARATION_REACH, _gain

    labs, _ = _subjects(6, seed=5)
    g = ReferenceGroup.from_labs(labs)
    f = g.rows.freq
    shape = np.exp(-0.5 * ((f - 1.0) / 0.4) ** 2) * (0.8 - 0.3j)

    def sig_of(c):  # offset in mm
        x = float(c[0])
        return shape * (-0.8 * math.exp(-((x - 6.0) / 2.0) ** 2) +
                        0.3 * max(x - 14.0, 0.0))

    info = SimpleNamespace(parts=["pan", "lower_pad", "upper_pad", "floor"],
                           penetration=np.array([8.6e-3, 5.0e-3, 9.0e-3, 0.3e-3]))
    statics = Statics(info, np.array([0.19e-3, -0.64e-3, -0.54e-3, -0.02e-3]))
    unload = statics.pad_unloading_mm()
    assert unload == pytest.approx([5.0 / 0.64, 9.0 / 0.54])
    name = "backrest_separation"
    scorer = _stub_scorer(g, sig_of, 8.0, statics)
    res = scorer.score(sig_of([21.0]), g, [name])
    assert 8.0 < SEPARATION_REACH * unload[-1]
    assert res[name]["coords"][0] == pytest.approx(21.0, abs=0.3)
    assert _gain(res[name], res["none"]) > 100
    # The model's own statics (pads that stay loaded) leave the bound at 8
    # mm: the fit cannot reach the separation.
    plain = _stub_scorer(g, sig_of, 8.0).score(sig_of([21.0]), g, [name])
    assert plain[name]["coords"][0] <= 8.0
    assert _gain(plain[name], plain["none"]) < 0.1 * _gain(res[name], res["none"])


def test_an_effect_far_weaker_than_the_models_strength_path_is_still_fitted():
    """A foam-like signature: nothing below the equivalent linearization's
    tolerance (flat at "off"), the right shape up to a small strength, and a
    wrong, growing one from there on, so that every start on the strength
    path costs more than "off".  The data carry the effect at 3% of the
    model's full strength: only the weak starts below the path find it."""
    from ehm_drake.gap.library.effects import EFFECTS
    from ehm_drake.gap.library.models import STRENGTH_PATH, Candidate
    from ehm_drake.gap.reference_group.reference import _gain

    labs, _ = _subjects(6, seed=7)
    g = ReferenceGroup.from_labs(labs)
    f = g.rows.freq
    right = np.exp(-0.5 * ((f - 2.0) / 0.8) ** 2) * (1.2 + 0.4j)
    wrong = np.exp(-0.5 * ((f - 7.0) / 1.5) ** 2) * (-0.5 + 0.4j)
    name = "seat_foam_stiffening"
    full = EFFECTS[name].params[0].full
    c_true = 0.03 * full

    def sig_of(c):
        c = float(c[0])
        if c < 2e-3 * full:  # below the tolerance: no change at all
            return 0.0 * right
        return right * min(c / c_true, 1.0) + wrong * max(c - c_true, 0.0) / c_true

    scorer = _stub_scorer(g, sig_of, 20.0)
    r = sig_of([c_true])
    # Every start on the model's strength path is worse than the effect off.
    none_cost = np.sum(np.abs(r) ** 2)
    assert all(np.sum(np.abs(r - sig_of(c)) ** 2) > none_cost
               for c in Candidate((name,)).start_grid(STRENGTH_PATH))
    res = scorer.score(r, g, [name])
    assert res[name]["coords"][0] == pytest.approx(c_true, rel=0.05)
    assert _gain(res[name], res["none"]) > 100


def test_candidates_without_held_out_gain_have_no_rank_for_top3():
    from ehm_drake.gap.lab.scoring import score

    ranking = [{"effect": "seat_friction", "heldout_gain": 40.0, "gap_reduction_heldout": 0.1},
               {"effect": "reflex_delay", "heldout_gain": 0.0, "gap_reduction_heldout": 0.0},
               {"effect": "arms", "heldout_gain": -5.0, "gap_reduction_heldout": -0.1}]
    report = {"verdict": "unexplained", "best_effect": None, "ranking": ranking,
              "gap_before": {"heldout": 0.2}}
    sc = score({"reflex_delay": 0.8}, report, True, reality=True)
    assert sc["ranking_top3"] == ["seat_friction"] and not sc["top3"]
    sc = score({"seat_friction": 0.8}, report, True, reality=True)
    assert sc["top3"] and not sc["top1"]


def test_a_detectable_miss_against_a_group_gets_its_cause():
    """Against a reference group each detectable miss is given why: another
    candidate named first; the hidden effect beyond its own bound and the
    minimum gain but under the threshold the family-wise test raised; or
    within its own bound.  A hit, an undetectable trial and a diagnosis
    without a group get none; the run's summary counts the causes and its
    report lists each miss with its numbers."""
    from ehm_drake.gap.lab.scoring import markdown, score, summarize

    def entry(name, evidence, bound, threshold):
        return {"effect": name, "evidence": evidence, "null_bound": bound,
                "null_threshold": threshold, "gap_reduction_heldout": 0.1}

    def report(best, *entries):
        return {"verdict": "explained" if best else "unexplained", "best_effect": best,
                "ranking": list(entries), "gap_before": {"heldout": 1.0},
                "method": {"min_gain": 16.3}}

    group = [entry("cocontraction", 468.0, 167.0, 2174.0), entry("arms", 12.0, 441.0, 623.0)]
    family = score({"cocontraction": 0.9}, report(None, *group), True, reality=True)
    assert family["missed"]["cause"] == "the family-wise test"
    assert family["missed"]["effects"]["cocontraction"] == {
        "evidence": 468.0, "bound": 167.0, "threshold": 2174.0}
    own = score({"arms": 0.9}, report(None, *group), True, reality=True)
    assert own["missed"]["cause"] == "below its own bound"
    # Beyond its bound but not the minimum gain: within the noise, not the test's doing.
    weak = score({"arms": 0.9}, report(None, entry("arms", 15.0, 10.0, 20.0)), True,
                 reality=True)
    assert weak["missed"]["cause"] == "below its own bound"
    other = score({"arms": 0.9}, report("cocontraction", *group), True, reality=True)
    assert other["missed"] == {"cause": "another candidate named first",
                               "named": "cocontraction", "effects": {
                                   "arms": {"evidence": 12.0, "bound": 441.0,
                                            "threshold": 623.0}}}
    assert score({"visceral_mass": 0.9}, report(None, *group), True,
                 reality=True)["missed"]["cause"] == "not a candidate"
    assert score({"cocontraction": 0.9}, report("cocontraction", *group), True,
                 reality=True)["missed"] is None
    assert score({"arms": 0.9}, report(None, *group), False, reality=True)["missed"] is None
    # A candidate whose numbers are missing is never counted beyond its bound.
    broken = report(None, entry("arms", float("nan"), 441.0, 623.0),
                    entry("cocontraction", 468.0, None, None))
    both = {"arms": 0.9, "cocontraction": 0.9}
    trial = {"trial": 0, "hidden": both, "score": score(both, broken, True, reality=True)}
    assert trial["score"]["missed"]["cause"] == "below its own bound"
    md = markdown(summarize([trial], "lumped"), [trial])
    assert "| 0 | arms | - | 441 | 623 | below its own bound | - |" in md
    assert "| 0 | cocontraction | 468 | - | - | below its own bound | - |" in md
    single = report(None, {"effect": "arms", "gap_reduction_heldout": 0.1})
    assert score({"arms": 0.9}, single, True, reality=True)["missed"] is None

    results = [{"trial": i, "hidden": h, "score": s} for i, (h, s) in enumerate(
        [({"cocontraction": 0.9}, family), ({"arms": 0.9}, own), ({"arms": 0.9}, other)])]
    summary = summarize(results, "lumped")
    assert summary["misses"] == {"another candidate named first": 1,
                                 "the family-wise test": 1, "below its own bound": 1}
    md = markdown(summary, results)
    assert "## Why the detectable misses were missed" in md
    assert "| 0 | cocontraction | 468 | 167 | 2174 | the family-wise test | - |" in md
    assert "| 2 | arms | 12 | 441 | 623 | another candidate named first | cocontraction |" in md


def test_a_reality_is_judged_against_its_own_bar():
    """On an independent reality: top-1 >= 75%, top-3 >= 90%, false alarms
    <= 10%, at least 30 scored trials, no held-out share required; on the
    model itself: 80 / 95 / 10 and a 70% held-out share."""
    from ehm_drake.gap.lab.scoring import markdown, summarize

    def trial(i, hit, effect=True, in_top3=False):
        return {"trial": i, "hidden": {"arms": 1.0} if effect else {}, "score": {
            "detectable": effect, "has_effect": effect, "top1": hit, "top3": hit or in_top3,
            "false_alarm": False, "heldout_reduction_true": 0.2 if effect else None,
            "truth_label": "arms" if effect else "none", "verdict": "explained",
            "predicted_label": "arms" if hit else "unexplained", "ranking_top3": ["arms"]}}
    # 39 of 50 detectable trials right (78%), 46 in the top 3 (92%), 5
    # no-effect trials without alarm.
    results = [trial(i, i < 39, in_top3=i < 46) for i in range(50)] + [
        trial(50 + i, False, False) for i in range(5)]
    on_reality = summarize(results, "spine5")
    assert on_reality["top1"] == pytest.approx(0.78)
    assert on_reality["passed"] and "heldout_reduction" not in on_reality["acceptance"]
    on_model = summarize(results)
    assert not on_model["acceptance"]["top1"] and not on_model["acceptance"]["heldout_reduction"]
    assert not on_model["passed"]
    # Too few trials on a reality fails, whatever the rates.
    short = summarize(results[:20] + results[-5:], "lumped")
    assert short["acceptance"] == {"top1": True, "top3": True, "false_alarm": True,
                                   "trials": False}
    md = markdown(on_reality, results)
    assert "| scored trials | 55 | >= 30 |" in md and ">= 75%" in md and ">= 90%" in md


def test_a_diverging_twin_leaves_the_trial_detectable(tmp_path, monkeypatch):
    from ehm_drake.gap.lab import blind
    from ehm_drake.realities import RealityError

    def diverge(*args):
        raise RealityError("spine5 diverged at t = 3.000 s: pelvis moved 30 cm")
    monkeypatch.setattr(blind, "_synthesize_once", diverge)
    spec = blind.BlindSpec(trials=1, seed=5, reality="spine5")
    res = {"hidden": {"arms": 0.8}}
    report = {"verdict": "unexplained", "best_effect": None, "ranking": [],
              "gap_before": {"heldout": 0.2}}
    key = {"effects": {"arms": {}}, "seed": 1, "levels_rms": [0.3], "directions": "z",
           "duration_s": 30.0}
    blind._judge(res, tmp_path / "data", key, report, spec,
                 (tmp_path / "twin", tmp_path / "twin.json"))
    assert res["detectability"]["detectable"] and "diverged" in \
        res["detectability"]["twin_error"]
    assert res["score"]["detectable"] and not res["score"]["top1"]


def test_cli_reference_errors(tmp_path, capsys):
    """A reference folder without subject data, or too few subjects: a
    one-line message and exit status 2, before any model work."""
    from ehm_drake.cli import main

    empty = tmp_path / "group"
    (empty / "notes").mkdir(parents=True)
    data = tmp_path / "subject"
    data.mkdir()
    assert main(["diagnose", str(data), "--reference", str(empty), "--out",
                 str(tmp_path / "o1")]) == 2
    assert "no subject data" in capsys.readouterr().err
    assert main(["diagnose", str(data), "--reference", str(tmp_path / "missing"), "--out",
                 str(tmp_path / "o2")]) == 2
    assert "not found" in capsys.readouterr().err


def test_blind_run_records_a_diverging_reality_trial_and_goes_on(tmp_path, monkeypatch):
    """A reality whose simulation diverges on a trial (the lumped body did on
    a reflex delay with backrest separation) leaves that trial skipped with
    its reason; the run continues and resumes without redoing it."""
    from ehm_drake.gap.lab import blind
    from ehm_drake.realities import RealityError

    calls = []

    def diverge(synth, data, key, workers, params=None):
        calls.append(synth.seed)
        raise RealityError("lumped: the pelvis moved 0.25 m from its seat at t = 9.186 s")
    monkeypatch.setattr(blind, "_synthesize_once", diverge)
    spec = blind.BlindSpec(trials=2, seed=5, directions="z", duration_s=30.0,
                           reality="lumped")
    s = blind.run_blind(spec, tmp_path, progress=False)
    assert len(calls) == 2 and s["trials"] == 0
    assert [t["trial"] for t in s["skipped_trials"]] == [0, 1]
    assert "pelvis moved" in s["skipped_trials"][0]["reason"]
    assert "skipped" in (tmp_path / "blind.md").read_text()
    blind.run_blind(spec, tmp_path, progress=False)
    assert len(calls) == 2  # resumed: the skipped trials are not simulated again


# ---------------------------------------------------------------------------
# A short blind run on a reality, against a reference group
# ---------------------------------------------------------------------------

#: Seed 21 draws a no-effect trial, then the hidden effect at 0.98.  The effect
#: is a loose seat cushion: under vertical tests alone and against a group of 4
#: it stands out of the group (evidence 3.9 times its threshold, the
#: family-wise score 55 against the group's 14 at stop 61), where a seat foam
#: at 0.98 does not (one group subject's own foam gain, 623, sets its
#: threshold at 3,309 against the trial's 629) and the arms leave no
#: significant cell: a group of 4 is a quarter of the recommended 16.
CANDIDATES = ("visceral_mass", "seat_foam_stiffening", "seat_cushion_dynamics")
SHORT_BLIND = dict(trials=2, seed=21, directions="z", levels=(0.3, 0.6), duration_s=30.0,
                   hidden=("seat_cushion_dynamics",), candidates=CANDIDATES,
                   p_none=0.34, p_two=0.0, reality="lumped", references=4, contrasts=2)


@pytest.fixture(scope="module")
def reference_blind(tmp_path_factory):
    from ehm_drake.gap.lab.blind import BlindSpec, run_blind

    out = tmp_path_factory.mktemp("blind_lumped_reference")
    spec = BlindSpec(**SHORT_BLIND, workers=2)
    return out, run_blind(spec, out, progress=False)


@pytest.mark.slow
@pytest.mark.xdist_group("gap_reference")
def test_reference_group_blind_run_on_a_reality(reference_blind):
    from ehm_drake.gap.lab.scoring import ACCEPTANCE, acceptance_for

    out, s = reference_blind
    subjects = sorted((out / "reference").glob("subject_*/frf.csv"))
    assert len(subjects) == 4
    assert s["trials"] == 2 and s["no_effect_trials"] == 1
    # The assertions on a reality (its bar: top-1 >= 75%, top-3 >=
    # 90%, false alarms <= 10%; all met but the 30 trials of a full run):
    # the effect is named, nothing is named on the no-effect subject.
    bar = acceptance_for("lumped")
    assert s["detectable_trials"] == 1, s["confusion"]
    assert s["top1"] >= bar["top1"] and s["top3"] >= bar["top3"], s["confusion"]
    assert s["false_alarm"] <= bar["false_alarm"] == ACCEPTANCE["false_alarm"]
    assert {k for k, ok in s["acceptance"].items() if not ok} == {"trials"}
    assert "reference group of 4" in (out / "blind.md").read_text()
    effect = next(t for t in sorted(out.glob("trial_*"))
                  if json.loads((t / "result.json").read_text())["hidden"])
    res = json.loads((effect / "result.json").read_text())
    rep = json.loads((effect / "diagnosis" / "report.json").read_text())
    assert (rep["verdict"], rep["best_effect"]) == ("explained", "seat_cushion_dynamics")
    named = next(e for e in rep["ranking"] if e["effect"] == "seat_cushion_dynamics")
    assert named["signature"] == "contrasts" and named["evidence"] > named["null_threshold"]
    assert "removes" in rep["explanation"] and "held-out gap" in rep["explanation"]
    # Detectable by its twin (same subject, seed and noise, no effect), made
    # after the diagnosis: the effect moves cells beyond the noise, and
    # fewer remain once the smooth discrepancy has taken what it can.
    det = res["detectability"]["effects"]["all"]
    assert det["cells_raw"] >= det["cells"] > 0 and res["score"]["detectable"]
    none = next(t for t in sorted(out.glob("trial_*"))
                if json.loads((t / "result.json").read_text())["hidden"] == {})
    rep = json.loads((none / "diagnosis" / "report.json").read_text())
    assert rep["method"]["design"] == "reference group" and rep["reference"]["size"] == 4
    # The model refit to the group still differs from it (a body that is not
    # the model): the model-form gap is located, in the tested direction.
    mf = rep["model_form"]
    assert mf["significant_cells"] > 0 and mf["rms_log_gain_difference"] > 0.05
    assert all(c["direction"] == "z" for c in mf["cells"])
    # No effect named on the no-effect subject, and every candidate carries
    # the threshold its gains on the group's own subjects set.
    assert rep["best_effect"] is None
    # Every cell judged against the group's own subjects too (each against
    # the other 3: the level 1/5 of a group of 4), and significant only
    # beyond that bar.
    cal = rep["method"]["cell_calibration"]
    assert cal["cell_subjects"] == 4 and cal["cell_level"] == pytest.approx(0.2)
    assert all(c["group_bar"] > 0 and (not c["significant"] or c["chi2"] > c["group_bar"])
               for c in rep["localization"])
    assert rep["significant_cells"] == sum(c["significant"] for c in rep["localization"])
    for e in rep["ranking"]:
        assert len(e["null_gains"]) == 4 and e["null_threshold"] >= 16.3
        assert e["beyond_null"] == (e["evidence"] > e["null_threshold"])
    # The two imposable candidates were measured on 2 group subjects each (in
    # a second sitting) and are scored with those signatures; the visceral
    # mass, which no protocol imposes, with the model's.
    assert rep["reference"]["contrasts"]["subjects"] == {"seat_cushion_dynamics": 2,
                                                         "seat_foam_stiffening": 2}
    assert {e["effect"]: e["signature"] for e in rep["ranking"]} == {
        "seat_cushion_dynamics": "contrasts", "seat_foam_stiffening": "contrasts",
        "visceral_mass": "model"}
    for eff in ("seat_cushion_dynamics", "seat_foam_stiffening"):
        made = sorted(p.name for p in (out / "reference" / "contrasts" / eff).iterdir())
        assert made == ["subject_00", "subject_01"]
        key = json.loads((out / "keys" / f"contrast_{eff}_subject_00.json").read_text())
        ref = json.loads((out / "keys" / "reference_subject_00.json").read_text())
        assert key["seed"] == ref["seed"] and key["session"] == 1
        assert key["effects"][eff]["strength"] > 0
    assert "measured again" in (out / "blind.md").read_text()
    # The report says where each effect's contrasts act and how far they agree.
    quality = rep["reference"]["contrasts"]["quality"]
    assert sorted(quality) == ["seat_cushion_dynamics", "seat_foam_stiffening"]
    for q in quality.values():
        assert q["subjects"] == ["subject_00", "subject_01"]
        assert -1.0 <= q["agreement"] <= 1.0 and q["rms_change_sd"] > 0
        assert all(c["direction"] == "z" for c in q["cells"])
    assert "| seat_foam_stiffening | subject_00, subject_01 |" in \
        (none / "diagnosis" / "report.md").read_text()
    # A stored run judged again offline with its own contrasts
    # (`bench/rescore_blind.py --rethreshold --contrasts`) gives each measured
    # candidate the evidence and null the diagnosis gave it.
    import io
    from contextlib import redirect_stdout

    scored = out / "rescored.json"
    with redirect_stdout(io.StringIO()):
        bench_script("rescore_blind").main([str(out), "--rethreshold", "--contrasts",
                                            str(out / "reference" / "contrasts"),
                                            "--out", str(scored)])
    again = json.loads(scored.read_text())["trials"][0]["ranking"]
    for e in rep["ranking"]:
        a = next(x for x in again if x["effect"] == e["effect"])
        assert a["evidence"] == pytest.approx(e["evidence"], rel=1e-6, abs=1e-6)
        assert a["null_gains"] == pytest.approx(e["null_gains"], rel=1e-6, abs=1e-6)
    assert "Reference group" in (none / "diagnosis" / "report.md").read_text()
    # A group of 4 is below the recommended 16: the report says so.
    assert "4 subjects" in rep["reference"]["caution"]
    assert "**Caution:** a reference group of 4" in \
        (none / "diagnosis" / "report.md").read_text()
    assert "reference group of 4" in (out / "blind.md").read_text()
    # Judged again from its stored gains, the report keeps its verdict.
    from ehm_drake.gap.reference_group.reference import rethreshold

    again = rethreshold(rep)
    assert (again["verdict"], again["best_effect"]) == (rep["verdict"], rep["best_effect"])
    assert [e["effect"] for e in again["ranking"]] == [e["effect"] for e in rep["ranking"]]
    assert [e["null_threshold"] for e in again["ranking"]] == \
        [e["null_threshold"] for e in rep["ranking"]]


def test_a_stored_report_is_judged_again_with_the_current_thresholds():
    """`rethreshold` recomputes each candidate's threshold from its stored
    null gains and the verdict from the evidence: a candidate whose
    chi^2-like null (one large leave-one-out gain) puts its evidence above
    the normal bound but below the cube-root bound is not named; the one
    beyond both is, alone (`explained`) or with a rival within the
    ambiguity margin (`ambiguous`); none beyond: `unexplained` with
    significant cells, else `no_significant_gap`."""
    from scipy.stats import t as student_t

    from ehm_drake.gap.reference_group.calibration import null_threshold
    from ehm_drake.gap.reference_group.reference import rethreshold

    null = [0.0, 3.0, 5.0, 8.0, 12.0, 20.0, 35.0, 160.0]
    q = student_t.ppf(1 - 0.1 / 3, 7) * np.sqrt(1 + 1 / 8)
    linear = np.mean(null) + q * np.std(null, ddof=1)
    thr = null_threshold(null, 3)
    assert thr > 1.3 * linear
    between = (linear + thr) / 2

    def report(evidence, reductions, cells=12):
        return {"method": {"design": "reference group", "candidates": ["a", "b", "c"],
                           "borrowed_null_spread": 10.0},
                "significant_cells": cells, "verdict": "?", "best_effect": "?",
                "ranking": [{"effect": n, "null_gains": null, "evidence": ev,
                             "gap_reduction_heldout": red, "null_threshold": 0.0,
                             "beyond_null": True}
                            for n, ev, red in zip("abc", evidence, reductions, strict=True)]}

    r = rethreshold(report([between, 2 * thr, 1.5 * thr], [0.9, 0.5, 0.2]))
    assert (r["verdict"], r["best_effect"]) == ("explained", "b")
    assert [e["effect"] for e in r["ranking"]] == ["b", "c", "a"]
    assert not r["ranking"][2]["beyond_null"] and r["ranking"][2]["null_threshold"] == thr
    r = rethreshold(report([between, 2 * thr, 1.5 * thr], [0.9, 0.5, 0.48]))
    assert (r["verdict"], r["best_effect"], r["ambiguous_with"]) == ("ambiguous", "b", ["c"])
    assert rethreshold(report([between] * 3, [0.5] * 3))["verdict"] == "unexplained"
    assert rethreshold(report([between] * 3, [0.5] * 3, cells=0))["verdict"] == \
        "no_significant_gap"
    # A model-based report has no null gains to judge again: said, not a KeyError.
    with pytest.raises(DiagnosisError, match="reference group"):
        rethreshold({"method": {"design": "model"}, "ranking": []})


def test_the_candidate_furthest_beyond_its_own_threshold_is_named():
    """Two candidates beyond their null: the one whose evidence exceeds its
    own threshold by more is named, not the one with the larger evidence
    (`lumped` seed 2046 with the thresholds of stops 41-43: a reflex delay
    at 243 against 68 lost to the seat cushion's 369 against 318).  The candidates below their null
    follow, by evidence; with none beyond, the verdict does not name one."""
    from ehm_drake.gap.reference_group.reference import decide

    def entry(name, evidence, threshold, red):
        return {"effect": name, "evidence": evidence, "null_threshold": threshold,
                "beyond_null": evidence > threshold, "gap_reduction_heldout": red}

    ranking = [entry("seat_cushion_dynamics", 369.0, 318.0, 0.10),
               entry("visceral_mass", 150.0, 700.0, 0.10),
               entry("reflex_delay", 243.0, 68.0, 0.20),
               entry("arms", 40.0, 500.0, 0.01)]
    verdict, best, close = decide(ranking, 12)
    assert (verdict, best, close) == ("explained", "reflex_delay", [])
    assert [e["effect"] for e in ranking] == ["reflex_delay", "seat_cushion_dynamics",
                                              "visceral_mass", "arms"]
    # Within the ambiguity margin of the named one's held-out share: ambiguous.
    ranking[1]["gap_reduction_heldout"] = 0.22
    assert decide(ranking, 12) == ("ambiguous", "reflex_delay", ["seat_cushion_dynamics"])
    below = [entry("a", 10.0, 20.0, 0.1), entry("b", 15.0, 100.0, 0.1)]
    assert decide(below, 3) == ("unexplained", None, [])
    assert [e["effect"] for e in below] == ["b", "a"]


def test_null_gains_are_not_reused_from_other_scoring_code(monkeypatch):
    """The cached null gains are keyed by the scoring code as well as the
    group, candidates and anchor: a change to how candidates are scored
    never reuses thresholds computed by the old code."""
    from ehm_drake.gap.reference_group import reference

    labs, _ = _subjects(5, seed=1)
    g = ReferenceGroup.from_labs(labs)
    k0 = reference._null_key(g, ["arms", "reflex_delay"], "a")
    assert k0 == reference._null_key(g, ["reflex_delay", "arms"], "a")
    assert k0 != reference._null_key(g, ["arms"], "a")
    assert k0 != reference._null_key(g, ["arms", "reflex_delay"], "b")
    assert k0 != reference._null_key(g.without(0), ["arms", "reflex_delay"], "a")
    monkeypatch.setattr(reference, "scoring_fingerprint", lambda: "other scoring code")
    assert k0 != reference._null_key(g, ["arms", "reflex_delay"], "a")


def test_null_threshold_is_a_prediction_bound_for_normal_gains():
    """For normal null gains the threshold from K of them is exceeded by one
    more subject's gain with probability at most alpha / n (the Student-t
    prediction bound is exact there; the cube-root bound, kept when higher,
    makes it conservative, but by less than a third), whatever the gains'
    location and spread: checked by drawing 20000 groups of K = 8 and one
    more subject each (seeded)."""
    from ehm_drake.gap.reference_group.calibration import MIN_GAIN, null_threshold

    rng = np.random.default_rng(3)
    for loc, scale in ((500.0, 200.0), (-400.0, 300.0)):
        g = rng.normal(loc, scale, (20000, 9))
        thr = np.array([null_threshold(row[:8], 2, alpha=0.2) for row in g])
        rate = np.mean(g[:, 8] > thr)
        # alpha / n = 0.1; sd of the rate 0.002.
        floor_share = np.mean(thr == MIN_GAIN)
        if loc > 0:
            assert floor_share < 0.01 and 0.067 < rate < 0.104
        else:
            # Mostly floored: a next gain above MIN_GAIN is rarer than alpha / n.
            assert rate < 0.1


@pytest.mark.parametrize("dof", [1, 3])
def test_null_threshold_holds_its_level_for_chi2_like_gains(dof):
    """A candidate's null gain is a chi^2 difference, skewed like chi^2 with
    1-3 degrees of freedom.  There the bound on the gains alone (exact for
    normal ones) is exceeded by one more subject 3.5-6 times as often as
    alpha / n (1.25% per candidate, 8 candidates, 10% family-wise): the
    clustered false alarms of the blind runs on `lumped`.  The threshold
    (with the cube-root bound) is exceeded at most 1.6 times as often, and
    not less than 0.8 times: it does not buy its level by refusing every
    effect.  20000 groups of K = 8 and one more subject each (seeded)."""
    from scipy.stats import t as student_t

    from ehm_drake.gap.reference_group.calibration import FAMILY_ALPHA, MIN_GAIN, null_threshold

    rng = np.random.default_rng(4 + dof)
    g = 100.0 * rng.chisquare(dof, (20000, 9))
    level = FAMILY_ALPHA / 8
    thr = np.array([null_threshold(row[:8], 8) for row in g])
    q = student_t.ppf(1 - level, 7) * np.sqrt(1 + 1 / 8)
    linear = np.maximum(MIN_GAIN, g[:, :8].mean(axis=1) + q * g[:, :8].std(axis=1, ddof=1))
    # sd of a rate near 1.25%: 0.08%.
    assert np.mean(g[:, 8] > linear) > 3.5 * level
    assert 0.8 * level < np.mean(g[:, 8] > thr) < 1.6 * level


def test_null_threshold_of_mixed_sign_gains_stays_near_their_quantile():
    """Held-out gains take both signs: a one-parameter candidate fitted to
    the training tests (z-score a) and scored on the held-out one (z-score
    b, relative size c = 0.7) gains 2abc - (ac)^2.  Negative gains must not
    widen the cube-root bound (on the raw gains' cube roots the threshold
    was 5.6 times the true 1.25% quantile): the threshold stays within 2
    times of that quantile and is exceeded at most at the nominal rate
    (within 1.6 times).  20000 groups of K = 8 (seeded)."""
    from ehm_drake.gap.reference_group.calibration import FAMILY_ALPHA, null_threshold

    rng = np.random.default_rng(11)

    def gains(shape):
        a, b = rng.standard_normal(shape), rng.standard_normal(shape)
        return 100.0 * (2 * a * b * 0.7 - (a * 0.7) ** 2)

    level = FAMILY_ALPHA / 8
    quantile = np.quantile(gains(400000), 1 - level)
    g = gains((20000, 9))
    thr = np.array([null_threshold(row[:8], 8) for row in g])
    assert np.median(thr) < 2.0 * quantile
    assert 0.4 * level < np.mean(g[:, 8] > thr) < 1.6 * level


DATA = Path(__file__).resolve().parent / "data"


def test_effect_atlas_reach_is_the_share_in_the_span():
    """`bench/effect_atlas.py`'s reach: the share of a complex (whitened)
    effect in the real span of the model's first-order directions; 1 inside
    the span, 0 orthogonal to it, the squared cosine between."""
    atlas = bench_script("effect_atlas")
    rng = np.random.default_rng(3)
    n = 200
    b1, b2 = (rng.normal(size=n) + 1j * rng.normal(size=n) for _ in range(2))
    basis = np.stack([atlas._real(b1), atlas._real(b2)], axis=1)
    assert atlas.span_share(basis, 2.0 * b1 - 0.5 * b2) == pytest.approx(1.0, abs=1e-12)
    # A part orthogonal to the span (the real inner product) adds to |s|^2 only.
    q, _ = np.linalg.qr(np.hstack([basis, atlas._real(rng.normal(size=n) + 0j)[:, None]]))
    out = q[:n, 2] + 1j * q[n:, 2]
    assert atlas.span_share(basis, out) == pytest.approx(0.0, abs=1e-12)
    inside = q[:n, 0] + 1j * q[n:, 0]
    assert atlas.span_share(basis, 3.0 * inside + 1.0 * out) == pytest.approx(0.9, abs=1e-12)
    # i times a direction is not in its real span (gain and phase differ).
    assert atlas.span_share(basis[:, :1], 1j * b1) < 0.2
    assert atlas.span_share(basis, np.zeros(n, complex)) == 0.0


def test_effect_atlas_loop_response_is_the_delayed_closed_loop():
    """`bench/effect_atlas.py --delay-parts`: the closed loop with extra
    feedback terms.  The whole feedback Bw K delayed by d steps (g = exp(-j
    w d h) - 1) is `family.response` with that delay (its Woodbury form);
    no extra term is the undelayed loop; a part and its rest delayed alike
    are the whole delayed."""
    from ehm_drake.gap.library.family import response

    atlas = bench_script("effect_atlas")
    rng = np.random.default_rng(5)
    n, m, h = 12, 4, 1e-3
    A = np.diag(rng.uniform(0.5, 0.95, n)) + 0.02 * rng.normal(size=(n, n))
    Bu, Bw, C = rng.normal(size=(n, 3)), 0.05 * rng.normal(size=(n, m)), rng.normal(size=(5, n))
    K = rng.normal(size=(m, n))
    f = np.linspace(0.5, 12.0, 7)
    rows = np.array([0, 2, 4])
    for d in (0, 3, 30):
        ref = response(A, Bu, Bw, C, K, h, f, [0, 2], rows=rows, delay_steps=d)
        loops = [(Bw @ K, atlas.delay_of(d * h))] if d else []
        got = atlas.loop_response(A, Bu, Bw, C, K, h, f, [0, 2], rows, loops)
        assert np.allclose(got, ref, rtol=1e-9, atol=1e-12)
        K1 = K.copy()
        K1[:2] = 0.0
        split = [(Bw @ K1, atlas.delay_of(d * h)), (Bw @ (K - K1), atlas.delay_of(d * h))]
        assert np.allclose(atlas.loop_response(A, Bu, Bw, C, K, h, f, [0, 2], rows, split),
                           ref, rtol=1e-9, atol=1e-12)
    # A delay on a part only differs from the whole delayed.
    part = atlas.loop_response(A, Bu, Bw, C, K, h, f, [0], rows,
                               [(Bw @ K1, atlas.delay_of(30 * h))])
    whole = response(A, Bu, Bw, C, K, h, f, [0], rows=rows, delay_steps=30)
    assert not np.allclose(part, whole, rtol=1e-3)


def test_effect_atlas_feedback_parts_add_up_to_the_cut_feedback():
    """The parts of the model's cut-open feedback (`--delay-parts`): the
    head-in-space controller and the PIDs' proportional paths are all of
    the feedback's action on the body; the rest of Bw K is the integrals'
    input (h e on the integral states, whatever the gains)."""
    from ehm_drake.gap.library.family import linearize_cut

    atlas = bench_script("effect_atlas")
    params = load_params()
    parts = atlas.feedback_parts(params)
    lin = linearize_cut(params)
    plant = np.array([s.startswith("plant:") for s in lin.state_names])
    integral = np.array([s.startswith("joint_pid:") for s in lin.state_names])
    assert plant.sum() == 62 and integral.sum() == 24
    assert all(M.shape == (len(plant), len(plant)) for M in parts.values())
    total = sum(parts[p] for p in atlas.FEEDBACK_PARTS)
    scale = np.abs(parts["all"][plant]).max()
    assert np.abs(total[plant] - parts["all"][plant]).max() < 1e-6 * scale
    assert np.abs(total[integral]).max() < 1e-9 * scale
    # Each part acts (neck and head-in-space on the head's joints, ...).
    assert all(np.abs(parts[p][plant]).max() > 1e-3 * scale for p in atlas.FEEDBACK_PARTS)
    e = parts["all"][integral] / lin.h  # the angle errors the integrals read
    assert np.allclose(np.sort(np.abs(e).sum(axis=1)), 1.0)


def test_null_threshold_level_on_measured_no_effect_subjects():
    """68 no-effect `lumped` subjects of five blind runs (seeds 2041,
    2043-2046, each against its run's group of 8; stored by
    `bench/null_calibration.py`): each candidate's evidence against its
    own bound from its group's leave-one-out gains.  Measured: exceeded 19
    times in 544 (2.8 times the nominal 1.25% per candidate; 11 while the
    linear bound was kept for every null, before the mostly-negative rule
    of `null_threshold`), an effect named by the bounds alone on 17 of the
    68; with the family-wise test, as the diagnosis judges, on 1 of the 68
    (as before the rule).  This test keeps the bound from getting worse
    unnoticed (at most 3 times nominal, at least 0.4 times: not bought by
    refusing every effect), holds the whole test at the 10% bar, and
    records the trade-off tried at stop 44: the cube-root gains clipped at
    -MIN_GAIN instead of 0 name at most half as many, but found 30 of 51
    effects on the fresh runs against 35 (seeds 2046 and 2047; not asserted
    here)."""
    from ehm_drake.gap.reference_group.calibration import FAMILY_ALPHA, MIN_GAIN, null_threshold

    nc = bench_script("null_calibration")
    data = json.loads((DATA / "lumped_null_evidence.json").read_text())
    assert sum(len(e["evidence"]) for e in data.values()) == 68
    level = FAMILY_ALPHA / 8
    now = nc.exceedances(data, lambda g, n, s: null_threshold(g, n, borrowed_spread=s))
    assert now["tests"] == 544
    assert 0.4 * level < now["exceedances"] / now["tests"] < 3.0 * level
    assert nc.family_named(data)["named"] <= FAMILY_ALPHA * 68
    clipped = nc.exceedances(data, nc.clipped_at(-MIN_GAIN))
    assert 0 < clipped["named"] <= now["named"] / 2
    # The clip at 0 is the library's default.
    assert nc.exceedances(data, nc.clipped_at(0.0)) == now


def test_a_group_of_16_names_fewer_no_effect_subjects_than_a_group_of_8():
    """The same no-effect `lumped` subjects judged against their run's group
    of 8 (`lumped_null_evidence.json`) and against a group of 16, the 8 and
    another run's 8 (`lumped_null_evidence_k16.json`, stop 45: every trial
    diagnosed again with `bench/rescore_blind.py --reference`, collected by
    `bench/null_calibration.py`; seeds 2043, 2046 and 2047).  Measured on the
    subjects both hold (seeds 2043 and 2046): 6 of 40 named at K = 8, 2 at
    K = 16; at K = 16 each candidate exceeds its threshold 2 times in 336
    (0.48 times the nominal level; at most the nominal level asserted, and
    not by refusing every effect).  What `group.RECOMMENDED_SUBJECTS` rests
    on, with the hits (docs/history/gap-diagnosis-on-realities.md, "A group of 16")."""
    from ehm_drake.gap.reference_group.calibration import FAMILY_ALPHA, null_threshold

    nc = bench_script("null_calibration")
    k8 = json.loads((DATA / "lumped_null_evidence.json").read_text())
    k16 = json.loads((DATA / "lumped_null_evidence_k16.json").read_text())
    common = sorted(set(k8) & set(k16))
    assert len(common) >= 2
    for run in common:  # the same subjects, in the same order
        assert len(k8[run]["evidence"]) == len(k16[run]["evidence"])
        assert all(len(g) == 16 for g in k16[run]["null_gains"].values())

    def judge(data):
        return nc.exceedances(data, lambda g, n, s: null_threshold(g, n, borrowed_spread=s))

    at8 = judge({r: k8[r] for r in common})
    at16 = judge({r: k16[r] for r in common})
    assert at8["subjects"] == at16["subjects"]
    assert at16["named"] <= at8["named"] / 2
    every = judge(k16)
    rate = every["exceedances"] / every["tests"]
    assert 0 < rate <= FAMILY_ALPHA / 8


def test_a_group_smaller_than_recommended_is_cautioned():
    """Below `RECOMMENDED_SUBJECTS` the report carries a caution that names
    the group's size and the recommendation; from there on none."""
    from ehm_drake.gap.reference_group.group import MIN_SUBJECTS, RECOMMENDED_SUBJECTS
    from ehm_drake.gap.reference_group.reference import group_size_caution

    assert RECOMMENDED_SUBJECTS > MIN_SUBJECTS
    for k in (MIN_SUBJECTS, 8, RECOMMENDED_SUBJECTS - 1):
        text = group_size_caution(k)
        assert f"group of {k} subjects" in text and f"{RECOMMENDED_SUBJECTS} subjects" in text
    assert group_size_caution(RECOMMENDED_SUBJECTS) is None
    assert group_size_caution(24) is None


def test_null_threshold_covers_the_spread_not_only_the_largest_gain():
    """A candidate that ends at a bound on every reference subject (all gains
    negative, spread several hundred) gets a threshold well above its largest
    null gain; identical null gains give MIN_GAIN; more candidates, a higher
    bar; bad nulls are refused."""
    from ehm_drake.gap.reference_group.calibration import MIN_GAIN, null_threshold

    arms = [-439, -509, -943, -880, -115, -737, -189, -119]
    thr = null_threshold(arms, 8, alpha=0.1)
    assert thr > 300
    # Half the subjects at -1..23, half far below (the seat foam's null on a
    # `lumped` group of 32: fits that overfit the training rows): the bar
    # comes from the upper half, not from the negative tail's spread (1,775
    # with the linear bound).
    foam = [-3698, -3270, -1737, -1090, -951, -657, -654, -627, -327, -232, -192, -136,
            -75, -34, -13, -5, -1, 0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 4, 5, 11, 15, 23]
    assert null_threshold(foam, 9) < 3 * max(foam)
    # The same upper half with no negative tail: the same bar.
    assert null_threshold(foam, 9) == null_threshold(np.maximum(foam, 0.0), 9)
    assert null_threshold([0.0] * 8, 8) == MIN_GAIN
    spread = [0, 30, 16, 0, 220, 0, 0, 0]
    assert null_threshold(spread, 8) > max(220, null_threshold(spread, 1))
    # Subjects whose null failed (None) are left out, not counted as zero.
    assert null_threshold([*spread, None], 8) == null_threshold(spread, 8)
    with pytest.raises(DiagnosisError, match="2 finite"):
        null_threshold([1.0, float("nan"), 3.0], 8)
    with pytest.raises(DiagnosisError, match="arms: .* 2 finite"):
        null_threshold([5.0], 8, name="arms")


def test_a_candidate_no_reference_subject_fits_borrows_the_groups_spread():
    """A degenerate null (every reference subject's gain 0: the candidate's
    fit stays off on all of them) would give `MIN_GAIN`, and one more
    subject that fits it at all is named.  Its threshold borrows the group's
    typical spread instead.  The nulls are `spine5`'s seed-2034 group at
    stop 32, where a subject with no hidden effect reached 180 with the
    backrest separation and was named."""
    from ehm_drake.gap.reference_group.calibration import (
        DEGENERATE_GAIN,
        MIN_GAIN,
        group_null_spread,
        null_threshold,
    )

    nulls = {"reflex_delay": [9, 0, -5, 17, 0, -6, 342, 37],
             "seat_foam_stiffening": [0, 6, 12, 0, -1449, 0, -93, 64],
             "seat_friction": [17, 0, 0, -1237, 0, 52, 0, 0],
             "backrest_separation": [0.0] * 8,
             "arms": [-57, 203, -30, -706, -125, 121, -603, -240],
             "visceral_mass": [7, 7, -3, 2, 0, -2, 299, 0],
             "cocontraction": [-15, -81, 0, 0, -162, 0, 0, 0],
             "seat_cushion_dynamics": [-8, 72, -3, -38, -82, 144, -3, 25]}
    spread = group_null_spread(nulls)
    stds = sorted(np.std(g, ddof=1) for g in nulls.values())
    assert stds[3] < spread < stds[4]  # the median variance's root: 105-119
    sep = nulls["backrest_separation"]
    assert null_threshold(sep, 8) == MIN_GAIN
    borrowed = null_threshold(sep, 8, borrowed_spread=spread)
    assert borrowed > 180 and borrowed > 10 * MIN_GAIN
    # Round-off-sized gains are still degenerate; one subject that fits is not.
    assert null_threshold([0.4, -0.2, 0, 0, 0, 0, 0, 0.9], 8, borrowed_spread=spread) > 180
    assert DEGENERATE_GAIN < 5
    one = [0, 0, 0, 0, 0, 0, 0, 5.0]
    assert null_threshold(one, 8, borrowed_spread=spread) == null_threshold(one, 8) < 50
    # A candidate with a spread of its own keeps its threshold.
    for name, g in nulls.items():
        if name != "backrest_separation":
            assert null_threshold(g, 8, borrowed_spread=spread) == null_threshold(g, 8)
    # Failed nulls (None) are left out; without two finite gains anywhere, None.
    assert group_null_spread({**nulls, "arms": [None] * 8}) > 0
    assert group_null_spread({"arms": [None, 3.0]}) is None


def test_level_pairs_match_each_higher_level_with_the_lowest_of_its_direction():
    """Rows pair by direction, channel and frequency: z@0.6 with z@0.3, x@0.9
    with x@0.3 (not with z), nothing for a single level or unknown levels."""
    lab = _lab(lambda f, lv, ch: 1 + f + lv + 1j * ch,
               tests=(("z", 0.3), ("z", 0.6), ("x", 0.3), ("x", 0.9), ("y", 0.5)))
    rows = lab.rows
    lo, hi = level_pairs(rows)
    assert len(lo) == 2 * 2 * 39  # (z, x) x 2 channels x 39 bins; y has one level
    for i, j in zip(lo, hi, strict=True):
        assert rows.direction[i] == rows.direction[j] != "y"
        assert rows.channel[i] == rows.channel[j] and rows.freq[i] == rows.freq[j]
        assert rows.level[i] == 0.3 and rows.level[j] in (0.6, 0.9)
    single = _lab(lambda f, lv, ch: 1 + f + 0j, tests=(("z", 0.3), ("x", 0.3)))
    assert len(level_pairs(single.rows)[0]) == 0
    unknown = _lab(lambda f, lv, ch: 1 + f + 0j, tests=(("z", float("nan")), ("z", 0.6)))
    assert len(level_pairs(unknown.rows)[0]) == 0


def _level_group_labs(K=8, seed=11):
    """K subjects on z at 0.3 and 0.6 m/s^2 that differ by a gain and phase
    shift and a small subject-specific level dependence."""
    rng = np.random.default_rng(seed)
    labs = []
    for k in range(K):
        a, b = rng.normal(0, 0.2), rng.normal(0, 0.3)
        e = rng.normal(0, 0.03, 2)

        def H(f, lv, ch, a=a, b=b, e=e):
            return (1 + f / 5) * np.exp(a + 1j * b + lv * (e[0] + 1j * e[1]) * f / 12)
        labs.append(_lab(H, name=f"s{k}"))
    return labs


def test_the_level_differences_cancel_the_subjects_structure_but_not_a_level_effect():
    """A subject far outside the group's scatter by a structural difference
    that is the same at both levels (a resonance the group does not have),
    plus a co-contraction-like effect that grows with the level.  On all
    rows the structure dominates; on the level differences it cancels, the
    effect is fitted (its strength within 5%) and gains far more than it
    does on a subject with the structure alone (which gains nothing there).
    A candidate that does not depend on the level has no level fit."""
    from ehm_drake.gap.reference_group.reference import _evidence, _gain

    labs = _level_group_labs()
    g = ReferenceGroup.from_labs(labs)
    f, lv = g.rows.freq, g.rows.level
    shape = np.exp(-0.5 * ((f - 5.0) / 1.0) ** 2) * (0.5 - 0.3j)

    def sig_of(c):  # stiffer with the level: the effect's change grows with it
        return float(c[0]) * lv * shape

    structure = 2.5 * np.exp(-0.5 * ((f - 3.0) / 0.7) ** 2) * (1 - 0.6j)
    scorer = _stub_scorer(g, sig_of, 4.0)
    name = "cocontraction"
    both = scorer.score(structure + sig_of([1.5]), g, [name, "visceral_mass"])
    alone = scorer.score(structure, g, [name, "visceral_mass"])
    chi_structure = np.sum(alone["none"]["chi_all"])
    assert chi_structure > 4 * len(f)  # far outside the group's scatter
    assert both[name]["level_coords"][0] == pytest.approx(1.5, rel=0.05)
    assert both[name]["level_gain"] > 100
    assert alone[name]["level_gain"] < 0.01 * both[name]["level_gain"]
    # (Scored at the level-only fit's size too, which is the all-rows fit's
    # here: the larger of the two scores, to 1e-4.)
    plain = _gain(both[name], both["none"]) + both[name]["level_gain"]
    assert plain <= _evidence(both[name], both["none"]) == pytest.approx(plain, rel=1e-4)
    for res in (both, alone):
        assert res["visceral_mass"]["level_gain"] == 0.0
        assert res["visceral_mass"]["level_coords"] is None
    # One level only: no level design, the evidence is the held-out gain.
    one = ReferenceGroup.from_labs([_lab(lambda f_, lv_, ch, L=lab: L.rows.H[:len(f_)],
                                         tests=(("z", 0.3),)) for lab in labs])
    single = _stub_scorer(one, lambda c: float(c[0]) * 0.3 * shape[:len(one.rows.freq)], 4.0)
    res = single.score(structure[:len(one.rows.freq)], one, [name])
    assert res[name]["level_gain"] == 0.0


def _level_effect_scorer(upper):
    """A group on z at 0.3 and 0.6 m/s^2, a change `shape` around 5 Hz and a
    stub scorer whose candidates change the response by c x level x shape."""
    g = ReferenceGroup.from_labs(_level_group_labs())
    f, lv = g.rows.freq, g.rows.level
    shape = np.exp(-0.5 * ((f - 5.0) / 1.0) ** 2) * (0.5 - 0.3j)

    def sig_of(c):
        return float(c[0]) * lv * shape

    return g, shape, sig_of, _stub_scorer(g, sig_of, upper)


def test_an_amplitude_driven_candidate_mimicking_a_level_independent_gap_loses_its_evidence():
    """A subject differs from the group by a resonance change that is the
    same at both levels.  A candidate whose change grows with the level fits
    it on all rows (a compromise strength) and gains held out, but that fit
    predicts level differences the subject does not show: for an
    amplitude-driven effect (co-contraction) that loss is taken off the
    evidence, down to zero; for a separation (level-dependent, not
    amplitude-driven) it is reported and not used.  On a subject with the
    effect itself the all-rows fit gains on the level differences too, and
    the evidence is the held-out plus the level gain."""
    from ehm_drake.gap.reference_group.reference import _evidence, _gain

    g, shape, sig_of, scorer = _level_effect_scorer(10.0)
    names = ["cocontraction", "backrest_separation"]
    mimic = scorer.score(4.0 * shape, g, names)  # the same at 0.3 and 0.6 m/s^2
    true = scorer.score(sig_of([1.5]), g, names)
    for n in names:
        m = mimic[n]
        plain = _gain(m, mimic["none"]) + m["level_gain"]
        assert plain > 50  # the fit to all rows gains held out ...
        assert m["level_gain_at_fit"] < -plain  # ... and contradicts the level differences
        t = true[n]
        assert t["level_gain_at_fit"] > 50
        assert _evidence(t, true["none"]) == pytest.approx(_gain(t, true["none"]) + t["level_gain"])
    assert mimic["cocontraction"]["amplitude_driven"]
    # (Scored at its level-only fit, which finds no such effect, it gains
    # nothing either.)
    co = mimic["cocontraction"]
    assert abs(_evidence(co, mimic["none"])) < 0.02 * (_gain(co, mimic["none"])
                                                       + co["level_gain"])
    sep = mimic["backrest_separation"]
    assert not sep["amplitude_driven"]
    assert _evidence(sep, mimic["none"]) == pytest.approx(_gain(sep, mimic["none"])
                                                          + sep["level_gain"])
    # A negative evidence is kept as it is (no effect is not made worse).
    neg = {**mimic["cocontraction"], "level_gain": -5.0 - _gain(mimic["cocontraction"],
                                                                 mimic["none"])}
    assert _evidence(neg, mimic["none"]) == pytest.approx(-5.0)


def test_an_amplitude_driven_candidate_is_also_scored_at_the_size_its_level_fit_gives():
    """A subject with an effect that grows with the level (strength 1.5)
    and a structural difference along the same change that does not
    (3 x the shape at both levels).  The all-rows fit and its refits take
    the structure for more effect; their held-out predictions at the other
    level miss, and their level differences contradict the subject's.  The
    level-only fit finds the true strength: scored held out at that size
    the candidate gains more, and the larger score is its evidence.  A
    candidate that is not amplitude-driven (a separation) keeps the
    all-rows score alone."""
    from ehm_drake.gap.reference_group.reference import _evidence, _gain

    g, shape, sig_of, scorer = _level_effect_scorer(20.0)
    names = ["cocontraction", "backrest_separation"]
    res = scorer.score(sig_of([1.5]) + 3.0 * shape, g, names)
    base = res["none"]
    co = res["cocontraction"]
    assert co["level_coords"][0] == pytest.approx(1.5, rel=0.05)
    assert co["coords"][0] > 3.0  # (the all-rows fit takes the structure in)
    at_level = _gain({"chi_heldout": co["chi_heldout_level_fit"]}, base)
    refits = _gain(co, base) + co["level_gain"] + min(co["level_gain_at_fit"], 0.0)
    assert at_level > 0 and at_level + co["level_gain"] > refits + 50
    assert _evidence(co, base) == pytest.approx(at_level + co["level_gain"])
    sep = res["backrest_separation"]
    assert "chi_heldout_level_fit" not in sep
    assert _evidence(sep, base) == pytest.approx(_gain(sep, base) + sep["level_gain"])


def test_the_report_gives_the_level_fit_score_beside_the_all_rows_one():
    """The reference report's ranking shows an amplitude-driven candidate's
    held-out gain at its level-only fit beside the all-rows one, and none
    for a candidate not scored there."""
    from ehm_drake.gap.report import _heldout

    assert _heldout({"heldout_gain": -2209.4, "heldout_gain_level_fit": 130.6}) == \
        "-2209 (131 at the level fit)"
    assert _heldout({"heldout_gain": 5106.2, "heldout_gain_level_fit": None}) == "5106"
    assert _heldout({"heldout_gain": 12.0}) == "12"


def test_a_delay_candidate_is_fitted_from_off_and_not_started_in_weak_wells():
    """A delay's (or a linear extension's) signature is smooth at "off", so
    the descent from "off" reaches a weak effect by itself (it did not while
    SciPy's trust radius started at the 1e-10 of a start on the bound: a
    0.9 ms delay ended at 0.42 ms), and such a candidate gets no weak starts
    below its strength path: a narrow well at 1% of its strength, which only
    a start there would find, stays unvisited (on the lumped reality's seed
    2032 such starts fitted 3-4 ms reflex delays on four trials where the
    strength path's starts found none, one of them that run's false alarm)."""
    from ehm_drake.gap.library.effects import EFFECTS
    from ehm_drake.gap.reference_group.reference import _gain

    labs, _ = _subjects(6, seed=7)
    g = ReferenceGroup.from_labs(labs)
    f = g.rows.freq
    shape = np.exp(-0.5 * ((f - 3.0) / 1.0) ** 2) * (18.0 - 27.0j)
    name = "reflex_delay"
    full = EFFECTS[name].params[0].full
    upper = EFFECTS[name].params[0].bounds[1]

    # A smooth signature, the effect at 3% of its strength: found from "off".
    scorer = _stub_scorer(g, lambda c: shape * float(c[0]) / full, upper)
    res = scorer.score(shape * 0.03, g, [name])
    assert res[name]["coords"][0] == pytest.approx(0.03 * full, rel=0.05)
    assert _gain(res[name], res["none"]) > 100

    # A narrow well at 1% of its strength, nothing anywhere else.
    def well(c):
        return shape * np.exp(-0.5 * ((float(c[0]) - 0.01 * full) / (0.0005 * full)) ** 2)

    scorer = _stub_scorer(g, well, upper)
    res = scorer.score(shape, g, [name])
    assert abs(res[name]["coords"][0] - 0.01 * full) > 0.005 * full
    assert _gain(res[name], res["none"]) < 1.0


def _lognormal_mixture_nulls(rng, n_subjects, p_on=0.3, sigma=1.5):
    """Gains of subjects without any effect, 8 candidates: most subjects 0
    (the fit stays "off"), the others log-normal with a heavy tail, each
    candidate on its own scale -- the shape of the measured nulls of a body
    that is not the model (`spine5_null_evidence.json`)."""
    scales = np.array([10, 30, 100, 300, 1000, 50, 200, 20.0])
    on = rng.random((n_subjects, 8)) < p_on
    return np.where(on, scales * np.exp(sigma * rng.standard_normal((n_subjects, 8))), 0.0)


def test_the_family_wise_test_holds_its_level_whatever_the_gains_distribution():
    """Heavy-tailed nulls (`_lognormal_mixture_nulls`), groups of 16 and one
    fresh no-effect subject each: the candidates' own bounds name an effect
    on about a third of the subjects (their distribution assumption fails);
    with the family-wise conformal test the rate is at most 1 / 17 (plus
    three Monte-Carlo standard errors), and a subject with a strong effect
    on one candidate is still named for it."""
    from ehm_drake.gap.reference_group.calibration import group_null_spread, thresholds

    rng = np.random.default_rng(55)
    groups = 600
    names = [f"c{i}" for i in range(8)]
    own = family = strong = 0
    for _ in range(groups):
        null = _lognormal_mixture_nulls(rng, 16)
        nulls = {c: list(null[:, i]) for i, c in enumerate(names)}
        fresh = dict(zip(names, _lognormal_mixture_nulls(rng, 1)[0], strict=True))
        spread = group_null_spread(nulls)  # as the diagnosis does
        thr, bounds, fam = thresholds(nulls, fresh, borrowed_spread=spread)
        assert all(thr[c] >= bounds[c] for c in names)
        assert (fam["rank"], fam["subjects"]) == (16, 16)
        own += any(fresh[c] > bounds[c] for c in names)
        family += any(fresh[c] > thr[c] for c in names)
        effect = {**fresh, "c2": fresh["c2"] + 50 * null[:, 2].max() + 1e4}
        thr = thresholds(nulls, effect, borrowed_spread=spread)[0]
        strong += effect["c2"] > thr["c2"]
    level = 1 / 17
    assert own / groups > 0.25
    assert family / groups <= level + 3 * np.sqrt(level * (1 - level) / groups)
    assert strong / groups > 0.95


def test_the_family_wise_test_on_measured_no_effect_subjects():
    """No-effect subjects of blind runs, each candidate's evidence and its
    group's leave-one-out gains (`bench/null_calibration.py --out`):
    `spine5` seed 2061, 30 subjects against a group of 16 (stop 54), and
    `lumped`'s 68 against groups of 8 and 42 against groups of 16 (stops 44,
    45).  Named with the candidates' own bounds: 6 of 30, 10 of 68, 2 of 42
    (the 10% bar missed on two).  With the family-wise test
    (`calibration.thresholds`): 1 of 30, 0 of 68, 0 of 42 with stop 55's
    scales, 0 of 30, 1 of 68, 0 of 42 with the runner-up scales of stop 56
    (both rules chosen after the `spine5` runs were seen, so this is a
    record, not a blind confirmation: docs/history/gap-diagnosis-on-realities.md)."""
    from ehm_drake.gap.reference_group.calibration import thresholds

    nc = bench_script("null_calibration")
    spine5 = json.loads((DATA / "spine5_null_evidence.json").read_text())
    assert sum(len(e["evidence"]) for e in spine5.values()) == 30
    assert all(len(g) == 16 for e in spine5.values() for g in e["null_gains"].values())
    assert nc.exceedances(spine5, nc.clipped_at(0.0))["named"] == 6
    for name, bar in (("spine5_null_evidence", 2), ("lumped_null_evidence", 6),
                      ("lumped_null_evidence_k16", 4)):
        data = json.loads((DATA / f"{name}.json").read_text())
        got = nc.family_named(data)
        assert got["named"] <= min(bar, nc.exceedances(data, nc.clipped_at(0.0))["named"]), name
    # A subject beyond every reference subject on one candidate by far is named.
    entry = next(iter(spine5.values()))
    nulls = entry["null_gains"]
    ev = {n: 0.0 for n in nulls}
    ev["reflex_delay"] = 20 * max(nulls["reflex_delay"])
    thr = thresholds(nulls, ev, borrowed_spread=entry["borrowed_spread"])[0]
    assert ev["reflex_delay"] > thr["reflex_delay"]


def test_family_scales_are_runner_ups_floored_by_their_median():
    """A candidate's scale is the second largest of its K + 1 values, at
    least the candidates' median runner-up and MIN_GAIN; a value left out
    (None) counts for nothing; the scales do not depend on which subject
    holds which value (exchangeability)."""
    from ehm_drake.gap.reference_group.calibration import MIN_GAIN, family_scales

    vals = {"heavy": [0, 0, 0, 436, 1005, 3], "tight": [186, 119, 65, 57, 538, 46],
            "silent": [0, 0, 0, 0, 900, 0], "none": [None, 0, 5, 7, 2, 1]}
    sc = family_scales(vals)
    # Runner-ups 436, 186, 0, 5; their median (95.5) floors the last two.
    assert sc == {"heavy": 436, "tight": 186, "silent": 95.5, "none": 95.5}
    rng = np.random.default_rng(0)
    shuffled = {c: list(rng.permutation(np.array(v, dtype=object))) for c, v in vals.items()}
    assert family_scales(shuffled) == sc
    assert family_scales({"a": [0.0, 1.0], "b": [2.0, -4.0]}) == {"a": MIN_GAIN, "b": MIN_GAIN}
    assert family_scales({}) == {}


def test_a_heavy_cluster_on_one_candidate_does_not_hide_an_effect_on_another():
    """`spine5`'s group of 16 (stop 54): backrest separation reaches 1,005
    and 436 on two no-effect subjects, 13 are at 0; visceral mass reaches
    at most 186.  A subject with a visceral mass of 538 (trial 11 of the
    seed-2061 effect run, its evidence 1.6 times its own bound) was held
    back by stop 55's scales, which scored the separation's 1,005 against a
    bound (309) that its own cluster exceeds; with the runner-up scales it
    is named (538 / 186 against 1,005 / 436).  (The group's 30 fresh
    no-effect subjects under the same rule:
    `test_the_family_wise_test_on_measured_no_effect_subjects`.)"""
    from ehm_drake.gap.reference_group.calibration import thresholds

    entry = json.loads((DATA / "spine5_null_evidence.json").read_text())
    (group,) = entry.values()
    nulls = group["null_gains"]
    assert sorted(nulls["backrest_separation"])[-2:] == pytest.approx([436.5, 1005.3], abs=0.1)
    assert max(nulls["visceral_mass"]) == pytest.approx(186.1, abs=0.1)
    ev = {c: 0.0 for c in nulls}
    ev["visceral_mass"] = 538.2
    thr, bounds, fam = thresholds(nulls, ev, borrowed_spread=group["borrowed_spread"])
    assert ev["visceral_mass"] > bounds["visceral_mass"]
    assert ev["visceral_mass"] > thr["visceral_mass"]
    assert fam["score"] == pytest.approx(1005.3 / 436.5, rel=1e-3)


def test_the_family_wise_test_refuses_nulls_of_unequal_subjects():
    """The test pairs each reference subject's gains over the candidates:
    nulls of different lengths, or a candidate without evidence, are
    refused with a message; with 8 subjects the largest score is used and
    the level said (1/9)."""
    from ehm_drake.gap.reference_group.calibration import thresholds

    with pytest.raises(DiagnosisError, match="different lengths"):
        thresholds({"a": [0.0, 1.0, 2.0], "b": [0.0, 1.0]}, {"a": 0.0, "b": 0.0})
    with pytest.raises(DiagnosisError, match="no evidence"):
        thresholds({"a": [0.0, 1.0, 2.0]}, {})
    with pytest.raises(DiagnosisError, match="not finite for {'a': nan}"):
        thresholds({"a": [0.0, 1.0, 2.0]}, {"a": float("nan")})
    null = {"a": [0, 3, 5, 8, 12, 20, 35, 160.0], "b": [0.0] * 8}
    thr, bounds, fam = thresholds(null, {"a": 0.0, "b": 0.0})
    assert fam["rank"] == 8 and fam["level"] == pytest.approx(1 / 9)
    assert all(thr[c] >= bounds[c] for c in null)
    # Subject 7's 160 stands out of a's null: the largest score is its.
    assert fam["score"] > 1
    # A subject further out than it on b (160 / 13, scaled to b's bound) is
    # named for b; one just below it is not.
    edge = thresholds(null, {"a": 0.0, "b": 1e3})
    assert edge[0]["b"] < 1e3


def test_a_candidate_held_back_by_the_family_wise_test_is_said():
    """When no candidate is named but one exceeds its own bound, the
    explanation names it with both scores (a lead, not a finding); none
    beyond its own bound, nothing said."""
    from ehm_drake.gap.single.verdict import held_back_note

    fam = {"score": 3.26, "subject_score": 1.91}
    ranking = [{"effect": "visceral_mass", "evidence": 538.0, "null_bound": 344.0},
               {"effect": "reflex_delay", "evidence": 170.0, "null_bound": 154.0},
               {"effect": "arms", "evidence": -498.0, "null_bound": 244.0}]
    note = held_back_note(ranking, fam)
    assert note.startswith("visceral_mass exceeds its own bound (538 against 344)")
    assert "1.91 against 3.26" in note
    assert held_back_note(ranking[2:], fam) is None


def test_the_anchor_fit_keeps_only_steps_that_lower_the_true_cost():
    """`anchor.trust_region_descent` on a cost whose local (Gauss-Newton)
    model overshoots: f(x) = sum (1 - exp(-a x_i))^2 about x = 3, a sharp
    valley the linear model badly predicts far from its point.  Every kept
    step lowers the true cost, an overshooting step is taken back with the
    region halved, and the descent ends at the best point it saw, near the
    minimum at 0.  Without the check (a free step, as the anchor fit once
    took) the first step already raises the cost."""
    from types import SimpleNamespace

    from ehm_drake.gap.reference_group.anchor import trust_region_descent

    a = np.array([1.0, 3.0])

    def residual(x):
        return 1.0 - np.exp(-a * x)

    def linearize(x):
        return SimpleNamespace(x=np.array(x, float), cost=float(np.sum(residual(x) ** 2)))

    def step(point, trust, clip=True):
        r, J = residual(point.x), np.diag(a * np.exp(-a * point.x))
        dx = -np.linalg.solve(J, r)  # the local model's minimum
        if clip:
            dx = np.clip(dx, -trust, trust)
        return dx, float(np.sum((r + J @ dx) ** 2))

    (best, x), history = trust_region_descent(linearize, step, np.full(2, 3.0),
                                              iterations=30, trust=8.0, min_trust=1e-3,
                                              tolerance=1e-6)
    assert np.array_equal(best.x, x)
    kept = [h for h in history if h[2] < h[0]]
    rejected = [h for h in history if h[2] >= h[0]]
    assert rejected and kept  # the region had to shrink at least once
    costs = [history[0][0]] + [h[2] for h in kept]
    assert all(b < c for b, c in zip(costs[1:], costs[:-1], strict=True))
    assert best.cost == min(costs) < 1e-3 * history[0][0]
    assert np.max(np.abs(x)) < 0.05
    # The unchecked Newton steps from the same start: the cost rises.
    start = linearize(np.full(2, 3.0))
    with np.errstate(over="ignore"):
        assert linearize(start.x + step(start, None, clip=False)[0]).cost > start.cost


def test_a_cut_cache_file_is_computed_again_not_a_crash(tmp_path):
    """A group's cached anchor or null gains cut short (a run stopped while
    writing it, before writes were whole-or-nothing) reads as no cache, and
    a cache written again reads back whole."""
    from ehm_drake.gap.reference_group.anchor import read_cache_json, write_cache_json

    path = tmp_path / "reference_null" / "k.json"
    path.parent.mkdir()
    path.write_text('{"visceral_mass": [0.1, 0.')
    assert read_cache_json(path) is None
    assert read_cache_json(tmp_path / "none.json") is None
    write_cache_json(path, {"visceral_mass": [0.1, 0.2]})
    assert read_cache_json(path) == {"visceral_mass": [0.1, 0.2]}
    assert [p.name for p in path.parent.iterdir()] == ["k.json"]


def _correlated_cells(rng, n_cells=60, n_bins=12, rho=0.85, outlier=None):
    """One subject's localization cells: each cell's standardized residuals
    smooth in frequency (AR(1), neighbouring bins correlated `rho`, as a
    subject's deviation from its group is), summed as `localize` does."""
    from scipy.stats import chi2

    cells = []
    for c in range(n_cells):
        z = np.empty(2 * n_bins)
        z[0] = rng.standard_normal()
        for i in range(1, len(z)):
            z[i] = rho * z[i - 1] + np.sqrt(1 - rho**2) * rng.standard_normal()
        if outlier == c:
            z += 3.0
        s = float(np.sum(z**2))
        cells.append({"direction": "z", "segment": "trunk", "dof": "x", "f_lo_hz": float(c),
                      "chi2": s, "significant": bool(s > chi2.isf(0.01 / n_cells, 2 * n_bins))})
    return cells


def test_the_cell_test_holds_its_level_on_bins_that_move_together():
    """Residual bins that move together make the chi^2 bound of a cell far too
    easy to pass: a subject of the group's own population passes it in some
    cell more often than not.  Judged against the group's own subjects
    (`calibrate_cells`, a group of 32: level 1/33) it passes in about 3% of
    fresh subjects of that population, and a subject 3 standard deviations
    off in one cell is still found there in most subjects (16 of 20 for this seed)."""
    from ehm_drake.gap.reference_group.calibration import calibrate_cells, cell_key

    rng = np.random.default_rng(7)
    group = [{cell_key(c): c["chi2"] for c in _correlated_cells(rng)} for _ in range(32)]
    raw = calibrated = 0
    n = 300
    for _ in range(n):
        cells = _correlated_cells(rng)
        raw += any(c["significant"] for c in cells)
        rec = calibrate_cells(cells, group)
        calibrated += any(c["significant"] for c in cells)
    assert raw / n > 0.5, raw
    assert calibrated / n < 0.08, calibrated
    assert rec["cell_subjects"] == 32 and rec["cell_level"] == pytest.approx(1 / 33)
    hits = 0
    for _ in range(20):
        cells = _correlated_cells(rng, outlier=5)
        calibrate_cells(cells, group)
        hits += cells[5]["significant"]
        assert all(c["group_bar"] > 0 for c in cells)
    assert hits >= 14, hits
    # Without the group's sums (a cache of an earlier version) the cells stay as they are.
    cells = _correlated_cells(rng)
    before = [c["significant"] for c in cells]
    assert calibrate_cells(cells, None) is None
    assert [c["significant"] for c in cells] == before
