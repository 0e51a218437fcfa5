"""Simulated output of a (time-varying) ARX model: open loop, in a loop, or integrated.

A recursive estimator's own output is the one-step-ahead prediction, which repeats the
measured y(k-1) and says little about the model. Simulating the model from the input
alone is the stricter test (paper 002's Figs. 6 and 9 compare system and model
outputs). Two physical situations need more than ``y = B/A u``:

* the model describes the **increment** of the output (``integrate=True``: e.g. the
  velocity y(k) - y(k-1) of a piston whose position is measured; the integrator is
  kinematics, not estimated, and a 2nd-order A(q) cannot hold it together with the
  pneumatic spring-mass pair);
* the experiment ran in a **loop** (``feedback``: the input applied at sample k is
  computed from the simulated output, as the rig's controller computed it from the
  measured one), so an integrating model does not drift away on errors of its gain.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ...errors import InputError
from .estimator import RlsResult

__all__ = ["a_priori_track", "simulate_tarx"]


def a_priori_track(result: RlsResult, length: int) -> np.ndarray:
    """Parameters in force at each sample: row k is the estimate theta(k-1), shape
    (length, na + nb); samples up to the first estimate get the first estimate."""
    th = result.theta
    out = np.empty((int(length), th.shape[1]))
    k0 = result.start_index
    out[:k0 + 1] = th[0]
    n = min(len(th) - 1, length - k0 - 1)
    out[k0 + 1:k0 + 1 + n] = th[:n]
    out[k0 + 1 + n:] = th[-1]
    return out


def simulate_tarx(theta, orders: tuple[int, int, int], y, u, start: int, *,
                  integrate: bool = False,
                  feedback: Callable[[int, float], float] | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Output (and input) of the ARX model simulated from sample ``start`` on.

    ``s(k) = -a1 s(k-1) - .. - a_na s(k-na) + b1 u(k-nk) + .. + b_nb u(k-nk-nb+1)``
    with ``s = y`` or, with ``integrate``, ``s(k) = y(k) - y(k-1)`` and ``y`` summed.
    Samples before ``start`` are the recording's (the initial state).

    Parameters
    ----------
    theta : array, shape (na + nb,) held, or (len(y), na + nb): row k in force at k
        (:func:`a_priori_track` of an RLS run gives theta(k-1), data before k only).
    orders : (na, nb, nk) as :func:`~workbench.identify.rls.rls`.
    y, u : recorded output and input, same length.
    start : first simulated sample (at least max(na + integrate, nk + nb - 1)).
    integrate : the model gives the increment of y.
    feedback : ``feedback(k, y_sim(k)) -> u(k)``, the input applied at k in the loop the
        experiment ran in; None keeps the recorded input.

    Returns
    -------
    (y_sim, u_sim) : arrays like ``y`` and ``u``.
    """
    na, nb, nk = (int(v) for v in orders)
    y = np.array(y, dtype=float)
    u = np.array(u, dtype=float)
    th = np.asarray(theta, dtype=float)
    if y.shape != u.shape or y.ndim != 1:
        raise InputError(f"y and u must be 1-D of the same length, got {y.shape} and {u.shape}")
    if th.shape not in ((na + nb,), (len(y), na + nb)):
        raise InputError(f"theta must have shape ({na + nb},) or ({len(y)}, {na + nb}), got "
                         f"{th.shape}", location="theta")
    if feedback is not None and nk < 1:
        raise InputError("a loop needs a delay nk >= 1 (with nk = 0 the input at k would "
                         "depend on the output it produces)", location="orders")
    need = max(na + int(integrate), nk + nb - 1)
    if not need <= start <= len(y):
        raise InputError(f"start must be in [{need}, {len(y)}] (the initial state needs "
                         f"{need} recorded samples), got {start}", location="start")
    rows = np.broadcast_to(th, (len(y), na + nb))
    s = np.diff(y, prepend=y[0]) if integrate else y.copy()
    ys, us = y.copy(), u.copy()
    if feedback is not None and start < len(y):
        us[start:] = np.nan
    for k in range(start, len(y)):
        a, b = rows[k, :na], rows[k, na:]
        s[k] = (-sum(a[i] * s[k - 1 - i] for i in range(na))
                + sum(b[j] * us[k - nk - j] for j in range(nb)))
        ys[k] = ys[k - 1] + s[k] if integrate else s[k]
        if feedback is not None:
            us[k] = feedback(k, ys[k])
    return ys, us
