"""The ``sweep`` command: ``ehm-drake sweep SPEC --out DIR`` and
``python -m ehm_drake.sweep SPEC --out DIR`` (the same options)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..cli_common import int_at_least
from .runner import run_sweep
from .spec import load_sweep_spec

#: The first line of the package doc (the description of ``python -m ehm_drake.sweep``).
DESCRIPTION = "Batch runs: parameter grids, anthropometry, seat sweeps, Monte Carlo populations."


def add_sweep_arguments(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``sweep`` command to an argparse subparsers object (sets func=cmd_sweep)."""
    p = subparsers.add_parser(
        "sweep", help="batch runs over parameters, bodies, seats, Monte Carlo populations",
        description="Run the settle + vibrate simulations of a sweep spec (YAML/JSON) in "
        "parallel; each run is stored as it finishes, so re-running the same command "
        "resumes an interrupted sweep.")
    _sweep_options(p)
    p.set_defaults(func=cmd_sweep)
    return p


def _sweep_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("spec", metavar="SPEC", help="sweep spec file (YAML or JSON)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (resumed if it "
                   "holds an earlier run of the sweep)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask distributed scheduler, e.g. "
                   "tcp://host:8786 (default: a local process pool)")
    p.add_argument("--workers", type=int_at_least(1, "--workers"), metavar="N",
                   help="local worker processes (default: number of CPUs)")
    p.add_argument("--force", action="store_true",
                   help="recompute runs already stored in DIR")
    p.add_argument("--retry-failed", action="store_true",
                   help="recompute runs stored as failed")
    p.add_argument("--quiet", action="store_true", help="no progress display")


def cmd_sweep(args: argparse.Namespace) -> int:
    """Run ``ehm-drake sweep``.  Exit status: 0 all runs done, 3 some runs failed (they
    are recorded), 130 interrupted; a bad spec raises SweepSpecError (a ValueError)."""
    out = Path(args.out)
    if (out.is_dir() and any(out.iterdir()) and not (out / "sweep_spec.json").exists()
            and not args.force):
        raise ValueError(f"output folder {out} exists, is not empty and holds no sweep; use "
                         "--force to write into it")
    spec = load_sweep_spec(args.spec)
    if args.workers is not None and args.scheduler is not None:
        raise ValueError("--workers sizes the local pool; with --scheduler the cluster's "
                         "workers run the sweep")
    result = run_sweep(spec, out, scheduler=args.scheduler, max_workers=args.workers,
                       progress=not args.quiet, force=args.force,
                       retry_failed=args.retry_failed)
    print(f"sweep '{spec.name}': {len(result.runs)} runs, {result.n_done} done, "
          f"{result.n_failed} failed, {result.n_pending} not run; {len(result.computed)} "
          f"computed, {len(result.reused)} reused, {result.wall_s:.0f} s -> "
          f"{out / 'summary.csv'}")
    if result.interrupted:
        print("interrupted: run the same command again to resume", file=sys.stderr)
        return 130
    return 3 if result.n_failed else 0


def main(argv: list[str] | None = None) -> int:
    """``python -m ehm_drake.sweep SPEC --out DIR ...`` (same as ``ehm-drake sweep``)."""
    parser = argparse.ArgumentParser(prog="python -m ehm_drake.sweep",
                                     description=DESCRIPTION)
    _sweep_options(parser)
    args = parser.parse_args(argv)
    try:
        return cmd_sweep(args)
    except ValueError as e:
        print(f"sweep: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\nsweep: interrupted", file=sys.stderr)
        return 130
