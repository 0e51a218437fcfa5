"""Proportional valve laws: the 5/3 four-edge valve and the input-affine law.

Spool opening ``s`` in [-1, 1]: positive connects supply -> A and B -> exhaust.
Flows are mass flows in kg/s, positive *into* the named port's chamber.
"""

from __future__ import annotations

import casadi as ca

from .gas import T_REF, iso6358_flow, is_symbolic, where

__all__ = [
    "spool_position",
    "effective_opening",
    "edge_openings",
    "four_edge_flows",
    "spool_dynamics",
    "polyval",
    "gamma_odd",
    "affine_flow",
]


def _clip(v, lo, hi):
    return ca.fmin(ca.fmax(v, lo), hi)


def spool_position(u, center, span, offset=0.0):
    """Normalised spool position s = (u - center - offset)/span, clipped to [-1, 1].

    Parameters
    ----------
    u : command, V.
    center : command that centres an ideal spool, V.
    span : |u - center| that opens an edge fully, V.
    offset : null offset, V (the spool is centred at ``center + offset``).
    """
    return _clip((u - center - offset) / span, -1.0, 1.0)


def effective_opening(s, deadband=0.0):
    """Signed metering opening after the spool overlap ``deadband`` (fraction of span).

    opening = sign(s) max(|s| - d, 0) / (1 - d), written as (s - clip(s, -d, d))/(1 - d)
    so that with d = 0 it is exactly s (slope 1 through the centre).
    """
    return (s - _clip(s, -deadband, deadband)) / (1.0 - deadband)


def edge_openings(opening, underlap=0.0):
    """(o_plus, o_minus): openings of the S->A/B->E and S->B/A->E edge pairs, in [0, 1].

    ``underlap`` adds a symmetric opening to every edge (a leaking centre); the
    plant uses it only to pin down the equilibrium pressures of a closed-centre
    valve (see :mod:`workbench.linearize`), never in simulation.
    """
    mag = ca.fabs(opening) if is_symbolic(opening) else abs(opening)
    o_plus = 0.5 * (mag + opening) + underlap
    o_minus = 0.5 * (mag - opening) + underlap
    return o_plus, o_minus


def four_edge_flows(opening, p_s, p_a, p_b, p_atm, conductance, b,
                    t_supply=T_REF, t_a=T_REF, t_b=T_REF, underlap=0.0):
    """Flows of a 5/3 valve with four ISO 6358 edges of equal conductance.

    Parameters
    ----------
    opening : signed effective opening (see :func:`effective_opening`), -.
    p_s, p_a, p_b, p_atm : supply, port A, port B and exhaust pressures, Pa.
    conductance : sonic conductance of one fully open edge, m^3/(s Pa).
    b : critical pressure ratio, -.
    t_supply, t_a, t_b : temperatures of the gas leaving supply, A and B, K.

    Returns
    -------
    q_a, q_b : mass flows into ports A and B, kg/s.
    q_supply : mass flow drawn from the supply, kg/s.
    """
    o_plus, o_minus = edge_openings(opening, underlap)
    s_to_a = o_plus * iso6358_flow(conductance, b, p_s, p_a, t_supply, t_a)
    a_to_e = o_minus * iso6358_flow(conductance, b, p_a, p_atm, t_a, T_REF)
    s_to_b = o_minus * iso6358_flow(conductance, b, p_s, p_b, t_supply, t_b)
    b_to_e = o_plus * iso6358_flow(conductance, b, p_b, p_atm, t_b, T_REF)
    return s_to_a - a_to_e, s_to_b - b_to_e, s_to_a + s_to_b


def spool_dynamics(y, y_dot, u, bandwidth_hz, damping):
    """Second-order spool lag: y'' = w^2 (u - y) - 2 zeta w y', w = 2 pi bandwidth.

    ``y`` is the command the spool currently follows (V); returns (y', y'').
    """
    w = 2.0 * ca.pi * bandwidth_hz
    return y_dot, w * w * (u - y) - 2.0 * damping * w * y_dot


def polyval(coeffs, x):
    """sum_i coeffs[i] x^i (ascending powers), Horner form; works on casadi types."""
    out = 0.0
    for c in reversed(list(coeffs)):
        out = out * x + c
    return out


def gamma_odd(du, coeffs):
    """Odd command characteristic Gamma(du) = sum_k g_k du |du|^(k-1), k = 1..l.

    Gamma(-du) = -Gamma(du) and Gamma(0) = 0 hold for any coefficients (paper 003:
    a degree-2 Gamma is g1 du + g2 du |du|).
    """
    mag = ca.fabs(du) if is_symbolic(du) else abs(du)
    out = 0.0
    power = 1.0
    for g in coeffs:
        out = out + g * du * power
        power = power * mag
    return out


def affine_flow(p, gamma, phi, psi_in, psi_out, pressure_scale=1e5):
    """Input-affine valve law q_m = phi(p) + psi(p, sgn Gamma) Gamma (paper 003, eq. 5).

    Parameters
    ----------
    p : chamber pressure, Pa.
    gamma : value of Gamma(u) (see :func:`gamma_odd`), in the coefficients' units.
    phi, psi_in, psi_out : ascending polynomial coefficients in ``p / pressure_scale``;
        phi in kg/s, psi such that psi * Gamma is kg/s. ``psi_in`` applies when
        Gamma > 0 (inlet), ``psi_out`` when Gamma < 0 (exhaust).
    pressure_scale : Pa per unit of the polynomial variable (1e5: bar).
    """
    pn = p / pressure_scale
    psi = where(gamma >= 0, polyval(psi_in, pn), polyval(psi_out, pn))
    return polyval(phi, pn) + psi * gamma
