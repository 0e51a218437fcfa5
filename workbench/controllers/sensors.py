"""The sensors of a real rig, between the simulated plant and a controller.

:class:`RigSensors` wraps a controller: before each update it quantises the position
(an ADC of ``position_bits`` over the stroke), adds white noise to the chamber
pressures and removes the velocity, so the controller sees what a rig with a
position transducer and two pressure sensors measures. The noise is drawn from a
seeded generator, restarted at every :meth:`reset`, so runs are reproducible.

Examples
--------
>>> from workbench.controllers import PID
>>> from workbench.controllers.sensors import RigSensors
>>> s = RigSensors(PID(kp=5.0, sample_time=0.01, u_center=5.0), stroke=0.5, position_bits=12)
>>> round(s.quantum * 1e3, 4)                   # mm per count
0.1221
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["RigSensors"]


@dataclass(frozen=True)
class RigSensors:
    """Position ADC, noisy pressure sensors, no velocity sensor (a DiscreteController).

    Attributes
    ----------
    inner : DiscreteController (must not need ``v``).
    stroke : float, m (the ADC spans 0 .. stroke).
    position_bits : int or None; None: the position as given.
    pressure_noise : float, Pa, std of each pressure sensor's white noise.
    position_noise : float, m, std of white noise added before quantisation.
    seed : int, of the noise generator.
    """

    inner: Any
    stroke: float
    position_bits: int | None = 12
    pressure_noise: float = 0.0
    position_noise: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not (isinstance(self.stroke, (int, float)) and math.isfinite(self.stroke)
                and self.stroke > 0):
            raise InputError(f"stroke must be > 0 m, got {self.stroke!r}")
        if self.position_bits is not None and not (isinstance(self.position_bits, int)
                                                   and 1 <= self.position_bits <= 32):
            raise InputError(f"position_bits must be an integer in 1..32, got {self.position_bits!r}")
        for name in ("pressure_noise", "position_noise"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InputError(f"{name} must be >= 0, got {v!r}")
        object.__setattr__(self, "_rng", [np.random.default_rng(self.seed)])

    @property
    def quantum(self) -> float | None:
        """Position step, m (None without quantisation)."""
        return None if self.position_bits is None else self.stroke / 2 ** self.position_bits

    @property
    def sample_time(self) -> float:
        return float(self.inner.sample_time)

    @property
    def kind(self) -> str:
        return getattr(self.inner, "kind", type(self.inner).__name__)

    def reset(self):
        self._rng[0] = np.random.default_rng(self.seed)
        return self.inner.reset()

    def measure(self, y: dict) -> dict:
        """What the sensors read of the plant's outputs ``y`` (SI): x, p_a, p_b."""
        rng = self._rng[0]
        x = float(y["x"])
        if self.position_noise:
            x += self.position_noise * float(rng.standard_normal())
        if self.quantum is not None:
            x = min(max(round(x / self.quantum), 0), 2 ** self.position_bits - 1) * self.quantum
        out = {"x": x, "p_a": float(y["p_a"]), "p_b": float(y["p_b"])}
        if self.pressure_noise:
            out["p_a"] += self.pressure_noise * float(rng.standard_normal())
            out["p_b"] += self.pressure_noise * float(rng.standard_normal())
        return out

    def update(self, state, r: float, y: dict):
        return self.inner.update(state, r, self.measure(y))
