"""The linear FRF against the transmissibility estimated from the nonlinear
time simulation at small amplitude (modal issue acceptance): the
equivalent-linear model at the test's level, since the body softens with
its movement (`ehm_drake.model.softening`), both on the commands' default
(implicit) design (the paper's reference design passes with errors as small:
docs/history/2026-12-05-guard-levels-checks-lumped-group.md).

The seat signal is a multisine (0.05 Hz grid, 0.1-12 Hz, seeded phases,
0.05 m/s^2 RMS, 60 s): its 20 s period makes the H1 estimate over whole
periods (rectangular window, no overlap, no band filter) free of leakage
bias, so the comparison measures the model, not the estimator.  The first
period holds the onset and the transients; the two after it are averaged
(in steady state every period is the same: the worst errors agree to four
digits with 2, 3 or 5 averaged periods).  (With
random excitation the same check is limited by H1's resolution bias at the
sharp lateral peak, ~10% at 0.075 Hz resolution.)"""

from __future__ import annotations

import numpy as np
import pytest

from ehm_drake.analysis.equivalent import SeatSpectrum, equivalent_linear
from ehm_drake.analysis.transmissibility import transmissibility
from ehm_drake.diagram import build_diagram
from ehm_drake.signals import make_seat_signal
from ehm_drake.simulation import static_equilibrium, vibrate
from ehm_drake.systems.outputs import CHANNEL_NAMES

#: Module fixtures: the module's tests stay on one xdist worker (built once).
pytestmark = pytest.mark.xdist_group("linear_vs_nonlinear")

DOMINANT = {"x": [("head", "x"), ("head", "pitch"), ("trunk", "x")],
            "y": [("head", "y"), ("head", "roll")],
            "z": [("pelvis", "z"), ("head", "z")]}
PERIOD_S = 20.0
AVERAGED = 2  # periods averaged after the first


@pytest.fixture(scope="module")
def design(params):
    """The parameters on the commands' default design (`accurate_step`) and
    the body settled there."""
    from ehm_drake.diagram import accurate_step
    from ehm_drake.simulation import settle

    p = accurate_step(params)
    return p, settle(p)


@pytest.fixture(scope="module")
def linear_model(design):
    """The equivalent-linear model at the multisine's level in each
    direction (the body softens with its movement, `model.softening`)."""
    params = design[0]
    model = build_diagram(params, guard=False)
    ctx, _ = static_equilibrium(model)
    return {d: equivalent_linear(model, SeatSpectrum.flat(d, 0.05, (0.1, 12.0)), ctx).linear
            for d in "xyz"}


@pytest.mark.slow
@pytest.mark.parametrize("direction", ["x", "y", "z"])
def test_linear_frf_matches_nonlinear_simulation(design, linear_model, direction):
    params, settled_default = design
    s = params.simulation
    sig = make_seat_signal("multisine", direction, 0.05, 3 * PERIOD_S, 21, s.time_step_s,
                           s.settle_time_s, s.onset_time_s)
    run = vibrate(params, settled_default, sig)
    # Whole periods after the first (onset and transients).
    steady = run.after(sig.settle_time + PERIOD_S)
    n = int(round(PERIOD_S * steady.sample_rate))
    steady = steady.after(steady.times[0])
    ts = steady.to_timeseries()
    assert len(ts.t) >= AVERAGED * n  # whole periods only
    ts = type(ts)(ts.t[:AVERAGED * n], ts.seat_acc[:AVERAGED * n],
                  {k: v[:AVERAGED * n] for k, v in ts.channels.items()}, ts.meta)
    est = transmissibility(ts, band=None, nperseg=n, noverlap=0, window="boxcar", f_min=0.075)
    worst = 0.0
    for seg, dof in DOMINANT[direction]:
        f, gain, _, coh = est.get(direction, seg, dof)
        lines = np.abs(f / 0.05 - np.round(f / 0.05)) < 1e-6  # excited lines
        ok = lines & (coh > 0.9) & (f >= 0.1)
        assert ok.sum() > 100, (seg, dof)
        c = CHANNEL_NAMES.index(f"{seg}_{dof}")
        lin = np.abs(linear_model[direction].transmissibility_array(f[ok], direction)[:, c, 0])
        # Near the channel's peak the error is judged relative to the gain; on
        # its flanks (below a quarter of the peak) relative to a quarter of
        # the peak: there the softening's running estimate of the movement,
        # which fluctuates, scatters the small gains bin by bin with both
        # signs (head pitch under x at 6.5-6.7 Hz, 12-15% of its peak:
        # -8% and +11% in neighbouring bins), while the bias the equivalent-
        # linear model could have shows in the median.
        scale = np.maximum(lin, 0.25 * np.max(lin))
        err = np.abs(gain[ok] - lin) / scale
        big = lin > 0.1 * np.max(lin)
        median = np.median(np.abs(gain[ok][big] - lin[big]) / lin[big])
        worst = max(worst, err.max())
        assert err.max() < 0.10, (seg, dof, err.max())
        assert median < 0.03, (seg, dof, median)
    print(f"\ndirection {direction}: worst relative gain error {worst:.4f}")
