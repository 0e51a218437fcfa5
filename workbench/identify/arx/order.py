"""ARX order selection by loss, AIC, BIC, FPE or validation fit (:func:`select_order`)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from ...errors import InputError
from .checks import (_check_excitation, _data, _fit_percent, _max_lag, _orders, _range,
                     _sample_time)
from .checks import finite_or_none as _num
from .model import ArxModel, _fit

__all__ = ["CRITERIA", "OrderCandidate", "OrderSelection", "select_order"]

#: Order selection criteria of :func:`select_order`.
CRITERIA = ("aic", "bic", "fpe", "loss", "fit")


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

    def to_dict(self) -> dict[str, Any]:
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

    def to_dict(self) -> dict[str, Any]:
        return {"criterion": self.criterion,
                "best": {"na": self.best.na, "nb": self.best.nb, "nk": self.best.nk},
                "candidates": [c.to_dict() for c in self.candidates]}

    def to_pandas(self):
        """The candidates as a :class:`pandas.DataFrame`, one row each."""
        import pandas as pd
        return pd.DataFrame([c.to_dict() for c in self.candidates])


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
    yv, uv = _validation_data(validation)
    start = max(_max_lag(*o) for o in grid)
    candidates = [_candidate(yy, uu, orders, start, ts, offset, yv, uv) for orders in grid]
    best = min(candidates, key=lambda c: _score(c, criterion))
    model = _fit(yy, uu, *best.orders, _max_lag(*best.orders), ts, offset)
    return OrderSelection(tuple(candidates), criterion, best, model)


def _validation_data(validation) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The checked pair (y_v, u_v) of held-out data, or (None, None)."""
    if validation is None:
        return None, None
    try:
        yv_raw, uv_raw = validation
    except (TypeError, ValueError):
        raise InputError("validation must be a pair (y_v, u_v)") from None
    return _data(yv_raw, uv_raw, "select_order (validation data)")


def _candidate(yy: np.ndarray, uu: np.ndarray, orders: tuple[int, int, int], start: int,
               ts: float | None, offset: bool, yv: np.ndarray | None,
               uv: np.ndarray | None) -> OrderCandidate:
    """Fit one order on the common equations from ``start``; score it on validation data."""
    na, nb, nk = orders
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
    return OrderCandidate(na, nb, nk, na + nb + offset, m.loss, m.aic, m.bic, m.fpe,
                          v_loss, v_fit)


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
