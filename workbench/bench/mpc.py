"""``workbench bench mpc``: NMPC time per sample against the strongest plain baselines,
all run in lockstep on the same closed loop.

Timing numbers are for this machine at the time of the run; the ratios (measured
interleaved, sample by sample) are what to compare between runs. Nothing here is a test.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from .timing import baseline, machine, unavailable

__all__ = ["bench", "bench_reference", "lockstep", "rti_breakdown"]

ROOT = Path(__file__).resolve().parents[2]

#: Plant of the benchmark (issue: the 25 mm reference plant, 4 states).
BENCH_PLANT = "designs/plants/rig25_mpye.toml"
#: s: the closed loop of the full run (the validation profile compressed to it)
FULL_S = 10.0
#: s: the old baseline (do-mpc at its defaults) runs in lockstep with ours converged
#: over the loop's first OLD_S seconds only (the full run stays within 3 minutes)
OLD_S = 2.0
#: RK4 steps per 10 ms interval of the benchmark's NMPC (ours and every baseline). Two:
#: along the benchmark's closed loop the one-interval prediction differs from Radau at
#: rtol 1e-10 by at most 2.3e-6 of the stroke, 2.7e-5 m/s and 3.8e-6 of supply
#: pressure (4 steps: 16x less, order 4), far below the model's own error against the
#: plant; the closed-loop cost of ours converged differs from 4 and 8 steps by < 0.01 %
#: (/tmp script in the h16b report: Radau on every 5th sample of the loop).
SUBSTEPS = 2
#: ours, adaptive: a second (third) Gauss-Newton step only where the step before moved
#: the planned commands by more than this (scaled, 1 % of the command span): one QP
#: on quiet samples, up to three after a jump of the reference
ADAPTIVE = {"mode": "sqp", "max_iterations": 3, "tolerance": 1e-2}


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


def lockstep(plant, controllers: dict, ref, duration: float, nmpc) -> dict[str, dict]:
    """Run every controller on its own copy of the plant, one sample of each in turn.

    The plant is integrated by CVODES (:class:`workbench.simulate.Simulator`) with the
    command clipped to the valve range and held for one sample. Per controller: wall
    and thread-CPU time of every ``update`` (s), positions, velocities, commands.
    """
    from ..simulate import Simulator
    sim = Simulator(plant)
    T = nmpc.sample_time
    n = int(round(duration / T))
    lo, hi = plant.params["valve.command_min"], plant.params["valve.command_max"]
    names = ("x", "v", "p_a", "p_b")
    idx = [plant.state_index(k) for k in names]
    x0 = plant.initial_state(float(ref(0.0)))
    runs = {k: {"x": np.empty(n + 1), "v": np.empty(n + 1), "u": np.empty(n), "wall": [],
                "cpu": [], "state": x0.copy(), "mem": c.reset()} for k, c in controllers.items()}
    for run in runs.values():
        run["x"][0], run["v"][0] = x0[idx[0]], x0[idx[1]]
    r = np.asarray(ref(T * np.arange(n + 1)), dtype=float)
    for k in range(n):
        if n >= 100 and k % (n // 10) == 0:
            print(f"bench mpc: sample {k}/{n}", file=sys.stderr, flush=True)
        for name, c in controllers.items():
            run = runs[name]
            y = dict(zip(names, (float(run["state"][i]) for i in idx)))
            c0, t0 = time.thread_time(), time.perf_counter()
            run["mem"], u = c.update(run["mem"], float(r[k]), y)
            run["wall"].append(time.perf_counter() - t0)
            run["cpu"].append(time.thread_time() - c0)
            if hasattr(run["mem"], "phase_times"):         # the compiled sample's own
                run.setdefault("phases", []).append(run["mem"].phase_times())
            run["u"][k] = u = float(np.clip(u, lo, hi))
            run["state"] = sim.step(run["state"], u, T)[-1]
            run["x"][k + 1], run["v"][k + 1] = run["state"][idx[0]], run["state"][idx[1]]
    for run in runs.values():
        run["r"] = r
    return runs


def _scores(run: dict, nmpc, T: float) -> dict[str, Any]:
    """Per-sample times (s; medians, quartiles, CPU p99 in ms), closed-loop cost and IAE."""
    wall, cpu = np.array(run["wall"]), np.array(run["cpu"])
    q = np.percentile(wall, [0, 25, 50, 75, 100])
    qc = np.percentile(cpu, [0, 25, 50, 75, 99, 100])
    e = run["x"] - run["r"]
    dr = np.diff(run["r"]) / T
    vr = np.where(np.abs(dr) < nmpc.reference_rate_limit, dr, 0.0)
    du = np.diff(np.concatenate(([run["u"][0]], run["u"])))
    cost = 0.5 * float(np.sum((e[1:] / nmpc.position_tolerance) ** 2)
                       + np.sum(((run["v"][1:] - vr) / nmpc.velocity_tolerance) ** 2)
                       + np.sum((du / nmpc.command_rate_tolerance) ** 2))
    return {"median_s": float(q[2]), "cpu_median_s": float(qc[2]),
            "spread": {"repeats": len(wall),
                       "wall_s": dict(zip(("min", "q25", "median", "q75", "max"), map(float, q))),
                       "cpu_s": dict(zip(("min", "q25", "median", "q75", "max"),
                                         map(float, qc[[0, 1, 2, 3, 5]])))},
            "cpu_p99_ms": 1e3 * float(qc[4]), "p99_ms": 1e3 * float(np.percentile(wall, 99)),
            "cost": cost, "iae_m_s": float(np.sum(np.abs(e[1:])) * T),
            "max_error_m": float(np.max(np.abs(e)))}


_DESCRIPTIONS = {
    "plain_rti_osqp": "Gauss-Newton RTI on the same NLP, sparse (uncondensed) QP by OSQP "
                      "(OSQP's defaults: eps 1e-3, rho, scaling; polished; warm started with the "
                      "multipliers shifted), Jacobians generated as C; one QP per sample",
    "ipopt_gauss_newton": "IPOPT to convergence on the same NLP, Gauss-Newton Hessian "
                          "(hess_lag), expanded to SX, warm-started primal and dual",
    "do_mpc_recommended": "do-mpc 5 on the same problem (collocation), IPOPT with expand and "
                          "warm start as do-mpc's documentation recommends",
    "do_mpc_defaults": "old baseline: do-mpc with IPOPT at its defaults (in lockstep with "
                       f"ours converged over the first {OLD_S:g} s only: 85 ms a sample)",
}
#: which of ours each baseline is compared with: RTI with RTI, converged with converged
_AGAINST = {"plain_rti_osqp": "rti", "ipopt_gauss_newton": "sqp", "do_mpc_recommended": "sqp",
            "do_mpc_defaults": "sqp"}


def _baselines(nmpc_vm) -> tuple[dict, dict]:
    """(controllers that could be built, {name: reason} of those that could not)."""
    from . import baselines_mpc as bl
    ctrls, missing = {}, {}
    why = bl.osqp_unavailable()
    if why:
        missing["plain_rti_osqp"] = why
    else:
        ctrls["plain_rti_osqp"] = bl.PlainRTI(nmpc_vm, qp="osqp")
    ctrls["ipopt_gauss_newton"] = bl.ipopt_gauss_newton(nmpc_vm)
    try:
        from ..controllers.mpc import DoMPC
        ctrls["do_mpc_recommended"] = bl.do_mpc_recommended(nmpc_vm)
        ctrls["do_mpc_defaults"] = DoMPC(nmpc_vm)
    except ImportError as exc:
        for k in ("do_mpc_recommended", "do_mpc_defaults"):
            missing[k] = f"do-mpc is not installed (pip install workbench[bench]): {exc}"
    return ctrls, missing


def _alone(plant, mine: dict, nmpc, ref, duration: float, plain_from) -> dict:
    """Ours (``mine``: name -> controller) and the plain RTI each run alone over the
    same closed loop.

    In lockstep every controller starts its sample with caches cold from the others
    (IPOPT, do-mpc); a controller on its own core does not. Each here runs in a loop of
    its own (only the plant's integration in between): the time per sample it would
    have on a controller, and the ratio of the two under that condition.
    """
    out = {"note": "each controller alone in its closed loop (caches warm from its own "
                   "previous sample); the headline median_s is from the lockstep run"}
    runs = {k: lockstep(plant, {k: c}, ref, duration, nmpc)[k] for k, c in mine.items()}
    if plain_from is not None:
        from .baselines_mpc import PlainRTI
        runs["plain_rti_osqp"] = lockstep(plant, {"p": PlainRTI(plain_from)}, ref, duration,
                                          nmpc)["p"]
    for k, run in runs.items():
        sc = _scores(run, nmpc, nmpc.sample_time)
        out[k] = {q: sc[q] for q in ("median_s", "cpu_median_s", "cpu_p99_ms", "cost")}
        if "phases" in run:
            out[k]["phases_us"] = phase_medians(run)
    if "plain_rti_osqp" in out:
        for k in mine:
            out[k]["ratio_plain_rti_osqp"] = (out["plain_rti_osqp"]["median_s"]
                                              / out[k]["median_s"])
            out[k]["cpu_ratio_plain_rti_osqp"] = (out["plain_rti_osqp"]["cpu_median_s"]
                                                  / out[k]["cpu_median_s"])
    return out


def phase_medians(run: dict) -> dict[str, float]:
    """us, medians over the run's samples of the compiled sample's phases (the
    linearisation ``lin``: shift, estimate, interval maps; ``condense``; ``prep``: the
    two; the QP; post; the whole sample in C) and of the update as Python saw it
    (``update``)."""
    ph = np.asarray(run["phases"])
    ph = 1e6 * np.median(np.column_stack([ph[:, 0] + ph[:, 1], ph]), axis=0)
    return {"prep": float(ph[0]), "lin": float(ph[1]), "condense": float(ph[2]),
            "qp": float(ph[3]), "post": float(ph[4]), "sample_in_c": float(ph[5]),
            "update": 1e6 * float(np.median(run["wall"]))}


def _interior_row(alone: dict, ctrl) -> dict:
    """The ``interior_limits`` row of the result: ours (adaptive) with the limits also
    between the nodes, alone, against the issue's targets."""
    a = dict(alone.get("adaptive_interior_limits", {}))
    pb = getattr(ctrl, "pb", None) or ctrl._problem
    ratio = a.get("ratio_plain_rti_osqp")
    a.update(rows=pb.n_rows, points_per_interval=pb.m_int,
             cost_vs_adaptive=a["cost"] / alone["adaptive"]["cost"] - 1.0,
             met={"median_s": a["median_s"] <= TARGETS["median_s"],
                  "cpu_p99_ms": a["cpu_p99_ms"] <= TARGETS["cpu_p99_ms"],
                  "ratio_plain_rti_osqp": None if ratio is None
                  else bool(ratio >= TARGETS["ratio_plain_rti_osqp"])},
             description="ours, adaptive, with the stroke, pressure and speed limits also "
                         "at the RK4 substep ends between the nodes (the NMPC's default; "
                         "the baselines and the headline keep them at the nodes), alone")
    return a


def _compiled(ctrls: dict, jit: bool) -> tuple[dict, str | None]:
    """The controllers as :class:`~workbench.controllers.mpc.fast.CompiledNMPC` (the
    whole sample one C call), or as they are and why not (no compiler, ``jit`` off)."""
    from ..controllers.mpc.fast import CompiledNMPC, compiled_unavailable
    why = "jit off: the NMPC as it is" if not jit else compiled_unavailable()
    if why:
        return dict(ctrls), why
    return {k: CompiledNMPC(c) for k, c in ctrls.items()}, None


def _baseline_rows(sc: dict, ctrls: dict, missing: dict) -> dict:
    """The ``baselines`` of the result: each against ours of its class (scores ``sc``)."""
    rows = {}
    for name in _DESCRIPTIONS:
        if name in missing:
            rows[name] = unavailable(_DESCRIPTIONS[name], missing[name])
            continue
        mine = sc["sqp_short" if name == "do_mpc_defaults" else _AGAINST[name]]
        rows[name] = baseline(sc[name], mine["median_s"], sc[name]["cost"] / mine["cost"] - 1.0,
                              _DESCRIPTIONS[name], ours_cpu_s=mine["cpu_median_s"],
                              against=_AGAINST[name],
                              cpu_p99_ms=sc[name]["cpu_p99_ms"], cost=sc[name]["cost"],
                              iae_m_s=sc[name]["iae_m_s"],
                              qp_failures=getattr(ctrls[name], "failures", None),
                              valid=bool(getattr(ctrls[name], "failures", 0) == 0
                                         and sc[name]["cost"] < 1.1 * mine["cost"]))
    return rows


def _ours_rows(sc: dict, nmpc) -> dict:
    """The result's rows of ours besides the headline (scores ``sc``): the NMPC through
    ``NMPC.update`` with and without its compiled sample, sqp2, adaptive."""
    head = sc["rti"]
    return {
        "rti_uncompiled": {**sc["rti_uncompiled"],
                           "ratio": sc["rti_uncompiled"]["median_s"] / head["median_s"],
                           "cost_difference": sc["rti_uncompiled"]["cost"] / head["cost"] - 1.0,
                           "description": "the same NMPC through NMPC.update with "
                                          "compiled_sample off (Python around the "
                                          "compiled step)"},
        "rti_nmpc": {**sc["rti_nmpc"],
                     "ratio": sc["rti_nmpc"]["median_s"] / head["median_s"],
                     "description": "the same NMPC through NMPC.update with its default "
                                    "compiled_sample (one C call, the memory copied "
                                    "into and out of an NMPCState)",
                     "compiled_reason": nmpc.compiled_reason},
        "sqp2": {**sc["sqp2"], "error": sc["sqp2"]["cost"] / sc["sqp"]["cost"] - 1.0,
                 "description": "ours with at most 2 Gauss-Newton steps per sample "
                                "(a second only where the first moved the plan by more "
                                "than the tolerance)"},
        "adaptive": {**sc["adaptive"], "error": sc["adaptive"]["cost"] / sc["sqp"]["cost"] - 1.0,
                     "settings": ADAPTIVE,
                     "description": "ours with a second and third Gauss-Newton step only "
                                    "where the step before moved the planned commands by "
                                    "more than 1 % of the command span"},
    }


def bench(quick: bool = False, jit: bool = True, duration: float | None = None) -> dict:
    """NMPC time per sample, ours against the plain baselines, all in lockstep.

    Horizon 20 samples of 10 ms, :data:`SUBSTEPS` RK4 steps per sample (ours and the
    baselines), on ``designs/plants/rig25_mpye.toml`` (4 states), the
    validation profile compressed to 10 s (``quick``: its first 3 s; 10 s keeps the
    full run, with IPOPT and do-mpc on every sample, within minutes), disturbance
    observer off (the baselines have none). Ours runs twice, each sample one compiled C
    call (:mod:`workbench.controllers.mpc.fast`; as ``rti_uncompiled`` also through
    ``NMPC.update``, for comparison): RTI (the headline:
    ``median_s`` per sample, ``cpu_p99_ms``, ``cost``) and SQP to convergence (at most
    5 steps per sample, ``converged``). Each baseline's ``ratio`` is its median over
    that of ours in the same class (RTI vs RTI, converged vs converged); ``error`` is
    its closed-loop cost relative to ours - 1. The first sample (a cold start) counts.
    Also: ``sqp2`` (ours with at most two steps per sample), ``adaptive`` (a second and
    third step only where the step before moved the plan by more than 1 % of the command
    span, :data:`ADAPTIVE`), ``targets_met`` (which configuration meets which of the
    issue's targets, :func:`targets_met`), ``alone`` (ours and the
    plain RTI each in a loop of its own, see :func:`_alone`) and ``variants`` (the
    friction, deadband and line models, :mod:`.mpc_variants`) and ``interior_limits``
    (adaptive with the limits also between the nodes, the NMPC's default, alone; the
    headline and the baselines keep them at the nodes).
    """
    from ..controllers.mpc import NMPC
    from ..plant import Plant
    plant = Plant.from_toml(ROOT / BENCH_PLANT)
    duration = duration or (3.0 if quick else FULL_S)
    ref = bench_reference(plant, FULL_S)
    t0 = time.perf_counter()
    nmpc = NMPC.for_plant(plant, horizon=20, sample_time=0.01, disturbance_gain=0.0, jit=jit,
                          substeps=SUBSTEPS, interior_limits=False)   # as the baselines' limits
    sqp = nmpc.with_settings(mode="sqp", max_iterations=5)
    sqp2 = nmpc.with_settings(mode="sqp", max_iterations=2)
    adaptive = nmpc.with_settings(**ADAPTIVE)
    ours, why = _compiled({"rti": nmpc, "sqp": sqp, "sqp2": sqp2, "adaptive": adaptive}, jit)
    build = time.perf_counter() - t0
    # first in each lockstep sample: they pay for the caches the baselines flushed
    ours = {"rti_uncompiled": nmpc.with_settings(compiled_sample=False), "rti_nmpc": nmpc,
            **ours}
    ctrls, missing = _baselines(nmpc.with_settings(jit=False))
    old = {k: ctrls.pop(k) for k in ("do_mpc_defaults",) if k in ctrls}
    runs = lockstep(plant, {**ours, **ctrls}, ref, duration, nmpc)
    sc = {k: _scores(v, nmpc, nmpc.sample_time) for k, v in runs.items()}
    if old:                                  # its own, shorter lockstep with ours converged
        short = lockstep(plant, {"sqp": ours["sqp"], **old}, ref, min(duration, OLD_S), nmpc)
        ss = {k: _scores(v, nmpc, nmpc.sample_time) for k, v in short.items()}
        sc["do_mpc_defaults"], sc["sqp_short"] = ss["do_mpc_defaults"], ss["sqp"]
        ctrls.update(old)
    rows = _baseline_rows(sc, ctrls, missing)
    head = sc["rti"]
    # ours with the limits between the nodes too (the baselines have them at the nodes
    # only): the cost of the NMPC's default, timed alone like the others
    rows_on = _compiled({"a": adaptive.with_settings(interior_limits=True)}, jit)[0]["a"]
    alone = _alone(plant, {**{k: ours[k] for k in ("rti", "sqp2", "adaptive", "rti_nmpc")},
                           "adaptive_interior_limits": rows_on}, nmpc, ref, duration,
                   None if "plain_rti_osqp" in missing else nmpc.with_settings(jit=False))
    from .mpc_variants import variants
    var = variants(plant, ref, min(duration, 5.0), nmpc,
                   lambda c: _compiled({"c": c}, jit)[0]["c"], lockstep, _scores)
    return {"benchmark": "mpc", **{k: head[k] for k in ("median_s", "cpu_median_s", "spread",
                                                        "cpu_p99_ms", "p99_ms", "cost")},
            "error": head["cost"] / sc["sqp"]["cost"] - 1.0,
            "error_note": "closed-loop cost of RTI relative to ours converged (SQP) - 1",
            "iae_m_s": head["iae_m_s"], "max_error_m": head["max_error_m"],
            "converged": sc["sqp"], "baselines": rows,
            "compiled_sample": why is None,
            "compiled_sample_note": why or (
                "ours (rti, sqp) run the whole sample as one compiled C call "
                "(controllers.mpc.fast): the linearisation generated by CasADi, the "
                "condensing in the driver, DAQP on the rows of the last working set and "
                "those its solution violates (the full QP's optimum; fast_c)"),
            **_ours_rows(sc, nmpc), "rti_breakdown": rti_breakdown(nmpc, runs["rti_uncompiled"]),
            "compiled_phases_us": phase_medians(runs["rti"]) if "phases" in runs["rti"] else None,
            "alone": alone, "variants": var,
            "targets_met": targets_met(sc, alone, var),
            "interior_limits": _interior_row(alone, rows_on),
            "targets_note": "judged on each configuration alone (its own loop, warm caches: "
                            "the time it would take on a controller); lockstep: interleaved "
                            "with IPOPT and do-mpc, whose samples flush the caches (the first "
                            "of ours after them pays most)",
            "variants_note": "friction, deadband and line versions of the prediction model "
                             "(bench.mpc_variants), each in lockstep with the 4-state model "
                             "on the variant plant for min(simulated_s, 5 s); ratio = "
                             "variant median / 4-state median",
            "plant": BENCH_PLANT, "horizon": nmpc.horizon, "sample_time_s": nmpc.sample_time,
            "substeps": nmpc.substeps,
            "simulated_s": duration, "samples": len(runs["rti"]["wall"]), "jit": jit,
            "build_s": build, "qp_solver": nmpc.qp_solver,
            "target": TARGETS,
            "machine": machine()}


#: the issue's targets for one configuration of ours
TARGETS = {"median_s": 0.15e-3, "cpu_p99_ms": 0.5, "ratio_plain_rti_osqp": 10.0,
           "cost_vs_converged": 0.01, "variants_ratio": 3.0}


def targets_met(sc: dict, alone: dict, var: dict) -> dict[str, dict]:
    """Which configuration of ours meets which target, each judged on the controller
    alone (its own loop, :func:`_alone`) and in lockstep (caches cold from IPOPT and
    do-mpc).

    Per configuration (rti, sqp2, adaptive): the median and CPU p99 per sample, the
    ratio to the plain RTI, the closed-loop cost relative to ours converged (SQP)
    and a verdict per target (True / False; None where the plain RTI did not run);
    ``all`` when every one holds alone. Variants: the largest variant / 4-state ratio.
    """
    conv = sc["sqp"]["cost"]
    out = {}
    for k in ("rti", "sqp2", "adaptive"):
        a = alone.get(k, {})
        ratio = a.get("ratio_plain_rti_osqp")
        plain = sc.get("plain_rti_osqp")
        row = {"median_s_alone": a.get("median_s"), "cpu_p99_ms_alone": a.get("cpu_p99_ms"),
               "median_s_lockstep": sc[k]["median_s"], "cpu_p99_ms_lockstep": sc[k]["cpu_p99_ms"],
               "ratio_plain_rti_osqp_alone": ratio,
               "ratio_plain_rti_osqp_lockstep": None if plain is None
               else plain["median_s"] / sc[k]["median_s"],
               "cost_vs_converged": sc[k]["cost"] / conv - 1}
        ok = {"median_s": a.get("median_s", np.inf) <= TARGETS["median_s"],
              "cpu_p99_ms": a.get("cpu_p99_ms", np.inf) <= TARGETS["cpu_p99_ms"],
              "ratio_plain_rti_osqp": None if ratio is None
              else bool(ratio >= TARGETS["ratio_plain_rti_osqp"]),
              "cost_vs_converged": abs(row["cost_vs_converged"]) <= TARGETS["cost_vs_converged"],
              "median_s_lockstep": sc[k]["median_s"] <= TARGETS["median_s"],
              "cpu_p99_ms_lockstep": sc[k]["cpu_p99_ms"] <= TARGETS["cpu_p99_ms"]}
        ok = {q: (None if v is None else bool(v)) for q, v in ok.items()}
        row["met"] = ok
        row["all"] = all(ok[q] for q in ("median_s", "cpu_p99_ms", "ratio_plain_rti_osqp",
                                         "cost_vs_converged"))
        out[k] = row
    worst = max((v["ratio"] for v in var.values()), default=None)
    out["variants"] = {"worst_ratio": worst,
                       "met": None if worst is None else bool(worst <= TARGETS["variants_ratio"])}
    return out


def rti_breakdown(nmpc, run: dict, calls: int = 200) -> dict[str, float]:
    """Where the time of one RTI sample of the NMPC through ``NMPC.update`` with its
    compiled sample off goes (us, medians over ``calls`` repeated calls at a mid-run
    sample; the compiled sample's own phases: ``compiled_phases_us``): the compiled prep
    (shift, Jacobians, condensing as generated by CasADi), the QP (all rows, cold), the
    compiled post (plan update), the whole step function, and the rest of ``update``
    (Python: argument packing, the memory object) from the run's median."""
    from ..controllers.mpc.qp import apply_step, prepare, qp_solver
    from ..integrate.jit import compiled
    pb = nmpc._problem
    mem = run["mem"]
    args = [mem.X, mem.U, 1.0, mem.z, float(run["r"][-1]) / pb.L, 0.0, mem.u_prev, mem.z,
            mem.d, 0.0, pb.P]
    prep, post = prepare(pb), apply_step(pb)
    if nmpc.jit:
        prep, post = compiled(prep), compiled(post)
    qp = qp_solver(nmpc.qp_solver, pb.N + pb.ns, pb.n_rows)

    def med(fn) -> float:
        fn()
        ts = []
        for _ in range(calls):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        return 1e6 * float(np.median(ts))
    o = prep(*args)
    sol = qp(h=o[0], g=o[1], a=o[2], lba=o[3], uba=o[4], lbx=o[5], ubx=o[6])
    out = {"step_function_us": med(lambda: pb.step(*args)),
           "prep_us": med(lambda: prep(*args)),
           "qp_us": med(lambda: qp(h=o[0], g=o[1], a=o[2], lba=o[3], uba=o[4], lbx=o[5],
                                   ubx=o[6])),
           "post_us": med(lambda: post(o[9], o[10], o[7], o[8], sol["x"], pb.P))}
    out["update_median_us"] = 1e6 * float(np.median(run["wall"]))
    out["python_overhead_us"] = out["update_median_us"] - out["step_function_us"]
    return out
