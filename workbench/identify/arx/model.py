"""The ARX model and its least-squares estimation (:func:`fit_arx`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ...errors import InputError
from .checks import _check_excitation, _data, _max_lag, _order, _orders, _sample_time, _vector
from .checks import complex_pairs as _pairs, finite_or_none as _num

__all__ = ["ArxModel", "fit_arx"]

#: Relative singular value below which the (column-scaled) regressors count as
#: linearly dependent: far above round-off (1e-16), far below any real excitation.
_RANK_TOL = 1e-9


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

    def to_dict(self) -> dict[str, Any]:
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
