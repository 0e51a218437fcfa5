"""Baseline of ``workbench bench rls``: the same RLS recursion as a compiled scalar loop
(numba), as a competent user would write it: explicit loops over the n parameters, no
temporaries, compiled once (``cache=False``: the compile time is reported apart).

Same arithmetic as :func:`workbench.identify.rls.kernels._run_numpy` (Joseph-form
covariance, trace-bounded forgetting, the information matrix M, V and the effective
sample count for the standard deviations), so both give the same estimates and stds.
"""

from __future__ import annotations

import numpy as np

__all__ = ["numba_rls", "unavailable_reason"]


def unavailable_reason() -> str | None:
    """None when numba (the ``bench`` extra) imports, else why not."""
    try:
        import numba  # noqa: F401
    except ImportError as exc:
        return f"numba is not installed (pip install workbench[bench]): {exc}"
    return None


def _rls_loop(phi, target, theta, P, lam, p_max, out):
    n = theta.size
    M = np.zeros((n, n))
    a, K, f = np.empty(n), np.empty(n), np.empty(n)
    Pn, B = np.empty((n, n)), np.empty((n, n))
    V, ne = 0.0, 0.0
    for k in range(target.size):
        tr = 0.0
        for i in range(n):
            f[i] = phi[k, i]
            tr += P[i, i]
        lk = min(1.0, max(lam, tr / p_max))
        den, eps = 1.0, target[k]
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += P[i, j] * f[j]
            a[i] = s / lk
            den += f[i] * a[i]
            eps -= f[i] * theta[i]
        for i in range(n):
            K[i] = a[i] / den
            theta[i] += K[i] * eps
        # Joseph form with P~ = P / lk: (I - K f') P~ (I - K f')' + K K'
        # = P~ - K a' - a K' + (f' a) K K' + K K'
        fa = den - 1.0
        for i in range(n):
            for j in range(n):
                Pn[i, j] = P[i, j] / lk - K[i] * a[j] - a[i] * K[j] + (fa + 1.0) * K[i] * K[j]
        for i in range(n):
            for j in range(n):
                P[i, j] = 0.5 * (Pn[i, j] + Pn[j, i])
                M[i, j] = lk * lk * M[i, j] + f[i] * f[j]
        V = lk * V + eps * eps / den
        ne = lk * ne + 1.0
        trB = 0.0
        for i in range(n):
            for j in range(n):
                s = 0.0
                for q in range(n):
                    s += P[i, q] * M[q, j]
                B[i, j] = s
            trB += B[i, i]
        dof = ne - trB
        s2 = V / dof if dof > 0.5 else np.nan
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += B[i, j] * P[j, i]
            out[k, i] = theta[i]
            out[k, n + i] = np.sqrt(s2 * s)
    return out


def numba_rls(phi: np.ndarray, target: np.ndarray, theta0: np.ndarray, p0: np.ndarray,
              lam: float, p_max: float) -> np.ndarray:
    """Estimates and stds (N, 2 n) of the recursion, compiled by numba on first use."""
    fn = _compiled()
    out = np.empty((target.size, 2 * theta0.size))
    return fn(np.ascontiguousarray(phi, dtype=float), np.ascontiguousarray(target, dtype=float),
              np.array(theta0, dtype=float), np.diag(np.asarray(p0, dtype=float)),
              float(lam), float(p_max), out)


_JIT = []


def _compiled():
    if not _JIT:
        import numba
        _JIT.append(numba.njit(cache=False, fastmath=False)(_rls_loop))
    return _JIT[0]
