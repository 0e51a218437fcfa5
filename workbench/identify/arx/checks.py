"""Input checks and small JSON conversions shared by the ARX modules and their CLI."""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from ...errors import InputError


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


def finite_or_none(x: Any) -> float | None:
    """``float(x)``, or None when it is NaN or infinite (JSON has neither)."""
    x = float(x)
    return x if math.isfinite(x) else None


def complex_pairs(z: np.ndarray) -> list[list[float]]:
    """Complex numbers (poles, zeros) as ``[[re, im], ...]`` for JSON."""
    return [[float(v.real), float(v.imag)] for v in np.asarray(z, dtype=complex)]
