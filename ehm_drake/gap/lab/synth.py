"""Lab-like synthetic data: the nonlinear time-domain model with hidden
effects, a simulated subject and a lab's measurement chain.

What a lab hands over (and nothing else) goes to the data folder:

* ``frf.csv``: seat-to-body transmissibility of every test (30 channels:
  pelvis, trunk, head, knees x 6 DoF), H1 estimates with their coherence,
  level and number of averages;
* ``<direction>_<level>/timeseries.csv``: the recorded seat acceleration and
  body motion of each test (steady part; metadata in the header);
* ``tests.json``: directions, levels and the processing used.

The truth (effects and their strengths, the subject's parameters) goes only
to the key file.

The subject.  The base parameters of the identification's default set (20
stiffnesses, dampings and gains, `fit_parameters.yaml`) are each scaled by
a seeded factor uniform in [1 - spread, 1 + spread] (spread 0.15: inter-
subject variability of seated-body resonance frequencies and peak gains is
10-20%).

The body.  By default the model itself (``reality="ehm"``); or an independent
reality (`ehm_drake.realities`: a seated-human simulation that is not the
EHM model, with its own subject scatter and its own implementation of the
candidate effects), whose records pass through the same measurement chain,
sampled at the lab's motion-capture rate (`LAB_RATE_HZ`).

The measurement chain.  Random seat excitation (flat 0.1-12 Hz, seeded) per
direction and level; body motion by motion capture: white noise of 0.1 mm
(translations) and 0.05 deg (rotations) RMS on every sample (optical
marker clusters); seat accelerometer noise 0.005 m/s^2 RMS; H1 estimation
with 10 s Hann segments, 50% overlap (0.1 Hz resolution), exactly the
`ehm-drake transmissibility` processing.

With ``c3d`` (``synth --c3d``) each test is also written as the C3D session a
motion-capture lab would record (`synth_c3d`: marker clusters with their own
noise and dropouts, the same seat accelerometer record as an analog channel)
into ``c3d/<direction>_<level>.c3d``, with the lab's marker map
``c3d/marker_map.yaml``; ``ehm-drake transmissibility c3d/*.c3d --markers
c3d/marker_map.yaml`` makes a lab folder of them.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...analysis.formats import FrfData, TimeSeriesData, write_test_list
from ...analysis.transmissibility import transmissibility
from ...identification.parameters import apply_scales, representative, resolve_free
from ...model.anthropometry import REFERENCE
from ...parallel import run_jobs
from ...params import ModelParams, params_from_dict
from ...progress import Progress
from ...realities import CHANNEL_NAMES, MODEL_REALITY, RealityError, get_reality
from ..library.effects import EFFECTS, effect_values, reflex_delay_steps

DEFAULT_LEVELS = (0.3, 0.6)
DEFAULT_DURATION_S = 60.0
SEGMENT_S = 10.0
SUBJECT_SPREAD = 0.15
#: Motion-capture and seat accelerometer noise (RMS per sample).
NOISE_TRANSLATION_M = 1.0e-4
NOISE_ROTATION_DEG = 0.05
NOISE_SEAT_MS2 = 0.005
#: Motion-capture sampling rate of the lab (Hz): an independent reality's
#: records are taken at this rate (the EHM model logs at its own output
#: rate, 200 Hz by default).
LAB_RATE_HZ = 200.0
#: Half-cosine fade-in of an independent reality's excitation, s.
REALITY_ONSET_S = 1.0


class SynthError(ValueError):
    """Bad synth request (unknown effect, bad strength, occupied output)."""


@dataclass
class SynthSpec:
    """What to synthesize."""

    effects: dict  # name -> strength in [0, 1]
    seed: int
    levels: tuple = DEFAULT_LEVELS
    directions: str = "xyz"
    duration_s: float = DEFAULT_DURATION_S
    spread: float = SUBJECT_SPREAD
    #: The body that makes the data: "ehm" (the model) or an independent
    #: reality's name (`ehm_drake.realities`).
    reality: str = MODEL_REALITY
    #: A repeated sitting of the same subject (the same seed): 0 the first;
    #: each other number draws its own excitation and sensor noise.
    session: int = 0
    #: Also write each test as a C3D session (`synth_c3d`) with the marker map.
    c3d: bool = False

    def validate(self) -> None:
        if self.reality != MODEL_REALITY:
            try:
                get_reality(self.reality)
            except RealityError as e:
                raise SynthError(str(e)) from None
        for name, s in self.effects.items():
            if name not in EFFECTS:
                raise SynthError(f"unknown effect {name!r}; choose from "
                                 f"{', '.join(EFFECTS)} or 'none'")
            if not (isinstance(s, (int, float)) and math.isfinite(s) and 0.0 <= s <= 1.0):
                raise SynthError(f"strength of {name} must be a fraction in [0, 1], got {s!r}")
        if not self.levels:
            raise SynthError("give at least one level")
        for lv in self.levels:
            if not (math.isfinite(lv) and 0.01 <= lv <= 5.0):
                raise SynthError(f"level {lv} m/s^2 outside 0.01-5 m/s^2 (units are m/s^2 RMS)")
        if len(set(self.levels)) != len(self.levels):
            raise SynthError(f"duplicate levels in {self.levels}")
        if not self.directions or any(d not in "xyz" for d in self.directions) or \
                len(set(self.directions)) != len(self.directions):
            raise SynthError(f"directions must be distinct letters of x, y, z, got "
                             f"{self.directions!r}")
        if not (math.isfinite(self.duration_s) and self.duration_s >= 3 * SEGMENT_S):
            raise SynthError(f"duration must be >= {3 * SEGMENT_S:g} s (3 segments of "
                             f"{SEGMENT_S:g} s), got {self.duration_s}")
        if not 0.0 <= self.spread < 0.5:
            raise SynthError(f"subject spread must be in [0, 0.5), got {self.spread}")
        if not (isinstance(self.session, int) and self.session >= 0):
            raise SynthError(f"session must be a whole number >= 0, got {self.session!r}")

    def effect_values(self) -> dict:
        return {n: effect_values(n, s) for n, s in self.effects.items() if s > 0}


def subject_parameters(params: ModelParams, seed: int, spread: float = SUBJECT_SPREAD):
    """The simulated subject: default-set base parameters scaled by seeded
    factors uniform in [1 - spread, 1 + spread].  Returns (params, factors)."""
    free = resolve_free("default")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 1]))
    factors = 1.0 + rng.uniform(-spread, spread, len(free))
    return apply_scales(params, free, factors), {f.name: float(s) for f, s in
                                                  zip(free, factors, strict=True)}


def _test_seeds(seed: int, n: int, session: int = 0) -> list[int]:
    """The tests' excitation and noise seeds (a later `session`: others)."""
    entropy = [seed, 2] if session == 0 else [seed, 2, session]
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(entropy).spawn(n)]


def level_label(level: float) -> str:
    return f"{level:g}"


def _truth(name: str, strength: float, h: float) -> dict:
    """An effect's entry in the key: its strength and values, and where
    the simulation realizes a value other than the one drawn, the realized
    one (a reflex delay is a whole number of time steps: at the implicit
    design's 5 ms, 24 ms runs as 25 ms)."""
    values = effect_values(name, strength)
    entry = {"strength": float(strength), "values": values}
    if "tau_s" in values:
        tau = reflex_delay_steps(values["tau_s"], h) * h
        if not math.isclose(tau, values["tau_s"], rel_tol=1e-9):
            entry["realized_values"] = {**values, "tau_s": tau}
    return entry


def _run_test(args):
    """One lab test: simulate, add sensor noise, H1.  Returns (FrfData,
    TimeSeriesData, wall seconds, real-time factor)."""
    from ...signals import make_seat_signal
    from ...simulation import vibrate

    params_dict, effects, settled, direction, level, duration, seed, c3d = args
    params = params_from_dict(params_dict)
    s = params.simulation
    t0 = time.perf_counter()
    signal = make_seat_signal("random", direction, level, duration + s.onset_time_s, seed,
                              s.time_step_s, s.settle_time_s, s.onset_time_s)
    result = vibrate(params, settled, signal, REFERENCE, effects=effects)
    steady = result.after(signal.steady_start)
    frf, ts, session = _measure(steady.to_timeseries(), direction, level, seed, c3d)
    return (frf, ts, time.perf_counter() - t0,
            result.meta.get("real_time_factor", float("nan")), session)


def _measure(ts: TimeSeriesData, direction: str, level: float, seed: int, c3d: bool = False):
    """The lab's measurement chain on a noise-free record: sensor noise
    (seeded by the test's seed), the test's nominal metadata, H1; with
    `c3d`, the test's C3D session too (its markers' own noise, the same
    accelerometer record).  Returns (FrfData, TimeSeriesData, C3DSession or
    None)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 3]))
    channels = {}
    for name, x in ts.channels.items():
        rot = name.rsplit("_", 1)[-1] in ("roll", "pitch", "yaw")
        sd = NOISE_ROTATION_DEG if rot else NOISE_TRANSLATION_M
        channels[name] = x + sd * rng.standard_normal(len(x))
    seat = ts.seat_acc + NOISE_SEAT_MS2 * rng.standard_normal(ts.seat_acc.shape)
    # The level is the nominal RMS of the test (what a lab reports).
    clean = ts
    ts = TimeSeriesData(ts.t - ts.t[0], seat, channels,
                        {"direction": direction, "level_rms": float(level)})
    nperseg = int(round(SEGMENT_S * ts.fs))
    frf = transmissibility(ts, directions=direction, nperseg=nperseg)
    session = None
    if c3d:
        from .synth_c3d import virtual_session

        session = virtual_session(clean, seat, seed)
    return frf, ts, session


def _run_reality_test(args):
    """One lab test on an independent reality: its record of the steady
    part, sampled at the lab rate, through `_measure`.  Same return as
    `_run_test`."""
    from ...signals import make_seat_signal

    name, prepared, direction, level, duration, seed, c3d = args
    reality = get_reality(name)
    t0 = time.perf_counter()
    signal = make_seat_signal("random", direction, level, duration + REALITY_ONSET_S, seed,
                              reality.time_step, 0.0, REALITY_ONSET_S)
    rec = reality.run_test(prepared, signal)
    rec.check(f"reality {name}, test {direction} @ {level_label(level)} m/s^2")
    step = (rec.t[-1] - rec.t[0]) / (len(rec.t) - 1)
    k = int(round(1.0 / (LAB_RATE_HZ * step)))
    if k < 1 or abs(k * step * LAB_RATE_HZ - 1.0) > 1e-6:
        raise SynthError(f"reality {name} records at {1 / step:g} Hz, not a multiple of the "
                         f"lab's {LAB_RATE_HZ:g} Hz")
    ts = TimeSeriesData(rec.t[::k] - rec.t[0], rec.seat_acc[::k],
                        {c: np.asarray(rec.channels[c])[::k] for c in CHANNEL_NAMES},
                        {"direction": direction, "level_rms": float(level)})
    frf, ts, session = _measure(ts, direction, level, seed, c3d)
    return frf, ts, time.perf_counter() - t0, rec.real_time_factor, session


@dataclass
class SynthResult:
    out_dir: Path
    key_path: Path
    frf: FrfData
    key: dict
    wall_s: float
    tests: list = field(default_factory=list)


def _check_outputs(out_dir: Path, key_path: Path) -> None:
    out_dir, key_path = Path(out_dir).resolve(), Path(key_path).resolve()
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise SynthError(f"{out_dir} exists and is not an empty folder; give a new --out "
                         "(nothing is overwritten)")
    if key_path.exists():
        raise SynthError(f"key file {key_path} exists; give a new --key (nothing is "
                         "overwritten)")
    if out_dir == key_path or out_dir in key_path.parents:
        raise SynthError("the key file must not be inside the data folder: the data must "
                         "hold only what a lab hands over")


def synthesize(spec: SynthSpec, out_dir, key_path, params: ModelParams | None = None,
               workers: int | None = None, progress: bool = True) -> SynthResult:
    """Simulate the lab tests of `spec` and write the data folder and key."""
    from ...params import load_params
    from ...simulation import settle

    spec.validate()
    out_dir, key_path = Path(out_dir), Path(key_path)
    _check_outputs(out_dir, key_path)
    t0 = time.perf_counter()
    desc = ", ".join(f"{n} ({s:.2f})" for n, s in spec.effects.items() if s > 0) or "none"
    Progress("synth", enabled=progress).say(
        f"{'' if spec.reality == MODEL_REALITY else f'reality {spec.reality}, '}"
        f"subject seed {spec.seed}, effects: {desc}; settling")
    tests = [(d, lv) for d in spec.directions for lv in spec.levels]
    seeds = _test_seeds(spec.seed, len(tests), spec.session)
    if spec.reality == MODEL_REALITY:
        base = params if params is not None else load_params()
        subject, factors = subject_parameters(base, spec.seed, spec.spread)
        effects = spec.effect_values()
        settled = settle(subject, REFERENCE, effects=effects)
        run = _run_test
        jobs = [(subject.to_dict(), effects, settled, d, lv, spec.duration_s, sd, spec.c3d)
                for (d, lv), sd in zip(tests, seeds, strict=True)]
        truth = {
            "effects": {n: _truth(n, s, subject.simulation.time_step_s)
                        for n, s in spec.effects.items() if s > 0},
            "simulation": {"design": subject.simulation.design,
                           "time_step_s": subject.simulation.time_step_s},
            "subject_factors": factors,
            "subject_values": {n: representative(subject, f) for n, f in
                               ((f.name, f) for f in resolve_free("default"))},
        }
    else:
        reality = get_reality(spec.reality)
        subject = reality.subject(spec.seed)
        values = {n: reality.effect_values(n, s) for n, s in spec.effects.items() if s > 0}
        settled = reality.prepare(subject, values)
        run = _run_reality_test
        jobs = [(spec.reality, settled, d, lv, spec.duration_s, sd, spec.c3d)
                for (d, lv), sd in zip(tests, seeds, strict=True)]
        truth = {
            "reality": spec.reality,
            "effects": {n: {"strength": float(s), "values": values[n]}
                        for n, s in spec.effects.items() if s > 0},
            "subject": subject,
        }
    prog = Progress("synth", len(tests), progress, unit="tests")

    def report(done, total, i, result):
        d, lv = tests[i]
        prog.step(f"test {d} @ {level_label(lv)} m/s^2 done (real-time factor "
                  f"{result[3]:.2f})")

    results = run_jobs([(run, j) for j in jobs], workers, report)
    out_dir.mkdir(parents=True, exist_ok=True)
    frf = FrfData.concat([r[0] for r in results])
    frf.to_csv(out_dir / "frf.csv")
    test_list = []
    for (d, lv), r in zip(tests, results, strict=True):
        sub = out_dir / f"{d}_{level_label(lv)}"
        sub.mkdir()
        r[1].to_csv(sub / "timeseries.csv")
        test_list.append({"direction": d, "level_rms": lv,
                          "timeseries": f"{sub.name}/timeseries.csv",
                          "duration_s": float(r[1].duration),
                          "n_averages": int(r[0].n_averages[0])})
    if spec.c3d:
        _write_sessions(out_dir, tests, [r[4] for r in results])
    write_test_list(out_dir, spec.directions, spec.levels, test_list,
                    {"estimator": "H1", "segment_s": SEGMENT_S, "overlap": 0.5,
                     "window": "hann", "band_hz": [0.1, 12.0],
                     "excitation": "random, flat 0.1-12 Hz"},
                    {"translation": "m/m", "rotation": "deg/m"})
    key = {
        "seed": spec.seed,
        **({"session": spec.session} if spec.session else {}),
        **truth,
        "levels_rms": list(spec.levels),
        "directions": spec.directions,
        "duration_s": spec.duration_s,
    }
    if spec.reality == MODEL_REALITY:
        key["settle_summary"] = settled.summary
    key_path.parent.mkdir(parents=True, exist_ok=True)
    key_path.write_text(json.dumps(key, indent=2, default=float) + "\n")
    wall = time.perf_counter() - t0
    prog.say(f"wrote {out_dir} ({len(frf)} FRF rows) and key {key_path} in {wall:.0f} s")
    return SynthResult(out_dir, key_path, frf, key, wall, test_list)


def _write_sessions(out_dir: Path, tests: list, sessions: list) -> None:
    """The tests' C3D sessions and the lab's marker map into out_dir/c3d."""
    import shutil

    from ...analysis.formats.c3d import write_c3d
    from ...analysis.marker_map import EXAMPLE_MARKER_MAP
    from .synth_c3d import C3D_FOLDER, MARKER_MAP_FILENAME

    folder = out_dir / C3D_FOLDER
    folder.mkdir()
    shutil.copyfile(EXAMPLE_MARKER_MAP, folder / MARKER_MAP_FILENAME)
    for (d, lv), session in zip(tests, sessions, strict=True):
        write_c3d(folder / f"{d}_{level_label(lv)}.c3d", session)


def parse_effects_arg(text: str, strength: float | None) -> dict:
    """`--effect a,b` (or `none`) and `--strength S` -> {name: strength}."""
    names = [t.strip() for t in (text or "").split(",") if t.strip()]
    if not names:
        raise SynthError("--effect needs a name (or 'none')")
    if names == ["none"]:
        return {}
    if "none" in names:
        raise SynthError("'none' cannot be combined with other effects")
    s = 1.0 if strength is None else strength
    out = {}
    for n in names:
        if n in out:
            raise SynthError(f"effect {n} given twice")
        out[n] = s
    return out
