"""Timing helpers shared by the benchmarks: repeats, medians, spreads, baseline rows.

Every benchmark's result has the same core (``docs``: ``workbench bench NAME --json``)::

    {"benchmark": NAME, "median_s": ..., "spread": {...}, "error" or "cost": ...,
     "baselines": {name: {"median_s", "error", "ratio", "description", ...}},
     "machine": {...}, ...details}

``median_s`` is the median wall time of the measured operation over repeats;
``spread`` gives the minimum, quartiles and maximum of the wall and CPU (thread) times
over the same repeats. ``ratio`` is the baseline's median over ours (> 1: ours is
faster). Ours and the baselines are measured interleaved (one repeat of each in turn),
so load from other processes falls on all of them alike; the ratios are what to compare
between runs, the absolute times depend on the machine and its load.
"""

from __future__ import annotations

import os
import time
from typing import Any, Callable, Mapping

import numpy as np

__all__ = ["summary", "interleaved", "baseline", "unavailable", "machine", "contract_problems"]


def _quantiles(values) -> dict[str, float]:
    v = np.asarray(values, dtype=float)
    q = np.percentile(v, [0, 25, 50, 75, 100])
    return {"min": float(q[0]), "q25": float(q[1]), "median": float(q[2]),
            "q75": float(q[3]), "max": float(q[4])}


def summary(walls, cpus) -> dict[str, Any]:
    """``median_s`` and ``spread`` (wall and CPU quantiles, s) of repeated timings."""
    return {"median_s": float(np.median(walls)), "cpu_median_s": float(np.median(cpus)),
            "spread": {"repeats": len(walls), "wall_s": _quantiles(walls),
                       "cpu_s": _quantiles(cpus)}}


def interleaved(fns: Mapping[str, Callable[[], Any]], repeats: int,
                warmup: bool = True, cpu_clock: Callable[[], float] = time.thread_time
                ) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Run each function ``repeats`` times, round-robin; (last results, :func:`summary` each).

    Wall time by ``time.perf_counter``, CPU time by ``cpu_clock``: by default
    ``time.thread_time`` (the calling thread: robust to other processes, blind to work
    in other threads; ``time.process_time`` counts all threads of this process). With
    ``warmup`` each function runs once first, untimed (first-call costs: page faults,
    lazy loading).
    """
    results: dict[str, Any] = {}
    if warmup:
        for name, fn in fns.items():
            results[name] = fn()
    walls: dict[str, list[float]] = {k: [] for k in fns}
    cpus: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(max(1, int(repeats))):
        for name, fn in fns.items():
            c0, t0 = cpu_clock(), time.perf_counter()
            results[name] = fn()
            walls[name].append(time.perf_counter() - t0)
            cpus[name].append(cpu_clock() - c0)
    return results, {k: summary(walls[k], cpus[k]) for k in fns}


def baseline(stats: Mapping[str, Any], ours_median_s: float, error: float | None,
             description: str, ours_cpu_s: float | None = None,
             **extra: Any) -> dict[str, Any]:
    """One row of ``baselines``: its median (s), error, ratio to ours, description.

    ``ratio`` is of the wall-time medians; with ``ours_cpu_s`` (our CPU-time median)
    also ``cpu_ratio``, of the CPU-time medians of the running thread: on a loaded
    machine a short run waits for a core for a larger fraction of its wall time than a
    long one, and the CPU ratio is the steadier figure (a baseline with solver threads,
    IPOPT, is undercounted by it).
    """
    med = float(stats["median_s"])
    cpu = stats.get("cpu_median_s")
    row = {"median_s": med, "cpu_median_s": cpu,
           "spread": stats.get("spread"), "error": error,
           "ratio": med / ours_median_s if ours_median_s > 0 else None,
           "description": description, "available": True}
    if ours_cpu_s and cpu is not None:
        row["cpu_ratio"] = float(cpu) / ours_cpu_s
    row.update(extra)
    return row


def unavailable(description: str, reason: str) -> dict[str, Any]:
    """A baseline row for a baseline that could not run here (``reason`` says why)."""
    return {"median_s": None, "error": None, "ratio": None, "description": description,
            "available": False, "reason": reason}


def machine() -> dict[str, Any]:
    """CPU count and 1-minute load average: context for the absolute times."""
    try:
        load = float(os.getloadavg()[0])
    except (AttributeError, OSError):
        load = None
    return {"cpus": os.cpu_count(), "load_average_1min": load,
            "note": "absolute times depend on the machine and its load; compare ratios "
                    "(measured interleaved in one run); final figures need a quiet machine"}


#: the keys issue 16 asks of one benchmark's JSON beyond the common core
_REQUIRED = {"mpc": ("cpu_p99_ms",), "simulate": ("realtime_factor",)}


def contract_problems(res: Mapping[str, Any]) -> list[str]:
    """What the result of ``workbench bench NAME --json`` lacks of the common contract
    (empty: none): ``median_s`` (> 0), ``spread`` (``repeats``, wall and CPU quantiles),
    ``error`` or ``cost``, ``baselines`` ({name: {"median_s", "error", "ratio"}}, the
    ratio the baseline's median over ours -- over ours of the row's class where it
    names one, ``against`` --, None where it could not run), and per
    benchmark ``cpu_p99_ms`` (mpc), ``realtime_factor`` (simulate: simulated s over
    ``median_s``)."""
    out = []
    med = res.get("median_s")
    if not isinstance(med, (int, float)) or not med > 0:
        out.append(f"median_s is {med!r}, not a positive number")
    sp = res.get("spread")
    if not isinstance(sp, Mapping) or not {"repeats", "wall_s", "cpu_s"} <= set(sp):
        out.append("spread lacks repeats, wall_s or cpu_s")
    else:
        for kind in ("wall_s", "cpu_s"):
            q = sp[kind]
            if not (isinstance(q, Mapping) and q.get("min", -1) <= q.get("median", -2)
                    <= q.get("max", -3)):
                out.append(f"spread.{kind} is not min <= median <= max")
        if isinstance(med, (int, float)) and sp["wall_s"].get("median") != med:
            out.append("spread.wall_s.median is not median_s")
    if res.get("error") is None and res.get("cost") is None:
        out.append("neither error nor cost")
    rows = res.get("baselines")
    if not isinstance(rows, Mapping):
        out.append("no baselines mapping")
        rows = {}
    for name, row in rows.items():
        missing = {"median_s", "error", "ratio"} - set(row)
        if missing:
            out.append(f"baseline {name} lacks {', '.join(sorted(missing))}")
        elif row["median_s"] is not None and "against" in row:
            if not (isinstance(row["ratio"], (int, float)) and row["ratio"] > 0):
                out.append(f"baseline {name}: no ratio to ours ({row['against']})")
        elif row["median_s"] is not None and isinstance(med, (int, float)) and med > 0:
            if row["ratio"] is None or abs(row["ratio"] / (row["median_s"] / med) - 1) > 1e-9:
                out.append(f"baseline {name}: ratio is not its median_s / ours")
        elif row.get("ratio") is not None:
            out.append(f"baseline {name}: a ratio without a median_s")
    for key in _REQUIRED.get(res.get("benchmark"), ()):
        if not isinstance(res.get(key), (int, float)):
            out.append(f"{key} missing")
    if res.get("benchmark") == "simulate" and isinstance(med, (int, float)) and med > 0:
        rf, dur = res.get("realtime_factor"), res.get("simulated_s")
        if isinstance(rf, (int, float)) and isinstance(dur, (int, float)) \
                and abs(rf * med / dur - 1) > 1e-9:
            out.append("realtime_factor is not simulated_s / median_s")
    return out
