"""Auto-validation of a position controller on the full nonlinear plant.

A controller is run in the sampled-data closed loop (:func:`workbench.simulate.closed_loop`)
on the plant exactly as its plant file describes it (every effect included) over a
validation profile -- steps both ways, large and small, ramps up and down, holds long
enough to settle -- and the response is judged against a :class:`Specification`.

The profile is cut into segments from the :class:`~workbench.simulate.Reference`
itself (never from the response): *steps* (a jump of the reference, then a hold),
*ramps* (the reference moves linearly) and *holds* (constant reference not entered
by a jump). Each segment gets its metrics; each check judges the worst segment.

Examples
--------
>>> from workbench import Plant, controllers, validate
>>> plant = Plant.from_toml("designs/plants/situm_rodless_nominal.toml")
>>> v = validate.validate(plant, controllers.from_plant(plant))
>>> v.passed, [c.name for c in v.failed]
(False, ['overshoot'])
>>> for row in v.table()[:3]: print(row)
('simulation', '22.75', '<= 22.75', 's', 'pass')
('overshoot', '12.019', '<= 10', '%', 'FAIL')
('settling time', '0.69288', '<= 1.5', 's', 'pass')
"""

from __future__ import annotations

import math
import sys
import time as _time
from dataclasses import dataclass, fields, replace
from typing import Any, Callable, Sequence

import numpy as np

from . import simulate
from .errors import InputError, WorkbenchError
from .metrics import Segment, SegmentMetrics, find_segments, segment_metrics, trapezoid
from .references import Reference, validation_profile
from .simulate import Trajectory
from .specification import Specification

__all__ = [
    "Specification", "Segment", "SegmentMetrics", "Check", "Metrics", "Validation",
    "validation_profile", "find_segments", "segment_metrics", "evaluate", "validate",
    "sine_sections", "precision_profile",
]


def precision_profile(plant, **kwargs) -> Reference:
    """The validation profile with the precision sine section appended
    (:func:`validation_profile` with ``sine=True``; keyword arguments passed on)."""
    kwargs.setdefault("sine", True)
    return validation_profile(plant, **kwargs)


# ---------------------------------------------------------------------- checks and results
@dataclass(frozen=True)
class Check:
    """One judged quantity.

    Attributes
    ----------
    name : str. value : measured (worst case), in ``unit``. limit : in ``unit``.
    unit : SI unit or ``%``. passed : bool.
    detail : where the worst case is, or why the check failed, in words.
    bound : ``"max"`` (value must not exceed limit) or ``"min"`` (must not fall below).
    """

    name: str
    value: float
    limit: float
    unit: str
    passed: bool
    detail: str = ""
    bound: str = "max"

    def __post_init__(self) -> None:
        if self.bound not in ("max", "min"):
            raise InputError(f"a check's bound is 'max' or 'min', got {self.bound!r}")
        object.__setattr__(self, "value", float(self.value))
        object.__setattr__(self, "limit", float(self.limit))
        object.__setattr__(self, "passed", bool(self.passed))


@dataclass(frozen=True)
class Metrics:
    """Whole-run figures (SI).

    Attributes
    ----------
    iae : m s, integral of |r - x|. saturation_fraction : -, of the run time.
    p_min, p_max : Pa, lowest and highest chamber pressure.
    ramp_error_max : m (NaN without ramps). simulated_time : s reached.
    duration : s, the reference's duration.
    sine_error_max : m, largest |r - x| over the sine sections (NaN without one).
    """

    iae: float
    saturation_fraction: float
    p_min: float
    p_max: float
    ramp_error_max: float
    simulated_time: float
    duration: float
    sine_error_max: float = math.nan


_DISPLAY = {"m": (1e3, "mm"), "Pa": (1e-5, "bar abs"), "s": (1.0, "s"), "%": (1.0, "%")}


def _fmt(v: float) -> str:
    if math.isnan(v):
        return "n/a"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.5g}" if abs(v) < 1e5 else f"{v:.4e}"


@dataclass(frozen=True, eq=False)
class Validation:
    """Result of :func:`validate` (or :func:`evaluate`).

    Attributes
    ----------
    trajectory : Trajectory (up to where the simulation got).
    reference : Reference. spec : Specification.
    segments : tuple of SegmentMetrics, in time order.
    checks : tuple of Check.
    metrics : Metrics.
    command_range : (command_min, command_max), V.
    pressure_range : (atmospheric, supply) pressure, Pa.
    error : str or None, why the simulation stopped early.
    wall_time : s spent simulating (0 for :func:`evaluate`).
    label : what was validated (plant and controller), for titles.
    """

    trajectory: Trajectory
    reference: Reference
    spec: Specification
    segments: tuple[SegmentMetrics, ...]
    checks: tuple[Check, ...]
    metrics: Metrics
    command_range: tuple[float, float]
    pressure_range: tuple[float, float]
    error: str | None = None
    wall_time: float = 0.0
    label: str = ""

    @property
    def passed(self) -> bool:
        """All checks passed."""
        return all(c.passed for c in self.checks)

    @property
    def failed(self) -> tuple[Check, ...]:
        """The checks that failed."""
        return tuple(c for c in self.checks if not c.passed)

    def check(self, name: str) -> Check:
        """A check by name."""
        for c in self.checks:
            if c.name == name:
                return c
        raise KeyError(f"no check '{name}'; checks: {', '.join(c.name for c in self.checks)}")

    def table(self) -> list[tuple[str, str, str, str, str]]:
        """Rows ``(item, value, limit, unit, "pass"/"FAIL")`` for a report.

        Lengths are shown in mm and pressures in bar (absolute); the limit carries
        its direction (``<=`` or ``>=``).
        """
        rows = []
        for c in self.checks:
            k, unit = _DISPLAY.get(c.unit, (1.0, c.unit))
            op = "<=" if c.bound == "max" else ">="
            rows.append((c.name, _fmt(c.value * k), f"{op} {_fmt(c.limit * k)}", unit,
                         "pass" if c.passed else "FAIL"))
        return rows

    def summary(self) -> str:
        """A few lines of plain text: verdict, then one line per check."""
        head = f"{self.label + ': ' if self.label else ''}{'PASSED' if self.passed else 'FAILED'}"
        if self.spec.name:
            head += f" ({self.spec.name} specification)"
        lines = [head]
        for (item, val, lim, unit, verdict), c in zip(self.table(), self.checks):
            lines.append(f"  {verdict:4s} {item:22s} {val:>10s} {lim:>12s} {unit:8s} {c.detail}")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON (SI)."""
        return {"label": self.label, "passed": self.passed, "error": self.error,
                "wall_time": self.wall_time, "spec": self.spec.to_dict(),
                "checks": [{"name": c.name, "value": c.value, "limit": c.limit, "unit": c.unit,
                            "bound": c.bound, "passed": c.passed, "detail": c.detail}
                           for c in self.checks],
                "metrics": {f.name: getattr(self.metrics, f.name) for f in fields(self.metrics)},
                "segments": [s.to_dict() for s in self.segments]}


def _worst(items, key: Callable) -> Any:
    best, best_k = None, -math.inf
    for it in items:
        k = key(it)
        if math.isnan(k):
            continue
        if best is None or k > best_k:
            best, best_k = it, k
    return best


def _plant_limits(plant) -> tuple[tuple[float, float], tuple[float, float]]:
    prm = plant.params
    try:
        return ((float(prm["valve.command_min"]), float(prm["valve.command_max"])),
                (float(prm["gas.atmospheric_pressure"]), float(prm["supply.pressure"])))
    except KeyError as exc:
        raise InputError(f"the plant lacks {exc} needed to judge a validation") from None


def _signal(traj: Trajectory, name: str) -> np.ndarray:
    try:
        return np.asarray(traj[name], dtype=float)
    except KeyError:
        raise InputError(f"the trajectory has no signal '{name}', needed for validation") from None


def evaluate(trajectory: Trajectory, reference: Reference, spec: Specification, plant,
             error: str | None = None, wall_time: float = 0.0, label: str = "") -> Validation:
    """Judge an existing trajectory against a specification (no simulation).

    Parameters
    ----------
    trajectory : Trajectory
        Needs ``x`` (m), ``u`` (V), ``p_a`` and ``p_b`` (Pa); time in s. It may stop
        before the reference ends (a failed simulation): the run then fails the
        ``simulation`` check, and the segments it reached are judged on what there is.
    reference : Reference, m.
    spec : Specification.
    plant : Plant
        Gives the command range (``valve.command_min/max``, V) and the pressure bounds
        (``gas.atmospheric_pressure``, ``supply.pressure``, Pa).
    error : str, optional
        Why the simulation stopped early, for the ``simulation`` check's detail.

    Returns
    -------
    Validation
    """
    if not isinstance(spec, Specification):
        raise InputError(f"spec must be a validate.Specification, got {type(spec).__name__}")
    sines = sine_sections(reference)
    segments = tuple(s for s in find_segments(reference)
                     if not any(s.start >= a - 1e-9 and s.end <= b + 1e-9 for a, b in sines))
    t = np.asarray(trajectory.time, dtype=float)
    if t.ndim != 1 or len(t) < 1:
        raise InputError("the trajectory has no samples")
    x, u = _signal(trajectory, "x"), _signal(trajectory, "u")
    p_a, p_b = _signal(trajectory, "p_a"), _signal(trajectory, "p_b")
    (u_min, u_max), (p_atm, p_sup) = _plant_limits(plant)
    seg_m = segment_metrics(t, x, reference, segments, spec)
    duration = reference.duration
    t_end = float(t[-1])
    completed = error is None and t_end >= duration - 1e-6

    metrics = _run_metrics(t, x, u, p_a, p_b, reference, seg_m, (u_min, u_max))
    checks = [_simulation_check(completed, error, t_end, duration)]
    checks += _segment_checks(seg_m, spec, metrics.ramp_error_max)
    if sines:
        sine_check = _sine_check(t, x, reference, sines, spec)
        metrics = replace(metrics, sine_error_max=sine_check.value)
        checks.append(sine_check)
    checks += _limit_checks(t, p_a, p_b, metrics, spec, (u_min, u_max), (p_atm, p_sup))
    return Validation(trajectory=trajectory, reference=reference, spec=spec, segments=seg_m,
                      checks=tuple(checks), metrics=metrics, command_range=(u_min, u_max),
                      pressure_range=(p_atm, p_sup), error=None if completed else (error or
                      "trajectory ends before the reference"), wall_time=wall_time, label=label)


def _run_metrics(t: np.ndarray, x: np.ndarray, u: np.ndarray, p_a: np.ndarray,
                 p_b: np.ndarray, reference: Reference, seg_m: Sequence[SegmentMetrics],
                 u_range: tuple[float, float]) -> Metrics:
    """Whole-run metrics: IAE (m s), share of time at a command limit, pressure range (Pa)."""
    u_min, u_max = u_range
    r_all = np.asarray(reference(t), dtype=float)
    iae = trapezoid(np.abs(r_all - x), t)
    tol_u = 1e-9 * max(1.0, u_max - u_min)
    sat = (u <= u_min + tol_u) | (u >= u_max - tol_u)
    if len(t) > 1:
        dt = np.diff(t)
        sat_frac = float(np.sum(dt * sat[:-1]) / (t[-1] - t[0]))   # u is held (ZOH) on [t_k, t_k+1)
    else:
        sat_frac = float(sat[0])
    p_all = np.concatenate((p_a, p_b))
    ramps = [m for m in seg_m if m.segment.kind == "ramp"]
    ramp_max = max((m.tracking_error for m in ramps if not math.isnan(m.tracking_error)),
                   default=math.nan)
    return Metrics(iae=iae, saturation_fraction=sat_frac, p_min=float(np.min(p_all)),
                   p_max=float(np.max(p_all)), ramp_error_max=ramp_max,
                   simulated_time=float(t[-1]), duration=reference.duration)


def _simulation_check(completed: bool, error: str | None, t_end: float,
                      duration: float) -> Check:
    if completed:
        return Check("simulation", duration, duration, "s", True,
                     f"ran the whole {duration:g} s profile")
    why = error or "the trajectory ends before the reference"
    return Check("simulation", t_end, duration, "s", False,
                 f"stopped at t = {t_end:.3f} s of {duration:g} s: {why}")


def _segment_checks(seg_m: Sequence[SegmentMetrics], spec: Specification,
                    ramp_max: float) -> list[Check]:
    """Overshoot, settling time, steady-state and ramp tracking error of the worst segment."""
    checks: list[Check] = []
    ramps = [m for m in seg_m if m.segment.kind == "ramp"]
    steps = [m for m in seg_m if m.segment.kind == "step" and not math.isnan(m.overshoot)]
    if steps:
        def over_ratio(m: SegmentMetrics) -> float:
            lim = _overshoot_limit(spec, m)
            return m.overshoot / lim if lim > 0 else (math.inf if m.overshoot > 0 else 0.0)
        w = _worst(steps, over_ratio)
        lim = _overshoot_limit(spec, w)
        checks.append(Check("overshoot", w.overshoot, lim, "%", w.overshoot <= lim,
                            f"{w.segment.describe()}: {w.overshoot_abs * 1e3:.2f} mm"
                            + (f" (limit raised from {spec.max_overshoot:g} % to the "
                               f"{spec.band_floor * 1e3:g} mm floor)" if lim > spec.max_overshoot else "")))
        w = _worst(steps, lambda m: m.settling_time)
        unsettled = "; never settled within the hold" if math.isinf(w.settling_time) else ""
        checks.append(Check("settling time", w.settling_time, spec.max_settling_time, "s",
                            w.settling_time <= spec.max_settling_time,
                            f"{w.segment.describe()}, band +-{w.band * 1e3:.2f} mm{unsettled}"
                            + ("" if w.complete else " (hold cut short)")))
    holds = [m for m in seg_m if m.segment.kind in ("step", "hold")
             and not math.isnan(m.steady_state_error)]
    if holds:
        w = _worst(holds, lambda m: m.steady_state_error)
        checks.append(Check("steady-state error", w.steady_state_error, spec.max_steady_state_error,
                            "m", w.steady_state_error <= spec.max_steady_state_error,
                            f"{w.segment.describe()}, mean over the last "
                            f"{min(spec.steady_state_window, 0.5 * w.segment.duration):g} s"))
    if ramps and not math.isnan(ramp_max):
        w = _worst(ramps, lambda m: m.tracking_error)
        checks.append(Check("ramp tracking error", w.tracking_error, spec.max_ramp_error, "m",
                            w.tracking_error <= spec.max_ramp_error,
                            f"{w.segment.describe()} "
                            f"({abs(w.segment.size) / w.segment.duration * 1e3:.0f} mm/s)"))
    return checks


def sine_sections(reference) -> list[tuple[float, float]]:
    """(start, end) in s of the reference's sections named "sine"."""
    out = []
    for sec in getattr(reference, "sections", ()) or ():
        if len(sec) != 3 or sec[0] != "sine":
            continue
        a, b = float(sec[1]), float(sec[2])
        if not (math.isfinite(a) and math.isfinite(b) and b > a):
            raise InputError(f"a reference section needs start < end in s, got {sec!r}")
        out.append((a, b))
    return out


def _sine_check(t: np.ndarray, x: np.ndarray, reference, sines, spec: Specification) -> Check:
    """Worst |r - x| over the sine sections (m); NaN and failed if none was simulated."""
    worst, where, covered = math.nan, "", True
    for a, b in sines:
        sel = (t >= a - 1e-9) & (t <= b + 1e-9)
        covered = covered and bool(len(t)) and t[-1] >= b - 1e-9
        if not np.any(sel):
            continue
        e = np.abs(np.asarray(reference(t[sel]), dtype=float) - x[sel])
        k = int(np.argmax(e))
        if math.isnan(worst) or e[k] > worst:
            worst, where = float(e[k]), f"sine {a:.2f}-{b:.2f} s, worst at t = {t[sel][k]:.2f} s"
    passed = (not math.isnan(worst)) and covered and worst <= spec.max_sine_error
    if not covered:
        where += ("; " if where else "") + "the run stops before the sine ends"
    return Check("sine tracking error", worst, spec.max_sine_error, "m", passed, where)


def _limit_checks(t: np.ndarray, p_a: np.ndarray, p_b: np.ndarray, metrics: Metrics,
                  spec: Specification, u_range: tuple[float, float],
                  p_range: tuple[float, float]) -> list[Check]:
    """Command saturation and chamber pressure bounds over the whole run."""
    (u_min, u_max), (p_atm, p_sup) = u_range, p_range
    sat_frac, p_min, p_max = metrics.saturation_fraction, metrics.p_min, metrics.p_max
    p_all = np.concatenate((p_a, p_b))
    checks: list[Check] = []
    checks.append(Check("command saturation", 100.0 * sat_frac, 100.0 * spec.max_saturation, "%",
                        sat_frac <= spec.max_saturation,
                        f"time at {u_min:g} V or {u_max:g} V: {sat_frac * (t[-1] - t[0]):.2f} s"))
    lo, hi = p_atm - spec.pressure_tolerance, p_sup + spec.pressure_tolerance
    k_lo = int(np.argmin(p_all)) % len(t)
    k_hi = int(np.argmax(p_all)) % len(t)
    ch_lo = "p_a" if p_a[k_lo] <= p_b[k_lo] else "p_b"
    ch_hi = "p_a" if p_a[k_hi] >= p_b[k_hi] else "p_b"
    checks.append(Check("min chamber pressure", p_min, lo, "Pa", p_min >= lo,
                        f"{ch_lo} at t = {t[k_lo]:.2f} s; atmosphere {p_atm / 1e5:.3f} bar "
                        f"- {spec.pressure_tolerance / 1e5:g} bar", bound="min"))
    checks.append(Check("max chamber pressure", p_max, hi, "Pa", p_max <= hi,
                        f"{ch_hi} at t = {t[k_hi]:.2f} s; supply {p_sup / 1e5:.3f} bar "
                        f"+ {spec.pressure_tolerance / 1e5:g} bar"))
    return checks


def _overshoot_limit(spec: Specification, m: SegmentMetrics) -> float:
    """Overshoot limit (%) of one step: the spec's, or the band floor if that is larger."""
    size = abs(m.segment.size)
    return max(spec.max_overshoot, 100.0 * spec.band_floor / size) if size > 0 else math.inf


# ---------------------------------------------------------------------- validate
#: s of wall time between two progress lines of a long validation (stderr).
PROGRESS_EVERY = 2.0


class _Counting:
    """Controller proxy counting the samples the simulator asked for.

    With a ``label`` it also prints a progress line to stderr every
    ``PROGRESS_EVERY`` seconds of wall time (simulated time of the total), so a long
    validation run from a script or a log is never silent.
    """

    def __init__(self, inner, label: str | None = None, duration: float = math.nan) -> None:
        self.inner = inner
        self.sample_time = inner.sample_time
        self.calls = 0
        self.label = label
        self.duration = duration
        self._last = _time.perf_counter()

    def reset(self):
        self.calls = 0
        self._last = _time.perf_counter()
        return self.inner.reset()

    def update(self, state, r, y):
        self.calls += 1
        if self.label is not None and _time.perf_counter() - self._last >= PROGRESS_EVERY:
            self._last = _time.perf_counter()
            print(f"  validate {self.label}: {self.calls * self.sample_time:.1f} of "
                  f"{self.duration:.1f} s simulated", file=sys.stderr, flush=True)
        return self.inner.update(state, r, y)


def _progress_lines(progress: bool | None) -> bool:
    """Lines on stderr for automatic progress (None) off a terminal (no bar there)."""
    try:
        return progress is None and not sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def _truncate(traj: Trajectory, n: int) -> Trajectory:
    return replace(traj, time=traj.time[:n], states=traj.states[:n], inputs=traj.inputs[:n],
                   outputs=traj.outputs[:n],
                   reference=None if traj.reference is None else traj.reference[:n])


def _describe(plant, controller) -> str:
    kind = getattr(controller, "kind", type(controller).__name__)
    gains = ", ".join(f"{k} = {getattr(controller, k):g}" for k in ("kp", "kd", "ki")
                      if getattr(controller, k, 0))
    return f"{getattr(plant, 'name', 'plant')}: {kind.upper() if len(kind) <= 3 else kind}" \
           + (f" ({gains})" if gains else "")


def validate(plant, controller=None, spec: Specification | None = None,
             reference: Reference | None = None, x0: Sequence[float] | float | None = None,
             progress: bool | None = None, output_step: float | None = 1e-3,
             label: str | None = None) -> Validation:
    """Run ``controller`` on the full nonlinear ``plant`` and judge the response.

    The plant is simulated with every effect its plant file has (sampled-data loop,
    command clipped to the valve range, ADC/DAC quantisation from the plant file).
    If the simulation fails (the solver gives up on a runaway loop) or produces
    non-finite values, the part simulated until then is kept and judged, and the
    ``simulation`` check fails with the solver's message: no exception escapes for
    that. Input errors (bad arguments, start outside the stroke) still raise.

    Parameters
    ----------
    plant : Plant
    controller : DiscreteController, optional
        Default: the plant file's ``[controller]`` (:func:`workbench.controllers.from_plant`).
    spec : Specification, optional
        Default ``Specification()``.
    reference : Reference, optional
        Default :func:`validation_profile` of the plant.
    x0 : float (m) or full state, optional
        Default: at rest at r(0).
    progress : bool, optional
        Progress bar (True), none (False), or automatic (None): a bar on a terminal,
        else a line on stderr every ``PROGRESS_EVERY`` (2) s of a long run.
    output_step : float, s, optional
        Sampling of the reported trajectory (default 1 ms, finer than the 10 ms
        control period so overshoot peaks are not missed), rounded so that a whole
        number of outputs fits in one control period; None: every control sample.
    label : str, optional
        Title for figures and reports (default plant name and controller gains).

    Returns
    -------
    Validation

    Examples
    --------
    >>> from workbench import Plant, controllers
    >>> plant = Plant.from_toml("designs/plants/situm_rodless_nominal.toml")
    >>> v = validate(plant, controllers.from_plant(plant))
    >>> print(v.summary().splitlines()[0])
    situm-rodless-15mm-nominal: P (kp = 10): FAILED
    """
    if controller is None:
        from .controllers import from_plant
        controller = from_plant(plant)
    from .plausibility import check_controller
    check_controller(plant, controller)           # a centre command that centres the valve
    spec = Specification() if spec is None else spec
    if not isinstance(spec, Specification):
        raise InputError(f"spec must be a validate.Specification, got {type(spec).__name__}")
    reference = validation_profile(plant) if reference is None else reference
    find_segments(reference)                      # reject a bad reference before simulating
    T = getattr(controller, "sample_time", None)
    if not (isinstance(T, (int, float)) and T > 0):
        raise InputError("the controller needs a sample_time > 0 s")
    duration = reference.duration
    if output_step is not None and not (output_step > 0):
        raise InputError(f"output_step must be > 0 s, got {output_step!r}")
    label = _describe(plant, controller) if label is None else label

    # Outputs on a grid that divides the control period, simulated to a whole number
    # of periods: closed_loop then integrates one period at a time (its fast path).
    per = 1 if output_step is None else max(1, int(round(T / output_step)))

    def run(t_end: float, proxy: _Counting) -> Trajectory:
        n = int(math.ceil(t_end / T - 1e-9))
        out_t = (T / per) * np.arange(n * per + 1)
        return simulate.closed_loop(plant, proxy, reference, t_end=n * T, x0=x0,
                                    output_times=out_t, progress=progress)

    t0 = _time.perf_counter()
    lines = label if _progress_lines(progress) else None
    traj, error = _run_keeping_failures(run, duration, controller, T, lines)
    wall = _time.perf_counter() - t0
    traj, error = _finite_part(traj, duration, error)
    return evaluate(traj, reference, spec, plant, error=error, wall_time=wall, label=label)


def _run_keeping_failures(run: Callable, duration: float, controller, T: float,
                          label: str | None = None) -> tuple[Trajectory, str | None]:
    """Simulate to ``duration`` (s); if the solver gives up, the part up to the failure.

    ``label``: print progress lines under this name (:class:`_Counting`).
    Returns the trajectory and the solver's message (None when it ran through).
    """
    error = None
    proxy = _Counting(controller, label, duration)
    try:
        traj = run(duration, proxy)
    except InputError:
        raise
    except WorkbenchError as exc:
        # The solver gave up on the interval after the last sample the controller
        # saw; everything before it was integrated. The loop is deterministic, so
        # rerunning to that sample reproduces it with every state kept.
        error = f"the simulation failed: {exc}"
        t_ok = max(proxy.calls - 1, 0) * T
        try:
            traj = run(t_ok, _Counting(controller))
        except InputError:
            raise
        except WorkbenchError:
            try:
                traj = run(0.0, _Counting(controller))
            except WorkbenchError as exc0:
                raise WorkbenchError(f"the simulation cannot even start: {exc0}") from None
    return traj, error


def _finite_part(traj: Trajectory, duration: float,
                 error: str | None) -> tuple[Trajectory, str | None]:
    """The trajectory cut at the reference's end (s) and before any non-finite sample."""
    beyond = np.flatnonzero(traj.time > duration + 1e-9)
    if len(beyond):                              # the last period ran past the reference's end
        traj = _truncate(traj, int(beyond[0]))
    sig = np.column_stack([traj["x"], traj["u"], traj["p_a"], traj["p_b"]])
    bad = np.flatnonzero(~np.all(np.isfinite(sig), axis=1))
    if len(bad):
        k = int(bad[0])
        if error is None:
            error = f"the simulation produced non-finite values at t = {traj.time[k]:.3f} s"
        traj = _truncate(traj, max(k, 1))
    return traj, error
