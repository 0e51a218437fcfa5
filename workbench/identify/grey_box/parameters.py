"""Parameters to estimate: names resolved against the plant, bounds, scaling.

Each estimated parameter is optimised as ``z``: log(value / start) when its bounds are
positive, else (value - start) / typical size (:class:`_Param`)."""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from typing import Mapping, Sequence

from ...errors import InputError
from ...params import EFFECTS, SCHEMA
from ...plant import Plant


#: Typical size of parameters whose start value may be zero (SI), used for scaling
#: and for default bounds of parameters that may be zero or negative.
_TYPICAL: dict[str, float] = {
    "load.viscous_friction": 10.0,
    "load.external_force": 10.0,
    "valve.null_offset": 0.1,
    "valve.command_center": 0.5,
    "valve.deadband": 0.02,
    "friction.coulomb": 5.0,
    "friction.static": 5.0,
    "friction.stribeck_velocity": 0.01,
    "leakage.conductance_to_atmosphere": 1e-10,
    "leakage.cross_piston": 1e-9,
    "gas.heat_transfer_coefficient": 0.1,
    "cylinder.rod_diameter": 0.005,
}

_Z95 = 1.959963984540054
_UNITS = {k.path: k.unit for k in SCHEMA}
_KEYS = {k.path: k for k in SCHEMA}


@dataclass(frozen=True)
class _Param:
    name: str
    index: int          # in plant.p0
    start: float        # SI
    lo: float
    hi: float
    log: bool           # z = log(p / start), else z = (p - start) / scale
    scale: float
    unit: str

    def value(self, z: float) -> float:
        return self.start * math.exp(z) if self.log else self.start + self.scale * z

    def dvalue(self, z: float) -> float:
        return self.value(z) if self.log else self.scale

    def z_of(self, value: float) -> float:
        return math.log(value / self.start) if self.log else (value - self.start) / self.scale

    @property
    def z_bounds(self) -> tuple[float, float]:
        return self.z_of(self.lo), self.z_of(self.hi)


def _base_name(name: str) -> str:
    return name.split("[", 1)[0]


def _resolve_parameters(plant: Plant, parameters: Sequence[str],
                        bounds: Mapping[str, tuple[float, float]] | None) -> list[_Param]:
    if isinstance(parameters, str):
        parameters = [parameters]
    parameters = list(parameters)
    if not parameters:
        raise InputError("no parameters to estimate: give at least one dotted name, e.g. "
                         "load.mass")
    seen = set()
    out: list[_Param] = []
    for name in parameters:
        if not isinstance(name, str):
            raise InputError(f"parameter names are strings like 'load.mass', got {name!r}")
        if name in seen:
            raise InputError(f"parameter '{name}' is listed twice")
        seen.add(name)
        if name not in plant.param_names:
            raise InputError(_unknown_parameter_message(plant, name),
                             location=f"parameter '{name}'")
        out.append(_make_param(plant, name, (bounds or {}).get(name), parameters))
    for name in (bounds or {}):
        if name not in seen:
            raise InputError(f"bounds given for '{name}', which is not among the parameters to "
                             f"estimate ({', '.join(parameters)})", location=f"bounds '{name}'")
    return out


def _unknown_parameter_message(plant: Plant, name: str) -> str:
    base = _base_name(name)
    key = _KEYS.get(base)
    if key is not None and key.effect and not plant.params.has_effect(key.effect):
        keys = ", ".join(k.path for k in EFFECTS[key.effect])
        return (f"'{name}' belongs to the effect '{key.effect}', which this plant does not "
                f"have; switch it on first (plant file keys {keys}, or "
                f"plant.with_params(**{{...}}) with start values)")
    if key is not None and not key.physical:
        return (f"'{name}' is not a physical parameter (it does not enter the dynamics) and "
                "cannot be estimated")
    if key is not None and key.law is not None and key.law != plant.valve_law:
        return (f"'{name}' belongs to the valve law '{key.law}', but this plant uses "
                f"'{plant.valve_law}'")
    if key is not None and key.kind == "floats":
        entries = ", ".join(n for n in plant.param_names if n.startswith(base + "["))
        return (f"'{name}' is an array; estimate its entries by index, e.g. '{base}[0]' "
                f"(this plant has {entries})")
    hint = difflib.get_close_matches(name, list(plant.param_names) + list(_KEYS), 3, 0.6)
    msg = f"unknown parameter '{name}'"
    if hint:
        msg += f" (did you mean {' or '.join(repr(h) for h in hint)}?)"
    return msg + f"; parameters of this plant: {', '.join(plant.param_names)}"


def _rule_bounds(plant: Plant, name: str, estimated: Sequence[str]) -> tuple[float, float]:
    """Bounds from the plant file's consistency rules (params.py) that involve other keys."""
    prm = plant.params
    lo, hi = -math.inf, math.inf
    if name == "valve.command_center":
        lo, hi = prm["valve.command_min"], prm["valve.command_max"]
    elif name == "supply.pressure":
        lo = 1.01 * prm["gas.atmospheric_pressure"]
    elif name == "gas.atmospheric_pressure":
        hi = prm["supply.pressure"] / 1.01
    elif name == "cylinder.rod_diameter":
        hi = 0.99 * prm["cylinder.bore"]
    elif name == "friction.coulomb" and "friction.static" not in estimated:
        hi = prm["friction.static"]
    elif name == "friction.static" and "friction.coulomb" not in estimated:
        lo = prm["friction.coulomb"]
    return float(lo), float(hi)


def _make_param(plant: Plant, name: str, user: tuple[float, float] | None,
                estimated: Sequence[str] = ()) -> _Param:
    idx = plant.param_index(name)
    start = float(plant.p0[idx])
    base = _base_name(name)
    key = _KEYS.get(base)
    unit = _UNITS.get(base, "")
    typical = _TYPICAL.get(name, abs(start) if start != 0.0 else 1.0)
    s_lo = -math.inf if key is None or key.low is None else float(key.low)
    s_hi = math.inf if key is None or key.high is None else float(key.high)
    if key is not None and key.low_open:
        s_lo = s_lo + 1e-12 * max(abs(s_lo), typical)
    if key is not None and key.high_open:
        s_hi = s_hi - 1e-9 * max(abs(s_hi), 1.0)
    r_lo, r_hi = _rule_bounds(plant, name, estimated)
    s_lo, s_hi = max(s_lo, r_lo), min(s_hi, r_hi)
    if user is not None:
        try:
            lo, hi = (float(user[0]), float(user[1]))
        except (TypeError, ValueError, IndexError):
            raise InputError(f"bounds of '{name}' must be a pair (low, high) in "
                             f"{unit or 'SI units'}, got {user!r}",
                             location=f"bounds '{name}'") from None
        if not (lo < hi) or math.isnan(lo) or math.isnan(hi):
            raise InputError(f"bounds of '{name}' must have low < high, got [{lo:g}, {hi:g}]",
                             location=f"bounds '{name}'")
        if lo < s_lo or hi > s_hi:
            raise InputError(f"bounds [{lo:g}, {hi:g}] of '{name}' leave its admissible range "
                             f"[{s_lo:g}, {s_hi:g}] ({key.expected() if key else 'finite'}, "
                             "and the plant file's rules)", location=f"bounds '{name}'")
    else:
        if start > 0 and s_lo >= 0:
            lo, hi = start / 10.0, start * 10.0
        else:
            span = 10.0 * (_TYPICAL[name] if name in _TYPICAL else max(abs(start), 1e-12))
            lo, hi = start - span, start + span
        lo, hi = max(lo, s_lo), min(hi, s_hi)
        if s_lo >= 0 and start == 0.0:
            lo = s_lo
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise InputError(f"'{name}' needs finite bounds, got [{lo:g}, {hi:g}]",
                         location=f"bounds '{name}'")
    start = min(max(start, lo), hi)
    if lo > 0:
        return _Param(name, idx, start, lo, hi, True, 1.0, unit)
    scale = max(abs(start), typical, (hi - lo) / 100.0)
    return _Param(name, idx, start, lo, hi, False, scale, unit)
