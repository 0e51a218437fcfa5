"""Velocity and disturbance-force observer from position and chamber pressures.

Most rigs measure the position ``x`` and the chamber pressures ``p_a``, ``p_b``, not
the velocity. :class:`KalmanObserver` estimates (x, v, d) from them: the piston law

    x' = v,   m v' = f - beta v - d,   d' = w (random walk)

with f = p_a A_a - p_b A_b - p_atm (A_a - A_b) - F_ext the pneumatic force known from
the measured pressures, d the force the model lacks (dry friction, a wrong mass, a
load; along -x, as ``load.external_force``). The pressures make the observer a
double integrator with a *known* input, so the velocity does not come from
differentiating a quantised position: it comes from integrating the force, with the
position only correcting the drift.

Discretisation is exact (matrix exponential) for the pneumatic force varying
linearly between two samples (first-order hold: both ends are measured when the
update runs). The gain is the steady-state Kalman gain (discrete algebraic Riccati
equation) for

* position noise: variance q^2 / 12 of a quantiser of step q (plus white noise
  ``position_noise``^2);
* force noise: the pressure noise ``pressure_noise`` (Pa, std) on both chambers,
  sqrt(A_a^2 + A_b^2) times it, held over the sample;
* disturbance: a random walk that can change by its own size ``disturbance`` (N) in
  ``disturbance_time`` (s), i.e. spectral density disturbance^2 / disturbance_time.
  Default: the plant file's static (else Coulomb) friction, else 2 % of the
  pneumatic force range, within 20 ms (a friction force reverses within a few
  samples as the piston passes through zero velocity).

:class:`Observed` wraps any position controller that needs ``v`` (FL, NMPC, PID
with velocity feedback) so that it runs on ``x``, ``p_a``, ``p_b`` only; it passes
the estimates as ``x``, ``v``, ``d`` and ``a`` (and the measured position as ``x_measured``).

Examples
--------
>>> from workbench import Plant
>>> from workbench.controllers.observer import kalman_observer
>>> plant = Plant.from_toml("designs/plants/rig25_mpye.toml")
>>> obs = kalman_observer(plant, sample_time=0.01, quantum=0.5 / 4096)
>>> s = obs.start(0.25, 0.0)
>>> s = obs.step(s, 0.25, 0.0, 0.0)
>>> [round(float(v), 6) for v in s]          # at rest, no force: nothing moves
[0.25, 0.0, 0.0]
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import expm, solve_discrete_are

from ..errors import InputError

__all__ = ["KalmanObserver", "kalman_observer", "Observed", "pneumatic_force",
           "DISTURBANCE_TIME"]

#: s: time in which the unmodelled force may change by its own size (default tuning).
DISTURBANCE_TIME = 0.02


def pneumatic_force(plant, p_a: float, p_b: float) -> float:
    """Net pneumatic force on the piston minus the external load, N (along +x)."""
    prm = plant.params
    p_atm = float(prm["gas.atmospheric_pressure"])
    f_ext = float(prm.get("load.external_force", 0.0) or 0.0)
    return (p_a * plant.area_a - p_b * plant.area_b - p_atm * (plant.area_a - plant.area_b)
            - f_ext)


def _positive(name: str, value, unit: str, zero_ok: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number in {unit}, got {value!r}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not zero_ok):
        raise InputError(f"{name} must be {'>= 0' if zero_ok else '> 0'} {unit}, got {value!r}")
    return v


@dataclass(frozen=True)
class KalmanObserver:
    """Steady-state Kalman filter on (x, v, d) with the pneumatic force as known input.

    Build it with :func:`kalman_observer`. Attributes: ``mass`` kg, ``viscous`` N s/m,
    ``sample_time`` s, ``position_variance`` m^2, ``force_variance`` N^2 (per sample),
    ``disturbance_density`` N^2/s; computed: ``phi`` (3x3), ``g0``, ``g1`` (input
    maps of the force at the previous sample and of its change over the sample),
    ``gain`` (3,) the Kalman gain, ``poles`` of the error dynamics (z-plane).
    """

    mass: float
    viscous: float
    sample_time: float
    position_variance: float
    force_variance: float
    disturbance_density: float
    phi: np.ndarray = field(init=False, repr=False)
    g0: np.ndarray = field(init=False, repr=False)
    g1: np.ndarray = field(init=False, repr=False)
    gain: np.ndarray = field(init=False, repr=False)
    poles: np.ndarray = field(init=False, repr=False)

    needs = ("x", "p_a", "p_b")

    def __post_init__(self) -> None:
        m, b, T = self.mass, self.viscous, self.sample_time
        A = np.array([[0.0, 1.0, 0.0], [0.0, -b / m, -1.0 / m], [0.0, 0.0, 0.0]])
        B = np.array([0.0, 1.0 / m, 0.0])
        # first-order hold: f(t) = f0 + (t / T) df; augmented state (s, f0, df / T)
        M = np.zeros((5, 5))
        M[:3, :3] = A
        M[:3, 3] = B
        M[3, 4] = 1.0
        E = expm(M * T)
        phi, g0, g1 = E[:3, :3], E[:3, 3], E[:3, 4] / T
        # process noise: the disturbance random walk (Van Loan) and the force noise
        Gd = np.array([[0.0], [0.0], [1.0]])
        V = np.zeros((6, 6))
        V[:3, :3] = -A
        V[:3, 3:] = Gd @ Gd.T * self.disturbance_density
        V[3:, 3:] = A.T
        EV = expm(V * T)
        Q = EV[3:, 3:].T @ EV[:3, 3:]
        Q = 0.5 * (Q + Q.T) + np.outer(g0, g0) * self.force_variance
        Q += np.eye(3) * 1e-30                    # numerically positive definite
        H = np.array([[1.0, 0.0, 0.0]])
        R = np.array([[self.position_variance]])
        P = solve_discrete_are(phi.T, H.T, Q, R)
        K = (P @ H.T / (H @ P @ H.T + R)).ravel()
        poles = np.linalg.eigvals((np.eye(3) - np.outer(K, H)) @ phi)
        for name, val in (("phi", phi), ("g0", g0), ("g1", g1), ("gain", K), ("poles", poles)):
            object.__setattr__(self, name, val)

    @property
    def bandwidth(self) -> float:
        """Slowest error pole as a continuous rate, rad/s (-ln|z| / T)."""
        return float(np.min(-np.log(np.abs(self.poles)) / self.sample_time))

    def start(self, x: float, f: float) -> np.ndarray:
        """State at the first sample: at rest at ``x`` (m), the force ``f`` (N)
        balanced by the disturbance (a piston at rest under a force is held by it)."""
        return np.array([float(x), 0.0, float(f)])

    def step(self, state: np.ndarray, x_meas: float, f_prev: float, f: float) -> np.ndarray:
        """Estimate at this sample from the previous one, the force at both samples (N)
        and the measured position (m): prediction (exact, FOH), then correction."""
        pred = self.phi @ state + self.g0 * f_prev + self.g1 * (f - f_prev)
        return pred + self.gain * (float(x_meas) - pred[0])

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "kalman", "mass": self.mass, "viscous": self.viscous,
                "sample_time": self.sample_time, "position_variance": self.position_variance,
                "force_variance": self.force_variance,
                "disturbance_density": self.disturbance_density,
                "gain": [float(k) for k in self.gain], "bandwidth": self.bandwidth}

    def summary(self) -> str:
        return (f"Kalman observer (x, v, d) at {self.sample_time * 1e3:g} ms: position noise "
                f"{math.sqrt(self.position_variance) * 1e6:.1f} um, slowest pole "
                f"{self.bandwidth:.0f} rad/s, gain {', '.join(f'{k:.3g}' for k in self.gain)}")


def kalman_observer(plant, sample_time: float | None = None, quantum: float | None = None,
                    position_noise: float = 0.0, pressure_noise: float = 0.0,
                    disturbance: float | None = None,
                    disturbance_time: float = DISTURBANCE_TIME) -> KalmanObserver:
    """:class:`KalmanObserver` for a plant (module docstring for the noise model).

    Parameters
    ----------
    plant : workbench.Plant
        Mass ``load.mass`` (kg), ``load.viscous_friction`` (N s/m), friction keys.
    sample_time : float, s
        Default the plant file's ``controller.sample_time``.
    quantum : float, m
        Position-sensor step; default ``controller.position_resolution``, else a
        12-bit sensor over the stroke.
    position_noise : float, m
        White position noise (std) on top of the quantisation.
    pressure_noise : float, Pa
        White noise (std) of each pressure sensor.
    disturbance : float, N
        Size of the unmodelled force; default static (else Coulomb) friction from the
        plant file, else 2 % of the pneumatic force range (supply over the bore).
    disturbance_time : float, s
        Time in which it may change by its own size (default 20 ms).
    """
    prm = plant.params
    if sample_time is None:
        sample_time = prm.get("controller.sample_time")
        if sample_time is None:
            raise InputError("give sample_time: the plant file has no [controller] section",
                             source=prm.source)
    T = _positive("sample_time", sample_time, "s")
    if quantum is None:
        quantum = prm.get("controller.position_resolution") or plant.stroke / 4096.0
    q = _positive("quantum", quantum, "m")
    sx = _positive("position_noise", position_noise, "m", zero_ok=True)
    sp = _positive("pressure_noise", pressure_noise, "Pa", zero_ok=True)
    if disturbance is None:
        disturbance = (prm.get("friction.static") or prm.get("friction.coulomb")
                       or 0.02 * float(prm["supply.pressure"]) * plant.area_a)
    fd = _positive("disturbance", disturbance, "N")
    td = _positive("disturbance_time", disturbance_time, "s")
    f_var = sp ** 2 * (plant.area_a ** 2 + plant.area_b ** 2)
    return KalmanObserver(mass=float(prm["load.mass"]), viscous=float(prm["load.viscous_friction"]),
                          sample_time=T, position_variance=q * q / 12.0 + sx * sx,
                          force_variance=f_var, disturbance_density=fd * fd / td)


@dataclass(frozen=True)
class Observed:
    """A position controller run on ``x``, ``p_a``, ``p_b`` only (a DiscreteController).

    Every sample the observer updates (x, v, d) from the measured position and the
    pneumatic force of the measured pressures; the inner controller then gets
    ``x`` = estimated position, ``v`` = estimated velocity, ``d`` = estimated
    unmodelled force (N, along -x), ``a`` = the model's acceleration (f - beta v -
    d) / m (m/s^2), ``x_measured``, ``p_a``, ``p_b``. A ``v`` in the
    measurements is never read.

    Attributes
    ----------
    inner : DiscreteController (its ``sample_time`` must be the observer's).
    observer : KalmanObserver.
    plant : workbench.Plant (areas, atmosphere, external force for the force).
    preview : the reference the inner controller was designed to track, or None
        (for reports; the inner controller holds its own copy).
    """

    inner: Any
    observer: KalmanObserver
    plant: Any
    preview: Any = None

    needs = ("x", "p_a", "p_b")

    def __post_init__(self) -> None:
        if abs(float(self.inner.sample_time) - self.observer.sample_time) > 1e-12:
            raise InputError("the observer must run at the controller's sample time "
                             f"({self.inner.sample_time} s), not {self.observer.sample_time} s")

    @property
    def sample_time(self) -> float:
        return float(self.inner.sample_time)

    @property
    def kind(self) -> str:
        return getattr(self.inner, "kind", type(self.inner).__name__) + " + observer"

    def reset(self):
        return (None, 0.0, self.inner.reset())

    def update(self, state, r: float, y: dict) -> tuple[tuple, float]:
        est, f_prev, inner_state = state
        x_m, p_a, p_b = float(y["x"]), float(y["p_a"]), float(y["p_b"])
        f = pneumatic_force(self.plant, p_a, p_b)
        est = (self.observer.start(x_m, f) if est is None
               else self.observer.step(est, x_m, f_prev, f))
        ob = self.observer
        acc = (f - ob.viscous * float(est[1]) - float(est[2])) / ob.mass
        yi = {"x": float(est[0]), "v": float(est[1]), "d": float(est[2]), "a": acc,
              "x_measured": x_m, "p_a": p_a, "p_b": p_b}
        inner_state, u = self.inner.update(inner_state, r, yi)
        return (est, f, inner_state), u
