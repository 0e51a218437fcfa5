"""Recursive least squares with a forgetting factor for time-varying ARX models (paper 002).

The model is an ARX model whose parameters may change with time, with MATLAB's ``arx``
order convention ``(na, nb, nk)``::

    y(k) + a1(k) y(k-1) + ... + a_na(k) y(k-na)
         = b1(k) u(k-nk) + ... + b_nb(k) u(k-nk-nb+1) + e(k)

so ``theta = [a1 .. a_na, b1 .. b_nb]`` and the regressor is
``phi(k) = [-y(k-1) .. -y(k-na), u(k-nk) .. u(k-nk-nb+1)]``. At every sample the
estimate is corrected by the a priori prediction error (physics.md, "Identification")::

    eps(k)   = y(k) - phi(k)' theta(k-1)
    K(k)     = P(k-1) phi(k) / (lambda + phi(k)' P(k-1) phi(k))
    theta(k) = theta(k-1) + K(k) eps(k)
    P(k)     = (P(k-1) - K(k) phi(k)' P(k-1)) / lambda

with the forgetting factor ``0 < lambda <= 1``: data ``j`` samples old carry the weight
``lambda**j`` (memory of about ``1 / (1 - lambda)`` samples). Paper 002 tracked a
2nd-order model of a pneumatic cylinder from 1000 PRBS samples and found
``lambda = 0.99`` best; ``0.9`` follows changes faster but is much noisier.

Numerical form (what is computed, equivalent to the recursion above)
--------------------------------------------------------------------
* **Forget first, then a unit-weight update**: ``P~ = P(k-1) / lambda_k``,
  ``K = P~ phi / (1 + phi' P~ phi)``; this is algebraically the same gain and covariance
  as the textbook form.
* **Joseph form** of the covariance update,
  ``P(k) = (I - K phi') P~ (I - K phi')' + K K'``, which stays positive semi-definite
  under rounding (the short form ``P~ - K phi' P~`` can lose definiteness when ``P`` is
  badly conditioned), followed by **symmetrisation** ``(P + P') / 2``.
* **Bounded trace against wind-up.** When the input stops exciting the system, plain
  forgetting divides ``P`` by ``lambda`` at every sample in the unexcited directions and
  ``P`` grows without bound (estimator wind-up: a burst of huge gains when excitation
  returns, eventually overflow). Here the forgetting factor of a step is raised just
  enough to keep ``trace(P) <= p_max``: ``lambda_k = min(1, max(lambda, trace(P(k-1)) /
  p_max))`` (default ``p_max = trace(P(0)) / lambda``: ``P`` never grows beyond its
  forgotten prior). While the data excite the system ``trace(P)`` is far below the
  bound and ``lambda_k = lambda`` exactly; the
  fraction of samples where the bound acted is reported
  (:attr:`RlsResult.effective_forgetting`).

Standard deviations
-------------------
With white equation noise of variance ``sigma**2`` and constant parameters, the
estimate at ``k`` is a weighted least-squares estimate with weights ``w_i``
(products of the ``lambda_k``), ``P(k)**-1 = sum w_i phi_i phi_i'`` (plus the prior),
and its covariance is the sandwich ``sigma**2 P M P`` with ``M = sum w_i**2 phi_i
phi_i'`` (``M(k) = lambda_k**2 M(k-1) + phi phi'``). For ``lambda = 1`` this is
``sigma**2 P``; for ``lambda < 1`` in steady state it tends to ``sigma**2 P / (1 +
lambda)`` (about half of ``sigma**2 P``, as MATLAB's recursive estimators note), so
scaling ``P`` alone would overstate the spread by up to ``sqrt(2)``. ``sigma**2`` is
estimated on line from the weighted residual sum of squares
``V(k) = lambda_k V(k-1) + eps**2 / (1 + phi' P~ phi)`` divided by its degrees of
freedom ``sum w_i - trace(P M)`` (``N - n`` for ``lambda = 1``); it is NaN until more
than half a degree of freedom is left. The bands describe the noise-driven spread of
the estimate, not its lag behind a parameter that is moving.

Speed
-----
The per-sample step is one CasADi ``SX`` function; ``mapaccum`` turns it into a loop
over chunks of samples that :func:`workbench._jit.compiled` compiles to C (cached), and
chunks are evaluated through CasADi's zero-copy function buffer directly on the numpy
arrays. Without a C compiler the same function runs on CasADi's virtual machine. A
plain numpy per-sample loop of the same arithmetic (``method="numpy"``) is the baseline
of ``workbench bench rls`` and the independent check of the compiled path.

Examples
--------
>>> import numpy as np
>>> from workbench.identify.rls import rls
>>> rng = np.random.default_rng(0)
>>> u = rng.choice([-1.0, 1.0], 500)
>>> y = np.zeros(500)
>>> for k in range(2, 500):        # y(k) - 1.5 y(k-1) + 0.7 y(k-2) = u(k-1) + 0.5 u(k-2)
...     y[k] = 1.5 * y[k-1] - 0.7 * y[k-2] + u[k-1] + 0.5 * u[k-2]
>>> res = rls(y, u, (2, 2, 1), forgetting=1.0)
>>> res.names
('a1', 'a2', 'b1', 'b2')
>>> np.round(res.theta[-1], 6).tolist()
[-1.5, 0.7, 1.0, 0.5]
"""

from __future__ import annotations

import argparse
import json
import math
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from ..errors import InputError
from ..params import json_safe

if TYPE_CHECKING:  # pragma: no cover
    import casadi
    import pandas

__all__ = ["RlsResult", "ForgettingChoice", "rls", "choose_forgetting", "regressors",
           "parameter_names", "add_cli", "bench", "DEFAULT_CANDIDATES"]

#: Forgetting factors tried by :func:`choose_forgetting` by default.
DEFAULT_CANDIDATES: tuple[float, ...] = (0.9, 0.95, 0.98, 0.99, 0.995, 0.999, 1.0)

_CHUNK = 1000                     # samples per compiled call (mapaccum length)
_P0_RELATIVE = 1e4                # p0="auto": P(0)_ii = 1e4 / mean(phi_i^2)
_METHODS = ("auto", "casadi", "numpy")


# --------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------
def _frozen_array(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=float, copy=True)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class RlsResult:
    """Parameter tracks of a recursive least-squares run (immutable).

    Row ``i`` of every track belongs to sample ``start_index + i`` of the record: the
    first ``start_index = max(na, nk + nb - 1)`` samples only fill the first regressor.

    Attributes
    ----------
    time : ndarray, shape (N,)
        Time of each estimate, s (the sample index when no time base was given).
    theta : ndarray, shape (N, na + nb)
        Estimates after the update at each sample, columns :attr:`names`
        (``a_i`` dimensionless, ``b_i`` in output unit per input unit).
    std : ndarray, shape (N, na + nb)
        Standard deviation of each estimate, same units (NaN while fewer than one
        degree of freedom is left for the noise estimate).
    errors : ndarray, shape (N,)
        A priori (one-step-ahead) prediction errors ``y(k) - phi(k)' theta(k-1)``,
        output unit.
    noise_variance : ndarray, shape (N,)
        Running estimate of the equation-noise variance, output unit squared.
    effective_forgetting : ndarray, shape (N,)
        Forgetting factor actually applied at each sample (larger than
        :attr:`forgetting` only where the trace bound ``p_max`` acted).
    covariance : ndarray, shape (na + nb, na + nb)
        Covariance of the final estimate.
    names : tuple of str
        ``('a1', .., 'a_na', 'b1', .., 'b_nb')``.
    orders : tuple of int
        ``(na, nb, nk)``.
    forgetting : float
        Forgetting factor lambda, -.
    p0 : tuple of float
        Diagonal of the initial covariance ``P(0)``.
    p_max : float
        Bound on ``trace(P)``.
    sample_time : float or None
        Sample time, s.
    start_index : int
        Index in the record of the first estimate.
    method : str
        ``"compiled"`` (C via CasADi), ``"casadi"`` (CasADi virtual machine) or
        ``"numpy"``.
    """

    time: np.ndarray
    theta: np.ndarray
    std: np.ndarray
    errors: np.ndarray
    noise_variance: np.ndarray
    effective_forgetting: np.ndarray
    covariance: np.ndarray
    names: tuple[str, ...]
    orders: tuple[int, int, int]
    forgetting: float
    p0: tuple[float, ...]
    p_max: float
    sample_time: float | None
    start_index: int
    method: str

    def __post_init__(self) -> None:
        for name in ("time", "theta", "std", "errors", "noise_variance",
                     "effective_forgetting", "covariance"):
            object.__setattr__(self, name, _frozen_array(getattr(self, name)))

    def __len__(self) -> int:
        return int(self.time.shape[0])

    # ---- convenient views ------------------------------------------------------------
    @property
    def a(self) -> np.ndarray:
        """Tracks of ``a1 .. a_na``, shape (N, na), -."""
        return self.theta[:, :self.orders[0]]

    @property
    def b(self) -> np.ndarray:
        """Tracks of ``b1 .. b_nb``, shape (N, nb), output unit / input unit."""
        return self.theta[:, self.orders[0]:]

    @property
    def final(self) -> dict[str, float]:
        """Final estimate by parameter name."""
        return {n: float(v) for n, v in zip(self.names, self.theta[-1])}

    @property
    def final_std(self) -> dict[str, float]:
        """Standard deviation of the final estimate by parameter name."""
        return {n: float(v) for n, v in zip(self.names, self.std[-1])}

    @property
    def bound_active_fraction(self) -> float:
        """Fraction of samples where the trace bound raised the forgetting factor, -."""
        return float(np.mean(self.effective_forgetting > self.forgetting * (1 + 1e-12)))

    def prediction_mse(self, burn_in: int = 0) -> float:
        """Mean squared a priori prediction error after ``burn_in`` estimates, output unit^2."""
        e = self.errors[int(burn_in):]
        return float(np.mean(e * e)) if e.size else float("nan")

    # ---- export ------------------------------------------------------------------------
    def to_pandas(self) -> "pandas.DataFrame":
        """Tracks as a DataFrame: ``time``, the parameters, ``std_<name>``, ``error``,
        ``noise_variance``, ``effective_forgetting`` (one row per estimate)."""
        import pandas as pd
        cols: dict[str, np.ndarray] = {"time": self.time}
        for i, n in enumerate(self.names):
            cols[n] = self.theta[:, i]
        for i, n in enumerate(self.names):
            cols[f"std_{n}"] = self.std[:, i]
        cols["error"] = self.errors
        cols["noise_variance"] = self.noise_variance
        cols["effective_forgetting"] = self.effective_forgetting
        return pd.DataFrame(cols)

    def as_dict(self, series: bool = False) -> dict[str, Any]:
        """JSON-ready summary (final estimates, standard deviations, prediction error).

        Parameters
        ----------
        series : bool
            Also include the full tracks (``time``, ``theta``, ``std``) as lists.
        """
        na, nb, nk = self.orders
        out: dict[str, Any] = {
            "orders": {"na": na, "nb": nb, "nk": nk},
            "names": list(self.names),
            "forgetting": self.forgetting,
            "p0": list(self.p0),
            "p_max": self.p_max,
            "sample_time": self.sample_time,
            "estimates": len(self),
            "start_index": self.start_index,
            "final": self.final,
            "final_std": self.final_std,
            "a": [float(v) for v in self.theta[-1, :na]],
            "b": [float(v) for v in self.theta[-1, na:]],
            "std_a": [float(v) for v in self.std[-1, :na]],
            "std_b": [float(v) for v in self.std[-1, na:]],
            "noise_variance": float(self.noise_variance[-1]),
            "prediction_mse": self.prediction_mse(_default_burn_in(len(self), len(self.names))),
            "prediction_mse_burn_in": _default_burn_in(len(self), len(self.names)),
            "bound_active_fraction": self.bound_active_fraction,
            "method": self.method,
        }
        if series:
            out["time"] = self.time.tolist()
            out["theta"] = self.theta.tolist()
            out["std"] = self.std.tolist()
        return json_safe(out)


@dataclass(frozen=True, eq=False)
class ForgettingChoice:
    """Forgetting factor chosen by one-step prediction error (immutable).

    Attributes
    ----------
    forgetting : float
        The candidate with the smallest mean squared a priori prediction error, -.
    candidates : tuple of float
        The forgetting factors tried, -.
    mse : tuple of float
        Mean squared a priori prediction error of each candidate after the burn-in,
        output unit squared.
    burn_in : int
        Estimates left out at the start (where the prior dominates).
    result : RlsResult
        The run with the chosen forgetting factor.
    """

    forgetting: float
    candidates: tuple[float, ...]
    mse: tuple[float, ...]
    burn_in: int
    result: RlsResult = field(repr=False)

    def to_pandas(self) -> "pandas.DataFrame":
        """Table: ``forgetting``, ``mse``, ``rmse``, ``chosen``."""
        import pandas as pd
        mse = np.asarray(self.mse)
        return pd.DataFrame({"forgetting": self.candidates, "mse": mse,
                             "rmse": np.sqrt(mse),
                             "chosen": [c == self.forgetting for c in self.candidates]})

    def as_dict(self) -> dict[str, Any]:
        return json_safe({"forgetting": self.forgetting, "burn_in": self.burn_in,
                           "table": [{"forgetting": c, "mse": m, "rmse": math.sqrt(m)}
                                     for c, m in zip(self.candidates, self.mse)]})


# --------------------------------------------------------------------------------------
# Input checks and regressors
# --------------------------------------------------------------------------------------
def _check_orders(orders: Any) -> tuple[int, int, int]:
    try:
        vals = tuple(orders)
    except TypeError:
        raise InputError(f"orders must be three integers (na, nb, nk), got {orders!r}") from None
    if len(vals) != 3:
        raise InputError(f"orders must be three integers (na, nb, nk), got {orders!r}")
    out = []
    for name, v in zip(("na", "nb", "nk"), vals):
        if isinstance(v, (bool, np.bool_)) or not float(v).is_integer():
            raise InputError(f"order {name} must be a whole number, got {v!r}")
        if int(v) < 0:
            raise InputError(f"order {name} must be >= 0, got {int(v)}")
        out.append(int(v))
    na, nb, nk = out
    if na + nb == 0:
        raise InputError("orders (na, nb, nk) give no parameter: na + nb must be >= 1")
    return na, nb, nk


def parameter_names(orders: Sequence[int]) -> tuple[str, ...]:
    """``('a1', .., 'a_na', 'b1', .., 'b_nb')`` for orders ``(na, nb, nk)``."""
    na, nb, _ = _check_orders(orders)
    return tuple(f"a{i}" for i in range(1, na + 1)) + tuple(f"b{i}" for i in range(1, nb + 1))


def _start_index(orders: tuple[int, int, int]) -> int:
    na, nb, nk = orders
    return max(na, nk + nb - 1 if nb else 0)


def _where(index: int, sample_time: float | None, time: np.ndarray | None) -> str:
    if time is not None:
        return f"sample {index} (t = {time[index]:.6g} s)"
    if sample_time is not None:
        return f"sample {index} (t = {index * sample_time:.6g} s)"
    return f"sample {index}"


def _as_signal(x: Any, what: str, sample_time: float | None = None,
               time: np.ndarray | None = None) -> np.ndarray:
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be an array of numbers") from None
    if arr.ndim == 2 and 1 in arr.shape:
        arr = arr.ravel()
    if arr.ndim != 1:
        raise InputError(f"{what} must be one signal (1-D), got an array of shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        k = int(bad[0])
        kind = "NaN" if np.isnan(arr[k]) else "inf"
        more = f" and {bad.size - 1} more non-finite samples" if bad.size > 1 else ""
        raise InputError(f"{what} is {kind} at {_where(k, sample_time, time)}{more}; "
                         "remove or repair those samples before identification")
    return arr


def _check_forgetting(lam: Any, what: str = "forgetting factor lambda") -> float:
    try:
        val = float(lam)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be a number in (0, 1], got {lam!r}") from None
    if not (0.0 < val <= 1.0):
        raise InputError(f"{what} must be in (0, 1] (0.99 remembers about 100 samples, "
                         f"1 never forgets), got {val:g}")
    return val


def _min_samples(orders: tuple[int, int, int]) -> int:
    """Shortest record: fill the first regressor, then two samples per parameter."""
    return _start_index(orders) + 2 * (orders[0] + orders[1]) + 1


def _prepare(y: Any, u: Any, orders: Any, sample_time: float | None,
             time: Any) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int],
                                  float | None, np.ndarray | None]:
    orders = _check_orders(orders)
    if sample_time is not None:
        try:
            sample_time = float(sample_time)
        except (TypeError, ValueError):
            raise InputError(f"sample_time must be a number of seconds, got {sample_time!r}") from None
        if not (math.isfinite(sample_time) and sample_time > 0):
            raise InputError(f"sample_time must be a positive number of seconds, got {sample_time:g}")
    tarr = None
    if time is not None:
        tarr = _as_signal(time, "time t")
    yarr = _as_signal(y, "output y", sample_time, tarr)
    na, nb, nk = orders
    if u is None:
        if nb > 0:
            raise InputError(f"orders give nb = {nb} input parameters but no input u was given")
        uarr = np.zeros_like(yarr)
    else:
        uarr = _as_signal(u, "input u", sample_time, tarr)
    if uarr.shape != yarr.shape:
        raise InputError(f"input u has {uarr.size} samples but output y has {yarr.size}; "
                         "they must be sampled together")
    if tarr is not None and tarr.shape != yarr.shape:
        raise InputError(f"time t has {tarr.size} samples but output y has {yarr.size}")
    need = _min_samples(orders)
    if yarr.size < need:
        raise InputError(f"record too short for orders (na, nb, nk) = {orders}: {yarr.size} "
                         f"samples, RLS needs at least {need} ({_start_index(orders)} to fill "
                         f"the first regressor, then 2 per parameter)")
    if nb > 0:
        span = float(np.ptp(uarr))
        if span <= 1e-12 * max(1.0, float(np.max(np.abs(uarr)))):
            raise InputError(f"input u is constant ({uarr[0]:g}) over the whole record: it does "
                             "not excite the system, so the b parameters cannot be estimated; "
                             "record with a PRBS or APRBS input")
    return yarr, uarr, orders, sample_time, tarr


def regressors(y: Any, u: Any, orders: Sequence[int]) -> tuple[np.ndarray, np.ndarray, int]:
    """ARX regressors in MATLAB ``arx`` convention.

    Parameters
    ----------
    y : array_like, shape (n,)
        Output, any unit.
    u : array_like, shape (n,)
        Input, any unit.
    orders : (na, nb, nk)
        Numbers of ``a`` and ``b`` parameters and the input delay, samples.

    Returns
    -------
    phi : ndarray, shape (n - k0, na + nb)
        Row ``i`` is ``[-y(k-1) .. -y(k-na), u(k-nk) .. u(k-nk-nb+1)]`` for ``k = k0 + i``.
    target : ndarray, shape (n - k0,)
        ``y(k)``.
    k0 : int
        First sample with a full regressor, ``max(na, nk + nb - 1)``.
    """
    na, nb, nk = _check_orders(orders)
    y = np.asarray(y, dtype=float)
    u = np.asarray(u, dtype=float)
    k0 = _start_index((na, nb, nk))
    n = y.size
    cols = [-y[k0 - i:n - i] for i in range(1, na + 1)]
    cols += [u[k0 - nk - j:n - nk - j] for j in range(nb)]
    return np.column_stack(cols), y[k0:].copy(), k0


def _default_burn_in(n_estimates: int, npar: int) -> int:
    return int(min(max(10 * npar, n_estimates // 10), max(n_estimates - 1, 0)))


# --------------------------------------------------------------------------------------
# The recursion: packed state [theta, triu(P), triu(M), V, N_eff]
# --------------------------------------------------------------------------------------
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


def _chunk_function(n: int) -> tuple["casadi.Function", str]:
    """``_CHUNK`` steps as one function, compiled to C when possible (cached)."""
    if n in _CHUNK_FUNCTIONS:
        return _CHUNK_FUNCTIONS[n]
    import casadi as ca
    from .. import _jit
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
    fun, kind = _chunk_function(n)
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


# --------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------
def rls(y: Any, u: Any, orders: Sequence[int], forgetting: float = 0.99,
        theta0: Any = None, p0: Any = 1e4, sample_time: float | None = None, *,
        time: Any = None, p_max: float | None = None, method: str = "auto",
        progress: bool = False) -> RlsResult:
    """Track time-varying ARX parameters by recursive least squares with forgetting.

    Parameters
    ----------
    y : array_like, shape (n,)
        Output samples (e.g. position x, m), equally spaced.
    u : array_like, shape (n,) or None
        Input samples (e.g. valve command u, V). ``None`` only when ``nb = 0``.
    orders : (na, nb, nk)
        MATLAB ``arx`` orders: number of ``a`` and ``b`` parameters and the input delay
        in samples (paper 002's model is ``(2, 2, 1)``).
    forgetting : float
        Forgetting factor lambda in (0, 1], -. Memory about ``1 / (1 - lambda)``
        samples; 1 = ordinary (growing-window) least squares.
    theta0 : array_like, shape (na + nb,), optional
        Initial estimate (default zeros), units of the parameters.
    p0 : float, array_like of shape (na + nb,), or "auto"
        Initial covariance ``P(0) = p0 I`` (or ``diag(p0)``), parameter unit squared per
        output unit squared (MATLAB's default is 1e4). Large = weak prior: the prior
        pulls the estimate towards ``theta0`` by a term of order ``1 / (p0 sum
        phi**2)``, which forgetting removes over time but ``lambda = 1`` keeps; with
        small signals in SI units (positions of a few mm in m) 1e4 is *not* weak.
        ``"auto"``: ``P(0) = diag(1e4 / mean(phi_i**2))`` from the record's regressor
        power, the same relative weak prior whatever the units (the estimates then
        scale exactly with the signals).
    sample_time : float, optional
        Sample time, s; the estimates are then timed ``k * sample_time``.
    time : array_like, shape (n,), optional
        Sample instants, s (e.g. a recording's ``t``); overrides ``sample_time`` for
        the time axis.
    p_max : float, optional
        Bound on ``trace(P)`` against wind-up (module notes); default
        ``trace(P(0)) / forgetting``; ``numpy.inf`` switches it off.
    method : {"auto", "casadi", "numpy"}
        ``"auto"``/``"casadi"``: the CasADi loop (C when a compiler is present);
        ``"numpy"``: the plain per-sample numpy loop (slow; reference).
    progress : bool
        Show a progress bar (CasADi loop only; costs nothing measurable).

    Returns
    -------
    RlsResult

    Raises
    ------
    InputError
        Bad orders, lambda outside (0, 1], NaN/inf samples (the first one is named),
        ``y`` and ``u`` of different lengths, a record too short for the orders, a
        constant input, bad ``theta0``, ``p0`` or ``p_max``.

    Examples
    --------
    >>> import numpy as np
    >>> from workbench.identify.rls import rls
    >>> rng = np.random.default_rng(1)
    >>> u = rng.choice([0.0, 1.0], 300)
    >>> y = np.zeros(300)
    >>> for k in range(1, 300):            # y(k) - 0.9 y(k-1) = 0.2 u(k-1)
    ...     y[k] = 0.9 * y[k-1] + 0.2 * u[k-1]
    >>> res = rls(y, u, (1, 1, 1), forgetting=0.99, sample_time=0.01)
    >>> [round(v, 6) for v in res.final.values()], float(res.time[-1])
    ([-0.9, 0.2], 2.99)
    """
    yarr, uarr, orders, sample_time, tarr = _prepare(y, u, orders, sample_time, time)
    lam = _check_forgetting(forgetting)
    if method not in _METHODS:
        raise InputError(f"method must be one of {', '.join(_METHODS)}, got {method!r}")
    na, nb, _ = orders
    npar = na + nb
    names = parameter_names(orders)

    if theta0 is None:
        th0 = np.zeros(npar)
    else:
        th0 = np.asarray(theta0, dtype=float).ravel()
        if th0.size != npar or not np.all(np.isfinite(th0)):
            raise InputError(f"theta0 must hold {npar} finite numbers ({', '.join(names)}), "
                             f"got {np.asarray(theta0).tolist()}")
    phi, target, k0 = regressors(yarr, uarr, orders)
    if isinstance(p0, str):
        if p0 != "auto":
            raise InputError(f"p0 must be a positive number or 'auto', got '{p0}'")
        power = np.mean(phi * phi, axis=0)
        p0_arr = np.where(power > 0, _P0_RELATIVE / np.where(power > 0, power, 1.0),
                          _P0_RELATIVE)
    else:
        try:
            p0_arr = np.asarray(p0, dtype=float).ravel()
        except (TypeError, ValueError):
            raise InputError(f"p0 must be a positive number or 'auto', got {p0!r}") from None
    if p0_arr.size == 1:
        p0_arr = np.full(npar, float(p0_arr[0]))
    if p0_arr.size != npar or not np.all(np.isfinite(p0_arr)) or np.any(p0_arr <= 0):
        raise InputError(f"p0 (initial covariance) must be a positive finite number or {npar} "
                         f"of them, got {np.asarray(p0).tolist()}")
    p0_arr = np.array(p0_arr, dtype=float)
    if p_max is None:
        pm = float(np.sum(p0_arr)) / lam
    else:
        try:
            pm = float(p_max)
        except (TypeError, ValueError):
            raise InputError(f"p_max must be a positive number, got {p_max!r}") from None
        if not pm > 0:
            raise InputError(f"p_max (bound on trace P) must be > 0, got {pm:g}")

    x0 = _pack(th0, np.diag(p0_arr), np.zeros((npar, npar)), 0.0, 0.0)
    if method == "numpy":
        out, xf = _run_numpy(phi, target, x0, lam, pm)
        kind = "numpy"
    else:
        out, xf, kind = _run_casadi(phi, target, x0, lam, pm, progress=progress)

    if tarr is not None:
        tt = tarr[k0:]
        if sample_time is None:
            sample_time = float(np.median(np.diff(tarr)))
    elif sample_time is not None:
        tt = np.arange(k0, yarr.size) * sample_time
    else:
        tt = np.arange(k0, yarr.size, dtype=float)
    n = npar
    return RlsResult(time=tt, theta=out[:, :n], std=out[:, n:2 * n], errors=out[:, 2 * n],
                     effective_forgetting=out[:, 2 * n + 1], noise_variance=out[:, 2 * n + 2],
                     covariance=_final_covariance(xf, n), names=names, orders=orders,
                     forgetting=lam, p0=tuple(float(v) for v in p0_arr), p_max=pm, sample_time=sample_time,
                     start_index=k0, method=kind)


def choose_forgetting(y: Any, u: Any, orders: Sequence[int],
                      candidates: Sequence[float] = DEFAULT_CANDIDATES, *,
                      burn_in: int | None = None, **kwargs: Any) -> ForgettingChoice:
    """Choose lambda by the mean squared one-step (a priori) prediction error.

    Each candidate runs :func:`rls` over the whole record; the errors
    ``y(k) - phi(k)' theta(k-1)`` use only data before ``k``, so a small lambda is not
    rewarded for fitting noise: too small a lambda makes the estimate noisy, too large
    a one lags behind changing parameters, and both raise the prediction error.

    Parameters
    ----------
    y, u, orders
        As for :func:`rls`.
    candidates : sequence of float
        Forgetting factors to try, each in (0, 1].
    burn_in : int, optional
        Estimates left out at the start, where the prior still dominates; default
        ``max(10 (na + nb), N / 10)``.
    **kwargs
        Passed to :func:`rls` (``theta0``, ``p0``, ``sample_time``, ``time``, ...).

    Returns
    -------
    ForgettingChoice
        ``forgetting`` (the best), the table of candidates and errors, and the run
        with the best lambda. Ties go to the larger lambda (less noise).

    Raises
    ------
    InputError
        As :func:`rls`, plus an empty candidate list or a burn-in that leaves fewer
        than 10 estimates.
    """
    try:
        cands = tuple(float(c) for c in candidates)
    except (TypeError, ValueError):
        raise InputError(f"candidates must be numbers in (0, 1], got {candidates!r}") from None
    if not cands:
        raise InputError("no candidate forgetting factors given")
    for c in cands:
        _check_forgetting(c, "candidate forgetting factor")
    yarr, uarr, ords, _, _ = _prepare(y, u, orders, kwargs.get("sample_time"),
                                      kwargs.get("time"))
    n_est = yarr.size - _start_index(ords)
    npar = ords[0] + ords[1]
    if burn_in is None:
        burn_in = _default_burn_in(n_est, npar)
    burn_in = int(burn_in)
    if burn_in < 0 or n_est - burn_in < 10:
        raise InputError(f"burn-in of {burn_in} estimates leaves {n_est - burn_in} of {n_est} "
                         "for the prediction error; need at least 10")
    results = [rls(yarr, uarr, ords, forgetting=c, **kwargs) for c in cands]
    mse = tuple(r.prediction_mse(burn_in) for r in results)
    order = sorted(range(len(cands)), key=lambda i: (mse[i], -cands[i]))
    best = order[0]
    return ForgettingChoice(forgetting=cands[best], candidates=cands, mse=mse,
                            burn_in=burn_in, result=results[best])


# --------------------------------------------------------------------------------------
# Command line: workbench identify rls
# --------------------------------------------------------------------------------------
def add_cli(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``workbench identify rls`` to the ``identify`` sub-parsers."""
    p = subparsers.add_parser(
        "rls", help="recursive least squares with forgetting: time-varying ARX tracks",
        description="Track the parameters of a time-varying ARX model y(k) + a1 y(k-1) + ... "
                    "= b1 u(k-nk) + ... + e(k) (MATLAB arx orders na nb nk) through a "
                    "recording by recursive least squares with forgetting factor lambda "
                    "(paper 002). Writes DIR/estimates.csv (columns t,a1..a_na,b1..b_nb: the "
                    "estimate after each sample), DIR/rls.png (tracks with +-2 std bands), "
                    "DIR/summary.json and DIR/report.md (final estimates with standard "
                    "deviations, lambda, one-step prediction error).",
        epilog="Units are SI (m, Pa absolute, kg, s, V). Example: workbench identify rls "
               "run.csv --input u --output x --orders 2 2 1 --forgetting 0.99 --out rls/")
    p.add_argument("recording", metavar="RECORDING", help="recording (.csv or .mat)")
    p.add_argument("--input", default="u", metavar="COLUMN", help="input column (default u)")
    p.add_argument("--output", default="x", metavar="COLUMN", help="output column (default x)")
    p.add_argument("--orders", nargs=3, type=int, default=[2, 2, 1], metavar=("NA", "NB", "NK"),
                   help="ARX orders na nb nk, MATLAB convention (default 2 2 1)")
    p.add_argument("--forgetting", default="0.99", metavar="LAMBDA",
                   help="forgetting factor in (0, 1], or 'auto' to choose it by one-step "
                        "prediction error among " + ", ".join(f"{c:g}" for c in DEFAULT_CANDIDATES)
                        + " (default 0.99)")
    p.add_argument("--p0", default="auto", metavar="P0",
                   help="initial covariance P(0) = p0 I, or 'auto' (default): "
                        "P(0) = diag(1e4 / mean(phi_i^2)), a weak prior whatever the units")
    p.add_argument("--detrend", choices=("none", "mean"), default="none",
                   help="'mean': subtract the record mean of input and output first (ARX has "
                        "no constant term, so offsets such as a 5 V valve centre or a 0.25 m "
                        "mid-stroke position bias the estimates); default none")
    p.add_argument("--burn-in", type=int, default=None, metavar="N",
                   help="estimates left out of the prediction error (default max(10 (na+nb), N/10))")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if needed)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--no-plot", action="store_true", help="do not write rls.png")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_rls)
    return p


def _parse_forgetting(text: str) -> float | None:
    if str(text).strip().lower() == "auto":
        return None
    try:
        val = float(text)
    except ValueError:
        raise InputError(f"--forgetting must be a number in (0, 1] or 'auto', got '{text}'") from None
    return _check_forgetting(val, "--forgetting")


def _cmd_rls(args: argparse.Namespace) -> int:
    from ..params import atomic_write_text
    from ..recording import UNITS, load_recording
    rec = load_recording(args.recording)
    for opt, col in (("--input", args.input), ("--output", args.output)):
        if col not in rec.columns:
            raise InputError(f"{opt} {col}: the recording has no column '{col}'; its columns "
                             f"are {', '.join(rec.columns)}", source=str(args.recording))
    lam = _parse_forgetting(args.forgetting)
    p0: Any = "auto"
    if str(args.p0).strip().lower() != "auto":
        try:
            p0 = float(args.p0)
        except ValueError:
            raise InputError(f"--p0 must be a positive number or 'auto', got '{args.p0}'") from None
    y, u = rec[args.output], rec[args.input]
    if args.detrend == "mean":
        y, u = y - np.mean(y), u - np.mean(u)
    progress = (not args.quiet) and y.size >= 500_000
    common = dict(time=rec.t, sample_time=rec.sample_time, p0=p0, progress=progress)
    try:
        if lam is None:
            choice = choose_forgetting(y, u, args.orders, burn_in=args.burn_in, **common)
            res = choice.result
        else:
            choice = None
            res = rls(y, u, args.orders, forgetting=lam, **common)
    except InputError as exc:
        raise InputError(str(exc).replace("output y", f"output '{args.output}'")
                         .replace("input u", f"input '{args.input}'"),
                         source=str(args.recording)) from None
    n_est = len(res)
    burn = args.burn_in if args.burn_in is not None else _default_burn_in(n_est, len(res.names))
    burn = min(max(int(burn), 0), n_est - 1)
    mse = res.prediction_mse(burn)

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    # estimates.csv: exactly t, a1.., b1..
    table = np.column_stack([res.time, res.theta])
    import io
    buf = io.StringIO()
    buf.write(",".join(("t",) + res.names) + "\n")
    np.savetxt(buf, table, delimiter=",", fmt="%.12g")
    atomic_write_text(out / "estimates.csv", buf.getvalue())

    y_unit = UNITS.get(args.output, "")
    u_unit = UNITS.get(args.input, "")
    summary = {
        "recording": str(args.recording), "input": args.input, "output": args.output,
        "detrend": args.detrend,
        "units": {"output": y_unit, "input": u_unit},
        **res.as_dict(),
        "prediction_mse": mse, "prediction_rmse": math.sqrt(mse), "prediction_mse_burn_in": burn,
        "forgetting_choice": None if choice is None else choice.as_dict(),
        "files": {"estimates": str(out / "estimates.csv"), "report": str(out / "report.md"),
                  "summary": str(out / "summary.json")},
    }
    if not args.no_plot:
        from .plots import rls_figure
        rls_figure(res, path=out / "rls.png", output_unit=y_unit or None,
                   input_unit=u_unit or None,
                   title=f"RLS: {args.output} from {args.input}, orders {tuple(res.orders)}, "
                         f"lambda = {res.forgetting:g}")
        summary["files"]["plot"] = str(out / "rls.png")
    summary = json_safe(summary)
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    atomic_write_text(out / "report.md", _report_md(res, summary, choice, y_unit, u_unit))
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f"RLS on {args.recording}: {args.output} from {args.input}, orders "
          f"{tuple(res.orders)}, lambda = {res.forgetting:g}"
          + (" (chosen by prediction error)" if choice is not None else ""))
    for name in res.names:
        print(f"  {name} = {res.final[name]: .6g}  +- {res.final_std[name]:.2g} (1 std)")
    print(f"  one-step prediction error RMS {math.sqrt(mse):.4g} {y_unit} "
          f"(after {burn} estimates)")
    print(f"  wrote {out / 'estimates.csv'}, {out / 'report.md'}, {out / 'summary.json'}"
          + ("" if args.no_plot else f", {out / 'rls.png'}"))
    return 0


def _report_md(res: RlsResult, summary: dict, choice: ForgettingChoice | None,
               y_unit: str, u_unit: str) -> str:
    na, nb, nk = res.orders
    b_unit = f"{y_unit or '-'}/{u_unit or '-'}"
    lines = [
        "# Recursive least squares",
        "",
        f"- recording: `{summary['recording']}`; output `{summary['output']}` "
        f"({y_unit or '-'}), input `{summary['input']}` ({u_unit or '-'})",
        f"- model: ARX orders na = {na}, nb = {nb}, nk = {nk} (MATLAB `arx` convention)"
        + ("; input and output minus their record means" if summary.get("detrend") == "mean"
           else ""),
        f"- forgetting factor lambda = {res.forgetting:g}"
        + (" (chosen by one-step prediction error)" if choice is not None else ""),
        f"- {len(res)} estimates from t = {res.time[0]:.6g} s to {res.time[-1]:.6g} s; "
        f"P(0) = diag({', '.join(f'{v:.3g}' for v in res.p0)}), trace bound {res.p_max:.3g} "
        f"(active on {100 * res.bound_active_fraction:.2f} % of samples)",
        f"- one-step (a priori) prediction error: RMS {summary['prediction_rmse']:.4g} "
        f"{y_unit} after {summary['prediction_mse_burn_in']} estimates; noise std estimate "
        f"{math.sqrt(res.noise_variance[-1]) if np.isfinite(res.noise_variance[-1]) else float('nan'):.4g} "
        f"{y_unit}",
        "",
        "## Final estimates",
        "",
        "| parameter | estimate | std | unit |",
        "|---|---:|---:|---|",
    ]
    for i, name in enumerate(res.names):
        unit = "-" if i < na else b_unit
        lines.append(f"| {name} | {res.theta[-1, i]:.6g} | {res.std[-1, i]:.3g} | {unit} |")
    if choice is not None:
        lines += ["", "## Forgetting factor by prediction error", "",
                  f"Mean squared a priori error after {choice.burn_in} estimates:", "",
                  "| lambda | MSE | RMS |", "|---:|---:|---:|"]
        for c, m in zip(choice.candidates, choice.mse):
            mark = " (chosen)" if c == choice.forgetting else ""
            lines.append(f"| {c:g}{mark} | {m:.4g} | {math.sqrt(m):.4g} |")
    lines += ["", "Standard deviations are the noise-driven spread of the estimate "
              "(sigma^2 P M P with sigma^2 estimated on line); they do not include the lag "
              "behind parameters that change.", ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------
# Benchmark: workbench bench rls
# --------------------------------------------------------------------------------------
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
    _chunk_function(4)
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
