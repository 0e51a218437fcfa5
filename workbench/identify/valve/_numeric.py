"""Evaluate a valve law on floats, numpy arrays or CasADi symbols (shared helpers)."""

from __future__ import annotations

from typing import Any, Callable

import casadi as ca
import numpy as np

__all__ = ["is_symbolic", "clip", "json_floats", "numeric"]


def is_symbolic(*args) -> bool:
    return any(isinstance(a, (ca.SX, ca.MX)) for a in args)


def clip(x, lo, hi):
    if is_symbolic(x):
        return ca.fmin(ca.fmax(x, lo), hi)
    return np.clip(x, lo, hi)


def json_floats(values) -> list:
    """Floats for JSON: NaN and inf become None (JSON has neither)."""
    return [float(v) if np.isfinite(v) else None for v in np.asarray(values, dtype=float).ravel()]


def numeric(flow: Callable) -> Callable[[Any, Any], np.ndarray]:
    """A numpy-broadcasting evaluator of a CasADi-traceable ``flow(p, u)``."""
    p, u = ca.SX.sym("p"), ca.SX.sym("u")
    fun = ca.Function("q", [p, u], [flow(p, u)])

    def evaluate(pp, uu):
        pp, uu = np.broadcast_arrays(np.asarray(pp, dtype=float), np.asarray(uu, dtype=float))
        if pp.size == 0:
            return np.zeros(pp.shape)
        out = np.asarray(fun(pp.reshape(1, -1), uu.reshape(1, -1)))
        return out.reshape(pp.shape)
    return evaluate
