"""Exact tangent models and the reduced position model of paper 000.

Operating points (equilibria) are computed by :mod:`workbench.equilibrium`; its
names (``operating_point``, ``OperatingPoint``, ``centre_balance_pressure``,
``PIN_UNDERLAP``) are re-exported here.

All derivatives come from CasADi (automatic differentiation of the symbolic plant),
never from finite differences.

Examples
--------
>>> from workbench import Plant, linearize
>>> plant = Plant.from_toml("designs/plants/situm_rodless_nominal.toml")
>>> op = linearize.operating_point(plant, x=0.25)
>>> lin = linearize.tangent(plant, op)
>>> red = linearize.reduced_position_model(lin)
>>> round(red.w0, 1), round(red.zeta, 2)      # rad/s; paper 000's formula: 33.0, 1.08
(28.1, 1.27)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import casadi as ca
import numpy as np
from scipy import optimize

from .equilibrium import (PIN_UNDERLAP, RATE_PER_SCALE, OperatingPoint, centre_balance_pressure,
                          operating_point)
from .errors import InputError, WorkbenchError
from .physics import gas
from .plant import Plant

__all__ = [
    "OperatingPoint", "TangentModel", "PositionModel", "TankTangent",
    "operating_point", "tangent", "reduced_position_model",
    "paper000_w0", "paper000_zeta", "paper000_kv_from_flow",
    "centre_balance_pressure", "tank_equilibrium", "tank_tangent",
    "PIN_UNDERLAP", "RATE_PER_SCALE",
]

@dataclass(frozen=True)
class TangentModel:
    """Exact tangent (small-signal) model dx' = A dx + B du, dy = C dx + D du.

    Matrices are CasADi Jacobians of the plant's ``f`` and ``h`` at ``op``.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    op: OperatingPoint
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    notes: tuple[str, ...] = ()

    @property
    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of A, 1/s, sorted by real part (slowest first)."""
        ev = np.linalg.eigvals(self.A)
        return ev[np.argsort(-ev.real)]

    def output(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(C row, D row) of one output."""
        i = self.output_names.index(name)
        return self.C[i:i + 1, :], self.D[i:i + 1, :]

    def frequency_response(self, omega: np.ndarray, output: str = "x") -> np.ndarray:
        """Complex response of ``output`` to u at angular frequencies ``omega`` (rad/s)."""
        c, d = self.output(output)
        n = self.A.shape[0]
        out = np.empty(len(omega), dtype=complex)
        for k, w in enumerate(omega):
            out[k] = (c @ np.linalg.solve(1j * w * np.eye(n) - self.A, self.B) + d)[0, 0]
        return out

    def to_dict(self) -> dict:
        """JSON-ready dict (SI): the equilibrium, signal names, A, B, C, D as nested lists,
        the eigenvalues (1/s) as ``{"re", "im"}`` pairs and the notes."""
        return {"equilibrium": self.op.to_dict(),
                "states": list(self.state_names), "inputs": list(self.input_names),
                "outputs": list(self.output_names),
                "A": self.A.tolist(), "B": self.B.tolist(), "C": self.C.tolist(),
                "D": self.D.tolist(),
                "eigenvalues": [{"re": float(e.real), "im": float(e.imag)}
                                for e in self.eigenvalues],
                "notes": list(self.notes)}

    def to_control(self, outputs: Sequence[str] | None = None):
        """python-control ``StateSpace`` with signal names (selected outputs)."""
        import control
        outs = list(outputs) if outputs is not None else list(self.output_names)
        idx = [self.output_names.index(o) for o in outs]
        return control.ss(self.A, self.B, self.C[idx, :], self.D[idx, :],
                          states=list(self.state_names), inputs=list(self.input_names),
                          outputs=outs)


def tangent(plant: Plant, op: OperatingPoint | None = None, x: float | None = None) -> TangentModel:
    """Exact tangent model of ``plant`` at ``op`` (or at the equilibrium at ``x``).

    Dry friction is not differentiable at rest; a piston at rest below break-away
    does not respond to small signals at all. The tangent model therefore leaves
    dry friction out (and says so in ``notes``): it describes the piston once it
    slides.
    """
    if op is None:
        if x is None:
            raise InputError("give an operating point or a position x")
        op = operating_point(plant, x)
    notes = []
    model = plant
    if plant.params.has_effect("dry_friction"):
        model = Plant(plant.params.without_effect("dry_friction"))
        notes.append("dry friction left out: not differentiable at rest (a stuck piston "
                     "does not respond to small signals)")
        pnames = model.param_names
        pv = np.array([op.params[plant.param_names.index(nm)] for nm in pnames])
    else:
        pv = op.params
    xs, us, ps = model.x_sym, model.u_sym, model.p_sym
    jac = ca.Function("tangent_abcd", [xs, us, ps],
                      [ca.jacobian(model.xdot_expr, xs), ca.jacobian(model.xdot_expr, us),
                       ca.jacobian(model.y_expr, xs), ca.jacobian(model.y_expr, us)])
    A, B, C, D = (np.asarray(m) for m in jac(op.state, op.u, pv))
    if plant.params.has_effect("valve_deadband"):
        notes.append("valve deadband: at the centre the small-signal valve gain is zero")
    return TangentModel(A=A, B=B, C=C, D=D, op=op, state_names=plant.state_names,
                        input_names=plant.input_names, output_names=plant.output_names,
                        notes=tuple(notes))


@dataclass(frozen=True)
class PositionModel:
    """Reduced model x/u = Kv / (s (s^2/w0^2 + 2 zeta s/w0 + 1)) of paper 000.

    Attributes
    ----------
    kv : velocity gain, m/(V s). w0 : rad/s. zeta : -.
    fit_error : RMS relative error of the fitted frequency response over the band.
    band : (low, high) angular frequencies of the fit, rad/s.
    """

    kv: float
    w0: float
    zeta: float
    fit_error: float
    band: tuple[float, float] = (0.0, 0.0)

    @property
    def t0(self) -> float:
        """Time constant 1/w0, s."""
        return 1.0 / self.w0

    def response(self, omega: np.ndarray) -> np.ndarray:
        s = 1j * np.asarray(omega)
        return self.kv / (s * (s * s / self.w0 ** 2 + 2 * self.zeta * s / self.w0 + 1.0))

    def transfer_function(self):
        """python-control transfer function."""
        import control
        w = self.w0
        return control.tf([self.kv], [1.0 / w ** 2, 2.0 * self.zeta / w, 1.0, 0.0])

    def to_dict(self) -> dict:
        """JSON-ready dict: Kv (m/(V s)), w0 (rad/s), zeta, fit error, fitted band (rad/s)."""
        return {"Kv": float(self.kv), "w0": float(self.w0), "zeta": float(self.zeta),
                "fit_error": float(self.fit_error), "band_rad_s": [float(b) for b in self.band]}


def reduced_position_model(lin: TangentModel, output: str = "x") -> PositionModel:
    """Fit Kv, w0, zeta of paper 000's third-order model to the exact tangent model.

    The fit matches the complex frequency response of ``output``/u (log magnitude
    and phase) over two decades around the dominant oscillatory mode. For the
    basic four-state drive the exact model *is* of this form and the fit is exact;
    with lines, valve dynamics or leakage it is the best third-order description.

    Raises
    ------
    WorkbenchError
        When the command has no small-signal effect on the position (e.g. a valve
        deadband at the centre).
    """
    ev = lin.eigenvalues
    osc = [e for e in ev if abs(e.imag) > 1e-6 and abs(e) > 1e-6]
    nonzero = [e for e in ev if abs(e) > 1e-6]
    if osc:
        w_guess = float(min(abs(e) for e in osc))
    elif nonzero:
        w_guess = float(np.sort(np.abs(nonzero))[min(1, len(nonzero) - 1)])
    else:
        raise WorkbenchError("the tangent model has no dynamics to fit")
    omega = np.logspace(math.log10(w_guess / 30.0), math.log10(w_guess * 3.0), 60)
    h = lin.frequency_response(omega, output)
    if not np.all(np.isfinite(h)) or np.max(np.abs(h)) < 1e-15:
        raise WorkbenchError(
            "the command has no small-signal effect on the position at this operating point "
            + ("(" + "; ".join(lin.notes) + ")" if lin.notes else ""))
    kv0 = float(np.abs(h[0] * 1j * omega[0]))
    zeta0 = 1.0
    if osc:
        e = min(osc, key=abs)
        zeta0 = float(-e.real / abs(e))
    elif len(nonzero) >= 2:
        a, b = sorted(np.abs(nonzero))[:2]
        w_guess = math.sqrt(a * b)
        zeta0 = (a + b) / (2 * w_guess)

    def resid(th):
        kv, w0, z = np.exp(th)
        s = 1j * omega
        hm = kv / (s * (s * s / w0 ** 2 + 2 * z * s / w0 + 1.0))
        r = np.log(hm / h)
        r = np.where(np.abs(r.imag) > np.pi, r - 2j * np.pi * np.round(r.imag / (2 * np.pi)), r)
        return np.concatenate([r.real, r.imag])

    th0 = np.log([max(kv0, 1e-12), w_guess, max(zeta0, 1e-3)])
    sol = optimize.least_squares(resid, th0, method="lm", xtol=1e-14, ftol=1e-14)
    kv, w0, z = np.exp(sol.x)
    err = float(np.sqrt(np.mean(np.abs(resid(sol.x)) ** 2)))
    return PositionModel(kv=float(kv), w0=float(w0), zeta=float(z), fit_error=err,
                         band=(float(omega[0]), float(omega[-1])))


# ---------------------------------------------------------------------- paper 000 formulas
def paper000_w0(area: float, mass: float, pressure: float, stroke: float,
                kappa: float = 1.4) -> float:
    """w0 = sqrt(4 kappa p A^2 / (M Vc)), Vc = A L (paper 000), rad/s."""
    vc = area * stroke
    return math.sqrt(4.0 * kappa * pressure * area ** 2 / (mass * vc))


def paper000_zeta(area: float, mass: float, pressure: float, stroke: float,
                  viscous: float, kappa: float = 1.4) -> float:
    """zeta = (k_f/2) sqrt(Vc / (4 kappa p A^2 M)) (paper 000), -."""
    vc = area * stroke
    return viscous / 2.0 * math.sqrt(vc / (4.0 * kappa * pressure * area ** 2 * mass))


def paper000_kv_from_flow(q_per_volt: float, area: float, pressure: float,
                          temperature: float = gas.T_REF) -> float:
    """Velocity gain Kv = r T (dq/du) / (p A), m/(V s), of a chamber held at pressure p."""
    return gas.R_AIR * temperature * q_per_volt / (pressure * area)


# ---------------------------------------------------------------------- paper 003 tank
@dataclass(frozen=True)
class TankTangent:
    """Tangent model of a tank fed by a valve: p* = G / (1 + tau s) u* (paper 003).

    Attributes
    ----------
    p_e : equilibrium pressure, Pa. u_e : command, V.
    cp : -dq/dp, kg/(s Pa). gu : dq/du, kg/(s V). tau : s. gain : G = Gu/Cp, Pa/V.
    """

    p_e: float
    u_e: float
    cp: float
    gu: float
    tau: float
    gain: float


def tank_equilibrium(flow: Callable, u_e: float, p_low: float, p_high: float) -> float:
    """Pressure p_e (Pa) with flow(p_e, u_e) = 0, by bracketing in [p_low, p_high]."""
    g = lambda pp: float(flow(pp, u_e))  # noqa: E731
    if g(p_low) * g(p_high) > 0:
        raise WorkbenchError(f"no equilibrium pressure between {p_low:g} and {p_high:g} Pa "
                             f"at u = {u_e:g} V")
    return optimize.brentq(g, p_low, p_high, xtol=1e-10, rtol=1e-15)


def tank_tangent(flow: Callable, volume: float, u_e: float, p_e: float | None = None,
                 k: float = 1.2, temperature: float = gas.T_REF,
                 p_range: tuple[float, float] = (gas.P_ATM, 10e5)) -> TankTangent:
    """Cp, Gu, tau, G of a tank of ``volume`` (m^3) fed by ``flow(p, u)`` (kg/s).

    ``flow`` is any function written with the physics functions (it is traced with
    CasADi SX); Cp and Gu are its exact partial derivatives at the equilibrium.
    tau = V / (k r T Cp), G = Gu / Cp.
    """
    if p_e is None:
        p_e = tank_equilibrium(flow, u_e, *p_range)
    p = ca.SX.sym("p")
    u = ca.SX.sym("u")
    q = flow(p, u)
    d = ca.Function("d", [p, u], [ca.jacobian(q, p), ca.jacobian(q, u)])
    dqdp, dqdu = (float(v) for v in d(p_e, u_e))
    cp, gu = -dqdp, dqdu
    tau = volume / (k * gas.R_AIR * temperature * cp)
    return TankTangent(p_e=float(p_e), u_e=float(u_e), cp=cp, gu=gu, tau=tau, gain=gu / cp)
