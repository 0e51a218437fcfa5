"""Valve tables generated from a plant's four-edge valve with a rounded underlap."""

from __future__ import annotations

import math
import os
from typing import Any, Callable, Sequence

import casadi as ca
import numpy as np

from ...errors import InputError
from ...params import PlantParams
from ...physics import gas
from ...physics.valve import (affine_flow, effective_opening, gamma_odd, rounded_edge_openings,
                               spool_position)
from ._numeric import numeric as _numeric
from .table import ValveTable

__all__ = ["valve_flow_law", "centre_dense_commands", "generate_valve_table"]


def _params_of(plant_or_params) -> PlantParams:
    if isinstance(plant_or_params, PlantParams):
        return plant_or_params
    if isinstance(plant_or_params, (str, os.PathLike)):
        return PlantParams.from_toml(plant_or_params)
    prm = getattr(plant_or_params, "params", None)
    if isinstance(prm, PlantParams):
        return prm
    raise TypeError(f"expected a Plant, PlantParams or a plant file, got {plant_or_params!r}")


def valve_flow_law(plant_or_params, leakage: float = 0.0) -> Callable:
    """The port flow q_m(p, u) (kg/s) of a plant's valve, as a CasADi-traceable function.

    The port-A flow of the plant's 5/3 valve with the port at pressure p (Pa) and
    command u (V): the plant's command centre, span, null offset and deadband, its
    supply and atmospheric pressures and temperature. Under ``law = "iso6358"`` the
    four ISO 6358 edges; ``leakage`` = d gives every edge a symmetric, rounded
    underlap: for the signed opening o the inlet (supply -> port) edge opens
    (sqrt(o^2 + d^2) + o) / 2 and the exhaust (port -> atmosphere) edge
    (sqrt(o^2 + d^2) - o) / 2 instead of max(o, 0) and max(-o, 0). At the centre both
    are open d/2: the port is fed from the supply and leaks to the exhaust, and the
    flow is zero at a pressure between atmosphere and supply that moves with u (the
    pressure gain characteristic). An overlapped edge still passes d^2 / (4 |o|), the
    clearance leakage that falls with the overlap length; an open edge tends to o.
    The flow is smooth in u. With d = 0 this is exactly
    :func:`workbench.physics.valve.four_edge_flows`. Under ``law = "input_affine"``
    the plant's affine law (``leakage`` must then be 0).

    Parameters
    ----------
    plant_or_params : Plant, PlantParams or plant file path
    leakage : float
        Underlap d of every edge, fraction of full opening (of the command span), in [0, 1).
    """
    prm = _params_of(plant_or_params)
    if not 0.0 <= leakage < 1.0:
        raise InputError(f"expected a leakage (underlap) in [0, 1) of the span, got {leakage!r}",
                         location="leakage")
    center = prm["valve.command_center"]
    span = prm["valve.command_span"]
    offset = prm.get("valve.null_offset", 0.0)
    deadband = prm.get("valve.deadband", 0.0)
    p_s, p_atm, T = prm["supply.pressure"], prm["gas.atmospheric_pressure"], prm["gas.temperature"]

    def opening(u):
        s = spool_position(u, center, span, offset)
        # effective_opening(s, 0) equals s but its CasADi derivative at s = 0 is 0.75
        # (fmax/fmin ties in its clip); without a deadband s is used directly.
        return effective_opening(s, deadband) if deadband else s

    if prm["valve.law"] == "input_affine":
        if leakage:
            raise InputError("leakage can only be added to a four-edge (iso6358) valve; "
                             "this plant's valve law is 'input_affine'", location="leakage")
        phi, psi_in, psi_out, gam = (prm[f"valve.affine_{k}"] for k in
                                     ("phi", "psi_in", "psi_out", "gamma"))

        def flow(p, u):
            return affine_flow(p, gamma_odd(opening(u), gam), phi, psi_in, psi_out)
        return flow
    C, b = prm["valve.sonic_conductance"], prm["valve.critical_pressure_ratio"]
    d = float(leakage)

    def flow(p, u):
        # physics.valve's rounded underlap law (with d = 0 exactly the plant's four edges)
        o_in, o_out = rounded_edge_openings(opening(u), d)
        return (o_in * gas.iso6358_flow(C, b, p_s, p, T, T)
                - o_out * gas.iso6358_flow(C, b, p, p_atm, T, T))
    return flow


def centre_dense_commands(center: float, span: float, n: int = 21,
                          power: float = 2.0) -> np.ndarray:
    """``n`` commands (V) over [center - span, center + span], denser near the centre.

    u = center + span sign(x) |x|^power for x evenly spaced in [-1, 1]: paper 003
    measured more densely where the characteristic is nonlinear (around the centre,
    where the pressure gain characteristic lives).
    """
    x = np.linspace(-1.0, 1.0, int(n))
    return center + span * np.sign(x) * np.abs(x) ** power


def generate_valve_table(plant_or_params, u_values: Sequence[float] | None = None,
                         p_values: Sequence[float] | None = None, leakage: float = 0.0,
                         noise: float = 0.0, seed: int = 0,
                         made_with: str | None = None) -> ValveTable:
    """A valve table q_m(p, u) from a plant's physical valve (:func:`valve_flow_law`).

    Parameters
    ----------
    plant_or_params : Plant, PlantParams or plant file path
    u_values : commands, V (default :func:`centre_dense_commands` over the span, 21).
    p_values : port pressures, Pa absolute (default 15 from atmosphere to supply).
    leakage : symmetric geometric underlap of every edge, fraction of the span.
    noise : standard deviation of Gaussian noise added to every flow, kg/s.
    seed : seed of the noise generator.
    made_with : text stored as the ``made_with`` metadata (the command that made it).

    Returns
    -------
    ValveTable
        The full grid, u varying slowest; metadata records the plant, supply and
        atmospheric pressures, temperature, command centre and span, leakage,
        noise and seed.
    """
    prm = _params_of(plant_or_params)
    if noise < 0 or not math.isfinite(noise):
        raise InputError(f"expected a noise standard deviation >= 0 (kg/s), got {noise!r}",
                         location="noise")
    p_s, p_atm = prm["supply.pressure"], prm["gas.atmospheric_pressure"]
    center, span = prm["valve.command_center"], prm["valve.command_span"]
    u_values = (centre_dense_commands(center, span) if u_values is None
                else np.asarray(u_values, dtype=float))
    p_values = (np.linspace(p_atm, p_s, 15) if p_values is None
                else np.asarray(p_values, dtype=float))
    uu, pp = (a.ravel() for a in np.meshgrid(u_values, p_values, indexing="ij"))
    q = _numeric(valve_flow_law(prm, leakage))(pp, uu)
    if noise > 0:
        q = q + np.random.default_rng(seed).normal(0.0, noise, q.shape)
    meta: dict[str, Any] = {}
    if made_with:
        meta["made_with"] = made_with
    meta.update({
        "plant": f"{prm.name} ({prm.source})",
        "generator": "workbench.identify.valve.generate_valve_table: port A flow of the "
                     "four-edge valve, every edge with a rounded underlap 'leakage'",
        "supply_pressure": float(p_s), "atmospheric_pressure": float(p_atm),
        "temperature": float(prm["gas.temperature"]),
        "command_center": float(center), "command_span": float(span),
        "leakage": float(leakage), "noise_kg_s": float(noise), "seed": int(seed),
    })
    return ValveTable.from_arrays(uu, pp, q, meta, source="<generated>")
