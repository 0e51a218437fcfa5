"""Pneumatic lines as lumped segments (volume, resistance, inertance).

A line of length L and diameter d is cut into N segments. Segment j has a node
pressure p_j (volume A L/N, adiabatic: waves travel at the speed of sound) and a
mass flow q_j leaving it towards the next node (inertance L/(N A)). q_0 is the
flow the valve delivers into the line, q_N the flow into the chamber. Friction
per segment is laminar (32 mu v L/d^2) plus a Blasius turbulent term.
The chain reproduces the transport delay L/a and the attenuation of paper 001.
"""

from __future__ import annotations

import math

from . import ops
from .gas import GAMMA, R_AIR

__all__ = ["AIR_VISCOSITY", "default_segments", "line_rates", "pressure_drop"]

AIR_VISCOSITY = 1.81e-5  #: Pa s, dynamic viscosity of air at 20 degC


def default_segments(length: float) -> int:
    """Segments per line when the plant file does not say: about one per 0.25 m, 2..40."""
    return int(min(40, max(2, math.ceil(length / 0.25))))


def pressure_drop(q, p, diameter, seg_length, temperature, r=R_AIR, mu=AIR_VISCOSITY):
    """Friction pressure drop (Pa) of mass flow q (kg/s) along one segment.

    Laminar Hagen-Poiseuille plus Blasius: dp = 32 mu L v/d^2 + 0.158 Re^-0.25 rho v|v| L/d,
    written so that it is smooth in q (the |v|^1.75 term has zero slope at v = 0).
    """
    area = ops.PI / 4.0 * diameter ** 2
    rho = p / (r * temperature)
    vel = q / (rho * area)
    lam = 32.0 * mu * seg_length * vel / diameter ** 2
    speed = ops.sqrt(vel * vel + 1e-12)
    turb = 0.158 * (rho * diameter / mu) ** -0.25 * rho * vel * speed ** 0.75 * seg_length / diameter
    return lam + turb


def line_rates(p_nodes, q_flows, q_in, p_end, length, diameter, temperature,
               gamma=GAMMA, r=R_AIR):
    """Derivatives of one line's node pressures and segment flows.

    Parameters
    ----------
    p_nodes : N node pressures, Pa (list of scalars/expressions).
    q_flows : N segment mass flows, kg/s; q_flows[-1] enters the chamber.
    q_in : mass flow delivered by the valve into node 0, kg/s.
    p_end : chamber pressure at the line's end, Pa.
    length, diameter : m. temperature : K.

    Returns
    -------
    (dp_nodes, dq_flows) as lists.
    """
    n = len(p_nodes)
    area = ops.PI / 4.0 * diameter ** 2
    seg = length / n
    vol = area * seg
    dp, dq = [], []
    for j in range(n):
        inflow = q_in if j == 0 else q_flows[j - 1]
        dp.append(gamma * r * temperature / vol * (inflow - q_flows[j]))
        p_next = p_end if j == n - 1 else p_nodes[j + 1]
        p_mean = 0.5 * (p_nodes[j] + p_next)
        drop = pressure_drop(q_flows[j], p_mean, diameter, seg, temperature, r)
        dq.append(area / seg * (p_nodes[j] - p_next - drop))
    return dp, dq
