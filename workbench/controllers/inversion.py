"""Inversion of the valve law: the command that makes a chamber take a wanted mass flow.

Both valve laws of :mod:`workbench.physics.valve` are affine in a *command
characteristic* G on each side of the spool centre::

    q = phi(p) + psi(p, sgn G) G

* input-affine law (paper 003, approximation II): G = Gamma(s), an odd polynomial
  of the signed effective opening s; phi, psi_in, psi_out polynomials in p;
* four-edge ISO 6358 law (no underlap): G = s, phi = 0,
  psi_in(p) = q_iso(p_s -> p) (edge supply -> port), psi_out(p) = q_iso(p -> p_atm)
  (edge port -> exhaust).

A wanted flow q* at chamber pressure p is therefore produced by
G = (q* - phi(p)) / psi(p, sgn(q* - phi(p))), then s = Gamma^-1(G) and the command
u from s through the command map (centre, span, null offset, deadband; see
:class:`CommandMap`). :meth:`ValveInversion.invert` does exactly this for the
input-affine law (Gamma^-1 in closed form for degree <= 2, a guarded Newton solve
otherwise) and, for the ISO law, solves flow(s) = q* by a bracketed (guarded)
Newton iteration on the four-edge flow of the opening on the side of the centre that
contains q*. (The four-edge flow is proportional to the opening on each side, so the
iteration stops after its first step; it stays correct for any monotone opening law.)

Side ``"a"`` is port A (the command's own sign: a positive opening fills A), side
``"b"`` the mirrored port B: it sees Gamma(-s) (input-affine law) or the opening -s
(four-edge law), as in :func:`workbench.physics.valve.affine_port_flows` and
:func:`~workbench.physics.valve.four_edge_flows`.

Saturation: a flow outside what the valve can pass at that pressure (the openings
reachable within the command range ``[command_min, command_max]``) gives the
command of the nearest reachable flow, ``saturated = True`` and the ``shortfall``
q* - q(u) in kg/s.

Examples
--------
>>> from workbench import Plant
>>> from workbench.controllers.inversion import ValveInversion
>>> plant = Plant.from_toml("tests/data/plants/input_affine.toml")
>>> inv = ValveInversion.from_plant(plant)
>>> res = inv.invert(5e-3, 3.5e5)      # 5 g/s into chamber a at 3.5 bar
>>> round(float(inv.flow(res.command, 3.5e5)), 9)  # kg/s: the flow asked for
0.005
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import casadi as ca
import numpy as np

from ..errors import InputError
from ..physics import gas, valve

__all__ = ["CommandMap", "FlowCommand", "ValveInversion", "bracketed_newton"]

SIDES = ("a", "b")


# ---------------------------------------------------------------------- numeric helpers
def bracketed_newton(fun, target, lo, hi, rtol: float = 1e-13, atol: float = 1e-300,
                     max_iter: int = 100):
    """Solve fun(s) = target for s in [lo, hi] element-wise (guarded Newton).

    ``fun(s)`` returns (value, slope) arrays; fun - target must change sign (or
    vanish) over each bracket, fun need not be smooth. The first iterate is the
    secant (regula falsi) point of the bracket; each further step is Newton's when
    it lands strictly inside the current bracket and bisection otherwise, and the
    bracket shrinks around the sign change at every step, so the iteration cannot
    leave it and always converges.

    Parameters
    ----------
    fun : callable
        s -> (f(s), f'(s)), vectorised.
    target, lo, hi : array_like
        Wanted value and bracket ends (lo <= hi).
    rtol, atol : float
        Stop when |f(s) - target| <= rtol |target| + atol or the bracket is
        narrower than a few ulps of s.

    Returns
    -------
    (s, iterations) : ndarray, int
    """
    t = np.asarray(target, dtype=float)
    a = np.array(np.broadcast_to(lo, t.shape), dtype=float)
    b = np.array(np.broadcast_to(hi, t.shape), dtype=float)
    fa = fun(a)[0] - t
    fb = fun(b)[0] - t
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(fb != fa, a - fa * (b - a) / (fb - fa), 0.5 * (a + b))
    s = np.where(np.isfinite(s) & (s >= a) & (s <= b), s, 0.5 * (a + b))
    s = np.where(fa == 0.0, a, np.where(fb == 0.0, b, s))
    tol = rtol * np.abs(t) + atol
    it = 0
    for it in range(1, max_iter + 1):
        f, df = fun(s)
        r = f - t
        done = (np.abs(r) <= tol) | (b - a <= 4.0 * np.spacing(np.maximum(np.abs(a), np.abs(b))))
        if np.all(done):
            break
        same = np.sign(r) == np.sign(fa)
        a = np.where(~done & same, s, a)
        fa = np.where(~done & same, r, fa)
        b = np.where(~done & ~same, s, b)
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = s - r / df
        ok = np.isfinite(newton) & (newton > a) & (newton < b)
        s = np.where(done, s, np.where(ok, newton, 0.5 * (a + b)))
    return s, it


# ---------------------------------------------------------------------- command map
@dataclass(frozen=True)
class CommandMap:
    """Command u (V) <-> signed effective opening s of the 5/3 valve (-).

    s = effective_opening(spool_position(u)) (:mod:`workbench.physics.valve`): the
    spool position (u - center - offset)/span clipped to [-1, 1], then the overlap
    ``deadband`` removed. The inverse :meth:`command` puts a non-zero opening just
    past the overlap (deadband compensation) and the zero opening at the spool centre.

    Parameters
    ----------
    center : command that centres an ideal spool, V.
    span : |u - center| that opens an edge fully, V.
    offset : null offset, V.
    deadband : spool overlap, fraction of the span, in [0, 1).
    u_min, u_max : command range the drive accepts, V.
    """

    center: float
    span: float
    offset: float = 0.0
    deadband: float = 0.0
    u_min: float = -math.inf
    u_max: float = math.inf

    def __post_init__(self) -> None:
        for name in ("center", "span", "offset", "deadband", "u_min", "u_max"):
            object.__setattr__(self, name, float(getattr(self, name)))
        if not (math.isfinite(self.span) and self.span > 0):
            raise InputError(f"valve command_span must be > 0 V, got {self.span!r}")
        if not 0.0 <= self.deadband < 1.0:
            raise InputError(f"valve deadband is a fraction of the span in [0, 1), got {self.deadband!r}")
        if not self.u_min < self.u_max:
            raise InputError(f"command_min ({self.u_min:g} V) must be below command_max ({self.u_max:g} V)")
        mid = self.center + self.offset
        if not self.u_min <= mid <= self.u_max:
            raise InputError(f"the spool centre {mid:g} V (command_center + null_offset) lies "
                             f"outside the command range [{self.u_min:g}, {self.u_max:g}] V: "
                             "the valve cannot be closed")

    @classmethod
    def from_plant(cls, plant, compensate: bool = True) -> "CommandMap":
        """The plant's command map; ``compensate=False`` ignores its deadband and offset."""
        prm = plant.params
        return cls(center=prm["valve.command_center"], span=prm["valve.command_span"],
                   offset=prm.get("valve.null_offset", 0.0) if compensate else 0.0,
                   deadband=prm.get("valve.deadband", 0.0) if compensate else 0.0,
                   u_min=prm["valve.command_min"], u_max=prm["valve.command_max"])

    def opening(self, u):
        """Signed effective opening (-) of command ``u`` (V); arrays allowed."""
        s = valve.spool_position(np.asarray(u, dtype=float), self.center, self.span, self.offset)
        return valve.effective_opening(s, self.deadband)

    @property
    def opening_range(self) -> tuple[float, float]:
        """(lowest, highest) effective opening within [u_min, u_max]."""
        return float(self.opening(self.u_min)), float(self.opening(self.u_max))

    def command(self, opening):
        """Command (V) giving the effective ``opening``, clipped to the reachable range."""
        lo, hi = self.opening_range
        s = np.clip(np.asarray(opening, dtype=float), lo, hi)
        d = self.deadband
        spool = np.where(s > 0, d + (1.0 - d) * s, np.where(s < 0, -d + (1.0 - d) * s, 0.0))
        return np.clip(self.center + self.offset + self.span * spool, self.u_min, self.u_max)

    def symbolic_command(self, opening):
        """:meth:`command` as a CasADi expression of ``opening``."""
        lo, hi = self.opening_range
        s = ca.fmin(ca.fmax(opening, lo), hi)
        d = self.deadband
        spool = ca.sign(s) * d + (1.0 - d) * s
        return ca.fmin(ca.fmax(self.center + self.offset + self.span * spool, self.u_min), self.u_max)


# ---------------------------------------------------------------------- results
@dataclass(frozen=True)
class FlowCommand:
    """Result of :meth:`ValveInversion.invert` (scalars for scalar input, else arrays).

    Attributes
    ----------
    command : command u, V (clipped to the valve's range).
    opening : signed effective opening of the spool, - (positive fills port A).
    gamma : value of the command characteristic G on the requested side, -
        (Gamma(+-s) for the input-affine law, +-s for the four-edge law).
    flow : mass flow into the chamber that the command produces, kg/s.
    wanted : the requested flow q*, kg/s.
    saturated : q* is outside the flows the valve can pass at that pressure.
    shortfall : q* - flow, kg/s (0 up to rounding when not saturated).
    iterations : Newton iterations used (0 for closed forms).
    """

    command: Any
    opening: Any
    gamma: Any
    flow: Any
    wanted: Any
    saturated: Any
    shortfall: Any
    iterations: int = 0

    @property
    def any_saturated(self) -> bool:
        return bool(np.any(self.saturated))


# ---------------------------------------------------------------------- the inversion
#: Fraction of each psi's largest value (between atmosphere and supply) that
#: :meth:`ValveInversion.authority` keeps as a floor when a controller inverts the law.
AUTHORITY_FLOOR = 0.05


@dataclass(frozen=True)
class ValveInversion:
    """A valve law together with its inverse (see the module docstring).

    Build it with :meth:`from_plant` (or :meth:`from_affine_fit`); all pressures are
    absolute, Pa; flows kg/s into the chamber on ``side``.

    Attributes
    ----------
    law : {"input_affine", "iso6358"}
    commands : CommandMap
    p_s, p_atm : supply and exhaust pressure, Pa.
    temperature : gas temperature (supply and chambers), K.
    phi, psi_in, psi_out, gamma, pressure_scale : coefficients of the input-affine law
        (ascending powers of p / pressure_scale; see :func:`workbench.physics.valve.affine_flow`).
    conductance, critical_ratio : ISO 6358 C (m^3/(s Pa)) and b (-) of one edge.
    source : where the law came from, for reports.
    """

    law: str
    commands: CommandMap
    p_s: float
    p_atm: float
    temperature: float = gas.T_REF
    phi: tuple[float, ...] = (0.0,)
    psi_in: tuple[float, ...] = ()
    psi_out: tuple[float, ...] = ()
    gamma: tuple[float, ...] = (1.0,)
    pressure_scale: float = 1e5
    conductance: float = math.nan
    critical_ratio: float = math.nan
    source: str = ""

    def __post_init__(self) -> None:
        if self.law not in ("input_affine", "iso6358"):
            raise InputError(f"valve law must be 'input_affine' or 'iso6358', got {self.law!r}")
        if not self.p_s > self.p_atm > 0:
            raise InputError(f"need supply > atmosphere > 0 Pa, got p_s = {self.p_s!r}, "
                             f"p_atm = {self.p_atm!r}")
        if self.law == "input_affine":
            for name in ("phi", "psi_in", "psi_out", "gamma"):
                vals = tuple(float(c) for c in getattr(self, name))
                if not vals or not all(math.isfinite(c) for c in vals):
                    raise InputError(f"input-affine law: {name} needs finite coefficients, got {vals!r}")
                object.__setattr__(self, name, vals)
            # Gamma must be strictly increasing on [0, 1] to be invertible
            s = np.linspace(0.0, 1.0, 401)
            d = np.polynomial.polynomial.polyval(s, [k * g for k, g in enumerate(self.gamma, 1)])
            if np.any(d <= 0.0):
                raise InputError(
                    f"input-affine law: Gamma(s) = sum g_k s|s|^(k-1) with g = {list(self.gamma)} "
                    f"is not increasing on [0, 1] (slope {float(d.min()):.3g} at "
                    f"s = {float(s[np.argmin(d)]):.3g}), so a flow has no unique command")
        else:
            if not (self.conductance > 0 and 0 < self.critical_ratio < 1):
                raise InputError("ISO 6358 law needs sonic_conductance > 0 and 0 < b < 1, got "
                                 f"C = {self.conductance!r}, b = {self.critical_ratio!r}")

    # ------------------------------------------------------------ construction
    @classmethod
    def from_plant(cls, plant, law: str | None = None, compensate: bool = True,
                   **fit_options: Any) -> "ValveInversion":
        """The inverse of a plant's valve.

        Parameters
        ----------
        plant : workbench.Plant
        law : {None, "input_affine", "iso6358"}
            None: the plant's own law. ``"input_affine"`` on a four-edge plant fits
            approximation II to it (:func:`workbench.physics.valve.fit_affine_to_four_edge`,
            ``fit_options`` passed on); ``"iso6358"`` on an input-affine plant uses
            its datasheet C and b (which do not enter that plant's dynamics).
        compensate : bool
            Include the plant's deadband and null offset in the command map (when it
            has them); False gives the ideal valve's map.
        """
        prm = plant.params
        want = plant.valve_law if law is None else law
        if want not in ("input_affine", "iso6358"):
            raise InputError(f"law must be None, 'input_affine' or 'iso6358', got {law!r}")
        base = dict(commands=CommandMap.from_plant(plant, compensate),
                    p_s=float(prm["supply.pressure"]),
                    p_atm=float(prm["gas.atmospheric_pressure"]),
                    temperature=float(prm["gas.temperature"]))
        if want == "iso6358":
            return cls(law="iso6358", conductance=float(prm["valve.sonic_conductance"]),
                       critical_ratio=float(prm["valve.critical_pressure_ratio"]),
                       source="ISO 6358 four-edge law of the plant file"
                              + ("" if plant.valve_law == "iso6358"
                                 else " (datasheet values; the plant simulates the affine law)"),
                       **base)
        if plant.valve_law == "input_affine":
            return cls(law="input_affine", phi=tuple(prm["valve.affine_phi"]),
                       psi_in=tuple(prm["valve.affine_psi_in"]),
                       psi_out=tuple(prm["valve.affine_psi_out"]),
                       gamma=tuple(prm["valve.affine_gamma"]),
                       source="input-affine law of the plant file", **base)
        fit = valve.fit_affine_to_four_edge(prm["valve.sonic_conductance"],
                                            prm["valve.critical_pressure_ratio"],
                                            base["p_s"], base["p_atm"], base["temperature"],
                                            **fit_options)
        return cls.from_affine_fit(fit, **base,
                                   source=f"approximation II fitted to the plant's four-edge "
                                          f"valve (RMS {fit.rms * 1e3:.2f} g/s, largest "
                                          f"{fit.max_error * 1e3:.2f} g/s)")

    @classmethod
    def from_affine_fit(cls, fit: valve.AffineValveFit, commands: CommandMap, p_s: float,
                        p_atm: float, temperature: float = gas.T_REF,
                        source: str = "") -> "ValveInversion":
        """From an :class:`~workbench.physics.valve.AffineValveFit`."""
        return cls(law="input_affine", commands=commands, p_s=p_s, p_atm=p_atm,
                   temperature=temperature, phi=fit.phi, psi_in=fit.psi_in,
                   psi_out=fit.psi_out, gamma=fit.gamma, pressure_scale=fit.pressure_scale,
                   source=source or "approximation II fit")

    def with_commands(self, commands: CommandMap) -> "ValveInversion":
        """The same law with another command map (e.g. without deadband compensation)."""
        return replace(self, commands=commands)

    # ------------------------------------------------------------ the law, affine view
    def terms(self, p):
        """(phi(p), psi_in(p), psi_out(p)) at chamber pressure ``p`` (Pa), kg/s.

        The port flow is q = phi + psi_in G for G >= 0 and phi + psi_out G for G < 0.
        Four-edge law: phi = 0, psi_in = flow of a fully open supply edge into p,
        psi_out = flow of a fully open exhaust edge out of p (gas at ``temperature``).
        """
        if self.law == "input_affine":
            # Horner in plain arithmetic: floats stay floats (fast in a controller),
            # arrays stay arrays
            pn = (p if isinstance(p, float) else np.asarray(p, dtype=float)) / self.pressure_scale
            return (valve.polyval(self.phi, pn) + 0.0 * pn, valve.polyval(self.psi_in, pn),
                    valve.polyval(self.psi_out, pn))
        p = np.asarray(p, dtype=float)
        T = self.temperature
        # the physics law itself: on arrays it runs element-wise in numpy
        q_in = gas.iso6358_flow(self.conductance, self.critical_ratio, self.p_s, p, T, T)
        q_out = gas.iso6358_flow(self.conductance, self.critical_ratio, p, self.p_atm, T, gas.T_REF)
        return np.zeros_like(p), q_in, q_out

    def authority(self, p):
        """:meth:`terms` as a controller should invert them: each psi floored at
        :data:`AUTHORITY_FLOOR` of its largest value between atmosphere and supply.

        A law describes the valve at the supply it was built for; beyond that (a rig
        whose supply is higher than the model's, a chamber pushed above the model's
        supply) it extrapolates, and psi_in -- zero at the model's supply -- turns
        negative: an inversion would then open the valve the wrong way. Floored, the
        model keeps a little authority in the right direction, so the inversion asks
        for a large opening that way and the loop's feedback does the rest. Within the
        range only the last few per cent near the pinned ends are affected, where the
        valve has almost no authority anyway.
        """
        phi, pin, pout = self.terms(p)
        f_in, f_out = self._authority_floors
        return phi, np.maximum(pin, f_in), np.maximum(pout, f_out)

    @property
    def _authority_floors(self) -> tuple[float, float]:
        cached = self.__dict__.get("_floors")
        if cached is None:
            grid = np.linspace(self.p_atm, self.p_s, 201)
            _, pin, pout = self.terms(grid)
            cached = (AUTHORITY_FLOOR * float(np.max(pin)), AUTHORITY_FLOOR * float(np.max(pout)))
            object.__setattr__(self, "_floors", cached)
        return cached

    def symbolic_terms(self, p):
        """:meth:`terms` as CasADi expressions of ``p`` (SX or MX)."""
        if self.law == "input_affine":
            pn = p / self.pressure_scale
            return (valve.polyval(self.phi, pn), valve.polyval(self.psi_in, pn),
                    valve.polyval(self.psi_out, pn))
        T = self.temperature
        return (0.0 * p, gas.iso6358_flow(self.conductance, self.critical_ratio, self.p_s, p, T, T),
                gas.iso6358_flow(self.conductance, self.critical_ratio, p, self.p_atm, T, gas.T_REF))

    def gamma_of(self, opening):
        """Command characteristic G = Gamma(s) (four-edge law: G = s), -."""
        s = np.asarray(opening, dtype=float)
        if self.law == "iso6358":
            return s + 0.0
        return valve.gamma_odd(s, self.gamma)

    def _gamma_slope(self, s):
        mag = np.abs(s)
        return sum(k * g * mag ** (k - 1) for k, g in enumerate(self.gamma, 1))

    def opening_of_gamma(self, g):
        """Inverse of :meth:`gamma_of` (odd, increasing): the opening s with Gamma(s) = G.

        Closed form for Gamma of degree 1 or 2 (g1 s + g2 s|s|), guarded Newton on
        [0, s_max] otherwise. ``G`` beyond Gamma(+-1) gives +-1 (and beyond).
        Returns (s, iterations).
        """
        g = np.asarray(g, dtype=float)
        if self.law == "iso6358":
            return g + 0.0, 0
        mag = np.abs(g)
        coeffs = [c for c in self.gamma]
        while len(coeffs) > 1 and coeffs[-1] == 0.0:
            coeffs.pop()
        if len(coeffs) == 1:
            return g / coeffs[0], 0
        if len(coeffs) == 2:
            g1, g2 = coeffs
            # g1 s + g2 s^2 = |G| for s >= 0, written without cancellation
            root = np.sqrt(np.maximum(g1 * g1 + 4.0 * g2 * mag, 0.0))
            return np.sign(g) * 2.0 * mag / (g1 + root), 0
        # Gamma grows at least like its slope at 0 past 1; find an upper bracket
        hi = np.ones_like(mag)
        for _ in range(60):
            short = self.gamma_of(hi) < mag
            if not np.any(short):
                break
            hi = np.where(short, 2.0 * hi, hi)
        s, it = bracketed_newton(lambda x: (self.gamma_of(x), self._gamma_slope(x)), mag,
                                 np.zeros_like(mag), hi)
        return np.sign(g) * s, it

    def gamma_range(self, side: str = "a") -> tuple[float, float]:
        """(lowest, highest) G reachable on ``side`` within the command range."""
        lo, hi = self.commands.opening_range
        if _side(side) == "b":
            lo, hi = -hi, -lo
        return float(self.gamma_of(lo)), float(self.gamma_of(hi))

    # ------------------------------------------------------------ forward law
    def port_flow(self, opening, p, side: str = "a"):
        """Mass flow (kg/s) into the chamber on ``side`` at pressure ``p`` for a spool opening.

        Input-affine law: exactly :func:`~workbench.physics.valve.affine_port_flows`;
        four-edge law: :func:`~workbench.physics.valve.four_edge_flows` (no underlap,
        gas at ``temperature``).
        """
        s = np.asarray(opening, dtype=float)
        if _side(side) == "b":
            s = -s
        G = self.gamma_of(s)
        phi, pin, pout = self.terms(p)
        return phi + np.where(G >= 0, pin, pout) * G

    def flow(self, u, p, side: str = "a"):
        """Mass flow (kg/s) into the chamber on ``side`` at pressure ``p`` for command ``u``."""
        return self.port_flow(self.commands.opening(u), p, side)

    def flow_range(self, p, side: str = "a"):
        """(lowest, highest) flow into ``side`` at pressure ``p`` over the command range, kg/s."""
        lo, hi = self.commands.opening_range
        q1 = self.port_flow(lo, p, side)
        q2 = self.port_flow(hi, p, side)
        q0 = self.port_flow(0.0, p, side)
        return (np.minimum(np.minimum(q1, q2), q0), np.maximum(np.maximum(q1, q2), q0))

    # ------------------------------------------------------------ inversion
    def invert(self, flow, p, side: str = "a") -> FlowCommand:
        """The command that makes the chamber on ``side`` at pressure ``p`` take ``flow``.

        Parameters
        ----------
        flow : float or array, kg/s (positive into the chamber).
        p : float or array, chamber pressure, Pa (broadcast against ``flow``).
        side : {"a", "b"}
            Chamber a (port A) or the mirrored chamber b (port B) of the 5/3 valve.

        Returns
        -------
        FlowCommand
            Scalars for scalar input. Where ``flow`` is not reachable the command is
            that of the nearest reachable flow and ``saturated`` is True.
        """
        side = _side(side)
        q = np.asarray(flow, dtype=float)
        p = np.asarray(p, dtype=float)
        scalar = q.ndim == 0 and p.ndim == 0
        q, p = np.broadcast_arrays(np.atleast_1d(q), np.atleast_1d(p))
        q, p = q.astype(float), p.astype(float)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(p))):
            raise InputError("flow (kg/s) and pressure (Pa) must be finite")
        if np.any(p <= 0):
            raise InputError("chamber pressures are absolute and must be > 0 Pa")
        lo, hi = self.commands.opening_range
        if side == "b":                      # port B sees the opening -s
            lo, hi = -hi, -lo
        # flows at the ends of each half (port-A convention on the opening s')
        q0 = self._port_a(np.zeros_like(q), p)
        q_hi = self._port_a(np.full_like(q, hi), p)
        q_lo = self._port_a(np.full_like(q, lo), p)
        in_pos = (hi > 0) & (q >= np.minimum(q0, q_hi)) & (q <= np.maximum(q0, q_hi))
        in_neg = ~in_pos & (lo < 0) & (q >= np.minimum(q0, q_lo)) & (q <= np.maximum(q0, q_lo))
        reach = in_pos | in_neg
        s = np.zeros_like(q)
        iters = 0
        if np.any(reach):
            a = np.where(in_pos, 0.0, lo)[reach]
            b = np.where(in_pos, hi, 0.0)[reach]
            if self.law == "input_affine":
                phi, pin, pout = self.terms(p[reach])
                psi = np.where(in_pos[reach], pin, pout)
                with np.errstate(divide="ignore", invalid="ignore"):
                    G = np.where(psi != 0.0, (q[reach] - phi) / psi, 0.0)
                sr, iters = self.opening_of_gamma(G)
                s[reach] = np.clip(sr, a, b)
            else:
                pr, qr = p[reach], q[reach]
                fun = self._port_a_with_slope(pr)
                sr, iters = bracketed_newton(fun, qr, a, b)
                s[reach] = sr
        if np.any(~reach):
            # nearest reachable flow among the three ends
            ends = np.stack([np.full_like(q, lo), np.zeros_like(q), np.full_like(q, hi)])
            qs = np.stack([q_lo, q0, q_hi])
            k = np.argmin(np.abs(qs - q), axis=0)
            s = np.where(reach, s, ends[k, np.arange(len(q))])
        opening = -s if side == "b" else s
        u = self.commands.command(opening)
        opening = self.commands.opening(u)           # what the command really opens
        achieved = self.port_flow(opening, p, side)
        G_side = self.gamma_of(-opening if side == "b" else opening)
        out = dict(command=u, opening=opening, gamma=G_side, flow=achieved, wanted=q,
                   saturated=~reach, shortfall=q - achieved)
        if scalar:
            out = {k: (bool(v[0]) if k == "saturated" else float(v[0])) for k, v in out.items()}
        return FlowCommand(iterations=int(iters), **out)

    def command_for_gamma(self, g, side: str = "a"):
        """Command (V) giving the characteristic value ``g`` on ``side``, and whether it saturated.

        For controllers that compute G directly (feedback linearisation); ``g``
        outside :meth:`gamma_range` is clipped (saturated = True).
        """
        side = _side(side)
        g = np.asarray(g, dtype=float)
        g_lo, g_hi = self.gamma_range(side)
        sat = (g < g_lo) | (g > g_hi)
        s, _ = self.opening_of_gamma(np.clip(g, g_lo, g_hi))
        if side == "b":
            s = -s
        u = self.commands.command(s)
        if g.ndim == 0:
            return float(u), bool(sat)
        return u, sat

    def _port_a(self, s, p):
        G = self.gamma_of(s)
        phi, pin, pout = self.terms(p)
        return phi + np.where(G >= 0, pin, pout) * G

    def _port_a_with_slope(self, p):
        phi, pin, pout = self.terms(p)

        def fun(s):
            G = self.gamma_of(s)
            psi = np.where(G >= 0, pin, pout)
            return phi + psi * G, psi * self._gamma_slope(s)
        return fun

    # ------------------------------------------------------------ symbolic
    def symbolic_command(self, flow, p, side: str = "a", newton_steps: int = 8):
        """The command u(q*, p) as a CasADi expression (SX or MX), for NMPC or FL.

        G = (q* - phi(p)) / psi(p, sgn(q* - phi(p))) clipped to the reachable range,
        s = Gamma^-1(G) (closed form for degree <= 2, else ``newton_steps`` Newton
        steps from the linear guess, each clipped to [0, 1]), then the command map.
        Valid for chamber pressures strictly between atmosphere and supply, where
        psi_in and psi_out are positive; outside, psi is floored at 1e-12 kg/s
        so the expression stays finite (and saturates).
        """
        side = _side(side)
        phi, pin, pout = self.symbolic_terms(p)
        d = flow - phi
        psi = ca.if_else(d >= 0, ca.fmax(pin, 1e-12), ca.fmax(pout, 1e-12))
        G = d / psi
        g_lo, g_hi = self.gamma_range(side)
        G = ca.fmin(ca.fmax(G, g_lo), g_hi)
        s = self._symbolic_opening_of_gamma(G, newton_steps)
        if side == "b":
            s = -s
        return self.commands.symbolic_command(s)

    def _symbolic_opening_of_gamma(self, G, newton_steps: int):
        if self.law == "iso6358":
            return G
        coeffs = list(self.gamma)
        while len(coeffs) > 1 and coeffs[-1] == 0.0:
            coeffs.pop()
        mag = ca.fabs(G)
        if len(coeffs) == 1:
            return G / coeffs[0]
        if len(coeffs) == 2:
            g1, g2 = coeffs
            return ca.sign(G) * 2.0 * mag / (g1 + ca.sqrt(ca.fmax(g1 * g1 + 4.0 * g2 * mag, 0.0)))
        s = mag / coeffs[0]
        for _ in range(newton_steps):
            val = sum(g * s ** k for k, g in enumerate(coeffs, 1))
            slope = sum(k * g * s ** (k - 1) for k, g in enumerate(coeffs, 1))
            s = ca.fmin(ca.fmax(s - (val - mag) / slope, 0.0), 1.0)
        return ca.sign(G) * s

    def describe(self) -> str:
        """One line for reports."""
        c = self.commands
        extra = []
        if c.deadband:
            extra.append(f"deadband {c.deadband:.3g} compensated")
        if c.offset:
            extra.append(f"null offset {c.offset:.3g} V compensated")
        return (f"{self.source or self.law}; command {c.center:g} +- {c.span:g} V in "
                f"[{c.u_min:g}, {c.u_max:g}] V" + ("; " + ", ".join(extra) if extra else ""))


def _side(side: str) -> str:
    if side not in SIDES:
        raise InputError(f"side must be 'a' (port A) or 'b' (port B), got {side!r}")
    return side
