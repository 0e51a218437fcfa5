"""Witnesses of a mismatch: the model's equations evaluated along the measurement.

With the chamber pressures recorded, the mass flow each chamber really received
follows from the chamber equation,

    q_i = (V_i dp_i/dt / k + p_i dV_i/dt) / (r T),

with V_i and dV_i/dt from the measured position and velocity; the valve law at the
recorded command and pressures says what it should have received. Their difference
(the *flow witness*, kg/s) is the pressure-rate equation error
``dp_i/dt - f_p(z, u)`` scaled by V_i / (k r T). Likewise the *force witness*
m (a - f_v(z, u)) (N) is what the piston's equation of motion leaves unexplained.

Each is formed here as the Savitzky-Golay derivative of the measurement minus the
same smoothing applied to the model's rates along the measurement, so the filter
delay and attenuation cancel. The model's rates come from :class:`.engine.Engine`
re-anchored on the measurement at every sample (an observer pass), so candidate
effects with states that are not measured (spool, lines, temperatures, supply
reservoir) are driven by the measured ones. Dry friction is evaluated separately:
a piston at rest only needs the driving force to stay within the static level.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.signal import savgol_coeffs

from ..physics import chamber
from ..physics.friction import stribeck_level
from ..physics.gas import R_AIR
from .data import Prepared
from .engine import INPUT_ROWS, EngineInputs

__all__ = ["Witness", "observer_inputs", "CHANNELS"]

#: Equation-error channels: acceleration (m/s^2), pressure rates (Pa/s), and the
#: pressure rates over a long window (slow effects: leaks, heat exchange, droop).
CHANNELS = ("v", "p_a", "p_b", "p_a_slow", "p_b_slow")


def observer_inputs(prep: Prepared) -> EngineInputs:
    """Engine inputs for an observer pass: re-anchored on the measurement at every sample."""
    n = prep.n
    d = np.zeros((len(INPUT_ROWS), n))
    row = {k: i for i, k in enumerate(INPUT_ROWS)}
    d[row["u_rec"]] = prep.rec["u"]
    d[row["x_m"]] = prep.xs
    d[row["v_m"]] = prep.v
    if prep.pressures:        # one recorded: the other is its force-balance estimate
        d[row["p_a_m"]] = prep.pas
        d[row["p_b_m"]] = prep.pbs
        d[row["anchor_p"]] = 1.0
    if prep.supply is not None:          # the recorded supply pressure, sample by sample
        d[row["use_p_s"]], d[row["p_s_m"]] = 1.0, prep.supply
    d[row["anchor"]] = 1.0
    d[row["anchor_hidden"], 0] = 1.0
    return EngineInputs(d)


@dataclass
class Witness:
    """Equation errors along one recording (see the module docstring).

    Attributes
    ----------
    mask : samples used (away from the recording's ends and the end stops).
    rest : samples where the piston is at rest (|v| below 3 velocity-noise levels).
    scale : noise level of each channel (same unit), the weights of :meth:`cost`.
    """

    prep: Prepared
    mask: np.ndarray
    rest: np.ndarray
    scale: dict[str, float]
    v_rest: float
    quiet: np.ndarray

    @classmethod
    def build(cls, prep: Prepared) -> "Witness":
        n = prep.n
        L = prep.plant.stroke
        edge = max(prep.win_x, prep.win_p, prep.win_slow)
        mask = np.ones(n, dtype=bool)
        mask[:edge] = False
        mask[-edge:] = False
        mask &= (prep.xs > 0.01 * L) & (prep.xs < 0.99 * L)
        dt = prep.dt
        cv = savgol_coeffs(prep.win_x, 3, deriv=1, delta=dt)
        ca_ = savgol_coeffs(prep.win_x, 3, deriv=2, delta=dt)
        cp = savgol_coeffs(prep.win_p, 2, deriv=1, delta=dt)
        sig_v = prep.noise["x"] * float(np.linalg.norm(cv))
        sig_a = prep.noise["x"] * float(np.linalg.norm(ca_))
        scale = {"v": max(sig_a, 1e-3)}
        cs = savgol_coeffs(prep.win_slow, 2, deriv=1, delta=dt)
        for side in prep.pressures:     # the recorded sides only
            scale[side] = max(prep.noise[side] * float(np.linalg.norm(cp)), 1.0)
            scale[f"{side}_slow"] = max(prep.noise[side] * float(np.linalg.norm(cs)), 1.0)
        v_rest = max(3.0 * sig_v, 1e-3)
        rest = np.abs(prep.v) < v_rest
        quiet = np.zeros(n, dtype=bool)
        if prep.pressures:
            # Slow channels only where the pressures change slowly: the long window
            # cannot follow a transient, so there it would compare smoothing errors.
            # (NaN where a side was not recorded: several recordings, never calm there.)
            rate = np.fmax.reduce([np.where(prep.mask(s), np.abs(
                prep.smooth_slow(prep.filled(s), 1)), np.nan) for s in prep.pressures])
            level = np.median(rate[np.isfinite(rate)]) if np.isfinite(rate).any() else 0.0
            calm = rate < 3.0 * level + 3.0 * scale[f"{prep.pressures[0]}_slow"]
            calm &= np.abs(prep.smooth_slow(prep.v)) < 10.0 * v_rest
            # dilate the transients by one long window
            k = prep.win_slow
            busy = np.convolve((~calm).astype(float), np.ones(k), mode="same") > 0
            quiet = mask & ~busy
        return cls(prep=prep, mask=mask, rest=rest, scale=scale, v_rest=v_rest, quiet=quiet)

    def _mask(self, ch: str) -> np.ndarray:
        """Samples of channel ``ch``: where its pressure was recorded (the force
        channel: where any was; several recordings), and quiet for the slow ones."""
        m = self.quiet if ch.endswith("_slow") else self.mask
        if not self.prep.recorded:
            return m
        side = ch[:3] if ch.startswith("p_") else None
        return m & (self.prep.mask(side) if side else self.prep.pressure_anchor())

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.scale)

    def residuals(self, rates: np.ndarray, friction: Mapping[str, float] | None = None
                  ) -> dict[str, np.ndarray]:
        """Equation errors per channel from an observer pass's rates (rows dv, dp_a, dp_b).

        ``friction`` (coulomb, static, stribeck_velocity, N and m/s) adds dry friction to
        rates computed without it: a moving piston feels the Stribeck level against its
        motion, a piston at rest is explained if the driving force is within the
        static level.
        """
        prep = self.prep
        dv = np.asarray(rates[0], dtype=float)
        res: dict[str, np.ndarray] = {}
        if friction:
            m = prep.plant.params["load.mass"]
            fc, fs, vs = friction["coulomb"], friction["static"], friction["stribeck_velocity"]
            v = prep.v
            level = stribeck_level(v, fc, fs, vs)
            moving = ~self.rest
            a_model = dv - np.where(moving, np.sign(v) * level / m, 0.0)
            r = prep.a - prep.smooth_x(a_model)
            need = r[self.rest]          # acceleration friction would have to supply
            r[self.rest] = np.sign(need) * np.maximum(np.abs(need) - fs / m, 0.0)
            res["v"] = r
        else:
            res["v"] = prep.a - prep.smooth_x(dv)
        for side in prep.pressures:     # the recorded sides only
            i = ("p_a", "p_b").index(side) + 1
            rate = np.asarray(rates[i], dtype=float)
            res[side] = (prep.dpa if side == "p_a" else prep.dpb) - prep.smooth_p(rate)
            res[f"{side}_slow"] = (prep.smooth_slow(prep.filled(side), 1)
                                   - prep.smooth_slow(rate))
        return res

    def cost(self, res: Mapping[str, np.ndarray]) -> float:
        """Sum over channels of the mean squared equation error in noise units."""
        total = 0.0
        for ch, s in self.scale.items():
            r = res[ch][self._mask(ch)] / s
            r = r[np.isfinite(r)]
            total += float(np.mean(r * r)) if len(r) else 0.0
        return total

    def channel_costs(self, res: Mapping[str, np.ndarray]) -> dict[str, float]:
        out = {}
        for ch, s in self.scale.items():
            r = res[ch][self._mask(ch)] / s
            r = r[np.isfinite(r)]
            out[ch] = float(np.mean(r * r)) if len(r) else 0.0
        return out

    def in_units(self, res: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Force witness (N) and flow witnesses (kg/s) from the equation errors."""
        prep = self.prep
        prm = prep.plant.params
        out = {"force": prm["load.mass"] * res["v"]}
        if prep.recorded:      # several recordings: no force witness without a pressure
            out["force"] = np.where(prep.pressure_anchor(), out["force"], np.nan)
        if prep.pressures:
            k, T = prm["gas.polytropic_index"], prm["gas.temperature"]
            plant = prep.plant
            vol = dict(zip(("p_a", "p_b"), chamber.volumes(
                prep.xs, 0.0, plant.area_a, plant.area_b, plant.stroke,
                prm["cylinder.dead_volume_a"], prm["cylinder.dead_volume_b"])[:2]))
            for side in prep.pressures:
                out[f"q_{side[-1]}"] = vol[side] / (k * R_AIR * T) * res[side]
        return out
