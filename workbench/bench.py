"""Benchmarks: ``workbench bench NAME --json``. Each measures against a baseline in the same run.

Timing numbers are for this machine at the time of the run; the ratios are what to
compare between runs. Nothing here is a test.
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import casadi as ca
import numpy as np

__all__ = ["run", "bench_simulate"]

ROOT = Path(__file__).resolve().parents[1]


def _reference_profile(duration: float):
    from . import simulate
    levels = [0.10, 0.40, 0.25, 0.30, 0.15, 0.35, 0.20, 0.45, 0.25, 0.30, 0.10, 0.25]
    hold = duration / len(levels)
    return simulate.steps(levels, hold=hold)


def _scipy_loop(plant, ctrl, ref, t_end, x0, method="LSODA", rtol=1e-6):
    """The same sampled-data loop with scipy.integrate.solve_ivp per period."""
    from scipy.integrate import solve_ivp
    f = plant.f
    jac = ca.Function("jx", [plant.x_sym, plant.u_sym, plant.p_sym],
                      [ca.jacobian(plant.xdot_expr, plant.x_sym)])
    T = ctrl.sample_time
    n = int(round(t_end / T))
    lo, hi = plant.params["valve.command_min"], plant.params["valve.command_max"]
    scale = np.array([plant.stroke, 1.0, 1e5, 1e5])
    state = np.array(x0, dtype=float)
    cstate = ctrl.reset()
    xs = [state[0]]
    p0 = plant.p0
    for k in range(n):
        cstate, u = ctrl.update(cstate, float(ref(k * T)), {"x": state[0], "v": state[1]})
        u = float(np.clip(u, lo, hi))
        sol = solve_ivp(lambda t, z: np.asarray(f(z, u, p0)).ravel(), (0.0, T), state,
                        method=method, rtol=rtol, atol=rtol * 1e-2 * scale,
                        jac=lambda t, z: np.asarray(jac(z, u, p0)))
        state = sol.y[:, -1]
        xs.append(state[0])
    return np.array(xs)


def bench_simulate(quick: bool = False) -> dict:
    """Closed loop, 25 mm reference plant (4 states), PD at 10 ms, 24 s of steps.

    Methods: the default CVODES path (``simulate.closed_loop``), the compiled loop
    (``simulate.CompiledLoop``: Radau IIA, 10 substeps per period, C code when a
    compiler is present) and scipy ``solve_ivp`` LSODA per period (baseline). Accuracy
    is the largest position difference from a tight CVODES run (rtol 1e-10),
    against the issue's bound of 0.1 % of stroke.
    """
    from . import controllers, simulate
    from .plant import Plant
    plant = Plant.from_toml(ROOT / "designs" / "plants" / "rig25_mpye.toml")
    ctrl = controllers.from_plant(plant)
    duration = 4.0 if quick else 24.0
    ref = _reference_profile(duration)
    x0 = plant.initial_state(0.25)
    bound = 1e-3 * plant.stroke

    truth = simulate.closed_loop(plant, ctrl, ref, t_end=duration, x0=x0, rtol=1e-10,
                                 atol=1e-12, progress=False)["x"]

    t0 = time.perf_counter()
    cv = simulate.closed_loop(plant, ctrl, ref, t_end=duration, x0=x0, progress=False)["x"]
    t_cv = time.perf_counter() - t0

    jit = shutil.which("gcc") is not None or shutil.which("cc") is not None
    t0 = time.perf_counter()
    loop = simulate.CompiledLoop(plant, ctrl, substeps=10, jit=jit)
    n = int(round(duration / ctrl.sample_time))
    loop._loop(n)
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    comp = loop.run(ref, duration, x0)["x"][::10]
    t_comp = time.perf_counter() - t0

    t0 = time.perf_counter()
    sp = _scipy_loop(plant, ctrl, ref, duration, x0)
    t_sp = time.perf_counter() - t0

    err = {"cvodes": float(np.max(np.abs(cv - truth))),
           "compiled_radau": float(np.max(np.abs(comp - truth))),
           "scipy_lsoda": float(np.max(np.abs(sp - truth)))}
    times = {"cvodes": t_cv, "compiled_radau": t_comp}
    ok = {k: err[k] < bound for k in times}
    best = min((k for k in times if ok[k]), key=lambda k: times[k], default="cvodes")
    return {
        "realtime_factor": duration / times[best],
        "speedup_vs_scipy": t_sp / times[best],
        "method": best,
        "simulated_s": duration,
        "wall_s": {"cvodes": t_cv, "compiled_radau": t_comp,
                   "compiled_radau_build": t_build, "scipy_lsoda": t_sp},
        "realtime_factor_by_method": {k: duration / v for k, v in times.items()},
        "max_position_error_m": err,
        "accuracy_bound_m": bound,
        "accurate": ok,
        "jit": jit,
        "target": {"realtime_factor": 500, "speedup_vs_scipy": 30},
    }


_BENCHES = {"simulate": bench_simulate}


def run(name: str, quick: bool = False) -> dict:
    """Run the named benchmark and return its result."""
    if name not in _BENCHES:
        raise KeyError(f"no benchmark '{name}'; known: {', '.join(_BENCHES)}")
    return _BENCHES[name](quick=quick)
