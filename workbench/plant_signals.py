"""What each signal of a plant means: kind, SI unit, scale, rest value, part, effect.

:class:`Signal` describes one state, input or output; :func:`state_signals` lists the
states a plant file's effects give, and :func:`valued` fills in the scale and rest
value of each for that plant. :class:`workbench.plant.Plant` holds the results
(``plant.states``, ``plant.inputs``, ``plant.outputs``) and re-exports the names
defined here, so nothing outside these two modules reads meaning from names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Sequence

from . import equilibrium
from .params import PlantParams
from .physics import piston

__all__ = ["Signal", "OUTPUT_SIGNALS", "INPUT_SIGNALS", "KINDS", "PRESSURE_SCALE",
           "VELOCITY_SCALE", "FLOW_SCALE", "state_signals", "valued"]


#: Kinds of signal, each with its SI unit (:attr:`Signal.kind`).
KINDS: dict[str, str] = {
    "position": "m", "velocity": "m/s", "pressure": "Pa", "temperature": "K",
    "mass_flow": "kg/s", "force": "N", "command": "V", "spool": "V", "spool_rate": "V/s",
}

#: Scale of every pressure, Pa: 1 bar, the resolution at which a rig engineer reads them.
PRESSURE_SCALE = 1e5
#: Scale of the piston velocity, m/s: the order of a servo-pneumatic drive's top speed.
VELOCITY_SCALE = 1.0
#: Scale of every mass flow, kg/s: 1 g/s (~50 l/min ANR), the order of a servo valve's
#: flow near its centre (a fully open valve passes 4-40 g/s on the reference plants).
FLOW_SCALE = 1e-3


@dataclass(frozen=True)
class Signal:
    """Name, SI unit and meaning of a state, input or output.

    Attributes
    ----------
    name : str
    unit : str
        SI unit (that of :data:`KINDS` for its kind).
    doc : str
    kind : str
        What it measures, a key of :data:`KINDS` (``"position"``, ``"pressure"``, ...).
    scale : float
        Its typical magnitude for this plant, in ``unit``: **the magnitude used to
        scale tolerances and residuals** (integrator tolerances, equilibrium
        residuals, least-squares weights, finite-difference steps). Stroke for the
        position, :data:`VELOCITY_SCALE`, :data:`PRESSURE_SCALE`, :data:`FLOW_SCALE`,
        the gas temperature for temperatures, the command span for the command and
        spool, span x 2 pi x bandwidth for the spool rate, the full-supply force on
        side a for forces.
    rest : float
        Its value at rest for the nominal parameters, in ``unit``: mid-stroke, zero
        velocity and flows, chamber and line pressures at the centre balance of the
        valve (:func:`workbench.equilibrium.rest_pressure`), temperatures the gas
        temperature, the command and spool the valve centre
        (``command_center + null_offset``), the supply its set pressure.
    part : str
        Part of the drive: ``"piston"``, ``"chamber"``, ``"line"``, ``"valve"`` or ``"supply"``.
    effect : str
        The effect that adds this state (``"valve_dynamics"``, ``"heat_transfer"``,
        ``"line_dynamics"``, ``"supply_droop"``); ``""`` for the basic drive's
        signals (x, v, p_a, p_b, the command, the outputs).
    follows : str
        Name of the state or input whose value this one takes at rest
        (``"p_a"`` for the nodes of line a, ``"u"`` for the spool), or ``""``.
    rest_key : str
        Plant-file key whose value is the rest value (``"gas.temperature"``,
        ``"supply.pressure"``), or ``""``.
    """

    name: str
    unit: str
    doc: str = ""
    kind: str = ""
    scale: float = 1.0
    rest: float = 0.0
    part: str = ""
    effect: str = ""
    follows: str = ""
    rest_key: str = ""


#: Outputs of every plant, in the order of ``h`` (names, units and meanings; a
#: plant's :attr:`~workbench.plant.Plant.outputs` carry its scales and rest values as well).
OUTPUT_SIGNALS: tuple[Signal, ...] = (
    Signal("x", "m", "piston position", "position", part="piston"),
    Signal("v", "m/s", "piston velocity", "velocity", part="piston"),
    Signal("p_a", "Pa", "pressure in chamber a", "pressure", part="chamber"),
    Signal("p_b", "Pa", "pressure in chamber b", "pressure", part="chamber"),
    Signal("p_s", "Pa", "supply pressure at the valve", "pressure", part="supply",
           rest_key="supply.pressure"),
    Signal("q_supply", "kg/s", "mass flow drawn from the supply", "mass_flow", part="supply"),
    Signal("force", "N", "net pneumatic force on the piston", "force", part="piston"),
)

#: The input of every plant: the valve command.
INPUT_SIGNALS: tuple[Signal, ...] = (Signal("u", "V", "valve command", "command", part="valve"),)


def state_signals(params: PlantParams, segments: int) -> tuple[Signal, ...]:
    """The state signals of a plant, in state order (kind, part, effect, rest rule).

    Parameters
    ----------
    params : PlantParams
        The plant file: its effects decide which states exist.
    segments : int
        Segments of each line (0 without ``line_dynamics``).

    Returns
    -------
    tuple of Signal
        x, v, p_a, p_b, then spool and spool rate, the chamber temperatures, line a's
        node pressures and segment flows, line b's, and the reservoir pressure, each
        only with its effect. Scales and rests are left at their defaults (see
        :func:`valued`).
    """
    s = [Signal("x", "m", "piston position", "position", part="piston"),
         Signal("v", "m/s", "piston velocity", "velocity", part="piston"),
         Signal("p_a", "Pa", "pressure in chamber a", "pressure", part="chamber"),
         Signal("p_b", "Pa", "pressure in chamber b", "pressure", part="chamber")]
    if params.has_effect("valve_dynamics"):
        eff = "valve_dynamics"
        s += [Signal("spool", "V", "command the spool currently follows", "spool",
                     part="valve", effect=eff, follows="u"),
              Signal("spool_rate", "V/s", "its rate", "spool_rate", part="valve",
                     effect=eff)]
    if params.has_effect("heat_transfer"):
        s += [Signal(f"T_{c}", "K", f"gas temperature in chamber {c}", "temperature",
                     part="chamber", effect="heat_transfer", rest_key="gas.temperature")
              for c in ("a", "b")]
    for side in ("a", "b"):
        s += [Signal(f"line_{side}_p{j}", "Pa", f"pressure of line {side} node {j}",
                     "pressure", part="line", effect="line_dynamics", follows=f"p_{side}")
              for j in range(segments)]
        s += [Signal(f"line_{side}_q{j}", "kg/s", f"mass flow of line {side} segment {j}",
                     "mass_flow", part="line", effect="line_dynamics")
              for j in range(segments)]
    if params.has_effect("supply_droop"):
        s += [Signal("p_s", "Pa", "reservoir (supply) pressure", "pressure", part="supply",
                     effect="supply_droop", rest_key="supply.pressure")]
    return tuple(s)


def valued(params: PlantParams, signals: Sequence[Signal], stroke: float, area_a: float,
           area_b: float) -> tuple[Signal, ...]:
    """``signals`` with this plant's scale and rest value (see :class:`Signal`).

    Parameters
    ----------
    params : PlantParams
        The plant file (nominal values).
    signals : sequence of Signal
        Signals whose ``kind`` (and ``rest_key``) are set.
    stroke : float
        Cylinder stroke, m.
    area_a, area_b : float
        Piston areas on sides a and b, m^2.

    Returns
    -------
    tuple of Signal
    """
    span = float(params["valve.command_span"])
    centre = float(params["valve.command_center"]) + float(params.get("valve.null_offset", 0.0))
    p_s, p_atm = float(params["supply.pressure"]), float(params["gas.atmospheric_pressure"])
    p_rest = equilibrium.rest_pressure(params)
    scale = {"position": stroke, "velocity": VELOCITY_SCALE,
             "pressure": PRESSURE_SCALE, "temperature": float(params["gas.temperature"]),
             "mass_flow": FLOW_SCALE, "force": (p_s - p_atm) * area_a,
             "command": span, "spool": span}
    if params.has_effect("valve_dynamics"):
        scale["spool_rate"] = span * 2.0 * math.pi * float(params["valve.bandwidth"])
    rest = {"position": 0.5 * stroke, "pressure": p_rest, "command": centre,
            "spool": centre,
            "force": piston.pneumatic_force(p_rest, p_rest, area_a, area_b, p_atm)}
    out = []
    for sig in signals:
        value = float(params[sig.rest_key]) if sig.rest_key else rest.get(sig.kind, 0.0)
        out.append(replace(sig, scale=float(scale[sig.kind]), rest=float(value)))
    return tuple(out)
