"""Confidence of the estimates: the KKT covariance (sandwich) and the stationarity test
that accepts a run IPOPT gave up on at a kink."""

from __future__ import annotations

import numpy as np

from .parameters import _Param
from .problem import _IterationCallback, _Problem


def _stationary(it: _IterationCallback, std: np.ndarray, params: list[_Param], z: np.ndarray,
                fraction: float = 0.25, last: int = 3) -> bool:
    """Whether the last iterates moved the parameters by less than ``fraction`` of their
    standard deviation, with the continuity constraints met."""
    if len(it.history) < last + 1:
        return False
    D = np.array([p.dvalue(float(zi)) for p, zi in zip(params, z)])
    sig_z = std / np.abs(D)
    steps = np.abs(np.diff(np.array(it.history[-(last + 1):]), axis=0))
    return bool(np.all(np.isfinite(sig_z)) and np.all(steps < fraction * sig_z)
                and max(it.gmax[-last:]) < 1e-5)


def _covariance(prob: _Problem, w: np.ndarray, fixed: np.ndarray, params: list[_Param],
                z: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    nsel = prob.nsel
    J, r = prob.residual_jacobian(w)
    G = prob.constraint_jacobian(w)
    free = np.flatnonzero(~fixed)
    J = J[:, free]
    G = G[:, free]
    # per-residual variance: each (recording, signal) from its own residuals
    var = np.zeros(prob.ny * prob.ntot)
    n_free_dims = nsel + prob.nx * len(prob.data)
    dof = max(1e-3, 1.0 - n_free_dims / max(prob.n_res, 1))
    Wt = prob.W.T.ravel()
    for d in prob.data:
        a, b = d.first * prob.M * prob.ny, (d.first + d.n_int) * prob.M * prob.ny
        for i in range(prob.ny):
            rows = np.arange(a + i, b, prob.ny)
            rows = rows[Wt[rows] > 0]
            if len(rows):
                var[rows] = np.mean(r[rows] ** 2) / dof
    H = (J.T @ J).tocsc()
    n, m = H.shape[0], G.shape[0]
    # a relative 1e-10 on the diagonal keeps the solve defined when a parameter is not
    # identifiable (its std then comes out huge); the constraints stay exact
    dh = H.diagonal()
    reg = sp.diags(1e-10 * np.where(dh > 0, dh, 1.0))
    K = sp.bmat([[H + reg, G.T], [G, None]], format="csc")
    rhs = np.zeros((n + m, nsel))
    rhs[np.arange(nsel), np.arange(nsel)] = 1.0     # z are the first free variables
    try:
        X = spla.splu(K).solve(rhs)
        ok = bool(np.all(np.isfinite(X)))
    except RuntimeError:
        X = np.full((n + m, nsel), np.nan)
        ok = False
    if ok:
        B = J @ X[:n]                                   # (rows, nsel)
        cov_z = B.T @ (var[:, None] * B)
    else:
        cov_z = np.full((nsel, nsel), np.inf)
    D = np.array([p.dvalue(float(zi)) for p, zi in zip(params, z)])
    cov = cov_z * np.outer(D, D)
    dg = np.diag(cov).copy()
    std = np.sqrt(np.where(dg >= 0, dg, np.nan))
    std = np.where(np.isfinite(std), std, np.inf)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    corr = np.where(np.isfinite(corr), corr, np.nan)
    np.fill_diagonal(corr, 1.0)
    return std, corr, ok
