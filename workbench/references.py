"""Position references r(t): steps, piecewise-linear profiles, the validation profile.

A :class:`Reference` is a position (m) as a function of time (s), either held
between its points (steps) or linear between them (ramps and holds). Simulators,
controllers and the validation all take one; none of them needs the others to build
one (``simulate.steps``, ``simulate.profile`` and ``validate.validation_profile``
re-export the functions defined here).

Examples
--------
>>> from workbench.references import steps, profile, validation_profile
>>> ref = steps([0.1, 0.4, 0.25], hold=2.0)
>>> float(ref(3.0)), ref.duration
(0.4, 6.0)
>>> float(profile([(0.0, 0.1), (1.0, 0.3)])(0.5))
0.2
>>> round(validation_profile(0.5).duration, 2)
22.75
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .errors import InputError

__all__ = ["Reference", "steps", "profile", "validation_profile", "sine_points", "smooth", "Trajectory",
           "SINE_AMPLITUDE", "SINE_FREQUENCY", "SINE_STROKE"]

#: The precision sine section (issue 14, after published rig results): amplitude 60 mm
#: at 0.5 Hz on a 0.5 m stroke; the amplitude scales with the stroke, the frequency not.
SINE_AMPLITUDE = 0.06
SINE_FREQUENCY = 0.5
SINE_STROKE = 0.5
#: Break-point spacing of a sine drawn as a profile, s: the chord error A w^2 dt^2 / 8
#: is 0.3 um for the 60 mm, 0.5 Hz sine, far below any sensor quantum.
_SINE_DT = 2e-3


@dataclass(frozen=True)
class Reference:
    """A position reference r(t) (m): piecewise linear through (times, values).

    Attributes
    ----------
    times : numpy.ndarray
        Break points, s, not decreasing.
    values : numpy.ndarray
        Positions at the break points, m.
    hold : bool
        True: each value is held until the next break point (steps); False: linear
        interpolation between break points (ramps and holds).
    sections : tuple of (name, start s, end s)
        Named stretches judged as a whole rather than piece by piece, e.g.
        ``("sine", 12.0, 18.0)``: a sine drawn as many short ramps is one tracking
        section for the validation, not hundreds of ramps.
    """

    times: np.ndarray
    values: np.ndarray
    hold: bool = False
    sections: tuple = ()

    def __call__(self, t: float | np.ndarray) -> np.ndarray:
        if self.hold:
            idx = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 1)
            return self.values[idx]
        return np.interp(t, self.times, self.values)

    @property
    def duration(self) -> float:
        """Time of the last break point, s."""
        return float(self.times[-1])


def steps(levels: Sequence[float], hold: float, t0: float = 0.0) -> Reference:
    """Step reference: each level (m) held for ``hold`` seconds, the first from ``t0`` (s)."""
    levels = np.asarray(levels, dtype=float)
    times = t0 + hold * np.arange(len(levels) + 1)
    return Reference(times=times, values=np.append(levels, levels[-1]), hold=True)


def profile(points: Sequence[tuple[float, float]]) -> Reference:
    """Piecewise-linear reference through (time s, position m) points (ramps and holds)."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or np.any(np.diff(pts[:, 0]) < 0):
        raise InputError("a profile is a list of (time, position) with time not decreasing")
    return Reference(times=pts[:, 0], values=pts[:, 1], hold=False)


def sine_points(t0: float, center: float, amplitude: float, frequency: float,
                periods: int) -> list[tuple[float, float]]:
    """Break points (s, m) of r = center - amplitude cos(2 pi f (t - t0)) from ``t0``.

    Starts and ends at rest at ``center - amplitude`` (a jump of acceleration only),
    ``periods`` whole periods, points every 2 ms (chord error below 1 um for the
    precision sine).
    """
    if not (math.isfinite(frequency) and frequency > 0):
        raise InputError(f"sine frequency must be > 0 Hz, got {frequency!r}")
    if int(periods) != periods or periods < 1:
        raise InputError(f"sine periods must be a whole number >= 1, got {periods!r}")
    dur = periods / frequency
    n = max(int(math.ceil(dur / _SINE_DT)), 8)
    tt = np.linspace(0.0, dur, n + 1)
    rr = center - amplitude * np.cos(2.0 * math.pi * frequency * tt)
    return [(t0 + float(a), float(b)) for a, b in zip(tt, rr)]


def validation_profile(plant, large_step: float | None = None, small_step: float | None = None,
                       hold: float = 2.5, ramp_speed: float | None = None,
                       margin: float = 0.1, start_hold: float = 0.5,
                       sine: bool = False, sine_periods: int = 3) -> Reference:
    """The standard validation reference for a plant (piecewise linear, m).

    Starting at rest at mid-stroke ``c = L/2`` (``L`` the stroke):

    1. hold ``start_hold`` at ``c``;
    2. large step up to ``c + a``, hold; large step down (size ``2 a``) to ``c - a``, hold;
    3. small step up to ``c - a + s``, hold; small step down to ``c - a``, hold;
    4. ramp up at ``ramp_speed`` to ``(1 - margin) L``, hold;
       ramp down to ``margin L``, hold.

    5. with ``sine``: ramp to ``c - A``, hold, then ``sine_periods`` periods of
       r = c - A cos(2 pi f t), A = 60 mm x L / 0.5 m, f = 0.5 Hz (the precision
       section of issue 14), then hold at ``c - A``. The reference's ``sections``
       name the sine ``("sine", start, end)``.

    Every level stays within [margin L, (1 - margin) L]. With the defaults on a
    0.5 m stroke: steps of 125, 250 and 10 mm, ramps at 0.1 m/s, 22.75 s in all
    (33.2 s with the sine).

    Parameters
    ----------
    plant : Plant or float
        The plant (its stroke is used) or the stroke itself, m.
    large_step : float, m
        ``a``; default a quarter of the stroke.
    small_step : float, m
        ``s``; default 2 % of the stroke (10 mm on 0.5 m).
    hold : float, s
        Hold after every step and ramp. Default 2.5 s (settling time limit 1.5 s plus
        the steady-state window 0.5 s, with room to spare).
    ramp_speed : float, m/s
        Default 0.2 stroke per second.
    margin : float, -
        Fraction of the stroke kept free at each end. Default 0.1.
    start_hold : float, s
        Initial hold at mid-stroke. Default 0.5 s.
    sine : bool
        Append the sine section (item 5).
    sine_periods : int
        Whole periods of the sine (default 3: 6 s at 0.5 Hz).

    Returns
    -------
    Reference
        A :func:`profile`.
    """
    L = float(plant.stroke) if hasattr(plant, "stroke") else float(plant)
    if not (math.isfinite(L) and L > 0):
        raise InputError(f"stroke must be a positive length in m, got {L!r}")
    if not 0.0 <= margin < 0.5:
        raise InputError(f"margin is a fraction of the stroke in [0, 0.5), got {margin!r}")
    lo, hi, c = margin * L, (1.0 - margin) * L, 0.5 * L
    a = 0.25 * L if large_step is None else float(large_step)
    s = 0.02 * L if small_step is None else float(small_step)
    v = 0.2 * L if ramp_speed is None else float(ramp_speed)
    room = c - lo
    if not 0.0 < a <= room + 1e-12:
        raise InputError(f"large_step must be in (0, {room:g}] m so that mid-stroke +- the step "
                         f"stays within {margin:.0%}..{1 - margin:.0%} of the {L:g} m stroke; "
                         f"got {a!r} m")
    if not 0.0 < s <= 2.0 * a:
        raise InputError(f"small_step must be in (0, {2 * a:g}] m, got {s!r} m")
    if not (math.isfinite(hold) and hold > 0):
        raise InputError(f"hold must be > 0 s, got {hold!r}")
    if not (math.isfinite(start_hold) and start_hold >= 0):
        raise InputError(f"start_hold must be >= 0 s, got {start_hold!r}")
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"ramp_speed must be > 0 m/s, got {v!r}")

    pts: list[tuple[float, float]] = [(0.0, c)]
    t = start_hold
    if start_hold > 0:
        pts.append((t, c))
    for level in (c + a, c - a, c - a + s, c - a):
        pts.append((t, level))
        t += hold
        pts.append((t, level))
    for target in (hi, lo):
        t += abs(target - pts[-1][1]) / v
        pts.append((t, target))
        t += hold
        pts.append((t, target))
    if not sine:
        return profile(pts)
    amp = SINE_AMPLITUDE * L / SINE_STROKE
    start = c - amp
    t += abs(start - pts[-1][1]) / v
    pts.append((t, start))
    t += hold
    pts.append((t, start))
    wave = sine_points(t, c, amp, SINE_FREQUENCY, sine_periods)
    pts.extend(wave[1:])
    t_sine = (t, wave[-1][0])
    t = wave[-1][0] + hold
    pts.append((t, start))
    ref = profile(pts)
    return Reference(times=ref.times, values=ref.values, hold=False,
                     sections=(("sine",) + t_sine,))


# ---------------------------------------------------------------------- smooth trajectories
#: s: shortest blend of a ramp corner (a sine drawn as a profile has a corner every
#: 2 ms; blending each over 10 ms is a zero-phase smoothing whose amplitude error on
#: the 60 mm, 0.5 Hz sine is A w^2 tau^2 / 56 = 1e-7 m).
CORNER_MIN = 0.01
_GRID = 5e-4


def _minjerk(s):
    """Min-jerk step 10 s^3 - 15 s^4 + 6 s^5 on [0, 1] and its first three derivatives."""
    s = np.clip(s, 0.0, 1.0)
    return (s ** 3 * (10 - 15 * s + 6 * s * s), 30 * s * s * (1 - s) ** 2,
            60 * s * (1 - s) * (1 - 2 * s), 60 * (1 - 6 * s + 6 * s * s))


@dataclass(frozen=True)
class Trajectory:
    """A smooth position reference with its derivatives, known in advance.

    Made by :func:`smooth` from a :class:`Reference`. Calling it gives the position
    (m); :meth:`derivatives` gives (r, r', r'', r''') in m, m/s, m/s^2, m/s^3.
    Tabulated every 0.5 ms and interpolated linearly (chord error below 0.1 um for
    the precision sine).

    Attributes
    ----------
    source : Reference it smooths. limits : (speed m/s, acceleration m/s^2, jerk m/s^3).
    table : (n, 5) time and the four derivatives.
    """

    source: Reference
    limits: tuple
    table: np.ndarray

    def __call__(self, t):
        return np.interp(t, self.table[:, 0], self.table[:, 1])

    def derivatives(self, t) -> tuple:
        """(r m, r' m/s, r'' m/s^2, r''' m/s^3) at ``t`` (s)."""
        tt = self.table[:, 0]
        return tuple(np.interp(t, tt, self.table[:, i]) for i in range(1, 5))

    @property
    def duration(self) -> float:
        return self.source.duration

    @property
    def sections(self) -> tuple:
        return self.source.sections

    @property
    def times(self):
        return self.source.times

    @property
    def values(self):
        return self.source.values

    @property
    def hold(self) -> bool:
        return self.source.hold


def _jumps_and_corners(ref: Reference):
    """Jumps (t, size) and slope changes (t, delta v) of a reference."""
    t, r = np.asarray(ref.times, float), np.asarray(ref.values, float)
    if ref.hold:
        d = np.diff(r)
        k = np.flatnonzero(np.abs(d) > 0)
        return [(float(t[i + 1]), float(d[i])) for i in k], []
    jumps, corners = [], []
    slope_prev = 0.0
    for i in range(len(t) - 1):
        dt, dr = t[i + 1] - t[i], r[i + 1] - r[i]
        if dt <= 0:
            if dr != 0:
                jumps.append((float(t[i]), float(dr)))
            continue
        slope = dr / dt
        if slope != slope_prev:
            corners.append((float(t[i]), slope - slope_prev))
        slope_prev = slope
    if slope_prev != 0.0:
        corners.append((float(t[-1]), -slope_prev))
    return jumps, corners


def smooth(reference: Reference, max_speed: float, max_acceleration: float,
           max_jerk: float, corner_min: float = CORNER_MIN) -> Trajectory:
    """The reference made feasible and smooth, with exact derivatives.

    * every **jump** of size D becomes a minimum-jerk move starting at the jump,
      r = D (10 s^3 - 15 s^4 + 6 s^5), s = (t - t_j) / T_f, with the shortest T_f
      that keeps the peak speed 1.875 D / T_f, acceleration 5.77 D / T_f^2 and
      jerk 60 D / T_f^3 within the limits (causal: the move starts at the jump);
    * every **corner** (slope change dv of a ramp, or of a sine drawn as a profile)
      is blended symmetrically over tau = max(1.875 |dv| / a_max, sqrt(5.77 |dv| /
      j_max), ``corner_min``): the velocity follows a minimum-jerk step centred on
      the corner, so ramps and holds are kept exactly outside the blends (zero phase,
      no lag).

    Parameters
    ----------
    reference : Reference
    max_speed : m/s. max_acceleration : m/s^2. max_jerk : m/s^3 (all > 0);
        :func:`workbench.controllers.design.axis_limits` derives them from the
        valve's flow and the pressure range.
    corner_min : s, shortest corner blend.

    Returns
    -------
    Trajectory

    Examples
    --------
    >>> traj = smooth(steps([0.2, 0.3], hold=1.0), 1.0, 20.0, 1000.0)
    >>> r, v, a, j = traj.derivatives(1.05)
    >>> 0.2 < float(r) < 0.3 and float(v) > 0
    True
    """
    if not isinstance(reference, Reference):
        raise InputError(f"smooth needs a Reference, got {type(reference).__name__}")
    lims = []
    for name, val in (("max_speed", max_speed), ("max_acceleration", max_acceleration),
                      ("max_jerk", max_jerk), ("corner_min", corner_min)):
        try:
            v = float(val)
        except (TypeError, ValueError):
            raise InputError(f"{name} must be a number, got {val!r}") from None
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"{name} must be > 0, got {val!r}")
        lims.append(v)
    vmax, amax, jmax, cmin = lims
    t_end = reference.duration
    tt = np.arange(0.0, t_end + _GRID, _GRID)
    base = np.asarray(reference(tt), dtype=float)
    out = np.zeros((len(tt), 5))
    out[:, 0], out[:, 1] = tt, base
    jumps, corners = _jumps_and_corners(reference)
    if not reference.hold:                      # slopes of the piecewise-linear part
        out[:, 2] = np.interp(tt, *_slope_table(reference))
    for tj, D in jumps:
        tf = max(1.875 * abs(D) / vmax, math.sqrt(5.7735 * abs(D) / amax),
                 (60.0 * abs(D) / jmax) ** (1.0 / 3.0))
        sel = slice(*np.searchsorted(tt, [tj, tj + tf]))
        s0, s1, s2, s3 = _minjerk((tt[sel] - tj) / tf)
        out[sel, 1] += D * (s0 - 1.0)
        out[sel, 2] += D * s1 / tf
        out[sel, 3] += D * s2 / tf ** 2
        out[sel, 4] += D * s3 / tf ** 3
    for tc, dv in corners:
        tau = max(1.875 * abs(dv) / amax, math.sqrt(5.7735 * abs(dv) / jmax), cmin)
        lo = tc - 0.5 * tau
        sel = slice(*np.searchsorted(tt, [lo, tc + 0.5 * tau]))
        x = tt[sel] - lo
        s0, s1, s2, s3 = _minjerk(x / tau)
        # velocity dv * s(x / tau); position dv * integral of it, minus the kink
        integ = tau * (2.5 * (x / tau) ** 4 - 3 * (x / tau) ** 5 + (x / tau) ** 6)
        out[sel, 1] += dv * (integ - np.maximum(tt[sel] - tc, 0.0))
        out[sel, 2] += dv * (s0 - (tt[sel] >= tc))
        out[sel, 3] += dv * s1 / tau
        out[sel, 4] += dv * s2 / tau ** 2
    return Trajectory(source=reference, limits=(vmax, amax, jmax), table=out)


def _slope_table(ref: Reference):
    """(times, slopes) for np.interp: the slope of each piece at its midpoint... as
    a step function sampled on both sides of every break point."""
    t, r = np.asarray(ref.times, float), np.asarray(ref.values, float)
    ts, vs = [], []
    for i in range(len(t) - 1):
        dt = t[i + 1] - t[i]
        if dt <= 0:
            continue
        s = (r[i + 1] - r[i]) / dt
        ts += [t[i], t[i + 1] - 1e-12]
        vs += [s, s]
    return np.asarray(ts), np.asarray(vs)
