"""The smallest leak a recording can show: a physical size test for ``leakage``.

A leak's fit can remove a real share of a mismatch another model form leaves (a
friction law that is not the rig's, a lumped line) without any leak on the rig: the
share is then absorbed residue, not a leak. What a leak does on the rig is bounded by
its size: at the recording's largest chamber pressure (to atmosphere) and largest
pressure difference across the piston (cross leak) its mass flow ``q`` changes a
chamber's pressure at the rate ``dp/dt = k R T q / V``; over one prediction horizon
(the short-horizon predictor re-anchors on the measured pressures every horizon) the
pressure it moves is at most::

    drift = k R T / V (q_atm(C_atm, p_hi) + c_cross dp_cross) horizon

A leak whose ``drift`` stays below the pressure noise ``sigma_p`` cannot be told from
the noise in any prediction window, so it is *negligible* (never named, whatever cost
it removes). The concealed leaks of ``designs/diagnose_concealed.py`` (1e-10 m^3/(s Pa)
and up) move 12 kPa and more in a horizon on its 25 mm rig (500 Pa pressure noise).
Measured on h12f's open-loop recording of a foreign rig with LuGre friction and no
leak, where a leak of 4.4e-12 m^3/(s Pa) to atmosphere and 2.6e-11 kg/(s Pa) across
the piston was named: it moves 1.0 kPa in a horizon, twice the 507 Pa noise -- not
negligible by its size (that leak was named because the friction's own fit was stuck,
:func:`.sets._project_pairs`).

All quantities come from the recording and the plant file (no threshold tuned to a
case): pressures by their 99th percentile (one spike does not set the size), the
chamber volume at the recording's mean position (the smaller chamber), the noise of
the short-horizon predictor (:func:`.predict._sigma`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..physics.gas import NOZZLE_CRITICAL_RATIO, R_AIR
from ..physics.supply import leak_to_atmosphere
from .data import Prepared
from .predict import Predictor

__all__ = ["LeakFloor"]

#: Quantile of the recorded pressures (and pressure differences) taken as their largest
#: value: one spike does not set the size a leak must have.
P_QUANTILE = 0.99


@dataclass(frozen=True)
class LeakFloor:
    """What a leak must move to be seen (SI units).

    Attributes
    ----------
    sigma_p : pressure noise of the recorded chamber pressures (the smaller), Pa.
    horizon : one prediction window, s.
    volume : chamber volume at the recording's mean position (the smaller chamber), m^3.
    p_high : largest recorded chamber pressure (99th percentile), Pa.
    dp_cross : largest pressure difference across the piston (99th percentile), Pa.
    p_atm : atmospheric pressure, Pa. temperature : gas temperature, K.
    b : critical pressure ratio of the leak gap, -. k : polytropic index, -.
    """

    sigma_p: float
    horizon: float
    volume: float
    p_high: float
    dp_cross: float
    p_atm: float
    temperature: float
    k: float
    b: float

    @classmethod
    def of(cls, prep: Prepared, shpe: Predictor) -> "LeakFloor | None":
        """The floor of a prepared recording and its short-horizon predictor; None
        without a recorded chamber pressure (no leak is a candidate then)."""
        sides = [s for s in prep.pressures if s in shpe.sigma]
        if not sides or shpe.windows < 1:
            return None
        prm = prep.plant.params
        bore, rod = prm["cylinder.bore"], prm.get("cylinder.rod_diameter", 0.0)
        a_a = np.pi / 4 * bore ** 2
        a_b = np.pi / 4 * (bore ** 2 - rod ** 2)
        stroke = prm["cylinder.stroke"]
        x = float(np.clip(np.nanmean(prep.x), 0.0, stroke))
        volume = min(a_a * x + prm["cylinder.dead_volume_a"],
                     a_b * (stroke - x) + prm["cylinder.dead_volume_b"])
        p = np.concatenate([np.asarray(prep.measured(s), dtype=float) for s in sides])
        pa, pb = prep.smoothed("p_a"), prep.smoothed("p_b")
        dp = np.abs(np.asarray(pa, dtype=float) - np.asarray(pb, dtype=float))
        dp = dp[prep.pressure_anchor()]     # where a pressure was recorded
        horizon = len(shpe.index) / shpe.windows * shpe.step * prep.dt
        return cls(sigma_p=min(float(shpe.sigma[s]) for s in sides), horizon=float(horizon),
                   volume=float(volume),
                   p_high=float(np.nanquantile(p[np.isfinite(p)], P_QUANTILE)),
                   dp_cross=float(np.nanquantile(dp[np.isfinite(dp)], P_QUANTILE)),
                   p_atm=float(prm["gas.atmospheric_pressure"]),
                   temperature=float(prm["gas.temperature"]),
                   k=float(prm.get("gas.polytropic_index", 1.0)), b=float(NOZZLE_CRITICAL_RATIO))

    def drift(self, values: Mapping[str, float]) -> float:
        """Pressure (Pa) a leak of ``values`` (candidate keys
        ``leakage.conductance_to_atmosphere``, m^3/(s Pa), ``leakage.cross_piston``,
        kg/(s Pa)) moves in one horizon at the recording's largest pressures."""
        c_atm = max(float(values.get("leakage.conductance_to_atmosphere", 0.0)), 0.0)
        c_x = max(float(values.get("leakage.cross_piston", 0.0)), 0.0)
        q = float(leak_to_atmosphere(max(self.p_high, self.p_atm), self.p_atm, c_atm,
                                     self.temperature, self.b)) + c_x * self.dp_cross
        return self.k * R_AIR * self.temperature / self.volume * q * self.horizon

    def invisible(self, values: Mapping[str, float]) -> bool:
        """Whether the leak moves less than the pressure noise in a horizon."""
        return self.drift(values) < self.sigma_p

    def to_dict(self) -> dict[str, Any]:
        """The floor's quantities (for ``details.json``)."""
        return {"sigma_p_Pa": self.sigma_p, "horizon_s": self.horizon,
                "chamber_volume_m3": self.volume, "p_high_Pa": self.p_high,
                "dp_cross_Pa": self.dp_cross}
