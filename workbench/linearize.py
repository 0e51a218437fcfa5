"""Equilibria, exact tangent models and the reduced position model of paper 000.

All derivatives come from CasADi (automatic differentiation of the symbolic plant),
never from finite differences.

Examples
--------
>>> from workbench import Plant, linearize
>>> plant = Plant.from_toml("designs/plants/situm_rodless.toml")   # doctest: +SKIP
>>> op = linearize.operating_point(plant, x=0.25)                  # doctest: +SKIP
>>> lin = linearize.tangent(plant, op)                             # doctest: +SKIP
>>> red = linearize.reduced_position_model(lin)                    # doctest: +SKIP
>>> round(red.w0, 1), round(red.zeta, 2)                           # doctest: +SKIP
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import casadi as ca
import numpy as np
from scipy import optimize

from .errors import InputError, WorkbenchError
from .physics import gas
from .plant import Plant

__all__ = [
    "OperatingPoint", "TangentModel", "PositionModel", "TankTangent",
    "operating_point", "tangent", "reduced_position_model",
    "paper000_w0", "paper000_zeta", "paper000_kv_from_flow",
    "centre_balance_pressure", "tank_equilibrium", "tank_tangent",
]

#: Edge leakage (fraction of full opening) used only to pin the equilibrium
#: pressures of a closed-centre valve; small enough that the pressures equal the
#: zero-leak limit to ~1e-6 relative.
PIN_UNDERLAP = 1e-4

_SCALES = {"x": 0.1, "v": 0.1, "p_a": 1e5, "p_b": 1e5, "spool": 1.0, "spool_rate": 100.0,
           "T_a": 300.0, "T_b": 300.0, "p_s": 1e5}


def _scale_of(name: str) -> float:
    if name in _SCALES:
        return _SCALES[name]
    if "_p" in name:
        return 1e5
    if "_q" in name:
        return 1e-3
    return 1.0


@dataclass(frozen=True)
class OperatingPoint:
    """An equilibrium of the plant: piston at rest at ``x`` under command ``u``.

    Attributes
    ----------
    x : position, m. u : command, V. p_a, p_b : chamber pressures, Pa.
    state : full state vector. params : parameter vector used.
    residual : largest |xdot_i| / scale_i at the point (should be ~0).
    """

    x: float
    u: float
    p_a: float
    p_b: float
    state: np.ndarray
    params: np.ndarray
    residual: float
    state_names: tuple[str, ...] = ()

    def as_dict(self) -> dict:
        return {"x": self.x, "u": self.u, "p_a": self.p_a, "p_b": self.p_b,
                "state": dict(zip(self.state_names, map(float, self.state))),
                "residual": self.residual}


def centre_balance_pressure(p_s: float, p_atm: float, b: float, t: float = gas.T_REF) -> float:
    """Pressure at which equal openings to supply and to exhaust pass equal flow, Pa.

    This is where a closed-centre valve with vanishing symmetric leakage holds a
    chamber, and the pressure at which the valve's one-sided flow gains agree, so
    the tangent model at the centre is well defined there.
    """
    def g(p):
        return (gas.iso6358_flow(1.0, b, p_s, p, t, t) - gas.iso6358_flow(1.0, b, p, p_atm, t, t))
    return optimize.brentq(lambda p: float(g(p)), p_atm * (1 + 1e-9), p_s * (1 - 1e-9),
                           xtol=1e-9, rtol=1e-14)


def operating_point(plant: Plant, x: float, p: Sequence[float] | None = None,
                    u_guess: float | None = None) -> OperatingPoint:
    """Equilibrium of the plant with the piston at rest at ``x`` (m).

    Unknowns are the command and every state but the position (velocity fixed at
    zero); equations are all state derivatives but dx/dt. Dry friction is left out
    (at rest it can hold any force below break-away, so it does not pin anything),
    and every valve edge gets a vanishing leakage (:data:`PIN_UNDERLAP`) so that the
    pressures of a closed-centre valve are the zero-leak limit rather than arbitrary.

    Raises
    ------
    InputError
        ``x`` outside the stroke.
    WorkbenchError
        No equilibrium found (e.g. an external force the valve cannot hold).
    """
    if not 0.0 <= x <= plant.stroke:
        raise InputError(f"position {x:g} m is outside the stroke [0, {plant.stroke:g}] m",
                         location="--x")
    prm = plant.params
    pv = np.asarray(plant.p0 if p is None else p, dtype=float)
    model = plant.with_friction("smooth") if prm.has_effect("dry_friction") else plant
    f_reg = model.regularised_f(PIN_UNDERLAP)
    names = plant.state_names
    n = len(names)
    free = [i for i in range(n) if names[i] not in ("x", "v")]
    eqs = [i for i in range(n) if names[i] != "x"]
    xs = np.array([_scale_of(names[i]) for i in free])
    fs = np.array([_scale_of(names[i]) * 100.0 for i in eqs])  # ~1 % of scale per 10 ms
    center = prm["valve.command_center"] + prm.get("valve.null_offset", 0.0)
    span = prm["valve.command_span"]

    z = ca.SX.sym("z", len(free) + 1)
    full = [0.0] * n
    full[names.index("x")] = x
    for j, i in enumerate(free):
        full[i] = z[j] * xs[j]
    u_sym = center + z[-1] * span
    anchor = ca.SX.sym("anchor", z.numel())

    def residual_function(fun_x):
        """Scaled xdot rows, then weak rows: u towards the centre and every unknown
        towards ``anchor`` (the pinned solution), so that directions the real model
        leaves undetermined (closed centre: the pressure level) stay where the
        pinned model put them instead of drifting to nonsense."""
        xdot = fun_x(ca.vertcat(*full), u_sym, pv)
        res = ca.vertcat(*[xdot[i] / fs[k] for k, i in enumerate(eqs)], 1e-6 * z[-1],
                         1e-8 * (z[:-1] - anchor[:-1]))
        fun = ca.Function("res", [z, anchor], [res, ca.jacobian(res, z)])
        return lambda zz, ref=None: fun(zz, zz if ref is None else ref)

    rf = residual_function(f_reg)
    rf_real_anchored = residual_function(model.f)

    p_e = centre_balance_pressure(prm["supply.pressure"], prm["gas.atmospheric_pressure"],
                                  prm["valve.critical_pressure_ratio"], prm["gas.temperature"])
    guess = np.zeros(len(free) + 1)
    for j, i in enumerate(free):
        nm = names[i]
        if nm in ("p_a", "p_b") or nm.startswith("line_a_p") or nm.startswith("line_b_p"):
            guess[j] = p_e / xs[j]
        elif nm in ("T_a", "T_b"):
            guess[j] = prm["gas.temperature"] / xs[j]
        elif nm == "spool":
            guess[j] = (center if u_guess is None else u_guess) / xs[j]
        elif nm == "p_s":
            guess[j] = prm["supply.pressure"] / xs[j]
    if u_guess is not None:
        guess[-1] = (u_guess - center) / span

    n_eq = len(eqs)

    def solve(resfun, start):
        sol = optimize.least_squares(lambda zz: np.asarray(resfun(zz)[0]).ravel(), start,
                                     jac=lambda zz: np.asarray(resfun(zz)[1]), method="lm",
                                     xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
        return sol.x, float(np.max(np.abs(np.asarray(resfun(sol.x)[0]).ravel()[:n_eq])))

    # 1) the pinned model: well posed even for a closed centre without leakage
    zz, _ = solve(rf, guess)
    # 2) refine on the real model from there. Without leakage the pinned point already
    #    satisfies it (the step is ~0); with physical leakage the real balance differs
    #    from the pinned one and this step moves to it.
    #    A leak-dominated closed centre settles far away (at atmosphere), so a
    #    second start there is tried as well; the smaller residual wins.
    pinned = zz.copy()
    zz_real, resid = solve(lambda q: rf_real_anchored(q, pinned), zz)
    if resid > 1e-9:
        start = zz.copy()
        for j, i in enumerate(free):
            nm = names[i]
            if nm in ("p_a", "p_b") or nm.startswith("line_a_p") or nm.startswith("line_b_p"):
                start[j] = prm["gas.atmospheric_pressure"] / xs[j]
        zz_alt, resid_alt = solve(lambda q, a=start.copy(): rf_real_anchored(q, a), start)
        if resid_alt < resid:
            zz_real, resid = zz_alt, resid_alt
    if np.all(np.isfinite(zz_real)):
        zz = zz_real
    state = np.zeros(n)
    state[names.index("x")] = x
    for j, i in enumerate(free):
        state[i] = zz[j] * xs[j]
    u = center + zz[-1] * span
    if not np.all(np.isfinite(state)) or resid > 1e-6:
        raise WorkbenchError(
            f"no equilibrium found at x = {x:g} m (largest scaled residual {resid:.2g}); "
            "can the valve hold the load there within its command range?")
    return OperatingPoint(x=float(x), u=float(u), p_a=float(state[names.index("p_a")]),
                          p_b=float(state[names.index("p_b")]), state=state, params=pv,
                          residual=resid, state_names=names)


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

    def as_dict(self) -> dict:
        return {"Kv": self.kv, "w0": self.w0, "zeta": self.zeta,
                "fit_error": self.fit_error, "band_rad_s": list(self.band)}


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
