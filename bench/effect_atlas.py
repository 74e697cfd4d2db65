"""Where each hidden effect acts on an independent reality, and how much of it
the EHM's candidate of the same name can represent.

For a finished blind run with a reference group (`ehm-drake blind --reality
NAME --references K`), each single-effect trial has its data and its twin
(the same subject without the effect).  The reality's effect signature is
their difference, s_r = log H(trial) - log H(twin) on the group's rows; the
EHM candidate's signature s_c is its change of log H at the group's anchor
(`gap.reference._Scorer`) at a strength on its plausible path or at the far
end of its bounds.  Both are whitened by the group's scatter per row (w =
1 / sd), so |w s|^2 is the chi^2 of the effect alone against the group.

Per effect the table gives: the reality's chi^2 and its shares per
excitation direction and in its largest channels; the candidate's, at
strength 0.7; and the share of the reality's effect that lies along the
candidate's signature, max over the strength path and the far end of the
bounds of cos^2 = (Re <w s_r, w s_c>)^2 / (|w s_r|^2 |w s_c|^2), averaged over the
trials (1: the candidate can reproduce the effect's shape up to its size; 0:
it acts elsewhere).  A linear measure: it ignores the base refit and the
nuisance directions the diagnosis also fits.  "On gap": the share of each
chi^2 on rows where the anchor itself differs from the group mean by more
than a factor of 2 (|log H_anchor - mean log H| > ln 2, gain and phase as
one complex number), where the model's form is most in doubt.

"Reach": the share of the reality's effect that lies in the span of the
model's first-order changes at the anchor, that is of everything a fit of
the model's parameters could absorb to first order: the base parameters'
directions (`--span`, the fit registry's groups or names; default the
diagnosis' 20), and those with the candidate's signatures added (mean over
the trials of |P s_r|^2 / |s_r|^2, P the real least-squares projection).
What lies outside acts through structure the model does not have; no
signature this model computes can name it, whatever its form.

"Delay parts" (`--delay-parts`, for `reflex_delay` trials): could another
delay in the model follow the reality's?  The signatures of a delay of 10,
20 and 30 ms on one part of the model's cut-open feedback at a time (the
head-in-space controller, the neck, spine or leg PIDs' proportional paths,
all of the feedback as the candidate delays it), and of a reflex loop the
model does not have: the PIDs' proportional paths again, through a 30 ms
delay and a 40 ms first-order activation (Winters & Stark 1985), as
stiffness and as rate feedback (two directions, to first order in its
gain).  Per part: its chi^2 at the three delays, its share along the
reality's effect (mean best cos^2) and the reach of the base directions
with its signatures added.

    python bench/effect_atlas.py BLIND_RUN_DIR [--out atlas.json]
        [--reference DIR ...] [--span passive,pid,his,contact,restraints]
        [--delay-parts]

Families and the anchor come from the diagnosis' caches (the run's
diagnoses made them); without them they are built (minutes).
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from ehm_drake.gap.library.family import linearize_cut
from ehm_drake.gap.library.models import STRENGTH_PATH, Candidate
from ehm_drake.gap.reference_group.anchor import fit_anchor
from ehm_drake.gap.reference_group.group import load_reference, wrap_log
from ehm_drake.gap.reference_group.reference import _Scorer
from ehm_drake.gap.single.diagnose import (
    DiagnosisError,
    candidate_names,
    load_families,
    load_lab_data,
    separation_slope,
)
from ehm_drake.identification.parameters import resolve_free
from ehm_drake.model.anthropometry import REFERENCE
from ehm_drake.params import ParameterError, load_params, params_from_dict

SHOWN_STRENGTH = 0.7


def shares(chi: np.ndarray, directions: np.ndarray, channels: np.ndarray, top: int = 4):
    """(total chi^2, {direction: share}, [(direction:channel, share)] largest first)."""
    total = float(chi.sum())
    if not total > 0:
        return 0.0, {}, []
    by_dir = {d: float(chi[directions == d].sum() / total) for d in sorted(set(directions))}
    by_ch = defaultdict(float)
    for d, c, v in zip(directions, channels, chi, strict=True):
        by_ch[f"{d}:{c}"] += float(v)
    largest = sorted(by_ch.items(), key=lambda kv: -kv[1])[:top]
    return total, by_dir, [(k, v / total) for k, v in largest]


def cos2(a: np.ndarray, b: np.ndarray) -> float:
    """Share of whitened complex signature a along b (real inner product)."""
    na, nb = float(np.sum(np.abs(a) ** 2)), float(np.sum(np.abs(b) ** 2))
    if not (na > 0 and nb > 0):
        return 0.0
    return float(np.sum((np.conj(a) * b).real)) ** 2 / (na * nb)


#: The step of each base parameter's first-order direction (its
#: coordinate, the log of its scale): small enough that log H is linear in
#: it (the families are linear in the parameters), large enough to stay
#: clear of rounding.
REACH_STEP = 0.02


def _real(z: np.ndarray) -> np.ndarray:
    """A complex vector as the real one of its real and imaginary parts (the
    real inner product the diagnosis' fits use)."""
    return np.concatenate([z.real, z.imag], axis=0)


def base_directions(scorer: _Scorer, w: np.ndarray, names) -> np.ndarray:
    """Whitened first-order change of log H at the anchor per base
    parameter in `names` (one real column each, in that order)."""
    pred = scorer._predictor(Candidate(()))
    cols = []
    for i in (scorer.base_names.index(n) for n in names):
        theta = scorer.theta0.copy()
        theta[i] = REACH_STEP
        pred.update_statistics(theta)
        cols.append(_real(wrap_log(np.log(pred.predict(theta)) - scorer.log0) * w)
                    / REACH_STEP)
    return np.stack(cols, axis=1)


def span_share(basis: np.ndarray, s: np.ndarray) -> float:
    """Share of |s|^2 (s complex, whitened) in the real span of `basis`."""
    y = _real(s)
    ny = float(y @ y)
    if not ny > 0:
        return 0.0
    coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
    fit = basis @ coef
    return float(fit @ fit) / ny


def along_and_reach(basis: np.ndarray, sigs, truths) -> tuple[float, float]:
    """Mean over the reality's effects `truths` of their best cos^2 along
    one of the signatures `sigs`, and of their share in the span of
    `basis` with the signatures added (whitened, complex)."""
    along = float(np.mean([max(cos2(s, v) for v in sigs) for s in truths]))
    with_sigs = np.hstack([basis, np.stack([_real(v) for v in sigs], axis=1)])
    return along, float(np.mean([span_share(with_sigs, s) for s in truths]))


def _zero_gains(section: str, groups, gains=("kp",)):
    def off(d: dict) -> None:
        for g in groups:
            block = d[section] if g is None else d[section][g]
            for k in gains:
                block[k] = [0.0] * len(block[k])
    return off


#: The parts of the model's feedback a delay can act on (`--delay-parts`),
#: each as the change of the parameter dict that switches it off.  (Only
#: the proportional paths run through the cut-open feedback: the PIDs'
#: derivative is the plant's joint damping, their integral a state.)
FEEDBACK_PARTS = {
    "head_in_space": _zero_gains("his", [None], ("kp", "kd")),
    "neck_pid": _zero_gains("pid", ["neck"]),
    "spine_pid": _zero_gains("pid", ["spine"]),
    "leg_pids": _zero_gains("pid", ["hips", "knees", "ankles"]),
}
PID_PARTS = ("neck_pid", "spine_pid", "leg_pids")
#: Delays of the parts' signatures (s).
PART_DELAYS_S = (0.01, 0.02, 0.03)
#: The reflex loop of `--delay-parts`: transport delay and activation time
#: constant (s; short-latency stretch reflexes 20-40 ms, excitation-
#: contraction 20-60 ms), and the gain of its first-order directions (a
#: share of the PIDs' proportional gains: small enough for first order).
REFLEX_DELAY_S, REFLEX_ACTIVATION_S, REFLEX_GAIN = 0.03, 0.04, 0.01


def feedback_parts(params) -> dict:
    """The cut-open feedback Bw K of the model at `params` split by part
    (`FEEDBACK_PARTS`: what switching each off removes from it; "all": the
    whole, as `reflex_delay` delays it)."""
    full = linearize_cut(params)
    BwK = full.Bw @ full.K
    parts = {}
    for name, off in FEEDBACK_PARTS.items():
        d = params.to_dict()
        off(d)
        lin = linearize_cut(params_from_dict(d))
        if lin.A.shape != full.A.shape:
            raise RuntimeError(f"switching {name} off changed the model's states")
        parts[name] = BwK - lin.Bw @ lin.K
    parts["all"] = BwK
    return parts


def loop_response(A, Bu, Bw, C, K, h: float, freqs_hz, inputs, rows, loops) -> np.ndarray:
    """H = C (zI - A - Bw K - sum_k g_k(f) M_k)^-1 Bu[:, inputs] at z = exp(j
    2 pi f h), shape (nf, ny, len(inputs)): the closed loop with extra
    feedback terms, `loops` = [(M_k, g_k)], M_k a square matrix acting on
    the leading states (a part of Bw K delayed by d: g = exp(-j w d) - 1; a
    loop the model lacks: its own transfer function)."""
    f = np.asarray(freqs_hz, float)
    z = np.exp(2j * np.pi * f * h)
    n = A.shape[0]
    L0 = A + Bw @ K
    Ms = []
    for M, g in loops:
        Mp = np.zeros((n, n))
        Mp[:M.shape[0], :M.shape[1]] = M
        Ms.append((Mp, g))
    Cr, Bj = C[rows], Bu[:, inputs].astype(complex)
    out = np.empty((len(f), Cr.shape[0], len(inputs)), complex)
    for k in range(len(f)):
        L = L0 + sum(g(f[k], z[k]) * M for M, g in Ms)
        out[k] = Cr @ np.linalg.solve(z[k] * np.eye(n) - L, Bj)
    return out


def delay_of(d_s: float):
    return lambda f, z: np.exp(-2j * np.pi * f * d_s) - 1.0


def reflex_path(rate: bool, h: float):
    """The reflex loop's transfer from the joint angle error (or its
    backward-difference rate) to its share of the PID's torque."""
    def g(f, z):
        c = REFLEX_GAIN * np.exp(-2j * np.pi * f * REFLEX_DELAY_S) / (
            1.0 + 2j * np.pi * f * REFLEX_ACTIVATION_S)
        return c * (1.0 - 1.0 / z) / h if rate else c
    return g


def delay_part_table(scorer: _Scorer, params, w, basis, truths) -> dict:
    """`--delay-parts`: per part of the feedback (and the reflex loop) its
    chi^2, share along the reality's effect and reach (module docstring)."""
    parts = feedback_parts(params)
    pred = scorer._predictor(Candidate(()))
    pred.update_statistics(scorer.theta0)
    h = pred.family.h
    loops = []

    def with_loops(mats, coords, freqs, inputs, rows):  # the base model plus `loops`
        return loop_response(*mats, h, freqs, inputs, rows, loops)

    pred._response = with_loops

    def signature(new_loops, scale: float = 1.0) -> np.ndarray:
        loops[:] = new_loops
        log_h = np.log(pred.predict(scorer.theta0))
        loops.clear()
        return wrap_log(log_h - scorer.log0) * w / scale

    def entry(sigs, chi2_scale: float = 1.0) -> dict:
        along, reach = along_and_reach(basis, sigs, truths)
        return {"chi2": [float(np.sum(np.abs(v * chi2_scale) ** 2)) for v in sigs],
                "along": along, "reach": reach}

    out = {name: entry([signature([(M, delay_of(d))]) for d in PART_DELAYS_S])
           for name, M in parts.items()}
    pid = sum(parts[p] for p in PID_PARTS)
    out["reflex_loop"] = entry([signature([(pid, reflex_path(rate, h))], REFLEX_GAIN)
                                for rate in (False, True)], REFLEX_GAIN)
    return out


def _xyz(by_dir: dict) -> str:
    return "/".join(f"{100 * by_dir.get(k, 0.0):.0f}" for k in "xyz")


def _top2(largest: list) -> str:
    return ", ".join(f"{k} {100 * v:.0f}%" for k, v in largest[:2])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--reference", type=Path, nargs="+", default=None,
                    help="the reference group's folders (default: the run's reference/); "
                         "e.g. the run's and another run's, for a larger group")
    ap.add_argument("--span", default="default",
                    help="the base parameters whose first-order directions the reach "
                         "spans: groups or names of the fit registry (default: the "
                         "diagnosis' 20)")
    ap.add_argument("--delay-parts", action="store_true",
                    help="for reflex_delay trials: a delay on each part of the model's "
                         "feedback, and a reflex loop it lacks (module docstring)")
    args = ap.parse_args()
    refs = args.reference or [args.run / "reference"]
    if args.reference is None and not refs[0].is_dir():
        raise SystemExit(f"{args.run}: no reference group (reference/); the atlas needs a "
                         "finished `ehm-drake blind --reality NAME --references K` run "
                         "(or --reference)")
    try:
        span = [f.name for f in resolve_free(args.span)]
    except ParameterError as e:
        raise SystemExit(f"--span: {e}") from None
    try:
        group = load_reference(refs)
    except (FileNotFoundError, DiagnosisError) as e:
        raise SystemExit(f"--reference: {e}" if args.reference else str(e)) from None
    rows = group.rows
    w = 1.0 / np.sqrt(np.maximum(group.variance, 1e-12))
    directions = np.asarray(rows.direction).astype(str)
    channels = np.array([f"{s}_{d}" for s, d in zip(rows.segment, rows.dof, strict=True)])

    # The reality's effects, from the single-effect trials and their twins.
    truth = defaultdict(list)
    for tdir in sorted(args.run.glob("trial_*")):
        rfile = tdir / "result.json"
        if not rfile.is_file() or not (tdir / "twin_data" / "frf.csv").is_file():
            continue
        res = json.loads(rfile.read_text())
        if "skipped" in res or len(res["hidden"]) != 1:
            continue
        a, b = load_lab_data(tdir / "data"), load_lab_data(tdir / "twin_data")
        s = wrap_log(np.log(a.rows.H[group.align(a)]) - np.log(b.rows.H[group.align(b)]))
        truth[next(iter(res["hidden"]))].append(s * w)

    if not truth:
        raise SystemExit(f"{args.run}: no scored single-effect trial with twin data "
                         "(trial_*/result.json and trial_*/twin_data/frf.csv); twins are "
                         "made on independent realities only")

    # The EHM candidates at the group's anchor (cached by the run's diagnoses).
    params = load_params()
    names = [n for n in candidate_names(None) if n in truth]
    base_names = [f.name for f in resolve_free("default")]
    # (The anchor is the diagnosis' own, refit on its 20 parameters; the
    # span's directions are taken there, whatever --span frees.)
    base_names = [*base_names, *(n for n in span if n not in base_names)]
    anchor = fit_anchor(group, params, REFERENCE, workers=args.workers, progress=None,
                        use_cache=True)
    families = load_families(anchor["params"], REFERENCE, names, base_names, args.workers,
                             None, True)
    scorer = _Scorer(group, families, separation_slope(anchor["params"], REFERENCE),
                     base_names)

    # Rows where the anchor misses the group by more than a factor of 2.
    on_gap = np.abs(wrap_log(scorer.log0 - group.mean_log)) > np.log(2.0)
    basis = base_directions(scorer, w, span)
    print(f"the anchor differs from the group mean by more than a factor 2 on "
          f"{100 * on_gap.mean():.0f}% of the rows")
    table = {}
    print(f"{args.run.name}: effect, trials; the reality's chi^2 and shares x/y/z; the EHM "
          f"candidate's at strength {SHOWN_STRENGTH}; the reality's effect along the "
          "candidate (mean cos^2, best strength); the shares of the reality's and the "
          "candidate's chi^2 on rows where the anchor misses the group by more than 2x; "
          f"reach: the share of the reality's effect in the span of the {len(span)} base "
          "parameters' first-order directions, and with the candidate's signatures")
    for name in names:
        cand = Candidate(tuple(name.split("+")))
        sig, refresh, lo, hi = scorer.signature_fn(cand)
        sigs = {}
        # The strength path, and the far end of the bounds (where a
        # separation's pads leave: on the path they stay in contact), on the
        # side the path goes, as `_Scorer.score` takes it.
        starts = {s: np.clip(cand.start_grid((s,))[0], lo, hi)
                  for s in sorted({*STRENGTH_PATH, SHOWN_STRENGTH})}
        off = cand.start_grid((0.0,))[0]
        starts["far"] = np.where(cand.start_grid((1.0,))[0] >= off, hi, lo)
        for key, c in starts.items():
            refresh(c)
            sigs[key] = sig(c) * w
        r_chi = np.mean([np.abs(s) ** 2 for s in truth[name]], axis=0)
        r_tot, r_dir, r_top = shares(r_chi, directions, channels)
        c_chi = np.abs(sigs[SHOWN_STRENGTH]) ** 2
        c_tot, c_dir, c_top = shares(c_chi, directions, channels)
        along, with_cand = along_and_reach(basis, list(sigs.values()), truth[name])
        reach = (float(np.mean([span_share(basis, s) for s in truth[name]])), with_cand)
        r_gap = float(r_chi[on_gap].sum() / r_tot) if r_tot > 0 else 0.0
        # (None: no signature at that strength, e.g. a separation whose pads
        # stay in contact, a level-dependent friction at the anchor.)
        c_gap = float(c_chi[on_gap].sum() / c_tot) if c_tot >= 1.0 else None
        table[name] = {"trials": len(truth[name]),
                       "reality": {"chi2": r_tot, "directions": r_dir, "channels": r_top},
                       "candidate": {"strength": SHOWN_STRENGTH, "chi2": c_tot,
                                     "directions": c_dir, "channels": c_top},
                       "along_candidate": along,
                       "on_anchor_gap": {"reality": r_gap, "candidate": c_gap},
                       "reach": {"span": span, "base": reach[0],
                                 "with_candidate": reach[1]}}
        print(f"  {name:22s} {len(truth[name])}  reality {r_tot:8.0f} ({_xyz(r_dir)}; "
              f"{_top2(r_top)})  candidate {c_tot:8.0f} ({_xyz(c_dir)}; {_top2(c_top)})  "
              f"along {along:.2f}  on gap {100 * r_gap:.0f}%/"
              f"{'-' if c_gap is None else f'{100 * c_gap:.0f}%'}  "
              f"reach {reach[0]:.2f}/{reach[1]:.2f}")
    if args.delay_parts and "reflex_delay" in truth:
        parts = delay_part_table(scorer, anchor["params"], w, basis, truth["reflex_delay"])
        print("reflex_delay: a delay of 10/20/30 ms on one part of the model's feedback (chi^2 "
              "of its signature at each; the reality's effect along it, mean best cos^2; "
              "reach with the base directions), and the reflex loop it lacks (stiffness and "
              f"rate paths, {1e3 * REFLEX_DELAY_S:g} ms delay, {1e3 * REFLEX_ACTIVATION_S:g} "
              f"ms activation; chi^2 at {100 * REFLEX_GAIN:g}% of the PIDs' gains)")
        for name, v in parts.items():
            chi2 = " / ".join(f"{c:,.0f}" if c >= 100 else f"{c:.3g}" for c in v["chi2"])
            print(f"  {name:14s} chi^2 {chi2}  "
                  f"along {v['along']:.2f}  reach {v['reach']:.2f}")
        table["reflex_delay"]["delay_parts"] = parts
    elif args.delay_parts:
        print("--delay-parts: no reflex_delay trial in this run")
    if args.out:
        args.out.write_text(json.dumps(table, indent=1) + "\n")


if __name__ == "__main__":
    main()
