"""Plausibility of a fitted valve law before it goes into a plant file.

A fitted polynomial is only trustworthy where the table had data; a plant simulates it
everywhere between atmosphere and supply and at every command. Before a fit is written
as a plant's valve, its flows over that whole domain are compared with what an ISO 6358
restriction of the plant's stated sonic conductance C can pass: at most the choked flow
C p_up rho0 sqrt(T0/T) from the upstream pressure (supply for the inlet, the port for
the exhaust). A law that exceeds it by more than ``tolerance`` (the datasheet's C is a
nominal value and the fit has errors) is physically impossible for that valve.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ...physics import gas
from ._numeric import numeric as _numeric

__all__ = ["flow_limit_problems"]


def flow_limit_problems(flow: Callable, conductance: float, supply_pressure: float,
                        atmospheric_pressure: float, command_range: tuple[float, float],
                        temperature: float = gas.T_REF, tolerance: float = 0.25,
                        n: int = 41) -> list[str]:
    """What is implausible about ``flow(p, u)`` (kg/s) for a valve of ``conductance``.

    Parameters
    ----------
    flow : CasADi-traceable q_m(p, u), kg/s into the port.
    conductance : stated sonic conductance C of one fully open restriction, m^3/(s Pa).
    supply_pressure, atmospheric_pressure : Pa abs. command_range : (low, high), V.
    temperature : K. tolerance : allowed excess over the ISO 6358 choked flow, fraction.
    n : grid points per axis.

    Returns
    -------
    list of str
        Empty when plausible; otherwise one sentence per problem (non-finite flows,
        inflow above the choked flow from the supply, outflow above the choked flow
        from the port), with where and by how much.
    """
    p = np.linspace(atmospheric_pressure, supply_pressure, n)
    u = np.linspace(*command_range, n)
    pp, uu = (a.ravel() for a in np.meshgrid(p, u, indexing="ij"))
    q = np.asarray(_numeric(flow)(pp, uu), dtype=float)
    if not np.all(np.isfinite(q)):
        return ["the law gives non-finite flows (NaN or inf) inside the table's range"]
    rho = gas.RHO_ANR * math.sqrt(gas.T_REF / temperature)
    limit_in = (1 + tolerance) * conductance * supply_pressure * rho
    limit_out = (1 + tolerance) * conductance * pp * rho
    problems = []
    i = int(np.argmax(q - limit_in))
    if q[i] > limit_in:
        problems.append(f"inflow {q[i] * 1e3:.4g} g/s at p = {pp[i]:.4g} Pa, u = {uu[i]:.4g} V "
                        f"exceeds the choked flow from the supply of C = {conductance:.4g} "
                        f"m^3/(s Pa), {limit_in / (1 + tolerance) * 1e3:.4g} g/s, by more than "
                        f"{100 * tolerance:g} %")
    j = int(np.argmax(-q - limit_out))
    if -q[j] > limit_out[j]:
        problems.append(f"outflow {-q[j] * 1e3:.4g} g/s at p = {pp[j]:.4g} Pa, u = {uu[j]:.4g} V "
                        f"exceeds the choked flow from the port through C = {conductance:.4g} "
                        f"m^3/(s Pa), {limit_out[j] / (1 + tolerance) * 1e3:.4g} g/s, by more "
                        f"than {100 * tolerance:g} %")
    return problems
