"""Transmissibility figures in the layout of the paper's Fig. 6-8.

One figure per loading case (fore-aft x, lateral y, vertical z): a grid of
gain versus frequency, rows pelvis / trunk / head, columns the DoFs the
paper validates for that case (x: x, pitch; y: y, roll, yaw; z: z, pitch).
Model variants are overlaid as lines; measured data, when given, as black
dots with its coherence on a thin axis underneath each panel.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np  # noqa: E402

from .formats import FrfData  # noqa: E402

#: DoFs shown per loading case (Desai et al. Sec. III-A).
CASE_DOFS = {"x": ("x", "pitch"), "y": ("y", "roll", "yaw"), "z": ("z", "pitch")}
CASE_NAMES = {"x": "fore-aft", "y": "lateral", "z": "vertical"}
SEGMENT_ROWS = ("pelvis", "trunk", "head")
_COLORS = ("#c0392b", "#2471a3", "#27ae60", "#8e44ad", "#d68910")


def _unit(dof: str) -> str:
    return "deg/m" if dof in ("roll", "pitch", "yaw") else "m/m"


def plot_case(direction: str, models: dict[str, FrfData], path: str | Path,
              measured: FrfData | None = None, f_max: float = 12.0) -> Path:
    """Figure of one loading case; `models` maps a label to its FrfData."""
    dofs = CASE_DOFS[direction]
    nrow, ncol = len(SEGMENT_ROWS), len(dofs)
    width, height = 3.4 * ncol, 2.6 * nrow + 0.6
    fig = plt.figure(figsize=(width, height))
    # Fixed margins (inches) for the labels and the title, instead of a
    # tight bounding box, which draws the figure twice.
    grid = fig.add_gridspec(2 * nrow, ncol, height_ratios=[4, 1.2] * nrow, hspace=0.45,
                            wspace=0.38, left=0.75 / width, right=1 - 0.15 / width,
                            top=1 - 0.7 / height, bottom=0.5 / height)
    for r, seg in enumerate(SEGMENT_ROWS):
        for c, dof in enumerate(dofs):
            ax = fig.add_subplot(grid[2 * r, c])
            axc = fig.add_subplot(grid[2 * r + 1, c], sharex=ax)
            for i, (label, frf) in enumerate(models.items()):
                sel = frf.select(direction=direction, segment=seg, dof=dof)
                if len(sel):
                    ax.plot(sel.freq_hz, sel.gain, color=_COLORS[i % 5], lw=1.5, label=label)
                    axc.plot(sel.freq_hz, sel.coherence, color=_COLORS[i % 5], lw=0.6)
            if measured is not None:
                sel = measured.select(direction=direction, segment=seg, dof=dof)
                if len(sel):
                    ax.plot(sel.freq_hz, sel.gain, "k.", ms=3, label="measured")
                    axc.plot(sel.freq_hz, sel.coherence, "k-", lw=0.8)
            ax.set_xlim(0, f_max)
            ax.set_title(f"{seg} {dof}", fontsize=9)
            ax.set_ylabel(f"gain ({_unit(dof)})", fontsize=8)
            ax.tick_params(labelsize=7, labelbottom=False)
            ax.grid(alpha=0.3)
            axc.set_ylim(0, 1.05)
            axc.set_yticks([0, 1])
            axc.tick_params(labelsize=6)
            axc.set_ylabel("coh.", fontsize=7)
            if r == nrow - 1:
                axc.set_xlabel("frequency (Hz)", fontsize=8)
            if r == 0 and c == 0:
                ax.legend(fontsize=7)
    fig.suptitle(f"Seat-to-body transmissibility, {CASE_NAMES[direction]} ({direction}) "
                 "excitation", fontsize=11)
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_cases(models: dict[str, FrfData], directory: str | Path,
               measured: FrfData | None = None, prefix: str = "transmissibility") -> list[Path]:
    """One figure per loading case present in the data (paper Fig. 6-8)."""
    present = set()
    for frf in [*models.values(), *([measured] if measured is not None else [])]:
        present |= {d for d in np.unique(frf.direction)}
    return [plot_case(d, models, Path(directory) / f"{prefix}_{d}.png", measured)
            for d in ("x", "y", "z") if d in present]
