"""Batch runs: parameter grids, anthropometry, seat sweeps, Monte Carlo populations.

``ehm-drake sweep SPEC --out DIR`` (or :func:`run_sweep` from Python) runs many
settle + vibrate simulations (:func:`ehm_drake.simulation.simulate`) described by
one spec file, in parallel, and keeps a compact result per run.

Spec file (YAML or JSON)
------------------------
::

    name: seat-stiffness            # optional label
    # common settings of every run (defaults shown)
    direction: z                    # x, y, z or xyz
    rms: 0.1941                     # seat acceleration RMS per axis, m/s^2
    duration: 60.0                  # vibration time after settling, s (onset included)
    seed: 0                         # excitation seed
    variant: default                # default, no-integrator, high-stiffness
    design: auto                    # auto, implicit, reference (see below)
    excitation: random              # random, multisine, sweep, sine
    frequency_hz: 4.0               # for excitation: sine
    params_file: my_params.yaml     # optional, relative to the spec file
    params:                         # optional overrides (nested, as the parameter file)
      simulation: {settle_time_s: 3.0}
    body: [small, median, {mass_kg: 60, stature_m: 1.62}]   # presets or measures
    grid:                           # full factorial over dotted paths
      contact.pelvis_pan.stiffness: [30000, 45000, 60000]
      rms: [0.2, 0.5]               # common settings may be swept too
      body.mass_kg: [60, 80]        # and body measures
    seat:                           # seat configurations: a grid of contact./restraints.
      - {name: soft, contact.thighs_pan.stiffness: 20000, restraints.pelvis_pan.stiffness: 4000}
      - {name: hard, contact.thighs_pan.stiffness: 90000}
    monte_carlo:                    # population: n samples around every grid point
      n: 20
      seed: 1
      vary:
        contact.pelvis_pan.stiffness: {dist: normal, rel_sd: 0.1}
        body.mass_kg: {dist: lognormal, rel_sd: 0.15}
        pid.neck.kp: {dist: uniform, rel_range: 0.2}
    analysis:
      peak_band_hz: [0.5, 12.0]     # band searched for transmissibility peaks
      frf: true                     # keep each run's frf.csv

``design: auto`` runs each run as ``simulate`` does: on the implicit design at the step
chosen by accuracy for that body, variant and parameters (about three times faster than
the paper's 1 ms reference design, and nearer the converged response:
docs/designs.md), unless the spec states ``simulation.design`` or
``simulation.time_step_s`` (in ``params_file``, ``params``, ``grid``, ``seat`` or
``monte_carlo``), whose design and step are then kept.  ``implicit`` and ``reference``
name one; ``design`` may be swept like any common setting.  Each run's results record
the design and step it ran.

Runs are the product bodies x grid x seat (x Monte Carlo samples), in that order.
Monte Carlo sample ``i`` draws from ``numpy.random.default_rng([seed, i])``, one draw per
varied path in sorted path order, so the same seed gives the same runs and raising ``n``
keeps the earlier samples.  Distributions: ``normal`` (``rel_sd``: v (1 + rel_sd z), or
``sd``: v + sd z), ``lognormal`` (``rel_sd``: mean v, coefficient of variation rel_sd;
always positive), ``uniform`` (``rel_range``: v (1 + U(-r, r)), or ``low``/``high``).
A vector parameter (e.g. ``pid.neck.kd``) gets one draw for all its components.  A sample
outside the admissible range (negative stiffness, a body beyond the scaling) is a failed
run, recorded like any other.

Output folder
-------------
* ``runs/<run_id>.json``: one per finished run, written atomically as it completes: its
  full inputs (complete parameter set, body, settings), the swept values, status, results
  (transmissibility peaks, ISO 2631-1 comfort of seat and head, settled posture, wall
  times) or, for a failed run, the error type and message.  ``runs/<run_id>.frf.csv``:
  the run's transmissibility table (``analysis.frf``).
* ``summary.csv`` (one row per run: id, status, swept values, key results) and
  ``summary.json``; ``sweep_spec.json``: the normalized spec.

``run_id`` is a hash of the run's inputs, so re-running the same spec into the same
folder skips the finished runs (failed runs too: they are deterministic; pass
``retry_failed``), and recomputes only what is missing.  A run whose worker crashed
(an executor error, not a model error) is retried automatically.

Execution goes through a :class:`concurrent.futures.Executor`: a local process pool by
default (``max_workers``), a Dask distributed cluster given its scheduler address, or
any executor passed in.  Workers build their own models from plain dicts (Drake diagrams
are not picklable).  Ctrl-C stops submitting, waits for the running runs and keeps them;
a second Ctrl-C abandons the running runs.  Everything finished is kept and the summary
is written; re-running the command resumes.

Modules
-------
``schema`` the spec file's typed keys (dataclasses for Drake's ``yaml_load_typed``),
names and defaults; ``checks`` what needs the parameter tree (paths, swept values,
seats, bodies, distributions); ``spec`` reading and normalizing (:class:`SweepSpec`);
``expand`` the runs and their ids; ``execute`` one run in a worker; ``store`` the run
records; ``backends`` process pool, Dask and the driving loop; ``summary`` the summary
files; ``runner`` :func:`run_sweep`; ``command`` the command line.
"""

from .checks import default_params_dict
from .command import add_sweep_arguments, cmd_sweep, main  # noqa: F401 - main: as before
from .execute import execute_run, summarize_result
from .expand import RunSpec, expand_runs, run_id_of
from .runner import run_sweep
from .schema import BODY_PRESETS, SweepSpecError
from .spec import MonteCarlo, SweepSpec, load_sweep_spec
from .store import SweepResult
from .summary import write_summary

__all__ = [
    "BODY_PRESETS", "MonteCarlo", "RunSpec", "SweepResult", "SweepSpec", "SweepSpecError",
    "add_sweep_arguments", "cmd_sweep", "default_params_dict", "execute_run", "expand_runs",
    "load_sweep_spec", "run_id_of", "run_sweep", "summarize_result", "write_summary",
]
