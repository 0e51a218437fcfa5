"""``workbench bench greybox``: grey-box estimation of 4 parameters from a simulated recording.

Timing numbers are for this machine at the time of the run. Nothing here is a test.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from .timing import baseline, interleaved, machine, unavailable

__all__ = ["bench"]

ROOT = Path(__file__).resolve().parents[2]

#: A baseline whose every estimate is within this many of our standard deviations of
#: ours reached the same accuracy (0.25 std of extra error adds 3 % to the rms error).
SAME_ACCURACY_STD = 0.25


def _timed(fns: Mapping[str, Callable[[], Any]], repeats: int):
    """Run each function ``repeats`` times, round-robin, no warm-up: (last results,
    summary each).

    CPU time is ``time.process_time`` (all threads of this process): the estimator
    maps its shooting intervals over up to 8 threads, which ``thread_time`` would miss.
    """
    return interleaved(fns, repeats, warmup=False, cpu_clock=time.process_time)

TRUTH = {"load.mass": 1.2, "load.viscous_friction": 40.0,
         "valve.sonic_conductance": 6.25e-8, "leakage.conductance_to_atmosphere": 5e-10}
#: Start values: the truth times these factors.
FACTORS = {"load.mass": 1.5, "load.viscous_friction": 0.6,
           "valve.sonic_conductance": 1.3, "leakage.conductance_to_atmosphere": 2.0}
#: Sensor noise of the simulated recording (standard deviations, SI).
NOISE = {"x": 1e-5, "p_a": 200.0, "p_b": 200.0}


def problem(duration: float):
    """(truth plant, start plant, recording) of the benchmark for a ``duration`` s record."""
    from ..identify.grey_box import synthetic_recording
    from ..plant import Plant
    truth = Plant.from_toml(ROOT / "designs" / "plants" / "rig25_mpye.toml").with_params(
        **TRUTH)
    rec = synthetic_recording(truth, duration, 1e-3, seed=1, noise=NOISE)
    start = truth.with_params(**{k: TRUTH[k] * f for k, f in FACTORS.items()})
    return truth, start, rec


def _baseline_row(base: dict, ours, stats: dict, ours_stats: dict) -> dict:
    """The ``baselines`` row of the least-squares baseline, with its accuracy vs ours."""
    from .baselines_greybox import DESCRIPTION, RTOL
    names = list(TRUTH)
    est = base["estimates"]
    rel = {k: est[k] / TRUTH[k] - 1.0 for k in names}
    dist = {k: abs(est[k] - ours.estimates[k]) / float(s)
            for k, s in zip(names, ours.std_)}
    return baseline(stats, ours_stats["median_s"], float(max(abs(v) for v in rel.values())),
                    DESCRIPTION, ours_cpu_s=ours_stats["cpu_median_s"],
                    estimates=est, relative_error=rel, distance_from_ours_std=dist,
                    same_accuracy=bool(max(dist.values()) <= SAME_ACCURACY_STD),
                    same_accuracy_note=f"every estimate within {SAME_ACCURACY_STD} of "
                                       "our standard deviation of ours",
                    cost=base["cost"], nfev=base["nfev"], status=base["status"],
                    message=base["message"], setup_s=base["setup_s"],
                    segments=base["segments"], rtol=RTOL)


def bench(quick: bool = False) -> dict:
    """``workbench bench greybox``: 4 parameters from a 20 s, 1 kHz open-loop recording.

    The 25 mm reference rig with leakage to atmosphere (5e-10 m^3/(s Pa)); the recording
    is simulated by the workbench (CVODES, tight tolerances) under random command
    doublets, with noise 10 um on x and 200 Pa on the pressures. Mass, viscous friction,
    valve sonic conductance and leak conductance start 30-100 % off. ``quick``: 4 s.
    Timed, interleaved (3 repeats, 1 when ``quick``): :func:`~workbench.identify.
    grey_box.estimate` (compiled step functions come from the cache after the first
    run; the first run's compile time is reported separately) and the plain baseline
    of :mod:`.baselines_greybox` (scipy ``least_squares`` on CVODES replays), each from
    the same start. CPU times are of the whole process (the estimator uses threads).
    """
    from ..identify.grey_box import _step_functions, estimate
    from .baselines_greybox import fit
    duration = 4.0 if quick else 20.0
    t0 = time.perf_counter()
    truth, start, rec = problem(duration)
    t_data = time.perf_counter() - t0
    names = list(TRUTH)
    # compile (or load) the step functions once, outside the timed runs
    t0 = time.perf_counter()
    _step_functions(start, len(names), [start.output_index(s) for s in ("x", "p_a", "p_b")],
                    2, 3)
    t_compile = time.perf_counter() - t0
    fns = {"ours": lambda: estimate(start, [rec], names),
           "least_squares": lambda: fit(start, rec, names, NOISE)}
    try:
        results, stats = _timed(fns, 1 if quick else 3)
    except Exception as exc:  # noqa: BLE001 -- the baseline failing is a result, ours is not
        from ..output import reraise_interrupt
        reraise_interrupt(exc)
        fns.pop("least_squares")
        results, stats = _timed(fns, 1 if quick else 3)
        results["least_squares"] = exc
    res = results["ours"]
    est = res.estimates
    rel = {k: est[k] / TRUTH[k] - 1.0 for k in names}
    within = res.within_ci(TRUTH)
    base = results["least_squares"]
    if isinstance(base, Exception):
        row = unavailable(_description(), f"the baseline failed: {base}")
    else:
        row = _baseline_row(base, res, stats["least_squares"], stats["ours"])
    return {
        "benchmark": "greybox",
        **stats["ours"],
        "cpu_clock": "process_time (all threads of the process)",
        "error": float(max(abs(v) for v in rel.values())),
        "error_note": "largest relative error of the four estimates from the truth (-)",
        "baselines": {"least_squares": row},
        "machine": machine(),
        "wall_time_s": res.wall_time,
        "samples": len(rec),
        "duration_s": duration,
        "parameters": names,
        "estimates": est,
        "truth": dict(TRUTH),
        "start": {k: TRUTH[k] * FACTORS[k] for k in names},
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


def _description() -> str:
    from .baselines_greybox import DESCRIPTION
    return DESCRIPTION
