"""What the NMPC returns: the update's report, its memory, a solved problem in SI units."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["StepInfo", "NMPCState", "Solution"]


@dataclass(frozen=True)
class StepInfo:
    """What one controller update did.

    Attributes
    ----------
    iterations : SQP steps (RTI: 1) or IPOPT iterations.
    success : the QP / NLP solver succeeded (on failure the previous plan, shifted,
        is applied).
    restarted : the warm start was abandoned and the problem re-solved from rest
        (after a failed or diverged step).
    solve_time : s, wall time of the update (linearisation, QP, bookkeeping).
    slack_stroke : m, largest predicted violation of the stroke limits.
    slack_pressure : Pa, largest predicted violation of the pressure limits.
    slack_speed : m/s, largest predicted violation of the speed limit.
    """

    iterations: int
    success: bool
    solve_time: float
    restarted: bool = False
    slack_stroke: float = 0.0
    slack_pressure: float = 0.0
    slack_speed: float = 0.0


@dataclass(frozen=True, eq=False)
class NMPCState:
    """Controller memory between samples (the warm start).

    Attributes
    ----------
    X : casadi.DM (nx, N + 1), predicted states, scaled (x/L, v/(1 m/s), p/p_supply;
        with lumped lines also their node pressures and flows, :attr:`Problem.sx`)
        (a numpy array after a compiled sample, :mod:`.fast`).
    U : casadi.DM (1, N), planned commands, scaled ((u - centre)/span) (ditto).
    u_prev : scaled command applied last. r_prev : m, reference at the last sample.
    z : (nx,) measured state at the last sample, scaled (with lumped lines: their
        estimated states after it).
    d : N, estimated disturbance force (along -x, like ``load.external_force``).
    lam : (lam_x, lam_g) of the last IPOPT solve (mode "ipopt"), else None.
    info : StepInfo of the last update.
    t : s, time of the last sample since the first update (for the preview).
    working_set : after a compiled sample (:mod:`.fast`), the working set of its last
        QP (the bounds, then the rows: +1 upper, -1 lower, 0 inactive), where its next
        QP starts; else None.
    line_cov : (nl^2,) covariance of the lumped lines' estimate (:mod:`.lines`), else None.
    brk : break-away state of a stuck piston (:mod:`.breakaway`), else None.
    """

    X: Any
    U: Any
    u_prev: float
    r_prev: float
    z: np.ndarray
    d: float = 0.0
    lam: Any = None
    info: StepInfo | None = None
    t: float = 0.0
    working_set: Any = None
    line_cov: Any = None
    brk: Any = None


@dataclass(frozen=True, eq=False)
class Solution:
    """One solved NMPC problem in SI units.

    Attributes
    ----------
    time : (N + 1,) s from now. states : (N + 1, 4) predicted x, v, p_a, p_b (SI).
    commands : (N,) V, held over each interval. reference : (N + 1,) m.
    info : StepInfo. state : NMPCState to warm start the next problem.
    """

    time: np.ndarray
    states: np.ndarray
    commands: np.ndarray
    reference: np.ndarray
    info: StepInfo
    state: NMPCState

