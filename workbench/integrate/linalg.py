"""Small dense linear algebra on CasADi SX scalars, written out in the expression.

LU factorisation without pivoting (the iteration matrices c I - J of the implicit
steps, c ~ 1/h, are dominated by their diagonal), real and complex (as (re, im)
pairs of SX scalars). Structural zeros are skipped, so a step is one short
straight-line function.
"""

from __future__ import annotations

import casadi as ca

__all__ = ["shifted", "lu_factor", "lu_solve", "complex_lu_factor", "complex_lu_solve"]


def _nz(a) -> bool:
    return not (a.nnz() == 0 or a.is_zero())


def shifted(J: ca.SX, c: float) -> list:
    """c I - J as a list of rows of SX scalars."""
    n = J.shape[0]
    return [[(c if i == j else 0.0) - J[i, j] for j in range(n)] for i in range(n)]


def lu_factor(M: list) -> list:
    """LU (no pivoting) of rows of SX scalars; the diagonal holds 1/U_ii."""
    n = len(M)
    A = [list(row) for row in M]
    for k in range(n):
        inv = 1.0 / A[k][k]
        for i in range(k + 1, n):
            if not _nz(A[i][k]):
                continue
            A[i][k] = A[i][k] * inv
            for j in range(k + 1, n):
                if _nz(A[k][j]):
                    A[i][j] = A[i][j] - A[i][k] * A[k][j]
        A[k][k] = inv
    return A


def lu_solve(A: list, b) -> ca.SX:
    """Solve with the factors of :func:`lu_factor`; ``b`` an SX column."""
    n = len(A)
    y = [b[i] for i in range(n)]
    for i in range(n):
        for j in range(i):
            if _nz(A[i][j]):
                y[i] = y[i] - A[i][j] * y[j]
    for i in reversed(range(n)):
        for j in range(i + 1, n):
            if _nz(A[i][j]):
                y[i] = y[i] - A[i][j] * y[j]
        y[i] = y[i] * A[i][i]
    return ca.vertcat(*y)


def _cmul(a, b):
    return (a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0])


def _cnz(a) -> bool:
    return _nz(a[0]) or _nz(a[1])


def complex_lu_factor(M: list) -> list:
    """LU (no pivoting) of rows of complex scalars given as (re, im) SX pairs."""
    n = len(M)
    A = [list(row) for row in M]
    for k in range(n):
        d = 1.0 / (A[k][k][0] * A[k][k][0] + A[k][k][1] * A[k][k][1])
        inv = (A[k][k][0] * d, -A[k][k][1] * d)
        for i in range(k + 1, n):
            if not _cnz(A[i][k]):
                continue
            A[i][k] = _cmul(A[i][k], inv)
            for j in range(k + 1, n):
                if _cnz(A[k][j]):
                    t = _cmul(A[i][k], A[k][j])
                    A[i][j] = (A[i][j][0] - t[0], A[i][j][1] - t[1])
        A[k][k] = inv
    return A


def complex_lu_solve(A: list, b: list) -> list:
    """Solve with the factors of :func:`complex_lu_factor`; ``b`` a list of (re, im)."""
    n = len(A)
    y = list(b)
    for i in range(n):
        for j in range(i):
            if _cnz(A[i][j]):
                t = _cmul(A[i][j], y[j])
                y[i] = (y[i][0] - t[0], y[i][1] - t[1])
    for i in reversed(range(n)):
        for j in range(i + 1, n):
            if _cnz(A[i][j]):
                t = _cmul(A[i][j], y[j])
                y[i] = (y[i][0] - t[0], y[i][1] - t[1])
        y[i] = _cmul(y[i], A[i][i])
    return y
