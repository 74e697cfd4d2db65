"""Independent realities: the interface, and synth/blind's plumbing around it
(a toy reality with a known response: each channel the seat displacement
through a second-order low-pass whose resonance the subject and the effect
set)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal as sps

from ehm_drake import realities
from ehm_drake.gap.lab.blind import twin_detectability
from ehm_drake.gap.lab.synth import SynthError, SynthSpec, synthesize
from ehm_drake.realities import (
    CHANNEL_NAMES,
    Reality,
    RealityError,
    RealityRecord,
    get_reality,
    reality_names,
    register_reality,
)


class ToyReality(Reality):
    """Every translation channel follows the seat's vertical displacement
    through wn^2 / (s^2 + 2 zeta wn s + wn^2); rotations are zero."""

    name = "toy"
    description = "second-order vertical transmissibility"
    sources = ("a test rig",)
    time_step = 1e-3

    def subject(self, seed):
        rng = np.random.default_rng(np.random.SeedSequence([seed, 7]))
        return {"f_n_hz": float(5.0 * (1 + rng.uniform(-0.2, 0.2)))}

    def effect_values(self, name, strength):
        if not 0 <= strength <= 1:
            raise RealityError(f"strength {strength}")
        # The toy's "visceral mass" lowers the resonance by up to 20%.
        return {"f_factor": 1.0 - 0.2 * strength}

    def prepare(self, subject, effects):
        f = subject["f_n_hz"]
        for v in effects.values():
            f *= v["f_factor"]
        return {"f_n_hz": f}

    def run_test(self, prepared, signal):
        wn, zeta, h = 2 * np.pi * prepared["f_n_hz"], 0.3, signal.time_step
        b, a = sps.bilinear([wn**2], [1.0, 2 * zeta * wn, wn**2], fs=1 / h)
        z = sps.lfilter(b, a, signal.displacement[:, 2])
        keep = signal.times >= signal.steady_start
        ch = {c: np.zeros(keep.sum()) for c in CHANNEL_NAMES}
        for seg in ("pelvis", "trunk", "head"):
            ch[f"{seg}_z"] = z[keep]
        return RealityRecord(signal.times[keep], signal.acceleration[keep], ch, 50.0)


@pytest.fixture
def toy(monkeypatch):
    monkeypatch.setitem(realities._REGISTRY, "toy", ToyReality)
    return get_reality("toy")


def test_registry_names_the_model_and_refuses_unknown_realities(toy):
    assert reality_names()[0] == "ehm" and "toy" in reality_names()
    with pytest.raises(RealityError, match="unknown reality 'nowhere'; choose from ehm"):
        get_reality("nowhere")
    with pytest.raises(ValueError, match="other than 'ehm'"):
        register_reality(type("Bad", (Reality,), {"name": "ehm"}))
    with pytest.raises(SynthError, match="unknown reality"):
        SynthSpec({}, 0, reality="nowhere").validate()


def test_a_record_that_blew_up_is_reported_with_time_and_channel():
    t = np.arange(5) * 0.01
    ch = {c: np.zeros(5) for c in CHANNEL_NAMES}
    ch["head_pitch"][3:] = np.nan
    with pytest.raises(RealityError, match=r"head_pitch is not finite from t = 0.030 s"):
        RealityRecord(t, np.zeros((5, 3)), ch).check("toy")
    del ch["knee_l_x"]
    with pytest.raises(RealityError, match="missing channels knee_l_x"):
        RealityRecord(t, np.zeros((5, 3)), ch).check("toy")


def _synth(tmp_path, name, effects, seed=3):
    spec = SynthSpec(effects, seed, (0.3, 0.6), "z", 30.0, reality="toy")
    return synthesize(spec, tmp_path / name, tmp_path / f"{name}_key.json", workers=1,
                      progress=False)


def test_synth_on_a_reality_gives_its_response_through_the_lab_chain(tmp_path, toy):
    res = _synth(tmp_path, "data", {"visceral_mass": 1.0})
    key = json.loads(res.key_path.read_text())
    # The truth is the reality's own: its name, subject and effect values.
    assert key["reality"] == "toy" and "subject_factors" not in key
    assert key["effects"]["visceral_mass"]["values"] == {"f_factor": pytest.approx(0.8)}
    f_n = key["subject"]["f_n_hz"] * 0.8
    frf = res.frf
    # Recorded at the lab's 200 Hz; H1 of a second-order low-pass: ~1 well
    # below the resonance, the resonance peak near f_n (0.1 Hz bins).
    ts = res.tests[0]
    assert ts["duration_s"] == pytest.approx(30.0 + 1 / 200, abs=1e-9)  # 6001 samples
    m = (frf.direction == "z") & (frf.segment == "head") & (frf.dof == "z") & \
        np.isclose(frf.level_rms, 0.3)
    f, g = frf.freq_hz[m], frf.gain[m]
    assert np.median(g[(f > 0.4) & (f < 1.0)]) == pytest.approx(1.0, abs=0.05)
    band = (f > 2) & (f < 10)
    assert f[band][np.argmax(g[band])] == pytest.approx(f_n, rel=0.1)
    # The data folder holds what a lab hands over, nothing of the truth.
    assert sorted(p.name for p in res.out_dir.iterdir()) == ["frf.csv", "tests.json", "z_0.3",
                                                             "z_0.6"]


def test_twin_detectability_sees_the_effect_and_nothing_without_it(tmp_path, toy):
    data = _synth(tmp_path, "data", {"visceral_mass": 1.0}).out_dir
    twin = _synth(tmp_path, "twin", {}).out_dir
    again = _synth(tmp_path, "again", {}).out_dir
    det = twin_detectability(data, twin)
    assert det["detectable"] and det["effects"]["all"]["cells"] >= 1
    none = twin_detectability(again, twin)  # same seed, no effect: the same bytes
    assert not none["detectable"] and none["effects"]["all"]["cells"] == 0
