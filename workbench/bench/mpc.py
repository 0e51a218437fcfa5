"""``workbench bench mpc``: NMPC solve times per control step, against do-mpc when installed.

Timing numbers are for this machine at the time of the run; the ratios are what to
compare between runs. Nothing here is a test.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["bench", "bench_reference"]

ROOT = Path(__file__).resolve().parents[2]

#: Plant of the benchmark (issue: the 25 mm reference plant, 4 states).
BENCH_PLANT = "designs/plants/rig25_mpye.toml"


def bench_reference(plant, duration: float = 20.0):
    """The standard validation profile compressed to ``duration`` (>= 9 s) seconds.

    Its holds are shortened so that the whole profile (steps of 125, 250 and 10 mm
    both ways, ramps at 0.1 m/s) lasts ``duration``.
    """
    from ..validate import validation_profile
    L = plant.stroke
    fixed = 0.5 + (0.9 * L - 0.25 * L) / (0.2 * L) + (0.8 * L) / (0.2 * L)   # start hold + ramps
    hold = (duration - fixed) / 6.0
    if hold <= 0.2:
        raise InputError(f"the validation profile needs more than {fixed + 1.2:g} s")
    return validation_profile(plant, hold=hold)


def _timed(controller):
    """Recorder that also keeps the thread CPU time of each update."""
    from ..controllers.mpc import Recorder
    rec = Recorder(controller)
    cpu: list[float] = []
    inner = rec.update

    def update(state, r, y):
        t0 = time.thread_time()
        out = inner(state, r, y)
        cpu.append(time.thread_time() - t0)
        return out

    rec.update = update
    rec.cpu = cpu
    return rec


def _iae(run) -> float:
    e = np.abs(run.reference - run["x"])
    return float(np.sum(0.5 * (e[1:] + e[:-1]) * np.diff(run.time)))


def bench(quick: bool = False, jit: bool = True) -> dict:
    """NMPC solve time per control step, ours against do-mpc on the same problem.

    Horizon 20 samples of 10 ms on ``designs/plants/rig25_mpye.toml`` (4 states), the
    standard validation profile compressed to 20 s (``quick``: its first 3 s), run in
    :func:`workbench.simulate.closed_loop` on the nominal plant. Times are wall
    clock per ``update`` call (everything the controller does in a sample; the
    first sample, which runs SQP to convergence, included), with the thread CPU
    time beside them (robust to other load on the machine). The disturbance observer
    is off (do-mpc has none), so every controller solves the same problem.

    Ours runs twice: the default real-time iteration (one Gauss-Newton step per
    sample; the headline ``median_ms``, ``p99_ms``) and SQP to convergence capped at
    5 steps per sample (``sqp_*``), which reaches the optimum do-mpc's IPOPT finds.

    Returns
    -------
    dict
        ``median_ms``, ``p99_ms`` (ours, RTI), ``do_mpc_median_ms`` (None without
        do-mpc), ``speedup_vs_do_mpc`` (do-mpc median / ours), ``iae_m_s`` and
        ``do_mpc_iae_m_s`` (integral of |r - x|, m s), the same for SQP, maximum
        errors, CPU times and notes.
    """
    from ..controllers.mpc import NMPC
    from ..plant import Plant
    plant = Plant.from_toml(ROOT / BENCH_PLANT)
    duration = 3.0 if quick else 20.0
    ref = bench_reference(plant, 20.0)
    t_build = time.perf_counter()
    nmpc = NMPC.for_plant(plant, horizon=20, sample_time=0.01, disturbance_gain=0.0, jit=jit)
    t_build = time.perf_counter() - t_build
    sqp = nmpc.with_settings(mode="sqp", max_iterations=5)
    out: dict[str, Any] = {"plant": BENCH_PLANT, "horizon": nmpc.horizon,
                           "sample_time_s": nmpc.sample_time, "simulated_s": duration,
                           "mode": nmpc.mode, "qp_solver": nmpc.qp_solver,
                           "substeps": nmpc.substeps, "sensitivities": nmpc.sensitivities,
                           "jit": jit, "build_s": t_build}

    def run(ctrl, prefix: str) -> None:
        out.update(_timings(plant, ctrl, ref, duration, prefix))

    run(nmpc, "")
    out["steps"] = int(round(duration / nmpc.sample_time)) + 1
    run(sqp, "sqp_")
    notes = _do_mpc_baseline(nmpc, out, run)
    out["target"] = {"median_ms": 1.0, "p99_ms": 5.0, "speedup_vs_do_mpc": 10.0}
    out["meets_target"] = bool(out["median_ms"] < 1.0 and out["p99_ms"] < 5.0)
    out["notes"] = notes
    return out


def _timings(plant, ctrl, ref, duration: float, prefix: str) -> dict[str, Any]:
    """Solve times (ms), CPU times (ms), IAE (m s) and the largest error (m) of ``ctrl``
    in the closed loop, keys prefixed by ``prefix``."""
    from .. import simulate
    rec = _timed(ctrl)
    traj = simulate.closed_loop(plant, rec, ref, t_end=duration, x0=ref(0.0), progress=False)
    ms = np.array(rec.times) * 1e3
    cpu = np.array(rec.cpu) * 1e3
    out = {f"{prefix}median_ms": float(np.median(ms)),
           f"{prefix}p99_ms": float(np.percentile(ms, 99)),
           f"{prefix}max_ms": float(np.max(ms)),
           f"{prefix}cpu_median_ms": float(np.median(cpu)),
           f"{prefix}cpu_p99_ms": float(np.percentile(cpu, 99)),
           f"{prefix}iae_m_s": _iae(traj),
           f"{prefix}max_error_m": float(np.max(np.abs(traj.reference - traj["x"])))}
    infos = [i for i in rec.infos if i is not None]
    if infos:
        out.update({f"{prefix}iterations_mean": float(np.mean([i.iterations for i in infos])),
                    f"{prefix}qp_failures": int(sum(not i.success for i in infos)),
                    f"{prefix}restarts": int(sum(i.restarted for i in infos))})
    else:
        out[f"{prefix}steps"] = len(ms)
    return out


def _do_mpc_baseline(nmpc, out: dict[str, Any], run) -> list[str]:
    """Run do-mpc on the same problem (``run(controller, "do_mpc_")``) and add its times
    and the ratios to ``out``; None for all of them without do-mpc. Returns notes."""
    from ..controllers.mpc import DoMPC
    notes = []
    try:
        dm = DoMPC(nmpc)
    except ImportError:
        dm = None
        notes.append("do-mpc is not installed (pip install do-mpc==5.1.2): no baseline")
    keys = ("median_ms", "p99_ms", "max_ms", "cpu_median_ms", "cpu_p99_ms", "iae_m_s",
            "max_error_m")
    if dm is not None:
        out["do_mpc_version"] = dm.version
        run(dm, "do_mpc_")
        out.pop("do_mpc_steps", None)
        for pre in ("", "sqp_"):
            out[f"{pre}speedup_vs_do_mpc"] = out["do_mpc_median_ms"] / out[f"{pre}median_ms"]
            out[f"{pre}iae_ratio_vs_do_mpc"] = out[f"{pre}iae_m_s"] / out["do_mpc_iae_m_s"]
    else:
        out["do_mpc_version"] = None
        out.update({f"do_mpc_{k}": None for k in keys})
        for pre in ("", "sqp_"):
            out[f"{pre}speedup_vs_do_mpc"] = None
            out[f"{pre}iae_ratio_vs_do_mpc"] = None
    return notes
