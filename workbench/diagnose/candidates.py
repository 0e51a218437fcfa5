"""The candidate explanations: each effect of formats.md section 2 and wrong nominal values.

A :class:`Candidate` says which plant-file keys it adds or changes, which of them are
fitted (:class:`Free`, with bounds and a transform so that the optimiser works on
numbers of order one), which are held (e.g. the number of line segments), the grid
its signature is scanned on, and whether it needs the chamber pressures to be seen.
Bounds scale with the nominal plant (valve conductance, force capacity, mass), so
they hold for any rig, not only the one the tests use.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from ..params import EFFECT_NAMES, PlantParams

__all__ = ["Free", "Candidate", "candidates", "PARAMETER_ERROR_KEYS", "LINE_SEGMENTS",
           "SPOOL_BANDWIDTH_MAX",
           "JOINT_NOMINAL"]

#: Nominal values whose error the diagnosis looks for (``parameter_error``).
PARAMETER_ERROR_KEYS = ("load.mass", "load.viscous_friction", "valve.sonic_conductance",
                        "supply.pressure")
#: Name of the candidate that corrects every nominal value of
#: :data:`PARAMETER_ERROR_KEYS` at once.
JOINT_NOMINAL = "parameter_error:nominal values"
#: Upper bound of the fitted spool bandwidth, Hz (also its neutral value: no lag at the
#: sample rates of a recording); the engine sizes a spool's steps for it
#: (:func:`workbench.diagnose.engine.stiff_substeps`), whatever the fit's start.
SPOOL_BANDWIDTH_MAX = 400.0
#: Lumped segments per line in the fitted line model (the length is what matters
#: for volume, delay and attenuation; more segments only add wave detail).
LINE_SEGMENTS = 3


@dataclass(frozen=True)
class Free:
    """A fitted value: plant key (or a derived quantity), bounds, start, transform.

    ``log`` fits log(value) (for positive quantities spanning decades); otherwise
    (value - 0) / scale. ``key`` may be a plant key or a derived name handled by the
    candidate (``friction.static_excess``: static = coulomb (1 + excess)).
    """

    key: str
    low: float
    high: float
    start: float
    log: bool = True
    scale: float = 1.0

    def to_z(self, value: float) -> float:
        value = min(max(value, self.low), self.high)
        return math.log(value) if self.log else value / self.scale

    def from_z(self, z: float) -> float:
        return math.exp(z) if self.log else z * self.scale

    @property
    def z_bounds(self) -> tuple[float, float]:
        return (self.to_z(self.low), self.to_z(self.high))


@dataclass(frozen=True)
class Candidate:
    """One explanation to test.

    Attributes
    ----------
    name : unique label (``"dry_friction"``, ``"parameter_error:load.mass"``).
    effect : the effect name reported (formats.md section 2), or ``"parameter_error"``.
    free : fitted values.
    fixed : plant keys set to fixed values when the candidate is added.
    grid : values (key -> list) whose combinations are scanned for the signature.
    needs_pressures : only visible in the chamber pressures.
    describe : one line for the report.
    neutral : values at which the candidate changes the model least (see
        :meth:`neutral_values`).
    size : the values whose neutral values make the effect vanish whatever the others
        (Coulomb force, deadband width, leak conductances, ...); empty when no value
        does (heat transfer: its least value is adiabatic, not the nominal polytropic
        chamber).
    """

    name: str
    effect: str
    free: tuple[Free, ...]
    fixed: Mapping[str, Any] = field(default_factory=dict)
    grid: Mapping[str, Sequence[float]] = field(default_factory=dict)
    needs_pressures: bool = False
    describe: str = ""
    neutral: Mapping[str, float] = field(default_factory=dict)
    size: tuple[str, ...] = ()

    @property
    def k(self) -> int:
        """Number of fitted values."""
        return len(self.free)

    def values(self, z: Sequence[float]) -> dict[str, float]:
        """Fitted values (candidate keys) from the optimiser's vector."""
        return {f.key: f.from_z(zi) for f, zi in zip(self.free, z)}

    def z0(self, start: Mapping[str, float] | None = None) -> np.ndarray:
        start = start or {}
        return np.array([f.to_z(start.get(f.key, f.start)) for f in self.free])

    def plant_values(self, values: Mapping[str, float]) -> dict[str, Any]:
        """Plant-file keys (dotted) for fitted values, derived keys resolved."""
        out: dict[str, Any] = dict(self.fixed)
        for k, v in values.items():
            if k == "friction.static_excess":
                continue
            out[k] = float(v)
        if "friction.static_excess" in values:
            out["friction.static"] = float(values["friction.coulomb"]
                                           * (1.0 + values["friction.static_excess"]))
        return out

    def neutral_values(self) -> dict[str, float]:
        """The values (candidate keys) at which this candidate changes the nominal model
        least: its ``neutral`` values (no leak, no offset, the narrowest deadband, ...),
        for a nominal-value correction the plant file's values. A set of candidates
        contains each of its subsets as the special case with the left-out member at
        these values (:mod:`.sets` starts a joint fit there too)."""
        if self.effect == "parameter_error":
            return {f.key: f.start for f in self.free}
        return dict(self.neutral)

    def apply(self, params: PlantParams, values: Mapping[str, float]) -> PlantParams:
        """The nominal parameters with this candidate added at ``values``."""
        return params.replace(**self.plant_values(values))

    def grid_points(self) -> list[dict[str, float]]:
        keys = list(self.grid)
        combos = itertools.product(*[self.grid[k] for k in keys])
        return [dict(zip(keys, combo)) for combo in combos]

    def reported(self, values: Mapping[str, float]) -> dict[str, float]:
        """``parameters`` of the diagnosis JSON: effect keys without section, or the
        dotted key of a corrected nominal value."""
        pv = self.plant_values(values)
        if self.effect == "parameter_error":
            return {k: float(v) for k, v in pv.items()}
        return {k.split(".", 1)[1]: float(v) for k, v in pv.items()
                if k.split(".", 1)[1] != "segments"}


def candidates(params: PlantParams, effects: Sequence[str] | None = None,
               has_pressures: bool = True) -> list[Candidate]:
    """The candidates for a nominal plant (effects it already has are left out).

    Parameters
    ----------
    params : nominal plant parameters.
    effects : restrict to these names (effect names, ``"parameter_error"`` or
        ``"parameter_error:<key>"``); default all.
    has_pressures : leave out what only pressures show when they are not recorded.

    Raises
    ------
    InputError
        A name in ``effects`` that is neither an effect, ``parameter_error`` nor a
        candidate.
    """
    sc = _Scales.of(params)
    have = set(params.effects)
    out = [c for c in _valve_and_friction(sc) + _air_path(sc) if c.effect not in have]
    out += _parameter_errors(params, sc)
    if not has_pressures:
        out = [c for c in out if not c.needs_pressures]
    singles = [c for c in out if c.effect == "parameter_error"]
    if len(singles) > 1:
        out.append(_joint_nominal(singles))
    if effects:
        out = _selected(out, effects)
    return out


@dataclass(frozen=True)
class _Scales:
    """Sizes of the nominal rig the candidates' bounds and grids scale with (SI)."""

    c_valve: float      #: sonic conductance of one valve edge, m^3/(s Pa)
    f_max: float        #: force capacity (p_s - p_atm) A, N
    span: float         #: valve command span, V
    mass: float         #: moving mass, kg
    beta: float         #: viscous friction, N s/m
    v_chamber: float    #: swept volume A L, m^3
    p_supply: float     #: supply pressure, Pa

    @classmethod
    def of(cls, params: PlantParams) -> "_Scales":
        area = math.pi / 4 * params["cylinder.bore"] ** 2
        return cls(c_valve=params["valve.sonic_conductance"]
                   if "valve.sonic_conductance" in params else 6e-8,
                   f_max=(params["supply.pressure"] - params["gas.atmospheric_pressure"]) * area,
                   span=params["valve.command_span"], mass=params["load.mass"],
                   beta=params["load.viscous_friction"],
                   v_chamber=area * params["cylinder.stroke"],
                   p_supply=params["supply.pressure"])


def _valve_and_friction(sc: _Scales) -> list[Candidate]:
    """Dry friction and the valve's deadband, null offset and spool dynamics."""
    f_max, span = sc.f_max, sc.span
    return [
        Candidate(
            "dry_friction", "dry_friction",
            (Free("friction.coulomb", 1e-3 * f_max, 0.6 * f_max, 0.05 * f_max),
             Free("friction.static_excess", 0.0, 3.0, 0.3, log=False, scale=1.0),
             Free("friction.stribeck_velocity", 1e-3, 0.2, 0.01)),
            grid={"friction.coulomb": [f_max * s for s in (0.015, 0.04, 0.08, 0.15, 0.3)],
                  "friction.static_excess": [0.0, 0.5],
                  "friction.stribeck_velocity": [0.01]},
            neutral={"friction.coulomb": 1e-3 * f_max, "friction.static_excess": 0.0,
                     "friction.stribeck_velocity": 0.01}, size=("friction.coulomb",),
            describe="Coulomb and static (break-away) friction with a Stribeck curve"),
        Candidate(
            "valve_deadband", "valve_deadband",
            (Free("valve.deadband", 0.002, 0.45, 0.03),),
            grid={"valve.deadband": [0.01, 0.025, 0.05, 0.08, 0.12, 0.2]},
            neutral={"valve.deadband": 0.002}, size=("valve.deadband",),
            describe="spool overlap: no flow for commands near the centre"),
        Candidate(
            "valve_offset", "valve_offset",
            (Free("valve.null_offset", -0.3 * span, 0.3 * span, 0.0, log=False,
                  scale=0.02 * span),),
            grid={"valve.null_offset": [s * span for s in (-0.08, -0.04, -0.02, -0.01,
                                                            0.01, 0.02, 0.04, 0.08)]},
            neutral={"valve.null_offset": 0.0}, size=("valve.null_offset",),
            describe="the spool is centred at another command than command_center"),
        Candidate(
            "valve_dynamics", "valve_dynamics",
            (Free("valve.bandwidth", 2.0, SPOOL_BANDWIDTH_MAX, 40.0), Free("valve.damping", 0.2, 3.0, 0.8)),
            grid={"valve.bandwidth": [8.0, 20.0, 50.0], "valve.damping": [0.7]},
            neutral={"valve.bandwidth": SPOOL_BANDWIDTH_MAX, "valve.damping": 0.8},
            size=("valve.bandwidth",),
            needs_pressures=False,
            describe="the spool follows the command through a 2nd-order lag"),
    ]


def _air_path(sc: _Scales) -> list[Candidate]:
    """Lines, leakage, supply droop and heat transfer (seen in the pressures)."""
    c_valve, v_chamber = sc.c_valve, sc.v_chamber
    return [
        Candidate(
            "line_dynamics", "line_dynamics",
            (Free("lines.length", 0.05, 30.0, 1.0), Free("lines.diameter", 1.5e-3, 15e-3, 4e-3)),
            fixed={"lines.segments": LINE_SEGMENTS},
            grid={"lines.length": [0.7, 2.0, 5.0], "lines.diameter": [3e-3, 5e-3]},
            neutral={"lines.length": 0.05, "lines.diameter": 4e-3},
            size=("lines.length",),
            needs_pressures=False,     # its volume and delay show in the position too
            describe="valve-chamber lines: extra volume, transport delay, pressure drop"),
        # leak conductances scaled with the valve: 1e-4 .. 0.03 of one valve edge
        Candidate(
            "leakage", "leakage",
            (Free("leakage.conductance_to_atmosphere", 0.0, 0.03 * c_valve, 2e-3 * c_valve,
                  log=False, scale=1e-3 * c_valve),
             Free("leakage.cross_piston", 0.0, 1e-6, 0.0, log=False, scale=1e-9)),
            grid={"leakage.conductance_to_atmosphere": [c_valve * s for s in
                                                        (0.0, 5e-4, 1.5e-3, 4e-3, 1e-2)],
                  "leakage.cross_piston": [0.0, 3e-9]},
            neutral={"leakage.conductance_to_atmosphere": 0.0, "leakage.cross_piston": 0.0},
            size=("leakage.conductance_to_atmosphere", "leakage.cross_piston"),
            needs_pressures=True,
            describe="leaks from the chambers to atmosphere and across the piston"),
        Candidate(
            "supply_droop", "supply_droop",
            (Free("supply.reservoir_volume", 0.02 * v_chamber, 500 * v_chamber, 5 * v_chamber),
             Free("supply.regulator_conductance", 0.02 * c_valve, 20.0 * c_valve,
                  0.3 * c_valve)),
            grid={"supply.reservoir_volume": [v_chamber * s for s in (0.5, 3.0, 20.0)],
                  "supply.regulator_conductance": [c_valve * s for s in (0.08, 0.25, 0.8)]},
            neutral={"supply.reservoir_volume": 500 * v_chamber,
                     "supply.regulator_conductance": 20.0 * c_valve},
            size=("supply.regulator_conductance",),
            needs_pressures=True,
            describe="the supply pressure sags under flow (reservoir behind a regulator)"),
        Candidate(
            "heat_transfer", "heat_transfer",
            (Free("gas.heat_transfer_coefficient", 1e-3, 50.0, 0.5),),
            grid={"gas.heat_transfer_coefficient": [0.05, 0.3, 1.5, 8.0]},
            # no value is the nominal polytropic chamber exactly: the least heat transfer
            neutral={"gas.heat_transfer_coefficient": 1e-3},
            needs_pressures=True,
            describe="chamber gas temperature varies (adiabatic when fast, isothermal when "
                     "slow)"),
    ]


def _parameter_errors(params: PlantParams, sc: _Scales) -> list[Candidate]:
    """Wrong nominal values (:data:`PARAMETER_ERROR_KEYS`); no conductance error for a
    valve law other than ISO 6358."""
    mass, beta, f_max, c_valve, p_s = sc.mass, sc.beta, sc.f_max, sc.c_valve, sc.p_supply
    pe = [
        Candidate("parameter_error:load.mass", "parameter_error",
                  (Free("load.mass", 0.1 * mass, 20.0 * mass, mass),),
                  grid={"load.mass": [mass * s for s in (0.5, 1.5, 2.5, 4.0)]},
                  describe="the moving mass is not the nominal one"),
        Candidate("parameter_error:load.viscous_friction", "parameter_error",
                  (Free("load.viscous_friction", 0.0, max(20 * beta, 0.2 * f_max), beta,
                        log=False, scale=max(beta, 1.0)),),
                  grid={"load.viscous_friction": [beta * s for s in (0.2, 2.0, 5.0)]
                        if beta > 0 else [0.01 * f_max, 0.05 * f_max, 0.2 * f_max]},
                  describe="the viscous friction is not the nominal one"),
        Candidate("parameter_error:valve.sonic_conductance", "parameter_error",
                  (Free("valve.sonic_conductance", 0.2 * c_valve, 5 * c_valve, c_valve),),
                  grid={"valve.sonic_conductance": [c_valve * s for s in (0.6, 0.85, 1.2, 1.6)]},
                  describe="the valve passes more or less air than its nominal conductance"),
        Candidate("parameter_error:supply.pressure", "parameter_error",
                  (Free("supply.pressure", 0.6 * p_s, 1.3 * p_s, p_s),),
                  grid={"supply.pressure": [p_s * s for s in (0.85, 0.95, 1.05)]},
                  needs_pressures=True,
                  describe="the supply pressure is not the nominal one"),
    ]
    if params.get("valve.law", "iso6358") != "iso6358":
        pe = [c for c in pe if "sonic_conductance" not in c.name]
    return pe


def _joint_nominal(pe: Sequence[Candidate]) -> Candidate:
    """All nominal values corrected at once (one member of a set, :data:`JOINT_NOMINAL`).

    Wrong nominal values trade off, so they must be fitted jointly: the valve's mass
    flow scales with ``C p_s``, so a conductance 6 % high and a supply 5 % low leave the
    flow within 1 % of nominal and neither correction alone removes much of the
    mismatch (measured: 12 % and 3 % of the short-horizon error, the supply left at its
    nominal value), while both together do; likewise mass and viscous friction share
    the acceleration. Started at the nominal values (no scan: a 5-10 % error is well
    inside the least squares' reach in log coordinates)."""
    return Candidate(JOINT_NOMINAL, "parameter_error", tuple(f for c in pe for f in c.free),
                     describe="several nominal values are wrong at once ("
                              + ", ".join(f.key for c in pe for f in c.free) + ")")


def _selected(cands: list[Candidate], effects: Sequence[str]) -> list[Candidate]:
    """The candidates named in ``effects`` (by effect or candidate name)."""
    wanted = set(effects)
    unknown = wanted - set(EFFECT_NAMES) - {"parameter_error"} - {c.name for c in cands}
    if unknown:
        from ..errors import InputError
        raise InputError(f"unknown candidate(s) {', '.join(sorted(unknown))}; known: "
                         + ", ".join(list(EFFECT_NAMES) + ["parameter_error"]))
    return [c for c in cands if c.name in wanted or c.effect in wanted]
