"""Empirical effect signatures from contrast measurements of the reference
group (`ehm_drake.gap.reference_group.contrasts`): loading and pairing, the amplitude fit
under the group's scatter, the leave-one-out null, the errors, and the blind
run's settings for them.  Synthetic subjects on disk; no model is built."""

from __future__ import annotations

import numpy as np
import pytest

from ehm_drake.analysis.formats.frf import FrfData
from ehm_drake.gap.reference_group.calibration import thresholds
from ehm_drake.gap.reference_group.contrasts import (
    LOW_AGREEMENT,
    MIN_CONTRASTS,
    Contrasts,
    ContrastScorer,
    contrast_evidence,
    contrast_nulls,
    contrast_quality,
    find_contrasts,
    load_contrasts,
    smoothing_bins,
)
from ehm_drake.gap.reference_group.group import load_reference, wrap_log
from ehm_drake.gap.single.diagnose import DiagnosisError, load_lab_data

F = np.round(np.arange(0.3, 12.01, 0.3), 6)
CHANNELS = (("pelvis", "z"), ("trunk", "pitch"), ("head", "pitch"))
TESTS = (("z", 0.3), ("z", 0.6), ("x", 0.3), ("x", 0.6))


def _table():
    rows = [(d, seg, dof, f, lv) for d, lv in TESTS for seg, dof in CHANNELS for f in F]
    d, seg, dof, f, lv = (np.array(c) for c in zip(*rows, strict=True))
    return d, seg, dof, f.astype(float), lv.astype(float)


def _subject(rng):
    """log H of a subject: a resonance whose frequency, height and phase lag
    scatter (+-10% on the frequency), per test and channel."""
    d, seg, dof, f, lv = _table()
    fn = 4.5 * (1 + 0.1 * rng.standard_normal())
    zeta = 0.3 * (1 + 0.15 * rng.standard_normal())
    ch = np.array([hash((a, b, c)) % 7 for a, b, c in zip(d, seg, dof, strict=True)]) / 7.0
    r = f / fn
    H = (1 + 2j * zeta * r) / (1 - r**2 + 2j * zeta * r) * (0.5 + ch)
    return np.log(H) + 0.02 * (rng.standard_normal(len(f)) + 1j * rng.standard_normal(len(f)))


def _effect(strength, d=None, f=None, lv=None):
    """An effect's change of log H: a notch near 2.5 Hz in the fore-aft
    tests, growing with the level (as a co-contraction's would); on the
    table's rows, or on rows given by direction, frequency and level."""
    if d is None:
        d, _, _, f, lv = _table()
    shape = np.exp(-0.5 * ((f - 2.5) / 0.6) ** 2) * (0.4 - 0.25j) * (d == "x") * lv / 0.45
    return strength * shape


def _write(folder, logH):
    d, seg, dof, f, lv = _table()
    folder.mkdir(parents=True)
    FrfData(d, seg, dof, f, np.exp(logH.real), np.degrees(logH.imag), np.full(len(f), 0.95),
            lv, np.full(len(f), 10.0)).to_csv(folder / "frf.csv")


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """A reference folder of 10 subjects, 3 of them measured again with the
    effect (strengths 0.8-1.2), and two subjects outside the group: one with
    the effect at 0.6 and one without."""
    root = tmp_path_factory.mktemp("contrasts")
    rng = np.random.default_rng(7)
    logs = [_subject(rng) for _ in range(10)]
    for k, x in enumerate(logs):
        _write(root / "ref" / f"subject_{k:02d}", x)
    for k, s in ((0, 0.8), (3, 1.0), (7, 1.2)):
        noise = 0.02 * (rng.standard_normal(len(x)) + 1j * rng.standard_normal(len(x)))
        _write(root / "ref" / "contrasts" / "cocontraction" / f"subject_{k:02d}",
               logs[k] + _effect(s) + noise)
    _write(root / "with", _subject(rng) + _effect(0.6))
    _write(root / "without", _subject(rng))
    return root, logs


def _residual(group, folder):
    data = load_lab_data(folder)
    return wrap_log(np.log(data.rows.H[group.align(data)]) - group.mean_log)


def test_contrasts_are_paired_with_their_own_subject(lab):
    root, logs = lab
    group = load_reference([root / "ref"])
    assert group.size == 10  # the contrasts folder is not a subject
    folder = find_contrasts(root / "ref")
    assert folder == root / "ref" / "contrasts"
    assert find_contrasts([root / "ref" / "subject_00", root / "ref" / "subject_01"]) is None
    assert find_contrasts(group) is None
    c = load_contrasts(folder, group)
    assert c.describe() == {"cocontraction": 3}
    subjects, deltas = c.by_effect["cocontraction"]
    assert subjects == [0, 3, 7]
    # delta is the subject's own change: the effect (and the noise of two
    # sittings), not the subject's difference from the group.
    rows = group.rows
    for dl, s in zip(deltas, (0.8, 1.0, 1.2), strict=True):
        mine = _effect(s, rows.direction, rows.freq, rows.level)
        assert np.sqrt(np.mean(np.abs(dl - mine) ** 2)) < 0.05
        assert np.sqrt(np.mean(np.abs(mine) ** 2)) > 0.05
    # The leave-one-out signature is the mean of the others (smoothed).
    np.testing.assert_allclose(c.signature("cocontraction", without=3),
                               c.smooth(deltas[[0, 2]].mean(axis=0)))
    np.testing.assert_allclose(c.signature("cocontraction", without=5),
                               c.smooth(deltas.mean(axis=0)))


def test_a_signature_is_smoothed_over_frequency_within_each_test_and_channel(lab):
    """The smoothing takes out the sittings' noise, not the effect: the
    signature is nearer the subjects' true mean change than the raw mean,
    and stays within its test and channel."""
    root, _ = lab
    group = load_reference([root / "ref"])
    c = load_contrasts(find_contrasts(root / "ref"), group)
    rows = group.rows
    assert smoothing_bins(rows) == 3  # 0.9 Hz on this 0.3 Hz grid
    assert smoothing_bins(rows, 0.0) == 1 and smoothing_bins(rows, 1.2) == 5
    _, deltas = c.by_effect["cocontraction"]
    true = _effect(1.0, rows.direction, rows.freq, rows.level)
    raw, smoothed = deltas.mean(axis=0), c.signature("cocontraction")
    # (the subjects' own 0.02 noise per sitting, less what the smoothing
    # flattens at the notch's peak)
    assert np.sqrt(np.mean(np.abs(smoothed - true) ** 2)) < \
        0.8 * np.sqrt(np.mean(np.abs(raw - true) ** 2))
    # A change on one channel of one test stays there.
    spike = np.zeros(len(rows.freq), complex)
    spike[len(spike) // 2] = 1.0
    m = (rows.direction == rows.direction[len(spike) // 2]) & \
        (rows.channel == rows.channel[len(spike) // 2]) & \
        (rows.level == rows.level[len(spike) // 2])
    out = c.smooth(spike)
    assert np.all(out[~m] == 0) and 2 <= np.count_nonzero(out) <= 3
    # Without the rows (a `Contrasts` made by hand) nothing is smoothed.
    assert Contrasts(c.by_effect, "here").signature("cocontraction") == \
        pytest.approx(raw)


def test_the_measured_signature_names_the_effect_and_not_a_subject_without_it(lab):
    root, _ = lab
    group = load_reference([root / "ref"])
    c = load_contrasts(find_contrasts(root / "ref"), group)
    scorer = ContrastScorer(group)
    s = c.signature("cocontraction")
    evidence = {}
    for name in ("with", "without"):
        r = _residual(group, root / name)
        res = scorer.score(r, "cocontraction", s)
        evidence[name] = contrast_evidence(res, scorer.baseline(r))
        if name == "with":
            # The amplitude is the subject's strength over the contrasts'
            # mean (0.6 / 1.0), on all rows and on the level differences.
            assert res["coords"][0] == pytest.approx(0.6, abs=0.1)
            assert res["level_coords"][0] == pytest.approx(0.6, abs=0.15)
            assert res["level_gain"] > 0
            assert res["params"] == {"cocontraction": {"contrast_amplitude": res["coords"][0]}}
    nulls = contrast_nulls(group, c)
    assert len(nulls["cocontraction"]) == group.size
    # Only the effects asked for (a diagnosis asks for its candidates).
    assert contrast_nulls(group, c, ["cocontraction"]) == nulls
    assert contrast_nulls(group, c, []) == {}
    with pytest.raises(DiagnosisError, match="no contrasts for arms"):
        contrast_nulls(group, c, ["arms"])
    assert evidence["with"] > 10 * max(max(nulls["cocontraction"]), evidence["without"], 1.0)
    for name, named in (("with", True), ("without", False)):
        thr, _, _ = thresholds(nulls, {"cocontraction": evidence[name]})
        assert (evidence[name] > thr["cocontraction"]) == named


def test_an_opposite_change_gets_amplitude_zero_and_no_gain(lab):
    """The amplitude is the effect's strength: never negative, so a subject
    who differs from the group the other way does not count for it."""
    root, _ = lab
    group = load_reference([root / "ref"])
    s = load_contrasts(find_contrasts(root / "ref"), group).signature("cocontraction")
    scorer = ContrastScorer(group)
    r = _residual(group, root / "without") - 0.8 * s
    res = scorer.score(r, "cocontraction", s)
    assert res["coords"] == [0.0] and res["level_coords"] == [0.0]
    assert contrast_evidence(res, scorer.baseline(r)) == pytest.approx(0.0, abs=1e-9)
    # A signature with nothing in it (no change measured) fits nothing.
    flat = scorer.score(r, "cocontraction", np.zeros_like(s))
    assert flat["coords"] == [0.0] and flat["level_gain"] == 0.0


def test_a_leave_one_out_null_never_scores_a_subject_with_its_own_contrast(lab, monkeypatch):
    root, _ = lab
    group = load_reference([root / "ref"])
    c = load_contrasts(find_contrasts(root / "ref"), group)
    asked = []
    real = c.signature

    def spy(effect, without=None):
        asked.append(without)
        return real(effect, without)
    monkeypatch.setattr(c, "signature", spy)
    contrast_nulls(group, c)
    assert asked == list(range(group.size))



def test_the_contrasts_quality_says_where_they_agree_and_when_they_do_not(lab, tmp_path):
    """A lab reads off its contrasts where the imposed change acts and
    whether its subjects agree on it, before diagnosing anyone."""
    from ehm_drake.gap.report import _contrast_lines

    root, logs = lab
    group = load_reference([root / "ref"])
    c = load_contrasts(find_contrasts(root / "ref"), group)
    # Two more "contrasts" that share no change: each subject measured
    # again with its own random change, as large as the effect's.
    rng = np.random.default_rng(11)
    subjects, deltas = c.by_effect["cocontraction"]
    scale = np.sqrt(np.mean(np.abs(deltas) ** 2))
    noise = scale * (rng.standard_normal((2, deltas.shape[1]))
                     + 1j * rng.standard_normal((2, deltas.shape[1]))) / np.sqrt(2)
    both = Contrasts({"cocontraction": (subjects, deltas), "arms": ([1, 2], noise),
                      "double": (subjects, 2 * deltas)}, "here")
    q = contrast_quality(group, both)
    co = q["cocontraction"]
    assert co["subjects"] == ["subject_00", "subject_03", "subject_07"]
    # The subjects' changes are the same notch (strengths 0.8-1.2, noise
    # 0.02): they agree, and the cells where they do are the fore-aft
    # tests' around 2.5 Hz, where the notch is.
    assert co["agreement"] > 0.8
    assert co["cells"] and all(x["direction"] == "x" and x["f_lo_hz"] in (1.0, 2.5)
                               for x in co["cells"])
    assert sum(x["share"] for x in co["cells"]) > 0.5
    # Twice the change is twice the size, and the same agreement.
    assert q["double"]["rms_change_sd"] == pytest.approx(2 * co["rms_change_sd"], rel=1e-12)
    assert q["double"]["agreement"] == pytest.approx(co["agreement"], rel=1e-12)
    # Independent changes have nothing in common.
    assert abs(q["arms"]["agreement"]) < LOW_AGREEMENT
    text = "\n".join(_contrast_lines({"source": "here", "quality": q}))
    assert "| cocontraction | subject_00, subject_03, subject_07 |" in text
    assert "The contrasts of arms disagree" in text
    assert "cocontraction disagree" not in text and "double disagree" not in text
    assert _contrast_lines(None) == [] and _contrast_lines({"source": "x"}) == []
    with pytest.raises(DiagnosisError, match="arms has 1 contrast subject"):
        contrast_quality(group, Contrasts({"arms": ([1], noise[:1])}, "here"))


def test_bad_contrasts_get_clear_errors(lab, tmp_path):
    import shutil

    root, logs = lab
    group = load_reference([root / "ref"])
    src = root / "ref" / "contrasts" / "cocontraction"

    def folder(name, subjects, effect="cocontraction"):
        base = tmp_path / name
        for s in subjects:
            shutil.copytree(src / s, base / effect / s)
        return base
    with pytest.raises(DiagnosisError, match="unknown effect 'tension'"):
        load_contrasts(folder("a", ["subject_00", "subject_03"], "tension"), group)
    stranger = folder("b", ["subject_00", "subject_03"])
    shutil.move(stranger / "cocontraction" / "subject_03", stranger / "cocontraction" / "bob")
    with pytest.raises(DiagnosisError, match="not in the reference group"):
        load_contrasts(stranger, group)
    with pytest.raises(DiagnosisError, match=f"at least {MIN_CONTRASTS}"):
        load_contrasts(folder("c", ["subject_00"]), group)
    with pytest.raises(DiagnosisError, match="contrasts folder not found"):
        load_contrasts(tmp_path / "nowhere", group)
    # A contrast measured with another protocol (the fore-aft tests missing).
    short = tmp_path / "d" / "cocontraction"
    for s in ("subject_00", "subject_03"):
        d, seg, dof, f, lv = _table()
        keep = d == "z"
        x = logs[int(s[-2:])]
        (short / s).mkdir(parents=True)
        FrfData(d[keep], seg[keep], dof[keep], f[keep], np.exp(x.real[keep]),
                np.degrees(x.imag[keep]), np.full(keep.sum(), 0.95), lv[keep],
                np.full(keep.sum(), 10.0)).to_csv(short / s / "frf.csv")
    with pytest.raises(DiagnosisError, match="same tests"):
        load_contrasts(tmp_path / "d", group)


def test_diagnose_contrasts_needs_a_reference(tmp_path, capsys):
    from ehm_drake.cli import main

    assert main(["diagnose", str(tmp_path), "--contrasts", str(tmp_path), "--out",
                 str(tmp_path / "o")]) == 2
    assert "--contrasts needs --reference" in capsys.readouterr().err


def test_blind_contrasts_are_reference_subjects_in_another_sitting():
    from ehm_drake.gap.lab.blind import BlindError, BlindSpec
    from ehm_drake.gap.lab.synth import SynthError, SynthSpec, _test_seeds

    for n, refs in ((1, 8), (9, 8), (2, 0)):
        with pytest.raises(BlindError, match="--contrasts"):
            BlindSpec(trials=1, seed=1, references=refs, contrasts=n).validate()
    BlindSpec(trials=1, seed=1, references=8, contrasts=2).validate()
    # The first sitting keeps its seeds (data made before stay the same);
    # another sitting draws its own excitation and noise.
    first = _test_seeds(5, 6)
    assert first == [int(s.generate_state(1)[0])
                     for s in np.random.SeedSequence([5, 2]).spawn(6)]
    second = _test_seeds(5, 6, session=1)
    assert len(set(first) & set(second)) == 0
    with pytest.raises(SynthError, match="session"):
        SynthSpec({}, 5, session=-1).validate()
