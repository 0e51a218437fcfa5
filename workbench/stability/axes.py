"""The axes of a stability map: which quantity is swept, over which values, in which unit.

An axis sweeps a plant parameter (dotted plant-file key, SI), the piston
``position`` (m), or a controller quantity (``kp``, ``kd``, ``ki``, ``k0`` = kp*Kv,
``sample_time``); :func:`parse_axis` reads the command line's ``NAME=START:STOP:NUM``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError

__all__ = ["Axis", "parse_axis", "AXIS_ALIASES", "CONTROLLER_AXES"]

#: Short names accepted for common plant parameters.
AXIS_ALIASES = {
    "mass": "load.mass",
    "payload": "load.mass",
    "supply_pressure": "supply.pressure",
    "supply": "supply.pressure",
    "line_length": "lines.length",
    "viscous_friction": "load.viscous_friction",
    "bore": "cylinder.bore",
    "T": "sample_time",
    "x": "position",
}

#: Axes that belong to the controller (no re-linearisation), with units.
CONTROLLER_AXES = {"kp": "V/m", "kd": "V s/m", "ki": "V/(m s)", "k0": "1/s",
                   "sample_time": "s"}


def _units_of(name: str) -> str:
    """SI unit of the swept quantity ``name`` (``""`` when unknown)."""
    if name in CONTROLLER_AXES:
        return CONTROLLER_AXES[name]
    if name == "position":
        return "m"
    from ..params import SCHEMA
    for key in SCHEMA:
        if f"{key.section}.{key.name}" == name:
            return key.unit
    return ""


@dataclass(frozen=True)
class Axis:
    """One swept quantity: a plant parameter (dotted name, SI), ``position`` (m),
    or a controller quantity (``kp``, ``kd``, ``ki``, ``k0`` = kp*Kv in 1/s,
    ``sample_time``)."""

    name: str
    values: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        name = AXIS_ALIASES.get(self.name, self.name)
        object.__setattr__(self, "name", name)
        vals = np.asarray(self.values, dtype=float).ravel()
        if vals.size < 2:
            raise InputError(f"axis {name!r} needs at least 2 values")
        if not np.all(np.isfinite(vals)):
            raise InputError(f"axis {name!r} has non-finite values")
        if np.any(np.diff(vals) <= 0):
            raise InputError(f"axis {name!r} values must be strictly increasing")
        vals.setflags(write=False)
        object.__setattr__(self, "values", vals)

    @classmethod
    def linspace(cls, name: str, start: float, stop: float, num: int = 100) -> "Axis":
        return cls(name, np.linspace(start, stop, int(num)))

    @classmethod
    def logspace(cls, name: str, start: float, stop: float, num: int = 100) -> "Axis":
        if start <= 0 or stop <= 0:
            raise InputError(f"log axis {name!r} needs positive bounds")
        return cls(name, np.geomspace(start, stop, int(num)))

    @property
    def unit(self) -> str:
        return _units_of(self.name)

    @property
    def label(self) -> str:
        return f"{self.name} ({self.unit})" if self.unit else self.name

    @property
    def kind(self) -> str:
        if self.name in CONTROLLER_AXES:
            return "controller"
        if self.name == "position":
            return "position"
        return "plant"

    def __len__(self) -> int:
        return len(self.values)


def parse_axis(text: str) -> Axis:
    """``"name=start:stop:num"`` (``:log`` appended for a log axis) -> :class:`Axis`."""
    try:
        name, spec = text.split("=", 1)
        parts = spec.split(":")
        log = parts[-1] == "log"
        if log:
            parts = parts[:-1]
        start, stop = float(parts[0]), float(parts[1])
        num = int(parts[2]) if len(parts) > 2 else 100
    except (ValueError, IndexError):
        raise InputError(f"axis {text!r}: expected NAME=START:STOP[:NUM][:log], "
                         "e.g. kp=1:40:100 or load.mass=0.5:5:100") from None
    if num < 2 or num > 2000:
        raise InputError(f"axis {text!r}: NUM must be 2..2000")
    return (Axis.logspace if log else Axis.linspace)(name.strip(), start, stop, num)

