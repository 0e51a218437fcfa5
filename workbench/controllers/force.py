"""Force model of the drive, pressure-trajectory inversion and force tracking.

The pneumatic force on the piston (:func:`workbench.physics.piston.pneumatic_force`)

    F = p_a A_a - p_b A_b - p_atm (A_a - A_b)

changes with the chamber pressures, which follow dp_i/dt = k/V_i (r T q_i - p_i dV_i/dt)
(:mod:`workbench.physics.chamber`). With the valve law affine in the command
characteristic G on each side of the centre (:mod:`.inversion`), port a taking
q_a = phi(p_a) + psi(p_a, sgn G) G and port b the mirrored q_b = phi(p_b) - psi(p_b, -sgn G) G,
the force rate is affine in G as well (:class:`DriveModel`):

    dF/dt = f0(x, v, p_a, p_b) + g(x, p_a, p_b, sgn G) G,   g > 0 between atmosphere and supply.

That is the third state of the feedback-linearising position controller
(:mod:`.feedback_linearizing`) and the plant of the force tracker (:class:`ForceTracker`).

Pressure trajectories (paper 003, conclusion): a wanted force fixes one combination
of the two pressures; the other, the pressure level, is free only if each chamber has
its own valve. :func:`pressure_plan` computes p_a(t), p_b(t) for a force (or, through
:func:`motion_force`, a position) trajectory under a rule for the level --

* ``"mean"``: constant mean pressure (p_a + p_b)/2 (constant stiffness of the air springs);
* ``"min_air"``: the lower chamber held at a floor pressure (least air);
* ``"single_valve"``: what one 5/3 valve does -- its single spool fills one chamber
  while it exhausts the other, so the level is not free but follows from the
  valve law (the zero dynamics of the force); the plan integrates it;

then the chamber mass flows from the chamber equation and the commands from the
valve inversion.

Examples
--------
>>> from workbench import Plant
>>> from workbench.controllers.force import DriveModel, pressure_plan
>>> plant = Plant.from_toml("tests/data/plants/input_affine.toml")
>>> model = DriveModel.from_plant(plant)
>>> t = np.linspace(0, 2, 2001)
>>> plan = pressure_plan(model, t, 100 * np.sin(np.pi * t) ** 2, x=0.25)
>>> round(plan.air_mass * 1e3, 2)              # g of air drawn from the supply over the 2 s
0.52
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from ..errors import InputError
from ..physics import chamber, piston
from ..physics.gas import R_AIR
from .inversion import ValveInversion

__all__ = ["DriveModel", "PressurePlan", "PLAN_RULES", "pressure_plan", "motion_force",
           "ForceTracker", "force_tracker", "smooth_profile"]

#: Rules for the free pressure level of :func:`pressure_plan`.
PLAN_RULES = ("mean", "min_air", "single_valve")


def _positive(name: str, value: Any, unit: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number in {unit}, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} must be a finite number > 0 {unit}, got {value!r}")
    return v


def _arr(x):
    """Floats stay floats (fast scalar arithmetic), anything else becomes an array."""
    if isinstance(x, float):
        return x
    if isinstance(x, (int, np.floating, np.integer)):
        return float(x)
    return np.asarray(x, dtype=float)


def _clip(x, lo, hi):
    x = _arr(x)
    return min(max(x, lo), hi) if isinstance(x, float) else np.clip(x, lo, hi)


# ---------------------------------------------------------------------- the model
@dataclass(frozen=True)
class DriveModel:
    """Cylinder, load and valve as a controller sees them (SI).

    The control model: chambers with the polytropic balance, the piston with its
    mass, viscous friction and constant external force. No dry friction, lines,
    spool dynamics, leakage or heat transfer -- whatever the plant it came from has.

    Attributes
    ----------
    valve : ValveInversion
        The valve law and its inverse.
    area_a, area_b : m^2. stroke : m. dead_a, dead_b : m^3 (chamber volumes at the
        ends). mass : kg. viscous : N s/m. external_force : N (opposes +x).
    polytropic_index : -. temperature : K. p_atm, p_s : Pa.
    """

    valve: ValveInversion
    area_a: float
    area_b: float
    stroke: float
    dead_a: float
    dead_b: float
    mass: float
    viscous: float
    external_force: float
    polytropic_index: float
    temperature: float
    p_atm: float
    p_s: float

    @classmethod
    def from_plant(cls, plant, valve: ValveInversion | None = None, law: str | None = "input_affine",
                   compensate: bool = False) -> "DriveModel":
        """The control model of a plant.

        Parameters
        ----------
        plant : workbench.Plant
        valve : ValveInversion, optional
            Default :meth:`ValveInversion.from_plant(plant, law, compensate)
            <workbench.controllers.inversion.ValveInversion.from_plant>`: the
            input-affine law (fitted when the plant has the four-edge valve).
        law : {"input_affine", "iso6358", None}
            Valve law of the model (None: the plant's).
        compensate : bool
            Let the command map include the plant's deadband and null offset. Default
            False: the controller does not know them (an unmodelled effect).
        """
        prm = plant.params
        if valve is None:
            valve = ValveInversion.from_plant(plant, law=law, compensate=compensate)
        return cls(valve=valve, area_a=plant.area_a, area_b=plant.area_b, stroke=plant.stroke,
                   dead_a=float(prm["cylinder.dead_volume_a"]),
                   dead_b=float(prm["cylinder.dead_volume_b"]),
                   mass=float(prm["load.mass"]), viscous=float(prm["load.viscous_friction"]),
                   external_force=float(prm.get("load.external_force", 0.0) or 0.0),
                   polytropic_index=float(prm["gas.polytropic_index"]),
                   temperature=float(prm["gas.temperature"]),
                   p_atm=float(prm["gas.atmospheric_pressure"]),
                   p_s=float(prm["supply.pressure"]))

    # ------------------------------------------------------------ algebra
    # Written for floats (the controllers call them once per sample, where numpy's
    # per-call overhead dominates) and arrays alike.
    def volumes(self, x, v=0.0):
        """(V_a, V_b, dV_a/dt, dV_b/dt), m^3 and m^3/s; x clipped to the stroke."""
        x = _clip(x, 0.0, self.stroke)
        v = v if isinstance(v, float) else np.asarray(v, dtype=float)
        return chamber.volumes(x, v, self.area_a, self.area_b, self.stroke,
                               self.dead_a, self.dead_b)

    def force(self, p_a, p_b):
        """Net pneumatic force along +x, N."""
        return piston.pneumatic_force(_arr(p_a), _arr(p_b), self.area_a, self.area_b,
                                      self.p_atm)

    def acceleration(self, v, p_a, p_b):
        """Model acceleration (F - beta v - F_ext)/m, m/s^2 (away from the end stops)."""
        return (self.force(p_a, p_b) - self.viscous * _arr(v) - self.external_force) / self.mass

    @property
    def force_range(self) -> tuple[float, float]:
        """(lowest, highest) pneumatic force with the chambers between atmosphere and supply, N."""
        return (float(self.force(self.p_atm, self.p_s)), float(self.force(self.p_s, self.p_atm)))

    def pressures_for_force(self, force, level):
        """(p_a, p_b) with the given force (N) and mean pressure ``level`` (p_a + p_b)/2 (Pa)."""
        fp = np.asarray(force, dtype=float) + self.p_atm * (self.area_a - self.area_b)
        two = 2.0 * np.asarray(level, dtype=float)
        p_a = (fp + two * self.area_b) / (self.area_a + self.area_b)
        return p_a, two - p_a

    def force_rate_terms(self, x, v, p_a, p_b):
        """(f0, g_plus, g_minus): dF/dt = f0 + g G with g = g_plus for G >= 0, g_minus for G < 0.

        G is the command characteristic on port A (port B sees -G). Units: f0 in N/s,
        g in N/s per unit G. The valve's authority is that of
        :meth:`ValveInversion.authority` (never below a floor), so that the command the
        inversion asks for keeps its direction where the law extrapolates.
        """
        p_a, p_b = _arr(p_a), _arr(p_b)
        va, vb, dva, dvb = self.volumes(x, v)
        c = self.polytropic_index
        rT = R_AIR * self.temperature
        phi_a, in_a, out_a = self.valve.authority(p_a)
        phi_b, in_b, out_b = self.valve.authority(p_b)
        ka = self.area_a * c / va
        kb = self.area_b * c / vb
        f0 = ka * (rT * phi_a - p_a * dva) - kb * (rT * phi_b - p_b * dvb)
        g_plus = rT * (ka * in_a + kb * out_b)      # a fills, b exhausts
        g_minus = rT * (ka * out_a + kb * in_b)     # a exhausts, b fills
        return f0, g_plus, g_minus

    def gamma_for_force_rate(self, rate, x, v, p_a, p_b):
        """G that makes dF/dt = ``rate`` (N/s) at this state (not yet clipped; +-inf
        where the valve has no authority in the needed direction)."""
        f0, gp, gm = self.force_rate_terms(x, v, p_a, p_b)
        d = _arr(rate) - f0
        if isinstance(d, float):
            g = gp if d >= 0 else gm
            return d / g if g > 0 else math.copysign(math.inf, d)
        g = np.where(d >= 0, gp, gm)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(g > 0, d / g, np.sign(d) * np.inf)

    def pressure_rates(self, x, v, p_a, p_b, G):
        """(dp_a/dt, dp_b/dt), Pa/s, with characteristic G on port A (-G on port B)."""
        p_a, p_b, G = _arr(p_a), _arr(p_b), _arr(G)
        va, vb, dva, dvb = self.volumes(x, v)
        c = self.polytropic_index
        phi_a, in_a, out_a = self.valve.terms(p_a)
        phi_b, in_b, out_b = self.valve.terms(p_b)
        if isinstance(G, float):
            q_a = phi_a + (in_a if G >= 0 else out_a) * G
            q_b = phi_b - (out_b if G >= 0 else in_b) * G
        else:
            q_a = phi_a + np.where(G >= 0, in_a, out_a) * G
            q_b = phi_b - np.where(G >= 0, out_b, in_b) * G
        return (chamber.pressure_rate(p_a, va, dva, q_a, c, self.temperature),
                chamber.pressure_rate(p_b, vb, dvb, q_b, c, self.temperature))

    def chamber_flows(self, x, v, p_a, p_b, dp_a, dp_b):
        """Net mass flows (kg/s) into a and b that give the pressure rates dp_a, dp_b (Pa/s)."""
        va, vb, dva, dvb = self.volumes(x, v)
        c, T = self.polytropic_index, self.temperature
        return (chamber.inflow_for_pressure_rate(np.asarray(p_a), va, dva, np.asarray(dp_a), c, T),
                chamber.inflow_for_pressure_rate(np.asarray(p_b), vb, dvb, np.asarray(dp_b), c, T))

    def balance_pressure(self) -> float:
        """Pressure (Pa) where the valve fills and exhausts a chamber equally fast,
        psi_in(p) = psi_out(p) -- where a closed-centre 5/3 valve holds both chambers
        at rest (phi = 0), and the natural mean pressure of a force plan."""
        lo, hi = self.p_atm * (1 + 1e-9), self.p_s * (1 - 1e-9)

        def h(p):
            _, a, b = self.valve.terms(p)
            return float(a - b)
        if h(lo) * h(hi) > 0:
            return 0.5 * (self.p_atm + self.p_s)
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if h(lo) * h(mid) <= 0:
                hi = mid
            else:
                lo = mid
            if hi - lo < 1e-6:
                break
        return 0.5 * (lo + hi)


# ---------------------------------------------------------------------- trajectories
def smooth_profile(points: Sequence[tuple[float, float]]) -> Callable[[Any], np.ndarray]:
    """A smooth function through (time s, value) break points.

    Between consecutive points the value moves along a cosine blend
    v0 + (v1 - v0)(1 - cos(pi tau))/2 (zero slope at both ends); equal values hold.
    Before the first and after the last point it holds. The result is a callable
    f(t) (arrays allowed) with ``f.duration`` (s) and ``f.derivative(t)``.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2 or np.any(np.diff(pts[:, 0]) <= 0):
        raise InputError("a smooth profile needs >= 2 (time, value) points with increasing times")
    tt, vv = pts[:, 0], pts[:, 1]

    def parts(t):
        t = np.asarray(t, dtype=float)
        i = np.clip(np.searchsorted(tt, t, side="right") - 1, 0, len(tt) - 2)
        h = tt[i + 1] - tt[i]
        tau = np.clip((t - tt[i]) / h, 0.0, 1.0)
        return i, h, tau

    def f(t):
        i, _, tau = parts(t)
        return vv[i] + (vv[i + 1] - vv[i]) * 0.5 * (1.0 - np.cos(np.pi * tau))

    def df(t):
        i, h, tau = parts(t)
        inside = (np.asarray(t) > tt[0]) & (np.asarray(t) < tt[-1])
        return np.where(inside, (vv[i + 1] - vv[i]) * 0.5 * np.pi / h * np.sin(np.pi * tau), 0.0)

    f.duration = float(tt[-1])
    f.derivative = df
    f.points = pts
    return f


def motion_force(model: DriveModel, time, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Force (N) a position trajectory needs: F = m a + beta v + F_ext.

    ``x`` (m) sampled at ``time`` (s) is differentiated numerically (second-order
    central differences), so sample it finely and smoothly. Returns (force, v, a).
    """
    t = np.asarray(time, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.shape != x.shape or t.ndim != 1 or len(t) < 3:
        raise InputError("time and x must be 1-D arrays of the same length (>= 3)")
    v = np.gradient(x, t, edge_order=2)
    a = np.gradient(v, t, edge_order=2)
    return model.mass * a + model.viscous * v + model.external_force, v, a


@dataclass(frozen=True)
class PressurePlan:
    """Chamber pressure trajectories for a force trajectory (:func:`pressure_plan`).

    Attributes
    ----------
    rule : str. time : (N,) s. force : (N,) N wanted. x, v : (N,) m, m/s.
    p_a, p_b : (N,) Pa. dp_a, dp_b : (N,) Pa/s.
    q_a, q_b : (N,) kg/s, net mass flow into each chamber the pressures need.
    command_a, command_b : (N,) V: the command that makes port A pass q_a at p_a,
        and port B pass q_b at p_b, of the model's valve. With one 5/3 valve for both
        chambers they must agree -- only the ``single_valve`` plan does so; the
        others need one valve per chamber (chamber a on port A of its valve,
        chamber b on port B of another).
    saturated : (N,) bool, a wanted flow beyond what the valve passes.
    air_mass : kg drawn from the supply, integral of max(q_a, 0) + max(q_b, 0).
    problems : what makes the plan unrealisable (pressures beyond atmosphere or
        supply, saturated commands), in words; empty when feasible.
    level : (N,) Pa, mean pressure (p_a + p_b)/2.
    """

    rule: str
    time: np.ndarray
    force: np.ndarray
    x: np.ndarray
    v: np.ndarray
    p_a: np.ndarray
    p_b: np.ndarray
    dp_a: np.ndarray
    dp_b: np.ndarray
    q_a: np.ndarray
    q_b: np.ndarray
    command_a: np.ndarray
    command_b: np.ndarray
    saturated: np.ndarray
    air_mass: float
    problems: tuple[str, ...] = ()
    info: dict = field(default_factory=dict)

    @property
    def feasible(self) -> bool:
        return not self.problems

    @property
    def level(self) -> np.ndarray:
        return 0.5 * (self.p_a + self.p_b)

    @property
    def command_mismatch(self) -> float:
        """Largest |command_a - command_b|, V (0 when one 5/3 valve can realise the plan)."""
        return float(np.max(np.abs(self.command_a - self.command_b)))

    def to_dict(self) -> dict[str, float]:
        """JSON-ready key figures (SI: Pa, kg/s, kg, V); the time series are left out."""
        return {"p_min": float(min(self.p_a.min(), self.p_b.min())),
                "p_max": float(max(self.p_a.max(), self.p_b.max())),
                "level_min": float(self.level.min()), "level_max": float(self.level.max()),
                "q_max": float(max(np.abs(self.q_a).max(), np.abs(self.q_b).max())),
                "air_mass": self.air_mass, "command_mismatch": self.command_mismatch,
                "saturated_fraction": float(np.mean(self.saturated)),
                "feasible": self.feasible}

    def summary(self) -> str:
        """One line for people: pressures (bar), peak flow (g/s), air (g), verdict."""
        d = self.to_dict()
        verdict = "feasible" if self.feasible else "infeasible: " + "; ".join(self.problems)
        return (f"pressure plan '{self.rule}': p {d['p_min'] / 1e5:.3g}-{d['p_max'] / 1e5:.3g} bar, "
                f"level {d['level_min'] / 1e5:.3g}-{d['level_max'] / 1e5:.3g} bar, "
                f"peak flow {d['q_max'] * 1e3:.3g} g/s, air {d['air_mass'] * 1e3:.3g} g, "
                f"command mismatch {d['command_mismatch']:.3g} V, "
                f"saturated {d['saturated_fraction']:.0%}; {verdict}")


def _trapz(y, t):
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t))) if len(t) > 1 else 0.0


def pressure_plan(model: DriveModel, time, force, x=0.0, v=None, rule: str = "mean",
                  level: float | None = None, floor: float | None = None,
                  p_a0: float | None = None) -> PressurePlan:
    """Chamber pressures, mass flows and commands that produce a force trajectory.

    Parameters
    ----------
    model : DriveModel
    time : (N,) s, increasing, fine enough to differentiate the pressures (1 ms).
    force : (N,) N, or a callable of time (e.g. :func:`smooth_profile`).
    x : m, position (scalar: held there; or (N,) with the motion).
    v : (N,) m/s, optional; default the numerical derivative of ``x``.
    rule : {"mean", "min_air", "single_valve"}
        How the free pressure level is chosen (module docstring).
    level : Pa, mean pressure of the ``"mean"`` rule; default
        :meth:`DriveModel.balance_pressure` (equal fill and exhaust authority).
    floor : Pa, pressure of the lower chamber under ``"min_air"``; default
        p_atm + 0.1 (p_s - p_atm): near atmosphere the exhaust edge loses its authority.
    p_a0 : Pa, chamber a's pressure at the start of the ``"single_valve"`` plan (p_b
        follows from the force); default the initial force at the balance level.

    Returns
    -------
    PressurePlan
    """
    if rule not in PLAN_RULES:
        raise InputError(f"rule must be one of {', '.join(PLAN_RULES)}, got {rule!r}")
    t = np.asarray(time, dtype=float)
    if t.ndim != 1 or len(t) < 3 or np.any(np.diff(t) <= 0):
        raise InputError("time must be a strictly increasing 1-D array of >= 3 samples (s)")
    F = np.asarray(force(t) if callable(force) else force, dtype=float)
    if F.shape != t.shape or not np.all(np.isfinite(F)):
        raise InputError("force must have one finite value (N) per time sample")
    xs = np.broadcast_to(np.asarray(x, dtype=float), t.shape).astype(float)
    if np.any(xs < 0) or np.any(xs > model.stroke):
        raise InputError(f"x must lie within the stroke [0, {model.stroke:g}] m")
    vs = (np.gradient(xs, t, edge_order=2) if v is None
          else np.broadcast_to(np.asarray(v, dtype=float), t.shape).astype(float))
    f_lo, f_hi = model.force_range
    problems: list[str] = []
    if F.min() < f_lo or F.max() > f_hi:
        problems.append(f"the force {F.min():.1f} .. {F.max():.1f} N exceeds what the chambers "
                        f"can give between atmosphere and supply ({f_lo:.1f} .. {f_hi:.1f} N)")
    p_bal = model.balance_pressure()
    info: dict[str, Any] = {"balance_pressure": p_bal}
    dFdt = (np.asarray(force.derivative(t), dtype=float) if callable(force)
            and hasattr(force, "derivative") else np.gradient(F, t, edge_order=2))

    if rule == "mean":
        lev = p_bal if level is None else _positive("level", level, "Pa")
        info["level"] = lev
        p_a, p_b = model.pressures_for_force(F, np.full_like(F, lev))
        dp_a = np.gradient(p_a, t, edge_order=2)
        dp_b = np.gradient(p_b, t, edge_order=2)
    elif rule == "min_air":
        fl = model.p_atm + 0.1 * (model.p_s - model.p_atm) if floor is None \
            else _positive("floor", floor, "Pa")
        info["floor"] = fl
        fp = F + model.p_atm * (model.area_a - model.area_b)
        # F >= F(floor, floor): b at the floor and a carries the force; else the reverse
        pa_push = (fp + fl * model.area_b) / model.area_a
        push = pa_push >= fl
        p_a = np.where(push, pa_push, fl)
        p_b = np.where(push, fl, (fl * model.area_a - fp) / model.area_b)
        dp_a = np.gradient(p_a, t, edge_order=2)
        dp_b = np.gradient(p_b, t, edge_order=2)
    else:
        p_a, p_b, dp_a, dp_b = _single_valve(model, t, F, dFdt, xs, vs, p_a0, p_bal)
    q_a, q_b = model.chamber_flows(xs, vs, p_a, p_b, dp_a, dp_b)
    lo_p = model.p_atm * (1 - 1e-9)
    hi_p = model.p_s * (1 + 1e-9)
    if min(p_a.min(), p_b.min()) < lo_p or max(p_a.max(), p_b.max()) > hi_p:
        problems.append(f"chamber pressures {min(p_a.min(), p_b.min()) / 1e5:.3f} .. "
                        f"{max(p_a.max(), p_b.max()) / 1e5:.3f} bar leave atmosphere .. supply "
                        f"({model.p_atm / 1e5:.3f} .. {model.p_s / 1e5:.3f} bar)")
    pa_c = np.clip(p_a, model.p_atm * 1.0001, model.p_s * 0.9999)
    pb_c = np.clip(p_b, model.p_atm * 1.0001, model.p_s * 0.9999)
    inv_a = model.valve.invert(q_a, pa_c, "a")
    inv_b = model.valve.invert(q_b, pb_c, "b")
    sat = np.asarray(inv_a.saturated) | np.asarray(inv_b.saturated)
    if np.any(sat):
        k = int(np.argmax(sat))
        problems.append(f"the valve cannot pass the flows at {np.mean(sat):.1%} of the samples "
                        f"(first at t = {t[k]:.3f} s: q_a = {q_a[k] * 1e3:.2f} g/s, "
                        f"q_b = {q_b[k] * 1e3:.2f} g/s)")
    air = _trapz(np.maximum(q_a, 0.0) + np.maximum(q_b, 0.0), t)
    return PressurePlan(rule=rule, time=t, force=F, x=xs, v=vs, p_a=p_a, p_b=p_b, dp_a=dp_a,
                        dp_b=dp_b, q_a=q_a, q_b=q_b,
                        command_a=np.asarray(inv_a.command), command_b=np.asarray(inv_b.command),
                        saturated=sat, air_mass=air, problems=tuple(problems), info=info)


def _single_valve(model: DriveModel, t, F, dFdt, xs, vs, p_a0, p_bal):
    """Pressures of one 5/3 valve producing F(t): the force rate fixes G, chamber a's
    balance then moves p_a, and the force gives p_b (classical RK4 on the grid; the
    inputs are interpolated linearly at the half steps)."""
    pa0 = (float(model.pressures_for_force(F[0], p_bal)[0]) if p_a0 is None
           else _positive("p_a0", p_a0, "Pa"))
    g_lo, g_hi = model.valve.gamma_range("a")
    fp_off = model.p_atm * (model.area_a - model.area_b)

    def rate(pa, f, fd, x, v):
        """dp_a/dt (vectorised over arrays of equal shape)."""
        pb = (pa * model.area_a - f - fp_off) / model.area_b
        G = np.clip(model.gamma_for_force_rate(fd, x, v, pa, pb), g_lo, g_hi)
        return model.pressure_rates(x, v, pa, pb, G)[0]

    mid = lambda arr: 0.5 * (arr[:-1] + arr[1:])      # noqa: E731 - inputs at the half steps
    Fm, dFm, xm, vm = mid(F), mid(dFdt), mid(xs), mid(vs)
    pa = np.empty_like(t)
    pa[0] = pa0
    h = np.diff(t)
    for k in range(len(t) - 1):
        y = pa[k]
        k1 = rate(y, F[k], dFdt[k], xs[k], vs[k])
        k2 = rate(y + h[k] / 2 * k1, Fm[k], dFm[k], xm[k], vm[k])
        k3 = rate(y + h[k] / 2 * k2, Fm[k], dFm[k], xm[k], vm[k])
        k4 = rate(y + h[k] * k3, F[k + 1], dFdt[k + 1], xs[k + 1], vs[k + 1])
        pa[k + 1] = y + h[k] / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    pb = (pa * model.area_a - F - fp_off) / model.area_b
    dpa = rate(pa, F, dFdt, xs, vs)
    dpb = (model.area_a * dpa - dFdt) / model.area_b
    return pa, pb, dpa, dpb


# ---------------------------------------------------------------------- force tracking
@dataclass(frozen=True)
class ForceTracker:
    """Sampled force controller of a drive with one 5/3 valve (DiscreteController).

    At each sample t_k it measures p_a, p_b (and x, v), forms the force F_k and
    asks for the force change that removes a fraction 1 - exp(-bandwidth T) of the
    error in one period while following the reference:

        dF/dt* = (F*_{k+1} - F*_k)/T + (1 - exp(-bandwidth T)) (F*_k - F_k) / T

    (F*_{k+1} from ``preview`` when given -- the feedforward of a planned force --,
    else the last reference change is repeated). The valve characteristic that gives
    it follows from the force-rate model (:meth:`DriveModel.gamma_for_force_rate`)
    and the command from the valve inversion (clipped and flagged when saturated).

    The simulator's reference ``r`` is the wanted force F*(t_k) in N.

    Attributes
    ----------
    model : DriveModel. bandwidth : rad/s, force-error pole. sample_time : s.
    preview : callable F*(t) (N), optional, evaluated at k T (t = 0 at reset).
    """

    model: DriveModel
    bandwidth: float
    sample_time: float
    preview: Callable[[Any], Any] | None = None

    kind = "force"

    def __post_init__(self) -> None:
        object.__setattr__(self, "bandwidth", _positive("bandwidth", self.bandwidth, "rad/s"))
        object.__setattr__(self, "sample_time", _positive("sample_time", self.sample_time, "s"))

    @property
    def alpha(self) -> float:
        """Error kept after one period, exp(-bandwidth T)."""
        return math.exp(-self.bandwidth * self.sample_time)

    def reset(self):
        return (0, None)

    def update(self, state, r: float, y: dict) -> tuple[tuple, float]:
        k, r_prev = state
        T = self.sample_time
        m = self.model
        F = float(m.force(y["p_a"], y["p_b"]))
        if self.preview is not None:
            r_next = float(self.preview((k + 1) * T))
        else:
            r_next = r + (r - (r if r_prev is None else r_prev))
        rate = (r_next - r) / T + (1.0 - self.alpha) * (r - F) / T
        G = float(m.gamma_for_force_rate(rate, y["x"], y["v"], y["p_a"], y["p_b"]))
        if not math.isfinite(G):
            G = math.copysign(1e9, G)
        u, _ = m.valve.command_for_gamma(G, "a")
        return (k + 1, r), float(u)


def force_tracker(plant, bandwidth: float, sample_time: float | None = None,
                  preview: Callable | None = None, law: str | None = "input_affine",
                  model: DriveModel | None = None) -> ForceTracker:
    """A :class:`ForceTracker` for a plant.

    Parameters
    ----------
    plant : workbench.Plant
    bandwidth : rad/s, pole of the force error; the sampled loop keeps exp(-bandwidth T)
        of the error per period. At most the Nyquist frequency pi/T: beyond it the
        kept fraction is below exp(-pi) = 4 % -- practically dead-beat -- and a higher
        number means nothing more. (On the 25 mm rig at T = 10 ms the error against
        the planned force keeps falling up to there: the one-step prediction with the
        measured pressures is good, also with 1 m lines the model lacks.)
    sample_time : s; default the plant file's ``controller.sample_time``.
    preview : callable F*(t), N, for the feedforward.
    law : valve law of the control model (default the input-affine law, fitted to a
        four-edge plant).
    model : DriveModel, optional, instead of building one.

    Raises
    ------
    InputError
        Bandwidth beyond pi/T, or no sample time.
    """
    if sample_time is None:
        if not plant.params.has_controller:
            raise InputError("give sample_time: the plant file has no [controller] section")
        sample_time = plant.params["controller.sample_time"]
    T = _positive("sample_time", sample_time, "s")
    lam = _positive("bandwidth", bandwidth, "rad/s")
    if lam * T > math.pi:
        raise InputError(f"force bandwidth {lam:g} rad/s is beyond the Nyquist frequency "
                         f"pi/T = {math.pi / T:.0f} rad/s of the T = {T * 1e3:g} ms loop: the "
                         "sampled loop cannot be faster than dead-beat (it would keep less than "
                         f"exp(-pi) = 4 % of the error per period); use at most {math.pi / T:.0f} rad/s")
    model = DriveModel.from_plant(plant, law=law) if model is None else model
    return ForceTracker(model=model, bandwidth=lam, sample_time=T, preview=preview)
