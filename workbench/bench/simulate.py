"""``workbench bench simulate``: the closed loop against scipy, accuracy against Radau.

Timing numbers are for this machine at the time of the run; the ratios are what to
compare between runs. Nothing here is a test.
"""

from __future__ import annotations

import time
from pathlib import Path

import casadi as ca
import numpy as np

__all__ = ["bench"]

ROOT = Path(__file__).resolve().parents[2]


def _reference_profile(duration: float):
    from .. import simulate
    levels = [0.10, 0.40, 0.25, 0.30, 0.15, 0.35, 0.20, 0.45, 0.25, 0.30, 0.10, 0.25]
    hold = duration / len(levels)
    return simulate.steps(levels, hold=hold)


def _scipy_loop(plant, ctrl, ref, t_end, x0, method="LSODA", rtol=1e-6, atol_factor=1e-2):
    """The same sampled-data loop with scipy.integrate.solve_ivp per period.

    atol = rtol * atol_factor on the states scaled by (stroke, 1 m/s, 1 bar, 1 bar).
    """
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
                        method=method, rtol=rtol, atol=rtol * atol_factor * scale,
                        jac=lambda t, z: np.asarray(jac(z, u, p0)))
        state = sol.y[:, -1]
        xs.append(state[0])
    return np.array(xs)


#: the accuracy reference of the issue: scipy Radau at rtol 1e-9 (atol 1e-9 on scaled states)
REFERENCE_RTOL = 1e-9


def _radau_reference(plant_file: Path, plant, ctrl, ref, t_end, x0) -> tuple[np.ndarray, dict]:
    """Positions at the control instants by scipy Radau (rtol 1e-9), cached on disk.

    The reference is deterministic and slow (minutes for 24 s), so it is kept in the
    temp directory under a key of everything it depends on.
    """
    import hashlib
    import json
    import os
    import tempfile

    import scipy
    T = ctrl.sample_time
    n = int(round(t_end / T))
    key_src = json.dumps({
        "plant": Path(plant_file).read_text(), "ctrl": repr(ctrl),
        "r": np.asarray(ref(T * np.arange(n + 1)), dtype=float).tolist(),
        "x0": np.asarray(x0, dtype=float).tolist(), "rtol": REFERENCE_RTOL,
        "scipy": scipy.__version__, "casadi": ca.__version__, "v": 1})
    key = hashlib.sha256(key_src.encode()).hexdigest()[:24]
    path = Path(tempfile.gettempdir()) / "workbench-bench" / f"radau_ref_{key}.npy"
    info = {"method": f"scipy solve_ivp Radau rtol {REFERENCE_RTOL:g}", "cached": path.exists()}
    if path.exists():
        xr = np.load(path)
        if xr.shape == (n + 1,):
            info["wall_s"] = 0.0
            return xr, info
    t0 = time.perf_counter()
    xr = _scipy_loop(plant, ctrl, ref, t_end, x0, method="Radau", rtol=REFERENCE_RTOL,
                     atol_factor=1.0)
    info["wall_s"] = time.perf_counter() - t0
    info["cached"] = False
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.stem}_{os.getpid()}.npy")
    np.save(tmp, xr)
    os.replace(tmp, path)
    return xr, info


def _best_of(fn, repeats: int, min_total: float = 1.0):
    """(result, best wall s, median wall s, best CPU s of this thread) over repeated calls."""
    walls, cpus = [], []
    out = None
    t_start = time.perf_counter()
    while len(walls) < repeats or time.perf_counter() - t_start < min_total:
        c0, t0 = time.thread_time(), time.perf_counter()
        out = fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.thread_time() - c0)
        if len(walls) >= 10 * repeats:
            break
    return out, min(walls), float(np.median(walls)), min(cpus)


#: substeps per 10 ms period of the compiled loop in the benchmark
BENCH_SUBSTEPS = 14


def bench(quick: bool = False) -> dict:
    """Closed loop, 25 mm reference plant (4 states), PD at 10 ms, 24 s of steps.

    Methods: the compiled loop (:class:`.compiled_loop.CompiledLoop`: ROS4, 14 substeps per
    period, run by a C driver when a compiler is present), the default CVODES path
    (``simulate.closed_loop``) and, as the baseline, scipy ``solve_ivp`` LSODA per
    period. Accuracy is the largest position difference, at the control instants,
    from scipy Radau at rtol 1e-9 (cached between runs), against the issue's bound
    of 0.1 % of stroke; a method outside it is not eligible and ``accurate`` says so.

    The compiled loop's time is the best of repeated runs (median and CPU time are
    reported too) of ``CompiledLoop.run`` (the whole 24 s, returning a Trajectory);
    building and compiling it (``compile_s``) is not included.
    """
    import sys

    from .. import controllers, simulate
    from ..plant import Plant
    from .compiled_loop import CompiledLoop
    plant_file = ROOT / "designs" / "plants" / "rig25_mpye.toml"
    plant = Plant.from_toml(plant_file)
    ctrl = controllers.from_plant(plant)
    duration = 4.0 if quick else 24.0
    ref = _reference_profile(duration)
    x0 = plant.initial_state(0.25)
    bound = 1e-3 * plant.stroke

    truth, ref_info = _radau_reference(plant_file, plant, ctrl, ref, duration, x0)

    t0 = time.perf_counter()
    cv = simulate.closed_loop(plant, ctrl, ref, t_end=duration, x0=x0, progress=False)["x"]
    t_cv = time.perf_counter() - t0

    t0 = time.perf_counter()
    loop = CompiledLoop(plant, ctrl, substeps=BENCH_SUBSTEPS, jit=True, method="ros4")
    native = loop.compile()
    t_build = time.perf_counter() - t0          # symbolic build + C generation + gcc
    loop.run(ref, duration, x0)                        # warm up (first call, page faults)
    run, t_comp, t_comp_med, cpu_comp = _best_of(lambda: loop.run(ref, duration, x0),
                                                 repeats=5 if native else 1)
    comp = run["x"]

    t0 = time.perf_counter()
    sp = _scipy_loop(plant, ctrl, ref, duration, x0)
    t_sp = time.perf_counter() - t0

    err = {"cvodes": float(np.max(np.abs(cv - truth))),
           "compiled": float(np.max(np.abs(comp - truth))),
           "scipy_lsoda": float(np.max(np.abs(sp - truth)))}
    times = {"cvodes": t_cv, "compiled": t_comp}
    ok = {k: err[k] < bound for k in err}
    if not ok["compiled"]:
        print(f"bench simulate: the compiled loop is OUTSIDE the accuracy bound: "
              f"{err['compiled']:.3g} m > {bound:.3g} m", file=sys.stderr)
    best = min((k for k in times if ok[k]), key=lambda k: times[k], default="cvodes")
    return {
        "realtime_factor": duration / times[best],
        "speedup_vs_scipy": t_sp / times[best],
        "method": best,
        "accurate": ok[best],
        "simulated_s": duration,
        "compiled": {"method": loop.method, "substeps": loop.substeps, "native": native,
                     "native_error": loop.native_error,
                     "us_per_period": 1e6 * t_comp / round(duration / ctrl.sample_time),
                     "realtime_factor_median": duration / t_comp_med,
                     "realtime_factor_cpu": duration / cpu_comp},
        "compile_s": t_build,
        "compile_cached": loop.compile_cached,
        "jit": native,
        "wall_s": {"cvodes": t_cv, "compiled": t_comp, "compiled_median": t_comp_med,
                   "compiled_cpu": cpu_comp, "scipy_lsoda": t_sp,
                   "reference": ref_info["wall_s"]},
        "realtime_factor_by_method": {k: duration / v for k, v in times.items()},
        "max_position_error_m": err,
        "max_position_error_pct_stroke": {k: 100.0 * v / plant.stroke for k, v in err.items()},
        "accuracy_bound_m": bound,
        "accurate_by_method": ok,
        "reference": ref_info,
        "target": {"realtime_factor": 500, "speedup_vs_scipy": 30},
    }
