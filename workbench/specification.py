"""What a position loop must achieve: :class:`Specification` (SI units).

Split from :mod:`workbench.validate` (which re-exports it): the limits a validation
judges against, with the defaults of paper 000's P loop and the precision
specification of issue 14 (:meth:`Specification.precision`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from .errors import InputError

__all__ = ["Specification"]

def _meta(unit: str, doc: str) -> dict:
    return {"unit": unit, "doc": doc}


@dataclass(frozen=True)
class Specification:
    """What a position loop must achieve on the validation profile (SI units).

    The defaults are those of a pneumatic positioning axis without integral action
    (a P or PD loop on a proportional valve, 10 ms sampling) as in paper 000: a few
    tenths of a second of time constant, millimetre accuracy. Any ``max_*`` limit may
    be ``inf`` to report a quantity without judging it.

    Parameters
    ----------
    max_overshoot : float, %
        Largest overshoot of a step, in percent of the step size. Default 10 %: a
        positioning axis may pass its target a little, but not by a tenth of the way.
        An overshoot not larger than ``band_floor`` is always accepted, so a 5 mm step
        is not failed for a 0.6 mm excursion.
    max_settling_time : float, s
        Time after a step at which the position has entered the settling band for
        good. Default 1.5 s: about ten closed-loop time constants of the paper-000 P
        loop (K0 = 7 1/s, 1/K0 = 0.14 s), long enough for the slower nonlinear
        response of large steps, short enough to catch a creeping or ringing loop.
    settling_band : float, -
        Half-width of the settling band as a fraction of the step size. Default 0.02
        (the usual 2 % band).
    band_floor : float, m
        Smallest half-width of the settling band (and the overshoot that is always
        accepted). Default 1 mm: the resolution a rig engineer measures a pneumatic
        axis to; without it a 10 mm step would need to settle within 0.2 mm.
    max_steady_state_error : float, m
        Mean |r - x| over the last ``steady_state_window`` of each hold. Default
        1 mm, equal to the band floor: a step that settled into its band passes.
    steady_state_window : float, s
        Length of the end of each hold over which the steady-state error is averaged
        (at most half the hold). Default 0.5 s.
    max_saturation : float, -
        Largest fraction of the run time during which the command sits at the valve's
        ``command_min`` or ``command_max``. Default 0.10: brief saturation on large
        steps is normal; a loop that spends more than a tenth of the time at a limit
        is limit-cycling or badly tuned.
    max_ramp_error : float, m
        Largest |r - x| during a ramp. Default 20 mm: at the profile's default ramp
        speed (0.2 stroke/s, 0.1 m/s on a 0.5 m stroke) this asks for a velocity-error
        constant of at least 5 1/s, which the paper-000 P loop (K0 = 7 1/s, following
        error v/K0 = 14 mm) meets and a sluggish loop does not.
    pressure_tolerance : float, Pa
        Chamber pressures must stay within [atmosphere - tolerance, supply +
        tolerance]. Default 0.2 bar (2e4 Pa): a chamber compressed by a braking piston
        may exceed the supply a little, and one expanding may dip below atmosphere a
        little; more means violent motion or a solver out of its depth.
    max_sine_error : float, m
        Largest |r - x| over a sine section of the reference (its ``sections``, e.g.
        :func:`validation_profile` with ``sine=True``). Default inf: reported, not
        judged. :meth:`precision` sets it.
    name : str
        What the specification is called in reports ("" for a custom one).

    See :meth:`precision` for the named precision-positioning specification.
    """

    max_overshoot: float = field(default=10.0, metadata=_meta("%", "largest step overshoot"))
    max_settling_time: float = field(default=1.5, metadata=_meta("s", "largest settling time"))
    settling_band: float = field(default=0.02, metadata=_meta("-", "band, fraction of step"))
    band_floor: float = field(default=1e-3, metadata=_meta("m", "smallest band half-width"))
    max_steady_state_error: float = field(default=1e-3, metadata=_meta("m", "mean |r - x| at hold end"))
    steady_state_window: float = field(default=0.5, metadata=_meta("s", "end of hold averaged"))
    max_saturation: float = field(default=0.10, metadata=_meta("-", "fraction of time saturated"))
    max_ramp_error: float = field(default=0.02, metadata=_meta("m", "largest |r - x| on ramps"))
    pressure_tolerance: float = field(default=2e4, metadata=_meta("Pa", "pressure bound margin"))
    max_sine_error: float = field(default=math.inf, metadata=_meta("m", "largest |r - x| on a sine"))
    name: str = field(default="", metadata={"unit": "", "doc": "name in reports",
                                           "text": True})

    @classmethod
    def precision(cls, plant=None, quantum: float | None = None,
                  stroke: float | None = None) -> "Specification":
        """The named precision-positioning specification (issue 14).

        * steady-state error within one position-sensor quantum (mean |r - x| over
          the last 0.5 s of every hold), and the settling band's floor one quantum;
        * overshoot <= 2 % of the step (a quantum is always accepted);
        * on the sine section (60 mm, 0.5 Hz on a 0.5 m stroke; :func:`validation_profile`
          with ``sine=True``) a worst error <= 1 mm x stroke / 0.5 m: the published rig
          result is 0.7 mm (model-reference adaptive friction compensation with a
          sliding-mode force loop), and a workbench loop on an exactly known model
          should do at least as well;
        * ramps tracked within 5 mm x stroke / 0.5 m (a precision axis follows a
          0.1 m/s ramp with a velocity-error constant of 20 1/s or better);
        * the rest as :class:`Specification`'s defaults.

        Parameters
        ----------
        plant : Plant, optional
            Gives the stroke and, from ``controller.position_resolution``, the quantum.
        quantum : float, m, optional
            Position-sensor quantum; default the plant file's
            ``controller.position_resolution``, else a 12-bit sensor over the stroke
            (stroke / 4096).
        stroke : float, m, optional
            Default the plant's stroke, else 0.5 m.

        Examples
        --------
        >>> spec = Specification.precision(quantum=0.5 / 4096, stroke=0.5)
        >>> round(spec.max_steady_state_error * 1e3, 4), spec.max_overshoot, spec.name
        (0.1221, 2.0, 'precision')
        """
        if stroke is None:
            stroke = float(plant.stroke) if plant is not None else 0.5
        if not (isinstance(stroke, (int, float)) and math.isfinite(stroke) and stroke > 0):
            raise InputError(f"stroke must be a positive length in m, got {stroke!r}")
        if quantum is None and plant is not None:
            quantum = plant.params.get("controller.position_resolution")
        if quantum is None:
            quantum = stroke / 4096.0
        if not (isinstance(quantum, (int, float)) and math.isfinite(quantum) and quantum > 0):
            raise InputError(f"the position quantum must be a positive length in m, got {quantum!r}")
        scale = stroke / 0.5
        return cls(max_overshoot=2.0, band_floor=float(quantum),
                   max_steady_state_error=float(quantum), max_sine_error=1e-3 * scale,
                   max_ramp_error=5e-3 * scale, name="precision")

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise InputError(f"specification name must be text, got {self.name!r}")
        for f in fields(self):
            if f.metadata.get("text"):
                continue
            val = getattr(self, f.name)
            unit = f.metadata.get("unit", "")
            if isinstance(val, bool) or not isinstance(val, (int, float, np.integer, np.floating)):
                raise InputError(f"specification {f.name} must be a number ({unit}), got {val!r}")
            val = float(val)
            object.__setattr__(self, f.name, val)
            if math.isnan(val):
                raise InputError(f"specification {f.name} is NaN; give a number in {unit}")
            can_be_inf = f.name.startswith("max_")
            if math.isinf(val) and not (can_be_inf and val > 0):
                raise InputError(f"specification {f.name} must be finite ({unit}), got {val!r}"
                                 + (" (only max_* limits may be +inf)" if not can_be_inf else ""))
            if val < 0:
                raise InputError(f"specification {f.name} must not be negative, got {val:g} {unit}")
        if not 0.0 < self.settling_band < 1.0:
            raise InputError("specification settling_band is a fraction of the step size and "
                             f"must lie in (0, 1), got {self.settling_band:g} (2 % is 0.02)")
        if self.max_settling_time <= 0:
            raise InputError("specification max_settling_time must be > 0 s")
        if self.steady_state_window <= 0:
            raise InputError("specification steady_state_window must be > 0 s")
        if self.max_saturation > 1.0:
            raise InputError("specification max_saturation is a fraction of the run time in "
                             f"[0, 1], got {self.max_saturation:g} (10 % is 0.10)")
        if self.max_overshoot > 1000.0 and not math.isinf(self.max_overshoot):
            raise InputError(f"specification max_overshoot is in percent of the step; "
                             f"{self.max_overshoot:g} % is not a meaningful limit")

    def band(self, step_size: float) -> float:
        """Half-width (m) of the settling band for a step of ``step_size`` m."""
        return max(self.settling_band * abs(step_size), self.band_floor)

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}
