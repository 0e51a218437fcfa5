"""``workbench bench greybox``: grey-box estimation of 4 parameters from a simulated recording.

Timing numbers are for this machine at the time of the run. Nothing here is a test.
"""

from __future__ import annotations

import time
from pathlib import Path

from .timing import machine, summary

__all__ = ["bench"]

ROOT = Path(__file__).resolve().parents[2]

def bench(quick: bool = False) -> dict:
    """``workbench bench greybox``: 4 parameters from a 20 s, 1 kHz open-loop recording.

    The 25 mm reference rig with leakage to atmosphere (5e-10 m^3/(s Pa)); the recording
    is simulated by the workbench (CVODES, tight tolerances) under random command
    doublets, with noise 10 um on x and 200 Pa on the pressures. Mass, viscous friction,
    valve sonic conductance and leak conductance start 30-100 % off. ``quick``: 4 s.
    The wall time is that of :func:`~workbench.identify.grey_box.estimate` (compiled
    step functions come from the cache after the first run; the first run's compile
    time is reported separately).
    """
    from ..identify.grey_box import _step_functions, estimate, synthetic_recording
    from ..plant import Plant
    truth_vals = {"load.mass": 1.2, "load.viscous_friction": 40.0,
                  "valve.sonic_conductance": 6.25e-8,
                  "leakage.conductance_to_atmosphere": 5e-10}
    truth = Plant.from_toml(ROOT / "designs" / "plants" / "rig25_mpye.toml").with_params(
        **truth_vals)
    duration = 4.0 if quick else 20.0
    noise = {"x": 1e-5, "p_a": 200.0, "p_b": 200.0}
    t0 = time.perf_counter()
    rec = synthetic_recording(truth, duration, 1e-3, seed=1, noise=noise)
    t_data = time.perf_counter() - t0
    factors = {"load.mass": 1.5, "load.viscous_friction": 0.6,
               "valve.sonic_conductance": 1.3, "leakage.conductance_to_atmosphere": 2.0}
    start = truth.with_params(**{k: truth_vals[k] * f for k, f in factors.items()})
    names = list(truth_vals)
    # compile (or load) the step functions once, outside the timed run
    t0 = time.perf_counter()
    _step_functions(start, len(names), [start.output_index(s) for s in ("x", "p_a", "p_b")],
                    2, 3)
    t_compile = time.perf_counter() - t0
    c0 = time.thread_time()
    res = estimate(start, [rec], names)
    cpu = time.thread_time() - c0
    est = res.estimates
    rel = {k: est[k] / truth_vals[k] - 1.0 for k in names}
    within = res.within_ci(truth_vals)
    return {
        "benchmark": "greybox",
        **summary([res.wall_time], [cpu]),
        "error": float(max(abs(v) for v in rel.values())),
        "error_note": "largest relative error of the four estimates from the truth (-)",
        "baselines": {},
        "baselines_note": "no baseline yet (a plain scipy least_squares on a CVODES "
                          "simulation with finite-difference Jacobians would be the one)",
        "machine": machine(),
        "wall_time_s": res.wall_time,
        "samples": len(rec),
        "duration_s": duration,
        "parameters": names,
        "estimates": est,
        "truth": truth_vals,
        "start": {k: truth_vals[k] * factors[k] for k in names},
        "relative_error": rel,
        "std": dict(zip(names, map(float, res.std_))),
        "within_ci": dict(zip(names, map(bool, within))),
        "fit_before": res.fit_before[0],
        "fit_after": res.fit_after[0],
        "iterations": res.iterations,
        "status": res.status,
        "poor_fit": res.poor_fit,
        "compile_or_cache_s": t_compile,
        "data_generation_s": t_data,
        "method": dict(res.method),
        "target": {"wall_time_s": 60.0},
    }
