"""Command line interface: `ehm-drake <command> ...`.

Commands
--------
simulate          settle, vibrate, write time series, transmissibility, plots
modes             linearize the closed loop: modes, shapes, participation, linear FRF
fit               identify parameters from measured transmissibility
sweep             batch runs (parameters, anthropometry, seats, Monte Carlo)
transmissibility  estimate frf.csv (+ figures) from a simulation or lab folder
comfort           ISO 2631-1 comfort metrics of a simulation or lab folder
diagnose          sim-to-real gap: where it lies, which unmodelled effect, how much it shrinks
synth             lab-like data from the model with hidden effects (truth to a key file)
blind             blind check of diagnose on synthetic trials
validate          the model against published facts (and a lab's datasets)

Errors in the input (parameter files, arguments, data) end the program with
a one-line message and exit status 2; a simulation that blows up, with
status 3.  Nothing is written over an existing output folder unless
`--force` is given.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from .cli_common import (
    UsageError,
    add_design_arguments,
    int_at_least,
    positive_float,
    preloaded_libraries,
    prepare_output_dir,
)
from .gap.commands import add_gap_arguments
from .model.anthropometry import REFERENCE, BodyMeasures
from .params import (
    IMPLICIT_TIME_STEP_S,
    VARIANTS,
    ParameterError,
    command_design,
    load_params,
)
from .signals import KINDS, PAPER_RMS, SignalError
from .sweep import add_sweep_arguments
from .validation.command import add_validate_arguments
from .viz import add_viz_arguments, handle_viz


def _measures(args) -> BodyMeasures:
    if args.mass is None and args.stature is None and args.sitting_height is None:
        return REFERENCE
    m = BodyMeasures(
        mass_kg=args.mass if args.mass is not None else REFERENCE.mass_kg,
        stature_m=args.stature if args.stature is not None else REFERENCE.stature_m,
        sitting_height_m=args.sitting_height,
    )
    m.validate()
    return m


# ---------------------------------------------------------------------------
# simulate
# ---------------------------------------------------------------------------


def _add_model_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--variant", choices=VARIANTS, default="default",
                   help="model variant of the paper (default: %(default)s)")
    p.add_argument("--params", metavar="FILE", help="parameter file (YAML/JSON), merged over "
                   "the defaults; a fit's output is accepted; or a packaged configuration: "
                   "car_seat (default), rigid_seat, rigid_seat_backrest, paper_linear")
    p.add_argument("--mass", type=positive_float("--mass"), metavar="KG", help="body mass (kg)")
    p.add_argument("--stature", type=positive_float("--stature"), metavar="M",
                   help="stature (m)")
    p.add_argument("--sitting-height", type=positive_float("--sitting-height"), metavar="M",
                   help="sitting height (m); default scales with stature")
    p.add_argument("--contact", choices=("point", "hydroelastic"),
                   help="contact model (default: from the parameters, point)")
    add_design_arguments(p)


def _load_model_params(args, simulates: bool = True):
    """The parameters of `simulate`, `modes` and `fit`: the file's (or the
    packaged defaults), on the design `params.command_design` chooses.
    `simulates`: the command runs in the time domain, where the implicit
    design is about three times faster (said when a file keeps the other)."""
    from .diagram import on_design

    params = load_params(args.params)
    if getattr(args, "contact", None):
        params.contact.model = args.contact
    design = command_design(args.params, getattr(args, "design", None))
    step = getattr(args, "time_step", None)
    by_accuracy = (design == "implicit" and params.simulation.design != "implicit"
                   and step is None)
    params = on_design(params, design, step, _measures(args), args.variant,
                       getattr(args, "output_every", None))
    quiet = getattr(args, "quiet", False)
    if by_accuracy and not quiet and params.simulation.time_step_s < IMPLICIT_TIME_STEP_S:
        print(f"implicit design: time step {params.simulation.time_step_s * 1e3:.3g} "
              f"ms, the largest that keeps the {args.variant} model second-order "
              "accurate (--time-step sets another)", file=sys.stderr)
    if simulates and design is None and params.simulation.design == "reference" and not quiet:
        # The file chose the paper's slower design (a fit's output states it).
        print(f"reference design at {params.simulation.time_step_s * 1e3:g} ms, as "
              f"{args.params} states (--design implicit runs the faster design)",
              file=sys.stderr)
    return params


def cmd_simulate(args) -> int:
    from .analysis.figures import plot_cases
    from .diagram import build_diagram
    from .plots import plot_posture, plot_responses
    from .signals import make_seat_signal
    from .simulation import SettledState, settle, vibrate

    if args.excitation == "csv" and not args.csv:
        raise UsageError("--excitation csv needs --csv FILE (columns t, seat_ax, seat_ay, seat_az)")
    params = _load_model_params(args)
    measures = _measures(args)
    out = prepare_output_dir(args.out, args.force)
    s = params.simulation
    signal = make_seat_signal(
        args.excitation, args.direction, args.rms, args.duration, args.seed, s.time_step_s,
        s.settle_time_s, s.onset_time_s, frequency_hz=args.frequency, csv_path=args.csv)
    progress = not args.quiet
    figures = not args.no_figures
    wall = {}
    t0 = time.perf_counter()
    if args.settled:
        settled = SettledState.load(args.settled)
    else:
        settled = settle(params, measures, args.variant, progress=progress)
    wall["settle"] = time.perf_counter() - t0
    settled.save(out / "settled_state.npz")
    t = time.perf_counter()
    result = vibrate(params, settled, signal, measures, args.variant, progress=progress)
    wall["vibrate"] = time.perf_counter() - t
    handle_viz(args, params, measures, result)
    t = time.perf_counter()
    files = [p.name for p in result.write_csv(out)]
    wall["write"] = time.perf_counter() - t
    model = build_diagram(params, measures, None, args.variant, guard=False)
    summary = _simulate_summary(args, params, measures, signal, settled, result, model)
    frf = None
    if signal.kind != "csv" or signal.meta.get("direction"):
        t = time.perf_counter()
        frf = _transmissibility_outputs(result, signal, out, files, summary)
        wall["analysis"] = time.perf_counter() - t
    if figures:
        t = time.perf_counter()
        ref = model.plant.GetPositions(model.plant.CreateDefaultContext())
        files.append(plot_posture(
            model, {f"settled ({args.variant})": settled.positions,
                    "initial (reference)": ref},
            out / "posture.png", f"Posture after settling, variant {args.variant}").name)
        files.append(plot_responses(result, out / "responses.png").name)
        if frf is not None:
            files += [p.name for p in plot_cases({args.variant: frf}, out)]
        wall["figures"] = time.perf_counter() - t
    wall["total (after imports)"] = time.perf_counter() - t0
    summary["settle_wall_s"] = wall["settle"]
    summary["wall_s"] = wall
    summary["files"] = sorted(files)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    if not args.quiet:
        _print_summary(summary)
    if args.verbose:
        _print_wall(wall, result, s.time_step_s)
    return 0


def _print_wall(wall: dict, result, time_step: float) -> None:
    """--verbose: where the command's time went (wall clock, s), and the
    run's cost per time step."""
    print("wall clock (s): " + ", ".join(f"{k} {v:.2f}" for k, v in wall.items()))
    steps = round(result.meta["simulated_s"] / time_step)
    if steps > 0:
        print(f"vibration run: {1e6 * wall['vibrate'] / steps:.0f} us per time step "
              f"({steps} steps of {1e3 * time_step:g} ms), real-time factor "
              f"{result.meta['real_time_factor']:.2f}")
    if preloaded := preloaded_libraries():
        print(f"preloaded (LD_PRELOAD): {', '.join(preloaded)}")


def _simulate_summary(args, params, measures, signal, settled, result, model) -> dict:
    s = params.simulation
    return {
        "dof": int(model.plant.num_velocities()),
        "segments": len(model.hp.body.segments),
        "mass_kg": float(model.hp.body.total_mass),
        "stature_m": measures.stature_m,
        "sitting_height_m": measures.resolved_sitting_height(),
        "variant": args.variant,
        "contact_model": params.contact.model,
        "design": s.design,
        "time_step_s": s.time_step_s,
        "excitation": signal.meta,
        "seat_rms_measured": dict(zip("xyz", map(float, signal.rms()), strict=True)),
        "real_time_factor": result.meta["real_time_factor"],
        "vibrate_wall_s": result.meta["wall_s"],
        **{k: settled.summary[k] for k in (
            "settle_posture_error_deg", "head_pitch_drift_deg", "head_pitch_deg",
            "trunk_T8_forward_drift_m", "backrest_force_n", "back_in_contact")},
    }


def _transmissibility_outputs(result, signal, out: Path, files: list, summary: dict):
    """frf.csv and apparent_mass.csv of a run, their entries in `summary`;
    returns the FRF."""
    from .analysis.apparent_mass import apparent_mass_table
    from .analysis.transmissibility import transmissibility

    vib = result.after(signal.settle_time)
    frf = transmissibility(vib.to_timeseries())
    frf.to_csv(out / "frf.csv")
    files.append("frf.csv")
    dirs = "".join(d for d in "xyz" if d in signal.meta.get("direction", ""))
    am = apparent_mass_table(vib.seat_acceleration, vib.pan_force(), vib.sample_rate, dirs)
    am.to_csv(out / "apparent_mass.csv")
    files.append("apparent_mass.csv")
    summary.update(transmissibility_peaks=_peaks(frf), static_seated_mass_kg=am.static_mass_kg)
    return frf


def _peaks(frf) -> dict:
    peaks = {}
    for key in frf.channels():
        f, gain, _, _ = frf.get(*key[:3])
        k = int(np.argmax(gain))
        peaks["/".join(key[:3])] = {"peak_gain": float(gain[k]), "peak_freq_hz": float(f[k])}
    return peaks


def _print_summary(summary: dict) -> None:
    print(f"\nEHM seated human, {summary['dof']} DoF, {summary['mass_kg']:.1f} kg, "
          f"variant {summary['variant']}, {summary['design']} design at "
          f"{1e3 * summary['time_step_s']:g} ms, real-time factor "
          f"{summary['real_time_factor']:.2f}")
    e = summary["settle_posture_error_deg"]
    print("settled posture error (deg): " + ", ".join(f"{k} {v:.2f}" for k, v in e.items()))
    print(f"head pitch drift {summary['head_pitch_drift_deg']:.2f} deg, backrest force "
          f"{summary['backrest_force_n']['total']:.0f} N")
    peaks = summary.get("transmissibility_peaks", {})
    if peaks:
        shown = {k: v for k, v in peaks.items()
                 if v["peak_gain"] > 0.05 and not _zero_by_symmetry(k)}
        hidden = sum(v["peak_gain"] > 0.05 and _zero_by_symmetry(k) for k, v in peaks.items())
        print("transmissibility peaks, gain (m/m or deg/m) @ frequency (Hz)"
              + (f"; {hidden} paths zero by the body's left-right symmetry left out (with axes "
                 "excited together their estimates are noise)" if hidden else "") + ":")
        for key, v in shown.items():
            print(f"  {key:24s} {v['peak_gain']:8.3f} @ {v['peak_freq_hz']:5.2f}")


#: Per excited axis, the motions of the midline segments that the body's
#: left-right symmetry makes zero (fore-aft and vertical excite no lateral,
#: roll or yaw motion; lateral excites no fore-aft, vertical or pitch motion).
_ANTISYMMETRIC = {"x": ("y", "roll", "yaw"), "z": ("y", "roll", "yaw"),
                  "y": ("x", "z", "pitch")}
_MIDLINE = ("pelvis", "trunk", "head")


def _zero_by_symmetry(key: str) -> bool:
    """Whether the path "direction/segment/dof" is zero by symmetry."""
    d, seg, dof = key.split("/")
    return seg in _MIDLINE and dof in _ANTISYMMETRIC.get(d, ())


# ---------------------------------------------------------------------------
# transmissibility, comfort
# ---------------------------------------------------------------------------


def _is_c3d(path: str) -> bool:
    p = Path(path)
    return p.suffix.lower() == ".c3d" or (p.is_dir() and any(
        q.suffix.lower() == ".c3d" for q in p.iterdir()))


def cmd_transmissibility(args) -> int:
    from .analysis.figures import plot_cases
    from .analysis.formats import check_units, read_data_dir
    from .analysis.transmissibility import transmissibility

    if args.markers or any(_is_c3d(d) for d in args.data):
        return _transmissibility_c3d(args)
    if len(args.data) > 1:
        raise UsageError("give one simulation or lab folder (several inputs are C3D "
                         "sessions, with --markers)")
    frf, ts = read_data_dir(args.data[0])
    out = prepare_output_dir(args.out, args.force)
    if ts is not None:
        frf = transmissibility(ts)
        source = "timeseries.csv"
    else:
        source = "frf.csv (as given)"
    frf.to_csv(out / "frf.csv")
    for w in check_units(frf):
        print(f"warning: {w}", file=sys.stderr)
    figs = plot_cases({"estimate": frf}, out, measured=None)
    print(f"transmissibility from {source}: {len(frf.channels())} channels, "
          f"{len(np.unique(frf.freq_hz))} frequencies -> {out / 'frf.csv'}, "
          + ", ".join(p.name for p in figs))
    return 0


def _transmissibility_c3d(args) -> int:
    """`transmissibility SESSION.c3d... --markers MAP.yaml`: a lab folder."""
    from .analysis.figures import plot_cases
    from .analysis.formats import check_units
    from .analysis.lab_c3d import REPORT_FILENAME, c3d_lab_folder

    if not args.markers:
        raise UsageError("C3D sessions need --markers MAP.yaml, the lab's marker map (example: "
                         "ehm_drake/data/marker_map_example.yaml)")
    not_c3d = [d for d in args.data if not _is_c3d(d)]
    if not_c3d:
        raise UsageError(f"--markers reads C3D sessions; {not_c3d[0]} is not a .c3d file or "
                         "a folder of them")
    if Path(args.out).exists() and not Path(args.out).is_dir():
        raise UsageError(f"--out {args.out} exists and is not a folder")
    lab = c3d_lab_folder(args.data, args.markers, args.out, args.force,
                         progress=not args.quiet)
    for w in lab.warnings + check_units(lab.frf):
        print(f"warning: {w}", file=sys.stderr)
    figs = plot_cases({"estimate": lab.frf}, lab.out, measured=None)
    for t, r in zip(lab.tests, lab.reports, strict=True):
        worst = max(r["clusters"].items(), key=lambda kv: kv[1]["residual_max_mm"])
        filled = sum(c["frames_filled"] for c in r["clusters"].values())
        print(f"{t['c3d']}: {t['direction']} @ {t['level_rms']:g} m/s^2, {t['duration_s']:.1f} "
              f"s at {r['point_rate_hz']:g} Hz; cluster residual up to "
              f"{worst[1]['residual_max_mm']:.2f} mm ({worst[0]}); {filled} cluster-frames "
              "filled")
    print(f"-> {lab.out}: frf.csv ({len(lab.frf.channels())} channels), tests.json, "
          f"{REPORT_FILENAME}, " + ", ".join(sorted({str(Path(t['timeseries']).parent) + '/'
                                                    for t in lab.tests}))
          + ", " + ", ".join(p.name for p in figs))
    return 0


def _acceleration_from_displacement(t, d):
    """Second central difference of displacement (m) -> acceleration (m/s^2)."""
    dt = float(np.median(np.diff(t)))
    a = np.zeros_like(d)
    a[1:-1] = (d[2:] - 2 * d[1:-1] + d[:-2]) / dt**2
    a[0], a[-1] = a[1], a[-2]
    return a


def cmd_comfort(args) -> int:
    from .analysis.comfort import comfort_metrics
    from .analysis.formats import read_data_dir

    _, ts = read_data_dir(args.data)
    if ts is None:
        raise UsageError(f"{args.data}: comfort needs timeseries.csv (seat acceleration)")
    out = Path(args.out) if args.out else Path(args.data)
    target = out / "comfort.json"
    if target.exists() and not args.force:
        raise UsageError(f"{target} exists; use --force to replace it")
    out.mkdir(parents=True, exist_ok=True)
    report = {"seat": _comfort_entry(comfort_metrics(ts.seat_acc, ts.fs, "seat"))}
    head = [f"head_{a}" for a in "xyz"]
    if all(h in ts.channels for h in head):
        acc = _acceleration_from_displacement(
            ts.t, np.column_stack([ts.channels[h] for h in head]))
        report["head"] = _comfort_entry(comfort_metrics(acc, ts.fs, "head"))
        report["head"]["note"] = ("from the absolute head displacement (second difference); "
                                  "seat weightings (Wd x, y; Wk z), factors 1")
    target.write_text(json.dumps(report, indent=2))
    print(f"{'':6s} {'a_w x':>8s} {'a_w y':>8s} {'a_w z':>8s} {'overall':>8s} "
          f"{'VDV z':>8s} {'MSDV z':>8s}   (m/s^2, m/s^1.75, m/s^1.5)")
    for loc, m in report.items():
        w = m["weighted_rms"]
        print(f"{loc:6s} {w['x']:8.4f} {w['y']:8.4f} {w['z']:8.4f} {m['overall']:8.4f} "
              f"{m['vdv']['z']:8.4f} {m['msdv_z']:8.4f}")
    print(f"-> {target}")
    return 0


def _comfort_entry(m: dict) -> dict:
    keep = ("weighted_rms", "overall", "vdv", "mtvv", "crest_factor", "msdv_z", "weightings", "k")
    return {k: m[k] for k in keep if k in m}


# ---------------------------------------------------------------------------
# modes
# ---------------------------------------------------------------------------

def cmd_modes(args) -> int:
    from .analysis.figures import plot_cases
    from .analysis.linear import default_frequencies, linearize
    from .diagram import build_diagram
    from .plots import plot_mode_shapes, plot_poles

    params = _load_model_params(args, simulates=False)
    measures = _measures(args)
    out = prepare_output_dir(args.out, args.force)
    t0 = time.perf_counter()
    model = build_diagram(params, measures, None, args.variant, guard=False)
    lm = linearize(model, method=args.method)
    modes = lm.modes()
    wall = time.perf_counter() - t0
    (out / "modes.json").write_text(json.dumps([m.to_dict() for m in modes], indent=1))
    f = default_frequencies()
    frf = lm.transmissibility(f)
    frf.to_csv(out / "frf_linear.csv")
    participation = []
    from .systems.outputs import PAPER_CHANNELS

    for d, channels in PAPER_CHANNELS.items():
        for seg, dof in channels:
            ff, gain, _, _ = frf.get(d, seg, dof)
            k = int(np.argmax(gain))
            top = lm.participation(d, f"{seg}_{dof}", float(ff[k]))
            participation.append({
                "direction": d, "segment": seg, "dof": dof, "peak_freq_hz": float(ff[k]),
                "peak_gain": float(gain[k]),
                "modes": [{"index": m.index, "freq_hz": m.freq_hz, "label": m.label,
                           "share": share} for m, share in top]})
    (out / "participation.json").write_text(json.dumps(participation, indent=1))
    rows = ["| # | f (Hz) | zeta | kind | mode |", "|---|---|---|---|---|"]
    rows += [f"| {m.index} | {m.freq_hz:.3f} | {m.damping_ratio:.3f} | {m.kind} | {m.label} |"
             for m in modes if m.kind != "slip" and m.freq_hz <= args.max_freq]
    nslip = sum(m.kind == "slip" for m in modes)
    rows.append(f"\n{nslip} slip-anchor states (z = 1, static, uncontrollable) not tabulated; "
                "see modes.json.")
    (out / "modal_table.md").write_text("\n".join(rows) + "\n")
    shown = [m for m in modes if m.kind in ("oscillatory", "unstable")
             and 0.3 < m.freq_hz <= 12.0][:12]
    figs = [plot_mode_shapes(model, lm, shown, out / "mode_shapes.png").name,
            plot_poles(modes, out / "poles.png").name]
    figs += [p.name for p in plot_cases({f"linear ({args.variant})": frf}, out,
                                        prefix="transmissibility_linear")]
    unstable = [m for m in modes if m.kind == "unstable"]
    print(f"linearized ({lm.method}, {lm.A.shape[0]} states) and analysed in {wall:.2f} s; "
          f"{'UNSTABLE' if unstable else 'stable'}")
    for m in modes:
        if m.kind in ("oscillatory", "unstable") and m.freq_hz <= args.max_freq:
            print(f"  {m.freq_hz:7.3f} Hz  zeta {m.damping_ratio:6.3f}  {m.label}")
    for m in unstable:
        print(f"unstable mode {m.index}: {m.label}, growth rate {m.s.real:.2f} 1/s at "
              f"{m.freq_hz:.2f} Hz", file=sys.stderr)
    print(f"-> {out}: modes.json, frf_linear.csv, participation.json, modal_table.md, "
          + ", ".join(figs))
    return 3 if unstable else 0


# ---------------------------------------------------------------------------
# fit
# ---------------------------------------------------------------------------


def _excitation_of(data: str, ts) -> str:
    """How a data folder was recorded: ``simultaneous`` when its simulation
    summary or its seat record has more than one excited axis, else
    ``separate`` (one axis per test, as lab folders hold)."""
    summary = Path(data) / "summary.json"
    if summary.is_file():
        try:
            direction = json.loads(summary.read_text()).get("excitation", {}).get("direction")
        except (ValueError, AttributeError):
            direction = None
        if isinstance(direction, str):
            return "simultaneous" if len(direction) > 1 else "separate"
    if ts is not None:
        rms = np.sqrt(np.mean(np.square(ts.seat_acc), axis=0))
        if np.sum(rms > 0.05 * rms.max()) > 1:
            return "simultaneous"
    return "separate"


def cmd_fit(args) -> int:
    from .analysis.formats import read_data_dir
    from .analysis.transmissibility import transmissibility
    from .identification.fit import fit, load_weights, write_outputs
    from .identification.verify import safe_parameters, verify_time_domain
    from .params import save_params

    frf, ts = read_data_dir(args.data)
    if frf is None:
        frf = transmissibility(ts)
    start = _load_model_params(args)
    measures = _measures(args)
    weights = load_weights(args.weights)
    out = prepare_output_dir(args.out, args.force)
    excitation = args.excitation if args.excitation != "auto" else _excitation_of(args.data, ts)
    result = fit(frf, start, args.free, weights, args.holdout, measures, args.variant,
                 workers=args.workers, progress=not args.quiet, excitation=excitation)
    report = result.report
    files = write_outputs(result, frf, out)
    if result.interrupted:
        print(f"interrupted: the best parameters so far are in {out / 'params.yaml'}",
              file=sys.stderr)
        return 130
    if not args.no_verify:
        params, frac, verification = safe_parameters(
            result, frf, verify_time_domain, measures=measures, variant=args.variant,
            duration=args.verify_duration, timeseries=ts, progress=not args.quiet)
        verification["step_fraction_kept"] = frac
        report["verification"] = verification
        if frac < 1.0:
            report["warnings"].append(
                f"the fitted parameters failed the time-domain check "
                f"({verification.get('reason', 'see verification')}); params.yaml holds "
                f"{'the start' if frac == 0 else f'{frac:g} of the log-step'} instead")
            save_params(params, out / "params.yaml")
        (out / "fit_report.json").write_text(json.dumps(report, indent=1))
    print(f"fit of {len(report['free'])} parameters to {report['data_rows_used']} rows in "
          f"{report['fit_wall_s']:.1f} s ({report['n_model_evaluations']} model evaluations): "
          f"cost {report['cost_before']:.4g} -> {report['cost_after']:.4g}, RMS gain error "
          f"{100 * report['gain_error_before']:.1f}% -> {100 * report['gain_error_after']:.1f}%")
    if "heldout_error" in report:
        print(f"held-out ({args.holdout}) RMS gain error {100 * report['heldout_error']:.1f}% "
              f"(before {100 * report['heldout_error_before']:.1f}%)")
    for p in report["parameters"]:
        flag = "" if p["identifiable"] else "  (not determined by the data)"
        print(f"  {p['name']:26s} {p['start']:10.4g} -> {p['fitted']:10.4g} {p['unit']:9s} "
              f"+/- {100 * p['rel_std_error']:.1f}%{flag}")
    if "verification" in report:
        v = report["verification"]
        print(f"time-domain verification: {'passed' if v['passed'] else 'FAILED'}; "
              + ", ".join(f"{d}: {100 * e['rms_log_gain_error']:.1f}% RMS gain error"
                          for d, e in v["directions"].items() if e.get("rms_log_gain_error")))
    for w in report["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    print(f"-> {out}: " + ", ".join(files))
    return 0


# ---------------------------------------------------------------------------
# main
# ---------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ehm-drake", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("simulate", help="settle, vibrate, transmissibility and plots")
    p.add_argument("--direction", choices=("x", "y", "z", "xyz"), default="z",
                   help="excited seat axis (xyz: simultaneous, independent)")
    p.add_argument("--rms", type=positive_float("--rms"), default=PAPER_RMS, metavar="A",
                   help="seat acceleration RMS per axis, m/s^2 (paper: %(default)s)")
    p.add_argument("--duration", type=positive_float("--duration"), default=60.0, metavar="S",
                   help="vibration time after settling, s (default %(default)s)")
    p.add_argument("--seed", type=int_at_least(0), default=0, metavar="N",
                   help="random seed of the excitation")
    p.add_argument("--excitation", choices=KINDS, default="random",
                   help="signal type (default random 0.1-12 Hz)")
    p.add_argument("--frequency", type=positive_float("--frequency"), default=4.0, metavar="HZ",
                   help="frequency of --excitation sine")
    p.add_argument("--csv", metavar="FILE", help="measured seat acceleration for "
                   "--excitation csv (columns t, seat_ax, seat_ay, seat_az)")
    p.add_argument("--settled", metavar="FILE", help="restart from a saved settled state "
                   "(settled_state.npz of an earlier run with the same model)")
    _add_model_arguments(p)
    p.add_argument("--output-every", type=int_at_least(1, "--output-every"), metavar="K",
                   help="record the outputs every K time steps, at 1 / (K step) exactly "
                   "(default: the parameters' rate, 200 Hz, whose period must be a whole "
                   "number of steps; e.g. --design implicit --time-step 0.006 --output-every "
                   "1: 166.7 Hz, about 15%% faster than 5 ms; docs/designs.md)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--force", action="store_true", help="write into an existing folder")
    p.add_argument("--quiet", action="store_true", help="no progress or summary on screen")
    p.add_argument("--no-figures", action="store_true",
                   help="write the data only, no PNG figures (they take about 4 s)")
    p.add_argument("--verbose", action="store_true",
                   help="print where the command's time went (settle, vibrate, writing, "
                   "analysis, figures), the run's cost per time step and the libraries "
                   "preloaded (LD_PRELOAD, e.g. a faster memory allocator)")
    add_viz_arguments(p)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("modes", help="linearize the closed loop; modes, shapes, linear FRF")
    _add_model_arguments(p)
    p.add_argument("--method", choices=("auto", "fd", "autodiff"), default="auto",
                   help="linearization: Drake AutoDiff where supported, else finite "
                   "differences (auto)")
    p.add_argument("--max-freq", type=positive_float("--max-freq"), default=15.0, metavar="HZ",
                   help="list modes up to this frequency (default %(default)s)")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--force", action="store_true")
    p.set_defaults(func=cmd_modes)

    p = sub.add_parser("fit", help="identify parameters from measured transmissibility")
    p.add_argument("data", metavar="DATA", help="folder with frf.csv and/or timeseries.csv")
    _add_model_arguments(p)
    p.add_argument("--free", metavar="GROUP,...", default="default",
                   help="free parameters: groups (passive, spine_axial, pid, his, contact, "
                   "restraints, default) and/or names (see ehm_drake/data/fit_parameters.yaml)")
    p.add_argument("--weights", metavar="FILE", help="channel weights (YAML/JSON): keys "
                   "segment, segment_dof or direction/segment/dof")
    p.add_argument("--holdout", metavar="KEY=VALUE", help="leave data out of the fit and "
                   "report the error on it: direction=z, segment=knee_l, level=0.3")
    p.add_argument("--excitation", choices=["auto", "separate", "simultaneous"], default="auto",
                   help="how the data were recorded: one seat axis per test (separate) or "
                   "the axes at a level together (simultaneous, multiple-input estimates); "
                   "auto: from the folder's summary.json or seat record, else separate. "
                   "Sets the model's softening at the data's levels")
    p.add_argument("--workers", type=int, default=2, help="parallel processes (default 2)")
    p.add_argument("--no-verify", action="store_true", help="skip the time-domain check")
    p.add_argument("--verify-duration", type=positive_float("--verify-duration"), default=60.0,
                   metavar="S", help="simulated seconds per direction in the check")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--force", action="store_true")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser("transmissibility", help="estimate frf.csv and figures from a "
                       "simulation or lab data folder (H1, 0-12 Hz band-pass), or make a lab "
                       "folder from motion-capture sessions (C3D files, with --markers)")
    p.add_argument("data", metavar="SIM_OR_DATA_DIR|SESSION.c3d", nargs="+",
                   help="a simulation or lab folder; or C3D sessions (files or folders of "
                   "them), one test each")
    p.add_argument("--markers", metavar="MAP.yaml", help="the lab's marker map for C3D "
                   "sessions: clusters, seat accelerometer, segment points (see "
                   "ehm_drake/data/marker_map_example.yaml)")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--force", action="store_true")
    p.add_argument("--quiet", action="store_true", help="no progress on screen")
    p.set_defaults(func=cmd_transmissibility)

    p = sub.add_parser("comfort", help="ISO 2631-1 comfort metrics of the seat (and head)")
    p.add_argument("data", metavar="SIM_OR_DATA_DIR")
    p.add_argument("--out", metavar="DIR", help="where to write comfort.json (default: the "
                   "data folder)")
    p.add_argument("--force", action="store_true", help="replace an existing comfort.json")
    p.set_defaults(func=cmd_comfort)

    add_sweep_arguments(sub)
    add_gap_arguments(sub)
    add_validate_arguments(sub)
    return parser


def main(argv=None) -> int:
    from .simulation import EquilibriumError, SimulationDiverged

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (UsageError, ParameterError, SignalError, ValueError, FileNotFoundError) as e:
        print(f"ehm-drake {args.command}: error: {e}", file=sys.stderr)
        return 2
    except (SimulationDiverged, EquilibriumError) as e:
        print(f"ehm-drake {args.command}: simulation failed: {e}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        print(f"\nehm-drake {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

