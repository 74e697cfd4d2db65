"""Sweeps: spec validation, run expansion (grids, bodies, seats, seeded Monte
Carlo), real runs on a local process pool and on a Dask cluster, failures,
resume and Ctrl-C."""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from ehm_drake.analysis.formats import read_frf
from ehm_drake.sweep import (
    BODY_PRESETS,
    SweepSpecError,
    add_sweep_arguments,
    cmd_sweep,
    default_params_dict,
    expand_runs,
    load_sweep_spec,
    main,
    run_sweep,
)

#: Module fixtures: the module's tests stay on one xdist worker (built once).
pytestmark = pytest.mark.xdist_group("sweep")

#: Short runs: 0.5 s settle (the default variant starts from the equilibrium),
#: 3 s of vibration with a 0.5 s onset.
SHORT = {
    "duration": 3.0,
    "rms": 0.5,
    "direction": "z",
    "params": {"simulation": {"settle_time_s": 0.5, "onset_time_s": 0.5}},
}
#: Head-in-space gains (N m/rad): the packaged ones and 20% more.
GOOD_KP = [[20.0, 20.0, 12.0], [24.0, 24.0, 14.4]]
#: The head-in-space feedback is explicit on both designs: a gain of 1e6
#: N m/rad on the head (inertia ~0.02 kg m^2: omega h ~ 35 > 2 at the implicit
#: design's 5 ms step) diverges within a few steps.
DIVERGING_KP = [1e6, 1e6, 1e6]


def spec_with(**over):
    d = json.loads(json.dumps(SHORT))
    d.update(over)
    return d


# ---------------------------------------------------------------------------
# Spec validation (no simulation)
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("spec, message", [
    ({"durations": 3}, r"unknown key\(s\): durations"),
    ({"direction": "w"}, r"direction must be one of x, y, z, xyz, got 'w'"),
    ({"rms": 194.1}, r"rms 194.1 m/s\^2 is beyond"),
    ({"excitation": "csv"}, r"a measured csv cannot be swept"),
    ({"variant": "stiff"}, r"variant must be one of"),
    ({"seed": -1}, r"seed must be an integer >= 0"),
    ({"params": {"contact": {"pelvis_pan": {"stiffnes": 1}}}},
     r"unknown parameter key: params.contact.pelvis_pan.stiffnes"),
    ({"params": {"contact": {"pelvis_pan": {"stiffness": -1.0}}}},
     r"params: contact.pelvis_pan.stiffness = -1.0: must not be negative"),
    ({"grid": {"contact.pelvis_pan.stiff": [1, 2]}},
     r"grid: 'contact.pelvis_pan.stiff' is not a parameter path \(no 'stiff' under "
     r"contact.pelvis_pan"),
    ({"grid": {"contact.pelvis_pan": [1, 2]}}, r"'contact.pelvis_pan' is a parameter group"),
    ({"grid": {"contact.pelvis_pan.stiffness": []}}, r"expected a non-empty list"),
    ({"grid": {"contact.pelvis_pan.stiffness": [3e4, 30000]}},
     r"grid\['contact.pelvis_pan.stiffness'\]\[1\]: duplicate value"),
    ({"grid": {"contact.pelvis_pan.stiffness": [3e4, -5.0]}},
     r"grid\['contact.pelvis_pan.stiffness'\]\[1\] = -5.0: .*must not be negative"),
    ({"grid": {"pid.neck.kd": [[1, 2]]}},
     r"grid\['pid.neck.kd'\]\[0\] = \[1, 2\]: pid.neck.kd: expected a list of 3"),
    ({"grid": {"rms": [0.2, "high"]}}, r"grid\['rms'\]\[1\]: rms must be a positive"),
    ({"grid": {"body.weight": [60]}}, r"unknown body measure 'body.weight'"),
    ({"body": "tall"}, r"body: unknown body preset 'tall'"),
    ({"body": [{"mass_kg": 75, "stature_m": 176}]},
     r"body\[0\]: stature_m=176.0 m is outside .* looks like centimetres"),
    ({"body": [{"mass_kg": 75}]}, r"body\[0\]: missing stature_m"),
    ({"seat": {"pid.neck.kp": [1, 2]}}, r"seat keys are contact.\* or restraints.\*"),
    ({"seat": [{"name": "a"}, {"name": "a"}]}, r"seat\[1\].name: duplicate seat name 'a'"),
    ({"seat": [{"restraints.pelvis_pan.force_limit": 0.0}]},
     r"seat\[0\]: restraints.pelvis_pan.force_limit must be positive"),
    ({"grid": {"contact.pelvis_pan.stiffness": [1e4]},
      "seat": {"contact.pelvis_pan.stiffness": [2e4]}}, r"also swept in grid"),
    ({"monte_carlo": {"n": 3, "vary": {"rms": {"dist": "normal", "rel_sd": 0.1}}}},
     r"monte_carlo.seed: missing"),
    ({"monte_carlo": {"n": 0, "seed": 1, "vary": {}}}, r"monte_carlo.n: expected an integer"),
    ({"monte_carlo": {"n": 3, "seed": 1, "vary": {"rms": {"dist": "gamma"}}}},
     r"monte_carlo.vary\['rms'\].dist: expected one of normal, lognormal, uniform"),
    ({"monte_carlo": {"n": 3, "seed": 1, "vary": {"rms": {"dist": "normal", "rel": 0.1}}}},
     r"dist normal takes rel_sd or sd, got rel"),
    ({"monte_carlo": {"n": 3, "seed": 1, "vary": {"contact.model": {"dist": "normal",
                                                                     "sd": 1}}}},
     r"contact.model is not numeric"),
    ({"monte_carlo": {"n": 3, "seed": 1, "vary": {"seed": {"dist": "normal", "sd": 1}}}},
     r"only numeric settings"),
    ({"monte_carlo": {"n": 3, "seed": 1, "vary": {"rms": {"dist": "uniform", "low": 2,
                                                           "high": 1}}}},
     r"low \(2\) must be below high \(1\)"),
    ({"analysis": {"peak_band_hz": [5, 1]}}, r"analysis.peak_band_hz: expected \[low, high\]"),
])
def test_spec_errors_name_the_key(spec, message):
    with pytest.raises(SweepSpecError, match=message):
        load_sweep_spec(spec)


def test_spec_files(tmp_path):
    (tmp_path / "p.yaml").write_text("contact:\n  pelvis_pan: {stiffness: 5.0e+4}\n")
    (tmp_path / "s.yaml").write_text(
        "name: files\nparams_file: p.yaml\ngrid:\n  contact.thighs_pan.stiffness: [3e4, 4e4]\n")
    spec = load_sweep_spec(tmp_path / "s.yaml")
    assert spec.grid == {"contact.thighs_pan.stiffness": [30000.0, 40000.0]}  # 3e4 is a number
    assert spec.params == {"contact": {"pelvis_pan": {"stiffness": 50000.0}}}
    runs = expand_runs(spec)
    assert [r.params["contact"]["pelvis_pan"]["stiffness"] for r in runs] == [5e4, 5e4]
    # The same spec as JSON or as a dict gives the same runs.
    (tmp_path / "s.json").write_text(json.dumps(spec.to_dict()))
    assert [r.run_id for r in expand_runs(tmp_path / "s.json")] == [r.run_id for r in runs]
    (tmp_path / "bad.yaml").write_text("grid: {rms: [0.2, 0.2]}\n")
    with pytest.raises(SweepSpecError, match=r"bad.yaml: grid\['rms'\]\[1\]: duplicate"):
        load_sweep_spec(tmp_path / "bad.yaml")
    with pytest.raises(SweepSpecError, match="sweep spec not found"):
        load_sweep_spec(tmp_path / "missing.yaml")
    (tmp_path / "broken.yaml").write_text("grid: [\n")
    with pytest.raises(SweepSpecError, match="not valid YAML"):
        load_sweep_spec(tmp_path / "broken.yaml")


# ---------------------------------------------------------------------------
# Expansion
# ---------------------------------------------------------------------------


def test_grid_bodies_and_seats_expand_to_the_product():
    spec = {
        "body": ["small", "median", "large"],
        "grid": {"contact.pelvis_pan.stiffness": [30000, 45000, 60000], "rms": [0.2, 0.5]},
        "seat": [{"name": "soft", "contact.thighs_pan.stiffness": 20000.0},
                 {"name": "firm", "contact.thighs_pan.stiffness": 80000.0,
                  "restraints.pelvis_pan.stiffness": 40000.0}],
    }
    runs = expand_runs(spec)
    assert len(runs) == 3 * 3 * 2 * 2
    assert len({r.run_id for r in runs}) == len(runs)
    assert [r.index for r in runs] == list(range(36))
    last = runs[-1]
    assert last.swept == {"body": "large", "contact.pelvis_pan.stiffness": 60000,
                          "rms": 0.5, "seat": "firm"}
    assert last.body == {"mass_kg": 98.0, "stature_m": 1.87, "sitting_height_m": None}
    assert last.settings["rms"] == 0.5
    assert last.params["contact"]["pelvis_pan"]["stiffness"] == 60000.0
    assert last.params["contact"]["thighs_pan"]["stiffness"] == 80000.0
    assert last.params["restraints"]["pelvis_pan"]["stiffness"] == 40000.0
    first = runs[0]
    assert first.body["mass_kg"] == BODY_PRESETS["small"]["mass_kg"]
    assert first.params["restraints"]["pelvis_pan"] == \
        default_params_dict()["restraints"]["pelvis_pan"]
    # Stable ids: same inputs -> same id, whatever the spelling of the numbers.
    again = expand_runs(json.loads(json.dumps(spec).replace("30000", "30000.0")))
    assert [r.run_id for r in again] == [r.run_id for r in runs]
    # The plain spec: one run of the median body with the defaults.
    (only,) = expand_runs({})
    assert only.swept == {}
    assert only.body == BODY_PRESETS["median"]
    assert only.params == default_params_dict()


def test_design_follows_the_simulate_command():
    """`design: auto` is the implicit design unless the spec states the parameters'
    design or step (anywhere a parameter can be set), which are then kept."""
    (plain,) = expand_runs({})
    assert plain.settings["design"] == "implicit"
    assert plain.params["simulation"]["design"] == "reference"  # (the file's, switched at run)
    stated = [{"params": {"simulation": {"time_step_s": 0.0005}}},
              {"grid": {"simulation.time_step_s": [0.001, 0.0005]}},
              {"seat": [{"name": "a", "contact.pelvis_pan.stiffness": 9e4}]},
              {"params": {"simulation": {"design": "implicit", "time_step_s": 0.0025}}}]
    designs = [{r.settings["design"] for r in expand_runs(s)} for s in stated]
    # A seat configuration names no step: the default design.
    assert designs == [{"reference"}, {"reference"}, {"implicit"}, {"implicit"}]
    named = expand_runs({"design": "reference", "grid": {"design": ["implicit", "auto"]}})
    assert [r.settings["design"] for r in named] == ["implicit", "implicit"]
    (ref,) = expand_runs({"design": "reference"})
    assert ref.settings["design"] == "reference" and ref.run_id != plain.run_id
    with pytest.raises(SweepSpecError, match="design must be one of auto, implicit, reference"):
        load_sweep_spec({"design": "fast"})


def test_monte_carlo_is_seeded_and_reproducible():
    def spec(n, seed, **vary):
        return {"grid": {"rms": [0.2, 0.4]},
                "monte_carlo": {"n": n, "seed": seed, "vary": vary or {
                    "contact.pelvis_pan.stiffness": {"dist": "normal", "rel_sd": 0.1},
                    "pid.neck.kp": {"dist": "lognormal", "rel_sd": 0.3},
                    "body.mass_kg": {"dist": "uniform", "rel_range": 0.2}}}}

    runs = expand_runs(spec(200, 1))
    assert len(runs) == 2 * 200
    assert [r.run_id for r in expand_runs(spec(200, 1))] == [r.run_id for r in runs]
    other = expand_runs(spec(200, 2))
    assert not {r.run_id for r in other} & {r.run_id for r in runs}
    # More samples keep the first ones.
    assert [r.run_id for r in expand_runs(spec(5, 1))] == \
        [r.run_id for r in runs[:5]] + [r.run_id for r in runs[200:205]]
    base = default_params_dict()
    k0 = base["contact"]["pelvis_pan"]["stiffness"]
    first = runs[:200]
    # Every grid point sees the same population (common random numbers).
    assert [r.swept["mc:contact.pelvis_pan.stiffness"] for r in first] == \
        [r.swept["mc:contact.pelvis_pan.stiffness"] for r in runs[200:]]
    assert [r.swept["rms"] for r in runs[199:201]] == [0.2, 0.4]
    assert [r.swept["mc_sample"] for r in first] == list(range(200))
    k = np.array([r.params["contact"]["pelvis_pan"]["stiffness"] for r in first]) / k0
    assert abs(np.mean(k) - 1) < 0.03 and abs(np.std(k) - 0.1) < 0.02
    kp0 = np.array(base["pid"]["neck"]["kp"])
    kp = np.array([r.params["pid"]["neck"]["kp"] for r in first]) / kp0
    assert np.all(kp > 0)
    np.testing.assert_allclose(kp, kp[:, :1] * np.ones(3))  # one draw for the vector
    assert abs(np.mean(kp[:, 0]) - 1) < 0.08 and abs(np.std(kp[:, 0]) - 0.3) < 0.08
    m = np.array([r.body["mass_kg"] for r in first]) / BODY_PRESETS["median"]["mass_kg"]
    assert np.all((m >= 0.8) & (m <= 1.2)) and np.ptp(m) > 0.3
    # A draw outside the body scaling is a run (that will fail), not a spec error.
    wild = expand_runs(spec(2, 0, **{"body.mass_kg": {"dist": "uniform", "low": 200,
                                                      "high": 210}}))
    assert all(200 <= r.body["mass_kg"] <= 210 for r in wild)


# ---------------------------------------------------------------------------
# Real sweeps
# ---------------------------------------------------------------------------


def local_spec():
    return spec_with(name="his-gains", grid={"his.kp": [*GOOD_KP, DIVERGING_KP]})


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "out"
    t0 = time.perf_counter()
    result = run_sweep(local_spec(), out, max_workers=2, progress=False)
    return result, out, time.perf_counter() - t0


def test_local_sweep_records_runs_and_failures(local_sweep):
    result, out, _ = local_sweep
    assert [r["status"] for r in result.records] == ["done", "done", "failed"]
    assert result.n_done == 2 and result.n_failed == 1 and not result.interrupted
    assert sorted(result.computed) == sorted(r.run_id for r in result.runs)
    good, _, bad = result.records
    assert bad["error"]["type"] == "SimulationDiverged"
    assert "diverged" in bad["error"]["message"] and bad["error"]["source"] == "run"
    for run, rec in zip(result.runs, result.records, strict=True):
        stored = json.loads((out / "runs" / f"{run.run_id}.json").read_text())
        assert stored["status"] == rec["status"] and stored["run_id"] == run.run_id
        assert stored["inputs"]["params"]["pid"]["neck"]["kp"] == run.params["pid"]["neck"]["kp"]
        assert stored["inputs"]["settings"]["duration"] == 3.0
        assert stored["pid"] != os.getpid()  # computed in a worker process
    res = good["results"]
    peaks = res["transmissibility"]
    assert set(peaks) == {f"z/{s}/{d}" for s in ("pelvis", "trunk", "head")
                          for d in ("z", "pitch")}
    for p in peaks.values():
        assert 0.5 <= p["peak_freq_hz"] <= 12.0 and p["peak_gain"] > 0
    # Seat vertical vibration: 0.5 m/s^2 RMS in z only; Wk weighting of the
    # 0.1-12 Hz noise keeps 60-90 % of it.
    seat = res["comfort"]["seat"]
    assert 0.3 < seat["weighted_rms"]["z"] < 0.5
    assert seat["weighted_rms"]["x"] < 1e-9 and seat["weighted_rms"]["y"] < 1e-9
    head = res["comfort"]["head"]
    assert head["weighted_rms"]["z"] > 0.1 and head["weighted_rms"]["x"] > 1e-4
    assert res["posture"]["back_in_contact"] is True
    assert res["wall_s"] > res["vibrate_wall_s"] > 0
    # The default design, at the step chosen by accuracy for the default body.
    assert res["design"] == "implicit" and res["time_step_s"] == pytest.approx(0.005)
    frf = read_frf(out / "runs" / f"{result.runs[0].run_id}.frf.csv")
    f, gain, _, _ = frf.get("z", "head", "z")
    assert np.max(gain[(f >= 0.5) & (f <= 12)]) == pytest.approx(peaks["z/head/z"]["peak_gain"],
                                                                 rel=1e-6)
    # Summary files: one row per run, the swept value and key results.
    lines = (out / "summary.csv").read_text().splitlines()
    header = lines[0].split(",")
    assert len(lines) == 4
    assert header[:4] == ["run_id", "index", "status", "his.kp"]
    assert {"seat_aw_overall", "head_aw_overall", "T_z_head_z_peak_gain",
            "error_type"} <= set(header)
    assert lines[3].startswith(f"{result.runs[2].run_id},2,failed,")
    assert "SimulationDiverged" in lines[3]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"] == {"runs": 3, "unique_runs": 3, "done": 2, "failed": 1,
                                 "pending": 0, "computed": 3, "reused": 0}
    assert summary["runs"][2]["error"]["type"] == "SimulationDiverged"
    assert load_sweep_spec(json.loads((out / "sweep_spec.json").read_text())).grid == \
        load_sweep_spec(local_spec()).grid


def test_resume_recomputes_only_missing_runs(local_sweep, tmp_path):
    result, out, _ = local_sweep
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    runs_dir = copy / "runs"
    lost = result.runs[1].run_id
    (runs_dir / f"{lost}.json").unlink()
    kept = {p.name: p.stat().st_mtime_ns for p in runs_dir.iterdir()}
    again = run_sweep(local_spec(), copy, max_workers=1, progress=False)
    assert again.computed == [lost]
    assert sorted(again.reused) == sorted(r.run_id for r in result.runs if r.run_id != lost)
    assert [r["status"] for r in again.records] == ["done", "done", "failed"]
    for name, mtime in kept.items():
        if not name.startswith(lost):
            assert (runs_dir / name).stat().st_mtime_ns == mtime, name
    # Deterministic: the recomputed run has the results of the lost one.
    new = json.loads((runs_dir / f"{lost}.json").read_text())
    assert new["results"]["transmissibility"] == result.records[1]["results"]["transmissibility"]
    assert new["results"]["comfort"] == result.records[1]["results"]["comfort"]
    summary = json.loads((copy / "summary.json").read_text())
    assert summary["counts"]["computed"] == 1 and summary["counts"]["reused"] == 2


def test_dask_cluster_runs_the_same_sweep(local_sweep, tmp_path):
    distributed = pytest.importorskip("distributed")
    result, _, _ = local_sweep
    spec = spec_with(name="his-gains", grid={"his.kp": GOOD_KP})
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as cluster:
        dask_result = run_sweep(spec, tmp_path / "dask", scheduler=cluster.scheduler_address,
                                progress=False)
        worker_pids = {w.pid for w in cluster.workers.values()}
    assert [r["status"] for r in dask_result.records] == ["done", "done"]
    assert {r["pid"] for r in dask_result.records} <= worker_pids
    # Same inputs, same run ids and the same numbers as on the local pool.
    local = {r["run_id"]: r for r in result.records}
    for rec in dask_result.records:
        ref = local[rec["run_id"]]["results"]
        assert rec["results"]["transmissibility"] == ref["transmissibility"]
        assert rec["results"]["comfort"] == ref["comfort"]


def test_ctrl_c_keeps_finished_runs(tmp_path):
    spec_path = tmp_path / "spec.json"
    spec_path.write_text(json.dumps(spec_with(
        grid={"contact.pelvis_pan.stiffness": [40000.0, 50000.0, 55000.0]})))
    out = tmp_path / "out"
    # Ctrl-C as at a terminal: a test run started in the background (as CI may be) hands
    # SIGINT down as ignored, and Python then keeps ignoring it; restore the default.
    proc = subprocess.Popen([sys.executable, "-m", "ehm_drake.sweep", str(spec_path), "--out",
                             str(out), "--workers", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 120
        while not (out / "runs").is_dir() or not list((out / "runs").glob("*.json")):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no run finished in 120 s"
            time.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True
    counts = summary["counts"]
    # The finished run and the one running at Ctrl-C are kept; the last was never started.
    assert 1 <= counts["done"] <= 2 and counts["done"] + counts["pending"] == 3
    assert counts["failed"] == 0
    stored = [json.loads(p.read_text()) for p in (out / "runs").glob("*.json")]
    assert len(stored) == counts["done"] and all(s["status"] == "done" for s in stored)
    assert "1 not run" in stdout or "2 not run" in stdout


# ---------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------


def test_cli_wiring_and_errors(tmp_path, capsys):
    parser = argparse.ArgumentParser(prog="ehm-drake")
    sub = parser.add_subparsers(dest="command", required=True)
    add_sweep_arguments(sub)
    args = parser.parse_args(["sweep", "spec.yaml", "--out", "d", "--workers", "3", "--force"])
    assert args.func is cmd_sweep and args.workers == 3 and args.force and args.scheduler is None
    with pytest.raises(SystemExit):
        parser.parse_args(["sweep", "spec.yaml", "--out", "d", "--workers", "0"])
    capsys.readouterr()
    # A non-empty folder that holds no sweep is refused without --force.
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    spec = tmp_path / "s.json"
    spec.write_text(json.dumps(SHORT))
    with pytest.raises(ValueError, match="holds no sweep; use --force"):
        cmd_sweep(parser.parse_args(["sweep", str(spec), "--out", str(tmp_path / "other")]))
    # Spec errors end with a one-line message and status 2.
    spec.write_text(json.dumps({"grid": {"contact.pelvis_pan.stiff": [1]}}))
    assert main([str(spec), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "sweep: error:" in err and "'contact.pelvis_pan.stiff' is not a parameter path" in err
    assert not (tmp_path / "o").exists()
