"""A 3/2 servo-distributor flow stage like paper 003's Servotronic, as a known law.

Paper 003 characterises one port of a 3/2-way servo-distributor: the port is fed from
the supply through the restriction A_S(u) and exhausts to atmosphere through A_E(u)
(its Fig. 2, the half Wheatstone bridge). :class:`FlowStage` is that flow stage built
from two ISO 6358 restrictions (physics.md) whose openings follow the rounded-underlap
law of :func:`workbench.physics.valve.rounded_edge_openings`: at the centred spool both
restrictions are open d/2 (the leakage that makes the port settle between atmosphere
and supply), an opened restriction tends to its full conductance, a closed one still
passes the clearance leakage d^2 / (4 |o|).

The paper gives the equilibrium of its closed tank at the centred command (5.1e5 Pa at
u = 0 V, section 5) but not the conductances; :meth:`FlowStage.calibrated` chooses the
exhaust conductance so that the centred port is at rest at that pressure -- the one
number of the paper the static characteristic has to reproduce. Everything it assumes
(supply, conductance, critical ratio, underlap, command range) is in :meth:`to_dict`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Sequence

import numpy as np

from ...errors import InputError
from ...physics import gas
from ...physics.valve import rounded_edge_openings
from ._numeric import clip as _clip, numeric as _numeric
from .table import ValveTable

__all__ = ["FlowStage", "chebyshev_pressures"]


@dataclass(frozen=True)
class FlowStage:
    """One port of a 3/2 flow stage: q_m(p, u) = o_S Q(p_s -> p) - o_E Q(p -> p_atm).

    Attributes
    ----------
    supply_pressure, atmospheric_pressure : Pa absolute.
    temperature : supply temperature, K.
    inlet_conductance : sonic conductance of the fully open supply restriction A_S,
        m^3/(s Pa) (ISO 6358).
    exhaust_conductance : the same for the exhaust restriction A_E, m^3/(s Pa).
    critical_pressure_ratio : b of both restrictions, -.
    underlap : d, the rounded underlap of both restrictions, fraction of full opening.
    command_center, command_span : V; the spool opening is o = (u - centre) / span,
        clipped to [-1, 1] (o > 0 opens the supply restriction).
    """

    supply_pressure: float = 7.0e5
    atmospheric_pressure: float = gas.P_ATM
    temperature: float = gas.T_REF
    inlet_conductance: float = 1.0e-8
    exhaust_conductance: float = 1.0e-8
    critical_pressure_ratio: float = 0.3
    underlap: float = 0.1
    command_center: float = 0.0
    command_span: float = 10.0

    def __post_init__(self) -> None:
        for name in ("supply_pressure", "atmospheric_pressure", "temperature",
                     "inlet_conductance", "exhaust_conductance", "command_span"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"expected a positive finite number, got {v!r}", location=name)
        if not self.supply_pressure > self.atmospheric_pressure:
            raise InputError("the supply pressure must exceed the atmospheric pressure",
                             location="supply_pressure")
        if not 0.0 < self.critical_pressure_ratio < 1.0:
            raise InputError(f"expected 0 < b < 1, got {self.critical_pressure_ratio!r}",
                             location="critical_pressure_ratio")
        if not 0.0 <= self.underlap < 1.0:
            raise InputError(f"expected an underlap in [0, 1), got {self.underlap!r}",
                             location="underlap")

    @classmethod
    def calibrated(cls, centre_equilibrium: float, **kwargs: Any) -> "FlowStage":
        """A flow stage whose centred port is at rest at ``centre_equilibrium`` (Pa).

        At the centre both restrictions are open d/2, so q = 0 there means
        C_S Q1(p_s -> p_e) = C_E Q1(p_e -> p_atm) with Q1 the flow of a unit
        conductance: C_E = C_S Q1(p_s -> p_e) / Q1(p_e -> p_atm), exactly.
        """
        base = cls(**kwargs)
        lo, hi = base.atmospheric_pressure, base.supply_pressure
        if not lo < centre_equilibrium < hi:
            raise InputError(f"the centre equilibrium {centre_equilibrium:g} Pa must lie "
                             f"between atmosphere ({lo:g} Pa) and supply ({hi:g} Pa)",
                             location="centre_equilibrium")
        b, T = base.critical_pressure_ratio, base.temperature
        q_in = float(gas.iso6358_flow(1.0, b, hi, centre_equilibrium, T, T))
        q_out = float(gas.iso6358_flow(1.0, b, centre_equilibrium, lo, T, T))
        return cls(**{**asdict(base), "exhaust_conductance": base.inlet_conductance * q_in / q_out})

    def opening(self, u):
        """Signed spool opening o = (u - centre) / span clipped to [-1, 1], -."""
        return _clip((u - self.command_center) / self.command_span, -1.0, 1.0)

    def flow(self, p, u):
        """Mass flow into the port, kg/s, at port pressure ``p`` (Pa) and command ``u`` (V).

        Floats, numpy arrays or CasADi expressions (derivatives are exact)."""
        o_s, o_e = rounded_edge_openings(self.opening(u), self.underlap)
        b, T = self.critical_pressure_ratio, self.temperature
        return (o_s * gas.iso6358_flow(self.inlet_conductance, b, self.supply_pressure, p, T, T)
                - o_e * gas.iso6358_flow(self.exhaust_conductance, b, p,
                                         self.atmospheric_pressure, T, T))

    def max_flow(self) -> float:
        """Choked flow of the fully open supply restriction, kg/s (the flow scale)."""
        return float(self.inlet_conductance * self.supply_pressure * gas.RHO_ANR
                     * math.sqrt(gas.T_REF / self.temperature))

    def table(self, u_values: Sequence[float], p_values: Sequence[float], noise: float = 0.0,
              seed: int = 0, made_with: str | None = None) -> ValveTable:
        """The characteristic on the grid u x p (u varying slowest), with Gaussian noise
        of ``noise`` kg/s standard deviation (the measurement), as a :class:`ValveTable`."""
        if not (math.isfinite(noise) and noise >= 0):
            raise InputError(f"expected a noise standard deviation >= 0 (kg/s), got {noise!r}",
                             location="noise")
        uu, pp = (a.ravel() for a in np.meshgrid(np.asarray(u_values, float),
                                                 np.asarray(p_values, float), indexing="ij"))
        q = np.asarray(_numeric(self.flow)(pp, uu), dtype=float)
        if noise > 0:
            q = q + np.random.default_rng(seed).normal(0.0, noise, q.shape)
        meta: dict[str, Any] = {"made_with": made_with} if made_with else {}
        meta.update({"generator": "workbench.identify.valve.FlowStage: 3/2 flow stage, two "
                                  "ISO 6358 restrictions with a rounded underlap",
                     "supply_pressure": self.supply_pressure,
                     "atmospheric_pressure": self.atmospheric_pressure,
                     "temperature": self.temperature, "command_center": self.command_center,
                     "command_span": self.command_span, "noise_kg_s": float(noise),
                     "seed": int(seed)})
        return ValveTable.from_arrays(uu, pp, q, meta, source="<flow stage>")

    def blocked_port(self, u_values: Sequence[float], margin: float = 0.05,
                     noise: float = 0.0, seed: int = 0) -> np.ndarray:
        """The pressure gain characteristic as a bench measures it: the port blocked
        (q = 0 exactly) at each command, its pressure p_e(u) read with Gaussian noise of
        ``noise`` Pa standard deviation.

        Only commands whose p_e lies more than ``margin`` x (supply - atmosphere) inside
        both ends are returned: there the port is saturated at atmosphere or supply
        (p_e no longer depends on u), the pressure gain characteristic is flat and
        carries no gain, and the nozzle law's infinite slope at the ends is what a
        polynomial in p cannot follow (:mod:`.blocked`). Returns rows (u in V, p_e in Pa).
        """
        from scipy import optimize
        if not (math.isfinite(noise) and noise >= 0):
            raise InputError(f"expected a noise standard deviation >= 0 (Pa), got {noise!r}",
                             location="noise")
        if not 0.0 <= margin < 0.5:
            raise InputError(f"expected a margin in [0, 0.5), got {margin!r}", location="margin")
        lo, hi = self.atmospheric_pressure, self.supply_pressure
        flow = _numeric(self.flow)
        rng = np.random.default_rng(seed)
        rows = []
        for u in np.asarray(u_values, dtype=float):
            pe = optimize.brentq(lambda p: float(flow(p, u)), lo, hi, xtol=1e-6, rtol=1e-14)
            if lo + margin * (hi - lo) < pe < hi - margin * (hi - lo):
                rows.append([float(u), pe + (rng.normal(0.0, noise) if noise > 0 else 0.0)])
        return np.array(rows).reshape(-1, 2)

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "kind": "3/2 flow stage (two ISO 6358 restrictions, rounded "
                                        "underlap)", "max_flow_kg_s": self.max_flow()}

    def summary(self) -> str:
        return (f"3/2 flow stage: supply {self.supply_pressure / 1e5:.3g} bar abs, C_S "
                f"{self.inlet_conductance:.3g}, C_E {self.exhaust_conductance:.3g} m^3/(s Pa), "
                f"b {self.critical_pressure_ratio:g}, underlap {self.underlap:g}, u "
                f"{self.command_center - self.command_span:g}..."
                f"{self.command_center + self.command_span:g} V")


def chebyshev_pressures(low: float, high: float, n: int) -> np.ndarray:
    """``n`` Chebyshev-Lobatto pressures on [low, high] (Pa), ends included.

    Denser near both ends, where the nozzle law bends (subsonic near supply for the
    inlet, near atmosphere for the exhaust: paper 003's "border effect"); the nodes
    that keep a degree-(n-1) polynomial fit from oscillating between samples.
    """
    if n < 2:
        raise InputError(f"expected at least 2 pressures, got {n}", location="pressures")
    k = np.arange(n)
    return 0.5 * (low + high) - 0.5 * (high - low) * np.cos(np.pi * k / (n - 1))
