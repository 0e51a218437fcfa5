"""P, PD and PID position controllers as in the plant file's ``[controller]``."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import InputError

__all__ = ["PID", "from_plant"]


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
        T = self.sample_time
        u_free = self.u_center + self.kp * e + self.kd * (e - e_prev) / T
        new_integ = integ + e * T
        u = u_free + self.ki * new_integ
        if self.ki and not (self.u_min < u < self.u_max):
            new_integ = integ           # hold the integral while saturated
            u = u_free + self.ki * integ
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
