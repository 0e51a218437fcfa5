"""Supply with droop (reservoir behind a regulator) and leakage paths."""

from __future__ import annotations

from .gas import NOZZLE_CRITICAL_RATIO, R_AIR, iso6358_flow

__all__ = ["reservoir_rate", "leak_to_atmosphere", "cross_piston_leak"]


def reservoir_rate(p_s, p_set, regulator_conductance, volume, q_out, temperature,
                   k=1.0, r=R_AIR, b=NOZZLE_CRITICAL_RATIO):
    """dp_s/dt of the reservoir (Pa/s) fed from a source at ``p_set`` through the regulator.

    The regulator is an ISO 6358 restriction of conductance C_reg (m^3/(s Pa));
    the reservoir of ``volume`` (m^3) feeds the valve with ``q_out`` (kg/s). At no
    flow p_s = p_set; under flow it sags (droop).
    """
    q_in = iso6358_flow(regulator_conductance, b, p_set, p_s, temperature, temperature)
    return k * r * temperature / volume * (q_in - q_out)


def leak_to_atmosphere(p, p_atm, conductance, temperature, b=NOZZLE_CRITICAL_RATIO):
    """Leak (kg/s) from a chamber at p to atmosphere through an ISO 6358 gap."""
    return iso6358_flow(conductance, b, p, p_atm, temperature, temperature)


def cross_piston_leak(p_a, p_b, conductance):
    """Laminar leak (kg/s) from chamber a to chamber b: c (p_a - p_b)."""
    return conductance * (p_a - p_b)
