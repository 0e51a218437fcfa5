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

**A leak must show in the chamber equations** (:func:`chamber_evidence`). A leak acts
on the chambers' mass balance only. Driven by the *measured* motion and command, with
the other chamber's recorded pressure imposed (:func:`.recorded.chamber_estimate`), a
chamber's equation involves no force: a friction law that is not the rig's, a wrong
mass or load cannot bias it. So a leak that is on the rig makes these force-free
estimates of the recorded pressures better, and a leak that only absorbs a force-side
misfit of the prediction makes them worse. Measured on test_diagnose.py's foreign
dry-friction recording (smooth Stribeck law 16.3/22.3 N, no leak) with the engine's
friction events refined (``predict.REFINE_STEPS``): the leak named beside the friction,
4.9e-12 m^3/(s Pa) to atmosphere and 8.4e-11 kg/(s Pa) across the piston (above the
floor), moved the force-free estimates from 0.63 kPa rms (the noise level) to 6.2 kPa;
a real leak of 2.5e-10 m^3/(s Pa) moves them from 171/203 kPa (p_a/p_b) to 0.69 kPa.
A leak is named only if the
set's plant (its other members applied) fits the recorded pressures this way better
with the leak than without it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..physics.gas import NOZZLE_CRITICAL_RATIO, R_AIR
from ..physics.supply import leak_to_atmosphere
from .data import Prepared
from .predict import Predictor

__all__ = ["LeakFloor", "chamber_misfit", "chamber_evidence"]

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


def chamber_misfit(prep: Prepared, plant: Any) -> float | None:
    """Rms error (Pa) of the force-free chamber estimates of the recorded pressures:
    each recorded chamber integrated by ``plant``'s own equations with the measured
    position, velocity and command and the other chamber's smoothed pressure imposed
    (:func:`.recorded.chamber_estimate`), from its recorded start, each joined
    recording from its own start; over the samples where the chamber was recorded.
    None without a recorded pressure or when the integration is not finite."""
    from .recorded import chamber_estimate
    sides = prep.pressures
    if not sides:
        return None
    u = np.asarray(prep.rec["u"], dtype=float)
    cuts = list(prep.starts or [0]) + [prep.n]
    sq, count = 0.0, 0
    for side in sides:
        other = "p_b" if side == "p_a" else "p_a"
        meas, p_o = np.asarray(prep.measured(side), float), prep.smoothed(other)
        p_s, mask = prep.smoothed(side), prep.mask(side)
        for a, b in zip(cuts[:-1], cuts[1:]):
            m = mask[a:b] & np.isfinite(meas[a:b])
            if b - a < 2 or not m.any() or not np.isfinite(p_s[a]):
                continue
            est = chamber_estimate(plant, side, float(p_s[a]), prep.xs[a:b], prep.v[a:b],
                                   p_o[a:b], u[a:b], prep.dt)
            err = (est - meas[a:b])[m]
            if not np.all(np.isfinite(err)):
                return None
            sq += float(np.sum(err ** 2))
            count += int(err.size)
    return float(np.sqrt(sq / count)) if count else None


def chamber_evidence(prep: Prepared, without: Mapping[str, Any],
                     leak: Mapping[str, Any]) -> dict[str, Any]:
    """Whether a leak shows in the force-free chamber estimates (module docstring).

    Parameters
    ----------
    prep : the prepared recording. without : plant keys (dotted) of the other members
        of the set, applied to the nominal plant. leak : the leak's plant keys.

    Returns
    -------
    ``{"without_Pa": .., "with_Pa": .., "shows": bool}``: the rms errors (Pa) of
    :func:`chamber_misfit` without and with the leak; ``shows`` is True when the leak
    makes them smaller, or when they cannot be computed (no judgement: the leak is
    then judged by the prediction cost alone).
    """
    base = prep.plant.with_params(**dict(without)) if without else prep.plant
    e0 = chamber_misfit(prep, base)
    e1 = chamber_misfit(prep, base.with_params(**dict(leak))) if e0 is not None else None
    shows = e0 is None or e1 is None or e1 < e0
    return {"without_Pa": e0, "with_Pa": e1, "shows": bool(shows)}
