"""Blind check of the gap diagnosis.

Each trial draws (seeded) a hidden truth: no effect, one effect or two, at
random strength over the detectable range; `synthesize` writes the lab data
and the key into separate folders; ``ehm-drake diagnose`` then runs in its
own process on the data folder only (it is never given the key's path).
The trial is scored against the key afterwards:

* detectable: the hidden effect, at its true size on the trial's true
  subject, leaves a gap the base model cannot absorb (`detectability`: the
  base model refit to the noise-free truth, with the data's own uncertainty,
  keeps a cell whose expected chi^2 exceeds the significance threshold),
  decided from the key, or the diagnosis found a significant gap anyway (so
  a found but misattributed gap is always a miss).  Top-1 and top-3 are
  taken over the detectable trials (and reported over all effect trials);
* top-1: verdict explained or ambiguous and its best effect is (one of) the
  hidden effect(s);
* top-3: a hidden effect is among the first three of the ranking (and the
  verdict is not ``no_significant_gap``);
* false alarm: a no-effect trial whose verdict is not ``no_significant_gap``;
* held-out reduction: the held-out gap reduction of the hidden effect's
  candidate (the better one of two).

A trial's result is stored as soon as it is scored, so an interrupted run,
re-run with the same arguments, resumes where it stopped.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ...progress import Progress
from ...realities import MODEL_REALITY, RealityError
from ...sweep.store import atomic_write
from ..library.effects import EFFECT_NAMES, EFFECTS
from .scoring import markdown, score, summarize
from .synth import DEFAULT_DURATION_S, DEFAULT_LEVELS, SynthSpec, synthesize

#: Strength range the blind trials draw from: the upper part of each effect's
#: plausible range, where most effects change the transmissibility beyond the
#: measurement uncertainty plus the 3% model floor.  Whether a given trial is
#: detectable is decided per trial (`detectability`): at 0.3-0.6 m/s^2
#: backrest_separation leaves no significant gap even at strength 1, and
#: seat_friction only at the top of it.
DETECTABLE_STRENGTH = (0.6, 1.0)
#: Effects a lab can impose on a reference subject and measure again (the
#: contrasts of `gap.contrasts`): hands on the thighs or not, tensed or
#: relaxed, leaning on the backrest or not, another cushion, foam or cover.
#: Not a visceral mass or a reflex delay: no protocol adds or takes them away.
IMPOSABLE_EFFECTS = ("arms", "cocontraction", "backrest_separation", "seat_cushion_dynamics",
                     "seat_foam_stiffening", "seat_friction")
#: Strength of an imposed effect in a contrast: one known condition, the
#: middle of the trials' range (`DETECTABLE_STRENGTH`).
CONTRAST_STRENGTH = 0.8
class BlindError(ValueError):
    """Bad blind-run settings."""


@dataclass
class BlindSpec:
    trials: int
    seed: int
    directions: str = "xyz"
    levels: tuple = DEFAULT_LEVELS
    duration_s: float = DEFAULT_DURATION_S
    hidden: tuple = EFFECT_NAMES  # effects the trials may hide
    candidates: tuple | None = None  # effects diagnose may propose (None: all)
    p_none: float = 0.15
    p_two: float = 0.10
    strength: tuple = DETECTABLE_STRENGTH
    workers: int | None = None
    extra: dict = field(default_factory=dict)
    #: The body that makes each trial's data ("ehm": the model itself; or an
    #: independent reality, `ehm_drake.realities`).
    reality: str = MODEL_REALITY
    #: Subjects of a reference group (no effect; same body, protocol and
    #: scatter, their own seeds) made once for the run; every trial is then
    #: diagnosed against it (`diagnose --reference`).  0: none.
    references: int = 0
    #: Contrast subjects per imposable effect (`IMPOSABLE_EFFECTS` among the
    #: candidates): the first ones of the reference group measured again, in
    #: another sitting (its own excitation and noise), with the effect at
    #: `CONTRAST_STRENGTH`; `diagnose` then scores those effects with their
    #: measured signatures (`gap.contrasts`).  0: none.
    contrasts: int = 0
    #: The model's parameters (`ModelParams.to_dict()`; None: the defaults):
    #: the model that makes the data on the model itself and the one
    #: `diagnose` fits, e.g. on the implicit design (``blind --design``).
    params: dict | None = None
    #: The lab path: every data set is made as C3D sessions (`synth --c3d`)
    #: and reduced to the lab folder diagnose reads (`analysis.lab_c3d`).
    c3d: bool = False

    def model_params(self):
        """The run's `ModelParams`, or None for the defaults."""
        from ...params import params_from_dict

        return None if self.params is None else params_from_dict(self.params)

    def validate(self) -> None:
        if self.trials < 1:
            raise BlindError(f"--trials must be >= 1, got {self.trials}")
        from ..reference_group.group import MIN_SUBJECTS
        if self.references and self.references < MIN_SUBJECTS:
            raise BlindError(f"--references must be 0 or >= {MIN_SUBJECTS}, got "
                             f"{self.references}")
        from ..reference_group.contrasts import MIN_CONTRASTS
        if self.contrasts and not MIN_CONTRASTS <= self.contrasts <= self.references:
            raise BlindError(f"--contrasts must be 0 or from {MIN_CONTRASTS} to --references "
                             f"({self.references}): they are the reference subjects measured "
                             f"again, got {self.contrasts}")
        for n in self.hidden:
            if n not in EFFECTS:
                raise BlindError(f"unknown effect {n!r}; choose from {', '.join(EFFECTS)}")
        for name, p in (("--p-none", self.p_none), ("--p-two", self.p_two)):
            if not 0 <= p <= 1:
                raise BlindError(f"{name} must be a fraction in [0, 1], got {p}")
        if self.p_none + self.p_two > 1:
            raise BlindError(
                f"--p-none {self.p_none} and --p-two {self.p_two} add up to more than 1 "
                f"(--p-two defaults to {BlindSpec.p_two}); for no-effect trials only pass "
                "--p-none 1 --p-two 0")
        lo, hi = self.strength
        if not (0 < lo <= hi <= 1):
            raise BlindError(f"strength range must satisfy 0 < lo <= hi <= 1, got {self.strength}")
        try:
            SynthSpec({}, 0, tuple(self.levels), self.directions, self.duration_s,
                      reality=self.reality).validate()
        except ValueError as e:
            raise BlindError(str(e)) from None


def plan(spec: BlindSpec) -> list[dict]:
    """The hidden truth of every trial (deterministic in the seed)."""
    rng = np.random.default_rng([spec.seed, 0xB11D])
    out = []
    for i in range(spec.trials):
        u = rng.random()
        k = 0 if u < spec.p_none else (2 if u < spec.p_none + spec.p_two and
                                       len(spec.hidden) > 1 else 1)
        names = [str(n) for n in rng.choice(spec.hidden, size=k, replace=False)] if k else []
        strengths = rng.uniform(*spec.strength, size=k)
        out.append({"trial": i, "synth_seed": int(rng.integers(0, 2**31 - 1)),
                    "effects": {n: round(float(s), 4) for n, s in
                                zip(names, strengths, strict=True)}})
    return out


def detectability(data, key: dict, params=None, measures=None, workers: int | None = None) -> dict:
    """Whether the trial's hidden effect can be seen in its data: per hidden
    effect, the linear model of the true subject (the key's base factors)
    with the effect at its true values gives the noise-free transmissibility
    at the data's rows; the base model (no effect) is refit to it; a cell
    whose remaining chi^2 (the data's own uncertainty and model floor)
    exceeds the Bonferroni threshold minus its degrees of freedom would, in
    expectation, be significant in the noisy data.  The trial is detectable
    if any hidden effect leaves such a cell.  Uses the key, never the
    diagnosis.  Returns {"detectable", "effects": {name: {"cells",
    "max_margin"}}}."""
    import copy
    import dataclasses

    from scipy.stats import chi2 as chi2_dist

    from ...identification.parameters import resolve_free
    from ...model.anthropometry import REFERENCE
    from ...params import load_params
    from ..library.family import linearize_cut
    from ..library.models import Candidate, Predictor, Statics, coordinate, fit_candidate
    from ..single.diagnose import load_families, load_lab_data, separation_slope
    from ..single.localize import SIGNIFICANCE, chi2_rows, localize

    params = params if params is not None else load_params()
    measures = measures if measures is not None else REFERENCE
    effects = key["effects"]
    if not effects:
        return {"detectable": False, "effects": {}}
    lab = data if hasattr(data, "rows") else load_lab_data(data)
    rows = lab.rows
    base_names = [f.name for f in resolve_free("default")]
    fams = load_families(params, measures, list(effects), base_names, workers, None, True)
    slope = separation_slope(params, measures)
    b_true = np.log([key["subject_factors"][n] for n in base_names])
    every = np.ones(len(rows), bool)
    base_fam = fams["base"]
    out = {}
    for name, truth in effects.items():
        cand = Candidate((name,))
        coords = np.array([coordinate(p, truth["values"][p.name]) for _, p in cand.params])
        fam = fams[cand.grid_effect or "base"]
        if cand.grid_effect:  # exact at the true values (the grid interpolates)
            fam = copy.copy(fam)
            fam.recenter(coords, linearize_cut(params, measures, cand.values(coords)))
        theta = np.concatenate([b_true, coords])
        pred = Predictor(fam, cand, rows, lab.tests, base_names, Statics(fam.family.info, slope))
        pred.update_statistics(theta)
        truth_rows = dataclasses.replace(rows, H=pred.predict(theta))
        base = Predictor(base_fam, Candidate(()), truth_rows, lab.tests, base_names,
                         Statics(base_fam.family.info, slope))
        fit = fit_candidate(base, every, b_true)
        cells = localize(truth_rows, chi2_rows(truth_rows, base.predict(fit.theta)))
        n = len(cells)
        margins = [c["chi2"] - (chi2_dist.isf(SIGNIFICANCE / n, c["dof_chi2"]) - c["dof_chi2"])
                   for c in cells]
        out[name] = {"cells": int(sum(m > 0 for m in margins)),
                     "max_margin": float(max(margins)) if margins else 0.0}
    return {"detectable": any(v["cells"] > 0 for v in out.values()), "effects": out}


def twin_detectability(data, twin) -> dict:
    """Whether a trial on an independent reality shows its hidden effect:
    the same subject, excitation and sensor noise without the effect (the
    twin data, made from the key) against the trial's data, cell by cell
    with the data's own uncertainty and the model floor (`localize`).  A
    cell whose chi^2 exceeds the significance threshold minus its degrees of
    freedom would, in expectation, be significant: the effect changes the
    measurement there beyond the noise.  (The model's base refit, which the
    own-family check uses, cannot be run on a reality; so an effect that
    only mimics subject scatter counts as detectable here: a stricter test.)
    What the diagnosis's smooth model-form discrepancy can absorb (a level-
    shared one fitted with the twin as the model, `discrepancy`) is taken
    out first, as the base refit is on the own family: an effect whose whole
    signature is a smooth per-channel change, the same at both levels, is
    indistinguishable from a model-form error and not detectable.
    Returns {"detectable", "effects": {"all": {"cells", "max_margin",
    "cells_raw"}}}."""
    from scipy.stats import chi2 as chi2_dist

    from ..single.diagnose import load_lab_data
    from ..single.localize import SIGNIFICANCE, chi2_rows, localize

    rows = load_lab_data(data).rows
    ref = load_lab_data(twin).rows
    if len(ref.H) != len(rows.H) or not np.array_equal(ref.freq, rows.freq):
        raise BlindError(f"twin data {twin} do not match {data} row for row")
    from ..single.discrepancy import SCALE_BOUNDS, Discrepancy

    def margins(H):
        cells = localize(rows, chi2_rows(rows, H))
        n = len(cells)
        return [c["chi2"] - (chi2_dist.isf(SIGNIFICANCE / n, c["dof_chi2"]) - c["dof_chi2"])
                for c in cells]

    absorbed, _ = Discrepancy.for_rows(rows, SCALE_BOUNDS[1]).absorb(
        ref.H, rows, np.ones(len(rows), bool))
    raw, beyond = margins(ref.H), margins(absorbed)
    det = {"cells": int(sum(m > 0 for m in beyond)),
           "max_margin": float(max(beyond)) if beyond else 0.0,
           "cells_raw": int(sum(m > 0 for m in raw))}
    return {"detectable": det["cells"] > 0, "effects": {"all": det}}


def _diagnose_subprocess(data: Path, out: Path, spec: BlindSpec, log: Path,
                         reference: Path | None = None, params_file: Path | None = None) -> int:
    cmd = [sys.executable, "-m", "ehm_drake.cli", "diagnose", str(data), "--out", str(out),
           "--force"]
    if params_file is not None:
        cmd += ["--params", str(params_file)]
    if reference is not None:
        cmd += ["--reference", str(reference)]
    if spec.candidates:
        cmd += ["--effects", ",".join(spec.candidates)]
    if spec.workers:
        cmd += ["--workers", str(spec.workers)]
    with open(log, "w") as f:
        return subprocess.call(cmd, stdout=f, stderr=subprocess.STDOUT)


def _design_of(params: dict | None) -> str:
    """The model design of a run's stored parameters (over the packaged
    defaults, as `BlindSpec.model_params` reads them; None: the defaults)."""
    from ...params import params_from_dict

    return params_from_dict(params or {}).simulation.design


def run_blind(spec: BlindSpec, out, progress: bool = True) -> dict:
    """Run (or resume) the blind trials into `out`; the summary."""
    spec.validate()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    settings = {k: v for k, v in asdict(spec).items() if k not in ("workers", "extra")}
    settings = json.loads(json.dumps(settings))
    sfile = out / "blind_settings.json"
    if sfile.is_file():
        old = {"reality": MODEL_REALITY, "references": 0, "params": None, "contrasts": 0,
               "c3d": False,
               **json.loads(sfile.read_text())}
        differ = sorted(k for k in set(old) | set(settings)
                        if k != "trials" and old.get(k) != settings.get(k))
        if differ:
            hint = ""
            was, now = _design_of(old.get("params")), _design_of(settings.get("params"))
            if was != now:
                hint = f" (it ran the {was} design: --design {was})"
            raise BlindError(f"{out} holds a blind run with other settings "
                             f"({', '.join(differ)}){hint}; use another --out")
    sfile.write_text(json.dumps(settings, indent=1) + "\n")
    params = spec.model_params()
    if params is not None:
        # What `diagnose` loads (it runs in its own process): the run's
        # parameters, written once next to the settings.
        (out / "params.json").write_text(json.dumps(spec.params, indent=1) + "\n")
    trials = plan(spec)
    reference = _reference_group(spec, out, progress, params) if spec.references else None
    if spec.contrasts:
        _contrast_subjects(spec, out, progress, params)
    results = []
    prog = Progress("blind", len(trials), progress, unit="trials")
    calibrated = False  # the group's thresholds computed (by a trial's diagnosis)
    for tr in trials:
        tdir = out / f"trial_{tr['trial']:03d}"
        rfile = tdir / "result.json"
        data, key, diag = tdir / "data", out / "keys" / f"trial_{tr['trial']:03d}.json", \
            tdir / "diagnosis"
        twin = (tdir / "twin_data", out / "keys" / f"trial_{tr['trial']:03d}_twin.json")
        if rfile.is_file():
            res = json.loads(rfile.read_text())
            if "skipped" in res:
                results.append(res)
                prog.skip()
                continue
            if "detectability" not in res:  # scored before the detectability check
                _judge(res, data, json.loads(key.read_text()),
                       json.loads((diag / "report.json").read_text()), spec, twin, params)
                atomic_write(rfile, json.dumps(res, indent=1) + "\n")
            results.append(res)
            prog.skip()
            calibrated = True  # (by the run that diagnosed it)
            continue
        t1 = time.perf_counter()
        try:
            _synthesize_once(SynthSpec(tr["effects"], tr["synth_seed"], tuple(spec.levels),
                                       spec.directions, spec.duration_s, reality=spec.reality,
                                       c3d=spec.c3d),
                             data, key, spec.workers, params)
        except RealityError as e:
            # The reality's own simulation diverged on this subject and effect:
            # no data to diagnose.  Recorded (with the reason) and left out of
            # the scores, not a crash of the whole run.
            res = {"trial": tr["trial"], "hidden": tr["effects"], "skipped": str(e)}
            tdir.mkdir(parents=True, exist_ok=True)
            atomic_write(rfile, json.dumps(res, indent=1) + "\n")
            results.append(res)
            prog.step(f"trial_{tr['trial']:03d}: skipped, the reality diverged ({e})")
            continue
        t_synth = time.perf_counter() - t1
        rc = _diagnose_subprocess(data, diag, spec, tdir / "diagnose.log", reference,
                                  out / "params.json" if params is not None else None)
        if rc != 0:
            raise RuntimeError(f"diagnose failed on trial {tr['trial']} (exit {rc}); see "
                               f"{tdir / 'diagnose.log'}")
        report = json.loads((diag / "report.json").read_text())
        key_data = json.loads(key.read_text())
        truth = key_data["effects"]
        res = {"trial": tr["trial"], "hidden": tr["effects"],
               "truth_values": {n: v.get("realized_values", v["values"])
                                for n, v in truth.items()},
               "fitted": {e["effect"]: e["params"] for e in report["ranking"]
                          if e["effect"] in tr["effects"]},
               "synth_s": t_synth, "diagnose_s": report.get("timing_s", {}).get("total")}
        _judge(res, data, key_data, report, spec, twin, params)
        atomic_write(rfile, json.dumps(res, indent=1) + "\n")
        results.append(res)
        s = res["score"]
        ok = s["top1"] or (not s["has_effect"] and not s["false_alarm"])
        prog.step(f"trial_{tr['trial']:03d}: hidden {s['truth_label']} -> {s['verdict']} "
                  f"{s['predicted_label']} ({'ok' if ok else 'MISS'}"
                  f"{'' if s['detectable'] or not s['has_effect'] else ', not detectable'})")
        if reference is not None and not calibrated:
            # The first diagnosis against the group also calibrated it (its
            # leave-one-out thresholds, cached for the others: tens of
            # minutes against a few for a trial): not the rate of the rest.
            prog.setup_done()
            calibrated = True
    summary = summarize(results, spec.reality)
    summary["settings"] = settings
    (out / "blind.json").write_text(json.dumps({"summary": summary, "trials": results},
                                               indent=1) + "\n")
    (out / "blind.md").write_text(markdown(summary, results))
    return summary


def _reference_group(spec: BlindSpec, out: Path, progress: bool, params=None) -> Path:
    """Make (or find) the run's reference group: `spec.references` subjects
    without effects, seeds from their own stream (never a trial's), into
    out/reference/subject_NN (keys in out/keys).  A subject on which the
    reality diverges is replaced by the next seed."""
    folder = out / "reference"
    rng = np.random.default_rng([spec.seed, 0x5EF])
    prog = Progress("blind: reference group", spec.references, progress, unit="subjects")
    made = 0
    for attempt in range(3 * spec.references):
        if made == spec.references:
            break
        seed = int(rng.integers(0, 2**31 - 1))
        name = f"subject_{attempt:02d}"
        try:
            _synthesize_once(SynthSpec({}, seed, tuple(spec.levels), spec.directions,
                                       spec.duration_s, reality=spec.reality, c3d=spec.c3d),
                             folder / name, out / "keys" / f"reference_{name}.json",
                             spec.workers, params, out / "c3d_labs" / "reference" / name)
        except RealityError as e:
            prog.say(f"reference {name} (seed {seed}) skipped: {e}")
            continue
        made += 1
        prog.step(name)
    if made < spec.references:
        raise BlindError(f"the reality diverged on too many reference subjects ({made} of "
                         f"{spec.references} made)")
    return folder


def _contrast_subjects(spec: BlindSpec, out: Path, progress: bool, params=None) -> None:
    """Measure the first `spec.contrasts` subjects of the reference group
    again with each imposable candidate effect, into
    out/reference/contrasts/<effect>/<subject> (keys in out/keys).  A
    subject on which the reality diverges is replaced by the next one."""
    folder = out / "reference"
    subjects = sorted(p.name for p in folder.glob("subject_*") if (p / "frf.csv").is_file())
    effects = [e for e in IMPOSABLE_EFFECTS if spec.candidates is None or e in spec.candidates]
    prog = Progress("blind: contrasts", spec.contrasts * len(effects), progress,
                    unit="subjects")
    for effect in effects:
        made = 0
        for name in subjects:
            if made == spec.contrasts:
                break
            seed = json.loads((out / "keys" / f"reference_{name}.json").read_text())["seed"]
            try:
                _synthesize_once(SynthSpec({effect: CONTRAST_STRENGTH}, seed, tuple(spec.levels),
                                           spec.directions, spec.duration_s,
                                           reality=spec.reality, session=1, c3d=spec.c3d),
                                 folder / "contrasts" / effect / name,
                                 out / "keys" / f"contrast_{effect}_{name}.json",
                                 spec.workers, params,
                                 out / "c3d_labs" / "contrasts" / effect / name)
            except RealityError as e:
                prog.say(f"contrast {effect} on {name} skipped: {e}")
                continue
            made += 1
            prog.step(f"{effect} on {name}")
        if made < spec.contrasts:
            raise BlindError(f"the reality diverged on too many contrast subjects of {effect} "
                             f"({made} of {spec.contrasts} made)")


def _synthesize_once(synth: SynthSpec, data: Path, key: Path, workers: int | None,
                     params=None, lab: Path | None = None) -> None:
    """`synthesize` into `data` and `key` unless a finished data folder is
    there.  Each folder is made under a temporary name and renamed when
    whole, and the key is written last, so a run interrupted at any point
    (even while a record is being written) redoes that subject on resuming;
    a folder without its key (left by an interrupted run of an earlier
    version) is redone too.  With `synth.c3d` the synthetic lab's own folder
    (its C3D sessions, marker map and direct estimates) is `lab` (default:
    `data` + ``_lab``), and `data` the lab folder made from its sessions
    alone: what diagnose is given."""
    import shutil

    if (data / "frf.csv").is_file() and key.is_file():
        return
    if not synth.c3d:
        lab = data
    elif lab is None:
        lab = data.with_name(data.name + "_lab")
    partial = {f: f.with_name(f.name + ".partial") for f in (data, lab)}
    for folder in (*partial, *partial.values()):
        shutil.rmtree(folder, ignore_errors=True)
    key.unlink(missing_ok=True)
    key_partial = key.with_name(key.name + ".partial")
    key_partial.unlink(missing_ok=True)
    synthesize(synth, partial[lab], key_partial, params=params, workers=workers,
               progress=False)
    if synth.c3d:
        from ...analysis.lab_c3d import c3d_lab_folder
        from .synth_c3d import C3D_FOLDER, MARKER_MAP_FILENAME

        partial[lab].rename(lab)
        c3d_lab_folder([lab / C3D_FOLDER], lab / C3D_FOLDER / MARKER_MAP_FILENAME,
                       partial[data], progress=False)
    partial[data].rename(data)
    key_partial.rename(key)


def _judge(res: dict, data: Path, key: dict, report: dict, spec: BlindSpec,
           twin: tuple[Path, Path], params=None) -> None:
    """Add the trial's detectability (from its key) and its score.  On an
    independent reality the twin data (the trial without its effects) are
    made here, after the diagnosis, into `twin` (folder, key file)."""
    if spec.reality == MODEL_REALITY:
        det = detectability(data, key, params, workers=spec.workers)
    elif not key["effects"]:
        det = {"detectable": False, "effects": {}}
    else:
        folder, twin_key = twin
        try:
            _synthesize_once(SynthSpec({}, key["seed"], tuple(key["levels_rms"]),
                                       key["directions"], key["duration_s"],
                                       reality=spec.reality, c3d=spec.c3d), folder, twin_key,
                             spec.workers)
            det = twin_detectability(data, folder)
        except RealityError as e:
            # No twin (the reality diverged without the effect): the trial
            # counts as detectable, the stricter choice, and says why.
            det = {"detectable": True, "effects": {}, "twin_error": str(e)}
    res["detectability"] = det
    res["score"] = score(res["hidden"], report, det["detectable"],
                         spec.reality != MODEL_REALITY)
