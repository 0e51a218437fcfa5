"""``workbench bench rls``: the compiled RLS loop against a compiled scalar loop (numba).

Timing numbers are for this machine at the time of the run; the ratios (measured
interleaved) are what to compare between runs. Nothing here is a test.
"""

from __future__ import annotations

import time

import numpy as np

from ..identify.rls import rls
from ..identify.rls.ckernel import c_kernel
from .timing import baseline, interleaved, machine, summary, unavailable

__all__ = ["bench"]


def _bench_data(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 2nd-order ARX (paper 002's structure) driven by a random binary input held 3
    samples, with equation noise; returns y, u and the true [a1, a2, b1, b2]."""
    from scipy.signal import lfilter
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.choice([-1.0, 1.0], -(-n // 3)), 3)[:n]
    a = np.array([1.0, -1.5, 0.7])
    b = np.array([0.0, 1.0, 0.5])
    e = 0.05 * rng.standard_normal(n)
    y = lfilter(b, a, u) + lfilter([1.0], a, e)
    return y, u, np.array([-1.5, 0.7, 1.0, 0.5])


def bench(quick: bool = False) -> dict:
    """RLS over 10^6 samples (orders 2 2 1, 4 parameters, lambda 0.99; ``quick``: 10^5).

    Ours: :func:`workbench.identify.rls.rls` end to end (checks, the plain C loop of
    :mod:`workbench.identify.rls.ckernel` forming the regressors itself, result).
    Baseline ``numba_loop``: the same recursion as a numba-compiled scalar loop
    (symmetric covariance update) on regressors built beforehand, untimed (its compile
    time apart). The old baseline, a
    numpy per-sample loop, runs on the first 20 000 samples (5 000 quick), extrapolated,
    and is the accuracy reference: ``error`` is the largest difference of the estimates
    from it on those samples (theta, dimensionless coefficients).
    """
    from ..identify.rls.estimator import regressors
    from . import baselines_rls as bl
    n = 10**5 if quick else 10**6
    n_loop = 5_000 if quick else 20_000
    orders = (2, 2, 1)
    y, u, truth = _bench_data(n)
    t0 = time.perf_counter()
    c_kernel(4)
    build = time.perf_counter() - t0
    ref = rls(y[:n_loop], u[:n_loop], orders, forgetting=0.99, sample_time=0.01, method="numpy")
    kw = dict(forgetting=0.99, sample_time=0.01)
    fns = {"ours": lambda: rls(y, u, orders, **kw)}
    phi, target, _ = regressors(y, u, orders)
    first = rls(y[:50], u[:50], orders, **kw)
    p0, pm = np.asarray(first.p0), first.p_max
    compile_s = None
    why = bl.unavailable_reason()
    if why is None:
        t0 = time.perf_counter()
        bl.numba_rls(phi[:10], target[:10], np.zeros(4), p0, 0.99, pm)
        compile_s = time.perf_counter() - t0
        fns["numba_loop"] = lambda: bl.numba_rls(phi, target, np.zeros(4), p0, 0.99, pm)
    res, stats = interleaved(fns, repeats=3 if quick else 7)
    m = len(ref)
    ours = res["ours"]
    err = float(np.max(np.abs(ours.theta[:m] - ref.theta)))
    med, cpu_med = stats["ours"]["median_s"], stats["ours"]["cpu_median_s"]
    desc = ("the same recursion (Joseph form on the upper triangle, bounded forgetting, "
            "stds) as a numba-compiled scalar loop over regressors built beforehand "
            "(untimed)")
    rows = {}
    if "numba_loop" in res:
        nb = res["numba_loop"]
        rows["numba_loop"] = baseline(stats["numba_loop"], med,
                                      float(np.max(np.abs(nb[:m, :4] - ref.theta))), desc,
                                      ours_cpu_s=cpu_med, compile_s=compile_s,
                                      std_rel_difference=_std_rel(nb[:m, 4:], ref.std))
    else:
        rows["numba_loop"] = unavailable(desc, why)
    t0, c0 = time.perf_counter(), time.thread_time()
    rls(y[:n_loop], u[:n_loop], orders, method="numpy", **kw)
    wall, cpu = (time.perf_counter() - t0) * n / n_loop, (time.thread_time() - c0) * n / n_loop
    rows["numpy_loop"] = baseline(summary([wall], [cpu]), med, 0.0,
                                  f"old baseline: numpy per-sample loop, timed on {n_loop} "
                                  "samples and extrapolated (the accuracy reference)",
                                  ours_cpu_s=cpu_med)
    return {"benchmark": "rls", **stats["ours"], "error": err,
            "error_note": "largest |theta - numpy loop| on the reference samples",
            "std_rel_difference": _std_rel(ours.std[:m], ref.std),
            "samples": n, "samples_per_s": n / med, "parameters": 4, "orders": list(orders),
            "forgetting": 0.99, "method": ours.method, "build_or_load_s": build,
            "final_estimate": [float(v) for v in ours.theta[-1]], "truth": truth.tolist(),
            "baselines": rows, "machine": machine()}


def _std_rel(a: np.ndarray, b: np.ndarray) -> float:
    both = np.isfinite(a) & np.isfinite(b) & (b > 0)
    return float(np.max(np.abs(a[both] - b[both]) / b[both])) if both.any() else float("nan")
