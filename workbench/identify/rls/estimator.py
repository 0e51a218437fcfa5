"""The RLS estimator: checks, regressors, :class:`RlsResult` and :func:`rls`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from ...errors import InputError
from ...params import json_safe
from .ckernel import c_kernel, run_c
from .kernels import _final_covariance, _pack, _run_casadi, _run_numpy

if TYPE_CHECKING:  # pragma: no cover
    import pandas

__all__ = ["RlsResult", "rls", "regressors", "parameter_names"]

_P0_RELATIVE = 1e4                # p0="auto": P(0)_ii = 1e4 / mean(phi_i^2)
_METHODS = ("auto", "c", "casadi", "numpy")


def _frozen_array(a: Any) -> np.ndarray:
    if (isinstance(a, np.ndarray) and a.dtype == np.float64 and a.base is None
            and not a.flags.writeable):
        return a            # already frozen and owning its data (rls's fresh outputs)
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
        ``"c"`` (the plain C loop, :mod:`.ckernel`), ``"compiled"`` (CasADi's
        loop compiled to C), ``"casadi"`` (CasADi virtual machine) or ``"numpy"``.
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
        """Mean squared a priori prediction error after ``burn_in`` estimates, output unit^2.

        Raises
        ------
        InputError
            Unless ``burn_in`` is a whole number from 0 to the number of estimates - 1
            (a negative one would count from the end, a larger one leave nothing).
        """
        n = int(self.errors.size)
        if (isinstance(burn_in, bool) or not isinstance(burn_in, (int, np.integer, float))
                or not float(burn_in).is_integer() or not 0 <= burn_in <= n - 1):
            raise InputError(f"burn-in must be a whole number of estimates from 0 to {n - 1}, "
                             f"got {burn_in!r}")
        e = self.errors[int(burn_in):]
        return float(np.mean(e * e))

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

    def to_dict(self, series: bool = False) -> dict[str, Any]:
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
            "prediction_mse": self.prediction_mse(default_burn_in(len(self), len(self.names))),
            "prediction_mse_burn_in": default_burn_in(len(self), len(self.names)),
            "bound_active_fraction": self.bound_active_fraction,
            "method": self.method,
        }
        if series:
            out["time"] = self.time.tolist()
            out["theta"] = self.theta.tolist()
            out["std"] = self.std.tolist()
        return json_safe(out)


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


def min_forgetting(npar: int) -> float:
    """Smallest forgetting factor whose memory ``1 / (1 - lambda)`` (samples) is at least
    the number of parameters ``npar``: ``1 - 1 / npar``."""
    return 1.0 - 1.0 / max(int(npar), 1)


def check_forgetting(lam: Any, what: str = "forgetting factor lambda") -> float:
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
    phi = np.empty((n - k0, na + nb))
    for i in range(1, na + 1):
        np.negative(y[k0 - i:n - i], out=phi[:, i - 1])
    for j in range(nb):
        phi[:, na + j] = u[k0 - nk - j:n - nk - j]
    return phi, y[k0:].copy(), k0


def default_burn_in(n_estimates: int, npar: int) -> int:
    return int(min(max(10 * npar, n_estimates // 10), max(n_estimates - 1, 0)))


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
    method : {"auto", "c", "casadi", "numpy"}
        ``"c"``: the plain C loop (:mod:`.ckernel`; needs a C compiler, built once per
        number of parameters and cached); ``"casadi"``: the CasADi loop (C when a
        compiler is present; refused above 16 parameters, whose symbolic step takes
        minutes to compile); ``"numpy"``: the plain per-sample numpy loop (reference);
        ``"auto"``: the C loop when a compiler is present, else the CasADi virtual
        machine up to 8 parameters and beyond that whichever the cost model says is
        faster for the record length.
    progress : bool
        Show a progress bar (C and CasADi loops; costs nothing measurable).

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
    lam = check_forgetting(forgetting)
    lowest = min_forgetting(orders[0] + orders[1])
    if lam < lowest:
        raise InputError(
            f"forgetting factor {lam:g} remembers about {1.0 / (1.0 - lam):.3g} samples, "
            f"fewer than the {orders[0] + orders[1]} parameters: the estimate is not "
            f"determined by the data (and P / lambda overflows for tiny lambda); use "
            f"lambda >= 1 - 1/{orders[0] + orders[1]} = {lowest:.4g}")
    if method not in _METHODS:
        raise InputError(f"method must be one of {', '.join(_METHODS)}, got {method!r}")
    na, nb, _ = orders
    npar = na + nb
    names = parameter_names(orders)
    th0 = _initial_estimate(theta0, names)
    k0 = _start_index(orders)
    p0_arr = _initial_covariance(p0, yarr, uarr, orders)
    pm = _trace_bound(p_max, p0_arr, lam)
    x0 = _pack(th0, np.diag(p0_arr), np.zeros((npar, npar)), 0.0, 0.0)
    tracks, xf, kind = _run(_choose_method(method, npar, yarr.size - k0), yarr, uarr,
                            orders, x0, lam, pm, progress)
    tt, sample_time = _time_axis(tarr, sample_time, k0, yarr.size)
    return RlsResult(time=tt, **tracks, covariance=_final_covariance(xf, npar), names=names,
                     orders=orders, forgetting=lam, p0=tuple(float(v) for v in p0_arr),
                     p_max=pm, sample_time=sample_time, start_index=k0, method=kind)


def _run(method: str, y: np.ndarray, u: np.ndarray, orders: tuple[int, int, int],
         x0: np.ndarray, lam: float, pm: float,
         progress: bool) -> tuple[dict[str, np.ndarray], np.ndarray, str]:
    """The tracks (fresh read-only arrays by name), the final packed state and the kind
    of loop that ran."""
    n = orders[0] + orders[1]
    if method == "c":
        tracks, xf = run_c(c_kernel(n), y, u, orders, _start_index(orders), x0, lam, pm,
                           progress=progress)
        kind = "c"
    else:
        phi, target, _ = regressors(y, u, orders)
        if method == "numpy":
            out, xf = _run_numpy(phi, target, x0, lam, pm)
            kind = "numpy"
        else:
            out, xf, kind = _run_casadi(phi, target, x0, lam, pm, progress=progress)
        tracks = {"theta": out[:, :n], "std": out[:, n:2 * n], "errors": out[:, 2 * n],
                  "effective_forgetting": out[:, 2 * n + 1],
                  "noise_variance": out[:, 2 * n + 2]}
        tracks = {k: np.ascontiguousarray(v) for k, v in tracks.items()}
    for v in tracks.values():
        v.flags.writeable = False
    return tracks, xf, kind


#: Cost model of the two loops (measured: 2 cores, gcc -O2): the numpy loop takes about
#: 1.5e-4 s per sample for up to 40 parameters; building and compiling the CasADi step
#: takes about 2 s at 8 parameters and grows as npar**3 (its symbolic covariance update
#: is n x n x n products: 6.9 s at 12 parameters, minutes at 40).
_NUMPY_SECONDS_PER_SAMPLE = 1.5e-4
_COMPILE_SECONDS_AT_8 = 2.0
#: Above this many parameters ``method="casadi"`` is refused (compiling would take
#: minutes; the numpy loop is then the faster way at any record length of minutes).
_CASADI_MAX_PARAMETERS = 16


def _choose_method(method: str, npar: int, nsamples: int) -> str:
    """``"c"``, ``"numpy"`` or ``"casadi"``: ``"auto"`` takes the C loop when it can be
    built; without a compiler it keeps CasADi's loop up to 8 parameters and beyond that
    whichever the cost model says is faster for this record."""
    if method in ("auto", "c") and c_kernel(npar) is not None:
        return "c"
    if method == "c":
        from .ckernel import MAX_PARAMETERS
        why = (f"takes at most {MAX_PARAMETERS} parameters, not {npar}"
               if npar > MAX_PARAMETERS else "needs a C compiler (none found: set CC)")
        raise InputError(f"method='c' {why}; use method='auto', 'casadi' or 'numpy'")
    compile_s = _COMPILE_SECONDS_AT_8 * (npar / 8.0) ** 3
    if method == "casadi" and npar > _CASADI_MAX_PARAMETERS:
        raise InputError(f"method='casadi' with {npar} parameters would spend about "
                         f"{compile_s:.0f} s building and compiling the symbolic step "
                         "(its cost grows as the cube of the parameters); use "
                         "method='auto' or 'numpy'")
    if method != "auto":
        return method
    from .kernels import _CHUNK_FUNCTIONS
    if npar <= 8 or npar in _CHUNK_FUNCTIONS:
        return "casadi"
    return "numpy" if nsamples * _NUMPY_SECONDS_PER_SAMPLE < compile_s else "casadi"


def _initial_estimate(theta0: Any, names: tuple[str, ...]) -> np.ndarray:
    """theta(0): zeros by default, else the checked ``theta0``."""
    npar = len(names)
    if theta0 is None:
        return np.zeros(npar)
    th0 = np.asarray(theta0, dtype=float).ravel()
    if th0.size != npar or not np.all(np.isfinite(th0)):
        raise InputError(f"theta0 must hold {npar} finite numbers ({', '.join(names)}), "
                         f"got {np.asarray(theta0).tolist()}")
    return th0


def _initial_covariance(p0: Any, y: np.ndarray, u: np.ndarray,
                        orders: tuple[int, int, int]) -> np.ndarray:
    """The diagonal of P(0): ``p0`` (one number or ``npar``) or "auto" from the regressor
    power (of :func:`regressors` on ``y``, ``u``)."""
    npar = orders[0] + orders[1]
    if isinstance(p0, str):
        if p0 != "auto":
            raise InputError(f"p0 must be a positive number or 'auto', got '{p0}'")
        phi = regressors(y, u, orders)[0]
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
    return np.array(p0_arr, dtype=float)


def _trace_bound(p_max: Any, p0_arr: np.ndarray, lam: float) -> float:
    """The bound on trace(P): ``p_max``, by default trace(P(0)) / lambda."""
    if p_max is None:
        return float(np.sum(p0_arr)) / lam
    try:
        pm = float(p_max)
    except (TypeError, ValueError):
        raise InputError(f"p_max must be a positive number, got {p_max!r}") from None
    if not pm > 0:
        raise InputError(f"p_max (bound on trace P) must be > 0, got {pm:g}")
    return pm


def _time_axis(tarr: np.ndarray | None, sample_time: float | None, k0: int,
               n: int) -> tuple[np.ndarray, float | None]:
    """Instants of the estimates (s, or sample numbers) and the sample time (s or None)."""
    if tarr is not None:
        tt = tarr[k0:]
        if sample_time is None:
            sample_time = float(np.median(np.diff(tarr)))
    elif sample_time is not None:
        tt = np.arange(k0, n, dtype=float)
        tt *= sample_time
    else:
        tt = np.arange(k0, n, dtype=float)
    return tt, sample_time
