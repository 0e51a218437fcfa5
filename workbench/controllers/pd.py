"""P, PD and PID position controllers as in the plant file's ``[controller]``."""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..errors import InputError, positive

__all__ = ["PID", "pid_law", "clip_and_quantise", "from_plant", "slow_time_constant",
           "pd_zero_on_slow_pole", "pd_zero_on_slow_pole_at"]


def pid_law(e, e_prev, integral, kp: float, kd: float, ki: float, sample_time: float,
            u_center: float, u_min: float, u_max: float):
    """The discrete PID update, on floats or CasADi SX/MX alike: (u, integral next).

    u = u_center + kp e + kd (e - e_prev) / T + ki I with I = integral + e T, except
    that while the command with the new integral is saturated (u <= u_min or
    u >= u_max) the integral is held (conditional integration). The command is not
    clipped here (see :func:`clip_and_quantise`).

    Parameters
    ----------
    e : position error r - x at this sample, m. e_prev : error at the previous sample,
        m (the first sample takes e_prev = e: no derivative kick).
    integral : sum of e T so far, m s.
    kp : V/m. kd : V s/m. ki : V/(m s). sample_time : T, s.
    u_center : command at zero error, V. u_min, u_max : command range, V.

    Returns
    -------
    (u, integral_next) : command, V, and the integral to carry, m s.
    """
    T = sample_time
    u_free = u_center + kp * e + kd * (e - e_prev) / T
    integ = integral + e * T
    if ki:
        u_try = u_free + ki * integ
        if isinstance(u_try, (int, float, np.floating)):
            if not u_min < u_try < u_max:
                integ = integral            # hold the integral while saturated
        else:
            integ = ca.if_else(ca.logic_or(u_try <= u_min, u_try >= u_max), integral, integ)
    return u_free + ki * integ, integ


def clip_and_quantise(u, lo: float, hi: float, resolution: float | None = None):
    """Command clipped to [lo, hi] V, then rounded to the DAC step ``resolution`` (V)
    and clipped again; floats or CasADi expressions."""
    u = ca.fmin(ca.fmax(u, lo), hi)
    if resolution:
        u = ca.fmin(ca.fmax(ca.floor(u / resolution + 0.5) * resolution, lo), hi)
    return u


@dataclass(frozen=True)
class PID:
    """Discrete PID on the position error e = r - x (formats.md section 1).

    u_k = u_center + kp e_k + kd (e_k - e_{k-1}) / T + ki T sum_{j<=k} e_j.

    The first sample takes e_{-1} = e_0 (no derivative kick). The integral is
    frozen while the command is saturated (conditional integration).

    Parameters
    ----------
    kp : V/m. kd : V s/m. ki : V/(m s). sample_time : T, s.
    u_center : command at zero error, V (the valve's command_center).
    u_min, u_max : command range, V (for the anti-windup).
    """

    kp: float
    sample_time: float
    kd: float = 0.0
    ki: float = 0.0
    u_center: float = 0.0
    u_min: float = float("-inf")
    u_max: float = float("inf")

    def __post_init__(self) -> None:
        if not self.sample_time > 0:
            raise InputError(f"sample_time must be > 0 s, got {self.sample_time!r}")
        if self.u_min >= self.u_max:
            raise InputError("u_min must be below u_max")

    #: Measurements read: the position only.
    needs = ("x",)

    @property
    def kind(self) -> str:
        return "pid" if self.ki else ("pd" if self.kd else "p")

    def reset(self):
        return (None, 0.0)

    def update(self, state, r: float, y: dict) -> tuple[tuple, float]:
        e_prev, integ = state
        e = r - y["x"]
        if e_prev is None:
            e_prev = e
        u, new_integ = pid_law(e, e_prev, integ, self.kp, self.kd, self.ki, self.sample_time,
                               self.u_center, self.u_min, self.u_max)
        return (e, new_integ), u

    def to_control(self):
        """Discrete-time python-control transfer function e -> (u - u_center)."""
        import control
        T = self.sample_time
        # kp + kd (1 - z^-1)/T + ki T / (1 - z^-1)
        num_pd = [self.kp + self.kd / T, -self.kd / T]
        if not self.ki:
            return control.tf(num_pd, [1.0, 0.0], T)
        # (kp + kd/T - kd/T z^-1)(1 - z^-1) + ki T  over (1 - z^-1)
        a = self.kp + self.kd / T
        b = -self.kd / T
        num = [a + self.ki * T, b - a, -b]
        return control.tf(num, [1.0, -1.0, 0.0], T)


def from_plant(plant) -> PID:
    """The controller described by the plant file's ``[controller]`` section."""
    prm = plant.params
    if not prm.has_controller:
        raise InputError("the plant file has no [controller] section", source=prm.source)
    kind = prm["controller.kind"]
    return PID(kp=prm["controller.kp"], sample_time=prm["controller.sample_time"],
               kd=prm["controller.kd"] if kind in ("pd", "pid") else 0.0,
               ki=prm["controller.ki"] if kind == "pid" else 0.0,
               u_center=prm["valve.command_center"], u_min=prm["valve.command_min"],
               u_max=prm["valve.command_max"])


# ---------------------------------------------------------------------- PD placement (paper 000)


def slow_time_constant(w0: float, zeta: float) -> float:
    """Slower time constant of s^2/w0^2 + 2 zeta s/w0 + 1 for zeta > 1, s.

    For zeta > 1 the factor has two real poles, time constants
    T0 / (zeta -+ sqrt(zeta^2 - 1)) with T0 = 1/w0 (paper 000); this is the larger one,
    T0 / (zeta - sqrt(zeta^2 - 1)) = T0 (zeta + sqrt(zeta^2 - 1)).

    Parameters
    ----------
    w0 : float
        Natural frequency, rad/s.
    zeta : float
        Damping ratio, - (must be > 1).

    Raises
    ------
    InputError
        zeta <= 1 (complex or double poles: no single slow real pole to cancel), or a
        non-positive / non-finite w0.
    """
    w0 = positive("w0", w0, "rad/s")
    try:
        z = float(zeta)
    except (TypeError, ValueError):
        raise InputError(f"zeta must be a number, got {zeta!r}") from None
    if not math.isfinite(z) or z <= 1.0:
        raise InputError(
            f"zeta = {zeta!r}: the process s^2/w0^2 + 2 zeta s/w0 + 1 has real poles only "
            "for zeta > 1, so there is no slower real pole for the PD zero to cancel "
            "(for zeta <= 1 use a P controller, or place the zero by another rule)")
    # T0 (zeta + sqrt(zeta^2 - 1)) equals T0 / (zeta - sqrt(zeta^2 - 1)) without the
    # cancellation in the denominator when zeta is large
    return (z + math.sqrt(z * z - 1.0)) / w0


def pd_zero_on_slow_pole(w0: float, zeta: float, kp: float, sample_time: float,
                         u_center: float = 0.0, u_min: float = float("-inf"),
                         u_max: float = float("inf")) -> PID:
    """PD controller whose zero cancels the slower real process pole (paper 000).

    The process Kv / (s (s^2/w0^2 + 2 zeta s/w0 + 1)) with zeta > 1 has the real
    poles -1/tau_slow, -1/tau_fast. The PD kp + kd s = kp (1 + (kd/kp) s) with
    kd/kp = tau_slow puts its zero on -1/tau_slow, leaving the loop
    kp Kv / (s (1 + tau_fast s)).

    Parameters
    ----------
    w0 : float
        Natural frequency of the process, rad/s.
    zeta : float
        Damping ratio, - (> 1).
    kp : float
        Proportional gain, V/m (> 0).
    sample_time : float
        T, s.
    u_center : float
        Command at zero error, V.
    u_min, u_max : float
        Command range, V.

    Returns
    -------
    PID
        With kd = kp tau_slow, V s/m, and ki = 0.

    Raises
    ------
    InputError
        zeta <= 1 (no real poles to cancel), non-positive w0, kp or sample_time.

    Examples
    --------
    >>> pd = pd_zero_on_slow_pole(w0=32.97, zeta=1.1, kp=10.0, sample_time=0.01)
    >>> round(pd.kd / pd.kp, 4)      # tau_slow = (1.1 + sqrt(0.21)) / 32.97 s
    0.0473
    """
    tau = slow_time_constant(w0, zeta)
    kp = positive("kp", kp, "V/m")
    return PID(kp=kp, sample_time=positive("sample_time", sample_time, "s"),
               kd=kp * tau, u_center=u_center, u_min=u_min, u_max=u_max)


def pd_zero_on_slow_pole_at(plant, x: float, kp: float | None = None,
                            k0: float | None = None,
                            sample_time: float | None = None) -> PID:
    """:func:`pd_zero_on_slow_pole` for a plant, from its reduced model at position ``x``.

    Linearises the plant exactly at the equilibrium at ``x`` (m) and fits Kv, w0, zeta
    (:func:`workbench.linearize.reduced_position_model`). The command centre and range
    are the valve's.

    Parameters
    ----------
    plant : workbench.Plant
    x : float
        Piston position, m.
    kp : float, optional
        Proportional gain, V/m; default the plant file's ``controller.kp``.
    k0 : float, optional
        Loop gain kp Kv, 1/s, instead of kp (kp = k0 / Kv).
    sample_time : float, optional
        T, s; default the plant file's ``controller.sample_time``.

    Raises
    ------
    InputError
        Both or neither of kp / k0 with no [controller] to fall back on, no sample
        time, or zeta <= 1 at ``x``.
    """
    from .. import linearize
    prm = plant.params
    if kp is not None and k0 is not None:
        raise InputError("give the controller gain kp (V/m) or the loop gain k0 (1/s), "
                         "not both")
    if sample_time is None:
        if not prm.has_controller:
            raise InputError("the plant file has no [controller] section, so the sample "
                             "time must be given", source=prm.source)
        sample_time = prm["controller.sample_time"]
    red = linearize.reduced_position_model(linearize.tangent(plant, x=x))
    if k0 is not None:
        kp = positive("k0", k0, "1/s") / red.kv
    elif kp is None:
        if not prm.has_controller:
            raise InputError("give kp (V/m) or k0 (1/s): the plant file has no "
                             "[controller] section", source=prm.source)
        kp = prm["controller.kp"]
    return pd_zero_on_slow_pole(red.w0, red.zeta, kp, sample_time,
                                u_center=prm["valve.command_center"],
                                u_min=prm["valve.command_min"], u_max=prm["valve.command_max"])
