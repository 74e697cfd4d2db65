"""Command line interface: `ehm-drake <command> ...`.

Commands
--------
simulate        settle, vibrate, write time series, transmissibility, plots
transmissibility  estimate frf.csv (+ figures) from a simulation or lab folder
comfort         ISO 2631-1 comfort metrics of a simulation or lab folder

Errors in the input (parameter files, arguments, data) end the program with
a one-line message and exit status 2; a simulation that blows up, with
status 3.  Nothing is written over an existing output folder unless
`--force` is given.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from .model.anthropometry import REFERENCE, BodyMeasures
from .params import VARIANTS, ParameterError, load_params
from .signals import KINDS, PAPER_RMS, SignalError


class UsageError(ValueError):
    """A bad command-line argument."""


def _positive(name):
    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not math.isfinite(v) or v <= 0:
            raise argparse.ArgumentTypeError(f"{name} must be a positive finite number, got {v}")
        return v
    return parse


def _non_negative_int(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"seed must be an integer, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"seed must be >= 0, got {v}")
    return v


def prepare_output_dir(path: str | Path, force: bool) -> Path:
    """Create the output folder; refuse a non-empty existing one unless
    `force` (then only the files this program writes are replaced)."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} exists and is not a folder")
    if out.exists() and any(out.iterdir()) and not force:
        raise UsageError(f"output folder {out} exists and is not empty; use --force to "
                         "write into it (files of the same name are replaced)")
    out.mkdir(parents=True, exist_ok=True)
    return out


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
                   "the defaults; a fit's output is accepted")
    p.add_argument("--mass", type=_positive("--mass"), metavar="KG", help="body mass (kg)")
    p.add_argument("--stature", type=_positive("--stature"), metavar="M",
                   help="stature (m)")
    p.add_argument("--sitting-height", type=_positive("--sitting-height"), metavar="M",
                   help="sitting height (m); default scales with stature")
    p.add_argument("--contact", choices=("point", "hydroelastic"),
                   help="contact model (default: from the parameters, point)")


def _load_model_params(args):
    params = load_params(args.params)
    if getattr(args, "contact", None):
        params.contact.model = args.contact
    return params


def cmd_simulate(args) -> int:
    from .diagram import build_diagram
    from .plots import plot_posture, plot_responses
    from .signals import make_seat_signal
    from .simulation import SettledState, settle, vibrate

    params = _load_model_params(args)
    measures = _measures(args)
    out = prepare_output_dir(args.out, args.force)
    s = params.simulation
    signal = make_seat_signal(
        args.excitation, args.direction, args.rms, args.duration, args.seed, s.time_step_s,
        s.settle_time_s, s.onset_time_s, frequency_hz=args.frequency, csv_path=args.csv)
    progress = not args.quiet
    t0 = time.perf_counter()
    if args.settled:
        settled = SettledState.load(args.settled)
    else:
        settled = settle(params, measures, args.variant, progress=progress)
    settle_wall = time.perf_counter() - t0
    settled.save(out / "settled_state.npz")
    result = vibrate(params, settled, signal, measures, args.variant, progress=progress)
    files = [p.name for p in result.write_csv(out)]
    model = build_diagram(params, measures, None, args.variant, guard=False)
    ref = model.plant.GetPositions(model.plant.CreateDefaultContext())
    files.append(plot_posture(
        model, {f"settled ({args.variant})": settled.state[:model.plant.num_positions()],
                "initial (reference)": ref},
        out / "posture.png", f"Posture after settling, variant {args.variant}").name)
    files.append(plot_responses(result, out / "responses.png").name)
    summary = {
        "dof": int(model.plant.num_velocities()),
        "segments": len(model.hp.body.segments),
        "mass_kg": float(model.hp.body.total_mass),
        "stature_m": measures.stature_m,
        "sitting_height_m": measures.resolved_sitting_height(),
        "variant": args.variant,
        "contact_model": params.contact.model,
        "excitation": signal.meta,
        "seat_rms_measured": dict(zip("xyz", map(float, signal.rms()), strict=True)),
        "real_time_factor": result.meta["real_time_factor"],
        "settle_wall_s": settle_wall,
        "vibrate_wall_s": result.meta["wall_s"],
        **{k: settled.summary[k] for k in (
            "settle_posture_error_deg", "head_pitch_drift_deg", "head_pitch_deg",
            "trunk_T8_forward_drift_m", "backrest_force_n", "back_in_contact")},
    }
    summary.update(_transmissibility_outputs(result, signal, model, out, files))
    summary["files"] = sorted(files)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    if not args.quiet:
        _print_summary(summary)
    return 0


def _transmissibility_outputs(result, signal, model, out: Path, files: list) -> dict:
    """frf.csv, apparent_mass.csv, figure and a summary of the peaks."""
    from .analysis.apparent import apparent_mass_table
    from .analysis.dataio import TimeSeriesData
    from .analysis.spectral import transmissibility
    from .analysis.figures import plot_frf_grid

    vib = result.after(signal.steady_start)
    names, data = vib.timeseries_columns()
    ts = TimeSeriesData.from_columns(names, data, meta={"direction": signal.meta["direction"],
                                                         "level_rms": signal.meta["rms"]})
    frf = transmissibility(ts)
    frf.to_csv(out / "frf.csv")
    files.append("frf.csv")
    static_mass = float(np.mean(result.seat_forces[:, 2])) / 9.81
    am = apparent_mass_table(vib, static_mass)
    am.to_csv(out / "apparent_mass.csv", index=False) if hasattr(am, "to_csv") else None
    files.append("apparent_mass.csv")
    files.append(plot_frf_grid(frf, out / "transmissibility.png").name)
    peaks = {}
    for key in frf.channels():
        sel = frf.select(*key[:3])
        k = int(np.argmax(sel.gain))
        peaks["/".join(key[:3])] = {"peak_gain": float(sel.gain[k]),
                                    "peak_freq_hz": float(sel.freq_hz[k])}
    return {"transmissibility_peaks": peaks}


def _print_summary(summary: dict) -> None:
    print(f"\nEHM seated human, {summary['dof']} DoF, {summary['mass_kg']:.1f} kg, "
          f"variant {summary['variant']}, real-time factor {summary['real_time_factor']:.2f}")
    e = summary["settle_posture_error_deg"]
    print("settled posture error (deg): " + ", ".join(f"{k} {v:.2f}" for k, v in e.items()))
    print(f"head pitch drift {summary['head_pitch_drift_deg']:.2f} deg, backrest force "
          f"{summary['backrest_force_n']['total']:.0f} N")
    peaks = summary.get("transmissibility_peaks", {})
    if peaks:
        print("transmissibility peaks (gain @ Hz; m/m or deg/m):")
        for key, v in peaks.items():
            print(f"  {key:24s} {v['peak_gain']:8.3f} @ {v['peak_freq_hz']:5.2f}")


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
    p.add_argument("--rms", type=_positive("--rms"), default=PAPER_RMS, metavar="A",
                   help="seat acceleration RMS per axis, m/s^2 (paper: %(default)s)")
    p.add_argument("--duration", type=_positive("--duration"), default=60.0, metavar="S",
                   help="vibration time after settling, s (default %(default)s)")
    p.add_argument("--seed", type=_non_negative_int, default=0, metavar="N",
                   help="random seed of the excitation")
    p.add_argument("--excitation", choices=KINDS, default="random",
                   help="signal type (default random 0.1-12 Hz)")
    p.add_argument("--frequency", type=_positive("--frequency"), default=4.0, metavar="HZ",
                   help="frequency of --excitation sine")
    p.add_argument("--csv", metavar="FILE", help="measured seat acceleration for "
                   "--excitation csv (columns t, seat_ax, seat_ay, seat_az)")
    p.add_argument("--settled", metavar="FILE", help="restart from a saved settled state "
                   "(settled_state.npz of an earlier run with the same model)")
    _add_model_arguments(p)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--force", action="store_true", help="write into an existing folder")
    p.add_argument("--quiet", action="store_true", help="no progress or summary on screen")
    p.set_defaults(func=cmd_simulate)
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

