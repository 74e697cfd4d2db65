"""The diagnosis report: ``report.json`` (the machine-readable result, the
keys of the issue's interface first), ``report.md`` (for a person) and the
figures

* ``gap_heatmap.png``: gap per channel (direction / segment / DoF) x band
  before and after the best effect; significant cells outlined;
* ``worst_cells.png``: measured transmissibility with its 1-sigma band
  against the refitted base model and the best candidate, for the worst
  significant cells;
* ``ranking.png``: held-out gap reduction and delta-BIC of every candidate.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .reference_group.contrasts import LOW_AGREEMENT
from .single.diagnose import Diagnosis
from .single.localize import BANDS, band_label

#: Keys of the interface (tools outside the package read them), in order.
INTERFACE_KEYS = ("verdict", "best_effect", "ranking", "localization", "gap_before",
                  "gap_after")


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def report_json(diag: Diagnosis, extra: dict | None = None) -> dict:
    r = diag.report
    ordered = {k: r[k] for k in INTERFACE_KEYS}
    ordered.update({k: v for k, v in r.items() if k not in ordered})
    if extra:
        ordered.update(extra)
    return _jsonable(ordered)


def write_report(diag: Diagnosis, out: Path, extra: dict | None = None) -> list[str]:
    """Write report.json, report.md and the figures into `out`; the file
    names written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rep = report_json(diag, extra)
    (out / "report.json").write_text(json.dumps(rep, indent=1) + "\n")
    files = ["report.json"]
    figs = write_figures(diag, out)
    (out / "report.md").write_text(markdown(rep, figs))
    return files + ["report.md"] + figs


def _at_fit(e: dict) -> str:
    """A ranking entry's level-difference gain at its all-rows fit, as the
    reference report shows it ("-" for an effect that does not depend on the
    level; marked where the evidence does not use it)."""
    if not e.get("level_dependent"):
        return "-"
    v = f"{e.get('level_gain_at_fit', 0.0):.0f}"
    return v if e.get("amplitude_driven") else f"{v} (not used)"


def _heldout(e: dict) -> str:
    """A ranking entry's held-out gain, and where an amplitude-driven
    candidate was also scored at its level-only fit's size, that score."""
    v = f"{e['heldout_gain']:.0f}"
    at_level = e.get("heldout_gain_level_fit")
    return v if at_level is None else f"{v} ({at_level:.0f} at the level fit)"


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * x:.0f}%"


def _num(x) -> str:
    return "n/a" if x is None else f"{x:.2f}"


def _num0(x) -> str:
    return "n/a" if x is None else f"{x:.0f}"


def markdown(rep: dict, figures: list[str]) -> str:
    lines = [f"# Sim-to-real gap diagnosis: **{rep['verdict']}**", ""]
    lines.append(rep.get("explanation", ""))
    lines.append("")
    if rep.get("design_caution"):
        lines += [f"Caution: {rep['design_caution']}.", ""]
    gb, ga = rep["gap_before"], rep["gap_after"]
    lines += ["## Gap (excess chi^2 per degree of freedom; 0 = within measurement noise)",
              "", "| | train | held-out |", "|---|---|---|",
              *([f"| given model | {rep['gap_given_model']:.3g} | |"]
                if "gap_given_model" in rep else []),
              f"| {'against the reference group' if rep.get('reference') else 'base refit'} "
              f"(before) | {gb['train']:.3g} | {gb['heldout']:.3g} |",
              f"| with {rep.get('best_candidate') or 'best'} (after) | {ga['train']:.3g} | "
              f"{ga['heldout']:.3g} |", ""]
    lines += ["## Candidates (best first)", "",
              "| effect | delta BIC | gap reduction train | held-out | parameters |",
              "|---|---|---|---|---|"]
    for e in rep["ranking"]:
        par = "; ".join(f"{k}={v:.3g}" for vals in e["params"].values()
                        for k, v in vals.items())
        lines.append(f"| {e['effect']} | {e['delta_bic']:.1f} | "
                     f"{_pct(e['gap_reduction_train'])} | {_pct(e['gap_reduction_heldout'])} "
                     f"| {par} |")
    lines.append("")
    sp = rep.get("structural")
    if sp:
        lines += ["## Model-form gap (smooth discrepancy per direction and channel, shared by "
                  "the levels)", "",
                  f"Scale estimated from the data: {_pct(sp['scale'])}. Held-out gap: base "
                  f"refit {sp['gap_heldout_base']:.3g}, with the discrepancy "
                  f"{sp['gap_heldout_discrepancy']:.3g} ({_pct(sp['discrepancy_share'])} "
                  "removed)" + ("" if sp["ran"] else "; too little for the model-form gap "
                                "to dominate, candidates not re-scored") + ".", ""]
        if sp["ranking"]:
            lines += ["| effect (beyond the discrepancy) | delta BIC | held-out gap | "
                      "removed of what remains | own share of the gap |", "|---|---|---|---|---|"]
            lines += [f"| {e['effect']} | {e['delta_bic']:.1f} | {e['gap_heldout']:.3g} | "
                      f"{_pct(e['reduction_beyond'])} | {_pct(e['effect_share'])} |"
                      for e in sp["ranking"]]
            lines.append("")
        lines += ["| direction | segment | DoF | band | RMS discrepancy |", "|---|---|---|---|---|"]
        lines += [f"| {c['direction']} | {c['segment']} | {c['dof']} | {c['f_lo_hz']:g}-"
                  f"{c['f_hi_hz']:g} Hz | {_pct(c['delta_rms'])} |" for c in sp["cells"][:10]]
        lines.append("")
    ref, mf = rep.get("reference"), rep.get("model_form")
    if ref and mf:
        lines += [f"## Reference group ({ref['size']} subjects)", "",
                  *([f"**Caution:** {ref['caution']}.", ""] if ref.get("caution") else []),
                  "The subject is compared with the group; the model, refit to the group mean "
                  "(re-linearized), gives the shape of each candidate. A candidate is named "
                  "when its evidence -- its held-out chi^2 gain plus, for an effect that "
                  "depends on the level, its gain on the differences between the levels, "
                  "where the subject's structural difference from the group cancels -- "
                  "exceeds the threshold set by the group's own subjects (each against the "
                  "others). An effect driven by the vibration's amplitude (foam, friction, "
                  "co-contraction, softening) loses the evidence its all-rows fit contradicts "
                  "on the level differences (down to zero); tested at two levels, it is also "
                  "scored held out at the size its fit to the level differences gives, and "
                  "the larger score is its evidence. Of the candidates beyond their "
                  "threshold, the one furthest beyond it is named.", "",
                  "| effect | held-out chi^2 gain | level-difference gain | at the all-rows fit "
                  "| evidence | own bound | threshold (with the family-wise test) | beyond |",
                  "|---|---|---|---|---|---|---|---|"]
        lines += [f"| {e['effect']} | {_heldout(e)} | "
                  f"{e.get('level_gain', 0.0):.0f} | "
                  f"{_at_fit(e)} | "
                  f"{e.get('evidence', e['heldout_gain']):.0f} | "
                  f"{_num0(e.get('null_bound'))} | "
                  f"{e['null_threshold']:.0f} | {'yes' if e['beyond_null'] else 'no'} |"
                  for e in rep["ranking"]]
        lines += _contrast_lines(ref.get("contrasts"))
        lines += ["", f"Model-form gap (the model refit to the group against the group mean): "
                  f"RMS log gain {mf['rms_log_gain_difference']:.2f}, phase "
                  f"{mf['rms_phase_difference_deg']:.0f} deg RMS, {mf['significant_cells']} "
                  "cells beyond the group mean's uncertainty; the largest:", "",
                  "| direction | segment | DoF | band | RMS log-gain difference | share |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| {c['direction']} | {c['segment']} | {c['dof']} | {c['f_lo_hz']:g}-"
                  f"{c['f_hi_hz']:g} Hz | {c['rms_log_gain_difference']:.2f} | "
                  f"{_pct(c['share'])} |" for c in mf["cells"][:8]]
        lines.append("")
    if rep.get("separating_experiment"):
        lines += ["## Experiment that would separate the tied candidates", "",
                  rep["separating_experiment"].get("text", ""), ""]
    ev = rep.get("evidence", {})
    if ev.get("level"):
        lines += ["## Level dependence (data alone)", ""]
        for d, e in ev["level"].items():
            lines.append(f"- {d}: levels {e['levels']}, difference gap "
                         f"{e['difference_gap']:.3g}, p = {e['p_value']:.2g}"
                         f"{' (significant)' if e['significant'] else ''}, coherence deficit "
                         f"{e['coherence_deficit']:.3f}")
        lines.append("")
    if ev.get("resonance"):
        lines += _resonance_lines(ev["resonance"], rep.get("level_rule"))
    sig = [c for c in rep["localization"] if c["significant"]]
    lines += [f"## Where the gap lies ({len(sig)} significant cells of "
              f"{len(rep['localization'])})", "",
              "| direction | segment | DoF | band | share | gap before | gap after |",
              "|---|---|---|---|---|---|---|"]
    for c in sig[:20]:
        lines.append(f"| {c['direction']} | {c['segment']} | {c['dof']} | "
                     f"{c['f_lo_hz']:g}-{c['f_hi_hz']:g} Hz | {_pct(c['share'])} | "
                     f"{c['gap']:.3g} | {c['gap_after']:.3g} |")
    lines += ["", "## Figures", ""] + [f"![{f}]({f})" for f in figures]
    m = rep.get("method", {})
    lines += ["", "## Method", "",
              f"Held-out sets ({m.get('folds')}): {', '.join(m.get('heldout_sets', []))}. "
              f"Significance: {m.get('significance')}; model floor "
              f"{m.get('model_floor')}. " + (
                  f"Explained when a candidate's evidence (held-out chi^2 gain plus "
                  f"level-difference gain) exceeds the upper "
                  f"prediction bound of the evidence it reaches on the reference group's own "
                  f"subjects (leave one out; Student t, family-wise alpha "
                  f"{m.get('null_alpha')} over the candidates) and {m.get('min_gain')}, and "
                  f"the subject stands out of the group as a whole: its largest ratio of "
                  f"evidence to scale (a candidate's runner-up among the group and the subject) "
                  f"over the candidates ({_num(m.get('family_subject_score'))}"
                  f") beyond the group's own subjects' ({_num(m.get('family_score'))}, the k-th "
                  f"smallest of them, k = {m.get('family_rank')}; a full conformal test, false "
                  f"alarms at most {_pct(m.get('family_level'))} whatever the evidence's "
                  f"distribution); the "
                  f"candidate furthest beyond its threshold is named; ambiguous when another "
                  f"named one comes within "
                  f"{_pct(m.get('ambiguity_margin'))} of its held-out share."
                  if m.get("design") == "reference group" else
                  f"Explained when the best candidate lowers the held-out chi^2 by more than "
                  f"its parameter penalty (delta BIC < 0) and removes >= "
                  f"{_pct(m.get('explained_reduction'))} of the held-out gap; ambiguous when "
                  f"another candidate comes within {_pct(m.get('ambiguity_margin'))} and the "
                  "level evidence does not separate them."), ""]
    t = rep.get("timing_s")
    if t:
        lines.append(f"Run time {t['total']:.0f} s ({t['families']:.0f} s linear families, "
                     f"{t['fits']:.0f} s fits, {t['workers']} processes).")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------
# Figures
# ---------------------------------------------------------------------------


def _cell_matrix(localization: list[dict], key: str):
    chans = sorted({(c["direction"], c["segment"], c["dof"]) for c in localization})
    idx = {ch: i for i, ch in enumerate(chans)}
    M = np.full((len(chans), len(BANDS)), np.nan)
    S = np.zeros_like(M, dtype=bool)
    for c in localization:
        b = [lo for lo, _ in BANDS].index(c["f_lo_hz"])
        M[idx[(c["direction"], c["segment"], c["dof"])], b] = c[key]
        S[idx[(c["direction"], c["segment"], c["dof"])], b] = c["significant"]
    return chans, M, S


def write_figures(diag: Diagnosis, out: Path) -> list[str]:
    import matplotlib.pyplot as plt

    rep = diag.report
    files = []
    loc = rep["localization"]
    if loc:
        chans, before, sig = _cell_matrix(loc, "gap")
        _, after, _ = _cell_matrix(loc, "gap_after")
        vmax = max(np.nanmax(before), 1.0)
        fig, axes = plt.subplots(1, 2, figsize=(10, 0.22 * len(chans) + 2), sharey=True)
        base_label = "reference group" if rep.get("reference") else "base refit"
        for ax, M, title in ((axes[0], before, f"before ({base_label})"),
                             (axes[1], after, f"after ({rep.get('best_candidate')})")):
            im = ax.imshow(np.log10(1 + np.nan_to_num(M)), aspect="auto", cmap="magma_r",
                           vmin=0, vmax=math.log10(1 + vmax))
            for i, j in zip(*np.nonzero(sig), strict=True):
                ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, ec="tab:blue",
                                           lw=1.5))
            ax.set_xticks(range(len(BANDS)), [band_label(i) for i in range(len(BANDS))],
                          rotation=45, ha="right", fontsize=7)
            ax.set_title(title, fontsize=9)
        axes[0].set_yticks(range(len(chans)), [f"{d}: {s} {q}" for d, s, q in chans],
                           fontsize=6)
        fig.colorbar(im, ax=axes, label="log10(1 + gap)  (gap = excess chi^2 / dof)")
        fig.suptitle(f"Gap per channel x band (blue: significant before); verdict "
                     f"{rep['verdict']}", fontsize=10)
        fig.savefig(out / "gap_heatmap.png", dpi=110)
        plt.close(fig)
        files.append("gap_heatmap.png")
    files += _worst_cells_figure(diag, out)
    if rep["ranking"]:
        names = [e["effect"] for e in rep["ranking"]]
        red = [100 * e["gap_reduction_heldout"] for e in rep["ranking"]]
        dbic = [e["delta_bic"] for e in rep["ranking"]]
        fig, axes = plt.subplots(1, 2, figsize=(10, 0.35 * len(names) + 1.5), sharey=True)
        y = np.arange(len(names))
        axes[0].barh(y, red, color=["tab:green" if r > 0 else "tab:gray" for r in red])
        axes[0].set_xlabel("held-out gap reduction, %")
        axes[0].axvline(100 * rep["method"]["explained_reduction"], color="k", ls="--", lw=0.8)
        axes[1].barh(y, np.sign(dbic) * np.log10(1 + np.abs(dbic)),
                     color=["tab:blue" if d < 0 else "tab:red" for d in dbic])
        axes[1].set_xlabel("sign(dBIC) log10(1 + |dBIC|)  (< 0: supported)")
        axes[0].set_yticks(y, names)
        axes[0].invert_yaxis()
        fig.suptitle("Candidate effects, best first", fontsize=10)
        fig.tight_layout()
        fig.savefig(out / "ranking.png", dpi=110)
        plt.close(fig)
        files.append("ranking.png")
    return files


def _worst_cells_figure(diag: Diagnosis, out: Path, n: int = 6) -> list[str]:
    import matplotlib.pyplot as plt

    rep, rows = diag.report, diag.rows
    cells = [c for c in rep["localization"] if c["significant"]][:n] or rep["localization"][:2]
    if not cells:
        return []
    H0 = diag.results["none"]["H_all"]
    best = rep.get("best_candidate")
    H1 = diag.results[best]["H_all"] if best in diag.results else None
    ncol = min(3, len(cells))
    nrow = math.ceil(len(cells) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.2 * nrow), squeeze=False)
    for ax, c in zip(axes.flat, cells, strict=False):
        chan = (rows.direction == c["direction"]) & (rows.segment == c["segment"]) & \
            (rows.dof == c["dof"])
        levels = sorted({float(v) for v in rows.level[chan]}, key=lambda v: (math.isnan(v), v))
        for k, lv in enumerate(levels):
            m = chan & ((rows.level == lv) if not math.isnan(lv) else np.isnan(rows.level))
            f = rows.freq[m]
            o = np.argsort(f)
            mag = np.abs(rows.H[m])[o]
            sd = np.sqrt(rows.rel_var[m][o]) * mag
            col = f"C{k}"
            ax.fill_between(f[o], mag - sd, mag + sd, color=col, alpha=0.25, lw=0)
            ax.plot(f[o], mag, ".", color=col, ms=2, label=f"measured {lv:g} m/s²")
            ax.plot(f[o], np.abs(H0[m])[o], "--", color=col, lw=1,
                    label="reference group mean" if rep.get("reference") else "base refit")
            if H1 is not None:
                ax.plot(f[o], np.abs(H1[m])[o], "-", color=col, lw=1.2, label=best)
        ax.axvspan(c["f_lo_hz"], c["f_hi_hz"], color="y", alpha=0.15)
        unit = "deg/m" if c["dof"] in ("roll", "pitch", "yaw") else "m/m"
        ax.set_title(f"{c['direction']}: {c['segment']} {c['dof']} (share "
                     f"{100 * c['share']:.0f}%)", fontsize=9)
        ax.set_xlabel("frequency, Hz")
        ax.set_ylabel(f"|T| ({unit})")
        ax.set_xlim(0, 12)
    for ax in list(axes.flat)[len(cells):]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(out / "worst_cells.png", dpi=110)
    plt.close(fig)
    return ["worst_cells.png"]


def _contrast_lines(con: dict | None) -> list[str]:
    """The contrasts' table (`contrasts.contrast_quality`), if any."""
    if not con or not con.get("quality"):
        return []
    lines = ["", f"Contrasts ({con['source']}): the effects above marked `contrasts` are scored "
             "with the change measured on these subjects of the group. Size: the mean change's "
             "RMS per row in units of the group's scatter; agreement: how far each subject's "
             "change follows the others' (1 = the same change); where: the cells where the "
             "subjects' changes agree most.", "",
             "| effect | subjects | size (group SD) | agreement | where (share, RMS log-gain "
             "change) |", "|---|---|---|---|---|"]
    weak = []
    for e, q in con["quality"].items():
        where = "; ".join(f"{c['direction']}: {c['segment']} {c['dof']} {c['f_lo_hz']:g}-"
                          f"{c['f_hi_hz']:g} Hz ({_pct(c['share'])}, "
                          f"{c['rms_log_gain_change']:.2f})" for c in q["cells"])
        lines.append(f"| {e} | {', '.join(q['subjects'])} | {q['rms_change_sd']:.2f} | "
                     f"{q['agreement']:.2f} | {where or '-'} |")
        if q["agreement"] < LOW_AGREEMENT:
            weak.append(e)
    if weak:
        lines += ["", f"The contrasts of {', '.join(weak)} disagree (agreement below "
                  f"{LOW_AGREEMENT:g}): their common change is weaker than what differs between "
                  "the sittings or the subjects. The diagnosis still fits it over all rows at "
                  "once, but more contrast subjects, longer records or a more clearly imposed "
                  "condition would sharpen its signature."]
    return lines


def _resonance_lines(resonance: dict, rule: dict | None = None) -> list[str]:
    """The report's "Resonance against level" section: each direction's
    resonance frequency at its two levels, in the data and the refitted
    model, the factor per doubling of the level, and the single-subject
    level rule's reading of it (`resonance.softening_rule`)."""
    def moves(factor):
        return "rises" if factor > 1 else "falls"

    lines = ["## Resonance against level (the data and the refitted model)", "",
             "| direction | segment | data (Hz) | per doubling | model (Hz) | per doubling |",
             "|---|---|---|---|---|---|"]
    for d, e in resonance.items():
        for seg, v in e["segments"].items():
            cells = []
            for name in ("data", "model"):
                if name in v:
                    lo, hi = v[name]["peak_hz"]
                    cells += [f"{lo:.2f} → {hi:.2f}", f"×{v[name]['per_doubling']:.3f}"]
                else:
                    cells += ["", ""]
            lines.append(f"| {d} | {seg} | " + " | ".join(cells) + " |")
    lines.append("")
    for d, e in resonance.items():
        if "compared" in e:
            fd, fm = e["data_per_doubling"], e["model_per_doubling"]
            lines.append(f"- {d} ({e['levels'][0]:g} → {e['levels'][1]:g} m/s²): the data's "
                         f"resonance {moves(fd)} ×{fd:.3f} per doubling of the level (median "
                         f"of the segments), the refitted model's {moves(fm)} ×{fm:.3f}: the "
                         f"subject softens {e['compared']} the model with level.")
        sc = e.get("scale") or {}
        if sc.get("data_per_doubling") is not None:
            model = (f", the refitted model's ×{sc['model_per_doubling']:.3f}"
                     if sc.get("model_per_doubling") is not None else "")
            lines.append(f"  The whole resonance region ({sc['band_hz'][0]:g}-"
                         f"{sc['band_hz'][1]:g} Hz, every segment) scales "
                         f"×{sc['data_per_doubling']:.3f} per doubling"
                         + (f" (± {sc['data_std']:.3f} from the measurement noise)"
                            if sc.get("data_std") is not None else "") + f"{model}.")
    if rule:
        lines.append(f"- Level rule: the vertical scale's difference {rule['difference']:+.3f} "
                     f"per doubling against {rule['threshold']:+.3g} and {rule['sigmas']:g} "
                     f"noise standard deviations: softening "
                     f"{'named' if rule['named'] else 'not named'}.")
    lines += ["- For comparison, seated people's vertical resonance: about ×0.87 per doubling "
              "from 0.25 to 2 m/s² r.m.s. (Fairley & Griffin 1989, "
              "doi:10.1016/0021-9290(89)90031-6).", ""]
    return lines
