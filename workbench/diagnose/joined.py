"""Predictors of several recordings with different signals diagnosed together.

Each recording is predicted as it would be alone (:func:`.nominal.predictors`): one
with a chamber pressure by short-horizon predictions re-anchored on its measured state
(:func:`.predict.horizons`); a position-only recording replayed in closed loop by
1 s re-anchored segments (:func:`.predict.segments`: open-loop horizons would let its
unmeasured pressures drift from window to window, and an effect that only moves the
pressures, a leak, could then fit that drift through the position), in open loop by
horizons as alone. The predictors are put end to end on the joined recording
(:func:`.data.prepare_many`): every signal is compared where it was recorded
(:meth:`.data.Prepared.mask`), and each recording starts afresh (state, hidden states,
controller memory; a position-only recording's pressures from the plant's equilibrium
at its first position, as alone).
"""

from __future__ import annotations

import numpy as np

from .data import Prepared
from .engine import INPUT_ROWS, EngineInputs
from .predict import MAX_PREDICTED, Predictor, _sigma, horizons, segments

__all__ = ["predictors"]


def predictors(prep: Prepared) -> tuple[Predictor, Predictor | None]:
    """The refit objective and its closed-loop check (None in open loop) of ``prep``,
    a join of recordings with different signals (``prep.parts``, ``prep.starts``)."""
    total = sum(p.n * p.dt for p in prep.parts)
    coverage = min(1.0, MAX_PREDICTED / max(total, 1e-9))

    def objective(part: Prepared) -> Predictor:
        if part.closed and not part.pressures:
            return segments(part, 1.0)
        return horizons(part, coverage=coverage)

    shpe = _join(prep, [objective(p) for p in prep.parts], "horizons")
    seg = _join(prep, [segments(p) for p in prep.parts], "segments") if prep.closed else None
    return shpe, seg


def _join(prep: Prepared, preds: list[Predictor], kind: str) -> Predictor:
    """The parts' predictors ``preds`` (one per ``prep.parts``) as one on ``prep``.

    Sample indices are shifted by each part's first sample; the pressure rows hold the
    joined recording's smoothed pressures (a part without a pressure: the fill of
    :func:`.data.prepare_many`), re-anchored at each part's first simulated sample and,
    within a part, where that part re-anchors them itself."""
    if len({(p.step, p.decimate) for p in preds}) > 1:
        raise ValueError("the parts' predictors differ in step or decimation")
    row = {k: i for i, k in enumerate(INPUT_ROWS)}
    index, data, starts = [], [], []
    offset = 0
    for pred, first in zip(preds, prep.starts):
        idx = pred.index + first
        d = pred.inputs.data.copy()
        if prep.pressures:
            d[row["p_a_m"]] = prep.pas[idx]
            d[row["p_b_m"]] = prep.pbs[idx]
        for name in ("anchor", "anchor_hidden", "anchor_p"):
            d[row[name], 0] = 1.0 if name != "anchor_p" or prep.pressures else 0.0
        index.append(idx)
        data.append(d)
        starts.append(pred.starts + offset)
        offset += len(idx)
    return Predictor(kind, prep, np.concatenate(index), EngineInputs(np.hstack(data)),
                     np.unique(np.concatenate(starts)), prep.signals, _sigma(prep),
                     preds[0].decimate, preds[0].step)
