"""Residual tests of an identified model: whiteness (Ljung-Box) and input independence.

Both work on the mean-free one-step residuals ``e`` and input ``u`` of the samples that
have a residual, at lags up to ``M``, and give a statistic, its chi-square p-value and a
verdict at the 1 % level (:data:`TEST_LEVEL`). Used by :func:`workbench.identify.arx.validate`.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["CONFIDENCE_Z99", "TEST_LEVEL", "covariances", "ljung_box", "input_independence"]

#: Two-sided 99 % quantile of the standard normal distribution: the confidence band
#: of a normalised correlation estimated from N samples is +-2.58/sqrt(N).
CONFIDENCE_Z99 = 2.5758293035489004
#: Significance level of the whiteness and independence tests.
TEST_LEVEL = 0.01


def covariances(e: np.ndarray, u: np.ndarray, m: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Auto- and cross-covariances of mean-free residuals and input, 1/N normalised.

    Parameters
    ----------
    e : residuals, shape (N,), unit of y.
    u : input on the same samples, shape (N,), unit of u.
    m : largest lag M, samples.

    Returns
    -------
    c_e : residual autocovariance at lags 0..M, unit of y squared.
    c_u : input autocovariance at lags 0..M, unit of u squared.
    cross_lags : lags -M..M, samples.
    c_eu : cross-covariance ``1/N sum e(k) u(k - tau)`` at ``cross_lags``.
    """
    n = e.size
    ec = e - e.mean()
    uc = u - u.mean()
    c_e = np.array([ec[k:] @ ec[: n - k] for k in range(m + 1)]) / n
    c_u = np.array([uc[k:] @ uc[: n - k] for k in range(m + 1)]) / n
    cross_lags = np.arange(-m, m + 1)
    c_eu = np.array([(ec[t:] @ uc[: n - t]) if t >= 0 else (ec[: n + t] @ uc[-t:])
                     for t in cross_lags]) / n
    return c_e, c_u, cross_lags, c_eu


def ljung_box(c_e: np.ndarray, n: int) -> tuple[np.ndarray, float, float, bool | None]:
    """Whiteness: Ljung-Box ``Q = N (N+2) sum_{tau=1..M} r(tau)^2 / (N - tau)``.

    Parameters
    ----------
    c_e : residual autocovariance at lags 0..M (:func:`covariances`).
    n : number of residuals N.

    Returns
    -------
    r_e : normalised autocorrelation, 1 at lag 0 (NaN for zero residuals).
    q, p : the statistic and its p-value against chi-square with M degrees of freedom.
    ok : ``p >= TEST_LEVEL``; None when the residuals are exactly zero.
    """
    from scipy import stats
    m = c_e.size - 1
    if not c_e[0] > 0:
        return np.full(m + 1, np.nan), math.nan, math.nan, None
    lags = np.arange(m + 1)
    r_e = c_e / c_e[0]
    q = n * (n + 2) * float(np.sum(r_e[1:] ** 2 / (n - lags[1:])))
    p_white = float(stats.chi2.sf(q, m))
    return r_e, q, p_white, p_white >= TEST_LEVEL


def input_independence(c_e: np.ndarray, c_u: np.ndarray, c_eu: np.ndarray, n: int
                       ) -> tuple[np.ndarray, float, float, bool | None]:
    """Input-residual independence: ``N c' (lambda R_u)^-1 c`` over lags 0..M.

    Ljung, System Identification, 16.6: c the residual-input cross-covariances,
    lambda the residual variance, R_u the input covariance matrix; chi-square with
    M + 1 degrees of freedom (the rank of R_u) for any input spectrum.

    Parameters
    ----------
    c_e, c_u, c_eu : from :func:`covariances` (lags 0..M, 0..M, -M..M).
    n : number of residuals N.

    Returns
    -------
    r_eu : normalised cross-correlation at lags -M..M (NaN for a constant input).
    s, p : the statistic and its p-value.
    ok : ``p >= TEST_LEVEL``; None when the input is constant or the residuals zero.
    """
    from scipy import stats
    m = c_e.size - 1
    if not (c_e[0] > 0 and c_u[0] > 0):
        return np.full(2 * m + 1, np.nan), math.nan, math.nan, None
    r_eu = c_eu / math.sqrt(c_e[0] * c_u[0])
    ru = c_u / c_u[0]
    idx = np.abs(np.subtract.outer(np.arange(m + 1), np.arange(m + 1)))
    R = ru[idx]
    c_pos = r_eu[m:]                       # lags 0..M, normalised
    sol, *_ = np.linalg.lstsq(R, c_pos, rcond=1e-10)
    dof = int(np.linalg.matrix_rank(R, tol=1e-10 * np.linalg.norm(R, 2)))
    s_ind = n * float(c_pos @ sol)
    p_ind = float(stats.chi2.sf(s_ind, dof))
    return r_eu, s_ind, p_ind, p_ind >= TEST_LEVEL
