"""`validate`: run the facts' configurations and the supplied datasets'
(`ehm_drake.validation.facts`, `.reference`), judge each fact, compare each
dataset, and write ``validation.json``, ``validation.md`` and the figures.

``validation.json``::

    {"model": {...parameters file, softening, design, duration, seed},
     "facts": [{"id", "source": {"citation", "doi", "read"}, "statement",
                "quantity", "unit", "configuration", "level_rms",
                "expected": {"low", "high", "reason"}, "model",
                "model_linear", "passed", "calibration"}, ...],
     "references": [{"dataset", "label", "provenance", "share_inside_range",
                     "peak_frequency_hz": {...}, "peak_modulus": {...}, ...}],
     "runs": [{"run", "configuration", "excitation", "resonance_hz", ...}],
     "summary": {"facts": n, "passed": n, "publications": n}}
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .facts import FACTS, Fact, Run, runs_for
from .reference import compare, model_curve, read_reference

#: Simulated seconds per run (after settling): 9 Welch averages of 10 s
#: segments at 50% overlap in 50 s; 90 s gives 17.
DEFAULT_DURATION_S = 90.0


class _LinearView:
    """A run's equivalent-linear resonance in the place of its measured one
    (other measures: NaN)."""

    def __init__(self, m):
        self.resonance_hz = m.linear_resonance_hz

    def head_z_at(self, f):
        return math.nan


def _linear_value(fact: Fact, measures: dict) -> float:
    """The fact's value from the runs' equivalent-linear models (resonances
    only; NaN for other quantities)."""
    v = fact.evaluate({k: _LinearView(m) for k, m in measures.items()})
    return float(v) if np.isfinite(v) else math.nan


def judge(facts, measures: dict) -> list[dict]:
    """Each fact's record (see the module docstring)."""
    out = []
    for fact in facts:
        value = float(fact.evaluate(measures))
        lo, hi = fact.expected
        out.append({
            "id": fact.id,
            "source": {"key": fact.source.key, "citation": fact.source.citation,
                       "doi": fact.source.doi, "read": fact.source.read},
            "statement": fact.statement,
            "quantity": fact.quantity,
            "unit": fact.unit,
            "configuration": fact.configuration,
            "level_rms": list(fact.level_rms),
            "expected": {"low": lo, "high": hi, "text": fact.expected_text(),
                         "reason": fact.expected_reason},
            "model": value,
            "model_linear": _linear_value(fact, measures),
            "passed": fact.passed(value),
            "calibration": fact.calibration,
            "runs": list(fact.runs),
        })
    return out


def validate(out: Path, params_path=None, references=(), duration: float = DEFAULT_DURATION_S,
             seed: int = 1, design: str | None = None, workers: int | None = None,
             progress: bool = True, facts=FACTS) -> dict:
    """Run the facts (and the supplied datasets) and write the report into
    the folder `out` (which must exist).  Returns the report."""
    from ..model.softening import describe
    from ..params import load_params
    from .run import run_all

    params = load_params(params_path)
    datasets = [read_reference(p) for p in references]  # (refused before any run)
    runs = runs_for(facts)
    # A dataset measured as a fact's run was (configuration, direction,
    # level, band) is compared with that run; others get their own.
    ref_runs = []
    for i, ds in enumerate(datasets):
        same = [r for r in runs + ref_runs if r.kind == "random" and
                (r.configuration, r.direction, r.level_rms, r.band_hz) ==
                (ds.configuration, ds.direction, ds.level_rms, ds.band_hz)]
        ref_runs.append(same[0] if same else Run(f"reference_{i + 1}", ds.configuration,
                                                 ds.direction, ds.level_rms,
                                                 band_hz=ds.band_hz))
    all_runs = runs + [r for r in dict.fromkeys(ref_runs) if r not in runs]

    def report_progress(done, total, index, result):
        if progress:
            r = all_runs[index]
            print(f"validate: {done}/{total} runs done ({r.describe()}: resonance "
                  f"{result.resonance_hz:.2f} Hz)", flush=True)

    measures = run_all(all_runs, params.to_dict(), duration, seed, design, workers,
                       report_progress)
    fact_records = judge(facts, measures)
    ref_records = []
    for ds, run in zip(datasets, ref_runs, strict=True):
        m = measures[run.key]
        f, mod, phase = model_curve(ds, m, m.frf)
        ref_records.append(compare(ds, f, mod, phase))
    report = {
        "model": {"params": str(params_path) if params_path else "default",
                  "softening": describe(params),
                  "design": design or params.simulation.design,
                  "duration_s": duration, "seed": seed},
        "facts": fact_records,
        "references": ref_records,
        "runs": [m.to_dict() for m in measures.values()],
        "summary": {"facts": len(fact_records),
                    "passed": sum(r["passed"] for r in fact_records),
                    "publications": len({r["source"]["key"] for r in fact_records})},
    }
    out = Path(out)
    (out / "validation.json").write_text(json.dumps(report, indent=2))
    figures = _figures(out, measures, datasets, ref_runs)
    (out / "validation.md").write_text(_markdown(report, figures))
    return report


def _figures(out: Path, measures: dict, datasets, ref_runs) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = []
    groups = [("rigid seat, no backrest", [k for k in measures if k.startswith("rigid_")
                                           and "back" not in k and "2-20" not in k]),
              ("rigid seat, rigid backrest", [k for k in measures
                                              if k.startswith("rigid_back")])]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, (title, keys) in zip(axes, groups, strict=True):
        for k in sorted(keys, key=lambda k: measures[k].run.level_rms):
            m = measures[k]
            sel = (m.freq_hz >= 0.5) & (m.freq_hz <= 12)
            ax.plot(m.freq_hz[sel], m.apparent_mass[sel],
                    label=f"{m.run.level_rms:g} m/s$^2$ ({m.resonance_hz:.1f} Hz)")
        ax.set_title(title)
        ax.set_xlabel("frequency (Hz)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_ylabel("normalized apparent mass (-)")
    fig.suptitle("Vertical apparent mass against vibration magnitude (model)")
    fig.tight_layout()
    fig.savefig(out / "apparent_mass_vs_magnitude.png", dpi=110)
    plt.close(fig)
    names.append("apparent_mass_vs_magnitude.png")

    fig, ax = plt.subplots(figsize=(6, 4))
    for k in sorted((k for k in measures if k.startswith("rigid_") and "back" not in k
                     and "2-20" not in k), key=lambda k: measures[k].run.level_rms):
        m = measures[k]
        sel = (m.freq_hz >= 0.5) & (m.freq_hz <= 12)
        ax.plot(m.freq_hz[sel], m.head_z[sel], label=f"{m.run.level_rms:g} m/s$^2$")
    for m in measures.values():
        if m.run.kind == "sine":
            ax.plot([m.run.frequency_hz], [m.head_z_at(m.run.frequency_hz)], "o",
                    label=f"car seat, {m.run.frequency_hz:g} Hz sine, "
                          f"{m.run.level_rms:g} m/s$^2$")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("seat-to-head vertical transmissibility (m/m)")
    ax.set_title("Seat-to-head transmissibility against magnitude (rigid seat)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "head_transmissibility_vs_magnitude.png", dpi=110)
    plt.close(fig)
    names.append("head_transmissibility_vs_magnitude.png")

    for i, (ds, run) in enumerate(zip(datasets, ref_runs, strict=True), 1):
        m = measures[run.key]
        f, mod, _ = model_curve(ds, m, m.frf)
        fig, ax = plt.subplots(figsize=(6, 4))
        ax.fill_between(ds.freq_hz, ds.lower, ds.upper, alpha=0.3, label="measured range")
        ax.plot(ds.freq_hz, ds.mean, "k", label="measured mean")
        sel = (f >= 0.5) & (f <= 12)
        ax.plot(f[sel], mod[sel], "C1", label="model")
        ax.set_xlabel("frequency (Hz)")
        ax.set_ylabel("modulus")
        ax.set_title(ds.label, fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        name = f"reference_{i}.png"
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
        names.append(name)
    return names


def _fmt(v) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.3g}"


def _markdown(report: dict, figures: list[str]) -> str:
    s = report["summary"]
    lines = ["# Validation against published facts", "",
             f"Model: {report['model']['params']} parameters, {report['model']['softening']}; "
             f"{report['model']['design']} design; {report['model']['duration_s']:g} s per run.",
             "", f"**{s['passed']} of {s['facts']} facts reproduced**, from "
             f"{s['publications']} publications.", "",
             "| fact | quantity | expected | model | linear | passed |",
             "|---|---|---|---|---|---|"]
    for r in report["facts"]:
        lines.append(f"| {r['id']} | {r['quantity']} | {r['expected']['text']} | "
                     f"{_fmt(r['model'])} | {_fmt(r['model_linear'])} | "
                     f"{'yes' if r['passed'] else '**no**'} |")
    lines += ["", "## The facts", ""]
    for r in report["facts"]:
        lines += [f"**{r['id']}**: {r['statement']}",
                  f"Source: {r['source']['citation']}, doi:{r['source']['doi']} "
                  f"(read: {r['source']['read']}).",
                  f"Configuration: {r['configuration']}.",
                  f"Expected {r['expected']['text']} ({r['expected']['reason']}); "
                  f"the model: {_fmt(r['model'])}.",
                  *( [f"Used to set the model's parameters: {r['calibration']}."]
                     if r["calibration"] else []), ""]
    if report["references"]:
        lines += ["## Supplied datasets", "",
                  "| dataset | inside range | peak f data / model (Hz) | peak modulus "
                  "data / model |", "|---|---|---|---|"]
        for r in report["references"]:
            pf, pm = r["peak_frequency_hz"], r["peak_modulus"]
            lines.append(f"| {r['label']} | {100 * r['share_inside_range']:.0f}% | "
                         f"{pf['data']:.2f} / {pf['model']:.2f} | {pm['data']:.3g} / "
                         f"{pm['model']:.3g} |")
        lines.append("")
    lines += ["## Figures", ""] + [f"![{f}]({f})" for f in figures] + [
        "", "## What remains unknown", "",
        "Without measured curves the whole frequency response (gain and phase of every "
        "channel), the peak moduli and the spread between people are not checked here; "
        "supply a dataset with `--reference FILE` (format: `ehm_drake.validation.reference`).",
        ""]
    return "\n".join(lines)


__all__ = ["DEFAULT_DURATION_S", "judge", "validate"]
