"""The seat's kinds (`params.Seat`): the paper's compliant car seat, and the
laboratory seats, rigid, with or without backrest
(`ehm_drake/data/configurations`): what each changes in the parameters
(`apply_seat`) and in the seat's geometry (`remove_backrest`), and the seat
adjusted to the body's static sink on its tissue (`adjust_seat_for_sink`)."""

from __future__ import annotations

import math

import numpy as np

from ..params import ModelParams
from .anthropometry import Body
from .softening import TISSUE_PAIRS

#: A seat without backrest (`params.Seat.backrest` false) keeps its pads this
#: far behind their place (m), clear of the back at any posture the model
#: reaches; their contact pairs and restraints then carry nothing.
BACKREST_CLEARANCE_M = 0.3
BACK_PAD_PARTS = ("lower_pad", "upper_pad")
BACK_PAD_PAIRS = ("lower_back_pad", "upper_back_pad")


def remove_backrest(body: Body) -> None:
    """Move the back pads of `body`'s seat `BACKREST_CLEARANCE_M` back (the
    seat keeps its parts; nothing touches them)."""
    for pad in BACK_PAD_PARTS:
        c, size = body.seat.boxes[pad]
        body.seat.boxes[pad] = (c - np.array([BACKREST_CLEARANCE_M, 0.0, 0.0]), size)


def adjust_seat_for_sink(body: Body, sink: dict) -> None:
    """Lower the floor and the back pads of `body`'s seat by the extra static
    sink of the thighs and of the pelvis (`ehm_drake.model.softening.static_sink`):
    the body on its tissue's long-range stiffness sits deeper in the pan, and
    the seat is adjusted to it as the lab adjusted its pads, so that the legs
    and the back rest where they did with the stiffness at rest."""
    if not sink:
        return
    for part, pair in (("floor", "thighs_pan"), ("lower_pad", "pelvis_pan"),
                       ("upper_pad", "pelvis_pan")):
        c, size = body.seat.boxes[part]
        body.seat.boxes[part] = (c - np.array([0.0, 0.0, sink[pair]]), size)


#: Without back support the trunk's damping gains (pid.spine.kd) are raised by
#: this factor: the paper's trunk, tuned leaning on the pads, has a 0.7 Hz
#: fore-aft sway that the integrator's slow correction destabilises once the
#: pads are gone (unstable at x2, damping ratio 0.03 at x3; checked in
#: tests/test_validation.py).  A modelling choice standing for the
#: co-contraction that holds an unsupported upright trunk, not a measured
#: value.
UNSUPPORTED_TRUNK_DAMPING_FACTOR = 3.0


def apply_seat(params: ModelParams) -> ModelParams:
    """`params` on their seat (`params.seat`): on a rigid seat each contact
    pair of `TISSUE_PAIRS` is the tissue alone, its stiffness the tissue's at
    rest and its damping scaled with the square root of the stiffness (the
    body-on-seat modes keep their damping ratio); without backrest the back
    pads' shear restraints are removed (their anchors would hold the back)
    and the trunk's damping gains raised (`UNSUPPORTED_TRUNK_DAMPING_FACTOR`).
    The car seat (backrest, not rigid) is returned unchanged."""
    if params.seat.backrest and not params.seat.rigid:
        return params
    p = params.copy()
    if p.seat.rigid:
        for pair in TISSUE_PAIRS:
            c = getattr(p.contact, pair)
            k_t = getattr(p.softening.tissue, f"{pair}_stiffness")
            c.damping = c.damping * math.sqrt(k_t / c.stiffness)
            c.stiffness = k_t
    if not p.seat.backrest:
        for pair in ("lower_back_pad", "upper_back_pad"):
            r = getattr(p.restraints, pair)
            r.stiffness, r.damping = 0.0, 0.0
        p.pid.spine.kd = tuple(UNSUPPORTED_TRUNK_DAMPING_FACTOR * k for k in p.pid.spine.kd)
    return p


