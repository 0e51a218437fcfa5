"""Blocked-port points of the pressure gain characteristic, as constraints of a fit.

A global characterisation bench (paper 003, section 3.2) throttles the port from open to
closed at each command: at the closed end the flow is zero *exactly* and the port pressure
p_e(u) is read by a pressure transducer -- the pressure gain characteristic of the
paper's Fig. 3d. These points are far more precise about where q_m(p, u) = 0 than the
flow readings around them: near the centred spool the characteristic's restoring slope
Cp = -dq/dp is small (about 0.13 g/s per bar on paper 003's kind of stage), so a flow
error of 0.05 g/s moves the zero crossing by 0.4 bar, while a transducer reads p_e to
0.01 bar. The pressure gain characteristic is also what decides a closed tank's (or a
cylinder chamber's) steady state after a command step (paper 003, section 5: "the errors
of the steady state pressure values originate from the errors of the pressure gain
characteristics"), so :func:`~workbench.identify.valve.fit_polynomial` and
:func:`~workbench.identify.valve.fit_affine` take them as equality constraints
q_m(p_e, u) = 0 (``pressure_gain=``) instead of as ordinary points.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ...errors import InputError
from .table import ValveTable

__all__ = ["check_pressure_gain_points", "load_pressure_gain"]


def check_pressure_gain_points(points, table: ValveTable, source: str = "<memory>") -> np.ndarray:
    """``points`` as an array of rows (u in V, p_e in Pa) inside the table's ranges.

    Raises
    ------
    InputError
        Not an (k, 2) array of finite numbers, a pressure outside the table's pressure
        range or a command outside its command range (a constraint where the fit has
        no data would bend it there), or the same command twice.
    """
    try:
        a = np.array(points, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"expected rows (u in V, p_e in Pa), got {points!r}",
                         source=source, location="pressure_gain") from exc
    if a.ndim != 2 or a.shape[1] != 2 or len(a) == 0:
        raise InputError(f"expected rows (u in V, p_e in Pa), got an array of shape {a.shape}",
                         source=source, location="pressure_gain")
    if not np.all(np.isfinite(a)):
        raise InputError("a pressure gain point is NaN or infinite", source=source,
                         location="pressure_gain")
    lo, hi = table.pressure_range
    ulo, uhi = table.command_range
    for u, p in a:
        if not lo < p < hi:
            raise InputError(f"the blocked-port pressure {p:g} Pa at u = {u:g} V is outside "
                             f"the table's pressures ({lo:g}..{hi:g} Pa, open interval): is it "
                             "in Pa absolute?", source=source, location="pressure_gain")
        if not ulo <= u <= uhi:
            raise InputError(f"the command {u:g} V of a pressure gain point is outside the "
                             f"table's commands ({ulo:g}..{uhi:g} V)", source=source,
                             location="pressure_gain")
    if len(np.unique(a[:, 0])) != len(a):
        raise InputError("a command appears twice among the pressure gain points (one "
                         "blocked-port pressure per command)", source=source,
                         location="pressure_gain")
    return a


def load_pressure_gain(path: str | os.PathLike) -> np.ndarray:
    """Blocked-port points from a CSV file with a header ``u,p`` or ``u,p_e`` (V, Pa abs).

    Lines starting with ``#`` are comments. Returns an (k, 2) array; the ranges are
    checked against the table by :func:`check_pressure_gain_points` when fitting.
    """
    path = Path(path)
    try:
        lines = [ln.strip() for ln in path.read_text().splitlines()]
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the pressure gain file: {exc}", source=str(path),
                         location="--pressure-gain") from exc
    lines = [ln for ln in lines if ln and not ln.startswith("#")]
    if not lines or [c.strip() for c in lines[0].split(",")] not in (["u", "p"], ["u", "p_e"]):
        raise InputError("expected a header line 'u,p' (command in V, blocked-port pressure "
                         "in Pa absolute; 'u,p_e' is read the same)", source=str(path),
                         location="--pressure-gain")
    rows = []
    for i, ln in enumerate(lines[1:], start=2):
        cells = ln.split(",")
        try:
            if len(cells) != 2:
                raise ValueError
            rows.append([float(cells[0]), float(cells[1])])
        except ValueError:
            raise InputError(f"data line {i}: expected two numbers 'u,p', got {ln!r}",
                             source=str(path), location="--pressure-gain") from None
    if not rows:
        raise InputError("no pressure gain points in the file", source=str(path),
                         location="--pressure-gain")
    return np.array(rows)
