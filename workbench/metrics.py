"""Segments of a position reference and how a response followed each of them.

The reference is cut into segments from its break points alone (never from the
response): *steps* (a jump of the reference, then a hold), *ramps* (the reference moves
linearly) and *holds* (constant reference not entered by a jump). Each segment gets its
metrics (overshoot, settling and rise time, steady-state and tracking error, IAE);
:mod:`workbench.validate` judges them against a specification.

Examples
--------
>>> from workbench.references import steps
>>> from workbench.metrics import find_segments
>>> [s.kind for s in find_segments(steps([0.1, 0.3], hold=1.0))]
['hold', 'step']
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from .errors import InputError
from .references import Reference

if TYPE_CHECKING:  # pragma: no cover
    from .validate import Specification

__all__ = ["Segment", "SegmentMetrics", "find_segments", "segment_metrics", "trapezoid", "window_mean"]

#: Two reference values closer than this (m) are the same level.
_LEVEL_TOL = 1e-12


# ---------------------------------------------------------------------- segments
@dataclass(frozen=True)
class Segment:
    """A piece of the reference.

    Attributes
    ----------
    kind : {"step", "ramp", "hold"}
        ``step``: the reference jumps at ``start`` from ``r_start`` to ``r_end`` and is
        held until ``end``; ``ramp``: it moves linearly from ``r_start`` to ``r_end``;
        ``hold``: it stays at ``r_start == r_end`` (not entered by a jump).
    start, end : s.
    r_start, r_end : m.
    """

    kind: str
    start: float
    end: float
    r_start: float
    r_end: float

    @property
    def size(self) -> float:
        """Change of the reference over the segment, m."""
        return self.r_end - self.r_start

    @property
    def duration(self) -> float:
        return self.end - self.start

    def describe(self) -> str:
        """E.g. ``step at 0.50 s, 250.0 -> 375.0 mm``."""
        if self.kind == "hold":
            return f"hold {self.start:.2f}-{self.end:.2f} s at {self.r_end * 1e3:.1f} mm"
        what = "step at" if self.kind == "step" else "ramp"
        when = f"{self.start:.2f} s" if self.kind == "step" else f"{self.start:.2f}-{self.end:.2f} s"
        return f"{what} {when}, {self.r_start * 1e3:.1f} -> {self.r_end * 1e3:.1f} mm"


def find_segments(reference: Reference) -> tuple[Segment, ...]:
    """Steps, ramps and holds of a reference, from its break points alone.

    A jump straight into a ramp is not a step (it has no hold to settle in); the
    ramp's tracking error covers it. Consecutive constant pieces at one level merge.

    Parameters
    ----------
    reference : Reference
        From :func:`workbench.simulate.steps` or :func:`workbench.simulate.profile`.
    """
    if not isinstance(reference, Reference):
        raise InputError("validation needs a workbench.simulate.Reference (from simulate.steps "
                         f"or simulate.profile) to find its steps and ramps, got {type(reference).__name__}")
    t = np.asarray(reference.times, dtype=float)
    r = np.asarray(reference.values, dtype=float)
    if t.ndim != 1 or t.shape != r.shape or len(t) < 2:
        raise InputError("a reference needs at least two (time, value) points")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(r))):
        raise InputError("the reference has non-finite times or values")
    if np.any(np.diff(t) < 0):
        raise InputError("reference times must not decrease")
    segs: list[Segment] = []

    def constant(t0: float, t1: float, level: float, jump_from: float | None) -> None:
        if jump_from is not None and abs(level - jump_from) > _LEVEL_TOL:
            segs.append(Segment("step", t0, t1, jump_from, level))
            return
        last = segs[-1] if segs else None
        if (last is not None and last.kind != "ramp" and abs(last.end - t0) <= 1e-12
                and abs(last.r_end - level) <= _LEVEL_TOL):
            segs[-1] = replace(last, end=t1)
        else:
            segs.append(Segment("hold", t0, t1, level, level))

    if t[0] > 0:
        constant(0.0, float(t[0]), float(r[0]), None)
    if reference.hold:
        prev = None
        for i in range(len(t) - 1):
            if t[i + 1] <= t[i]:
                continue
            constant(float(t[i]), float(t[i + 1]), float(r[i]), prev)
            prev = float(r[i])
        return tuple(segs)

    jump_from: float | None = None
    for i in range(len(t) - 1):
        dt, dr = t[i + 1] - t[i], r[i + 1] - r[i]
        if dt <= 0:
            if abs(dr) > _LEVEL_TOL and jump_from is None:
                jump_from = float(r[i])
            continue
        if abs(dr) <= _LEVEL_TOL:
            constant(float(t[i]), float(t[i + 1]), float(r[i]), jump_from)
        else:
            segs.append(Segment("ramp", float(t[i]), float(t[i + 1]), float(r[i]), float(r[i + 1])))
        jump_from = None
    return tuple(segs)


# ---------------------------------------------------------------------- metrics
@dataclass(frozen=True)
class SegmentMetrics:
    """How the position followed one segment.

    Attributes
    ----------
    segment : Segment
    overshoot : %, of the step size (steps; NaN otherwise).
    overshoot_abs : m, the same as a length.
    settling_time : s after the step until |x - r| stays within ``band``; ``inf`` if it
        is outside the band at any time in the steady-state window at the end of the
        hold (it must have settled before the steady-state error is measured).
    rise_time : s from 10 % to 90 % of the step; ``inf`` if 90 % is never reached.
    band : m, settling band half-width used.
    steady_state_error : m, mean |r - x| over the end of the hold (steps, holds).
    tracking_error : m, max |r - x| over the segment.
    iae : m s, integral of |r - x| over the segment.
    complete : the trajectory covers the whole segment.
    """

    segment: Segment
    overshoot: float = math.nan
    overshoot_abs: float = math.nan
    settling_time: float = math.nan
    rise_time: float = math.nan
    band: float = math.nan
    steady_state_error: float = math.nan
    tracking_error: float = math.nan
    iae: float = math.nan
    complete: bool = True

    def to_dict(self) -> dict[str, Any]:
        s = self.segment
        return {"kind": s.kind, "start": s.start, "end": s.end, "r_start": s.r_start,
                "r_end": s.r_end, "overshoot": self.overshoot, "overshoot_abs": self.overshoot_abs,
                "settling_time": self.settling_time, "rise_time": self.rise_time,
                "band": self.band, "steady_state_error": self.steady_state_error,
                "tracking_error": self.tracking_error, "iae": self.iae, "complete": self.complete}


def trapezoid(y: np.ndarray, t: np.ndarray) -> float:
    """Trapezoidal integral of samples ``y`` over instants ``t`` (s): unit of y times s."""
    if len(t) < 2:
        return 0.0
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))


def window_mean(y: np.ndarray, t: np.ndarray) -> float:
    """Time mean of samples ``y`` over their instants ``t`` (s): the trapezoidal
    integral over the span, the plain mean if the span is a single instant (NaN for
    no sample)."""
    if len(t) > 1 and t[-1] > t[0]:
        return trapezoid(y, t) / float(t[-1] - t[0])
    return float(np.mean(y)) if len(y) else math.nan


def _first_crossing(t: np.ndarray, y: np.ndarray, level: float) -> float:
    """First time (linear interpolation) at which ``y`` reaches ``level`` from below."""
    above = np.flatnonzero(y >= level)
    if len(above) == 0:
        return math.inf
    k = int(above[0])
    if k == 0:
        return float(t[0])
    y0, y1 = y[k - 1], y[k]
    return float(t[k - 1] + (level - y0) / (y1 - y0) * (t[k] - t[k - 1]))


def _settling(t: np.ndarray, err: np.ndarray, band: float, t_step: float,
              dwell: float = 0.0) -> float:
    """Time after ``t_step`` from which |err| <= band to the end (interpolated).

    ``inf`` if the response is outside the band during the last ``dwell`` seconds
    (a ringing response that happens to be inside at the last sample has not settled).
    """
    out = np.flatnonzero(np.abs(err) > band)
    if len(out) == 0:
        return 0.0
    k = int(out[-1])
    if k == len(t) - 1 or t[k] >= t[-1] - dwell:
        return math.inf
    a, b = abs(err[k]), abs(err[k + 1])
    frac = (a - band) / (a - b) if a != b else 1.0
    return float(t[k] + frac * (t[k + 1] - t[k]) - t_step)


def segment_metrics(time: np.ndarray, x: np.ndarray, reference: Reference,
                    segments: Sequence[Segment], spec: Specification) -> tuple[SegmentMetrics, ...]:
    """Metrics of every segment from a sampled position.

    Parameters
    ----------
    time : (N,) s, increasing. x : (N,) position, m.
    reference : Reference, m (evaluated at ``time``; the step levels come from the segments).
    segments : from :func:`find_segments`. spec : Specification (band, window).
    """
    time = np.asarray(time, dtype=float)
    x = np.asarray(x, dtype=float)
    t_last = float(time[-1]) if len(time) else -math.inf
    out = []
    for seg in segments:
        sel = (time >= seg.start - 1e-9) & (time <= seg.end + 1e-9)
        tt, xx = time[sel], x[sel]
        complete = t_last >= seg.end - 1e-9
        if len(tt) < 2 or seg.duration <= 0:
            out.append(SegmentMetrics(seg, complete=complete and len(tt) >= 2))
            continue
        if seg.kind == "ramp":
            rr = np.asarray(reference(tt), dtype=float)
        else:
            rr = np.full_like(tt, seg.r_end)
        e = np.abs(rr - xx)
        kw: dict[str, Any] = {"tracking_error": float(np.max(e)), "iae": trapezoid(e, tt),
                              "complete": complete}
        w = min(spec.steady_state_window, 0.5 * seg.duration)
        if seg.kind in ("step", "hold"):
            if complete:
                win = tt >= seg.end - w - 1e-9
            else:
                win = tt >= tt[-1] - w - 1e-9
            ew, tw = e[win], tt[win]
            kw["steady_state_error"] = window_mean(ew, tw)
        if seg.kind == "step":
            size = seg.size
            sgn = math.copysign(1.0, size)
            band = spec.band(size)
            peak = float(np.max(sgn * (xx - seg.r_end)))
            over = max(peak, 0.0)
            progress = sgn * (xx - seg.r_start) / abs(size)
            t10 = _first_crossing(tt, progress, 0.1)
            t90 = _first_crossing(tt, progress, 0.9)
            kw.update(overshoot=100.0 * over / abs(size), overshoot_abs=over, band=band,
                      settling_time=_settling(tt, xx - seg.r_end, band, seg.start, w),
                      rise_time=(t90 - t10) if math.isfinite(t90) else math.inf)
        out.append(SegmentMetrics(seg, **kw))
    return tuple(out)
