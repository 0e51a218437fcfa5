"""What the sampled-data simulator expects of a controller."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

__all__ = ["DiscreteController"]


@runtime_checkable
class DiscreteController(Protocol):
    """A sampled-data position controller.

    The simulator calls :meth:`reset` once, then :meth:`update` every
    ``sample_time`` seconds with the reference and the measured outputs; the
    command it returns is clipped to the valve's range, quantised by the DAC and
    held until the next sample (ZOH).

    A controller may declare ``needs``, the names of the measurements it reads
    (e.g. ``("x",)`` for :class:`~workbench.controllers.PID`, ``("x", "v", "p_a",
    "p_b")`` for FL and NMPC); :func:`workbench.controllers.design` returns
    controllers that need ``("x", "p_a", "p_b")`` only (an observer supplies v).
    """

    sample_time: float

    def reset(self) -> Any:
        """Initial controller state."""

    def update(self, state: Any, r: float, y: dict[str, float]) -> tuple[Any, float]:
        """(new state, command in V) from the reference (m) and measurements (SI).

        ``y`` holds the sampled position ``x`` (m, after the ADC's resolution),
        velocity ``v`` (m/s) and chamber pressures ``p_a``, ``p_b`` (Pa abs).
        """
