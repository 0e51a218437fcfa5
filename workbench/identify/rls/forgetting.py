"""Choice of the forgetting factor by one-step prediction error (:func:`choose_forgetting`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from ...errors import InputError
from ...params import json_safe
from .estimator import (RlsResult, _prepare, _start_index, check_forgetting, default_burn_in,
                        min_forgetting, rls)

if TYPE_CHECKING:  # pragma: no cover
    import pandas

__all__ = ["DEFAULT_CANDIDATES", "ForgettingChoice", "choose_forgetting"]

#: Forgetting factors tried by :func:`choose_forgetting` by default.
DEFAULT_CANDIDATES: tuple[float, ...] = (0.9, 0.95, 0.98, 0.99, 0.995, 0.999, 1.0)


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

    def to_dict(self) -> dict[str, Any]:
        return json_safe({"forgetting": self.forgetting, "burn_in": self.burn_in,
                           "table": [{"forgetting": c, "mse": m, "rmse": math.sqrt(m)}
                                     for c, m in zip(self.candidates, self.mse)]})


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
        Forgetting factors to try, each in (0, 1] and at least ``1 - 1/(na + nb)``
        (a memory of as many samples as parameters); of the defaults, those below are
        left out.
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
        check_forgetting(c, "candidate forgetting factor")
    yarr, uarr, ords, _, _ = _prepare(y, u, orders, kwargs.get("sample_time"),
                                      kwargs.get("time"))
    n_est = yarr.size - _start_index(ords)
    npar = ords[0] + ords[1]
    if tuple(candidates) == DEFAULT_CANDIDATES:   # the defaults that suit these orders
        cands = tuple(c for c in cands if c >= min_forgetting(npar))
    if burn_in is None:
        burn_in = default_burn_in(n_est, npar)
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
