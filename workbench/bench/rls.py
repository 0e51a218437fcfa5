"""``workbench bench rls``: the compiled RLS loop against a plain numpy per-sample loop."""

from __future__ import annotations

import time as _time

import numpy as np

from ..identify.rls import rls
from ..identify.rls.kernels import chunk_function

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
    """``workbench bench rls``: RLS over 10^6 samples (orders 2 2 1, 4 parameters,
    lambda 0.99) against a plain numpy per-sample loop of the same arithmetic, in the
    same run. The numpy loop is timed on the first ``numpy_loop_samples`` samples and
    extrapolated (its cost per sample is constant); both estimate tracks are compared
    on those samples. ``quick``: 10^5 samples."""
    n = 10**5 if quick else 10**6
    n_loop = 5_000 if quick else 20_000
    orders = (2, 2, 1)
    y, u, truth = _bench_data(n)
    t0 = _time.perf_counter()
    chunk_function(4)
    build = _time.perf_counter() - t0
    t0, c0 = _time.perf_counter(), _time.process_time()
    res = rls(y, u, orders, forgetting=0.99, sample_time=0.01)
    wall, cpu = _time.perf_counter() - t0, _time.process_time() - c0
    t0, c0 = _time.perf_counter(), _time.process_time()
    ref = rls(y[:n_loop], u[:n_loop], orders, forgetting=0.99, sample_time=0.01, method="numpy")
    wall_loop, cpu_loop = _time.perf_counter() - t0, _time.process_time() - c0
    m = len(ref)
    diff = float(np.max(np.abs(res.theta[:m] - ref.theta)))
    both = np.isfinite(ref.std) & np.isfinite(res.std[:m])
    std_rel = float(np.max(np.abs(res.std[:m][both] - ref.std[both]) / ref.std[both]))
    rate = n / wall
    rate_loop = n_loop / wall_loop
    return {
        "samples": n,
        "parameters": 4,
        "orders": list(orders),
        "forgetting": 0.99,
        "samples_per_s": rate,
        "numpy_loop_samples_per_s": rate_loop,
        "speedup_vs_numpy_loop": rate / rate_loop,
        "max_abs_difference": diff,
        "max_rel_difference_std": std_rel,
        "numpy_loop_samples": n_loop,
        "wall_s": {"rls": wall, "numpy_loop": wall_loop,
                   "numpy_loop_extrapolated": n / rate_loop, "build_or_load": build},
        "cpu_samples_per_s": n / cpu,
        "numpy_loop_cpu_samples_per_s": n_loop / cpu_loop,
        "speedup_vs_numpy_loop_cpu": (n / cpu) / (n_loop / cpu_loop),
        "load_average_1min": _load_average(),
        "method": res.method,
        "final_estimate": [float(v) for v in res.theta[-1]],
        "final_std": [float(v) for v in res.std[-1]],
        "truth": truth.tolist(),
        "note": "wall time of rls() end to end (checks, regressors, loop, result); "
                "the numpy loop is extrapolated from its subset; the cpu_* rates use "
                "process CPU time, which a busy shared machine distorts less",
    }


def _load_average() -> float | None:
    import os
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return None
