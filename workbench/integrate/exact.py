"""Exact steps of linear subsystems driven by an input held over the step.

A second-order lag y'' = w^2 (u - y) - 2 zeta w y' with ``u`` constant over the step
(a zero-order hold) has the exact solution e(t) = E(t) e(0) for its deviation
e = (y - u, y') with E(t) = exp(A t), A = [[0, 1], [-w^2, -2 zeta w]]. For a 2x2
matrix (Cayley-Hamilton): exp(A t) = e^(mu t) [cosh(d t) I + sinh(d t)/d (A - mu I)],
mu = -zeta w, d^2 = w^2 (zeta^2 - 1) (cosh/sinh become cos/sin when d^2 < 0: the
under-damped lag). Written with exponentials of non-positive arguments only, it cannot
overflow at any w h. The mean of y over the step is exact too:
int_0^h e dt = A^-1 (e(h) - e(0)).

:func:`lag2_split` puts such a lag into a larger system it drives (and nothing drives
back): the lag's exact motion, the rest stepped by any one-step method.

Everything is CasADi (SX or MX: the parameters may be symbols, the derivatives are
exact); on floats the results are DM.
"""

from __future__ import annotations

import math

import casadi as ca

__all__ = ["lag2_step", "lag2_split"]

#: |d^2 h^2| below which the series of cosh and sinh(s)/s are used (their next terms,
#: d^6 h^6 / 720 and d^6 h^6 / 5040, are below 1e-20 there).
_SERIES = 1e-6


def lag2_step(y0, r0, u, bandwidth_hz, damping, h):
    """One exact step of the second-order lag y'' = w^2 (u - y) - 2 zeta w y'.

    Parameters
    ----------
    y0, r0 : y and y' at the step's start (units of u, and per s).
    u : input held over the step (units of y).
    bandwidth_hz : w / (2 pi), Hz (> 0).
    damping : zeta (> 0).
    h : step, s.

    Returns
    -------
    (y1, r1, y_mean) : y and y' at the step's end and the mean of y over the step.
    """
    w = 2.0 * math.pi * bandwidth_hz
    a = w * h
    m = -damping * a                                   # mu h <= 0
    d2 = a * a * (damping * damping - 1.0)             # (d h)^2
    sp = ca.sqrt(ca.fmax(d2, _SERIES))                 # over-damped: d h real
    sn = ca.sqrt(ca.fmax(-d2, _SERIES))                # under-damped: d h imaginary
    ep, em = ca.exp(m + sp), ca.exp(m - sp)            # m + sp <= 0 since zeta^2 - 1 < zeta^2
    em0 = ca.exp(m)
    # e^(mu h) cosh(d h) and e^(mu h) sinh(d h)/(d h), branch by branch
    c = ca.if_else(d2 > _SERIES, 0.5 * (ep + em),
                   ca.if_else(d2 < -_SERIES, em0 * ca.cos(sn),
                              em0 * (1.0 + d2 / 2.0 + d2 * d2 / 24.0)))
    s = ca.if_else(d2 > _SERIES, (ep - em) / (2.0 * sp),
                   ca.if_else(d2 < -_SERIES, em0 * ca.sin(sn) / sn,
                              em0 * (1.0 + d2 / 6.0 + d2 * d2 / 120.0)))
    e0, r = y0 - u, r0
    # E(h) = c I + s h (A - mu I), h (A - mu I) = [[zeta a, h], [-w a, -zeta a]]
    e1 = c * e0 + s * (damping * a * e0 + h * r)
    r1 = c * r + s * (-w * a * e0 - damping * a * r)
    # int_0^h e dt = A^-1 (e(h) - e(0)), A^-1 = [[-2 zeta / w, -1 / w^2], [1, 0]]
    integral = -2.0 * damping / w * (e1 - e0) - (r1 - r) / (w * w)
    return u + e1, r1, u + integral / h


def lag2_split(f, z, iy: int, ir: int, u, bandwidth_hz, damping, h, zs=None):
    """A system with a second-order lag (states ``iy``, ``ir``: y, y') driven by ``u``
    alone and driving the rest, prepared for a one-step method: (zs, g, end).

    The lag's motion over the step is known exactly from the step's start ``z``
    (:func:`lag2_step`); the step integrates the other states with y following that
    motion: the lag's slot ``iy`` of the integrated state ``zs`` carries the time tau
    since the step's start (rate 1: a non-autonomous step by its autonomous form, right
    for a Rosenbrock method, not for a W-method), the slot ``ir`` nothing (rate 0).
    ``g(zz)`` are those rates; ``end(zn, *more)`` substitutes zs = z with tau = 0 in the
    step's result ``zn`` (and in any further expressions ``more``) and puts the exact y,
    y' at the step's end into it.

    Parameters
    ----------
    f : rates of the whole system, zz -> dz/dt (SX), y read from zz[iy].
    z : the step's start (SX symbol). iy, ir : indices of y and y'.
    u, bandwidth_hz, damping : as in :func:`lag2_step`. h : step, s.
    zs : the symbol to integrate (default a new one; pass the same for several ``g``).
    """
    nx = z.shape[0]
    zs = ca.SX.sym("zs", nx) if zs is None else zs

    def motion(tau):
        return lag2_step(z[iy], z[ir], u, bandwidth_hz, damping, tau)[:2]

    def g(zz):
        held = ca.vertcat(*[motion(zz[iy])[0] if i == iy else (0.0 if i == ir else zz[i])
                            for i in range(nx)])
        fz = f(held)
        return ca.vertcat(*[1.0 if i == iy else (0.0 if i == ir else fz[i]) for i in range(nx)])

    def end(zn, *more):
        start = ca.vertcat(*[0.0 if i == iy else z[i] for i in range(nx)])
        out = ca.substitute([zn, *more], [zs], [start])
        y1, r1 = motion(h)
        zn = ca.vertcat(*[y1 if i == iy else (r1 if i == ir else out[0][i]) for i in range(nx)])
        return (zn, *out[1:])
    return zs, g, end
