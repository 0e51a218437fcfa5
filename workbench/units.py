"""Unit conversions at the edges (SI inside the workbench)."""

from __future__ import annotations

from .physics.gas import RHO_ANR

__all__ = ["BAR", "bar_to_pa", "pa_to_bar", "mm_to_m", "m_to_mm",
           "kg_s_to_l_min_anr", "l_min_anr_to_kg_s", "l_s_bar_to_si"]

BAR = 1e5  #: Pa per bar


def bar_to_pa(p_bar: float) -> float:
    return p_bar * BAR


def pa_to_bar(p_pa: float) -> float:
    return p_pa / BAR


def mm_to_m(x_mm: float) -> float:
    return x_mm * 1e-3


def m_to_mm(x_m: float) -> float:
    return x_m * 1e3


def kg_s_to_l_min_anr(q_kg_s: float) -> float:
    """Mass flow (kg/s) as standard volume flow in litres per minute ANR (1.185 kg/m^3)."""
    return q_kg_s / RHO_ANR * 1e3 * 60.0


def l_min_anr_to_kg_s(q_l_min: float) -> float:
    return q_l_min / 60.0 / 1e3 * RHO_ANR


def l_s_bar_to_si(c_l_s_bar: float) -> float:
    """Sonic conductance from l/(s bar) (datasheets) to m^3/(s Pa)."""
    return c_l_s_bar * 1e-3 / BAR
