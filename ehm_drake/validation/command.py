"""`ehm-drake validate`: the command line of `ehm_drake.validation`."""

from __future__ import annotations

import argparse

from ..cli_common import int_at_least, positive_float, prepare_output_dir
from .report import DEFAULT_DURATION_S


def add_validate_arguments(sub) -> None:
    p = sub.add_parser(
        "validate", help="the model against published facts (and supplied datasets)",
        description="Run the model in the configuration and at the level of each shipped "
        "published fact of seated-human biodynamics (the vertical resonance against "
        "vibration magnitude on a rigid seat, with and without backrest; seat-to-head "
        "transmissibility) and judge it; compare datasets a lab supplies frequency by "
        "frequency. Writes validation.json, validation.md and figures.",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--params", metavar="FILE", help="the body's parameters (YAML/JSON, merged "
                   "over the defaults); each fact's seat configuration is applied over them")
    p.add_argument("--reference", metavar="FILE", nargs="+", default=[],
                   help="measured datasets (YAML/JSON, format: ehm_drake.validation.reference)")
    p.add_argument("--duration", type=positive_float("--duration"), default=DEFAULT_DURATION_S,
                   metavar="S", help="simulated seconds per run (default %(default)s)")
    p.add_argument("--seed", type=int_at_least(0, "--seed"), default=1, metavar="N",
                   help="seed of the first run's excitation (run i gets N + i)")
    p.add_argument("--design", choices=("reference", "implicit"),
                   help="simulation design (default: implicit, or the --params file's if it "
                   "states its design or step; docs/designs.md)")
    p.add_argument("--workers", type=int_at_least(1, "--workers"), default=2,
                   help="parallel processes (default 2)")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--force", action="store_true")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_validate)


def cmd_validate(args) -> int:
    from ..params import command_design, load_params
    from .reference import read_reference
    from .report import validate

    load_params(args.params)  # a bad file is refused before the folder is made
    for path in args.reference:
        read_reference(path)
    out = prepare_output_dir(args.out, args.force)
    report = validate(out, args.params, args.reference, args.duration, args.seed,
                      command_design(args.params, args.design), args.workers,
                      progress=not args.quiet)
    if not args.quiet:
        s = report["summary"]
        print(f"{s['passed']} of {s['facts']} facts reproduced ({s['publications']} "
              f"publications) -> {out / 'validation.md'}")
        for r in report["facts"]:
            print(f"  {'ok  ' if r['passed'] else 'FAIL'} {r['id']:26s} model "
                  f"{r['model']:.3g} (expected {r['expected']['text']})")
        for r in report["references"]:
            print(f"  reference {r['label']}: {100 * r['share_inside_range']:.0f}% inside "
                  f"its range, peak {r['peak_frequency_hz']['model']:.2f} Hz (data "
                  f"{r['peak_frequency_hz']['data']:.2f})")
    return 0
