"""Step 2 of the diagnosis: the nominal plant against the recording -- the refit
objective and its closed-loop check (:mod:`.predict`), the short-horizon error per
sample, the witnesses, the operating regimes and where the mismatch lives."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import PlantParams
from .data import Prepared
from .engine import INPUT_ROWS
from .locate import concentration, intervals, regimes, smooth_error
from . import predict
from .predict import Predictor, horizons, segments, settle_refinement
from .refit import CandidateModel
from .replays import observer_rates
from .witness import Witness

__all__ = ["Nominal", "nominal", "predictors"]


@dataclass
class Nominal:
    """The nominal plant against the recording: the predictors, the short-horizon cost
    and per-sample error, the closed-loop segment cost, the witnesses, the operating
    regimes and where the mismatch lives."""

    shpe: Predictor
    seg: Predictor | None
    cost: float
    seg_cost: float | None
    err: np.ndarray
    wit: Witness
    masks: dict[str, np.ndarray]
    witness: dict[str, np.ndarray]
    share: dict[str, dict[str, float]]
    located: list[list[float]]


def predictors(prep: Prepared) -> tuple[Predictor, Predictor | None]:
    """The refit objective (short-horizon predictions) and its closed-loop check
    (re-anchored segments, closed loop only), re-anchored where a recording starts;
    recordings with different signals: each predicted as alone (:mod:`.joined`)."""
    if prep.recorded:
        from .joined import predictors as joined
        return joined(prep)
    if prep.closed and not prep.pressures:
        return _at_starts(segments(prep, 1.0), prep), None   # horizons drift without p
    seg = _at_starts(segments(prep), prep) if prep.closed else None
    return _at_starts(horizons(prep), prep), seg


def _at_starts(pred: Predictor, prep: Prepared) -> Predictor:
    """``pred`` re-anchored (state, pressures, hidden states, controller memory) at the
    first simulated sample of each joined recording after the first (several recordings:
    no prediction runs from one into the next)."""
    if len(prep.starts) < 2:
        return pred
    d = pred.inputs.data.copy()
    pos = np.searchsorted(pred.index, np.asarray(prep.starts[1:]))
    pos = pos[pos < len(pred.index)]
    for name in ("anchor", "anchor_hidden") + (("anchor_p",) if prep.pressures else ()):
        d[INPUT_ROWS.index(name), pos] = 1.0
    pred.inputs = type(pred.inputs)(d)
    pred.starts = np.unique(np.concatenate([pred.starts, pos]))
    return pred


def _replay(pred: Predictor, base: CandidateModel) -> np.ndarray:
    """The nominal model's replay of ``pred``; with :data:`.predict.REFINE_STEPS` the
    engine's refined steps are decided here, once, for every later replay of ``pred``
    (:func:`.predict.settle_refinement`)."""
    if predict.REFINE_STEPS:
        return settle_refinement(pred, lambda pr: base.run(pr, {}))
    return base.run(pred, {})


def nominal(prep: Prepared, params: PlantParams, jit: bool) -> Nominal:
    """Step 2: the nominal model's predictions, witnesses and regimes."""
    shpe, seg = predictors(prep)
    base = CandidateModel(prep, params, None, jit=jit)
    Y0 = _replay(shpe, base)
    err = shpe.error_by_sample(Y0)
    seg_cost = seg.cost(_replay(seg, base)) if seg is not None else None
    wit = Witness.build(prep)
    masks = regimes(prep, wit.v_rest)
    witness: dict[str, np.ndarray] = {}
    if prep.pressures:
        witness = wit.in_units(wit.residuals(observer_rates(prep, params, jit)))
    e_s = smooth_error(err, prep.dt)
    floor = float(np.nanmedian(e_s[e_s > 0])) if np.any(e_s > 0) else 0.0
    located = intervals(e_s, prep.t, max(5.0 * floor, 3.0 * len(prep.signals)))
    return Nominal(shpe=shpe, seg=seg, cost=shpe.cost(Y0), seg_cost=seg_cost, err=err,
                    wit=wit, masks=masks, witness=witness, share=concentration(err, masks),
                    located=located)
