"""The recording replayed on a plant, as the diagnosis reports it (``fit_before``,
``fit_after``), and one observer pass for the witnesses' model rates."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..params import PlantParams
from ..plant import Plant
from ..recording import Recording, fit
from .data import Prepared
from .engine import Engine
from . import predict
from .predict import segments, settle_refinement
from .refit import CandidateModel, substeps_for
from .witness import observer_inputs

__all__ = ["replay", "EngineOpenLoop", "observer_rates", "fits", "OPEN_ANCHOR"]

#: s: anchor spacing of the open-loop replay reported when there is no closed loop.
OPEN_ANCHOR = 0.5

@dataclass(frozen=True, eq=False)
class EngineOpenLoop:
    """Replay strategy (:class:`workbench.replay.Strategy`) that the diagnosis provides:
    open loop on u on its fixed-step engine (:mod:`.engine`, ROS2 with stick-slip),
    re-anchored on the measured (smoothed) state every ``anchor_every`` s.

    It stays here because its numbers are those of the engine, not of CVODES; ``x0``
    and ``params`` are not used (the anchors come from ``prep``, the parameters from
    the plant). Returns x, p_a, p_b, u on the recording's samples.
    """

    prep: Prepared
    anchor_every: float = OPEN_ANCHOR

    def __call__(self, plant: Plant, recording: Recording, x0=None, params=None,
                 progress=False) -> dict[str, np.ndarray]:
        model = CandidateModel(self.prep, plant.params, None)
        pred = segments(self.prep, self.anchor_every)
        Y = (settle_refinement(pred, lambda pr: model.run(pr, {})) if predict.REFINE_STEPS
             else model.run(pred, {}))
        return {k: pred.full(Y, i) for i, k in enumerate(("x", "p_a", "p_b", "u"))}


def replay(plant: Plant, prep: Prepared) -> dict[str, np.ndarray]:
    """The recording replayed on ``plant`` (:mod:`workbench.replay`): closed loop on r
    (CVODES, :class:`~workbench.replay.ClosedLoop` with the diagnosis' controller, from
    the first position, smoothed pressures and recorded u) when the diagnosis runs closed
    loop, falling back on the engine re-anchored every 2 s when CVODES fails; else
    open loop on u on the engine re-anchored every :data:`OPEN_ANCHOR` s
    (:class:`EngineOpenLoop`). Returns x, p_a, p_b, u on the recording's samples."""
    from .. import replay as rp
    if prep.parts:             # several recordings: each replayed on its own
        runs = [replay(plant, part) for part in prep.parts]
        return {k: np.concatenate([r[k] for r in runs]) for k in ("x", "p_a", "p_b", "u")}
    if not prep.closed:
        return EngineOpenLoop(prep, OPEN_ANCHOR)(plant, prep.rec)
    if prep.supply is not None:   # p_s sample by sample: the engine's closed loop, unbroken
        return EngineOpenLoop(prep, 2.0 * prep.t[-1] + 1.0)(plant, prep.rec)
    x0 = rp.initial_state(plant, prep.rec, u0=float(prep.rec["u"][0]),
                          recorded_pressures=False, **prep.first_pressures())
    strategy = rp.Fallback(rp.ClosedLoop(prep.controller), EngineOpenLoop(prep, 2.0))
    run = rp.run(plant, prep.rec, strategy, x0=x0)
    return {k: np.asarray(run[k], dtype=float) for k in ("x", "p_a", "p_b", "u")}


def observer_rates(prep: Prepared, params: PlantParams, jit: bool) -> np.ndarray:
    """Model rates (dv, dp_a, dp_b) along the measurement, one observer pass at 1 step/sample."""
    plant = Plant(params)
    eng = Engine(plant, prep.dt, None, jit=jit, rates=True, substeps=substeps_for(prep.dt))
    z0 = plant.initial_state(float(np.clip(prep.xs[0], 0.0, plant.stroke)),
                             p_a=float(prep.pas[0]), p_b=float(prep.pbs[0]),
                             u0=float(prep.rec["u"][0]))
    return eng.run(z0, observer_inputs(prep), plant.p0)[4:7]


def fits(prep: Prepared, sim: Mapping[str, np.ndarray]) -> dict[str, float]:
    out = {}
    for s in prep.signals:
        y = np.asarray(sim[s])
        ok = np.isfinite(y) & prep.mask(s)       # where recorded (several recordings)
        out[s] = fit(prep.measured(s)[ok], y[ok]) if ok.sum() > 2 else float("nan")
    return out
