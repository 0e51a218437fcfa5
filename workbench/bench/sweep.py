"""``workbench bench sweep``: the stability map against a point-by-point loop with the
model built once.

Timing numbers are for this machine at the time of the run; the ratios are what to
compare between runs. Nothing here is a test.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from .timing import baseline, interleaved, machine, summary

__all__ = ["bench"]

ROOT = Path(__file__).resolve().parents[2]


def bench(quick: bool = False) -> dict:
    """A 200 x 200 map (position x supply pressure: every point its own equilibrium,
    tangent, ZOH discretisation and eigenvalues) on the paper-000 rig, ``quick``: 60 x 60.

    Ours: :func:`workbench.stability.maps.stability_map` (warm: compiled kernels from the
    cache) on all cores (forked workers; the parent's CPU time is not the work, so the
    ratios are of wall time), and in this process alone (``workers=1``:
    ``single_process``, the same one core as the baselines, with CPU ratios). Baselines, on a random sample of the points (100, quick 30), extrapolated to
    the whole map: ``loop_model_built_once`` (:mod:`.baselines_sweep`: plant built once,
    equilibrium per point, numpy ZOH and eigenvalues) and the old
    ``python_control_loop`` (plant rebuilt per point, python-control c2d/feedback/poles).
    ``batched_numpy_casadi`` (:class:`.baselines_sweep.BatchedMap`: the whole map at
    once, model built once, mapped Newton steps and Jacobians compiled to C, batched
    scipy/numpy on state-scaled matrices; built and compiled outside the timing, as
    ours) runs on every point. ``error``: the largest |rho| difference between the map and the
    model-built-once loop on the sample (-).
    """
    from ..controllers import from_plant
    from ..identify.valve import serial_blas
    from ..plant import Plant
    from ..stability.maps import Axis, stability_map
    from .baselines_sweep import BatchedMap, pointwise_rho
    plant = Plant.from_toml(ROOT / "designs" / "plants" / "situm_rodless_nominal.toml")
    n = 60 if quick else 200
    xa = Axis.linspace("position", 0.05, 0.45, n)
    ya = Axis.linspace("supply.pressure", 3e5, 7e5, n)
    t0 = time.perf_counter()
    stability_map(plant, xa, ya, progress=False)           # compiles (or loads the cache)
    first = time.perf_counter() - t0
    ctrl = from_plant(plant)
    rng = np.random.default_rng(0)
    sample = rng.choice(n * n, 30 if quick else 100, replace=False)
    iy, ix = np.divmod(sample, n)
    px, pp = xa.values[ix], ya.values[iy]
    scale = n * n / len(sample)
    gx, gy = np.meshgrid(xa.values, ya.values)
    t0 = time.perf_counter()
    batched = BatchedMap(plant, ctrl, n * n, compile_c=not quick)
    build_batched = time.perf_counter() - t0
    # OpenBLAS single-threaded for all alike: on a loaded machine its worker threads
    # made the baseline's batched expm 10x slower (21 s against 2 s, load 19)
    with serial_blas():
        res, stats = interleaved(
            {"ours": lambda: stability_map(plant, xa, ya, progress=False),
             "single": lambda: stability_map(plant, xa, ya, progress=False, workers=1),
             "batched": lambda: batched(gx.ravel(), gy.ravel()),
             "loop": lambda: pointwise_rho(plant, px, pp, ctrl)},
            repeats=2 if quick else 3, warmup=False)
    m = res["ours"]
    err = float(np.max(np.abs(res["loop"] - m.rho[iy, ix])))
    err_b = float(np.max(np.abs(res["batched"] - m.rho.ravel())))
    loop_stats = {k: v * scale if isinstance(v, float) else v
                  for k, v in stats["loop"].items() if k != "spread"}
    med = stats["ours"]["median_s"]
    single = stats["single"]
    rows = {"batched_numpy_casadi": baseline(
        stats["batched"], med, err_b, "all points at once, model built once: mapped "
        "Newton steps for the equilibria and one mapped Jacobian call (CasADi, compiled "
        "to C), batched scipy expm (ZOH) of state-scaled matrices, numpy eigenvalues",
        build_s=build_batched,
        ratio_single_process=stats["batched"]["median_s"] / single["median_s"],
        cpu_ratio_single_process=(stats["batched"]["cpu_median_s"]
                                  / single["cpu_median_s"])),
            "loop_model_built_once": baseline(
        loop_stats, med, err, "python loop over the points, plant built once: workbench "
        "operating_point, one CasADi Jacobian function, scipy expm ZOH, numpy eigenvalues; "
        f"timed on {len(sample)} points and extrapolated")}
    wall, cpu, worst = _python_control_loop(plant, ctrl, xa, ya, iy, ix, m.rho)
    rows["python_control_loop"] = baseline(
        summary([wall * scale], [cpu * scale]), med, worst,
        "old baseline: plant rebuilt per point (with_params), python-control ss/c2d/"
        "feedback/poles; one run on the sample, extrapolated")
    parts = _where_time_goes(plant, xa, ya, repeats=2 if quick else 3)
    return {"benchmark": "sweep", **stats["ours"], "error": err,
            "error_note": "largest |rho| difference from the model-built-once loop (-)",
            "points": n * n, "points_per_s": n * n / med, "first_run_s": first,
            "loop_sample": int(len(sample)), "baselines": rows,
            "timing_note": "ours runs in forked worker processes: its cpu_median_s is the "
                           "parent's only; compare CPU times with single_process (the map "
                           "in this process, one core like the baselines)",
            "single_process": {**single, "points_per_s": n * n / single["median_s"],
                               "error": float(np.max(np.abs(res["single"].rho - m.rho))),
                               "note": "the map with workers=1 (this process, one core)"},
            "single_process_parts_cpu_s": parts,
            "parts_note": "the map in one process split into the kernel's steps (CPU "
                          "medians over repeats): 'eigenvalues only' is what the batched "
                          "baseline computes instead of the map's visible-mode test "
                          "(eigenvectors, their inverse, the weights), so the difference "
                          "is the cost of that exactness",
            "target": ">= 20000 points/s", "machine": machine()}


def _python_control_loop(plant, ctrl, xa, ya, iy, ix, rho):
    """The old baseline on the sample: (wall s, CPU s, largest |rho| difference)."""
    import control

    from ..identify.valve import serial_blas
    from ..linearize import operating_point, tangent
    c_tf = ctrl.to_control()
    worst = 0.0
    t0, c0 = time.perf_counter(), time.thread_time()
    with warnings.catch_warnings(), serial_blas():
        warnings.simplefilter("ignore")
        for jy, jx in zip(iy, ix):
            p = plant.with_params(**{"supply.pressure": float(ya.values[jy])})
            lin = tangent(p, operating_point(p, float(xa.values[jx])))
            c, d = lin.output("x")
            sd = control.c2d(control.ss(lin.A, lin.B, c, d), ctrl.sample_time, "zoh")
            poles = control.poles(control.feedback(c_tf * sd, 1))
            poles = poles[np.abs(np.abs(poles) - 1.0) > 1e-6]
            worst = max(worst, abs(float(np.max(np.abs(poles))) - float(rho[jy, jx])))
    wall, cpu = time.perf_counter() - t0, time.thread_time() - c0
    return wall, cpu, worst


def _where_time_goes(plant, xa, ya, repeats: int = 3) -> dict:
    """CPU seconds of each step of the map in this process (medians over ``repeats``),
    on the map's own blocks; ``eigenvalues only`` is timed on the same closed loops."""
    from ..identify.valve import serial_blas
    from ..stability import kernel, maps
    from ..stability.parallel import sweeper_for
    ctrl = maps._controller_spec(plant, None)
    pos = plant.stroke / 2
    spec = (plant.params.to_dict(), plant.friction, pos, ctrl, 0,
            len(xa) * len(ya) >= maps._COMPILE_ABOVE)
    sw = sweeper_for(spec)
    flat, P, positions, gains, T, k0 = maps._point_inputs(sw, xa, ya, ctrl, pos)
    tasks = maps._blocks(positions, P, gains, T, k0, 2500)
    runs: dict[str, list[float]] = {}
    with serial_blas():
        for _ in range(repeats):
            acc: dict[str, float] = {}
            for t in tasks:
                _block_parts(sw, kernel, t, acc)
            c = time.process_time()
            maps._boundaries(sw, xa, ya, flat, P, positions, gains, T, k0, 40)
            acc["boundaries (40 x 40 coarse grid)"] = time.process_time() - c
            for k, v in acc.items():
                runs.setdefault(k, []).append(v)
    return {k: float(np.median(v)) for k, v in runs.items()}


def _block_parts(sw, kernel, t: dict, acc: dict) -> None:
    """One block through the kernel's steps, adding each step's CPU time to ``acc``."""
    def lap(name, c):
        now = time.process_time()
        acc[name] = acc.get(name, 0.0) + now - c
        return now
    c = time.process_time()
    first, inv = kernel._unique_rows(np.column_stack([t["positions"], t["P"].T]))
    c = lap("distinct points", c)
    _, u, _, A, B, _ = sw.points(t["positions"][first], t["P"][:, first])
    c = lap("equilibrium and tangent (compiled)", c)
    A, B = A[inv], B[inv]
    S = sw.state_scale
    As, Bs = A * S[None, None, :] / S[None, :, None], B / S[None, :, None] * sw.u_scale
    sw._velocity_gain(As, Bs)
    c = lap("scaling and Kv", c)
    n, N, Ts = sw.n, len(inv), t["T"]
    M = np.zeros((N, n + 1, n + 1))
    M[:, :n, :n], M[:, :n, n:] = As * Ts[:, None, None], Bs * Ts[:, None, None]
    E = kernel.expm_batched(M)
    c = lap("ZOH (batched expm)", c)
    Acl, Br = kernel._closed_loop(E[:, :n, :n], E[:, :n, n], t["kp"], t["kd"], t["ki"], Ts,
                                  S[0], sw.u_scale, sw.delay)
    c = lap("closed loop", c)
    kernel._visible_radius(Acl.copy(), Br)
    c = lap("eigenvalues and the visible-mode test", c)
    np.abs(np.linalg.eigvals(Acl)).max(axis=1)
    lap("(eigenvalues only, for comparison)", c)
