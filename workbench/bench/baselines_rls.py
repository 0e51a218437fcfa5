"""Baseline of ``workbench bench rls``: the same RLS recursion as a compiled scalar loop
(numba), as a competent user would write it: explicit loops over the n parameters, no
temporaries, compiled once (``cache=False``: the compile time is reported apart).

Same arithmetic as :func:`workbench.identify.rls.kernels._run_numpy` (Joseph-form
covariance, trace-bounded forgetting, the information matrix M, V and the effective
sample count for the standard deviations), so both give the same estimates and stds.
It uses the symmetry a careful user would: the covariance update is computed on the
upper triangle and mirrored, and ``trace(P M)`` and ``diag(P M P)`` are summed without
forming ``P M``; while the trace bound does not act, ``lambda_k = lambda`` without the
two divisions (as in the C loop: 3 % off this loop, 76 -> 74 ms CPU). The session-7
version updated the full matrices, symmetrised ``(P + P') / 2`` and formed ``B = P M``:
1.25x slower (90 vs 72 ms CPU per 10^6 samples, 4 parameters, interleaved, loaded
2-core machine).
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
    a, K = np.empty(n), np.empty(n)
    V, ne = 0.0, 0.0
    lam_pmax = lam * p_max
    il_lam = 1.0 / lam
    for k in range(target.size):
        tr = 0.0
        for i in range(n):
            tr += P[i, i]
        if tr > lam_pmax:          # the bound acts (rare): the divisions only then
            lk = min(1.0, max(lam, tr / p_max))
            il = 1.0 / lk
        else:
            lk = lam
            il = il_lam
        den, eps = 1.0, target[k]
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += P[i, j] * phi[k, j]
            a[i] = s * il
        for i in range(n):
            den += phi[k, i] * a[i]
            eps -= phi[k, i] * theta[i]
        for i in range(n):
            K[i] = a[i] / den
            theta[i] += K[i] * eps
        # Joseph form with P~ = P / lk: (I - K f') P~ (I - K f')' + K K'
        # = P~ - K a' - a K' + den K K', upper triangle mirrored (symmetric exactly)
        for j in range(n):
            for i in range(j + 1):
                v = P[i, j] * il - (K[i] * a[j] + a[i] * K[j]) + den * (K[i] * K[j])
                P[i, j] = v
                P[j, i] = v
                v = lk * lk * M[i, j] + phi[k, i] * phi[k, j]
                M[i, j] = v
                M[j, i] = v
        V = lk * V + eps * eps / den
        ne = lk * ne + 1.0
        trB = 0.0
        for i in range(n):
            for j in range(n):
                trB += P[i, j] * M[j, i]
        dof = ne - trB
        s2 = V / dof if dof > 0.5 else np.nan
        for i in range(n):                       # diag(P M P)_i = p_i' M p_i
            s = 0.0
            for j in range(n):
                mp = 0.0
                for q in range(n):
                    mp += M[j, q] * P[q, i]
                s += P[i, j] * mp
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
