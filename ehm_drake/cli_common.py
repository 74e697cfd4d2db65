"""Pieces shared by every command of the command line (`ehm_drake.cli`,
the sweep's and the gap diagnosis' commands): argparse value types, the
output-folder rule and the usage error.  It imports nothing of the
package, so every command module can sit above it without a cycle."""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path


class UsageError(ValueError):
    """A bad command-line argument."""


def int_at_least(lo: int, name: str | None = None):
    """An argparse type: an integer >= `lo`, with a message naming the value
    (and the option, if `name` is given)."""
    what = f"{name} " if name else ""

    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{what}must be an integer, got {text!r}" if name
                else f"expected an integer, got {text!r}") from None
        if v < lo:
            raise argparse.ArgumentTypeError(f"{what}must be >= {lo}, got {v}")
        return v

    return parse


def positive_float(name: str):
    """An argparse type: a positive finite number, with a message naming
    the option."""

    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not math.isfinite(v) or v <= 0:
            raise argparse.ArgumentTypeError(f"{name} must be a positive finite number, got {v}")
        return v

    return parse


def csv_floats(name: str):
    """An argparse type: comma-separated numbers (at least one)."""

    def parse(text):
        try:
            vals = tuple(float(t) for t in text.split(",") if t.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{name} must be comma-separated numbers, got {text!r}") from None
        if not vals:
            raise argparse.ArgumentTypeError(f"{name} is empty")
        return vals

    return parse


def add_design_arguments(p: argparse.ArgumentParser) -> None:
    """``--design`` and ``--time-step``: how the model's joints are built and
    its step (resolved by `ehm_drake.diagram.on_design`).  Every command runs
    the implicit design unless told otherwise (`params.command_design`)."""
    default = "implicit, or the --params file's if it states its design or step"
    p.add_argument("--design", choices=("reference", "implicit"),
                   help=f"joint design (default: {default}): implicit = Cardan joint chains, "
                   "stiff feedback in the implicit solve, a step chosen by accuracy (5 ms; "
                   "5/3 ms for the high-stiffness variant); reference = the paper's spherical "
                   "joints, feedback explicit, 1 ms step, about 3x slower (docs/designs.md)")
    p.add_argument("--time-step", type=positive_float("--time-step"), metavar="S",
                   help="simulation time step in seconds (default: the design's own: "
                   "implicit the largest of 0.005 / n that keeps the model second-order "
                   "accurate, reference 0.001; the parameters' step on their own design)")


def preloaded_libraries(environ=None) -> list[str]:
    """The file names of the libraries preloaded into this process
    (``LD_PRELOAD``, space or colon separated), e.g. a faster memory
    allocator (the user guide, "Simulation"); `--verbose` and the bench
    print them beside the run's speed."""
    environ = os.environ if environ is None else environ
    return [os.path.basename(p) for p in environ.get("LD_PRELOAD", "").replace(":", " ").split()]


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
