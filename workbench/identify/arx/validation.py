"""ARX validation on (held-out) data: simulation fit and residual tests (:func:`validate`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import InputError
from ...signals import (CONFIDENCE_Z99, WHITENESS_LEVEL, autocorrelation, cross_correlation,
                        independence_test, ljung_box)
from .checks import _data, _fit_percent, _order
from .checks import finite_or_none as _num
from .model import ArxModel, _ro

__all__ = ["ArxValidation", "validate"]


def _verdict(p: float) -> bool | None:
    """Passed at the 1 % level (:data:`workbench.signals.WHITENESS_LEVEL`); None if undefined."""
    return None if math.isnan(p) else p >= WHITENESS_LEVEL


@dataclass(frozen=True, eq=False)
class ArxValidation:
    """Result of :func:`validate`: simulation fit and residual tests.

    Attributes
    ----------
    fit : float
        Simulation fit ``100 (1 - ||y - y_sim|| / ||y - mean y||)``, %, over the
        samples after the initial ``max_lag`` (which are the measured initial state).
    y, u : numpy.ndarray, shape (n,)
        The data validated on, units of the model.
    y_simulated : numpy.ndarray, shape (n,)
        Pure simulation from the measured first ``max_lag`` outputs, unit of y.
    residuals : numpy.ndarray, shape (n - max_lag,)
        One-step prediction errors ``y(k) - y_hat(k | k-1)``, unit of y.
    lags : numpy.ndarray, shape (M + 1,)
        Lags 0..M of the autocorrelation, samples.
    autocorrelation : numpy.ndarray, shape (M + 1,)
        Normalised autocorrelation of the (mean-free) residuals, -, 1 at lag 0.
    cross_lags : numpy.ndarray, shape (2 M + 1,)
        Lags -M..M of the cross-correlation, samples; lag tau pairs ``e(k)`` with
        ``u(k - tau)`` (positive: past inputs; negative: future inputs, i.e. feedback).
    cross_correlation : numpy.ndarray, shape (2 M + 1,)
        Normalised cross-correlation of residuals and (mean-free) input, -. NaN if the
        input is constant on these data.
    band : float
        99 % confidence band of a normalised correlation, ``2.58 / sqrt(N)``, -.
    whiteness_statistic, whiteness_p_value : float
        Ljung-Box ``Q = N (N+2) sum_{tau=1..M} r(tau)^2 / (N - tau)`` and its p-value
        against chi-square with M degrees of freedom.
    whiteness_ok : bool or None
        ``p >= 0.01``: no evidence at the 1 % level that the residuals are coloured.
        None when the residuals are exactly zero.
    independence_statistic, independence_p_value : float
        ``N c' (lambda R_u)^-1 c`` over lags 0..M (Ljung, System Identification, 16.6):
        c the residual-input cross-covariances, lambda the residual variance, R_u the
        input covariance matrix; chi-square with M + 1 degrees of freedom for any
        input spectrum.
    independence_ok : bool or None
        ``p >= 0.01``; None when the input is constant on these data.
    autocorrelation_outside, cross_correlation_outside : int
        Lags (autocorrelation: 1..M; cross: -M..M) outside the band, for the plot.
    sample_time : float or None
        s.
    n_samples : int
        N, residuals used.
    max_lag : int
        The model's max lag, samples: the first ``max_lag`` samples are the measured
        initial state, not predicted or simulated.
    """

    fit: float
    y: np.ndarray
    u: np.ndarray
    y_simulated: np.ndarray
    residuals: np.ndarray
    lags: np.ndarray
    autocorrelation: np.ndarray
    cross_lags: np.ndarray
    cross_correlation: np.ndarray
    band: float
    whiteness_statistic: float
    whiteness_p_value: float
    whiteness_ok: bool | None
    independence_statistic: float
    independence_p_value: float
    independence_ok: bool | None
    autocorrelation_outside: int
    cross_correlation_outside: int
    sample_time: float | None
    n_samples: int
    max_lag: int

    def __post_init__(self) -> None:
        for name in ("y", "u", "y_simulated", "residuals", "lags", "autocorrelation",
                     "cross_lags", "cross_correlation"):
            object.__setattr__(self, name, _ro(getattr(self, name)))

    @property
    def time(self) -> np.ndarray:
        """Sample instants from 0, s (sample numbers if the sample time is unknown)."""
        return np.arange(self.y.size) * (self.sample_time or 1.0)

    @property
    def ok(self) -> bool:
        """Residuals white and independent of the input (None counts as not shown)."""
        return bool(self.whiteness_ok) and bool(self.independence_ok)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no signals)."""
        return {
            "fit": _num(self.fit), "n_samples": self.n_samples, "band": self.band,
            "whiteness_ok": self.whiteness_ok,
            "whiteness_statistic": _num(self.whiteness_statistic),
            "whiteness_p_value": _num(self.whiteness_p_value),
            "independence_ok": self.independence_ok,
            "independence_statistic": _num(self.independence_statistic),
            "independence_p_value": _num(self.independence_p_value),
            "autocorrelation_outside": self.autocorrelation_outside,
            "cross_correlation_outside": self.cross_correlation_outside,
            "correlation_lags": int(self.lags[-1]) if self.lags.size else 0,
            "residual_std": _num(float(np.std(self.residuals))),
        }


#: Default largest correlation lag, samples (MATLAB's ``resid``).
DEFAULT_LAGS = 25


def validate(model: ArxModel, y: Any, u: Any, lags: int | None = None) -> ArxValidation:
    """Simulate ``model`` on data and analyse its one-step residuals.

    Use held-out data (not the estimation data) for the fit: a model that only fits
    its own data has learnt the noise.

    Parameters
    ----------
    model : ArxModel
        The model.
    y, u : array_like, shape (n,)
        Output and input, units of the model.
    lags : int, optional
        Largest correlation lag M, samples. By default 25 (as MATLAB's ``resid``),
        reduced to a quarter of the residuals if the data are short; a value given
        must be at most a quarter of the residuals (a correlation at lag M averages
        only N - M products, and the portmanteau tests assume M << N).

    Returns
    -------
    ArxValidation
        Fit %, simulated output, residuals, correlations with the 99 % band and the
        whiteness and independence verdicts.

    Raises
    ------
    InputError
        For NaN/inf, mismatched lengths, fewer than ``model.max_lag + 8`` samples
        (too few residuals for a correlation test), or ``lags`` beyond a quarter of
        the residuals.

    Notes
    -----
    Verdicts are portmanteau tests at the 1 % level rather than counts of lags outside
    the band: with M = 25 lags, one of them falls outside a 99 % band in about one
    experiment in five even for white residuals. The whiteness test uses M degrees
    of freedom without subtracting the fitted parameters, which makes it slightly
    lenient for a model fitted on the same data. Both correlations use the mean-free
    residuals and input on the samples that have a residual.
    """
    if not isinstance(model, ArxModel):
        raise InputError(f"validate needs an ArxModel, got {type(model).__name__}")
    yy, uu = _data(y, u, "validate")
    lag_max = DEFAULT_LAGS if lags is None else _order("lags", lags, 1)
    n0 = model.max_lag
    if yy.size < n0 + 8:
        raise InputError(f"validate: {yy.size} samples are too few for a model with max "
                         f"lag {n0}; need at least {n0 + 8} (8 residuals)")
    if lags is not None and lag_max > (yy.size - n0) // 4:
        raise InputError(f"lags = {lag_max} is more than a quarter of the "
                         f"{yy.size - n0} residuals of these data; give at most "
                         f"{max(1, (yy.size - n0) // 4)} (or leave the default)")
    y_sim = model.simulate(uu, y0=yy[:n0])
    fit = _fit_percent(yy[n0:], y_sim[n0:])
    e = yy[n0:] - model.predict(yy, uu)[n0:]
    n = e.size
    m = max(1, min(lag_max, n // 4))
    band = CONFIDENCE_Z99 / math.sqrt(n)
    lags = np.arange(m + 1)
    r_e = autocorrelation(e, m)
    q, p_white = ljung_box(e, m)
    cross_lags, r_eu = cross_correlation(e, uu[n0:], m)
    s_ind, p_ind, _ = independence_test(e, uu[n0:], m)
    white_ok = _verdict(p_white)
    ind_ok = _verdict(p_ind)
    with np.errstate(invalid="ignore"):
        auto_out = int(np.sum(np.abs(r_e[1:]) > band))
        cross_out = int(np.sum(np.abs(r_eu) > band))
    return ArxValidation(
        fit=fit, y=yy, u=uu, y_simulated=y_sim, residuals=e, lags=lags,
        autocorrelation=r_e, cross_lags=cross_lags, cross_correlation=r_eu, band=band,
        whiteness_statistic=q, whiteness_p_value=p_white, whiteness_ok=white_ok,
        independence_statistic=s_ind, independence_p_value=p_ind,
        independence_ok=ind_ok, autocorrelation_outside=auto_out,
        cross_correlation_outside=cross_out, sample_time=model.sample_time,
        n_samples=n, max_lag=n0)
