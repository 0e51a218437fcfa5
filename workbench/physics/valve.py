"""Proportional valve laws: the 5/3 four-edge valve and the input-affine law.

Spool opening ``s`` in [-1, 1]: positive connects supply -> A and B -> exhaust.
Flows are mass flows in kg/s, positive *into* the named port's chamber.

Two laws give the port flows of the same 5/3 valve:

* :func:`four_edge_flows` -- four ISO 6358 metering edges (the plant default,
  ``[valve] law = "iso6358"``);
* :func:`affine_port_flows` -- paper 003's approximation II,
  q_m = phi(p) + psi(p, sgn Gamma) Gamma, applied to port A with Gamma(s) and to
  port B with Gamma(-s) = -Gamma(s) (``[valve] law = "input_affine"``). Its
  coefficients can be fitted to a four-edge valve by linear least squares with
  :func:`fit_affine_to_four_edge`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from . import ops
from .gas import T_REF, iso6358_flow

__all__ = [
    "UNDERLAP_LAWS",
    "spool_position",
    "effective_opening",
    "edge_openings",
    "rounded_edge_openings",
    "underlap_openings",
    "four_edge_flows",
    "spool_dynamics",
    "polyval",
    "gamma_odd",
    "affine_flow",
    "affine_port_flows",
    "AffineValveFit",
    "fit_affine_to_four_edge",
]


#: Underlap laws of a four-edge valve (see :func:`underlap_openings`).
UNDERLAP_LAWS = ("linear", "rounded")


def spool_position(u, center, span, offset=0.0):
    """Normalised spool position s = (u - center - offset)/span, clipped to [-1, 1].

    Parameters
    ----------
    u : command, V.
    center : command that centres an ideal spool, V.
    span : |u - center| that opens an edge fully, V.
    offset : null offset, V (the spool is centred at ``center + offset``).
    """
    return ops.clip((u - center - offset) / span, -1.0, 1.0)


def effective_opening(s, deadband=0.0):
    """Signed metering opening after the spool overlap ``deadband`` (fraction of span).

    opening = sign(s) max(|s| - d, 0) / (1 - d), written as (s - clip(s, -d, d))/(1 - d)
    so that with d = 0 it is exactly s (slope 1 through the centre).
    """
    if not ops.is_symbolic(deadband) and np.ndim(deadband) == 0 and deadband == 0.0:
        # no overlap: the opening is the command itself. (The clip form below would
        # also give s, but its derivative at s = 0 hits the fmin/fmax tie and comes
        # out 0.75 instead of 1 -- wrong for every tangent model at the centre.)
        return s
    return (s - ops.clip(s, -deadband, deadband)) / (1.0 - deadband)


def edge_openings(opening, underlap=0.0):
    """Linear underlap law: (o_plus, o_minus), the S->A/B->E and S->B/A->E edge openings.

    o_plus = max(o, 0) + u, o_minus = max(-o, 0) + u for the signed opening o: every
    edge is ``underlap`` u (fraction of full opening) more open than the ideal
    closed-centre edge, whatever the spool position (a leaking centre of constant
    width). With u = 0 the openings are in [0, 1]. The plant uses it only to pin
    down the equilibrium pressures of a closed-centre valve (see
    :mod:`workbench.linearize`), never in simulation.

    Parameters
    ----------
    opening : signed effective opening, -.
    underlap : extra opening u of every edge, fraction of full opening, -.
    """
    mag = ops.fabs(opening)
    o_plus = 0.5 * (mag + opening) + underlap
    o_minus = 0.5 * (mag - opening) + underlap
    return o_plus, o_minus


def rounded_edge_openings(opening, underlap=0.0):
    """Rounded underlap law: (o_plus, o_minus) = ((r + o)/2, (r - o)/2), r = sqrt(o^2 + d^2).

    The law of the valve-table generator (:mod:`workbench.identify.valve`): at the
    centre both edges are open d/2, an overlapped edge still passes d^2/(4 |o|) (the
    clearance leakage that falls with the overlap length) and an open edge tends to
    o; o_plus - o_minus = o exactly, and the openings are smooth in o. It differs
    from :func:`edge_openings` (which adds d to every edge at every opening): at the
    centre d/2 against d, far from it o against o + d. With d = 0 (a plain number)
    it returns (max(o, 0), max(-o, 0)), the ideal closed-centre edges.

    Parameters
    ----------
    opening : signed effective opening o, -.
    underlap : underlap d of every edge, fraction of full opening, -.
    """
    if not ops.is_symbolic(underlap) and np.ndim(underlap) == 0 and underlap == 0.0:
        return ops.fmax(opening, 0.0), ops.fmax(-opening, 0.0)
    r = ops.sqrt(opening * opening + underlap * underlap)
    return 0.5 * (r + opening), 0.5 * (r - opening)


def underlap_openings(opening, underlap=0.0, law: str = "linear"):
    """Edge openings (o_plus, o_minus) under the named underlap law.

    ``law`` is one of :data:`UNDERLAP_LAWS`: ``"linear"`` (:func:`edge_openings`,
    the plant's default) or ``"rounded"`` (:func:`rounded_edge_openings`).
    ``opening`` and ``underlap`` are fractions of full opening, -.
    """
    if law == "linear":
        return edge_openings(opening, underlap)
    if law == "rounded":
        return rounded_edge_openings(opening, underlap)
    raise ValueError(f"unknown underlap law {law!r}; expected one of "
                     + ", ".join(repr(n) for n in UNDERLAP_LAWS))


def four_edge_flows(opening, p_s, p_a, p_b, p_atm, conductance, b,
                    t_supply=T_REF, t_a=T_REF, t_b=T_REF, underlap=0.0,
                    underlap_law: str = "linear"):
    """Flows of a 5/3 valve with four ISO 6358 edges of equal conductance.

    Parameters
    ----------
    opening : signed effective opening (see :func:`effective_opening`), -.
    p_s, p_a, p_b, p_atm : supply, port A, port B and exhaust pressures, Pa.
    conductance : sonic conductance of one fully open edge, m^3/(s Pa).
    b : critical pressure ratio, -.
    t_supply, t_a, t_b : temperatures of the gas leaving supply, A and B, K.
    underlap : underlap of every edge, fraction of full opening, -.
    underlap_law : ``"linear"`` or ``"rounded"``, see :func:`underlap_openings`.

    Returns
    -------
    q_a, q_b : mass flows into ports A and B, kg/s.
    q_supply : mass flow drawn from the supply, kg/s.
    """
    o_plus, o_minus = underlap_openings(opening, underlap, underlap_law)
    s_to_a = o_plus * iso6358_flow(conductance, b, p_s, p_a, t_supply, t_a)
    a_to_e = o_minus * iso6358_flow(conductance, b, p_a, p_atm, t_a, T_REF)
    s_to_b = o_minus * iso6358_flow(conductance, b, p_s, p_b, t_supply, t_b)
    b_to_e = o_plus * iso6358_flow(conductance, b, p_b, p_atm, t_b, T_REF)
    return s_to_a - a_to_e, s_to_b - b_to_e, s_to_a + s_to_b


def spool_dynamics(y, y_dot, u, bandwidth_hz, damping):
    """Second-order spool lag: y'' = w^2 (u - y) - 2 zeta w y', w = 2 pi bandwidth.

    ``y`` is the command the spool currently follows (V); returns (y', y'').
    """
    w = 2.0 * ops.PI * bandwidth_hz
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
    mag = ops.fabs(du)
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
    psi = ops.where(gamma >= 0, polyval(psi_in, pn), polyval(psi_out, pn))
    return polyval(phi, pn) + psi * gamma


def affine_port_flows(opening, p_a, p_b, phi, psi_in, psi_out, gamma,
                      pressure_scale=1e5, underlap=0.0):
    """Flows of a 5/3 valve whose two ports follow the input-affine law.

    Port A sees Gamma(opening), port B the mirrored Gamma(-opening) = -Gamma(opening):
    a positive opening fills A and exhausts B, as in :func:`four_edge_flows`. The
    same coefficients serve both ports (a symmetric valve).

    Parameters
    ----------
    opening : signed effective opening (see :func:`effective_opening`), -.
    p_a, p_b : port pressures, Pa.
    phi, psi_in, psi_out : ascending coefficients in ``p / pressure_scale``; phi in
        kg/s, psi in kg/s per unit Gamma (see :func:`affine_flow`).
    gamma : coefficients g_k of :func:`gamma_odd` (Gamma is dimensionless, a
        function of the normalised opening).
    pressure_scale : Pa per unit of the polynomial variable (1e5: bar).
    underlap : every edge leaks this fraction of its full opening (as in
        :func:`edge_openings`): adds underlap * Gamma(1) * (psi_in(p) - psi_out(p))
        to each port, the inflow of a fully open inlet minus the outflow of a fully
        open exhaust. Only used to pin the equilibrium pressures when phi does not
        (see :mod:`workbench.linearize`), never in simulation.

    Returns
    -------
    q_a, q_b : mass flows into ports A and B, kg/s.
    q_supply : mass flow drawn from the supply, kg/s: max(q_a, 0) + max(q_b, 0).
        A port can only gain mass from the supply (the exhaust is at atmosphere),
        so this is the supply draw the law implies; it equals the four-edge valve's
        supply flow for a closed-centre valve whose exhausting chamber is above
        atmosphere. Internal supply -> exhaust leakage the law does not see is not
        counted.

    The law does not depend on the gas temperatures (paper 003 characterises the
    valve at one temperature).
    """
    g_a = gamma_odd(opening, gamma)
    g_b = gamma_odd(-opening, gamma)
    q_a = affine_flow(p_a, g_a, phi, psi_in, psi_out, pressure_scale)
    q_b = affine_flow(p_b, g_b, phi, psi_in, psi_out, pressure_scale)
    if ops.is_symbolic(underlap) or np.ndim(underlap) != 0 or underlap != 0.0:
        g_full = gamma_odd(1.0, gamma)
        for_p = [p_a / pressure_scale, p_b / pressure_scale]
        leak = [underlap * g_full * (polyval(psi_in, pn) - polyval(psi_out, pn)) for pn in for_p]
        q_a, q_b = q_a + leak[0], q_b + leak[1]
    q_supply = ops.fmax(q_a, 0.0) + ops.fmax(q_b, 0.0)
    return q_a, q_b, q_supply


# ---------------------------------------------------------------------- fitting (approx. II)
@dataclass(frozen=True)
class AffineValveFit:
    """Coefficients of the input-affine law fitted to a valve, and the fit's quality.

    Attributes
    ----------
    phi, psi_in, psi_out : ascending coefficients in p / pressure_scale, kg/s
        (psi: kg/s per unit Gamma).
    gamma : coefficients of :func:`gamma_odd` in the normalised opening, -.
    pressure_scale : Pa per unit of the polynomial variable.
    rms, max_error : RMS and largest |q_affine - q_reference| over the grid, kg/s.
    pressure_range : (low, high) pressures of the grid, Pa.
    points : number of (p, opening) grid points.
    """

    phi: tuple[float, ...]
    psi_in: tuple[float, ...]
    psi_out: tuple[float, ...]
    gamma: tuple[float, ...]
    pressure_scale: float
    rms: float
    max_error: float
    pressure_range: tuple[float, float]
    points: int

    def flow(self, p, opening):
        """Port flow (kg/s) of the fitted law at pressure ``p`` (Pa) and ``opening`` (-)."""
        g = gamma_odd(opening, self.gamma)
        return affine_flow(p, g, self.phi, self.psi_in, self.psi_out, self.pressure_scale)

    def plant_values(self) -> dict[str, Any]:
        """Dotted plant-file keys selecting this law, for ``PlantParams.replace``."""
        return {"valve.law": "input_affine", "valve.affine_phi": list(self.phi),
                "valve.affine_psi_in": list(self.psi_in),
                "valve.affine_psi_out": list(self.psi_out),
                "valve.affine_gamma": list(self.gamma)}

    def toml_lines(self) -> str:
        """The ``[valve]`` lines of a plant file (full precision, round-trips exactly)."""
        def arr(v):
            return "[" + ", ".join(repr(float(c)) for c in v) + "]"
        return "\n".join([
            'law = "input_affine"',
            f"affine_phi = {arr(self.phi)}",
            f"affine_psi_in = {arr(self.psi_in)}",
            f"affine_psi_out = {arr(self.psi_out)}",
            f"affine_gamma = {arr(self.gamma)}",
        ])


def fit_affine_to_four_edge(conductance: float, b: float, p_s: float, p_atm: float,
                            temperature: float = T_REF, *, psi_degree: int = 5,
                            phi_degree: int | None = None,
                            gamma: Sequence[float] = (1.0, 0.0), pin_ends: bool = True,
                            n_pressure: int = 60, n_opening: int = 41,
                            pressure_scale: float = 1e5) -> AffineValveFit:
    """Fit the input-affine law to a four-edge ISO 6358 valve (paper 003, approximation II).

    Reference data: the port-A flow of :func:`four_edge_flows` (no underlap) on a
    grid of ``n_pressure`` port pressures in [p_atm, p_s] and ``n_opening`` openings
    in [-1, 1]. With Gamma held fixed, q = phi(p) + psi(p, sgn Gamma) Gamma is linear
    in the coefficients of phi, psi_in and psi_out, so they follow from one linear
    least-squares solve. The four-edge law is exactly linear in the opening (an
    edge's area is proportional to it), so the default Gamma(s) = s is exact and
    only the pressure dependence is approximated.

    Parameters
    ----------
    conductance : sonic conductance of one fully open edge, m^3/(s Pa).
    b : critical pressure ratio, -.
    p_s, p_atm : supply and exhaust pressures, Pa (absolute).
    temperature : gas temperature, K.
    psi_degree : degree of psi_in and psi_out in p / pressure_scale.
    phi_degree : degree of phi, or None for phi = 0: a closed-centre four-edge
        valve passes no flow at the centre, so its phi is zero and fitting it would
        only absorb the error of psi (and make the centre equilibrium wander).
    gamma : coefficients g_k of :func:`gamma_odd`, held fixed (default s, written
        in paper 003's degree-2 form g1 s + g2 s|s| with g2 = 0 so that a later
        grey-box fit can free g2).
    pin_ends : constrain psi_in(p_s) = 0 and psi_out(p_atm) = 0, as the valve does:
        a chamber at supply pressure takes no more air, one at atmosphere gives no
        more. Unconstrained, a fully open valve would drive the chamber slightly past
        p_s or below p_atm (about 8 kPa for the 25 mm rig's valve); pinned, the RMS
        error grows a little (0.29 -> 0.42 g/s for that valve).
    n_pressure, n_opening : grid size.
    pressure_scale : Pa per unit of the polynomial variable.

    Returns
    -------
    AffineValveFit

    Examples
    --------
    >>> fit = fit_affine_to_four_edge(6.25e-8, 0.23, 6.0e5, 101325.0)
    >>> fit.rms < 0.5e-3            # kg/s, paper 003's bound for approximation II
    True
    """
    if psi_degree < 1 or (phi_degree is not None and phi_degree < 0):
        raise ValueError("psi_degree must be >= 1 and phi_degree >= 0 (or None)")
    if not p_s > p_atm > 0:
        raise ValueError(f"need p_s > p_atm > 0, got p_s = {p_s!r} Pa, p_atm = {p_atm!r} Pa")
    gamma = tuple(float(g) for g in gamma)
    pressures = np.linspace(p_atm, p_s, n_pressure)
    openings = np.linspace(-1.0, 1.0, n_opening)
    pp, oo = (a.ravel() for a in np.meshgrid(pressures, openings, indexing="ij"))
    # the laws run element-wise on the whole grid (numpy backend of ops)
    q_ref = four_edge_flows(oo, p_s, pp, pp, p_atm, conductance, b,
                            temperature, temperature, temperature)[0]
    pn = pp / pressure_scale
    g = gamma_odd(oo, gamma)
    inlet = (g >= 0).astype(float)
    n_psi = psi_degree + 1

    # Basis of each polynomial (ascending powers of pn). With pin_ends, psi_in is
    # (pn_s - pn) r(pn) and psi_out (pn - pn_atm) r(pn), r of degree psi_degree - 1;
    # the free coefficients are those of r, mapped back to monomials afterwards.
    pn_s, pn_atm = p_s / pressure_scale, p_atm / pressure_scale
    if pin_ends:
        k = psi_degree
        root_in, root_out = pn_s, pn_atm
    else:
        k = n_psi
    powers = np.vander(pn, k, increasing=True)
    if pin_ends:
        b_in = (root_in - pn)[:, None] * powers
        b_out = (pn - root_out)[:, None] * powers
    else:
        b_in = b_out = powers
    blocks = [b_in * (g * inlet)[:, None], b_out * (g * (1.0 - inlet))[:, None]]
    if phi_degree is not None:
        blocks.insert(0, np.vander(pn, phi_degree + 1, increasing=True))
    A = np.hstack(blocks)
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0.0] = 1.0
    sol, *_ = np.linalg.lstsq(A / scale, q_ref, rcond=None)
    sol = sol / scale
    i = 0
    if phi_degree is not None:
        phi = tuple(float(c) for c in sol[:phi_degree + 1])
        i = phi_degree + 1
    else:
        phi = (0.0,)
    r_in, r_out = sol[i:i + k], sol[i + k:i + 2 * k]
    P = np.polynomial.polynomial
    if pin_ends:
        psi_in = P.polymul([root_in, -1.0], r_in)
        psi_out = P.polymul([-root_out, 1.0], r_out)
    else:
        psi_in, psi_out = r_in, r_out
    psi_in = tuple(float(c) for c in np.pad(psi_in, (0, n_psi - len(psi_in))))
    psi_out = tuple(float(c) for c in np.pad(psi_out, (0, n_psi - len(psi_out))))
    fit = AffineValveFit(phi=phi, psi_in=psi_in, psi_out=psi_out, gamma=gamma,
                         pressure_scale=float(pressure_scale), rms=0.0, max_error=0.0,
                         pressure_range=(float(p_atm), float(p_s)), points=int(len(q_ref)))
    q_fit = fit.flow(pp, oo)
    err = q_fit - q_ref
    return AffineValveFit(phi=phi, psi_in=psi_in, psi_out=psi_out, gamma=gamma,
                          pressure_scale=float(pressure_scale),
                          rms=float(np.sqrt(np.mean(err ** 2))),
                          max_error=float(np.max(np.abs(err))),
                          pressure_range=(float(p_atm), float(p_s)), points=int(len(q_ref)))
