"""Baselines of ``workbench bench simulate``: the same sampled-data PD loop, written
plainly as a competent CasADi / scipy user would.

* :func:`cvodes_mapaccum`: one control period = CasADi's CVODES integrator over the
  period (states scaled by the plant's state scales, so one tolerance fits metres
  and pascals) after the PD law; the whole run one ``mapaccum`` (no Python per period);
* :func:`rk4_compiled`: the period as ``m`` fixed RK4 steps (a loop, not unrolled), the
  run one ``mapaccum`` compiled to C (the workbench JIT cache, so repeated runs skip gcc);
* :func:`scipy_loop`: ``solve_ivp`` restarted from Python at every period (the old
  baseline, and with Radau at rtol 1e-9 the accuracy reference).

All run the PD law of :func:`workbench.controllers.pd.pid_law` with the same clipping
(:func:`.compiled_loop._pid_kernel`) and return the positions at the control instants.
"""

from __future__ import annotations

from typing import Callable

import casadi as ca
import numpy as np

from ..integrate import RK4, explicit_rk
from ..integrate.jit import compiled
from .compiled_loop import _NC, _pid_kernel

__all__ = ["cvodes_mapaccum", "rk4_compiled", "scipy_loop"]


def _loop(plant, ctrl, n: int, advance: Callable, jit: str = "") -> Callable:
    """run(r (n,), x0) -> positions (n + 1,) of the loop whose period ends with advance."""
    nx = len(plant.states)
    pid = _pid_kernel(plant, ctrl, None, None)
    xc, r = ca.MX.sym("xc", nx + _NC), ca.MX.sym("r")
    u, c = pid(xc[:nx], xc[nx:], r)
    period = ca.Function("period", [xc, r], [ca.vertcat(advance(xc[:nx], u), c)])
    loop = period.mapaccum(jit or "loop", n)
    if jit:                    # generated C (a loop over the periods), compiled once
        loop = compiled(loop)
    ix = plant.state_index("x")

    def run(rvals, x0):
        out = np.asarray(loop(np.concatenate((x0, np.zeros(_NC))), np.reshape(rvals, (1, -1))))
        return np.concatenate(([x0[ix]], out[ix, :]))
    return run


def cvodes_mapaccum(plant, ctrl, n: int, rtol: float, atol: float) -> Callable:
    """CVODES (BDF) per period on states scaled by ``plant.state_scales()``; tolerances
    ``rtol`` and ``atol`` (on the scaled states)."""
    s = ca.DM(plant.state_scales())
    z, u = ca.SX.sym("z", len(plant.states)), ca.SX.sym("u")
    ode = plant.f(z * s, u, plant.p0) / s
    F = ca.integrator("F", "cvodes", {"x": z, "p": u, "ode": ode}, 0.0, ctrl.sample_time,
                      {"reltol": rtol, "abstol": atol})
    return _loop(plant, ctrl, n, lambda x, uu: F(x0=x / s, p=uu)["xf"] * s)


def rk4_compiled(plant, ctrl, n: int, substeps: int) -> Callable:
    """``substeps`` classical RK4 steps per period; the loop compiled to C.

    The substeps are a ``fold`` of one RK4 step (a loop in the generated C), not
    unrolled: on the 4-state loop 5.0 ms against 6.5 ms unrolled at 5 substeps (the
    unrolled code outgrows the instruction cache), the same numbers to the last bit,
    and 1.3 s to compile instead of 10 s (the 22-state loop at 64 substeps: minutes).
    """
    h = ctrl.sample_time / substeps
    z, u = ca.SX.sym("z", len(plant.states)), ca.SX.sym("u")
    one = ca.Function("rk4_step", [z, u],
                      [explicit_rk(RK4, lambda q: plant.f(q, u, plant.p0), z, h)])
    steps = one.fold(substeps)
    return _loop(plant, ctrl, n, lambda x, uu: steps(x, ca.repmat(uu, 1, substeps)),
                 jit=f"wb_rk4fold_{substeps}_{n}")


def scipy_loop(plant, ctrl, ref, n: int, x0, method: str = "LSODA",
               rtol: float = 1e-6, atol_scaled: float = 1e-8) -> np.ndarray:
    """``solve_ivp`` from Python over each period (exact Jacobian from CasADi); positions
    at the control instants. ``atol = atol_scaled * plant.state_scales()``."""
    from scipy.integrate import solve_ivp
    jac = ca.Function("jx", [plant.x_sym, plant.u_sym, plant.p_sym],
                      [ca.jacobian(plant.xdot_expr, plant.x_sym)])
    T, p0, f = ctrl.sample_time, plant.p0, plant.f
    lo, hi = plant.params["valve.command_min"], plant.params["valve.command_max"]
    atol = atol_scaled * plant.state_scales()
    state, cstate = np.array(x0, dtype=float), ctrl.reset()
    ix, iv = plant.state_index("x"), plant.state_index("v")
    xs = [state[ix]]
    for k in range(n):
        cstate, u = ctrl.update(cstate, float(ref(k * T)), {"x": state[ix], "v": state[iv]})
        u = float(np.clip(u, lo, hi))
        sol = solve_ivp(lambda t, z: np.asarray(f(z, u, p0)).ravel(), (0.0, T), state,
                        method=method, rtol=rtol, atol=atol,
                        jac=lambda t, z: np.asarray(jac(z, u, p0)))
        state = sol.y[:, -1]
        xs.append(state[ix])
    return np.array(xs)
