"""Stability of the sampled position loop: gain limits and parameter-sweep maps.

:mod:`.limits` gives the continuous Hurwitz, PCT and exact sampled-data gain limits
and the margins; :mod:`.maps` sweeps two parameters into a stability map.
"""

from .limits import (
    GainLimits,
    closed_loop_poles,
    continuous_limit,
    gain_limits,
    limits_from_plant,
    pct_closed_loop_poles,
    pct_limit,
    pct_time_constant,
    sampled_gain_limit,
    unit_circle_crossings,
    zoh_position_loop,
)
from .maps import Axis, StabilityMap, parse_axis, stability_map

__all__ = [
    "Axis", "StabilityMap", "stability_map", "parse_axis",
    "GainLimits", "gain_limits", "limits_from_plant", "sampled_gain_limit",
    "unit_circle_crossings", "zoh_position_loop", "pct_time_constant",
    "continuous_limit", "pct_limit", "closed_loop_poles", "pct_closed_loop_poles",
]
