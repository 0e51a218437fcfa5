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

With the NMPC's ``compiled_sample`` on (and ``jit``), modes rti and sqp run the
whole sample as one C call (:class:`.fast.CompiledNMPC`: the same
plans, bit for bit on the tests); :func:`compiled_sample` says why not otherwise.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...errors import InputError
from .model import NMPC_STATES, V_SCALE
from .nodes import admissible, node_reference
from .qp import SQP_CONTRACTION, SQP_DAMPING
from .results import NMPCState, Solution, StepInfo

__all__ = ["advance", "solution", "compiled_sample", "node_reference", "admissible"]


@dataclass(frozen=True)
class _Sample:
    """What the solvers need of one sample, scaled.

    z : (nx,) measured state (with lumped lines: their estimate). R, VR : (1, N + 1) reference position and velocity at
    the nodes. u_prev : command applied since the last sample. z_prev : (nx,)
    measured state one sample ago.
    """

    z: np.ndarray
    R: np.ndarray
    VR: np.ndarray
    u_prev: float
    z_prev: np.ndarray


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
    fast = compiled_sample(pb)[0]
    if fast is not None:
        return _advance_compiled(pb, fast, y, r, state, t0)
    zm, line_cov = pb.measured_state(_measured(y, r) / pb.sx[:len(NMPC_STATES)], state)
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
    brk, dprev = _breakaway(pb, y, r, state, dprev)
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
    return NMPCState(X=X, U=U, u_prev=w0, r_prev=r, z=zm, d=d, lam=lam, info=info, t=t,
                     line_cov=line_cov, brk=brk)


def _breakaway(pb, y: dict, r: float, state: NMPCState | None, d: float):
    """(break-away state, force estimate N to start this sample from): the
    setting ``breakaway`` (:mod:`.breakaway`), else (None, ``d``)."""
    if state is None or not pb.c.breakaway:
        return None, d
    fr = getattr(pb, "_dry", False)
    if fr is False:
        from .breakaway import dry_friction
        pb._dry = fr = dry_friction(pb)
    if fr is None:
        return None, d
    from .breakaway import breakaway_force
    want = float(node_reference(pb, r, state.r_prev, state.t + pb.T)[1][0])
    return breakaway_force(fr, state.brk, want, float(y["v"]),
                           float(y.get("x_measured", y["x"])), d)


def _measured(y: dict, r: float) -> np.ndarray:
    """(4,) measured x, v, p_a, p_b (SI) from ``y``; InputError naming a missing,
    non-numeric or non-finite one (or the reference ``r``), as the compiled sample's
    (:meth:`.fast.CompiledNMPC.update`)."""
    try:
        z = np.array([y[k] for k in NMPC_STATES], dtype=float)
    except KeyError as exc:
        raise InputError(f"the NMPC needs the measured {exc} (it measures x, v, p_a, p_b)") from None
    except (TypeError, ValueError):
        bad = [k for k in NMPC_STATES if not _is_number(y[k])]
        raise InputError(f"the NMPC's measured {', '.join(bad)} must be numbers") from None
    if not (np.all(np.isfinite(z)) and np.isfinite(r)):
        bad = [k for k, v in (*zip(NMPC_STATES, z), ("reference", r)) if not np.isfinite(v)]
        raise InputError(f"the NMPC got a measurement or reference that is not a finite "
                         f"number: {', '.join(bad)}")
    return z


def _is_number(v) -> bool:
    try:
        float(v)
    except (TypeError, ValueError):
        return False
    return True


def compiled_sample(pb):
    """(the compiled sample of the problem's NMPC, None) or (None, why not); built at
    the first call and kept on the problem. Off: the setting ``compiled_sample`` or
    ``jit`` off, mode ipopt, a QP solver other than DAQP, no C compiler, no DAQP
    library, or too many compiled NMPCs alive."""
    got = getattr(pb, "_compiled_sample", None)
    if got is not None:
        return got
    c = pb.c
    why = None
    if not getattr(c, "compiled_sample", False):
        why = "compiled_sample is off"
    elif not c.jit:
        why = "jit is off"
    elif c.mode not in ("rti", "sqp"):
        why = f"mode {c.mode} runs in Python"
    elif c.qp_solver != "daqp":
        why = f"the compiled sample links DAQP, not {c.qp_solver}"
    fast = None
    if why is None:
        from ...integrate.jit import CompileError
        from .fast import CompiledNMPC, compiled_unavailable
        why = compiled_unavailable()
        if why is None:
            try:
                fast = CompiledNMPC(c)
            except (CompileError, MemoryError, OSError) as exc:   # OSError: loading it
                why = str(exc)
    pb._compiled_sample = got = (fast, why)
    return got


def _advance_compiled(pb, fast, y: dict, r: float, state: NMPCState | None,
                      t0: float) -> NMPCState:
    """:func:`advance` as one compiled C call, the state passed in not changed.

    The compiled sample works on a :class:`.fast.CompiledMemory` buffer. The buffer
    behind the state this problem returned last is kept (``pb._compiled_last``) and
    updated in place when that state comes back (a closed loop); any other state is
    copied into a fresh buffer. The new state's X, U, z and working set are read-only
    copies (numpy: a casadi.DM each would cost 30 us a sample; read-only: the buffer,
    not the state, is read back at the next sample).
    """
    last = getattr(pb, "_compiled_last", None)
    if state is not None and last is not None and last[0] is state:
        mem = last[1]
    else:
        mem = fast.memory(None if state is None else
                          (state.X, state.U, state.u_prev, state.r_prev, state.z, state.d,
                           state.t, state.working_set))
        mem.line_cov = None if state is None else state.line_cov
    pb._compiled_last = None                           # mem changes: no state matches it
    b, o = mem.buf, mem._off
    brk, d = _breakaway(pb, y, r, state, float(b[o["d"]]))
    b[o["d"]] = d
    mem, _ = fast.update(mem, r, y)
    new = NMPCState(X=mem.X.copy(), U=mem.U[None, :].copy(), u_prev=float(b[o["u_prev"]]),
                    r_prev=r, z=b[o["z"]:o["z"] + pb.nx].copy(), d=float(b[o["d"]]), lam=None,
                    info=mem.step_info(pb, time.perf_counter() - t0), t=float(b[o["t"]]),
                    working_set=mem.working_set.copy(),
                    line_cov=None if mem.line_cov is None else mem.line_cov.copy(), brk=brk)
    for a in (new.X, new.U, new.z, new.working_set):
        a.flags.writeable = False
    pb._compiled_last = (new, mem)
    return new


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
    """Up to ``iters`` Gauss-Newton steps; stops at a full step below tolerance.

    The force estimate is updated in the first step only (``est``). A step whose QP
    CasADi refuses (NaN in it) fails, as in the compiled sample. In mode sqp the
    steps taken are halved (:data:`SQP_DAMPING`) at each full step that is not below
    :data:`SQP_CONTRACTION` times the one before and turns the commands back (its
    moves against the previous step's: a cycle; the compiled sample likewise).
    Returns (X, U, iterations, success, violations, force estimate).
    """
    ok, it, viol, d = False, 0, None, dprev
    sh = 1.0 if shift else 0.0
    a, prev, dprev_u, damp = 1.0, math.inf, None, pb.c.mode == "sqp"
    for it in range(1, iters + 1):
        try:
            Xn, Un, _, viol, okk, stp, dd = pb.step(X, U, sh, s.z, s.R, s.VR, s.u_prev,
                                                    s.z_prev, dprev, est, pb.P)
        except RuntimeError as exc:
            # CasADi's QP plugin refuses a QP with NaN in it (a plan whose states left
            # the model's domain: the linearisation not finite) by an error; the
            # compiled sample fails such a step: so does this one (then the fallbacks)
            from ...output import reraise_interrupt
            reraise_interrupt(exc)
            ok = False
            break
        ok = bool(okk)
        if it == 1:
            d = dprev = float(dd)
            est = 0.0
        if not ok:
            break
        stp = float(stp)
        du = np.asarray(Un - U, dtype=float).ravel()
        if (damp and it > 1 and stp >= SQP_CONTRACTION * prev
                and float(np.dot(du, dprev_u)) < 0.0):   # not contracting, turned back
            a *= SQP_DAMPING
        prev, dprev_u = stp, du
        X, U = (Xn, Un) if a == 1.0 else (X + a * (Xn - X), U + a * (Un - U))
        sh = 0.0
        if stp < pb.c.tolerance:
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
    X, U = ca.DM(state.X), ca.DM(state.U)            # numpy after a compiled sample
    return ca.horzcat(X[:, 1:], X[:, -1]), ca.horzcat(U[:, 1:], U[:, -1])


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
