"""ARX models by least squares: estimation, order selection and validation.

The model structure follows MATLAB's ``arx`` with orders ``[na nb nk]``::

    y(k) + a1 y(k-1) + ... + a_na y(k-na) = b1 u(k-nk) + ... + b_nb u(k-nk-nb+1) + e(k)

``a`` excludes the leading 1; ``nk`` is the delay in samples from the input to the first
``b`` term. Paper 000's closed-loop model ``[na nb d] = [4 1 1]`` (dead time d = 1 on top of
the one-sample delay of any sampled system) is ``orders=(4, 1, 2)`` here.

* :func:`fit_arx` estimates ``a``, ``b`` with their standard deviations (numerically
  sound least squares: SVD of the column-scaled regressor matrix, never the normal
  equations) and returns a frozen :class:`ArxModel`.
* :func:`select_order` compares candidate orders by loss, AIC, BIC, FPE (all on the same
  estimation samples) or on validation data, and returns a :class:`OrderSelection`.
* :func:`validate` simulates the model on (held-out) data - fit in percent - and tests
  the one-step residuals: autocorrelation (whiteness) and input-residual
  cross-correlation (independence) against 99 % confidence bands, returning a
  :class:`ArxValidation`.

Closed-loop data: identifying the closed loop from the reference ``r`` to the position
``x`` (as paper 000 does) is an ordinary open-loop problem, because ``r`` is chosen by the
experimenter and does not depend on the noise. Identifying the plant from ``u`` to ``x``
inside a loop is not: the noise then feeds back into ``u`` and least squares is biased
unless the noise really has the ARX structure.

Examples
--------
>>> import numpy as np
>>> from workbench.identify.arx import fit_arx, validate
>>> from workbench.identify.excitation import aprbs
>>> rng = np.random.default_rng(0)
>>> u = aprbs(800, hold_min=5, low=0.0, high=10.0, seed=0)
>>> y = np.zeros(800)
>>> for k in range(2, 800):       # y(k) - 0.9 y(k-1) = 0.1 u(k-2) + e(k)
...     y[k] = 0.9 * y[k - 1] + 0.1 * u[k - 2] + 0.01 * rng.standard_normal()
>>> model = fit_arx(y[:400], u[:400], orders=(1, 1, 2), sample_time=0.01)
>>> np.round(model.a, 2), np.round(model.b, 2)
(array([-0.9]), array([0.1]))
>>> check = validate(model, y[400:], u[400:])
>>> bool(check.fit > 95.0), check.whiteness_ok
(True, True)
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import numbers
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from ..errors import InputError

__all__ = [
    "ArxModel", "fit_arx", "OrderCandidate", "OrderSelection", "select_order",
    "ArxValidation", "validate", "CONFIDENCE_Z99", "CRITERIA", "add_cli",
]

#: Two-sided 99 % quantile of the standard normal distribution: the confidence band
#: of a normalised correlation estimated from N samples is +-2.58/sqrt(N).
CONFIDENCE_Z99 = 2.5758293035489004
#: Order selection criteria of :func:`select_order`.
CRITERIA = ("aic", "bic", "fpe", "loss", "fit")
#: Significance level of the whiteness and independence tests of :func:`validate`.
TEST_LEVEL = 0.01
#: Relative singular value below which the (column-scaled) regressors count as
#: linearly dependent: far above round-off (1e-16), far below any real excitation.
_RANK_TOL = 1e-9


# --------------------------------------------------------------------------------------
# The model
# --------------------------------------------------------------------------------------
def _ro(x: Any) -> np.ndarray:
    arr = np.array(x, dtype=float)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class ArxModel:
    """An ARX model ``A(q) y = q^-nk B(q) u + e`` estimated by :func:`fit_arx`.

    Units: ``y`` and ``u`` keep the units of the data they were estimated from (e.g. m
    for a position, V for a valve command); ``a`` is dimensionless, ``b`` has the unit
    of ``y`` per unit of ``u``.

    Attributes
    ----------
    a : numpy.ndarray, shape (na,)
        ``a1 .. a_na`` (the leading 1 of A(q) excluded), -.
    b : numpy.ndarray, shape (nb,)
        ``b1 .. b_nb``, unit of y / unit of u.
    nk : int
        Input delay, samples (>= 0).
    std_a, std_b : numpy.ndarray
        Standard deviations of ``a`` and ``b`` from ``noise_variance * (Phi' Phi)^-1``.
    noise_variance : float
        Residual variance with the degrees of freedom corrected,
        ``sum(e**2) / (N - na - nb)``, unit of y squared.
    sample_time : float or None
        Sample time, s (None: unknown; the model is then in samples).
    loss : float
        Loss function ``V = sum(e**2) / N`` (MATLAB's ``LossFcn``), unit of y squared.
    aic, bic, fpe : float
        Akaike ``N ln V + 2 d``, Bayesian (MDL) ``N ln V + d ln N`` (both up to a
        constant that is the same for every model fitted on the same N samples),
        final prediction error ``V (1 + d/N) / (1 - d/N)`` (unit of y squared), with
        ``d = na + nb`` parameters.
    n_samples : int
        ``N``: equations (samples with a full regressor) used in the estimate.
    covariance : numpy.ndarray, shape (na+nb, na+nb)
        Covariance of ``[a, b]``.
    y_offset, u_offset : float
        Operating point (an equilibrium of the model), unit of y and u; zero unless
        estimated with ``offset=True`` in :func:`fit_arx`. The model relates the
        deviations ``y - y_offset`` and ``u - u_offset``; :meth:`predict` and
        :meth:`simulate` take and return absolute values.
    """

    a: np.ndarray
    b: np.ndarray
    nk: int
    std_a: np.ndarray
    std_b: np.ndarray
    noise_variance: float
    sample_time: float | None = None
    loss: float = math.nan
    aic: float = math.nan
    bic: float = math.nan
    fpe: float = math.nan
    n_samples: int = 0
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    y_offset: float = 0.0
    u_offset: float = 0.0

    def __post_init__(self) -> None:
        for name in ("a", "b", "std_a", "std_b", "covariance"):
            object.__setattr__(self, name, _ro(getattr(self, name)))
        if self.b.size < 1:
            raise InputError("an ARX model needs at least one b coefficient (nb >= 1)")
        if self.std_a.shape != self.a.shape or self.std_b.shape != self.b.shape:
            raise InputError("std_a and std_b must have the shapes of a and b")
        object.__setattr__(self, "nk", _order("nk", self.nk, 0))
        if self.sample_time is not None:
            object.__setattr__(self, "sample_time", _sample_time(self.sample_time))

    # ---- structure ------------------------------------------------------------------
    @property
    def na(self) -> int:
        """Number of ``a`` coefficients."""
        return int(self.a.size)

    @property
    def nb(self) -> int:
        """Number of ``b`` coefficients."""
        return int(self.b.size)

    @property
    def orders(self) -> tuple[int, int, int]:
        """``(na, nb, nk)`` as in MATLAB's ``arx``."""
        return (self.na, self.nb, self.nk)

    @property
    def max_lag(self) -> int:
        """Samples of the past a prediction needs: ``max(na, nk + nb - 1)``."""
        return _max_lag(self.na, self.nb, self.nk)

    @property
    def theta(self) -> np.ndarray:
        """All parameters ``[a, b]``."""
        return np.concatenate([self.a, self.b])

    # ---- transfer function ----------------------------------------------------------
    def polynomials(self) -> tuple[np.ndarray, np.ndarray]:
        """Numerator and denominator of G(z) in descending powers of z, same length.

        ``G(z) = (b1 z^-nk + ... ) / (1 + a1 z^-1 + ...)`` multiplied through by
        ``z^n``, ``n = max(na, nk + nb - 1)``.
        """
        n = self.max_lag
        den = np.zeros(n + 1)
        den[: self.na + 1] = np.concatenate([[1.0], self.a])
        num = np.zeros(n + 1)
        num[self.nk: self.nk + self.nb] = self.b
        return num, den

    @property
    def poles(self) -> np.ndarray:
        """Roots of ``z^na + a1 z^(na-1) + ... + a_na`` (complex), -."""
        return np.roots(np.concatenate([[1.0], self.a])).astype(complex)

    @property
    def zeros(self) -> np.ndarray:
        """Finite zeros of the input polynomial ``b1 z^(nb-1) + ... + b_nb`` (complex)."""
        b = np.trim_zeros(self.b, "f")
        return np.roots(b).astype(complex) if b.size > 1 else np.zeros(0, complex)

    @property
    def dc_gain(self) -> float:
        """Static gain ``B(1) / A(1)``, unit of y / unit of u (inf for an integrator)."""
        den = 1.0 + float(np.sum(self.a))
        num = float(np.sum(self.b))
        if den == 0.0:
            return math.copysign(math.inf, num) if num else math.nan
        return num / den

    @property
    def is_stable(self) -> bool:
        """Whether every pole is strictly inside the unit circle."""
        return bool(np.all(np.abs(self.poles) < 1.0))

    def to_control(self):
        """The model ``y/u`` as a discrete :class:`control.TransferFunction`.

        The time base is ``sample_time`` (s), or ``True`` (unspecified) when unknown.
        The noise path ``1/A(q)`` is not included.
        """
        import control

        num, den = self.polynomials()
        num = np.trim_zeros(num, "f") if np.any(num) else np.zeros(1)
        return control.tf(num, den, self.sample_time if self.sample_time else True)

    # ---- use ------------------------------------------------------------------------
    def predict(self, y: Any, u: Any) -> np.ndarray:
        """One-step-ahead prediction ``y_hat(k | k-1)`` from measured ``y`` and ``u``.

        Parameters
        ----------
        y : array_like, shape (n,)
            Measured output, unit of y.
        u : array_like, shape (n,)
            Input, unit of u.

        Returns
        -------
        numpy.ndarray, shape (n,)
            Predicted output, unit of y; the first :attr:`max_lag` entries are NaN
            (no full past there).

        Raises
        ------
        InputError
            For NaN/inf, mismatched lengths or fewer than ``max_lag + 1`` samples.
        """
        yy, uu = _data(y, u, "predict")
        n0 = self.max_lag
        if yy.size <= n0:
            raise InputError(f"predict: the model needs more than {n0} samples of past "
                             f"data (max lag {n0}); got {yy.size}")
        phi = _regressors(yy - self.y_offset, uu - self.u_offset, self.na, self.nb,
                          self.nk, n0)
        pred = np.full(yy.size, np.nan)
        pred[n0:] = phi @ self.theta + self.y_offset
        return pred

    def simulate(self, u: Any, y0: Any = None) -> np.ndarray:
        """Pure simulation: the output the model gives for the input ``u`` alone.

        Parameters
        ----------
        u : array_like, shape (n,)
            Input, unit of u. Its first :attr:`max_lag` samples are the past inputs.
        y0 : float or array_like of shape (max_lag,), optional
            The first :attr:`max_lag` outputs (the initial state), unit of y; a number
            is repeated. Default: ``y_offset`` (rest at the operating point). For
            validation pass the measured ``y[:max_lag]``.

        Returns
        -------
        numpy.ndarray, shape (n,)
            Simulated output, unit of y; the first :attr:`max_lag` entries are ``y0``.

        Raises
        ------
        InputError
            For NaN/inf in ``u`` or ``y0`` or a ``y0`` of the wrong length.
        """
        uu = _vector(u, "input u", "simulate")
        n0 = self.max_lag
        if y0 is None:
            y0v = np.full(n0, self.y_offset)
        else:
            y0v = np.asarray(y0, dtype=float).ravel()
            if y0v.size == 1:
                y0v = np.full(n0, float(y0v[0]))
            if y0v.size != n0:
                raise InputError(f"simulate: y0 must hold the first {n0} outputs (the "
                                 f"model's max lag), got {y0v.size} values")
            if not np.all(np.isfinite(y0v)):
                raise InputError("simulate: y0 must be finite")
        out = np.empty(uu.size)
        m = min(n0, uu.size)
        out[:m] = y0v[:m]
        if uu.size <= n0:
            return out
        from scipy.signal import lfilter, lfiltic

        num = np.concatenate([np.zeros(self.nk), self.b])
        den = np.concatenate([[1.0], self.a])
        ud = uu - self.u_offset
        yd0 = y0v - self.y_offset
        zi = lfiltic(num, den, y=yd0[::-1], x=ud[:n0][::-1])
        out[n0:] = lfilter(num, den, ud[n0:], zi=zi)[0] + self.y_offset
        return out

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready description (lists and floats; inf/NaN as None; poles [re, im])."""
        return {
            "orders": {"na": self.na, "nb": self.nb, "nk": self.nk},
            "a": self.a.tolist(), "b": self.b.tolist(), "nk": self.nk,
            "std_a": self.std_a.tolist(), "std_b": self.std_b.tolist(),
            "noise_variance": _num(self.noise_variance),
            "sample_time": self.sample_time,
            "loss": _num(self.loss), "aic": _num(self.aic), "bic": _num(self.bic),
            "fpe": _num(self.fpe), "n_samples": self.n_samples,
            "poles": _pairs(self.poles), "zeros": _pairs(self.zeros),
            "dc_gain": _num(self.dc_gain), "stable": self.is_stable,
            "y_offset": self.y_offset, "u_offset": self.u_offset,
        }

    def __repr__(self) -> str:
        return (f"ArxModel(orders={self.orders}, a={np.round(self.a, 5).tolist()}, "
                f"b={np.round(self.b, 6).tolist()}, N={self.n_samples}, "
                f"sample_time={self.sample_time})")


# --------------------------------------------------------------------------------------
# Estimation
# --------------------------------------------------------------------------------------
def fit_arx(y: Any, u: Any, orders: Sequence[int] = (2, 2, 1),
            sample_time: float | None = None, offset: bool = False) -> ArxModel:
    """Estimate an ARX model by least squares.

    Parameters
    ----------
    y : array_like, shape (n,)
        Measured output (e.g. position x, m), one value per sample.
    u : array_like, shape (n,)
        Input on the same samples (e.g. reference r, m, or command u, V).
    orders : (int, int, int)
        ``(na, nb, nk)`` in MATLAB's ``arx`` convention: ``na >= 0`` a-coefficients,
        ``nb >= 1`` b-coefficients, delay ``nk >= 0`` samples. Paper 000: (4, 1, 2).
    sample_time : float, optional
        Sample time, s; stored in the model (poles to continuous time, python-control).
    offset : bool, optional
        Estimate a constant ``c`` in the equation along with ``a`` and ``b``
        (``A(q) y = B(q) q^-nk u + c + e``) and store it as an operating point
        (``y_offset``, ``u_offset``) with ``A(1) y_offset - B(1) u_offset = c``: the
        mean of the data for the better-determined of the two (the output for a
        process with a static gain, the input's null for an integrator), the other
        from c. Unlike subtracting the means, this is exact for data that do not start
        at rest. Use it when the data sit around an operating point the model should
        not have to explain (e.g. a valve command around 5 V). Default False, as
        MATLAB's ``arx``: a closed position loop r -> x needs no offsets.

    Returns
    -------
    ArxModel
        Estimates, standard deviations ``sqrt(diag(sigma^2 (Phi' Phi)^-1))`` with the
        degrees-of-freedom corrected residual variance ``sigma^2``, loss, AIC, BIC, FPE.

    Raises
    ------
    InputError
        If the data are too short for the orders (the message says how many samples
        are needed), the input is constant or otherwise not persistently exciting, the
        data hold NaN or inf (the message gives the index), ``y`` and ``u`` differ in
        length, or an order is negative, not whole, or ``nb`` is zero.

    Notes
    -----
    The equations are those samples ``k >= max(na, nk + nb - 1)`` that have a full
    past; nothing before the data is assumed. The regressor columns are scaled to unit
    norm and solved by SVD, which keeps the estimate accurate when the columns differ
    in size (m against V) or are nearly dependent.

    The standard deviations hold for the ARX noise structure (white ``e``); with
    coloured noise the estimate is biased and the residual tests of :func:`validate`
    say so.

    Examples
    --------
    Paper 000, Table I (closed loop r -> x, [na nb d] = [4 1 1]):

    >>> import numpy as np
    >>> from workbench.identify.excitation import aprbs
    >>> a_true, b_true = [-2.4478, 2.1352, -0.7742, 0.0995], [0.0125]
    >>> r = aprbs(400, hold_min=8, low=0.0, high=10.0, seed=1)
    >>> x = np.zeros(400)
    >>> for k in range(4, 400):
    ...     x[k] = -np.dot(a_true, x[k - 1::-1][:4]) + b_true[0] * r[k - 2]
    >>> m = fit_arx(x, r, orders=(4, 1, 2), sample_time=0.01)
    >>> np.allclose(m.a, a_true) and np.allclose(m.b, b_true)
    True
    """
    na, nb, nk = _orders(orders)
    ts = None if sample_time is None else _sample_time(sample_time)
    yy, uu = _data(y, u, "fit_arx")
    if not isinstance(offset, (bool, np.bool_)):
        raise InputError(f"offset must be True or False, got {offset!r}")
    _check_excitation(uu, "fit_arx")
    return _fit(yy, uu, na, nb, nk, _max_lag(na, nb, nk), ts, bool(offset))


def _fit(y: np.ndarray, u: np.ndarray, na: int, nb: int, nk: int, start: int,
         sample_time: float | None, offset: bool = False) -> ArxModel:
    """Least squares on equations k = start .. n-1 (data already checked)."""
    d = na + nb + int(offset)
    n_eq = y.size - start
    needed = start + d + 1
    if n_eq < d + 1:
        raise InputError(
            f"too few samples for ARX orders (na, nb, nk) = ({na}, {nb}, {nk}): "
            f"{d} parameters need at least {needed} samples ({start} of past for the "
            f"first regressor, {d} equations for the parameters and 1 more for the "
            f"noise variance); got {y.size}")
    phi = _regressors(y, u, na, nb, nk, start)
    if offset:
        phi = np.column_stack([phi, np.ones(n_eq)])
    target = y[start:]
    norms = np.linalg.norm(phi, axis=0)
    if np.any(norms == 0.0):
        j = int(np.flatnonzero(norms == 0.0)[0])
        raise InputError(_dependent_message(j, na, nb, nk, zero=True))
    scaled = phi / norms
    U, s, Vt = np.linalg.svd(scaled, full_matrices=False)
    if s[-1] < _RANK_TOL * s[0]:
        # Which column is (nearly) a combination of the others?
        j = int(np.argmax(np.abs(Vt[-1])))
        raise InputError(_dependent_message(j, na, nb, nk, zero=False))
    theta_s = Vt.T @ ((U.T @ target) / s)
    theta = theta_s / norms
    resid = target - phi @ theta
    sse = float(resid @ resid)
    dof = n_eq - d
    sigma2 = sse / dof
    # (Phi' Phi)^-1 = D^-1 V S^-2 V' D^-1 with D = diag(norms)
    vs = Vt.T / s
    cov = sigma2 * (vs @ vs.T) / np.outer(norms, norms)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    loss = sse / n_eq
    log_v = math.log(loss) if loss > 0 else -math.inf
    aic = n_eq * log_v + 2 * d
    bic = n_eq * log_v + d * math.log(n_eq)
    fpe = loss * (1 + d / n_eq) / (1 - d / n_eq)
    y_off = u_off = 0.0
    if offset:
        a1 = 1.0 + float(np.sum(theta[:na]))
        b1 = float(np.sum(theta[na:na + nb]))
        c = float(theta[-1])
        if abs(b1) * float(np.std(u)) >= abs(a1) * float(np.std(y)):
            y_off = float(np.mean(y))
            u_off = (a1 * y_off - c) / b1
        else:
            u_off = float(np.mean(u))
            y_off = (b1 * u_off + c) / a1
    k = na + nb
    return ArxModel(a=theta[:na], b=theta[na:k], nk=nk, std_a=std[:na], std_b=std[na:k],
                    noise_variance=sigma2, sample_time=sample_time, loss=loss, aic=aic,
                    bic=bic, fpe=fpe, n_samples=n_eq, covariance=cov[:k, :k],
                    y_offset=y_off, u_offset=u_off)


def _regressors(y: np.ndarray, u: np.ndarray, na: int, nb: int, nk: int,
                start: int) -> np.ndarray:
    n = y.size
    phi = np.empty((n - start, na + nb))
    for i in range(1, na + 1):
        phi[:, i - 1] = -y[start - i: n - i]
    for j in range(nb):
        lag = nk + j
        phi[:, na + j] = u[start - lag: n - lag]
    return phi


def _dependent_message(j: int, na: int, nb: int, nk: int, zero: bool) -> str:
    if j >= na + nb:
        return ("the constant offset cannot be told apart from the other regressors: "
                "the data hold no step or level change; fit without offset")
    name = f"y(k-{j + 1}) (a{j + 1})" if j < na else \
        f"u(k-{nk + j - na}) (b{j - na + 1})"
    if j >= na:
        return (f"the input is not persistently exciting for nb = {nb}: the regressor "
                f"{name} is {'zero' if zero else 'a combination of the others'}, so "
                "the b coefficients cannot be told apart; excite with a richer input "
                "(PRBS/APRBS with more level changes) or lower nb")
    return (f"the regressors are linearly dependent: {name} is "
            f"{'zero' if zero else 'a combination of the others'}; the output does not "
            f"move enough for na = {na} (is it constant or noise-free and of lower "
            "order?): lower na or use data with more excitation")


# --------------------------------------------------------------------------------------
# Order selection
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class OrderCandidate:
    """One row of an order selection table.

    Attributes
    ----------
    na, nb, nk : int
        Orders (MATLAB ``arx`` convention).
    n_parameters : int
        ``na + nb`` (+1 with an estimated offset).
    loss : float
        ``sum(e**2) / N`` on the estimation data, unit of y squared.
    aic, bic : float
        ``N ln V + 2 d`` and ``N ln V + d ln N`` on the estimation data, -.
    fpe : float
        Final prediction error, unit of y squared.
    validation_loss : float
        Mean squared one-step prediction error on the validation data, unit of y
        squared (NaN without validation data).
    validation_fit : float
        Simulation fit on the validation data, % (NaN without validation data).
    """

    na: int
    nb: int
    nk: int
    n_parameters: int
    loss: float
    aic: float
    bic: float
    fpe: float
    validation_loss: float = math.nan
    validation_fit: float = math.nan

    @property
    def orders(self) -> tuple[int, int, int]:
        return (self.na, self.nb, self.nk)

    def as_dict(self) -> dict[str, Any]:
        return {"na": self.na, "nb": self.nb, "nk": self.nk,
                "n_parameters": self.n_parameters, "loss": _num(self.loss),
                "aic": _num(self.aic), "bic": _num(self.bic), "fpe": _num(self.fpe),
                "validation_loss": _num(self.validation_loss),
                "validation_fit": _num(self.validation_fit)}


@dataclass(frozen=True, eq=False)
class OrderSelection:
    """Result of :func:`select_order`.

    Attributes
    ----------
    candidates : tuple of OrderCandidate
        Every order tried, in grid order.
    criterion : str
        The criterion used (one of :data:`CRITERIA`).
    best : OrderCandidate
        The candidate with the smallest criterion (the largest fit for ``"fit"``);
        ties go to fewer parameters.
    model : ArxModel
        The best orders fitted on all estimation samples (not only the common ones).
    """

    candidates: tuple[OrderCandidate, ...]
    criterion: str
    best: OrderCandidate
    model: ArxModel

    @property
    def orders(self) -> tuple[int, int, int]:
        """Best ``(na, nb, nk)``."""
        return self.best.orders

    def table(self, limit: int | None = None) -> str:
        """The candidates as a text table, best marked with ``*``, sorted by criterion.

        Parameters
        ----------
        limit : int, optional
            Show only the best ``limit`` rows (and say how many were left out).
        """
        rows = sorted(self.candidates, key=lambda c: _score(c, self.criterion))
        left_out = 0
        if limit is not None and len(rows) > limit:
            left_out = len(rows) - limit
            rows = rows[:limit]
        has_val = any(math.isfinite(c.validation_loss) for c in rows)
        head = f"  {'na':>3} {'nb':>3} {'nk':>3} {'d':>3} {'loss':>12} {'AIC':>11} " \
               f"{'BIC':>11} {'FPE':>12}"
        if has_val:
            head += f" {'val loss':>12} {'val fit %':>9}"
        lines = [head]
        for c in rows:
            mark = "*" if c.orders == self.best.orders else " "
            line = (f"{mark} {c.na:>3} {c.nb:>3} {c.nk:>3} {c.n_parameters:>3} "
                    f"{c.loss:>12.5g} {c.aic:>11.2f} {c.bic:>11.2f} {c.fpe:>12.5g}")
            if has_val:
                line += f" {c.validation_loss:>12.5g} {c.validation_fit:>9.2f}"
            lines.append(line)
        if left_out:
            lines.append(f"  ... {left_out} more candidates")
        return "\n".join(lines)

    def as_dict(self) -> dict[str, Any]:
        return {"criterion": self.criterion,
                "best": {"na": self.best.na, "nb": self.best.nb, "nk": self.best.nk},
                "candidates": [c.as_dict() for c in self.candidates]}

    def to_pandas(self):
        """The candidates as a :class:`pandas.DataFrame`, one row each."""
        import pandas as pd
        return pd.DataFrame([c.as_dict() for c in self.candidates])


def select_order(y: Any, u: Any, na_range: Iterable[int] = range(1, 6),
                 nb_range: Iterable[int] = range(1, 4),
                 nk_range: Iterable[int] = range(1, 4), criterion: str = "aic",
                 validation: tuple[Any, Any] | None = None,
                 sample_time: float | None = None, offset: bool = False
                 ) -> OrderSelection:
    """Fit every ARX order of a grid and pick the best by a criterion.

    All candidates are estimated on the same equations (samples from the largest max
    lag of the grid on), so their losses, AIC, BIC and FPE compare like with like, as
    MATLAB's ``arxstruc``.

    Parameters
    ----------
    y, u : array_like, shape (n,)
        Estimation data: output and input (units of the problem, e.g. m and m).
    na_range, nb_range, nk_range : iterable of int
        Orders to try (``na >= 0``, ``nb >= 1``, ``nk >= 0``).
    criterion : {"aic", "bic", "fpe", "loss", "fit"}
        ``aic``/``bic``/``fpe``: on the estimation data. ``loss``: mean squared
        one-step prediction error on the validation data if given (as ``arxstruc``),
        else on the estimation data (which always prefers the largest model). ``fit``:
        simulation fit on the validation data (needs ``validation``). AIC is the
        classical choice but tends to over-fit by a parameter now and then; BIC is
        consistent (picks the true order as N grows).
    validation : (y_v, u_v), optional
        Held-out data, same units.
    sample_time : float, optional
        Sample time, s, stored in the models.
    offset : bool, optional
        Estimate a constant offset in every candidate, as in :func:`fit_arx`.

    Returns
    -------
    OrderSelection
        Table of candidates, the best and its model.

    Raises
    ------
    InputError
        For an unknown criterion, ``fit`` without validation data, an empty or bad
        range, and every data error of :func:`fit_arx` (for the largest orders).

    Examples
    --------
    >>> import numpy as np
    >>> from workbench.identify.excitation import aprbs
    >>> rng = np.random.default_rng(0)
    >>> u = aprbs(600, 4, 0.0, 1.0, seed=0)
    >>> y = np.zeros(600)
    >>> for k in range(3, 600):
    ...     y[k] = 1.5 * y[k-1] - 0.7 * y[k-2] + 0.5 * u[k-3] + 0.01 * rng.standard_normal()
    >>> select_order(y, u, range(1, 4), range(1, 3), range(1, 5), criterion="bic").orders
    (2, 1, 3)
    """
    if criterion not in CRITERIA:
        raise InputError(f"unknown order selection criterion {criterion!r}; use one "
                         f"of {', '.join(CRITERIA)}")
    if criterion == "fit" and validation is None:
        raise InputError("criterion 'fit' is the simulation fit on validation data: "
                         "pass validation=(y_v, u_v)")
    grid = [_orders(o) for o in itertools.product(
        _range("na_range", na_range), _range("nb_range", nb_range),
        _range("nk_range", nk_range))]
    ts = None if sample_time is None else _sample_time(sample_time)
    yy, uu = _data(y, u, "select_order")
    _check_excitation(uu, "select_order")
    if not isinstance(offset, (bool, np.bool_)):
        raise InputError(f"offset must be True or False, got {offset!r}")
    offset = bool(offset)
    yv = uv = None
    if validation is not None:
        try:
            yv_raw, uv_raw = validation
        except (TypeError, ValueError):
            raise InputError("validation must be a pair (y_v, u_v)") from None
        yv, uv = _data(yv_raw, uv_raw, "select_order (validation data)")
    start = max(_max_lag(*o) for o in grid)
    candidates = []
    for na, nb, nk in grid:
        m = _fit(yy, uu, na, nb, nk, start, ts, offset)
        v_loss = v_fit = math.nan
        if yv is not None:
            n0 = m.max_lag
            if yv.size <= n0 + 1:
                raise InputError(f"select_order: the validation data have {yv.size} "
                                 f"samples, orders ({na}, {nb}, {nk}) need more than "
                                 f"{n0 + 1}")
            e = yv[n0:] - m.predict(yv, uv)[n0:]
            v_loss = float(e @ e) / e.size
            v_fit = _fit_percent(yv[n0:], m.simulate(uv, y0=yv[:n0])[n0:])
        candidates.append(OrderCandidate(na, nb, nk, na + nb + offset, m.loss, m.aic, m.bic,
                                         m.fpe, v_loss, v_fit))
    best = min(candidates, key=lambda c: _score(c, criterion))
    model = _fit(yy, uu, *best.orders, _max_lag(*best.orders), ts, offset)
    return OrderSelection(tuple(candidates), criterion, best, model)


def _score(c: OrderCandidate, criterion: str) -> tuple[float, int]:
    if criterion == "fit":
        value = -c.validation_fit
    elif criterion == "loss" and math.isfinite(c.validation_loss):
        value = c.validation_loss          # as arxstruc: loss on the validation data
    else:
        value = getattr(c, criterion)
    if not math.isfinite(value):
        value = math.inf
    return (value, c.n_parameters)


# --------------------------------------------------------------------------------------
# Validation: simulation fit and residual analysis
# --------------------------------------------------------------------------------------
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

    def as_dict(self) -> dict[str, Any]:
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


def validate(model: ArxModel, y: Any, u: Any, lags: int = 25) -> ArxValidation:
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
        Largest correlation lag M, samples (default 25, as MATLAB's ``resid``); reduced
        to a quarter of the residuals if the data are short.

    Returns
    -------
    ArxValidation
        Fit %, simulated output, residuals, correlations with the 99 % band and the
        whiteness and independence verdicts.

    Raises
    ------
    InputError
        For NaN/inf, mismatched lengths, or fewer than ``model.max_lag + 8`` samples
        (too few residuals for a correlation test).

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
    lag_max = _order("lags", lags, 1)
    n0 = model.max_lag
    if yy.size < n0 + 8:
        raise InputError(f"validate: {yy.size} samples are too few for a model with max "
                         f"lag {n0}; need at least {n0 + 8} (8 residuals)")
    from scipy import stats

    y_sim = model.simulate(uu, y0=yy[:n0])
    fit = _fit_percent(yy[n0:], y_sim[n0:])
    e = yy[n0:] - model.predict(yy, uu)[n0:]
    n = e.size
    m = max(1, min(lag_max, n // 4))
    ec = e - e.mean()
    uc = uu[n0:] - uu[n0:].mean()
    c_e = np.array([ec[k:] @ ec[: n - k] for k in range(m + 1)]) / n
    c_u = np.array([uc[k:] @ uc[: n - k] for k in range(m + 1)]) / n
    band = CONFIDENCE_Z99 / math.sqrt(n)
    lags = np.arange(m + 1)
    cross_lags = np.arange(-m, m + 1)
    # cross-covariance c_eu(tau) = 1/N sum e(k) u(k - tau)
    c_eu = np.array([(ec[t:] @ uc[: n - t]) if t >= 0 else (ec[: n + t] @ uc[-t:])
                     for t in cross_lags]) / n
    if c_e[0] > 0:
        r_e = c_e / c_e[0]
        q = n * (n + 2) * float(np.sum(r_e[1:] ** 2 / (n - lags[1:])))
        p_white = float(stats.chi2.sf(q, m))
        white_ok: bool | None = p_white >= TEST_LEVEL
    else:
        r_e = np.full(m + 1, np.nan)
        q, p_white, white_ok = math.nan, math.nan, None
    if c_e[0] > 0 and c_u[0] > 0:
        r_eu = c_eu / math.sqrt(c_e[0] * c_u[0])
        ru = c_u / c_u[0]
        idx = np.abs(np.subtract.outer(np.arange(m + 1), np.arange(m + 1)))
        R = ru[idx]
        c_pos = r_eu[m:]                       # lags 0..M, normalised
        sol, *_ = np.linalg.lstsq(R, c_pos, rcond=1e-10)
        dof = int(np.linalg.matrix_rank(R, tol=1e-10 * np.linalg.norm(R, 2)))
        s_ind = n * float(c_pos @ sol)
        p_ind = float(stats.chi2.sf(s_ind, dof))
        ind_ok: bool | None = p_ind >= TEST_LEVEL
    else:
        r_eu = np.full(2 * m + 1, np.nan)
        s_ind, p_ind, ind_ok = math.nan, math.nan, None
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


# --------------------------------------------------------------------------------------
# Input checks
# --------------------------------------------------------------------------------------
def _order(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        if isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)) \
                and math.isfinite(value) and float(value).is_integer():
            value = int(value)
        else:
            raise InputError(f"{name} must be a whole number, got {value!r}")
    value = int(value)
    if value < minimum:
        what = {"na": "a-coefficients (0 for an FIR model)",
                "nb": "b-coefficients (at least one: the input must act)",
                "nk": "samples of input delay"}.get(name, "")
        raise InputError(f"{name} must be >= {minimum}, got {value}"
                         + (f" ({name} counts {what})" if what else ""))
    return value


def _orders(orders: Any) -> tuple[int, int, int]:
    try:
        na, nb, nk = orders
    except (TypeError, ValueError):
        raise InputError(f"orders must be three whole numbers (na, nb, nk), got "
                         f"{orders!r}") from None
    return _order("na", na, 0), _order("nb", nb, 1), _order("nk", nk, 0)


def _range(name: str, values: Any) -> list[int]:
    try:
        vals = list(values)
    except TypeError:
        raise InputError(f"{name} must be an iterable of whole numbers, got "
                         f"{values!r}") from None
    if not vals:
        raise InputError(f"{name} is empty: give at least one order")
    return vals


def _max_lag(na: int, nb: int, nk: int) -> int:
    return max(na, nk + nb - 1)


def _sample_time(value: Any) -> float:
    try:
        ts = float(value)
    except (TypeError, ValueError):
        raise InputError(f"sample_time must be a positive number of seconds, got "
                         f"{value!r}") from None
    if not (math.isfinite(ts) and ts > 0):
        raise InputError(f"sample_time must be a positive number of seconds, got {ts}")
    return ts


def _vector(x: Any, what: str, who: str) -> np.ndarray:
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{who}: the {what} is not numeric") from None
    if arr.ndim > 1 and sum(s > 1 for s in arr.shape) <= 1:
        arr = arr.ravel()
    if arr.ndim != 1:
        raise InputError(f"{who}: the {what} must be one signal (1-D), got shape "
                         f"{arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = np.flatnonzero(bad)
        more = f" (and {idx.size - 1} more)" if idx.size > 1 else ""
        raise InputError(f"{who}: the {what} has {arr[idx[0]]} at index {idx[0]}{more}; "
                         "remove or repair those samples (ARX needs finite data)")
    return arr


def _data(y: Any, u: Any, who: str) -> tuple[np.ndarray, np.ndarray]:
    yy = _vector(y, "output y", who)
    uu = _vector(u, "input u", who)
    if yy.size != uu.size:
        raise InputError(f"{who}: output y has {yy.size} samples but input u has "
                         f"{uu.size}; they must be sampled together")
    if yy.size == 0:
        raise InputError(f"{who}: no data")
    return yy, uu


def _check_excitation(u: np.ndarray, who: str) -> None:
    scale = max(1.0, float(np.max(np.abs(u))))
    if float(np.ptp(u)) <= 1e-12 * scale:
        raise InputError(f"{who}: the input is constant ({u[0]:g} on all {u.size} "
                         "samples): it is not persistently exciting, so nothing about "
                         "the dynamics from u to y can be learnt; excite with steps, "
                         "a PRBS or an APRBS")


def _fit_percent(y: np.ndarray, y_model: np.ndarray) -> float:
    den = float(np.linalg.norm(y - y.mean()))
    if den == 0.0:
        return math.nan
    return float(100.0 * (1.0 - np.linalg.norm(y - y_model) / den))


def _num(x: Any) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _pairs(z: np.ndarray) -> list[list[float]]:
    return [[float(v.real), float(v.imag)] for v in np.asarray(z, dtype=complex)]


# --------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------
def _int_range(text: str) -> range:
    """``"1:5"`` or ``"3"`` -> range (inclusive)."""
    try:
        if ":" in text:
            lo, hi = (int(s) for s in text.split(":", 1))
        else:
            lo = hi = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected N or LO:HI, got {text!r}") from None
    if hi < lo:
        raise argparse.ArgumentTypeError(f"empty range {text!r}")
    return range(lo, hi + 1)


def add_cli(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``workbench identify arx`` to the ``identify`` sub-parsers."""
    p = subparsers.add_parser(
        "arx", help="ARX model by least squares, with validation on held-out data",
        description="Fit an ARX model y(k) + a1 y(k-1) + ... = b1 u(k-nk) + ... + e(k) "
                    "(MATLAB arx orders na nb nk) to two columns of RECORDING by least "
                    "squares on the first SPLIT fraction of the samples; simulate it on "
                    "the rest (fit %) and test the one-step residuals there: "
                    "autocorrelation (Ljung-Box) and input-residual cross-correlation "
                    "against 99 % bands, each at the 1 % level. Paper 000's closed loop "
                    "[na nb d] = [4 1 1]: --input r --output x --orders 4 1 2. With "
                    "--select, orders are chosen over a grid first and the table printed.",
        epilog="Units are those of the recording's columns (SI). Example: workbench "
               "identify arx run.csv --input r --output x --orders 4 1 2 --split 0.5 --json")
    p.add_argument("recording", metavar="RECORDING",
                   help="recording (.csv or .mat, formats.md section 3)")
    p.add_argument("--input", default="r", metavar="COL", help="input column (default r)")
    p.add_argument("--output", default="x", metavar="COL", help="output column (default x)")
    p.add_argument("--orders", nargs=3, type=int, metavar=("NA", "NB", "NK"),
                   help="orders na nb nk (required unless --select)")
    p.add_argument("--split", type=float, default=0.5, metavar="F",
                   help="fraction of the samples used for estimation, 0 < F < 1; the rest "
                        "validates (default 0.5)")
    p.add_argument("--offset", action="store_true",
                   help="estimate a constant offset (operating point) along with a and b")
    p.add_argument("--select", action="store_true",
                   help="choose the orders over a grid (--na, --nb, --nk) and print the table")
    p.add_argument("--criterion", choices=CRITERIA, default="aic",
                   help="order selection criterion (default aic; loss and fit are on the "
                        "validation part)")
    p.add_argument("--na", type=_int_range, default=range(1, 6), metavar="LO:HI",
                   help="na grid for --select (default 1:5)")
    p.add_argument("--nb", type=_int_range, default=range(1, 4), metavar="LO:HI",
                   help="nb grid for --select (default 1:3)")
    p.add_argument("--nk", type=_int_range, default=range(0, 5), metavar="LO:HI",
                   help="nk grid for --select (default 0:4)")
    p.add_argument("--lags", type=int, default=25, metavar="M",
                   help="correlation lags of the residual tests, samples (default 25)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--out", metavar="DIR",
                   help="also write DIR/arx.json, DIR/residuals.png and DIR/validation.png")
    p.set_defaults(func=_cmd_arx)
    return p


def _cmd_arx(args: argparse.Namespace) -> int:
    from ..recording import load_recording

    rec = load_recording(args.recording)
    for role, col in (("input", args.input), ("output", args.output)):
        if not rec.has(col):
            raise InputError(f"no column '{col}' for the {role}; the recording has: "
                             f"{', '.join(rec.columns)}", source=rec.source)
    if not (math.isfinite(args.split) and 0.0 < args.split < 1.0):
        raise InputError(f"--split must be a fraction between 0 and 1 (exclusive), got "
                         f"{args.split}")
    if args.orders is None and not args.select:
        raise InputError("give --orders NA NB NK, or --select to choose them")
    y, u = np.asarray(rec[args.output]), np.asarray(rec[args.input])
    n_est = int(round(args.split * len(rec)))
    if n_est < 2 or len(rec) - n_est < 2:
        raise InputError(f"--split {args.split} leaves {n_est} estimation and "
                         f"{len(rec) - n_est} validation samples of {len(rec)}",
                         source=rec.source)
    ts = rec.sample_time
    src = rec.source
    ye, ue, yv, uv = y[:n_est], u[:n_est], y[n_est:], u[n_est:]
    selection = None
    try:
        if args.select:
            selection = select_order(ye, ue, args.na, args.nb, args.nk,
                                     criterion=args.criterion, validation=(yv, uv),
                                     sample_time=ts, offset=args.offset)
            model = selection.model
        else:
            model = fit_arx(ye, ue, tuple(args.orders), sample_time=ts,
                            offset=args.offset)
        check = validate(model, yv, uv, lags=args.lags)
    except InputError as exc:
        if exc.source:
            raise
        raise InputError(str(exc), source=src,
                         location=f"columns '{args.input}' -> '{args.output}'") from None
    result = {
        "a": model.a.tolist(), "b": model.b.tolist(),
        "std_a": model.std_a.tolist(), "std_b": model.std_b.tolist(),
        "fit_validation": _num(check.fit),
        "residual_whiteness_ok": check.whiteness_ok,
        "poles": _pairs(model.poles),
        "residual_independence_ok": check.independence_ok,
        "orders": [model.na, model.nb, model.nk],
        "nk": model.nk,
        "fit_estimation": _num(validate(model, ye, ue, lags=args.lags).fit),
        "whiteness_p_value": _num(check.whiteness_p_value),
        "independence_p_value": _num(check.independence_p_value),
        "noise_variance": _num(model.noise_variance),
        "loss": _num(model.loss), "aic": _num(model.aic), "fpe": _num(model.fpe),
        "dc_gain": _num(model.dc_gain), "zeros": _pairs(model.zeros),
        "stable": model.is_stable, "sample_time": ts,
        "input": args.input, "output": args.output, "recording": str(args.recording),
        "n_estimation": n_est, "n_validation": len(rec) - n_est,
        "offset": bool(args.offset), "y_offset": model.y_offset,
        "u_offset": model.u_offset,
    }
    if selection is not None:
        result["selection"] = selection.as_dict()
    if args.out:
        from ..params import atomic_write_text
        from . import plots

        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / "arx.json", json.dumps(result, indent=2) + "\n")
        names = {"input_unit": _unit(args.input), "output_unit": _unit(args.output),
                 "input_name": args.input, "output_name": args.output}
        label = (f"ARX [{model.na} {model.nb} {model.nk}] {args.input} -> {args.output}, "
                 f"{Path(args.recording).name}")
        plots.residual_figure(check, out / "residuals.png",
                              title=f"{label}: residuals on held-out data", **names)
        plots.validation_figure(check, out / "validation.png",
                                title=f"{label}: simulation on held-out data",
                                t0=float(rec.t[n_est]), **names)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    if selection is not None:
        print(f"order selection by {selection.criterion} "
              f"({n_est} estimation, {len(rec) - n_est} validation samples):")
        print(selection.table(limit=15))
        print()
    _print_summary(model, check, result, args)
    if args.out:
        print(f"wrote {Path(args.out) / 'arx.json'}, residuals.png, validation.png")
    return 0


def _unit(column: str) -> str:
    from ..recording import UNITS
    return UNITS.get(column, "-")


def _print_summary(model: ArxModel, check: ArxValidation, result: Mapping[str, Any],
                   args: argparse.Namespace) -> None:
    na, nb, nk = model.orders
    print(f"ARX [na nb nk] = [{na} {nb} {nk}] from {args.input} to {args.output}, "
          f"{result['n_estimation']} estimation samples, T = {model.sample_time} s")
    for name, vals, stds in (("a", model.a, model.std_a), ("b", model.b, model.std_b)):
        for i, (v, s) in enumerate(zip(vals, stds), start=1):
            print(f"  {name}{i} = {v: .6g}  +- {s:.2g} (1 std)")
    print(f"  noise variance {model.noise_variance:.4g}, DC gain {model.dc_gain:.4g}, "
          f"{'stable' if model.is_stable else 'NOT stable'}")
    print("  poles " + ", ".join(f"{p.real:.4f}{p.imag:+.4f}j" for p in model.poles))
    print(f"validation ({result['n_validation']} held-out samples): fit "
          f"{check.fit:.2f} %")

    def verdict(ok: bool | None, p: float) -> str:
        return "n/a" if ok is None else f"{'pass' if ok else 'FAIL'} (p = {p:.3g})"

    print(f"  residual whiteness   {verdict(check.whiteness_ok, check.whiteness_p_value)}, "
          f"{check.autocorrelation_outside}/{int(check.lags[-1])} lags outside the 99 % band")
    print(f"  input independence   "
          f"{verdict(check.independence_ok, check.independence_p_value)}, "
          f"{check.cross_correlation_outside}/{check.cross_lags.size} lags outside")
