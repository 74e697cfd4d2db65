"""The anchor of a reference-group diagnosis: the model refit to the group.

The candidates' signatures against a reference group (`reference`) come
from the model, so they should come from a model that resonates where the
group does.  `fit_anchor` refits the base parameters (the default 20,
within their physiological bounds) to the group's mean transmissibility,
re-linearizing after every step and keeping a step only where the model
linearized anew fits the group better (a trust region, since the
first-order model of 20 parameters far from the nominal body overshoots).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np

from ...identification.parameters import apply_scales, resolve_free, scale_bounds
from ...model.anthropometry import BodyMeasures
from ...params import ModelParams
from ..library.models import Candidate, Predictor, Statics, fit_candidate, residuals
from ..single.diagnose import _code_fingerprint, cache_dir, load_families, separation_slope
from ..single.localize import MODEL_FLOOR

#: Linearizations of the anchor fit, at most.  Each fits an increment of
#: the log-scales on the model linearized at the current point, then the
#: model is linearized again at the new point, where the fit's true cost is
#: measured: a step that does not lower it is taken back and the trust
#: radius halved.  Before this the fit took three steps without that check:
#: on a `lumped` group of 16 its true cost rose on the last step (909k to
#: 964k on the implicit design) and the two designs' anchors differed by up
#: to a factor of 2 in the pan restraints' stiffness.
ANCHOR_ITERATIONS = 10
#: Largest change of a log-scale in one step at first (0.7: a factor of 2),
#: halved at each rejected step; the fit ends below `ANCHOR_MIN_TRUST`.
ANCHOR_TRUST = 0.7
ANCHOR_MIN_TRUST = 0.05
#: The fit ends when a step lowers the true cost by less than this share.
ANCHOR_TOLERANCE = 0.01
#: Version of the cached anchors' content (its key before the move from
#: `reference`, so that anchors already cached stay valid; 3: the fit
#: with the true cost checked at every step).
ANCHOR_CACHE_VERSION = "3"


def write_cache_json(path: Path, obj) -> None:
    """Cache `obj` at `path`, whole or not at all (a run stopped while
    writing leaves no cut file; a cache that cannot be written is skipped)."""
    from ...sweep.store import atomic_write

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, json.dumps(obj))
    except OSError:
        pass


def read_cache_json(path: Path):
    """The object cached at `path`; None when there is none or it cannot be
    read (computed again and cached over it)."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


class _BoundedPredictor(Predictor):
    """A base-only predictor whose log-scales stay within the parameters'
    physiological bounds around the current linearization point."""

    def __init__(self, *args, scale_lo, scale_hi, **kw):
        super().__init__(*args, **kw)
        self._lo, self._hi = np.log(scale_lo) + 1e-9, np.log(scale_hi) - 1e-9

    def bounds(self):
        lo, hi = super().bounds()
        nb = self.n_base
        lo[:nb] = np.maximum(lo[:nb], self._lo)
        hi[:nb] = np.minimum(hi[:nb], self._hi)
        return lo, np.maximum(hi, lo + 1e-9)


@dataclasses.dataclass
class _Point:
    """The model linearized at a point of the anchor fit, and the fit's
    true cost there (the data's share of the weighted squared error)."""

    fams: dict
    statics: Statics
    bounds: np.ndarray  # (n, 2) physiological scale bounds about the point
    cost: float

    def predictor(self, rows, tests, base_names, trust: float) -> _BoundedPredictor:
        """A base-only predictor whose step stays within `trust` (log) and
        the physiological bounds."""
        lo = np.minimum(np.maximum(self.bounds[:, 0], np.exp(-trust)), 1.0)
        hi = np.maximum(np.minimum(self.bounds[:, 1], np.exp(trust)), 1.0)
        pred = _BoundedPredictor(self.fams["base"], Candidate(()), rows, tests, base_names,
                                 self.statics, scale_lo=lo, scale_hi=hi)
        pred.update_statistics(np.zeros(len(base_names)))
        return pred


def trust_region_descent(linearize, step, x0, iterations: int = ANCHOR_ITERATIONS,
                         trust: float = ANCHOR_TRUST, min_trust: float = ANCHOR_MIN_TRUST,
                         tolerance: float = ANCHOR_TOLERANCE, progress=None):
    """Descend a cost through local models, keeping a step only where the
    true cost falls.  `linearize(x)` -> a point with its true ``cost`` at
    `x` (one linearization); `step(point, trust)` -> (increment, the local
    model's cost after it), each coordinate of the increment within
    `trust`.  A step that does not lower the true cost is taken back and
    `trust` halved; the descent ends when a kept step gains less than
    `tolerance` of the cost, `trust` falls below `min_trust`, or after
    `iterations` linearizations.  Returns (the best point, its x) and the
    history [(true cost before a step, local model's after, true after)]."""
    x = np.asarray(x0, float)
    best, history = linearize(x), []
    for k in range(iterations - 1):
        dx, predicted = step(best, trust)
        new = linearize(x + dx)
        history.append([best.cost, predicted, new.cost])
        if progress:
            progress(k + 1, iterations - 1, best.cost, min(best.cost, new.cost))
        if new.cost < best.cost:
            gain = best.cost - new.cost
            best, x = new, x + dx
            if gain < tolerance * (best.cost + gain):
                break
        else:  # the local model overshot: a smaller region from the same point
            trust *= 0.5
            if trust < min_trust:
                break
    return (best, x), history


def _data_cost(pred, theta, every, n_rows: int) -> float:
    return float(np.sum(residuals(pred, theta, every)[:2 * n_rows] ** 2))


def fit_anchor(group, params: ModelParams, measures: BodyMeasures,
               iterations: int = ANCHOR_ITERATIONS, workers=None, progress=None,
               use_cache: bool = True) -> dict:
    """The base parameters refit to the group mean (a `ReferenceGroup`),
    re-linearized after every step, a step kept only when it lowers the
    true cost (`ANCHOR_TRUST`): {"log_scales", "history": [(true cost
    before the step, its linear prediction after, true cost after)],
    "params"}.  At most `iterations` linearizations.  Weighted by the
    variance of the group mean (scatter / K) plus the 3% model floor.
    Cached by the group's data and the model."""
    free = resolve_free("default")
    base_names = [f.name for f in free]
    key = hashlib.sha256(json.dumps([ANCHOR_CACHE_VERSION, _code_fingerprint(),
                                     group.fingerprint(), params.to_dict(), measures.mass_kg,
                                     measures.stature_m, iterations], sort_keys=True,
                                    default=float).encode()).hexdigest()[:20]
    path = cache_dir() / "anchors" / f"{key}.json"
    out = read_cache_json(path) if use_cache else None
    if out is not None:
        out["params"] = apply_scales(params, free, np.exp(out["log_scales"]))
        return out
    rows = dataclasses.replace(group.rows, rel_var=group.variance / group.size / 2
                               + MODEL_FLOOR**2)
    every = np.ones(len(rows), bool)
    zero = np.zeros(len(free))

    def linearized(total) -> _Point:
        pk = apply_scales(params, free, np.exp(total))
        fams = load_families(pk, measures, [], base_names, workers, None, use_cache)
        point = _Point(fams, Statics(fams["base"].family.info, separation_slope(pk, measures)),
                       np.array([scale_bounds(pk, f) for f in free]), np.nan)
        point.cost = _data_cost(point.predictor(rows, group.tests, base_names, ANCHOR_TRUST),
                                zero, every, len(rows))
        return point

    def step(point, trust):
        pred = point.predictor(rows, group.tests, base_names, trust)
        fit = fit_candidate(pred, every, zero)
        return fit.theta, _data_cost(pred, fit.theta, every, len(rows))

    (_, total), history = trust_region_descent(linearized, step, zero, iterations,
                                               progress=progress)
    out = {"log_scales": total.tolist(), "history": history, "base_names": base_names}
    if use_cache:
        write_cache_json(path, out)
    out["params"] = apply_scales(params, free, np.exp(total))
    return out
