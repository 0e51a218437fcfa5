"""Cylinder chambers: volumes and the pressure (and temperature) balance.

Chamber i with net mass inflow q (kg/s), volume V and volume rate dV/dt:
polytropic form dp/dt = k/V (r T q - p dV/dt) (physics.md); with wall heat
transfer the chamber temperature is a state and the energy balance is used.
"""

from __future__ import annotations

from .gas import GAMMA, R_AIR

__all__ = ["volumes", "pressure_rate", "inflow_for_pressure_rate",
           "pressure_temperature_rates", "chamber_mass"]


def volumes(x, v, area_a, area_b, stroke, dead_a, dead_b):
    """Chamber volumes and their rates.

    V_a = V_a0 + A_a x, V_b = V_b0 + A_b (L - x).

    Parameters
    ----------
    x, v : piston position (m) and velocity (m/s).
    area_a, area_b : piston areas on the a and b sides, m^2.
    stroke : m. dead_a, dead_b : chamber volumes at x = 0 (a) and x = stroke (b), m^3.

    Returns
    -------
    (V_a, V_b, dV_a/dt, dV_b/dt) in m^3 and m^3/s.
    """
    return (dead_a + area_a * x, dead_b + area_b * (stroke - x),
            area_a * v, -area_b * v)


def pressure_rate(p, volume, volume_rate, q, k, temperature, r=R_AIR):
    """Polytropic chamber: dp/dt = k/V (r T q - p dV/dt), Pa/s.

    Parameters
    ----------
    p : Pa. volume : m^3. volume_rate : m^3/s. q : net mass inflow, kg/s.
    k : polytropic index, -. temperature : K. r : gas constant, J/(kg K).
    """
    return k / volume * (r * temperature * q - p * volume_rate)


def inflow_for_pressure_rate(p, volume, volume_rate, dp, k, temperature, r=R_AIR):
    """Net mass inflow (kg/s) that gives the pressure rate ``dp`` (Pa/s).

    The inverse of :func:`pressure_rate` in q: q = (V dp/k + p dV/dt) / (r T).
    Arguments as in :func:`pressure_rate`.
    """
    return (volume * dp / k + p * volume_rate) / (r * temperature)


def pressure_temperature_rates(p, temp, volume, volume_rate, tq_in, q_in, q_out,
                               h, t_wall, gamma=GAMMA, r=R_AIR):
    """Chamber with wall heat transfer: energy and mass balance of an ideal gas.

    Parameters
    ----------
    p, temp : chamber pressure (Pa) and temperature (K).
    volume, volume_rate : m^3, m^3/s.
    tq_in : sum of T_k q_k over the entering flows (each at its own temperature), K kg/s.
    q_in, q_out : total mass flow entering and leaving (leaving gas is at ``temp``), kg/s, >= 0.
    h : wall heat transfer coefficient times area, W/K.
    t_wall : wall temperature, K.

    Returns
    -------
    (dp/dt, dT/dt) in Pa/s and K/s:
    dp/dt = gamma r/V (sum T_k q_k - T q_out) - gamma p/V dV/dt + (gamma-1)/V h (T_w - T),
    dT/dt = T (dp/dt / p + dV/dt / V - r T (q_in - q_out) / (p V)).
    """
    dp = (gamma * r / volume * (tq_in - temp * q_out)
          - gamma * p / volume * volume_rate
          + (gamma - 1.0) / volume * h * (t_wall - temp))
    dtemp = temp * (dp / p + volume_rate / volume - r * temp * (q_in - q_out) / (p * volume))
    return dp, dtemp


def chamber_mass(p, volume, temperature, r=R_AIR):
    """Mass of gas in a chamber, m = p V / (r T), kg (p in Pa, volume in m^3, T in K)."""
    return p * volume / (r * temperature)
