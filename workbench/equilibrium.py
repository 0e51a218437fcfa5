"""Operating points and initial states of a plant.

An operating point is an equilibrium with the piston at rest at a chosen position;
an initial state is a consistent state vector to start a simulation from. Both
need a nonlinear solve, which is why they live here and not in :mod:`workbench.plant`:
the plant composes the physics, this module solves it. This module never imports
:mod:`workbench.plant` at run time (the plant is passed in), so ``plant.py`` can
delegate :meth:`workbench.plant.Plant.initial_state` here without an import circle;
:mod:`workbench.linearize` re-exports the public names.

Examples
--------
>>> from workbench import Plant, equilibrium
>>> plant = Plant.from_toml("designs/plants/situm_rodless_nominal.toml")
>>> op = equilibrium.operating_point(plant, x=0.25)
>>> x0 = equilibrium.initial_state(plant, 0.25)
>>> op.u, round(op.p_a / 1e5, 3), round(op.p_b / 1e5, 3)   # V, bar: symmetric at mid-stroke
(5.0, 3.786, 3.786)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Sequence

import casadi as ca
import numpy as np
from scipy import optimize

from .errors import InputError, WorkbenchError
from .physics import gas, valve

if TYPE_CHECKING:  # types only: the plant is passed in, never imported at run time
    from .plant import Plant

__all__ = [
    "OperatingPoint", "operating_point", "initial_state", "centre_balance_pressure",
    "affine_balance_pressure", "rest_pressure", "PIN_UNDERLAP", "RATE_PER_SCALE",
]

#: Edge leakage (fraction of full opening) used only to pin the equilibrium
#: pressures of a closed-centre valve; small enough that the pressures equal the
#: zero-leak limit to ~1e-6 relative.
PIN_UNDERLAP = 1e-4

#: Rate, 1/s, that turns a state's scale (:attr:`workbench.plant.Signal.scale`) into
#: the scale of its derivative in the equilibrium residuals: a residual of 1 means
#: the state drifts by 1 % of its scale in 10 ms.
RATE_PER_SCALE = 100.0


@dataclass(frozen=True)
class OperatingPoint:
    """An equilibrium of the plant: piston at rest at ``x`` under command ``u``.

    Attributes
    ----------
    x : position, m. u : command, V. p_a, p_b : chamber pressures, Pa.
    state : full state vector. params : parameter vector used.
    residual : largest |xdot_i| / (RATE_PER_SCALE scale_i) at the point (should be ~0).
    """

    x: float
    u: float
    p_a: float
    p_b: float
    state: np.ndarray
    params: np.ndarray
    residual: float
    state_names: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        """JSON-ready dict (SI): x, u, p_a, p_b, the state by name, the residual."""
        return {"x": float(self.x), "u": float(self.u), "p_a": float(self.p_a),
                "p_b": float(self.p_b),
                "state": dict(zip(self.state_names, map(float, self.state))),
                "residual": float(self.residual)}


def centre_balance_pressure(p_s: float, p_atm: float, b: float, t: float = gas.T_REF) -> float:
    """Pressure at which equal openings to supply and to exhaust pass equal flow, Pa.

    This is where a closed-centre valve with vanishing symmetric leakage holds a
    chamber, and the pressure at which the valve's one-sided flow gains agree, so
    the tangent model at the centre is well defined there.

    Parameters
    ----------
    p_s, p_atm : supply and atmospheric pressure, Pa. b : critical pressure ratio, -.
    t : gas temperature, K.
    """
    def g(p):
        return (gas.iso6358_flow(1.0, b, p_s, p, t, t) - gas.iso6358_flow(1.0, b, p, p_atm, t, t))
    return optimize.brentq(lambda p: float(g(p)), p_atm * (1 + 1e-9), p_s * (1 - 1e-9),
                           xtol=1e-9, rtol=1e-14)


def affine_balance_pressure(psi_in: Sequence[float], psi_out: Sequence[float], p_s: float,
                            p_atm: float, pressure_scale: float = 1e5) -> float | None:
    """Pressure, Pa, where the input-affine law's inlet and exhaust gains agree.

    psi_in(p) = psi_out(p) is where :meth:`workbench.plant.Plant.regularised_f`'s
    pin holds a closed centre under that law. ``None`` when the fitted polynomials
    do not cross between ``p_atm`` and ``p_s``.

    Parameters
    ----------
    psi_in, psi_out : ascending coefficients in ``p / pressure_scale`` (kg/s per unit Gamma).
    p_s, p_atm : supply and atmospheric pressure, Pa. pressure_scale : Pa (1e5: bar).
    """
    def g(p):
        pn = p / pressure_scale
        return float(valve.polyval(psi_in, pn) - valve.polyval(psi_out, pn))
    lo, hi = p_atm * (1 + 1e-9), p_s * (1 - 1e-9)
    if not g(lo) * g(hi) < 0:
        return None
    return optimize.brentq(g, lo, hi, xtol=1e-9, rtol=1e-14)


def rest_pressure(params: Any) -> float:
    """Chamber pressure, Pa, at which the plant's valve at its centre holds a chamber.

    The zero-leak limit of a closed-centre valve: :func:`centre_balance_pressure` for
    the four-edge ISO 6358 law, :func:`affine_balance_pressure` for the input-affine
    law (falling back to the ISO balance when the fitted gains do not cross).
    Physical leakage moves the real equilibrium away from it
    (:func:`operating_point` finds that one).

    Parameters
    ----------
    params : workbench.params.PlantParams (or any mapping of the dotted keys).
    """
    p_s, p_atm = params["supply.pressure"], params["gas.atmospheric_pressure"]
    if params["valve.law"] == "input_affine":
        p = affine_balance_pressure(params["valve.affine_psi_in"], params["valve.affine_psi_out"],
                                    p_s, p_atm)
        if p is not None:
            return float(p)
    return float(centre_balance_pressure(p_s, p_atm, params["valve.critical_pressure_ratio"],
                                         params["gas.temperature"]))


def _residual_function(fun_x: ca.Function, names, x: float, free, eqs, xs, fs, center: float,
                       span: float, pv: np.ndarray) -> Callable:
    """Scaled xdot rows, then weak rows: u towards the centre and every unknown
    towards ``anchor`` (the pinned solution), so that directions the real model
    leaves undetermined (closed centre: the pressure level) stay where the
    pinned model put them instead of drifting to nonsense."""
    n = len(names)
    z = ca.SX.sym("z", len(free) + 1)
    anchor = ca.SX.sym("anchor", z.numel())
    full = [0.0] * n
    full[names.index("x")] = x
    for j, i in enumerate(free):
        full[i] = z[j] * xs[j]
    xdot = fun_x(ca.vertcat(*full), center + z[-1] * span, pv)
    res = ca.vertcat(*[xdot[i] / fs[k] for k, i in enumerate(eqs)], 1e-6 * z[-1],
                     1e-8 * (z[:-1] - anchor[:-1]))
    fun = ca.Function("res", [z, anchor], [res, ca.jacobian(res, z)])
    return lambda zz, ref=None: fun(zz, zz if ref is None else ref)


def _solve(resfun: Callable, start: np.ndarray, n_eq: int) -> tuple[np.ndarray, float]:
    """Levenberg-Marquardt on ``resfun``; returns (z, largest |xdot row|)."""
    sol = optimize.least_squares(lambda zz: np.asarray(resfun(zz)[0]).ravel(), start,
                                 jac=lambda zz: np.asarray(resfun(zz)[1]), method="lm",
                                 xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
    return sol.x, float(np.max(np.abs(np.asarray(resfun(sol.x)[0]).ravel()[:n_eq])))


def operating_point(plant: "Plant", x: float, p: Sequence[float] | None = None,
                    u_guess: float | None = None) -> OperatingPoint:
    """Equilibrium of the plant with the piston at rest at ``x`` (m).

    Unknowns are the command and every state but the position (velocity fixed at
    zero); equations are all state derivatives but dx/dt, each divided by
    :data:`RATE_PER_SCALE` times its state's scale (:meth:`Plant.state_scales`).
    Dry friction is left out (at rest it can hold any force below break-away, so it
    does not pin anything), and every valve edge gets a vanishing leakage
    (:data:`PIN_UNDERLAP`) so that the pressures of a closed-centre valve are the
    zero-leak limit rather than arbitrary. The solve starts from the plant's rest
    state (:meth:`Plant.rest_state`).

    Parameters
    ----------
    plant : Plant. x : position, m. p : parameter vector (default ``plant.p0``).
    u_guess : starting command, V (default: the valve centre).

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
    names = plant.state_names
    n = len(names)
    ix, iv = plant.states_of_kind("position")[0], plant.states_of_kind("velocity")[0]
    free = [i for i in range(n) if i not in (ix, iv)]
    eqs = [i for i in range(n) if i != ix]
    scales = plant.state_scales()
    xs, fs = scales[free], scales[eqs] * RATE_PER_SCALE   # ~1 % of scale per 10 ms
    center = float(plant.inputs[0].rest)
    span = float(plant.inputs[0].scale)
    args = (names, x, free, eqs, xs, fs, center, span, pv)
    rf = _residual_function(model.regularised_f(PIN_UNDERLAP), *args)
    rf_real_anchored = _residual_function(model.f, *args)

    rest = plant.rest_state(u=center if u_guess is None else u_guess)
    guess = np.append(rest[free] / xs, 0.0 if u_guess is None else (u_guess - center) / span)
    n_eq = len(eqs)
    # 1) the pinned model: well posed even for a closed centre without leakage
    zz, _ = _solve(rf, guess, n_eq)
    # 2) refine on the real model from there. Without leakage the pinned point already
    #    satisfies it (the step is ~0); with physical leakage the real balance differs
    #    from the pinned one and this step moves to it.
    #    A leak-dominated closed centre settles far away (at atmosphere), so a
    #    second start there is tried as well; the smaller residual wins.
    pinned = zz.copy()
    zz_real, resid = _solve(lambda q: rf_real_anchored(q, pinned), zz, n_eq)
    if resid > 1e-9:
        start = zz.copy()
        held = set(plant.states_of_kind("pressure", parts=("chamber", "line")))
        for j, i in enumerate(free):
            if i in held:
                start[j] = prm["gas.atmospheric_pressure"] / xs[j]
        zz_alt, resid_alt = _solve(lambda q, a=start.copy(): rf_real_anchored(q, a), start, n_eq)
        if resid_alt < resid:
            zz_real, resid = zz_alt, resid_alt
    if np.all(np.isfinite(zz_real)):
        zz = zz_real
    state = np.zeros(n)
    state[ix] = x
    state[free] = zz[:-1] * xs
    u = center + zz[-1] * span
    if not np.all(np.isfinite(state)) or resid > 1e-6:
        raise WorkbenchError(
            f"no equilibrium found at x = {x:g} m (largest scaled residual {resid:.2g}); "
            "can the valve hold the load there within its command range?")
    return OperatingPoint(x=float(x), u=float(u), p_a=float(state[names.index("p_a")]),
                          p_b=float(state[names.index("p_b")]), state=state, params=pv,
                          residual=resid, state_names=names)


def initial_state(plant: "Plant", x0: float, p_a: float | None = None, p_b: float | None = None,
                  v0: float = 0.0, u0: float | None = None) -> np.ndarray:
    """A consistent state of ``plant`` at position ``x0`` (m).

    Pressures ``p_a``, ``p_b`` (Pa) default to the equilibrium of the valve at rest at
    ``x0`` (:func:`operating_point`); the states effects add take their rest values
    given those (:meth:`Plant.rest_state`): line nodes their chamber's pressure, line
    flows zero, temperatures the gas temperature, the spool the command ``u0`` (V,
    default: the equilibrium command) and the supply its set pressure. ``v0`` in m/s.
    """
    if not 0.0 <= x0 <= plant.stroke:
        raise InputError(f"initial position {x0:g} m is outside the stroke [0, {plant.stroke:g}] m")
    if p_a is None or p_b is None or u0 is None:
        op = operating_point(plant, x0)
        p_a = op.p_a if p_a is None else p_a
        p_b = op.p_b if p_b is None else p_b
        u0 = op.u if u0 is None else u0
    base = plant.rest_state(u=u0)
    base[plant.state_index("x")] = x0
    base[plant.state_index("v")] = v0
    base[plant.state_index("p_a")] = p_a
    base[plant.state_index("p_b")] = p_b
    return plant.rest_state(base, u0)
