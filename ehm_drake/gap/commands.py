"""The gap-diagnosis commands of the CLI: ``diagnose``, ``synth`` and
``blind`` (argument parsing and printing only; the work is in
`diagnose`, `synth` and `blind`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..cli_common import (
    UsageError,
    add_design_arguments,
    csv_floats,
    int_at_least,
    prepare_output_dir,
)
from ..realities import MODEL_REALITY
from .library.effects import EFFECT_NAMES


def _default_hidden(reality: str | None) -> tuple[str, ...]:
    """The effects a blind run hides by default: every candidate the body
    implements (an independent reality may implement a subset)."""
    from ..realities import get_reality

    if not reality or reality == MODEL_REALITY:
        return EFFECT_NAMES
    known = get_reality(reality).effect_names()
    return tuple(n for n in EFFECT_NAMES if n in known)


def _effect_list(text):
    names = tuple(t.strip() for t in text.split(",") if t.strip())
    bad = [n for n in names if n not in EFFECT_NAMES]
    if bad or not names:
        raise argparse.ArgumentTypeError(
            f"unknown effect(s) {', '.join(bad) or repr(text)}; choose from "
            f"{', '.join(EFFECT_NAMES)}")
    return names


def add_gap_arguments(sub) -> None:
    p = sub.add_parser("diagnose", help="sim-to-real gap: where, which unmodelled effect, how "
                       "much it removes")
    p.add_argument("data", metavar="DATA", help="lab data: a folder with frf.csv (and "
                   "tests.json, <direction>_<level>/timeseries.csv), a timeseries.csv folder "
                   "or an frf.csv")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--params", metavar="FILE", help="model parameters (default or a fit's "
                   "params.yaml)")
    add_design_arguments(p)
    p.add_argument("--effects", type=_effect_list, metavar="A,B,...",
                   help=f"candidate effects (default all: {', '.join(EFFECT_NAMES)})")
    p.add_argument("--workers", type=int_at_least(1), default=None,
                   help="parallel processes (default: all cores)")
    p.add_argument("--reference", nargs="+", metavar="DIR", default=None,
                   help="a reference group: data of subjects without the effects in question, "
                   "measured with the same protocol (subject folders, or a folder of them; at "
                   "least 4, 16 recommended). The subject is compared with the group, the "
                   "model gives only the shape of each candidate (see "
                   "ehm_drake.gap.reference_group.reference)")
    p.add_argument("--contrasts", metavar="DIR", default=None,
                   help="with --reference: contrast measurements of the group's subjects, "
                   "DIR/<effect>/<subject>/ (the subject measured again with the effect "
                   "imposed; at least 2 per effect). Those effects are scored with their "
                   "measured signatures instead of the model's (default: the reference "
                   "folder's own 'contrasts' folder, if any; see "
                   "ehm_drake.gap.reference_group.contrasts)")
    p.add_argument("--no-discrepancy", action="store_true",
                   help="leave out the model-form discrepancy (an unexplained gap stays "
                   "unexplained instead of being tested as a structural one)")
    p.add_argument("--no-cache", action="store_true", help="recompute the linear families "
                   "instead of reusing $EHM_DRAKE_CACHE (default ~/.cache/ehm_drake)")
    p.add_argument("--force", action="store_true")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_diagnose)

    p = sub.add_parser("synth", help="lab-like data from the nonlinear model with hidden "
                       "effects (the truth goes to --key only)")
    p.add_argument("--effect", required=True, metavar="NAME[,NAME]",
                   help=f"effect(s) to hide, or none ({', '.join(EFFECT_NAMES)})")
    p.add_argument("--strength", type=float, default=None, metavar="S",
                   help="fraction [0, 1] of the effect's plausible range (default 1)")
    p.add_argument("--seed", type=int_at_least(0), required=True, metavar="N")
    p.add_argument("--levels", type=csv_floats("--levels"), default=None, metavar="A,B",
                   help="seat acceleration RMS per test, m/s^2 (default 0.3,0.6)")
    p.add_argument("--directions", default="x,y,z", metavar="x,y,z")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="record length per test, s (default 60)")
    p.add_argument("--workers", type=int_at_least(1), default=None)
    p.add_argument("--reality", default=MODEL_REALITY, metavar="NAME",
                   help="the body that makes the data: ehm (the model itself, default) or an "
                   "independent reality (see ehm_drake.realities)")
    p.add_argument("--params", metavar="FILE", help="the model's parameters (default or a "
                   "fit's params.yaml); the subject scatter is applied to them")
    add_design_arguments(p)
    p.add_argument("--c3d", action="store_true",
                   help="also write each test as the C3D session of a motion-capture lab "
                   "(marker clusters with noise and dropouts, the seat accelerometer as an "
                   "analog channel) into DIR/c3d, with its marker map")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--key", required=True, metavar="KEYFILE")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_synth)

    p = sub.add_parser("blind", help="blind check of diagnose on synthetic trials with "
                       "hidden effects")
    p.add_argument("--trials", type=int_at_least(1), required=True, metavar="N")
    p.add_argument("--seed", type=int_at_least(0), required=True, metavar="S")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (re-running "
                   "with the same settings resumes)")
    p.add_argument("--hidden", type=_effect_list, default=None, metavar="A,B,...",
                   help="effects the trials may hide (default all)")
    p.add_argument("--effects", type=_effect_list, default=None, metavar="A,B,...",
                   help="candidates diagnose may propose (default all)")
    p.add_argument("--levels", type=csv_floats("--levels"), default=None, metavar="A,B")
    p.add_argument("--directions", default="x,y,z", metavar="x,y,z")
    p.add_argument("--duration", type=float, default=None, metavar="S")
    p.add_argument("--p-none", type=float, default=0.15, help="fraction of no-effect trials")
    p.add_argument("--p-two", type=float, default=0.10, help="fraction of two-effect trials")
    p.add_argument("--reality", default=MODEL_REALITY, metavar="NAME",
                   help="the body that makes each trial's data: ehm (the model itself, "
                   "default) or an independent reality (see ehm_drake.realities)")
    p.add_argument("--references", type=int_at_least(0), default=0, metavar="K",
                   help="make a reference group of K subjects without effects (same body and "
                   "protocol, their own seeds) and diagnose every trial against it "
                   "(diagnose --reference); default 0: no reference group; 16 recommended")
    p.add_argument("--contrasts", type=int_at_least(0), default=0, metavar="N",
                   help="with --references: measure the first N reference subjects again with "
                   "each effect a lab can impose (arms, co-contraction, backrest separation, "
                   "the seat effects); diagnose scores those with their measured signatures "
                   "(diagnose --contrasts); default 0")
    p.add_argument("--params", metavar="FILE", help="the model's parameters: the model that "
                   "makes the data (on --reality ehm) and the one diagnose fits")
    add_design_arguments(p)
    p.add_argument("--c3d", action="store_true",
                   help="the lab path: each data set is recorded as C3D sessions (synth "
                   "--c3d) and diagnose reads the lab folder made from them (transmissibility "
                   "--markers)")
    p.add_argument("--workers", type=int_at_least(1), default=None)
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_blind)


def _directions(text: str) -> str:
    return "".join(t.strip() for t in text.split(",") if t.strip())


def cmd_diagnose(args) -> int:
    from .report import write_report
    from .single.diagnose import diagnose

    params = _command_params(args)
    out = prepare_output_dir(args.out, args.force)
    if args.contrasts and not args.reference:
        raise UsageError("--contrasts needs --reference (the contrasts are measurements of "
                         "the reference group's subjects)")
    if args.reference:
        from .reference_group.reference import diagnose_with_reference

        diag = diagnose_with_reference(args.data, args.reference, params, args.effects,
                                       workers=args.workers, progress=not args.quiet,
                                       use_cache=not args.no_cache, contrasts=args.contrasts)
    else:
        diag = diagnose(args.data, params, args.effects, workers=args.workers,
                        progress=not args.quiet, use_cache=not args.no_cache,
                        discrepancy=not args.no_discrepancy)
    extra = {"params_file": args.params,
             "simulation": {"design": params.simulation.design,
                            "time_step_s": params.simulation.time_step_s}}
    caution = _design_caution(args, params)
    if caution:
        extra["design_caution"] = caution
    files = write_report(diag, out, extra)
    r = diag.report
    print(f"verdict: {r['verdict']}" + (f" ({r['best_effect']})" if r["best_effect"] else ""))
    print(f"  {r['explanation']}")
    if caution:
        print(f"  caution: {caution}")
    print(f"  gap before: train {r['gap_before']['train']:.3g}, held-out "
          f"{r['gap_before']['heldout']:.3g}; after: train {r['gap_after']['train']:.3g}, "
          f"held-out {r['gap_after']['heldout']:.3g}")
    for e in r["ranking"][:3]:
        print(f"  {e['effect']:24s} dBIC {e['delta_bic']:10.1f}  held-out reduction "
              f"{100 * e['gap_reduction_heldout']:5.1f}%")
    if (r.get("reference") or {}).get("caution"):
        print(f"  caution: {r['reference']['caution']}")
    mf = r.get("model_form")
    if mf:
        print(f"  model-form gap (model refit to the reference group vs the group): RMS log "
              f"gain {mf['rms_log_gain_difference']:.2f}, {mf['significant_cells']} cells; "
              "largest in " + ", ".join(f"{c['direction']}: {c['segment']} {c['dof']} "
                                        f"{c['f_lo_hz']:g}-{c['f_hi_hz']:g} Hz"
                                        for c in mf["cells"][:3]))
    sig = [c for c in r["localization"] if c["significant"]]
    for c in sig[:5]:
        print(f"  gap in {c['direction']}: {c['segment']} {c['dof']} {c['f_lo_hz']:g}-"
              f"{c['f_hi_hz']:g} Hz (share {100 * c['share']:.0f}%)")
    if r.get("separating_experiment"):
        print(f"  to separate: {r['separating_experiment']['text']}")
    print(f"-> {out}: " + ", ".join(files))
    return 0


def _design_caution(args, params) -> str | None:
    """When the data are an ehm-drake simulation (its ``summary.json`` names
    the design) on another design than the diagnosis's model, and no design
    was asked for: what that does and how to match them (None otherwise)."""
    import json

    from ..params import CHOICES, names_stepping

    if args.design is not None or args.time_step is not None or names_stepping(args.params):
        return None
    try:
        design = json.loads((Path(args.data) / "summary.json").read_text()).get("design")
    except (OSError, ValueError, AttributeError):
        return None
    ours = params.simulation.design
    if design not in CHOICES["simulation.design"] or design == ours:
        return None
    # (The designs' linear responses: docs/designs.md, and the fit's bias
    # when one design's data are fitted on the other.)
    return (f"{args.data} was simulated by ehm-drake on the {design} design; the diagnosis's "
            f"model runs the {ours} design, whose response differs from it by 0.2-4%, a gap "
            "the candidates then fit: to diagnose "
            f"the model against its own data, give --design {design}")


def _command_params(args):
    """The model's parameters given by ``--params``, ``--design`` and
    ``--time-step``, on the design the commands run when none is named
    (`params.command_design`: the implicit design at its accurate step)."""
    from ..diagram import on_design
    from ..params import command_design, load_params

    return on_design(load_params(args.params), command_design(args.params, args.design),
                     args.time_step)


def _model_params(args, data_from_model: bool):
    """The model's parameters (`_command_params`) where the model makes the
    data or diagnoses it; None for `synth` on an independent reality, whose
    data come from its own simulation (naming the model's then is an error)."""
    if data_from_model:
        return _command_params(args)
    if args.params is not None or args.design is not None or args.time_step is not None:
        raise UsageError(f"--params, --design and --time-step set the model; the data of "
                         f"--reality {args.reality} come from that reality's own simulation")
    return None


def cmd_synth(args) -> int:
    from .lab.synth import (
        DEFAULT_DURATION_S,
        DEFAULT_LEVELS,
        SynthSpec,
        parse_effects_arg,
        synthesize,
    )

    spec = SynthSpec(parse_effects_arg(args.effect, args.strength), args.seed,
                     args.levels or DEFAULT_LEVELS, _directions(args.directions),
                     args.duration or DEFAULT_DURATION_S, reality=args.reality, c3d=args.c3d)
    res = synthesize(spec, args.out, args.key, _model_params(args, args.reality == MODEL_REALITY),
                     workers=args.workers, progress=not args.quiet)
    print(f"synth: {len(res.tests)} tests, {len(res.frf)} FRF rows -> {res.out_dir}; "
          f"key -> {res.key_path}")
    return 0


def cmd_blind(args) -> int:
    from .lab.blind import BlindSpec, run_blind
    from .lab.synth import DEFAULT_DURATION_S, DEFAULT_LEVELS

    params = _model_params(args, True)
    spec = BlindSpec(args.trials, args.seed, _directions(args.directions),
                     args.levels or DEFAULT_LEVELS, args.duration or DEFAULT_DURATION_S,
                     args.hidden or _default_hidden(args.reality), args.effects, args.p_none,
                     args.p_two, workers=args.workers, reality=args.reality,
                     references=args.references, contrasts=args.contrasts, c3d=args.c3d,
                     params=None if params is None else params.to_dict())
    s = run_blind(spec, args.out, progress=not args.quiet)
    def pct(x):
        return "n/a" if x is None else f"{100 * x:.0f}%"

    print(f"blind: {s['trials']} trials ({s['detectable_trials']} with hidden effects): "
          f"top-1 {pct(s['top1'])}, top-3 {pct(s['top3'])}, false alarms "
          f"{pct(s['false_alarm'])}, held-out gap removed {pct(s['heldout_reduction_mean'])} "
          f"(mean); acceptance {'passed' if s['passed'] else 'NOT met'}")
    print(f"-> {args.out}: blind.json, blind.md", file=sys.stdout)
    return 0
