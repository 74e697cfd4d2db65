"""`ehm-drake validate` and the laboratory configurations: the shipped
published facts, each reproduced in its configuration (nonlinear time
domain), a lab's dataset compared bin by bin, bad datasets refused, the
configurations themselves (no backrest, rigid seat, stability)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import yaml

from ehm_drake.analysis.equivalent import SeatSpectrum, equivalent_linear
from ehm_drake.analysis.linear import default_frequencies, linearize
from ehm_drake.cli import main
from ehm_drake.diagram import build_diagram
from ehm_drake.model.seats import apply_seat
from ehm_drake.params import configuration_names, load_params
from ehm_drake.simulation import posture_summary, static_equilibrium
from ehm_drake.validation import FACTS, RUNS, ReferenceError, read_reference
from ehm_drake.validation.run import peak_frequency

pytestmark = pytest.mark.xdist_group("validation")


def test_the_facts_catalogue():
    # At least 4 facts from at least 3 publications, each cited with a DOI,
    # its runs defined, its range an interval that holds its own statement.
    assert len(FACTS) >= 4
    assert len({f.source.key for f in FACTS}) >= 3
    assert len({f.id for f in FACTS}) == len(FACTS)
    for f in FACTS:
        assert re.fullmatch(r"10\.\d{4,5}/\S+", f.source.doi), f.id
        assert f.source.citation and f.source.read and f.statement and f.expected_reason
        assert all(k in RUNS for k in f.runs), f.id
        lo, hi = f.expected
        assert lo is not None or hi is not None
        assert lo is None or hi is None or lo < hi
        assert all(RUNS[k].configuration in configuration_names() for k in f.runs)


def test_configurations():
    names = configuration_names()
    assert {"car_seat", "rigid_seat", "rigid_seat_backrest", "paper_linear"} <= set(names)
    rigid = apply_seat(load_params("rigid_seat"))
    t = rigid.softening.tissue
    # A rigid seat: each contact is the tissue alone; no backrest: the pads
    # carry nothing and the trunk's damping is raised.
    assert rigid.contact.pelvis_pan.stiffness == t.pelvis_pan_stiffness
    assert rigid.restraints.upper_back_pad.stiffness == 0.0
    assert rigid.pid.spine.kd[1] == pytest.approx(3 * load_params().pid.spine.kd[1])
    assert apply_seat(load_params()) == load_params()  # the car seat: the defaults
    with pytest.raises(ValueError, match="unknown configuration|not found"):
        load_params("no_such_configuration")


@pytest.mark.parametrize("config", ["rigid_seat", "rigid_seat_backrest", "car_seat"])
def test_configurations_are_stable_at_rest_and_at_2ms2(config):
    # Every mode of the configuration is stable at rest; the trunk's slow
    # fore-aft sway (0.5-1 Hz) is damped (zeta > 0.02), at 2 m/s^2 too.
    model = build_diagram(load_params(config), guard=False)
    ctx, _ = static_equilibrium(model)
    rest = linearize(model, ctx)
    high = equivalent_linear(model, SeatSpectrum.flat("z", 2.0, (0.5, 20.0)), ctx).linear
    for lin in (rest, high):
        assert lin.is_stable
        slow = [m for m in lin.modes(include_slip=False)
                if m.kind == "oscillatory" and 0.3 < m.freq_hz < 1.5]
        assert all(m.damping_ratio > 0.02 for m in slow)
    if config == "rigid_seat":
        back = posture_summary(model, ctx)["backrest_force_n"]["total"]
        assert back == 0.0  # nothing touches the pads


def _dataset(tmp_path, name, f, mean, spread=0.1, **over):
    data = {"quantity": "apparent_mass", "direction": "z", "configuration": "rigid_seat",
            "level_rms": 0.25, "band_hz": [0.5, 20.0],
            "provenance": {"citation": "synthetic: the model's equivalent-linear curve",
                           "posture": "upright", "seat": "rigid, no backrest",
                           "subjects": "one model", "level": "0.25 m/s^2",
                           "obtained": "computed by the test"},
            "data": {"freq_hz": [float(x) for x in f], "mean": [float(x) for x in mean],
                     "lower": [float(x * (1 - spread)) for x in mean],
                     "upper": [float(x * (1 + spread)) for x in mean]}}
    for k, v in over.items():
        data[k] = v
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture(scope="module")
def validated(tmp_path_factory):
    """`ehm-drake validate` in its short form (30 s runs on the implicit
    design), with two supplied datasets: the model's own equivalent-linear
    apparent mass on the rigid seat at 0.25 m/s^2 (within 15%) and the same
    curve moved 1.3x up in frequency."""
    tmp = tmp_path_factory.mktemp("validate")
    model = build_diagram(load_params("rigid_seat"), guard=False)
    eq = equivalent_linear(model, SeatSpectrum.flat("z", 0.25, (0.5, 20.0)))
    f = np.linspace(0.5, 12.0, 116)
    mean = eq.linear.apparent_mass(f, "z")["z"][1]
    own = _dataset(tmp, "own.yaml", f, mean, spread=0.15)
    moved = _dataset(tmp, "moved.yaml", f, np.interp(f / 1.3, f, mean), spread=0.15)
    out = tmp / "out"
    assert main(["validate", "--out", str(out), "--duration", "30", "--design", "implicit",
                 "--workers", "2", "--quiet", "--reference", str(own), str(moved)]) == 0
    return out, json.loads((out / "validation.json").read_text()), eq


@pytest.mark.slow
def test_every_fact_is_reproduced(validated):
    out, report, _ = validated
    s = report["summary"]
    assert s["facts"] == len(FACTS) and s["publications"] >= 3
    failed = [(r["id"], r["model"], r["expected"]["text"]) for r in report["facts"]
              if not r["passed"]]
    assert not failed
    for r in report["facts"]:
        for key in ("id", "source", "quantity", "configuration", "level_rms", "expected",
                    "model", "passed"):
            assert key in r
        assert r["source"]["doi"] and r["source"]["citation"]
    text = (out / "validation.md").read_text()
    assert "7 of 7" in text or f"{s['passed']} of {s['facts']}" in text
    for png in ("apparent_mass_vs_magnitude.png", "head_transmissibility_vs_magnitude.png",
                "reference_1.png", "reference_2.png"):
        assert (out / png).stat().st_size > 10_000


@pytest.mark.slow
def test_the_resonance_falls_with_magnitude_in_time_domain_as_linearized(validated):
    # The nonlinear simulation and the equivalent-linear model agree on the
    # resonance of every random run within 6% (short records on the
    # implicit design), and it falls by a third from 0.25 to 2.0 m/s^2.
    _, report, _ = validated
    runs = {r["run"]: r for r in report["runs"]}
    for r in runs.values():
        if np.isfinite(r["linear_resonance_hz"] or np.nan):
            assert r["resonance_hz"] == pytest.approx(r["linear_resonance_hz"], rel=0.06), r
    assert runs["rigid_2.0"]["resonance_hz"] < 0.8 * runs["rigid_0.25"]["resonance_hz"]


@pytest.mark.slow
def test_a_supplied_dataset_is_compared_bin_by_bin(validated):
    _, report, eq = validated
    own, moved = report["references"]
    # The model's own curve: inside its +-15% range almost everywhere, the
    # same peak; the curve moved up 30% in frequency: mostly outside, the
    # peak error about +30% of the peak frequency.
    assert own["share_inside_range"] > 0.8
    assert abs(own["peak_frequency_hz"]["error_hz"]) < 0.4
    assert moved["share_inside_range"] < own["share_inside_range"] - 0.25
    f_peak = own["peak_frequency_hz"]["data"]
    assert moved["peak_frequency_hz"]["data"] == pytest.approx(1.3 * f_peak, rel=0.05)
    assert moved["peak_frequency_hz"]["error_hz"] < -0.2 * f_peak
    assert own["provenance"]["obtained"] == "computed by the test"


@pytest.mark.parametrize("change, field", [
    ({"quantity": "force"}, "quantity"),
    ({"configuration": "sofa"}, "configuration"),
    ({"level_rms": 250.0}, "level_rms"),
    ({"provenance": {"citation": "x"}}, "provenance.posture"),
    ({"data": {"freq_hz": [1.0, 2.0], "mean": [1.0], "lower": [0.9], "upper": [1.1]}},
     "data.mean"),
    ({"data": {"freq_hz": [1.0, 2.0], "mean": [1.0, float("nan")], "lower": [0.9, 0.9],
               "upper": [1.1, 1.1]}}, "data.mean[1]"),
    ({"data": {"freq_hz": [1.0, 2.0], "mean": [1.0, 1.0], "lower": [1.1, 0.9],
               "upper": [1.2, 1.1]}}, "data (at 1 Hz)"),
    ({"data": {"freq_hz": [2.0, 1.0], "mean": [1.0, 1.0], "lower": [0.9, 0.9],
               "upper": [1.1, 1.1]}}, "data.freq_hz"),
    ({"unknown_key": 1}, "unknown_key"),
])
def test_bad_datasets_are_refused_naming_file_and_field(tmp_path, capsys, change, field):
    path = _dataset(tmp_path, "bad.yaml", [1.0, 2.0], [1.0, 1.0], **change)
    with pytest.raises(ReferenceError) as e:
        read_reference(path)
    msg = str(e.value)
    assert str(path) in msg and field in msg and "\n" not in msg
    # The command refuses it before running anything, in one line, status 2.
    assert main(["validate", "--out", str(tmp_path / "o"), "--reference", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert field in err and len(err.splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_the_paper_linear_model_does_not_soften():
    model = build_diagram(load_params("paper_linear"), guard=False)
    f = default_frequencies(1200)
    peaks = [peak_frequency(f, equivalent_linear(model, SeatSpectrum.flat("z", a)).linear
                            .apparent_mass(f, "z")["z"][1]) for a in (0.25, 2.0)]
    assert peaks[0] == pytest.approx(peaks[1], abs=1e-9)
    assert "softening" not in model.systems and "body_softening" not in model.systems
