"""Gas properties and flow through one restriction.

Pure functions written once on :mod:`workbench.physics.ops`: they take floats,
numpy arrays (element-wise) or CasADi SX/MX/DM and return a value of the same kind.
Signs: a flow is positive from its first pressure argument to its second.
"""

from __future__ import annotations

import math

from . import ops

__all__ = [
    "R_AIR", "GAMMA", "T_REF", "P_ATM", "RHO_ANR", "NOZZLE_CRITICAL_RATIO",
    "LAMINAR_MARGIN",
    "smooth_sqrt",
    "nozzle_cm", "nozzle_flow",
    "iso6358_psi", "iso6358_flow", "speed_of_sound",
]

R_AIR = 287.0            #: J/(kg K), specific gas constant of air
GAMMA = 1.4              #: -, ratio of specific heats of air
T_REF = 293.15           #: K, ISO 6358 reference temperature
P_ATM = 101325.0         #: Pa, standard atmosphere
RHO_ANR = 1.185          #: kg/m^3, air density at ANR (T_REF, 1 atm)
NOZZLE_CRITICAL_RATIO = (2.0 / (GAMMA + 1.0)) ** (GAMMA / (GAMMA - 1.0))  #: 0.528

#: Width, in pressure ratio, of the smooth (laminar) patch below ratio 1. The ISO
#: 6358 and nozzle laws have an infinite slope at ratio 1; on [1 - margin, 1] the
#: square root is replaced by the quadratic that matches it in value and slope at
#: 1 - margin, so the flow is C1 in both pressures, also through flow reversal.
LAMINAR_MARGIN = 0.005


def smooth_sqrt(y, margin: float = LAMINAR_MARGIN):
    """sqrt(y) for y >= margin, C1 quadratic y (3 m - y) / (2 m^1.5) below.

    The patch has a finite slope 1.5/sqrt(margin) at y = 0 (laminar behaviour)
    and vanishes at y = 0. Negative ``y`` gives the odd continuation.
    """
    m = margin
    ya = ops.fabs(y)
    patch = y * (3.0 * m - ya) / (2.0 * m ** 1.5)
    return ops.where(ya >= m, ops.sqrt(ops.fmax(ya, m)) * ops.sign(y), patch)


def speed_of_sound(temperature=T_REF, gamma: float = GAMMA, r: float = R_AIR):
    """Speed of sound a = sqrt(gamma r T) in m/s."""
    return ops.sqrt(gamma * r * temperature)


# ---------------------------------------------------------------------- nozzle law
def nozzle_cm(ratio, gamma: float = GAMMA, r: float = R_AIR):
    """Flow function Cm(x) of the nozzle law (paper 003, eq. 1), x = p_dw / p_up.

    Returns sqrt(kg K / J)-scaled function in s sqrt(K)/m: Cm = sqrt(gamma/r * 2/(gamma-1)
    * (x^(2/gamma) - x^((gamma+1)/gamma))) above the critical ratio, its maximum
    (choked) below it. Near x = 1 the smooth patch of :func:`smooth_sqrt` applies to
    z = 1 - x^((gamma-1)/gamma).
    """
    b = (2.0 / (gamma + 1.0)) ** (gamma / (gamma - 1.0))
    k = gamma / r * 2.0 / (gamma - 1.0)
    choked = math.sqrt(gamma / r * (2.0 / (gamma + 1.0)) ** ((gamma + 1.0) / (gamma - 1.0)))
    xs = ops.clip(ratio, b, 1.0)
    z = 1.0 - xs ** ((gamma - 1.0) / gamma)
    patch = LAMINAR_MARGIN * (gamma - 1.0) / gamma
    sub = math.sqrt(k) * xs ** (1.0 / gamma) * smooth_sqrt(z, patch)
    return ops.where(ratio <= b, choked, sub)


def nozzle_flow(area, p1, p2, t1=T_REF, t2=T_REF, discharge: float = 1.0,
                gamma: float = GAMMA, r: float = R_AIR):
    """Mass flow (kg/s) through an orifice of ``area`` (m^2), positive from 1 to 2.

    q_m = A Cq p_up / sqrt(T_up) Cm(p_dw/p_up), with the upstream side chosen by the
    pressures (paper 003, eq. 1).
    """
    with ops.quiet():                  # p = 0 divides in the branch not taken
        forward = area * discharge * p1 / ops.sqrt(t1) * nozzle_cm(p2 / p1, gamma, r)
        backward = area * discharge * p2 / ops.sqrt(t2) * nozzle_cm(p1 / p2, gamma, r)
    return ops.where(p1 >= p2, forward, -backward)


# ---------------------------------------------------------------------- ISO 6358
def iso6358_psi(ratio, b, margin: float = LAMINAR_MARGIN):
    """ISO 6358 flow function psi(x), x = p_dw/p_up in [0, 1].

    psi = 1 (choked) for x <= b, sqrt(1 - ((x - b)/(1 - b))^2) above, with the C1
    patch of :func:`smooth_sqrt` in (1 - x) near x = 1. Written as
    sqrt(1 + x - 2 b) * sqrt(1 - x) / (1 - b), which equals the ISO form.
    """
    x = ops.clip(ratio, b, 1.0)
    sub = ops.sqrt(1.0 + x - 2.0 * b) * smooth_sqrt(1.0 - x, margin) / (1.0 - b)
    return ops.where(ratio <= b, 1.0, sub)


def iso6358_flow(conductance, b, p1, p2, t1=T_REF, t2=T_REF, margin: float = LAMINAR_MARGIN):
    """Mass flow (kg/s) through an ISO 6358 restriction, positive from 1 to 2.

    q_m = C p_up rho0 sqrt(T0/T_up) psi(p_dw/p_up). The flow is odd in the
    exchange of the two sides and continuously differentiable everywhere
    (including p1 = p2), which linearisation and Newton solves need.

    Parameters
    ----------
    conductance : float, ndarray or casadi expression
        Sonic conductance C, m^3/(s Pa).
    b : float, ndarray or casadi expression
        Critical pressure ratio, -.
    p1, p2 : float, ndarray or casadi expression
        Pressures on the two sides, Pa absolute.
    t1, t2 : float, ndarray or casadi expression
        Upstream temperatures for either flow direction, K.
    margin : float
        Width of the laminar patch, see :data:`LAMINAR_MARGIN`.

    Returns
    -------
    float, ndarray or casadi expression
        Mass flow, kg/s (numpy arrays broadcast element-wise).
    """
    with ops.quiet():                  # p = 0 divides in the branch not taken
        forward = (conductance * p1 * RHO_ANR * ops.sqrt(T_REF / t1)
                   * iso6358_psi(p2 / p1, b, margin))
        backward = (conductance * p2 * RHO_ANR * ops.sqrt(T_REF / t2)
                    * iso6358_psi(p1 / p2, b, margin))
    return ops.where(p1 >= p2, forward, -backward)
