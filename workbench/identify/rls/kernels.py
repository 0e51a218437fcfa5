"""The RLS recursion on a packed state [theta, triu(P), triu(M), V, N_eff]: numpy, CasADi."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    import casadi

__all__ = ["chunk_function"]

_CHUNK = 1000                     # samples per compiled call (mapaccum length)


def _ntri(n: int) -> int:
    return n * (n + 1) // 2


def _triu_index(n: int) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = [], []
    for j in range(n):
        for i in range(j + 1):
            rows.append(i)
            cols.append(j)
    return np.array(rows), np.array(cols)


def _pack(theta: np.ndarray, P: np.ndarray, M: np.ndarray, V: float, ne: float) -> np.ndarray:
    r, c = _triu_index(theta.size)
    return np.concatenate([theta, P[r, c], M[r, c], [V, ne]])


def _unpack(x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    t = _ntri(n)
    r, c = _triu_index(n)
    P = np.zeros((n, n))
    P[r, c] = x[n:n + t]
    P[c, r] = x[n:n + t]
    M = np.zeros((n, n))
    M[r, c] = x[n + t:n + 2 * t]
    M[c, r] = x[n + t:n + 2 * t]
    return x[:n].copy(), P, M, float(x[n + 2 * t]), float(x[n + 2 * t + 1])


def _final_covariance(x: np.ndarray, n: int) -> np.ndarray:
    _, P, M, V, ne = _unpack(x, n)
    dof = ne - float(np.trace(P @ M))
    if not dof > 0.5:
        return np.full((n, n), np.nan)
    C = (V / dof) * (P @ M @ P)
    return 0.5 * (C + C.T)


def _run_numpy(phi: np.ndarray, target: np.ndarray, x0: np.ndarray, lam: float,
               p_max: float) -> tuple[np.ndarray, np.ndarray]:
    """The recursion as a plain numpy per-sample loop (baseline and reference).

    Returns the outputs (N, 2n + 3): theta, std, eps, lambda_k, sigma^2; and the final
    packed state.
    """
    n = phi.shape[1]
    theta, P, M, V, ne = _unpack(x0, n)
    eye = np.eye(n)
    out = np.empty((target.size, 2 * n + 3))
    for k in range(target.size):
        f = phi[k]
        lk = min(1.0, max(lam, np.trace(P) / p_max))
        Pt = P / lk
        a = Pt @ f
        den = 1.0 + f @ a
        K = a / den
        eps = target[k] - f @ theta
        theta = theta + K * eps
        A = eye - np.outer(K, f)
        P = A @ Pt @ A.T + np.outer(K, K)
        P = 0.5 * (P + P.T)
        M = (lk * lk) * M + np.outer(f, f)
        V = lk * V + eps * eps / den
        ne = lk * ne + 1.0
        B = P @ M
        dof = ne - np.trace(B)
        s2 = V / dof if dof > 0.5 else np.nan
        var = s2 * np.einsum("ij,ji->i", B, P)
        out[k, :n] = theta
        out[k, n:2 * n] = np.sqrt(var)
        out[k, 2 * n] = eps
        out[k, 2 * n + 1] = lk
        out[k, 2 * n + 2] = s2
    return out, _pack(theta, P, M, V, ne)


def _step_function(n: int) -> "casadi.Function":
    """One RLS step as a CasADi SX function (x, d, lambda, p_max) -> (x_next, out).

    ``d = [phi; y; active]``; with ``active = 0`` (padding) the state is unchanged.
    Same arithmetic as :func:`_run_numpy`, on the packed symmetric state.
    """
    import casadi as ca
    t = _ntri(n)
    x = ca.SX.sym("x", n + 2 * t + 2)
    d = ca.SX.sym("d", n + 2)
    lam = ca.SX.sym("lam")
    p_max = ca.SX.sym("p_max")
    r, c = _triu_index(n)

    def sym(v):
        S = ca.SX(n, n)
        for idx, (i, j) in enumerate(zip(r, c)):
            S[int(i), int(j)] = v[idx]
            S[int(j), int(i)] = v[idx]
        return S

    def triu(S):
        return ca.vertcat(*[S[int(i), int(j)] for i, j in zip(r, c)])

    theta = x[:n]
    P = sym(x[n:n + t])
    M = sym(x[n + t:n + 2 * t])
    V = x[n + 2 * t]
    ne = x[n + 2 * t + 1]
    f = d[:n]
    target = d[n]
    active = d[n + 1]

    lk = ca.fmin(1.0, ca.fmax(lam, ca.trace(P) / p_max))
    Pt = P / lk
    a = ca.mtimes(Pt, f)
    den = 1.0 + ca.dot(f, a)
    K = a / den
    eps = target - ca.dot(f, theta)
    theta_n = theta + K * eps
    A = ca.SX.eye(n) - ca.mtimes(K, f.T)
    Pn = ca.mtimes([A, Pt, A.T]) + ca.mtimes(K, K.T)
    Pn = 0.5 * (Pn + Pn.T)
    Mn = (lk * lk) * M + ca.mtimes(f, f.T)
    Vn = lk * V + eps * eps / den
    ne_n = lk * ne + 1.0
    B = ca.mtimes(Pn, Mn)
    dof = ne_n - ca.trace(B)
    s2 = ca.if_else(dof > 0.5, Vn / dof, np.nan)
    var = ca.vertcat(*[s2 * ca.dot(B[i, :].T, Pn[:, i]) for i in range(n)])
    x_n = ca.vertcat(theta_n, triu(Pn), triu(Mn), Vn, ne_n)
    x_n = ca.if_else(active > 0.5, x_n, x)
    out = ca.vertcat(theta_n, ca.sqrt(var), eps, lk, s2)
    return ca.Function(f"rls_step{n}", [x, d, lam, p_max], [x_n, out])


_CHUNK_FUNCTIONS: dict[int, tuple["casadi.Function", str]] = {}


def chunk_function(n: int) -> tuple["casadi.Function", str]:
    """``_CHUNK`` steps as one function, compiled to C when possible (cached)."""
    if n in _CHUNK_FUNCTIONS:
        return _CHUNK_FUNCTIONS[n]
    import casadi as ca
    from ...integrate import jit as _jit
    step = _step_function(n)
    acc = step.mapaccum("acc", _CHUNK, [0], [0])
    x0 = ca.MX.sym("x0", step.size1_in(0))
    D = ca.MX.sym("D", n + 2, _CHUNK)
    lam = ca.MX.sym("lam")
    p_max = ca.MX.sym("p_max")
    X, O = acc(x0, D, ca.repmat(lam, 1, _CHUNK), ca.repmat(p_max, 1, _CHUNK))
    chunk = ca.Function(f"rls_chunk{n}_{_CHUNK}", [x0, D, lam, p_max], [X[:, -1], O])
    fun = _jit.compiled(chunk, ("-O2",))
    kind = "compiled" if fun.class_name() == "External" else "casadi"
    _CHUNK_FUNCTIONS[n] = (fun, kind)
    return fun, kind


def _run_casadi(phi: np.ndarray, target: np.ndarray, x0: np.ndarray, lam: float,
                p_max: float, progress: bool = False) -> tuple[np.ndarray, np.ndarray, str]:
    n = phi.shape[1]
    nout = 2 * n + 3
    fun, kind = chunk_function(n)
    N = target.size
    nchunks = -(-N // _CHUNK)
    # row k of D is column k of the (n+2) x N Fortran-ordered matrix CasADi reads
    D = np.zeros((nchunks * _CHUNK, n + 2))
    D[:N, :n] = phi
    D[:N, n] = target
    D[:N, n + 1] = 1.0
    out = np.empty((nchunks * _CHUNK, nout))
    xa = np.array(x0, dtype=float)
    xb = np.empty_like(xa)
    lam_a = np.array([lam], dtype=float)
    pmax_a = np.array([p_max], dtype=float)
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=N, desc="rls", unit="sample", leave=False)
    try:
        try:
            buf, trigger = fun.buffer()
        except AttributeError:          # CasADi without FunctionBuffer: plain calls
            buf = trigger = None
        if buf is not None:
            buf.set_arg(2, memoryview(lam_a))
            buf.set_arg(3, memoryview(pmax_a))
        for j in range(nchunks):
            sl = slice(j * _CHUNK, (j + 1) * _CHUNK)
            if buf is not None:
                dv = D[sl].reshape(-1)
                ov = out[sl].reshape(-1)
                buf.set_arg(0, memoryview(xa))
                buf.set_arg(1, memoryview(dv))
                buf.set_res(0, memoryview(xb))
                buf.set_res(1, memoryview(ov))
                trigger()
            else:
                xe, oc = fun(xa, D[sl].T, lam, p_max)
                xb[:] = np.asarray(xe).ravel()
                out[sl] = np.asarray(oc).T
            xa, xb = xb, xa
            if bar is not None:
                bar.update(min(_CHUNK, N - j * _CHUNK))
    finally:
        if bar is not None:
            bar.close()
    return out[:N], xa, kind
