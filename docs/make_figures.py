"""Regenerate the README's figures: `python docs/make_figures.py`."""

from __future__ import annotations

from pathlib import Path

from ehm_drake.diagram import build_diagram
from ehm_drake.params import load_params
from ehm_drake.plots import plot_posture
from ehm_drake.simulation import settle

HERE = Path(__file__).resolve().parent


def main() -> None:
    params = load_params()
    model = build_diagram(params, guard=False)
    states = {v: settle(params, variant=v).positions
              for v in ("default", "no-integrator", "high-stiffness")}
    plot_posture(model, {"default (PID with integrator + HIS)": states["default"],
                         "no-integrator": states["no-integrator"],
                         "high-stiffness": states["high-stiffness"]},
                 HERE / "posture_variants.png",
                 "EHM on the seat after 5 s settling (cf. paper Fig. 5)")


if __name__ == "__main__":
    main()
