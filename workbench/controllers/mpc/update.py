"""One NMPC update per sample: measured state and reference -> the new memory.

Per mode (see :mod:`workbench.controllers.mpc`):

``"rti"``, ``"sqp"``
    Gauss-Newton steps (:func:`.qp.sqp_step`) from the previous plan shifted by one
    sample: one step (RTI) or until the command step is below ``tolerance``. The
    first sample, and a sample whose warm start failed, start from rest at the
    measured state and iterate up to ``max_iterations``.
``"ipopt"``
    The full NLP (:class:`.nlp.IpoptSolver`) from the shifted primal and dual
    solution.

If the solver fails the previous plan is applied, shifted.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...errors import InputError
from .model import NMPC_STATES, V_SCALE, horizon_reference
from .results import NMPCState, Solution, StepInfo

__all__ = ["advance", "solution"]


@dataclass(frozen=True)
class _Sample:
    """What the solvers need of one sample, scaled.

    z : (4,) measured state. R, VR : (1, N + 1) reference position and velocity at
    the nodes. u_prev : command applied since the last sample. z_prev : (4,)
    measured state one sample ago.
    """

    z: np.ndarray
    R: np.ndarray
    VR: np.ndarray
    u_prev: float
    z_prev: np.ndarray


def node_reference(pb, r: float, r_prev: float | None, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Reference position (m) and velocity (m/s) at the N + 1 shooting nodes.

    With the controller's ``preview`` (the whole reference r(t), s -> m) the nodes
    take it at t + k T and its velocity from the chord over one sample centred on
    each node (bounded by ``max_speed``); else :func:`horizon_reference` extrapolates
    the current sample (a ramp) or holds it (a step).
    """
    c = pb.c
    if c.preview is None:
        R, rate = horizon_reference(r, r_prev, pb.T, pb.N, c.reference_rate_limit)
        return np.asarray(R, dtype=float), np.full(pb.N + 1, rate)
    tk = t + pb.T * np.arange(pb.N + 1)
    R = np.asarray(c.preview(tk), dtype=float)
    h = 0.5 * pb.T
    VR = (np.asarray(c.preview(tk + h), dtype=float) - np.asarray(c.preview(tk - h), dtype=float)) / pb.T
    vmax = c.max_speed if c.max_speed is not None else np.inf
    return R, np.clip(VR, -vmax, vmax)


def admissible(pb, R: np.ndarray, VR: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The node reference projected onto the stroke the NMPC may use (m, m/s).

    A reference beyond ``stroke_margin`` cannot be reached: tracking it makes the
    stroke limit's exact (L1) penalty active, and the optimum sits on the kink where
    the tracking cost's pull balances the penalty's multiplier. Any model error (the
    lines' delay) then moves the plan from one side of the kink to the other every
    sample: the command chattered by +-0.5 V and p_b by +-1 bar at the margin. The
    projected reference is reachable, the constraint inactive, the cost smooth there;
    where it is clipped its velocity is zero.
    """
    lo, hi = pb.c.stroke_margin, pb.L - pb.c.stroke_margin
    clipped = (R < lo) | (R > hi)
    return np.clip(R, lo, hi), np.where(clipped, 0.0, VR)


def advance(pb, y: dict, r: float, state: NMPCState | None) -> NMPCState:
    """One controller update: the new memory (its U[0] is the command).

    Parameters
    ----------
    pb : workbench.controllers.mpc.problem.Problem
    y : measured x (m), v (m/s), p_a, p_b (Pa).
    r : m, reference now.
    state : the memory of the previous sample, None at the first.
    """
    t0 = time.perf_counter()
    c = pb.c
    try:
        zm = np.array([y[k] for k in NMPC_STATES], dtype=float) / pb.sx
    except KeyError as exc:
        raise InputError(f"the NMPC needs the measured {exc} (it measures x, v, p_a, p_b)") from None
    t = 0.0 if state is None else state.t + pb.T
    R, VR = node_reference(pb, r, None if state is None else state.r_prev, t)
    R, VR = admissible(pb, R, VR)
    R, VR = (R / pb.L)[None, :], (VR / V_SCALE)[None, :]
    if state is None:
        s = _Sample(zm, R, VR, 0.0, zm)
        dprev, est = 0.0, 0.0
    else:
        s = _Sample(zm, R, VR, state.u_prev, state.z)
        dprev, est = state.d, 1.0
    warm = state is not None and c.warm_start
    lam = None
    if c.mode == "ipopt":
        X, U, it, ok, d, lam = _ipopt_update(pb, s, state, warm, dprev, est)
        viol, restarted = None, False
    else:
        X, U, it, ok, viol, d, restarted = _sqp_update(pb, s, state, warm, dprev, est)
    if not ok:                                         # keep the previous plan, shifted
        X, U = _previous_plan(pb, state, zm)
    w0 = float(U[0])
    info = _step_info(pb, it, ok, viol, restarted, time.perf_counter() - t0)
    return NMPCState(X=X, U=U, u_prev=w0, r_prev=r, z=zm, d=d, lam=lam, info=info, t=t)


def _sqp_update(pb, s: _Sample, state: NMPCState | None, warm: bool, dprev: float,
                est: float):
    """Modes rti and sqp: from the shifted plan, or from rest if that fails.

    Returns (X, U, iterations, success, violations, force estimate, restarted).
    """
    c = pb.c
    ok = False
    if warm:
        iters = 1 if c.mode == "rti" else c.max_iterations
        X, U, it, ok, viol, d = _sqp(pb, state.X, state.U, True, s, dprev, est, iters)
        dprev, est = d, 0.0
    restarted = False
    if not ok:                                         # first sample, or the warm start failed
        restarted = warm
        iters = c.max_iterations if (state is None or c.mode != "rti" or restarted) else 1
        X, U = _cold(pb, s.z)
        X, U, it, ok, viol, d = _sqp(pb, X, U, False, s, dprev, est, iters)
    return X, U, it, ok, viol, d, restarted


def _sqp(pb, X, U, shift: bool, s: _Sample, dprev: float, est: float, iters: int):
    """Up to ``iters`` full Gauss-Newton steps; stops at a step below tolerance.

    The force estimate is updated in the first step only (``est``).
    Returns (X, U, iterations, success, violations, force estimate).
    """
    ok, it, viol, d = False, 0, None, dprev
    sh = 1.0 if shift else 0.0
    for it in range(1, iters + 1):
        Xn, Un, _, viol, okk, stp, dd = pb.step(X, U, sh, s.z, s.R, s.VR, s.u_prev, s.z_prev,
                                                dprev, est, pb.P)
        ok = bool(okk)
        if it == 1:
            d = dprev = float(dd)
            est = 0.0
        if not ok:
            break
        X, U, sh = Xn, Un, 0.0
        if float(stp) < pb.c.tolerance:
            break
    return X, U, it, ok, viol, d


def _ipopt_update(pb, s: _Sample, state: NMPCState | None, warm: bool, dprev: float,
                  est: float):
    """Mode ipopt: the force estimate, then the NLP from the shifted or a cold guess.

    Returns (X, U, iterations, success, force estimate, multipliers).
    """
    c = pb.c
    d = float(pb.estimate(s.z_prev, s.u_prev, dprev, s.z, est, c.disturbance_gain))
    X, U = (state.X, state.U) if warm else _cold(pb, s.z)
    X, U, it, ok, lam = pb.ipopt(X, U, warm, s.z, s.R, s.VR, s.u_prev, d,
                                 state.lam if warm else None)
    return X, U, it, ok, d, lam


def _cold(pb, zm: np.ndarray):
    """A plan at rest at the measured state: every node zm, every command move 0."""
    return ca.DM(np.tile(zm[:, None], (1, pb.N + 1))), ca.DM.zeros(1, pb.N)


def _previous_plan(pb, state: NMPCState | None, zm: np.ndarray):
    """After a failed solve: the previous plan shifted by one sample (or rest)."""
    if state is None:
        return _cold(pb, zm)
    return (ca.horzcat(state.X[:, 1:], state.X[:, -1]),
            ca.horzcat(state.U[:, 1:], state.U[:, -1]))


def _step_info(pb, it: int, ok: bool, viol, restarted: bool, solve_time: float) -> StepInfo:
    """The update's report, violations in SI units (none after a failure or IPOPT)."""
    v = np.zeros(4) if viol is None or not ok else np.asarray(viol).ravel()
    return StepInfo(iterations=it, success=ok, solve_time=solve_time,
                    restarted=restarted, slack_stroke=max(v[0], 0.0) * pb.L,
                    slack_pressure=max(v[2], v[3]) * pb.p_sup,
                    slack_speed=v[1] * V_SCALE if pb.c.max_speed is not None else 0.0)


def solution(pb, state: NMPCState, r: float, r_prev: float | None) -> Solution:
    """The memory of an update as a Solution in SI units."""
    R, _ = node_reference(pb, r, r_prev, state.t)
    X = np.asarray(state.X)
    return Solution(time=pb.T * np.arange(pb.N + 1), states=(X * pb.sx[:, None]).T,
                    commands=np.array([pb.command(w) for w in np.asarray(state.U).ravel()]),
                    reference=R, info=state.info, state=state)
