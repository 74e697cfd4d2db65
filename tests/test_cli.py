"""The command line: the main job end to end, files, and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ehm_drake.analysis.formats import read_frf, read_timeseries
from ehm_drake.cli import main
from ehm_drake.params import save_params

#: Module fixtures: the module's tests stay on one xdist worker (built once).
pytestmark = pytest.mark.xdist_group("cli")


@pytest.fixture(scope="module")
def sim_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "run"
    assert main(["simulate", "--design", "reference", "--duration", "12", "--direction", "z",
                 "--seed", "3", "--out", str(out), "--quiet"]) == 0
    return out


def test_simulate_writes_summary_series_and_plots(sim_dir):
    summary = json.loads((sim_dir / "summary.json").read_text())
    assert summary["dof"] == 31 and summary["segments"] == 12
    assert summary["mass_kg"] == pytest.approx(75.3, abs=0.5)
    assert summary["real_time_factor"] > 0
    assert set(summary["settle_posture_error_deg"]) == {
        "lumbar", "thoracic", "neck", "hips", "knees", "ankles"}
    assert abs(summary["head_pitch_drift_deg"]) < 0.5
    assert summary["backrest_force_n"]["total"] > 0
    assert summary["seat_rms_measured"]["z"] == pytest.approx(0.1941, rel=0.01)
    for name in ("timeseries.csv", "seat_forces.csv", "joint_torques.csv", "frf.csv",
                 "apparent_mass.csv", "posture.png", "responses.png",
                 "transmissibility_z.png", "settled_state.npz"):
        assert (sim_dir / name).stat().st_size > 0, name
    ts = read_timeseries(sim_dir / "timeseries.csv", min_duration=5.0)
    assert ts.fs == pytest.approx(200.0)
    assert ts.meta["direction"] == "z"
    frf = read_frf(sim_dir / "frf.csv")
    f, gain, _, coh = frf.get("z", "head", "z")
    assert gain.max() > 1.0  # a vertical resonance amplifies the head


def test_restart_from_settled_state(sim_dir, tmp_path, capsys):
    out = tmp_path / "again"
    assert main(["simulate", "--design", "reference", "--duration", "3", "--settled",
                 str(sim_dir / "settled_state.npz"), "--out", str(out), "--quiet"]) == 0
    # On another design (the commands' default is the implicit one) the
    # state does not fit: a one-line error naming both designs, nothing run.
    capsys.readouterr()
    assert main(["simulate", "--duration", "3", "--settled", str(sim_dir / "settled_state.npz"),
                 "--out", str(tmp_path / "other"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "reference design at a 1 ms step" in err and "--design reference" in err


def test_no_figures_writes_the_same_data_and_verbose_splits_the_time(sim_dir, tmp_path, capsys,
                                                                    monkeypatch):
    """--no-figures leaves out the PNGs only: the data files are the same
    bytes; --verbose prints the command's wall-clock split, whose parts
    sum to at most the total, the cost per time step and the preloaded
    libraries (a faster allocator, which a user checks took effect)."""
    runs = {}
    for name, extra in (("with", []), ("without", ["--no-figures", "--verbose"])):
        out = runs[name] = tmp_path / name
        if extra:  # (only the name is read: nothing is started with it)
            monkeypatch.setenv("LD_PRELOAD", "/usr/lib/x86_64-linux-gnu/libjemalloc.so.2:libx.so")
        assert main(["simulate", "--design", "reference", "--duration", "3", "--settled",
                     str(sim_dir / "settled_state.npz"), "--out", str(out), "--quiet",
                     *extra]) == 0
    assert not list(runs["without"].glob("*.png"))
    assert {p.name for p in runs["with"].glob("*.png")} == {
        "posture.png", "responses.png", "transmissibility_z.png"}
    for name in ("timeseries.csv", "seat_forces.csv", "joint_torques.csv", "frf.csv",
                 "apparent_mass.csv"):
        assert (runs["with"] / name).read_bytes() == (runs["without"] / name).read_bytes()
    summary = json.loads((runs["without"] / "summary.json").read_text())
    assert "posture.png" not in summary["files"]
    wall = summary["wall_s"]
    assert set(wall) == {"settle", "vibrate", "write", "analysis", "total (after imports)"}
    assert sum(v for k, v in wall.items() if k != "total (after imports)") \
        <= wall["total (after imports)"]
    printed = capsys.readouterr().out
    assert "wall clock (s): settle" in printed
    assert "us per time step (3000 steps of 1 ms)" in printed
    assert "preloaded (LD_PRELOAD): libjemalloc.so.2, libx.so" in printed


def test_comfort_and_transmissibility_commands(sim_dir, tmp_path):
    assert main(["comfort", str(sim_dir), "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "comfort.json").read_text())
    assert report["seat"]["weighted_rms"]["z"] > 0.05
    assert report["seat"]["weighted_rms"]["x"] < 1e-9
    assert "head" in report
    # Refuses to overwrite without --force.
    assert main(["comfort", str(sim_dir), "--out", str(tmp_path)]) == 2
    out = tmp_path / "tr"
    assert main(["transmissibility", str(sim_dir), "--out", str(out)]) == 0
    assert (out / "frf.csv").is_file() and (out / "transmissibility_z.png").is_file()


def test_existing_output_folder_is_not_overwritten(sim_dir, capsys):
    before = (sim_dir / "summary.json").read_bytes()
    assert main(["simulate", "--duration", "2", "--out", str(sim_dir), "--quiet"]) == 2
    assert "--force" in capsys.readouterr().err
    assert (sim_dir / "summary.json").read_bytes() == before


@pytest.mark.parametrize("argv,match", [
    (["simulate", "--rms", "-1", "--out", "x"], "positive"),
    (["simulate", "--direction", "w", "--out", "x"], "invalid choice"),
    (["simulate", "--duration", "abc", "--out", "x"], "number"),
    (["simulate", "--seed", "-2", "--out", "x"], ">= 0"),
    (["simulate", "--variant", "stiff", "--out", "x"], "invalid choice"),
])
def test_bad_arguments_exit_with_usage(argv, match, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    assert match in capsys.readouterr().err


@pytest.mark.parametrize("extra,match", [
    (["--stature", "176"], "centimetres"),
    (["--rms", "194.1"], "mm/s"),
    (["--excitation", "csv"], "--csv FILE"),
])
def test_bad_values_give_one_line_errors(tmp_path, extra, match, capsys):
    code = main(["simulate", "--out", str(tmp_path / "o"), "--quiet", *extra])
    assert code == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err


def test_bad_parameter_file(tmp_path, capsys):
    f = tmp_path / "p.yaml"
    f.write_text("passive:\n  neck:\n    stiffness: [-1, 1, 1]\n")
    assert main(["simulate", "--params", str(f), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert "passive.neck.stiffness[0]" in capsys.readouterr().err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_unstable_parameters_exit_3(tmp_path, capsys):
    f = tmp_path / "p.yaml"
    f.write_text("his:\n  kd: [60, 60, 60]\n")
    code = main(["simulate", "--params", str(f), "--duration", "2", "--direction", "xyz",
                 "--rms", "0.5", "--out", str(tmp_path / "o"), "--quiet"])
    assert code == 3
    assert "diverged" in capsys.readouterr().err


def test_simulate_runs_the_implicit_design_at_its_own_step_by_default(sim_dir, tmp_path):
    """No --design: the implicit design at 5 ms, the same body as the paper's
    reference design (``--design reference``, the fixture's run)."""
    out = tmp_path / "implicit"
    assert main(["simulate", "--duration", "12", "--direction", "z",
                 "--seed", "3", "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["design"], summary["time_step_s"]) == ("implicit", 0.005)
    assert summary["dof"] == 31
    reference = json.loads((sim_dir / "summary.json").read_text())
    assert (reference["design"], reference["time_step_s"]) == ("reference", 0.001)
    # The same body: outputs at the same rate, the same settled posture and
    # the same vertical transmissibility: mean gain per band within 6% (12 s
    # records of different random realizations, one per step; measured
    # 0.5-3%, where the band-mean gains' coherence is > 0.97).
    assert read_timeseries(out / "timeseries.csv", min_duration=5.0).fs == pytest.approx(200.0)
    for joint, e in summary["settle_posture_error_deg"].items():
        assert e == pytest.approx(reference["settle_posture_error_deg"][joint], abs=0.3), joint
    for seg in ("pelvis", "trunk", "head"):
        f, gain, _, _ = read_frf(out / "frf.csv").get("z", seg, "z")
        f_ref, gain_ref, _, _ = read_frf(sim_dir / "frf.csv").get("z", seg, "z")
        assert np.array_equal(f, f_ref)
        for lo, hi in ((1.0, 3.0), (3.0, 7.0), (7.0, 12.0)):
            band = (f >= lo) & (f <= hi)
            assert gain[band].mean() == pytest.approx(gain_ref[band].mean(), rel=0.06), \
                (seg, lo, hi)


def test_a_parameter_file_that_states_its_design_keeps_it_and_says_so(params, tmp_path,
                                                                       capsys):
    """A complete parameter set (a fit's output, `save_params`) states the
    reference design: simulate keeps it, and says how to run the faster one."""
    save_params(params, tmp_path / "all.yaml")
    assert main(["simulate", "--params", str(tmp_path / "all.yaml"), "--duration", "2",
                 "--no-figures", "--out", str(tmp_path / "run")]) == 0
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["design"] == "reference"
    assert "--design implicit runs the faster design" in capsys.readouterr().err


def test_output_every_k_steps_lets_a_step_that_does_not_divide_200_hz_run(sim_dir, tmp_path):
    """`--output-every 1` at 6 ms (the largest step the accuracy table allows;
    200 Hz outputs are refused there): outputs every 6 ms exactly, the same
    vertical transmissibility as the 1 ms reference run (band means within 6%,
    as the 5 ms run above; measured 0.2-2.7%), and the one part beyond its second-order step
    named in the build's warning."""
    out = tmp_path / "six"
    with pytest.warns(UserWarning, match="lower_torso_y"):
        assert main(["simulate", "--design", "implicit", "--time-step", "0.006",
                     "--output-every", "1", "--duration", "12", "--direction", "z",
                     "--seed", "3", "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["design"], summary["time_step_s"]) == ("implicit", 0.006)
    t = read_timeseries(out / "timeseries.csv", min_duration=5.0).t
    assert np.allclose(np.diff(t), 0.006, rtol=0, atol=1e-9)
    for seg in ("pelvis", "trunk", "head"):
        f, gain, _, _ = read_frf(out / "frf.csv").get("z", seg, "z")
        f_ref, gain_ref, _, _ = read_frf(sim_dir / "frf.csv").get("z", seg, "z")
        for lo, hi in ((1.0, 3.0), (3.0, 7.0), (7.0, 12.0)):
            band, band_ref = (f >= lo) & (f <= hi), (f_ref >= lo) & (f_ref <= hi)
            assert gain[band].mean() == pytest.approx(gain_ref[band_ref].mean(), rel=0.06), \
                (seg, lo, hi)


def test_output_every_sets_the_rate_exactly_on_any_design_step():
    from ehm_drake.diagram import on_design
    from ehm_drake.params import ParameterError, load_params

    p = load_params()
    q = on_design(p, "implicit", 0.006, output_every=1)
    assert q.simulation.output_rate_hz == 1.0 / 0.006
    assert p.simulation.output_rate_hz == 200.0  # the caller's parameters untouched
    assert on_design(p, "implicit", output_every=2).simulation.output_rate_hz == 100.0
    # The step chosen by accuracy first (5/3 ms on the high-stiffness variant), then the rate.
    high = on_design(p, "implicit", variant="high-stiffness", output_every=3)
    assert high.simulation.time_step_s == pytest.approx(0.005 / 3, rel=1e-12)
    assert high.simulation.output_rate_hz == pytest.approx(200.0, rel=1e-12)
    assert on_design(p, None, None, output_every=5).simulation.output_rate_hz == 200.0
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ParameterError, match="whole number"):
            on_design(p, "implicit", 0.006, output_every=bad)
    with pytest.raises(ParameterError, match="output_rate_hz"):  # below 100 Hz
        on_design(p, "implicit", 0.006, output_every=2)


def test_the_implicit_step_is_chosen_by_accuracy(capsys):
    """`--design implicit` without `--time-step` takes the largest step of
    5 ms / n that keeps every part of that body and variant second-order
    accurate: 5 ms for the default model, 5/3 ms for the high-stiffness
    variant (its lower-torso springs need 2.19 ms; at 5 ms their implicit
    first-order springs cost it 27% in its worst bin).  The diagram then
    builds without the step warning.  A step the user gives is kept."""
    import warnings

    from ehm_drake.cli import _load_model_params, build_parser
    from ehm_drake.diagram import build_diagram

    def params(*argv):
        return _load_model_params(build_parser().parse_args(["simulate", "--out", "x", *argv]))

    assert params("--design", "implicit").simulation.time_step_s == 0.005
    high = params("--design", "implicit", "--variant", "high-stiffness")
    assert high.simulation.time_step_s == pytest.approx(0.005 / 3, rel=1e-12)
    assert "second-order" in capsys.readouterr().err
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        build_diagram(high, variant="high-stiffness", guard=False, seat_forces=False)
    given = params("--design", "implicit", "--variant", "high-stiffness", "--time-step", "0.005")
    assert given.simulation.time_step_s == 0.005
    # The commands' default (simulate, modes, fit): the same, without --design.
    default = params("--variant", "high-stiffness").simulation
    assert (default.design, default.time_step_s) == ("implicit", high.simulation.time_step_s)


def test_design_and_time_step_options(tmp_path, capsys):
    from ehm_drake.params import load_params, with_design

    p = load_params()
    assert (p.simulation.design, p.simulation.time_step_s) == ("reference", 0.001)
    q = with_design(p, "implicit")
    assert (q.simulation.design, q.simulation.time_step_s) == ("implicit", 0.005)
    assert p.simulation.design == "reference"  # the caller's parameters untouched
    # A step given in the parameters on that design is kept.
    assert with_design(with_design(p, "implicit", 0.0025), "implicit").simulation.time_step_s \
        == 0.0025
    assert with_design(q, "reference").simulation.time_step_s == 0.001
    # Steps the output rate or the range forbid: one line, exit 2.
    for step, match in (("0.006", "output_rate_hz"), ("0.002", "whole number of time steps"),
                        ("5", "seconds")):
        code = main(["simulate", "--design", "implicit", "--time-step", step, "--out",
                     str(tmp_path / "o"), "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and match in err and "Traceback" not in err, err


def test_diagnosing_a_simulation_of_another_design_says_so(sim_dir, params, tmp_path):
    """`diagnose` on a `simulate` folder (its summary.json names the design)
    whose design is not the diagnosis's model's: a caution naming both and
    the option that matches them; none when they match, when a design is
    asked for, or for lab data (no summary.json)."""
    import argparse

    from ehm_drake.gap.commands import _design_caution
    from ehm_drake.params import with_design

    design = json.loads((sim_dir / "summary.json").read_text())["design"]
    other = "reference" if design == "implicit" else "implicit"

    def args(data, **kw):
        return argparse.Namespace(data=str(data), design=kw.get("design"), time_step=None,
                                  params=None)

    text = _design_caution(args(sim_dir), with_design(params, other))
    assert f"on the {design} design" in text and f"runs the {other} design" in text
    assert text.endswith(f"--design {design}")
    assert _design_caution(args(sim_dir), with_design(params, design)) is None
    assert _design_caution(args(sim_dir, design=other), with_design(params, other)) is None
    lab = tmp_path / "lab"
    lab.mkdir()
    assert _design_caution(args(lab), with_design(params, other)) is None


def test_the_gap_commands_run_the_implicit_design_unless_told(tmp_path):
    """`diagnose`, `synth` and `blind` give their model the implicit design
    at its accurate step (5 ms for the default body) like every command;
    `--design reference` the paper's 1 ms design; a parameter file that
    states its step keeps it; `synth` on an independent reality has no model."""
    from ehm_drake.cli import build_parser
    from ehm_drake.gap.commands import _command_params, _model_params

    parser = build_parser()

    def resolved(*argv):
        return _command_params(parser.parse_args(list(argv)))

    for cmd in (["diagnose", "data"], ["synth", "--effect", "none", "--seed", "1",
                                         "--key", "k.json"],
                ["blind", "--trials", "1", "--seed", "1"]):
        sim = resolved(*cmd, "--out", "o").simulation
        assert (sim.design, sim.time_step_s) == ("implicit", 0.005), cmd
        sim = resolved(*cmd, "--out", "o", "--design", "reference").simulation
        assert (sim.design, sim.time_step_s) == ("reference", 0.001), cmd
    stepped = tmp_path / "stepped.yaml"
    stepped.write_text("simulation:\n  time_step_s: 0.0005\n")
    sim = resolved("diagnose", "data", "--out", "o", "--params", str(stepped)).simulation
    assert (sim.design, sim.time_step_s) == ("reference", 0.0005)
    args = parser.parse_args(["synth", "--effect", "none", "--seed", "1", "--key", "k.json",
                              "--out", "o", "--reality", "lumped"])
    assert _model_params(args, False) is None


def test_the_paths_the_summary_leaves_out_are_zero_in_the_model(params):
    """The printed summary leaves out the midline segments' paths that the
    body's left-right symmetry makes zero (with axes excited together their
    estimates are noise): in the linearized model those are zero to 1e-6 of
    the largest gain of their kind, and every other midline path is not."""
    from ehm_drake.analysis.linear import linearize
    from ehm_drake.cli import _zero_by_symmetry
    from ehm_drake.diagram import build_diagram

    frf = linearize(build_diagram(params)).transmissibility(np.linspace(0.5, 12.0, 24))
    peak = {}
    for key in frf.channels():
        peak["/".join(key[:3])] = float(np.max(frf.get(*key[:3])[1]))
    for kind in (("x", "y", "z"), ("roll", "pitch", "yaw")):
        largest = max(v for k, v in peak.items() if k.split("/")[2] in kind)
        for key, v in peak.items():
            d, seg, dof = key.split("/")
            if dof not in kind or seg not in ("pelvis", "trunk", "head"):
                continue
            assert (v < 1e-6 * largest) == _zero_by_symmetry(key), (key, v / largest)
