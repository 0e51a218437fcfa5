"""Grey-box estimation: physical parameters of the CasADi plant from recordings.

Any subset of the plant's parameter vector (:attr:`workbench.Plant.param_names`,
effect parameters included) is fitted to one or more recordings by replaying the
recorded command ``u`` open loop (zero-order hold at the recording's instants) and
comparing the simulated outputs with the measured ones (``x``, ``p_a``, ``p_b`` as
recorded; ``v`` and ``p_s`` when asked for). Recordings made in closed loop are
fitted the same way (the command that was applied is what the plant saw).

Method
------
*Multiple shooting.* Each recording is cut into shooting intervals of ``M`` samples
(:func:`estimate`'s ``shooting_interval``, 50 ms by default). The plant state at the
start of every interval is a decision variable, next to the (scaled) parameters, and
continuity between intervals is an equality constraint, so a long open-loop replay
never has to be stable or even close to the data at the start: the nodes start on
the measured states (velocity from differenced position, unmeasured states from a
replay with the start values) and the optimiser closes the gaps.

*Integration.* Inside an interval the plant is integrated with a fixed step per
sample (``substeps`` steps per sample when the sample time exceeds the largest step)
of the Radau IIA collocation method (2 stages, order 3, by default; 3 stages, order 5,
on request; L-stable and stiffly accurate, so the stiff chamber dynamics near a
pressure ratio of 1 or at an end stop do not limit the step). The stage equations are
solved by a fixed number of simplified Newton iterations with the exact CasADi
Jacobian; the sensitivities of each step with respect to its start state and to the
parameters are exact for the stage equations (implicit function theorem) and are
propagated through the interval in the same compiled function. The step is generated
as C and compiled once per plant structure and number of parameters
(:mod:`workbench.integrate.jit`, cached on disk); plants with many states (line segments) use a
sparse LU at run time instead. On the 25 mm reference rig at 1 kHz the 2-stage scheme
at 1 ms stays within about 1e-6 of full scale of CVODES at a tight tolerance (the
default tolerances of :func:`workbench.simulate.open_loop` give about 1e-5); every
result reports the RMS difference to CVODES interval by interval
(``integration_error_``).

*Dry friction.* The Karnopp stick-slip form of a plant with ``friction="stick"`` is
not differentiable, so the estimation always uses the smooth form
(``plant.with_friction("smooth")``: Stribeck level times tanh(v / 1 mm/s)). That form
is stiff and kinked around v = 0 (the friction force turns over within 1 mm/s), which
costs the fixed-step scheme its order at every velocity reversal: with dry friction
the default step is 0.125 ms instead of 1 ms (at 0.25 ms the position error against
CVODES was still about 20 um on the reference rig, enough to bias estimates on a good
sensor). The before/after fits are simulated with the plant as given (a stick-slip
plant is checked in its stick-slip form).

*Optimiser.* IPOPT on the least-squares cost 0.5 sum(r^2) / n of residuals r
normalised by the measurement noise of each signal (estimated from the data unless
given), with the constrained Gauss-Newton Hessian J'J (J the residual Jacobian; the
curvature of the continuity constraints is left out, as in Bock's method). Parameters
are optimised as log(value / start) when their bounds are positive, else as
(value - start) / typical size; node states are scaled by their typical size. Default
bounds are a factor of 10 either side of the start value, within the plant file's
admissible range and rules. Kinks in the model (valve deadband, the valve edges
switching at the centre, flow reversal) make the gradient jump, so IPOPT's optimality
measure can stall while the estimates only jitter; the run then stops when the
parameters have moved by less than a tenth of their standard deviation for three
iterations (status ``Parameters_Converged``).

*Confidence.* The covariance of the estimates is that of the linearised
equality-constrained least-squares problem at the solution: the parameter rows of
the inverse KKT matrix [[J'J, G'], [G, 0]] (G the continuity Jacobian) take the node
states into account as nuisance variables, and the residual variance of each signal
is re-estimated from the residuals (a sandwich estimate, so the intervals stay honest
when the assumed noise level was off). 95 % intervals are value +- 1.96 std (delta
method from the optimised scale). A parameter whose standard deviation exceeds half
its size is reported as not identifiable. Over 16 noisy 1.5 s recordings of the
reference rig the spread of (estimate - truth) / std was 0.8 to 1.04 for the four
parameters of the benchmark.

*Honest check and verdict.* The fits before and after (NRMSE %,
:func:`workbench.recording.fit`) come from fresh CVODES simulations
(:class:`workbench.simulate.Simulator`, the integrator of
:func:`workbench.simulate.open_loop`; closed loop on the recorded ``r`` with the
plant's controller when both exist) of the nominal and of the estimated plant,
started from the recording's first sample and from the estimated initial state. The
result is a ``poor_fit`` when the estimated model cannot follow a recording: a fit
below ``fit_threshold`` (90 %) both in that replay and along the model's own
trajectory in the fit, or residuals that are strongly correlated and more than three
times the noise. An open-loop replay that drifts while the model's own trajectory
follows the data is reported in the message, not counted as a poor fit.

Examples
--------
A recording simulated by the workbench with a heavier payload, fitted from the plant
file's values (run from the repository root):

>>> from workbench import Plant
>>> from workbench.identify.grey_box import estimate, synthetic_recording
>>> plant = Plant.from_toml("designs/plants/rig25_mpye.toml")              # doctest: +SKIP
>>> rig = plant.with_params(**{"load.mass": 1.5})                           # doctest: +SKIP
>>> rec = synthetic_recording(rig, 2.0, noise={"x": 1e-5, "p_a": 200.0,     # doctest: +SKIP
...                                            "p_b": 200.0})
>>> res = estimate(plant, [rec], ["load.mass", "load.viscous_friction"])   # doctest: +SKIP
>>> round(res.value("load.mass"), 3), res.poor_fit                          # doctest: +SKIP
(1.5, False)
>>> print(res.table())                                                      # doctest: +SKIP

From the command line: ``workbench identify greybox PLANT.toml RUN1.csv RUN2.csv
--params load.mass load.viscous_friction --out DIR``.
"""

from __future__ import annotations

import difflib
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import casadi as ca
import numpy as np

from ..integrate import RADAU_IIA, radau_sensitivity, radau_stages
from ..integrate import jit as _jit
from ..errors import InputError, WorkbenchError
from ..params import EFFECTS, SCHEMA
from ..plant import Plant
from ..recording import Recording, fit as nrmse_fit, load_recording
from ..signals import autocorrelation, derivative, fraction_outside, noise_floor, odd_window

__all__ = ["estimate", "GreyBoxResult", "SIGNALS", "RADAU_TABLES", "noise_std",
           "synthetic_recording"]

#: Recorded signals the estimator can compare with the model (plant output names).
SIGNALS: tuple[str, ...] = ("x", "p_a", "p_b", "v", "p_s")

#: Radau IIA Butcher tables (A, c), by number of stages (from
#: :data:`workbench.integrate.RADAU_IIA`).
RADAU_TABLES: dict[int, tuple[np.ndarray, np.ndarray]] = {
    s: (tab.A, np.array(tab.c, dtype=float)) for s, tab in RADAU_IIA.items()}

#: Above this size of the stage equations (stages x states) the step is built from
#: matrix expressions with a sparse LU instead of compiled scalar code (line segments).
LARGE_SYSTEM = 24

#: Largest integration step (s) by default, without and with dry friction.
MAX_STEP = 1e-3
MAX_STEP_FRICTION = 1.25e-4

#: Typical size of parameters whose start value may be zero (SI), used for scaling
#: and for default bounds of parameters that may be zero or negative.
_TYPICAL: dict[str, float] = {
    "load.viscous_friction": 10.0,
    "load.external_force": 10.0,
    "valve.null_offset": 0.1,
    "valve.command_center": 0.5,
    "valve.deadband": 0.02,
    "friction.coulomb": 5.0,
    "friction.static": 5.0,
    "friction.stribeck_velocity": 0.01,
    "leakage.conductance_to_atmosphere": 1e-10,
    "leakage.cross_piston": 1e-9,
    "gas.heat_transfer_coefficient": 0.1,
    "cylinder.rod_diameter": 0.005,
}

_Z95 = 1.959963984540054
_UNITS = {k.path: k.unit for k in SCHEMA}
_KEYS = {k.path: k for k in SCHEMA}
_SIGNAL_UNITS = {"x": "m", "v": "m/s", "p_a": "Pa", "p_b": "Pa", "p_s": "Pa"}


# ====================================================================== result
@dataclass(frozen=True, eq=False)
class GreyBoxResult:
    """Estimated parameters with their confidence, and the fit before and after.

    Learned values end in ``_``. Arrays are in the order of :attr:`names`, SI units.

    Attributes
    ----------
    names : tuple of str
        Dotted parameter names.
    units : tuple of str
    nominal : (n,) start values (the plant's).
    bounds : (n, 2) lower and upper bounds used.
    values_ : (n,) estimates.
    std_ : (n,) standard deviations (inf when not identifiable).
    ci95_ : (n, 2) 95 % confidence intervals.
    correlation_ : (n, n) correlation matrix of the estimates.
    identifiable_ : (n,) bool, std below half the parameter's size.
    at_bound_ : (n,) bool, the estimate sits on a bound (its interval is then not
        meaningful).
    fit_before, fit_after : tuple of dict
        Per recording, NRMSE fit (%) of each compared signal: nominal plant and
        estimated plant, from fresh CVODES simulations (closed loop on the recorded
        ``r`` with the plant's controller when both exist, else open loop on ``u``;
        ``method["replay"]``), from the recording's first sample and from the
        estimated initial state respectively.
    fit_ms_ : tuple of dict
        Per recording, fit (%) of the estimated model's own trajectory in the fit (the
        multiple-shooting solution: continuous, from the estimated initial state,
        fixed-step integration). An open-loop replay of a position drive integrates
        every small difference, so on closed-loop data ``fit_after`` can drift while
        this stays at the noise level.
    x0_ : tuple of (nx,) arrays, the estimated initial state of each recording.
    noise : tuple of dict, per recording the noise standard deviation (SI) assumed
        for each signal (estimated from the data unless given).
    residual_rms_ : tuple of dict, per recording the RMS of the residuals (SI) of the
        estimated model (discrete model, multiple-shooting solution).
    whiteness_ : tuple of dict, per recording the fraction of residual
        autocorrelation lags (1..25) outside the 99 % band (about 0.01 when white).
    integration_error_ : tuple of dict, per recording the RMS difference (SI) between
        the fixed-step model used in the fit and CVODES (same parameters), each shooting
        interval integrated by CVODES from its node.
    residuals_ : tuple of dict, per recording and signal the residual (SI) measured
        minus estimated model (the multiple-shooting solution, a continuous model
        trajectory from the estimated initial state), one value per sample.
    cost : float, final cost 0.5 sum(r^2) / n (about 0.5 when the residuals are at
        the noise level).
    iterations : int. success : bool.
    status : str, IPOPT's return status, or ``Parameters_Converged`` when the run was
        stopped (or accepted after IPOPT gave up) because the parameters no longer moved
        beyond a fraction of their standard deviation (see the module notes on kinks).
    wall_time : float, s.
    poor_fit : bool. message : str, the verdict in words.
    plant_ : Plant, the plant with the estimated values (friction form as given; with
        line dynamics, ``lines.segments`` is fixed to the number used in the fit).
    method : dict, settings used (scheme, substeps, shooting interval, ...).
    trajectories_before, trajectories_after : tuple of Trajectory (CVODES replays).
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    nominal: np.ndarray
    bounds: np.ndarray
    values_: np.ndarray
    std_: np.ndarray
    ci95_: np.ndarray
    correlation_: np.ndarray
    identifiable_: np.ndarray
    at_bound_: np.ndarray
    fit_before: tuple[dict[str, float], ...]
    fit_after: tuple[dict[str, float], ...]
    fit_ms_: tuple[dict[str, float], ...]
    x0_: tuple[np.ndarray, ...]
    noise: tuple[dict[str, float], ...]
    residual_rms_: tuple[dict[str, float], ...]
    whiteness_: tuple[dict[str, float], ...]
    integration_error_: tuple[dict[str, float], ...]
    residuals_: tuple[dict[str, np.ndarray], ...]
    cost: float
    iterations: int
    status: str
    success: bool
    wall_time: float
    poor_fit: bool
    message: str
    plant_: Plant = field(repr=False, compare=False)
    method: Mapping[str, Any] = field(default_factory=dict)
    sources: tuple[str, ...] = ()
    trajectories_before: tuple = field(default=(), repr=False, compare=False)
    trajectories_after: tuple = field(default=(), repr=False, compare=False)

    def value(self, name: str) -> float:
        """Estimate of one parameter by name (SI)."""
        return float(self.values_[self._index(name)])

    def _index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"'{name}' was not estimated; estimated: "
                           f"{', '.join(self.names)}") from None

    @property
    def estimates(self) -> dict[str, float]:
        """Estimates by name (SI)."""
        return {n: float(v) for n, v in zip(self.names, self.values_)}

    def within_ci(self, truth: Mapping[str, float] | Sequence[float]) -> np.ndarray:
        """Whether each true value lies in its 95 % interval."""
        if isinstance(truth, Mapping):
            tv = np.array([float(truth[n]) for n in self.names])
        else:
            tv = np.asarray(truth, dtype=float)
        return (tv >= self.ci95_[:, 0]) & (tv <= self.ci95_[:, 1])

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary (SI; inf and nan as None)."""
        def num(v):
            v = float(v)
            return v if math.isfinite(v) else None

        def fits(seq):
            return [{k: num(v) for k, v in d.items()} for d in seq]

        params = {}
        for i, n in enumerate(self.names):
            params[n] = {
                "value": num(self.values_[i]), "std": num(self.std_[i]),
                "ci95": [num(self.ci95_[i, 0]), num(self.ci95_[i, 1])],
                "nominal": num(self.nominal[i]),
                "bounds": [num(self.bounds[i, 0]), num(self.bounds[i, 1])],
                "unit": self.units[i], "identifiable": bool(self.identifiable_[i]),
                "at_bound": bool(self.at_bound_[i]),
            }
        return {
            "parameters": params,
            "correlation": [[num(c) for c in row] for row in self.correlation_],
            "recordings": list(self.sources),
            "fit_before": fits(self.fit_before),
            "fit_after": fits(self.fit_after),
            "fit_ms": fits(self.fit_ms_),
            "noise": fits(self.noise),
            "residual_rms": fits(self.residual_rms_),
            "residual_whiteness": fits(self.whiteness_),
            "integration_error": fits(self.integration_error_),
            "x0": [dict(zip(self.plant_.state_names, map(num, x))) for x in self.x0_],
            "cost": num(self.cost), "iterations": int(self.iterations),
            "status": self.status, "success": bool(self.success),
            "wall_time_s": num(self.wall_time),
            "poor_fit": bool(self.poor_fit), "message": self.message,
            "method": dict(self.method),
        }

    def table(self) -> str:
        """The estimates as a text table, with fits and the verdict."""
        rows = [("parameter", "nominal", "estimate", "std", "95 % interval", "unit", "")]
        for i, n in enumerate(self.names):
            flag = []
            if not self.identifiable_[i]:
                flag.append("not identifiable")
            if self.at_bound_[i]:
                flag.append("at bound")
            rows.append((n, f"{self.nominal[i]:.5g}", f"{self.values_[i]:.6g}",
                         f"{self.std_[i]:.2g}",
                         f"[{self.ci95_[i, 0]:.5g}, {self.ci95_[i, 1]:.5g}]",
                         self.units[i], ", ".join(flag)))
        widths = [max(len(r[c]) for r in rows) for c in range(len(rows[0]))]
        lines = ["  ".join(r[c].ljust(widths[c]) for c in range(len(r))).rstrip() for r in rows]
        lines.insert(1, "-" * len(lines[0]))
        for k, (fb, fa) in enumerate(zip(self.fit_before, self.fit_after)):
            src = self.sources[k] if k < len(self.sources) else f"recording {k + 1}"
            sig = ", ".join(f"{s} {fb.get(s, float('nan')):.1f} -> {fa.get(s, float('nan')):.1f} %"
                            for s in fa)
            lines.append(f"fit {src}: {sig}")
        lines.append(f"IPOPT: {self.status}, {self.iterations} iterations, cost {self.cost:.4g}, "
                     f"{self.wall_time:.1f} s")
        lines.append(("POOR FIT: " if self.poor_fit else "") + self.message)
        return "\n".join(lines)


# ====================================================================== parameters
@dataclass(frozen=True)
class _Param:
    name: str
    index: int          # in plant.p0
    start: float        # SI
    lo: float
    hi: float
    log: bool           # z = log(p / start), else z = (p - start) / scale
    scale: float
    unit: str

    def value(self, z: float) -> float:
        return self.start * math.exp(z) if self.log else self.start + self.scale * z

    def dvalue(self, z: float) -> float:
        return self.value(z) if self.log else self.scale

    def z_of(self, value: float) -> float:
        return math.log(value / self.start) if self.log else (value - self.start) / self.scale

    @property
    def z_bounds(self) -> tuple[float, float]:
        return self.z_of(self.lo), self.z_of(self.hi)


def _base_name(name: str) -> str:
    return name.split("[", 1)[0]


def _resolve_parameters(plant: Plant, parameters: Sequence[str],
                        bounds: Mapping[str, tuple[float, float]] | None) -> list[_Param]:
    if isinstance(parameters, str):
        parameters = [parameters]
    parameters = list(parameters)
    if not parameters:
        raise InputError("no parameters to estimate: give at least one dotted name, e.g. "
                         "load.mass")
    seen = set()
    out: list[_Param] = []
    for name in parameters:
        if not isinstance(name, str):
            raise InputError(f"parameter names are strings like 'load.mass', got {name!r}")
        if name in seen:
            raise InputError(f"parameter '{name}' is listed twice")
        seen.add(name)
        if name not in plant.param_names:
            raise InputError(_unknown_parameter_message(plant, name),
                             location=f"parameter '{name}'")
        out.append(_make_param(plant, name, (bounds or {}).get(name), parameters))
    for name in (bounds or {}):
        if name not in seen:
            raise InputError(f"bounds given for '{name}', which is not among the parameters to "
                             f"estimate ({', '.join(parameters)})", location=f"bounds '{name}'")
    return out


def _unknown_parameter_message(plant: Plant, name: str) -> str:
    base = _base_name(name)
    key = _KEYS.get(base)
    if key is not None and key.effect and not plant.params.has_effect(key.effect):
        keys = ", ".join(k.path for k in EFFECTS[key.effect])
        return (f"'{name}' belongs to the effect '{key.effect}', which this plant does not "
                f"have; switch it on first (plant file keys {keys}, or "
                f"plant.with_params(**{{...}}) with start values)")
    if key is not None and not key.physical:
        return (f"'{name}' is not a physical parameter (it does not enter the dynamics) and "
                "cannot be estimated")
    if key is not None and key.law is not None and key.law != plant.valve_law:
        return (f"'{name}' belongs to the valve law '{key.law}', but this plant uses "
                f"'{plant.valve_law}'")
    if key is not None and key.kind == "floats":
        entries = ", ".join(n for n in plant.param_names if n.startswith(base + "["))
        return (f"'{name}' is an array; estimate its entries by index, e.g. '{base}[0]' "
                f"(this plant has {entries})")
    hint = difflib.get_close_matches(name, list(plant.param_names) + list(_KEYS), 3, 0.6)
    msg = f"unknown parameter '{name}'"
    if hint:
        msg += f" (did you mean {' or '.join(repr(h) for h in hint)}?)"
    return msg + f"; parameters of this plant: {', '.join(plant.param_names)}"


def _rule_bounds(plant: Plant, name: str, estimated: Sequence[str]) -> tuple[float, float]:
    """Bounds from the plant file's consistency rules (params.py) that involve other keys."""
    prm = plant.params
    lo, hi = -math.inf, math.inf
    if name == "valve.command_center":
        lo, hi = prm["valve.command_min"], prm["valve.command_max"]
    elif name == "supply.pressure":
        lo = 1.01 * prm["gas.atmospheric_pressure"]
    elif name == "gas.atmospheric_pressure":
        hi = prm["supply.pressure"] / 1.01
    elif name == "cylinder.rod_diameter":
        hi = 0.99 * prm["cylinder.bore"]
    elif name == "friction.coulomb" and "friction.static" not in estimated:
        hi = prm["friction.static"]
    elif name == "friction.static" and "friction.coulomb" not in estimated:
        lo = prm["friction.coulomb"]
    return float(lo), float(hi)


def _make_param(plant: Plant, name: str, user: tuple[float, float] | None,
                estimated: Sequence[str] = ()) -> _Param:
    idx = plant.param_index(name)
    start = float(plant.p0[idx])
    base = _base_name(name)
    key = _KEYS.get(base)
    unit = _UNITS.get(base, "")
    typical = _TYPICAL.get(name, abs(start) if start != 0.0 else 1.0)
    s_lo = -math.inf if key is None or key.low is None else float(key.low)
    s_hi = math.inf if key is None or key.high is None else float(key.high)
    if key is not None and key.low_open:
        s_lo = s_lo + 1e-12 * max(abs(s_lo), typical)
    if key is not None and key.high_open:
        s_hi = s_hi - 1e-9 * max(abs(s_hi), 1.0)
    r_lo, r_hi = _rule_bounds(plant, name, estimated)
    s_lo, s_hi = max(s_lo, r_lo), min(s_hi, r_hi)
    if user is not None:
        try:
            lo, hi = (float(user[0]), float(user[1]))
        except (TypeError, ValueError, IndexError):
            raise InputError(f"bounds of '{name}' must be a pair (low, high) in "
                             f"{unit or 'SI units'}, got {user!r}",
                             location=f"bounds '{name}'") from None
        if not (lo < hi) or math.isnan(lo) or math.isnan(hi):
            raise InputError(f"bounds of '{name}' must have low < high, got [{lo:g}, {hi:g}]",
                             location=f"bounds '{name}'")
        if lo < s_lo or hi > s_hi:
            raise InputError(f"bounds [{lo:g}, {hi:g}] of '{name}' leave its admissible range "
                             f"[{s_lo:g}, {s_hi:g}] ({key.expected() if key else 'finite'}, "
                             "and the plant file's rules)", location=f"bounds '{name}'")
    else:
        if start > 0 and s_lo >= 0:
            lo, hi = start / 10.0, start * 10.0
        else:
            span = 10.0 * (_TYPICAL[name] if name in _TYPICAL else max(abs(start), 1e-12))
            lo, hi = start - span, start + span
        lo, hi = max(lo, s_lo), min(hi, s_hi)
        if s_lo >= 0 and start == 0.0:
            lo = s_lo
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise InputError(f"'{name}' needs finite bounds, got [{lo:g}, {hi:g}]",
                         location=f"bounds '{name}'")
    start = min(max(start, lo), hi)
    if lo > 0:
        return _Param(name, idx, start, lo, hi, True, 1.0, unit)
    scale = max(abs(start), typical, (hi - lo) / 100.0)
    return _Param(name, idx, start, lo, hi, False, scale, unit)


# ====================================================================== data
@dataclass
class _Data:
    rec: Recording
    source: str
    t: np.ndarray
    u: np.ndarray
    signals: tuple[str, ...]
    y: dict[str, np.ndarray]
    noise: dict[str, float]
    n_int: int = 0
    first: int = 0


def _as_recording(item: Any, k: int) -> Recording:
    if isinstance(item, Recording):
        return item
    if isinstance(item, (str, os.PathLike)):
        return load_recording(item)
    raise InputError(f"recording {k + 1}: expected a Recording or a file path, got "
                     f"{type(item).__name__}")


#: Measurement noise standard deviation of a sampled signal, model-free: the one
#: estimator of the workbench (:func:`workbench.signals.noise_floor`), also used by
#: the diagnosis, so a recording gets the same noise numbers in both.
noise_std = noise_floor


def _prepare(plant: Plant, recordings: Sequence[Any], signals: Sequence[str],
             noise: Mapping[str, float] | None) -> list[_Data]:
    if isinstance(recordings, (Recording, str, os.PathLike)):
        recordings = [recordings]
    recs = [_as_recording(r, k) for k, r in enumerate(recordings)]
    if not recs:
        raise InputError("no recording given")
    if isinstance(signals, str):
        signals = [signals]
    signals = tuple(signals)
    if not signals:
        raise InputError("no signals to compare: give some of " + ", ".join(SIGNALS))
    for s in signals:
        if s not in SIGNALS:
            hint = difflib.get_close_matches(s, SIGNALS, 1)
            raise InputError(f"cannot compare signal '{s}'"
                             + (f" (did you mean '{hint[0]}'?)" if hint else "")
                             + f"; signals: {', '.join(SIGNALS)}")
    for s in noise or {}:
        if s not in signals:
            raise InputError(f"noise level given for '{s}', which is not compared "
                             f"({', '.join(signals)})")
        if not (float(noise[s]) > 0):
            raise InputError(f"noise level of '{s}' must be > 0 (SI), got {noise[s]!r}")
    out = []
    for k, rec in enumerate(recs):
        src = rec.source
        if "u" not in rec:
            raise InputError("the recording has no command column 'u'; the grey-box fit "
                             "replays the recorded command", source=src)
        have = tuple(s for s in signals if s in rec)
        if not have:
            raise InputError(f"the recording has none of the signals to compare "
                             f"({', '.join(signals)}); its columns: {', '.join(rec.columns)}",
                             source=src)
        n = len(rec)
        if n < 20:
            raise InputError(f"the recording has {n} samples; the grey-box fit needs at least "
                             "20 (and many more to say anything about the parameters)", source=src)
        t = np.asarray(rec.t, dtype=float)
        dt = np.diff(t)
        if np.max(dt) > 20.0 * np.median(dt):
            i = int(np.argmax(dt))
            raise InputError(f"a gap of {dt[i]:g} s in time at sample {i} (median step "
                             f"{np.median(dt):g} s): split the recording there", source=src)
        y = {s: np.asarray(rec[s], dtype=float) for s in have}
        nz = {}
        for s in have:
            if noise and s in noise:
                nz[s] = float(noise[s])
            else:
                spread = float(np.std(y[s]))
                floor = max(1e-4 * spread, 1e-6 * _typical_signal(plant, s))
                nz[s] = max(noise_std(y[s]), floor)
        out.append(_Data(rec, src, t, np.asarray(rec["u"], dtype=float), have, y, nz))
    return out


def _typical_signal(plant: Plant, s: str) -> float:
    return plant.signal(s).scale


def _state_bounds(plant: Plant) -> tuple[np.ndarray, np.ndarray]:
    prm = plant.params
    p_hi = 3.0 * max(prm["supply.pressure"], prm["gas.atmospheric_pressure"])
    p_lo = 0.05 * prm["gas.atmospheric_pressure"]
    bounds = {"position": (-0.05 * plant.stroke, 1.05 * plant.stroke),
              "velocity": (-50.0, 50.0), "pressure": (p_lo, p_hi),
              "temperature": (100.0, 1000.0)}
    lo, hi = zip(*(bounds.get(s.kind, (-math.inf, math.inf)) for s in plant.states))
    return np.array(lo), np.array(hi)


# ====================================================================== integrator
def _step_functions(model: Plant, nsel: int, out_idx: Sequence[int], stages: int,
                    newton: int, flags: Sequence[str] | None = ("-O1",)
                    ) -> tuple[ca.Function, ca.Function]:
    """One step of the fixed-step Radau IIA scheme: primal and with sensitivities.

    gb_step(X, u, h, p) -> (X+, y):  y = measured outputs at X (before the step).
    gb_step_sens(X, S, u, h, p, E) -> (X+, S+, y, dy): S = d X / d[X_node, theta] with
    theta = E' p (E selects the estimated parameters), dy = d y / d[X_node, theta].
    """
    tableau = RADAU_IIA[stages]
    nx, npf = len(model.states), len(model.p0)
    nc = nx + nsel
    xs, us, ps = model.x_sym, model.u_sym, model.p_sym
    fx = ca.Function("gb_f", [xs, us, ps], [model.xdot_expr])
    fjac = ca.Function("gb_fj", [xs, us, ps], [ca.jacobian(model.xdot_expr, xs),
                                               ca.jacobian(model.xdot_expr, ps)])
    y_expr = model.y_expr[list(out_idx)]
    hjac = ca.Function("gb_h", [xs, us, ps], [y_expr, ca.jacobian(y_expr, xs),
                                              ca.jacobian(y_expr, ps)])

    # Small plants: scalar expressions (SX) with a symbolic QR, compiled to C. Plants
    # with many states (line segments) would give huge code: matrix expressions (MX)
    # with a sparse LU at run time, evaluated by CasADi's virtual machine.
    large = stages * nx > LARGE_SYSTEM
    T = ca.MX if large else ca.SX
    X = T.sym("X", nx)
    S = T.sym("S", nx, nc)
    u = T.sym("u")
    h = T.sym("h")
    p = T.sym("p", npf)
    E = T.sym("E", npf, nsel)
    y, hy_x, hy_p = hjac(X, u, p)
    dy = ca.mtimes(hy_x, S) + ca.horzcat(T.zeros(len(out_idx), nx), ca.mtimes(hy_p, E))
    # the Radau IIA step of workbench.integrate: stages by Newton, sensitivities by the
    # implicit function theorem on the stage equations
    Z = radau_stages(tableau, fx, fjac, X, u, h, p, newton, large)
    last = slice((stages - 1) * nx, stages * nx)
    primal = ca.Function("gb_step", [X, u, h, p], [X + Z[last], y], ["X", "u", "h", "p"],
                         ["Xn", "y"])
    Xk, Sk = radau_sensitivity(tableau, fjac, X, Z, S, u, h, p, E, large)
    sens = ca.Function("gb_step_sens", [X, S, u, h, p, E], [Xk, Sk, y, dy],
                       ["X", "S", "u", "h", "p", "E"], ["Xn", "Sn", "y", "dy"])
    if flags is None or large:        # CasADi's virtual machine, no compiler
        return primal, sens
    # compiled once, cached by the hash of the generated source (_jit changes the
    # working directory while generating, so never two at a time)
    return _jit.compiled(primal, tuple(flags)), _jit.compiled(sens, tuple(flags))


def _interval_functions(step: ca.Function, step_sens: ca.Function, nx: int, nsel: int,
                        ny: int, npf: int, M: int, substeps: int, n_int: int):
    """All intervals at once: primal (S, U, H, p) -> (X_end, Y) and with sensitivities
    (S, U, H, p, E) -> (X_end, S_end, Y, dY); also one interval's primal function.

    Each sample is ``substeps`` steps of h / substeps with the command held; outputs are
    taken at the samples."""
    nc = nx + nsel
    L = M * substeps
    Xm = ca.MX.sym("X", nx)
    U = ca.MX.sym("U", 1, M)
    H = ca.MX.sym("H", 1, M)
    P = ca.MX.sym("P", npf)
    E = ca.MX.sym("E", npf, nsel)
    Us = ca.reshape(ca.repmat(U, substeps, 1), 1, L)
    Hs = ca.reshape(ca.repmat(H / substeps, substeps, 1), 1, L)
    at_samples = list(range(0, L, substeps))
    dcols = [k * nc + c for k in at_samples for c in range(nc)]
    acc = step.mapaccum("gb_acc", L, [0], [0])
    Xs, Y = acc(Xm, Us, Hs, ca.repmat(P, 1, L))
    one = ca.Function("gb_interval", [Xm, U, H, P], [Xs[:, -1], Y[:, at_samples]])
    acc_s = step_sens.mapaccum("gb_acc_sens", L, [0, 1], [0, 1])
    S0 = ca.DM(np.hstack([np.eye(nx), np.zeros((nx, nsel))]))
    Xs, Ss, Y, dY = acc_s(Xm, S0, Us, Hs, ca.repmat(P, 1, L), ca.repmat(E, 1, L))
    one_s = ca.Function("gb_interval_sens", [Xm, U, H, P, E],
                        [Xs[:, -1], Ss[:, (L - 1) * nc:], Y[:, at_samples], dY[:, dcols]])
    threads = max(1, min(os.cpu_count() or 1, 8))
    mode = "thread" if threads > 1 and n_int > 1 else "serial"
    all_p = one.map(n_int, mode, threads) if mode == "thread" else one.map(n_int)
    all_s = one_s.map(n_int, mode, threads) if mode == "thread" else one_s.map(n_int)
    Sm = ca.MX.sym("S", nx, n_int)
    Ua = ca.MX.sym("U", 1, M * n_int)
    Ha = ca.MX.sym("H", 1, M * n_int)
    Pa = ca.MX.sym("P", npf)
    Ea = ca.MX.sym("E", npf, nsel)
    prim = ca.Function("gb_all", [Sm, Ua, Ha, Pa], all_p(Sm, Ua, Ha, ca.repmat(Pa, 1, n_int)))
    sens = ca.Function("gb_all_sens", [Sm, Ua, Ha, Pa, Ea],
                       all_s(Sm, Ua, Ha, ca.repmat(Pa, 1, n_int), ca.repmat(Ea, 1, n_int)))
    return prim, sens, one


# ====================================================================== NLP
class _Pattern:
    """A fixed sparsity given in COO order, with the permutation to CasADi's CCS."""

    def __init__(self, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> None:
        rows = np.asarray(rows, dtype=np.int64)
        cols = np.asarray(cols, dtype=np.int64)
        order = np.lexsort((rows, cols))
        self.perm = order
        self.rows = rows[order]
        self.colind = np.searchsorted(cols[order], np.arange(shape[1] + 1)).astype(np.int64)
        self.shape = shape
        self.sparsity = ca.Sparsity(shape[0], shape[1], self.colind.tolist(), self.rows.tolist())

    def dm(self, values: np.ndarray) -> ca.DM:
        return ca.DM(self.sparsity, np.asarray(values, dtype=float)[self.perm])

    def scipy(self, values: np.ndarray):
        import scipy.sparse as sp
        return sp.csc_matrix((np.asarray(values, dtype=float)[self.perm], self.rows, self.colind),
                             shape=self.shape)


class _Callback(ca.Callback):
    """A CasADi function evaluated by Python (IPOPT callbacks)."""

    def __init__(self, name: str, sp_in: list, sp_out: list, fun: Callable,
                 jac: tuple | None = None) -> None:
        ca.Callback.__init__(self)
        self._in, self._out, self._fun, self._jac = sp_in, sp_out, fun, jac
        self._keep: list = []
        self.construct(name, {})

    def get_n_in(self):
        return len(self._in)

    def get_n_out(self):
        return len(self._out)

    def get_sparsity_in(self, i):
        return self._in[i]

    def get_sparsity_out(self, i):
        return self._out[i]

    def eval(self, arg):
        return self._fun(arg)

    def has_jacobian(self):
        return self._jac is not None

    def get_jacobian(self, name, inames, onames, opts):
        sp_in, sp_out, fun = self._jac
        cb = _Callback(name, sp_in, sp_out, fun)
        self._keep.append(cb)
        return cb


class _IterationCallback(ca.Callback):
    """IPOPT's iteration callback: progress, and a stop when the parameters stand still.

    Kinks in the model (valve deadband, the valve edges switching at the centre, flow
    reversal, clipping) make the gradient jump, so near the solution IPOPT's optimality
    measure can stall above its tolerance while the estimates only jitter. Such a run is
    stopped when, for ``patience`` iterations in a row, every scaled parameter moved by
    less than ``fraction`` of a lower bound of its standard deviation (from the
    parameter block of the Gauss-Newton Hessian, which ignores the correlation with the
    node states and so underestimates it) and the continuity constraints hold to ``gtol``.
    """

    def __init__(self, prob: "_Problem", fraction: float, gtol: float, patience: int,
                 tick: Callable[[float], None] | None) -> None:
        ca.Callback.__init__(self)
        self.prob = prob
        self.nw, self.ng, self.nsel = prob.nw, prob.ng, prob.nsel
        self.fraction, self.gtol, self.patience, self.tick = fraction, gtol, patience, tick
        self.history: list[np.ndarray] = []
        self.gmax: list[float] = []
        self.still = 0
        self.stopped = False
        self.construct("gb_iteration", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        name = ca.nlpsol_out(i)
        if name in ("x", "lam_x"):
            return ca.Sparsity.dense(self.nw)
        if name in ("g", "lam_g"):
            return ca.Sparsity.dense(self.ng)
        if name == "f":
            return ca.Sparsity.dense(1)
        return ca.Sparsity(0, 1)

    def eval(self, arg):
        x = np.asarray(arg[0], dtype=float).ravel()
        f = float(arg[1])
        g = np.asarray(arg[2], dtype=float).ravel()
        if self.tick is not None:
            self.tick(f)
        z = x[:self.nsel].copy()
        gm = float(np.max(np.abs(g), initial=0.0))
        sigma = self.prob.sigma_lower(f)
        if self.history and sigma is not None and gm < self.gtol \
                and np.all(np.abs(z - self.history[-1]) < self.fraction * sigma):
            self.still += 1
        else:
            self.still = 0
        self.history.append(z)
        self.gmax.append(gm)
        if self.still >= self.patience:
            self.stopped = True
            return [1]
        return [0]


class _Problem:
    """The multiple-shooting least-squares problem and its derivatives (numpy)."""

    def __init__(self, model: Plant, params: list[_Param], data: list[_Data],
                 sig_names: tuple[str, ...], M: int, stages: int, substeps: int, newton: int,
                 weights: Mapping[str, float], flags: Sequence[str] | None = ("-O1",)) -> None:
        self.model, self.params, self.data, self.M = model, params, data, M
        self.sig = sig_names
        self.nx = nx = len(model.states)
        self.nsel = nsel = len(params)
        self.nc = nx + nsel
        self.ny = ny = len(sig_names)
        self.npf = len(model.p0)
        self.sc = model.state_scales()
        out_idx = [model.output_index(s) for s in sig_names]
        first = 0
        for d in data:
            d.n_int = int(math.ceil(len(d.t) / M))
            d.first = first
            first += d.n_int
        self.n_int = n_int = first
        self.ntot = ntot = M * n_int
        # command, steps, measurements and weights on the padded grid
        U = np.zeros(ntot)
        Hs = np.zeros(ntot)
        Ym = np.zeros((ny, ntot))
        W = np.zeros((ny, ntot))
        self.rec_of_int = np.zeros(n_int, dtype=np.int64)
        for k, d in enumerate(data):
            a = d.first * M
            n = len(d.t)
            U[a:a + n] = d.u
            U[a + n:a + d.n_int * M] = d.u[-1]
            Hs[a:a + n - 1] = np.diff(d.t)
            for i, s in enumerate(sig_names):
                if s in d.y:
                    Ym[i, a:a + n] = d.y[s]
                    W[i, a:a + n] = float(weights.get(s, 1.0)) / d.noise[s]
            self.rec_of_int[d.first:d.first + d.n_int] = k
        self.U, self.H, self.Ym, self.W = U, Hs, Ym, W
        self.n_res = int(np.count_nonzero(W))
        self.E = np.zeros((self.npf, nsel))
        for j, prm in enumerate(params):
            self.E[prm.index, j] = 1.0
        # continuity pairs (j -> j + 1 inside one recording)
        self.pairs = np.array([j for j in range(n_int - 1)
                               if self.rec_of_int[j] == self.rec_of_int[j + 1]], dtype=np.int64)
        self.ng = nx * len(self.pairs)
        self.nw = nsel + nx * n_int
        step, step_sens = _step_functions(model, nsel, out_idx, stages, newton, flags)
        self.f_prim, self.f_sens, self._one = _interval_functions(
            step, step_sens, nx, nsel, ny, self.npf, M, substeps, n_int)
        self._build_patterns()
        self._cache_p: tuple[bytes, Any] | None = None
        self._cache_s: tuple[bytes, Any] | None = None
        self._Hzz: np.ndarray | None = None
        self.n_eval = 0
        self.n_sens = 0
        self.on_iteration: Callable[[float], None] | None = None

    # ------------------------------------------------------------ layout helpers
    def node_slice(self, j: int) -> slice:
        a = self.nsel + j * self.nx
        return slice(a, a + self.nx)

    def split(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        z = w[:self.nsel]
        s = w[self.nsel:].reshape(self.n_int, self.nx)      # scaled nodes, row per node
        p = self.model.p0.copy()
        for prm, zi in zip(self.params, z):
            p[prm.index] = prm.value(float(zi))
        return z, s, p

    def _build_patterns(self) -> None:
        nx, nsel, M, ny, n_int = self.nx, self.nsel, self.M, self.ny, self.n_int
        # constraint Jacobian: per pair q rows q*nx + a; cols z, s_j (nx), s_{j+1} (diag)
        q = np.arange(len(self.pairs))
        rows, cols = [], []
        a = np.arange(nx)
        R = (q[:, None] * nx + a[None, :])                        # (nq, nx)
        rows.append(np.repeat(R[:, :, None], nsel, axis=2).ravel())
        cols.append(np.broadcast_to(np.arange(nsel), (len(q), nx, nsel)).ravel())
        cj = nsel + self.pairs[:, None] * nx + a[None, :]          # (nq, nx) columns of s_j
        rows.append(np.repeat(R[:, :, None], nx, axis=2).ravel())
        cols.append(np.repeat(cj[:, None, :], nx, axis=1).ravel())
        rows.append(R.ravel())
        cols.append((cj + nx).ravel())
        self.jg = _Pattern(np.concatenate(rows), np.concatenate(cols), (self.ng, self.nw))
        # Hessian (upper triangle): z-z, z-s_j, s_j-s_j
        rows, cols = [], []
        iu, ju = np.triu_indices(nsel)
        rows.append(iu)
        cols.append(ju)
        jj = np.arange(n_int)
        base = nsel + jj[:, None] * nx                             # (n_int, 1)
        rows.append(np.broadcast_to(np.arange(nsel)[None, :, None], (n_int, nsel, nx)).ravel())
        cols.append(np.broadcast_to((base + a[None, :])[:, None, :], (n_int, nsel, nx)).ravel())
        iu2, ju2 = np.triu_indices(nx)
        rows.append((base + iu2[None, :]).ravel())
        cols.append((base + ju2[None, :]).ravel())
        self.hp = _Pattern(np.concatenate(rows), np.concatenate(cols), (self.nw, self.nw))
        self._iu, self._ju, self._iu2, self._ju2 = iu, ju, iu2, ju2
        # residual Jacobian (for the covariance): rows k*ny + i of interval j
        nrow = ny * M
        rj = np.arange(n_int)[:, None] * nrow + np.arange(nrow)[None, :]   # (n_int, nrow)
        rows = [np.broadcast_to(rj[:, :, None], (n_int, nrow, nsel)).ravel(),
                np.broadcast_to(rj[:, :, None], (n_int, nrow, nx)).ravel()]
        cols = [np.broadcast_to(np.arange(nsel), (n_int, nrow, nsel)).ravel(),
                np.broadcast_to((base + a[None, :])[:, None, :], (n_int, nrow, nx)).ravel()]
        self.jr = _Pattern(np.concatenate(rows), np.concatenate(cols), (self.ntot * ny, self.nw))

    # ------------------------------------------------------------ evaluation
    def primal(self, w: np.ndarray):
        key = w.tobytes()
        if self._cache_p is not None and self._cache_p[0] == key:
            return self._cache_p[1]
        if self._cache_s is not None and self._cache_s[0] == key:
            out = self._cache_s[1][:3]
            self._cache_p = (key, out)
            return out
        z, s, p = self.split(w)
        Xe, Y = self.f_prim((s * self.sc).T, self.U[None, :], self.H[None, :], p)
        self.n_eval += 1
        out = self._residuals(s, np.asarray(Xe), np.asarray(Y))
        self._cache_p = (key, out)
        return out

    def _residuals(self, s: np.ndarray, Xe: np.ndarray, Y: np.ndarray):
        r = self.W * (Y - self.Ym)                                 # (ny, ntot)
        g = (Xe[:, self.pairs].T / self.sc - s[self.pairs + 1]).ravel()
        return r, g, Y

    def full(self, w: np.ndarray):
        key = w.tobytes()
        if self._cache_s is not None and self._cache_s[0] == key:
            return self._cache_s[1]
        z, s, p = self.split(w)
        Xe, Se, Y, dY = self.f_sens((s * self.sc).T, self.U[None, :], self.H[None, :], p, self.E)
        self.n_sens += 1
        r, g, Yn = self._residuals(s, np.asarray(Xe), np.asarray(Y))
        nx, nc, M, ny, n_int = self.nx, self.nc, self.M, self.ny, self.n_int
        dpdz = np.array([prm.dvalue(float(zi)) for prm, zi in zip(self.params, z)])
        dY = np.asarray(dY).reshape(ny, self.ntot, nc)                # [i, k, c]
        dY = dY * self.W[:, :, None]
        dY = dY.transpose(1, 0, 2).reshape(n_int, M * ny, nc)      # [j, k*ny + i, c]
        As = dY[:, :, :nx] * self.sc[None, None, :]
        Bz = dY[:, :, nx:] * dpdz[None, None, :]
        Se = np.asarray(Se).reshape(nx, n_int, nc).transpose(1, 0, 2)   # [j, a, c]
        Phi = Se[:, :, :nx] * (self.sc[None, None, :] / self.sc[None, :, None])
        Gam = Se[:, :, nx:] * (dpdz[None, None, :] / self.sc[None, :, None])
        out = (r, g, Yn, As, Bz, Phi, Gam)
        self._cache_s = (key, out)
        return out

    # ------------------------------------------------------------ NLP pieces
    def f_g(self, w):
        r, g, _ = self.primal(w)
        return 0.5 * float(np.sum(r * r)) / self.n_res, g

    def grad_f(self, w):
        r, g, _, As, Bz, _, _ = self.full(w)
        R = r.T.reshape(self.n_int, self.M * self.ny)
        gz = np.einsum("jr,jri->i", R, Bz)
        gs = np.einsum("jr,jri->ji", R, As)
        f = 0.5 * float(np.sum(r * r)) / self.n_res
        return f, np.concatenate([gz, gs.ravel()]) / self.n_res

    def jac_g(self, w):
        r, g, _, _, _, Phi, Gam = self.full(w)
        P = Phi[self.pairs]
        G = Gam[self.pairs]
        vals = np.concatenate([G.ravel(), P.ravel(), -np.ones(self.ng)])
        return g, vals

    def sigma_lower(self, cost: float) -> np.ndarray | None:
        """Lower bounds of the standard deviations of the scaled parameters at the last
        Hessian evaluation (parameter block of J'J only), residuals at ``cost``."""
        if self._Hzz is None:
            return None
        d = np.diag(self._Hzz)
        with np.errstate(divide="ignore"):
            return np.sqrt(max(2.0 * cost, 1.0) / np.where(d > 0, d, np.nan))

    def hess(self, w, lam_f):
        _, _, _, As, Bz, _, _ = self.full(w)
        Hzz = np.einsum("jri,jrk->ik", Bz, Bz)
        self._Hzz = Hzz
        Hzs = np.einsum("jri,jrk->jik", Bz, As)
        Hss = np.einsum("jri,jrk->jik", As, As)
        vals = np.concatenate([Hzz[self._iu, self._ju], Hzs.ravel(),
                               Hss[:, self._iu2, self._ju2].ravel()])
        return vals * (lam_f / self.n_res)

    def residual_jacobian(self, w):
        """Residual Jacobian (scipy CSC, unscaled) and residual vector (row k*ny + i)."""
        r, _, _, As, Bz, _, _ = self.full(w)
        vals = np.concatenate([Bz.ravel(), As.ravel()])
        return self.jr.scipy(vals), r.T.ravel()

    def constraint_jacobian(self, w):
        g, vals = self.jac_g(w)
        return self.jg.scipy(vals)

    # ------------------------------------------------------------ IPOPT
    def solver(self, max_iter: int, tol: float, verbose: bool) -> ca.Function:
        d = ca.Sparsity.dense
        nw, ng = self.nw, self.ng
        P0 = ca.Sparsity(0, 1)
        self._callbacks = []

        def fg(arg):
            f, g = self.f_g(np.asarray(arg[0], dtype=float).ravel())
            return [f, g]

        def jac_fg(arg):
            w = np.asarray(arg[0], dtype=float).ravel()
            f, grad = self.grad_f(w)
            _, vals = self.jac_g(w)
            return [ca.DM(grad.reshape(1, -1)), self.jg.dm(vals)]

        def grad(arg):
            f, gr = self.grad_f(np.asarray(arg[0], dtype=float).ravel())
            return [f, gr]

        def jac(arg):
            g, vals = self.jac_g(np.asarray(arg[0], dtype=float).ravel())
            return [g, self.jg.dm(vals)]

        def hess(arg):
            w = np.asarray(arg[0], dtype=float).ravel()
            return [self.hp.dm(self.hess(w, float(arg[2])))]

        cb_fg = _Callback("gb_fg", [d(nw)], [d(1), d(ng)], fg,
                          jac=([d(nw), d(1), d(ng)], [d(1, nw), self.jg.sparsity], jac_fg))
        cb_grad = _Callback("gb_grad_f", [d(nw), P0], [d(1), d(nw)], grad)
        cb_jac = _Callback("gb_jac_g", [d(nw), P0], [d(ng), self.jg.sparsity], jac)
        cb_hess = _Callback("gb_hess_l", [d(nw), P0, d(1), d(ng)], [self.hp.sparsity], hess)
        self.iteration = _IterationCallback(self, 0.1, 1e-5, 3, self.on_iteration)
        self._callbacks = [cb_fg, cb_grad, cb_jac, cb_hess, self.iteration]
        wsym = ca.MX.sym("w", nw)
        fgx = cb_fg(wsym)
        opts = {
            "grad_f": cb_grad, "jac_g": cb_jac, "hess_lag": cb_hess,
            "iteration_callback": self.iteration,
            "print_time": False, "error_on_fail": False,
            "ipopt.print_level": 5 if verbose else 0, "ipopt.sb": "yes",
            "ipopt.max_iter": int(max_iter), "ipopt.tol": float(tol),
            "ipopt.acceptable_tol": 100.0 * float(tol), "ipopt.acceptable_iter": 2,
            "ipopt.acceptable_obj_change_tol": 1e-10,
            "ipopt.constr_viol_tol": 1e-9, "ipopt.nlp_scaling_method": "none",
            "ipopt.mu_strategy": "adaptive",
        }
        return ca.nlpsol("gb_solver", "ipopt", {"x": wsym, "f": fgx[0], "g": fgx[1]}, opts)

    # ------------------------------------------------------------ start values
    def simulate_nodes(self, x0s: list[np.ndarray], p: np.ndarray) -> np.ndarray:
        """Single shooting with the fixed-step scheme: states at every node, (n_int, nx)."""
        nodes = np.zeros((self.n_int, self.nx))
        M = self.M
        for d, x0 in zip(self.data, x0s):
            x = np.asarray(x0, dtype=float)
            for j in range(d.first, d.first + d.n_int):
                nodes[j] = x
                seg = slice(j * M, (j + 1) * M)
                xe, _ = self._one(x, self.U[None, seg], self.H[None, seg], p)
                x = np.asarray(xe).ravel()
                if not np.all(np.isfinite(x)):
                    x = nodes[j].copy()
        return nodes


# ====================================================================== helpers
def _smooth_derivative(t: np.ndarray, y: np.ndarray, window_s: float = 0.02) -> np.ndarray:
    """dy/dt (unit of y per s): Savitzky-Golay slope over about ``window_s`` (s).

    :func:`workbench.signals.derivative`, quadratic fits (the slope of a straight
    line fitted over the window inside; unbiased by curvature at the ends).
    """
    dt = float(np.median(np.diff(t)))
    n = len(y)
    window = min(odd_window(window_s, dt, 3), n if n % 2 else n - 1)
    if window < 3:
        return np.zeros(n)
    return derivative(y, dt, order=2, window=window)


def _first_value(t: np.ndarray, y: np.ndarray, n: int = 11) -> float:
    """Value at the first instant of a straight line fitted to the first ``n`` samples
    (less noisy than the first sample alone)."""
    n = min(n, len(y))
    tt = np.asarray(t[:n], dtype=float) - float(t[0])
    a, b = np.polyfit(tt, np.asarray(y[:n], dtype=float), 1)
    return float(b)


def _initial_state(plant: Plant, d: _Data) -> np.ndarray:
    """State at the first sample from the recording: measured states, v from x, the
    rest from the equilibrium at the first position (or resting values)."""
    names = plant.state_names
    x_first = float(np.clip(d.rec["x"][0], 0.0, plant.stroke))
    p_a = float(d.rec["p_a"][0]) if "p_a" in d.rec else None
    p_b = float(d.rec["p_b"][0]) if "p_b" in d.rec else None
    try:
        st = plant.initial_state(x_first, p_a=p_a, p_b=p_b, u0=float(d.u[0]))
    except WorkbenchError:
        st = plant.initial_state(x_first, p_a=p_a if p_a else 3e5, p_b=p_b if p_b else 3e5,
                                 u0=float(d.u[0]))
    v = _smooth_derivative(d.t, np.asarray(d.rec["x"], dtype=float))
    st[names.index("v")] = float(v[0]) if "v" not in d.rec else float(d.rec["v"][0])
    if "p_s" in names and "p_s" in d.rec:
        st[names.index("p_s")] = float(d.rec["p_s"][0])
    return st


def _replay(plant: Plant, t: np.ndarray, u: np.ndarray, x0: np.ndarray,
            params: np.ndarray | None = None, anchors: np.ndarray | None = None,
            every: int = 0):
    """Open-loop CVODES replay, u held on [t_k, t_k+1): :func:`simulate.open_loop`'s
    integrator, stepping once over each run of equal commands instead of each sample.

    With ``anchors`` (one state per ``every`` samples) the state is reset to
    ``anchors[j]`` at sample ``j * every``: CVODES over each shooting interval from its
    node, which checks the fixed-step integration without the drift of a long replay.
    """
    from .. import simulate
    sim = simulate.Simulator(plant, params=params)
    n = len(t)
    states = np.empty((n, len(x0)))
    states[0] = x0
    state = np.asarray(x0, dtype=float)
    dt = np.diff(t)
    k = 0
    while k < n - 1:
        if anchors is not None and k % every == 0:
            state = np.asarray(anchors[k // every], dtype=float)
            states[k] = state
        j = k + 1
        while (j < n - 1 and u[j] == u[k] and abs(dt[j] - dt[k]) <= 1e-9 * dt[k]
               and j - k < 64 and (anchors is None or j % every)):
            j += 1
        states[k + 1:j + 1] = sim.hold(state, float(u[k]), dt[k:j])
        state = states[j]
        k = j
    outs = sim.outputs(states, u)
    return simulate.Trajectory(time=np.asarray(t, dtype=float), states=states,
                               inputs=np.asarray(u, dtype=float).reshape(-1, 1), outputs=outs,
                               state_names=plant.state_names, output_names=plant.output_names,
                               info={"mode": "open_loop"})


def _closed_replay(plant: Plant, rec: Recording, x0: np.ndarray):
    """Closed-loop CVODES replay on the recorded reference r with the plant's controller
    (as ``workbench simulate`` does), from the state ``x0``."""
    from .. import controllers, simulate
    t = np.asarray(rec.t, dtype=float) - float(rec.t[0])
    ctrl = controllers.from_plant(plant)
    ref = simulate.Reference(times=t, values=np.asarray(rec["r"], dtype=float), hold=True)
    return simulate.closed_loop(plant, ctrl, ref, x0=np.asarray(x0, dtype=float),
                                output_times=t, progress=False)


def _use_closed_loop(replay: str, rec: Recording, plant: Plant) -> bool:
    if replay == "open":
        return False
    can = "r" in rec and plant.params.has_controller
    if replay == "closed" and not can:
        raise InputError("a closed-loop replay needs an 'r' column in the recording and a "
                         "[controller] in the plant file", source=rec.source)
    return can


def _whiteness(e: np.ndarray, lags: int = 25) -> float:
    """Fraction of autocorrelation lags 1..lags outside the 99 % band +-2.58/sqrt(N)."""
    n = len(e)
    r = autocorrelation(e, lags) if n >= 4 * lags else np.full(lags + 1, np.nan)
    if not np.isfinite(r[0]):
        return float("nan")
    return fraction_outside(r[1:], n, band=2.58 / math.sqrt(n))


def _fits(rec_y: Mapping[str, np.ndarray], run) -> dict[str, float]:
    out = {}
    for s, y in rec_y.items():
        try:
            out[s] = nrmse_fit(y, run[s])
        except InputError:
            out[s] = float("nan")
    return out


# ====================================================================== estimate
def estimate(plant: Plant, recordings: Sequence[Recording | str | os.PathLike],
             parameters: Sequence[str],
             bounds: Mapping[str, tuple[float, float]] | None = None,
             signals: Sequence[str] = ("x", "p_a", "p_b"),
             weights: Mapping[str, float] | None = None,
             method: str = "multiple_shooting",
             shooting_interval: float = 0.05,
             x0: str = "estimate",
             replay: str = "auto",
             noise: Mapping[str, float] | None = None,
             integrator: str = "radau2",
             substeps: int | None = None,
             newton_iterations: int = 3,
             compiler_flags: Sequence[str] | None = ("-O1",),
             max_iter: int = 50,
             tol: float = 1e-5,
             fit_threshold: float = 90.0,
             verbose: bool = False,
             progress: bool | None = False) -> GreyBoxResult:
    """Estimate physical parameters of ``plant`` from recordings (open-loop replay of u).

    Parameters
    ----------
    plant : Plant
        Model with the start values; every parameter to estimate must exist in it
        (switch an effect on, with start values, to estimate its parameters).
    recordings : sequence of Recording or paths
        One or more recordings (e.g. different excitations) of the same drive, each
        with ``t`` (s), ``u`` (V) and the signals to compare.
    parameters : sequence of str
        Dotted names from ``plant.param_names``, e.g. ``"load.mass"`` (kg),
        ``"valve.sonic_conductance"`` (m^3/(s Pa)), ``"friction.coulomb"`` (N).
    bounds : mapping name -> (low, high), SI, optional
        Default: a factor 10 either side of the start value for positive parameters,
        start +- 10 typical sizes otherwise, within the plant file's admissible range.
    signals : sequence of str
        Signals compared, those of ``("x", "p_a", "p_b", "v", "p_s")`` a recording has
        are used (default x, p_a, p_b).
    weights : mapping signal -> float, optional
        Extra relative weight of a signal (default 1); residuals are first divided by
        the signal's noise level.
    method : {"multiple_shooting", "single_shooting"}
        Single shooting is one interval per recording (for comparison; it fails on
        long open-loop replays that drift).
    shooting_interval : float
        Length of a shooting interval, s (rounded to whole samples; default 50 ms).
    x0 : {"estimate", "from_recording"}
        Initial state of each recording: estimated with the rest (default), or its
        measured components (x and the recorded pressures) fixed to their values at
        the first instant (a line fitted to the first 11 samples). Fixing noisy values
        biases an open-loop replay (a pressure error holds a force error, the position
        integrates it), so ``"estimate"`` is the better choice unless the initial state
        is known exactly.
    replay : {"auto", "open", "closed"}
        How the before/after fits are simulated: closed loop on the recording's ``r``
        with the plant's ``[controller]`` when both exist ("auto"), or always open loop
        on ``u``. The estimation itself always replays ``u``.
    noise : mapping signal -> float, optional
        Measurement noise standard deviation (SI) of each signal; default estimated
        from the data (:func:`noise_std`).
    integrator : {"radau2", "radau3", "radau1"}
        Fixed-step Radau IIA scheme: 2 stages (order 3), 3 stages (order 5) or 1 stage
        (implicit Euler, order 1; for comparison only).
    substeps : int, optional
        Integration steps per sample; default so that a step is at most 1 ms
        (0.125 ms with dry friction).
    newton_iterations : int
        Simplified Newton iterations per step for the stage equations.
    compiler_flags : sequence of str or None
        C compiler flags for the step functions (compiled once per plant structure and
        number of parameters, then cached; about 10 s with -O1, 4 s with -O0 and half
        the speed); None evaluates them in CasADi's virtual machine (no compiler,
        about 5 times slower).
    max_iter, tol : IPOPT iteration limit and tolerance (on the gradient of the cost
        normalised per residual; the problem is scaled, IPOPT's own scaling is off).
    fit_threshold : float
        Fit (%) below which the result is called a poor fit.
    verbose : bool
        Print IPOPT's iteration log.
    progress : bool or None
        Show a progress bar of the IPOPT iterations (None: when the terminal is
        interactive).

    Returns
    -------
    GreyBoxResult

    Raises
    ------
    InputError
        Unknown parameter (with a suggestion), a parameter of an effect the plant does
        not have, bad bounds, a recording without ``u`` or none of the signals, too
        short, bad options.
    """
    t_start = time.perf_counter()
    if not isinstance(plant, Plant):
        raise InputError(f"plant must be a workbench Plant, got {type(plant).__name__}")
    if method not in ("multiple_shooting", "single_shooting"):
        raise InputError("method must be 'multiple_shooting' or 'single_shooting', "
                         f"got {method!r}")
    if x0 not in ("estimate", "from_recording"):
        raise InputError(f"x0 must be 'estimate' or 'from_recording', got {x0!r}")
    if replay not in ("auto", "open", "closed"):
        raise InputError(f"replay must be 'auto', 'open' or 'closed', got {replay!r}")
    schemes = {"radau1": 1, "radau2": 2, "radau3": 3}
    if integrator not in schemes:
        raise InputError(f"integrator must be one of {', '.join(schemes)}, got {integrator!r}")
    if not (isinstance(shooting_interval, (int, float)) and shooting_interval > 0):
        raise InputError("shooting_interval must be a positive time in s, "
                         f"got {shooting_interval!r}")
    if substeps is not None and (int(substeps) != substeps or substeps < 1):
        raise InputError(f"substeps must be a positive integer, got {substeps!r}")
    if int(newton_iterations) < 1:
        raise InputError("newton_iterations must be at least 1")
    for s, wv in (weights or {}).items():
        if s not in signals:
            raise InputError(f"weight given for '{s}', which is not compared "
                             f"({', '.join(signals)})")
        if not (float(wv) > 0):
            raise InputError(f"weight of '{s}' must be > 0, got {wv!r}")
    params = _resolve_parameters(plant, parameters, bounds)
    data = _prepare(plant, recordings, signals, noise)

    friction = plant.params.has_effect("dry_friction")
    model = plant.with_friction("smooth") if friction and plant.friction != "smooth" else plant
    dt_max = max(float(np.max(np.diff(d.t))) for d in data)
    dt_med = min(float(np.median(np.diff(d.t))) for d in data)
    if substeps is None:
        h_max = MAX_STEP_FRICTION if friction else MAX_STEP
        substeps = max(1, int(math.ceil(dt_max / h_max - 1e-9)))
    if method == "single_shooting":
        M = max(len(d.t) for d in data)
    else:
        M = max(1, int(round(shooting_interval / dt_med)))
    M = min(M, max(len(d.t) for d in data))
    sig_names = tuple(s for s in signals if any(s in d.y for d in data))

    prob = _Problem(model, params, data, sig_names, M, schemes[integrator], int(substeps),
                    int(newton_iterations), dict(weights or {}), compiler_flags)
    nx, nsel = prob.nx, prob.nsel

    # ---- start values: parameters at their start, nodes from the data
    z0 = np.zeros(nsel)
    p_start = prob.split(np.concatenate([z0, np.zeros(nx * prob.n_int)]))[2]
    x_init = [_initial_state(model, d) for d in data]
    nodes = prob.simulate_nodes(x_init, p_start)
    names = model.state_names
    for d in data:
        idx = np.arange(d.n_int) * M
        idx = np.minimum(idx, len(d.t) - 1)
        rows = slice(d.first, d.first + d.n_int)
        v = _smooth_derivative(d.t, np.asarray(d.rec["x"], dtype=float))
        for s in ("x", "p_a", "p_b", "p_s"):
            if s in names and s in d.rec:
                nodes[rows, names.index(s)] = np.asarray(d.rec[s], dtype=float)[idx]
        nodes[rows, names.index("v")] = (np.asarray(d.rec["v"], dtype=float)[idx]
                                         if "v" in d.rec else v[idx])
    lo_s, hi_s = _state_bounds(model)
    nodes = np.clip(nodes, lo_s, hi_s)
    w0 = np.concatenate([z0, (nodes / prob.sc).ravel()])
    lbw = np.concatenate([[p.z_bounds[0] for p in params], np.tile(lo_s / prob.sc, prob.n_int)])
    ubw = np.concatenate([[p.z_bounds[1] for p in params], np.tile(hi_s / prob.sc, prob.n_int)])
    fixed = np.zeros(prob.nw, dtype=bool)
    if x0 == "from_recording":
        for d, xi in zip(data, x_init):
            sl = prob.node_slice(d.first)
            for s in ("x", "p_a", "p_b", "p_s"):
                if s in names and s in d.rec:
                    i = sl.start + names.index(s)
                    w0[i] = lbw[i] = ubw[i] = _first_value(d.t, d.rec[s]) / prob.sc[names.index(s)]
                    fixed[i] = True

    # ---- solve
    bar = None
    if progress is not False:
        from tqdm.auto import tqdm
        bar = tqdm(total=max_iter, desc="grey-box (IPOPT)", unit="it", leave=False,
                   disable=None if progress is None else False)

        def tick(cost: float) -> None:
            bar.update(1)
            bar.set_postfix(cost=f"{cost:.4g}")
        prob.on_iteration = tick
    try:
        solver = prob.solver(max_iter, tol, verbose)
        sol = solver(x0=w0, lbx=lbw, ubx=ubw, lbg=0.0, ubg=0.0)
        stats = solver.stats()
    finally:
        if bar is not None:
            bar.close()
    w = np.asarray(sol["x"], dtype=float).ravel()
    if not np.all(np.isfinite(w)):
        raise WorkbenchError("the grey-box optimisation diverged (non-finite values); try "
                             "tighter bounds, a shorter shooting interval or more substeps")
    status = str(stats.get("return_status", "unknown"))
    if prob.iteration.stopped:
        status = "Parameters_Converged"
    success = bool(stats.get("success", False)) or status in (
        "Solve_Succeeded", "Solved_To_Acceptable_Level", "Parameters_Converged")
    iterations = int(stats.get("iter_count", 0))
    z, s_nodes, p_hat = prob.split(w)
    values = np.array([p_hat[p.index] for p in params])
    cost = prob.f_g(w)[0]

    # ---- covariance (KKT, sandwich with the per-signal residual variance)
    std, corr, cov_ok = _covariance(prob, w, fixed, params, z)
    if not success and _stationary(prob.iteration, std, params, z):
        # IPOPT gave up (kinks), but the last iterates agree to a fraction of the std
        status = f"Parameters_Converged ({status})"
        success = True

    # ---- residual statistics per recording and signal (discrete model)
    r, _, Ydisc = prob.primal(w)
    res_rms, white, resid = [], [], []
    for d in data:
        a = d.first * M
        n = len(d.t)
        rr, ww, ee = {}, {}, {}
        for i, s in enumerate(sig_names):
            if s in d.y:
                e = d.y[s] - Ydisc[i, a:a + n]
                rr[s] = float(np.sqrt(np.mean(e * e)))
                ww[s] = _whiteness(e)
                ee[s] = e
        res_rms.append(rr)
        white.append(ww)
        resid.append(ee)

    # ---- honest check: fresh CVODES simulations before and after
    changes = {p.name: float(v) for p, v in zip(params, values)}
    if model.segments and "lines.segments" not in plant.params:
        # the number of line segments follows the length unless the file fixes it: keep
        # the one the fit used, so the estimated plant is the model that was fitted
        changes["lines.segments"] = int(model.segments)
    try:
        est_plant = plant.with_params(**changes)
    except InputError as exc:
        raise WorkbenchError(f"the estimates break a rule of the plant file ({exc}); give "
                             "bounds that respect it") from None
    fit_before, fit_after, fit_ms, runs_b, runs_a, int_err, x0_hat, modes = \
        [], [], [], [], [], [], [], []
    for d, xi in zip(data, x_init):
        a = d.first * M
        n = len(d.t)
        xs = s_nodes[d.first] * prob.sc
        x0_hat.append(xs)
        closed = _use_closed_loop(replay, d.rec, plant)
        modes.append("closed_loop" if closed else "open_loop")
        runs = []
        for pl, xstart, fits in ((plant, xi, fit_before), (est_plant, xs, fit_after)):
            try:
                run = (_closed_replay(pl, d.rec, xstart) if closed
                       else _replay(pl, d.t, d.u, xstart))
                fits.append(_fits(d.y, run))
            except WorkbenchError:
                run = None
                fits.append({s: float("nan") for s in d.y})
            runs.append(run)
        runs_b.append(runs[0])
        runs_a.append(runs[1])
        fit_ms.append({s: nrmse_fit(d.y[s], d.y[s] - resid[len(fit_ms)][s]) for s in d.y})
        # the fixed-step scheme against CVODES, interval by interval from the nodes
        try:
            anchors = s_nodes[d.first:d.first + d.n_int] * prob.sc
            rc = _replay(model, d.t, d.u, anchors[0], params=p_hat, anchors=anchors, every=M)
            int_err.append({s: float(np.sqrt(np.mean(
                (rc[s] - Ydisc[sig_names.index(s), a:a + n]) ** 2))) for s in d.y})
        except WorkbenchError:
            int_err.append({s: float("nan") for s in d.y})

    # ---- verdict
    lo = np.array([p.lo for p in params])
    hi = np.array([p.hi for p in params])
    zb = np.array([p.z_bounds for p in params])
    at_bound = np.minimum(z - zb[:, 0], zb[:, 1] - z) <= 1e-5 * (zb[:, 1] - zb[:, 0])
    size = np.array([max(abs(v), _TYPICAL.get(p.name, 0.0) if not p.log else 0.0)
                     for p, v in zip(params, values)])
    identifiable = np.isfinite(std) & (std <= 0.5 * np.where(size > 0, size, np.inf))
    ci = np.column_stack([values - _Z95 * std, values + _Z95 * std])
    poor, msgs = _verdict(data, fit_after, fit_ms, modes, res_rms, white, int_err,
                          fit_threshold, success, status, params, identifiable, at_bound, corr)
    method_info = {
        "method": method, "integrator": integrator, "substeps": int(substeps),
        "newton_iterations": int(newton_iterations),
        "compiled": compiler_flags is not None and _jit.have_compiler(),
        "shooting_interval_samples": int(M), "shooting_intervals": int(prob.n_int),
        "x0": x0, "signals": list(sig_names), "replay": modes,
        "friction_form": model.friction if friction else "none",
        "samples": int(sum(len(d.t) for d in data)),
        "sensitivity_evaluations": int(prob.n_sens), "evaluations": int(prob.n_eval),
        "covariance": "kkt-sandwich" if cov_ok else "failed",
    }
    return GreyBoxResult(
        names=tuple(p.name for p in params), units=tuple(p.unit for p in params),
        nominal=np.array([float(plant.p0[p.index]) for p in params]),
        bounds=np.column_stack([lo, hi]), values_=values, std_=std, ci95_=ci,
        correlation_=corr, identifiable_=identifiable, at_bound_=at_bound,
        fit_before=tuple(fit_before), fit_after=tuple(fit_after), fit_ms_=tuple(fit_ms),
        x0_=tuple(x0_hat),
        noise=tuple(dict(d.noise) for d in data), residual_rms_=tuple(res_rms),
        whiteness_=tuple(white), integration_error_=tuple(int_err), residuals_=tuple(resid),
        cost=float(cost),
        iterations=iterations, status=status, success=success,
        wall_time=time.perf_counter() - t_start, poor_fit=poor, message=" ".join(msgs),
        plant_=est_plant, method=method_info, sources=tuple(d.source for d in data),
        trajectories_before=tuple(runs_b), trajectories_after=tuple(runs_a))


def _stationary(it: _IterationCallback, std: np.ndarray, params: list[_Param], z: np.ndarray,
                fraction: float = 0.25, last: int = 3) -> bool:
    """Whether the last iterates moved the parameters by less than ``fraction`` of their
    standard deviation, with the continuity constraints met."""
    if len(it.history) < last + 1:
        return False
    D = np.array([p.dvalue(float(zi)) for p, zi in zip(params, z)])
    sig_z = std / np.abs(D)
    steps = np.abs(np.diff(np.array(it.history[-(last + 1):]), axis=0))
    return bool(np.all(np.isfinite(sig_z)) and np.all(steps < fraction * sig_z)
                and max(it.gmax[-last:]) < 1e-5)


def _covariance(prob: _Problem, w: np.ndarray, fixed: np.ndarray, params: list[_Param],
                z: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    nsel = prob.nsel
    J, r = prob.residual_jacobian(w)
    G = prob.constraint_jacobian(w)
    free = np.flatnonzero(~fixed)
    J = J[:, free]
    G = G[:, free]
    # per-residual variance: each (recording, signal) from its own residuals
    var = np.zeros(prob.ny * prob.ntot)
    n_free_dims = nsel + prob.nx * len(prob.data)
    dof = max(1e-3, 1.0 - n_free_dims / max(prob.n_res, 1))
    Wt = prob.W.T.ravel()
    for d in prob.data:
        a, b = d.first * prob.M * prob.ny, (d.first + d.n_int) * prob.M * prob.ny
        for i in range(prob.ny):
            rows = np.arange(a + i, b, prob.ny)
            rows = rows[Wt[rows] > 0]
            if len(rows):
                var[rows] = np.mean(r[rows] ** 2) / dof
    H = (J.T @ J).tocsc()
    n, m = H.shape[0], G.shape[0]
    # a relative 1e-10 on the diagonal keeps the solve defined when a parameter is not
    # identifiable (its std then comes out huge); the constraints stay exact
    dh = H.diagonal()
    reg = sp.diags(1e-10 * np.where(dh > 0, dh, 1.0))
    K = sp.bmat([[H + reg, G.T], [G, None]], format="csc")
    rhs = np.zeros((n + m, nsel))
    rhs[np.arange(nsel), np.arange(nsel)] = 1.0     # z are the first free variables
    try:
        X = spla.splu(K).solve(rhs)
        ok = bool(np.all(np.isfinite(X)))
    except RuntimeError:
        X = np.full((n + m, nsel), np.nan)
        ok = False
    if ok:
        B = J @ X[:n]                                   # (rows, nsel)
        cov_z = B.T @ (var[:, None] * B)
    else:
        cov_z = np.full((nsel, nsel), np.inf)
    D = np.array([p.dvalue(float(zi)) for p, zi in zip(params, z)])
    cov = cov_z * np.outer(D, D)
    dg = np.diag(cov).copy()
    std = np.sqrt(np.where(dg >= 0, dg, np.nan))
    std = np.where(np.isfinite(std), std, np.inf)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    corr = np.where(np.isfinite(corr), corr, np.nan)
    np.fill_diagonal(corr, 1.0)
    return std, corr, ok


def _verdict(data, fit_after, fit_ms, modes, res_rms, white, int_err, threshold, success,
             status, params, identifiable, at_bound, corr) -> tuple[bool, list[str]]:
    """Poor fit: the estimated model cannot follow a recording.

    Either a signal's fit is below ``threshold`` both in the fresh CVODES replay and
    along the model's own trajectory in the fit, or its residuals are strongly
    correlated (more than half of the autocorrelation lags outside the 99 % band) and
    more than 3 times the measurement noise. A replay that drifts while the model's own
    trajectory follows the data is reported, not counted as a poor fit.
    """
    poor = False
    msgs: list[str] = []
    worst, drift = [], []
    for d, fa, fm, mode in zip(data, fit_after, fit_ms, modes):
        where = "" if len(data) == 1 else f" ({d.source})"
        for s, fv in fa.items():
            bad_replay = not math.isfinite(fv) or fv < threshold
            bad_model = not math.isfinite(fm.get(s, float("nan"))) or fm[s] < threshold
            if bad_replay and bad_model:
                worst.append(f"{s} {fv:.1f} %{where}")
            elif bad_replay:
                drift.append((s, fv, fm[s], mode, where))
    if worst:
        poor = True
        msgs.append(f"Fit after estimation below {threshold:g} %: {', '.join(worst)}; the model "
                    "structure does not explain the recording (a missing effect?).")
    systematic = []
    for d, rr, ww in zip(data, res_rms, white):
        for s in rr:
            ratio = rr[s] / d.noise[s]
            if ratio > 3.0 and math.isfinite(ww.get(s, float("nan"))) and ww[s] > 0.5:
                systematic.append(f"{s} ({ratio:.1f} x noise)")
    if systematic:
        poor = True
        msgs.append("Residuals are correlated and well above the measurement noise for "
                    f"{', '.join(systematic)}: a systematic model error remains.")
    for s, fv, fm, mode, where in drift:
        hint = ("" if mode == "closed_loop" else
                "; open-loop replay of a position drive integrates every small difference "
                "(give the recording's r and the plant's [controller] for a closed-loop check)")
        msgs.append(f"The {mode.replace('_', '-')} replay of {s}{where} drifts (fit {fv:.1f} %) "
                    f"although the model follows it to {fm:.1f} % from the estimated initial "
                    f"state{hint}.")
    if not success:
        msgs.append(f"IPOPT did not converge ({status}); the estimates are not reliable.")
    for p, ok, ab in zip(params, identifiable, at_bound):
        if ab:
            msgs.append(f"{p.name} is at a bound ({p.lo:g} .. {p.hi:g}).")
        elif not ok:
            msgs.append(f"{p.name} is not identifiable from these data (std above half its size).")
    n = len(params)
    for i in range(n):
        for j in range(i + 1, n):
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) > 0.99:
                msgs.append(f"{params[i].name} and {params[j].name} are strongly correlated "
                            f"({corr[i, j]:+.3f}).")
    for d, ie in zip(data, int_err):
        for s, e in ie.items():
            if math.isfinite(e) and e > 0.5 * d.noise[s]:
                msgs.append(f"The fixed-step integration differs from CVODES by {e:.3g} "
                            f"{_SIGNAL_UNITS.get(s, '')} RMS on {s}, comparable with the noise: "
                            "use more substeps.")
                break
    if not poor and not msgs:
        msgs.append("The estimated model explains the recordings to the noise level.")
    elif not poor:
        msgs.insert(0, "Good fit.")
    return poor, msgs


# ====================================================================== benchmark
def _aprbs_doublets(duration: float, dt: float, rng: np.random.Generator, center: float,
                    amplitude: float, hold: tuple[float, float]) -> np.ndarray:
    """Command of random doublets (+a then -a, random a and hold) around ``center``, V.

    Doublets keep an open-loop cylinder near where it started: each excursion is
    undone by the next half.
    """
    n = int(round(duration / dt)) + 1
    u = np.empty(n)
    k = 0
    while k < n:
        a = rng.uniform(-amplitude, amplitude)
        m = max(1, int(rng.uniform(*hold) / dt))
        u[k:k + m] = center + a
        u[k + m:k + 2 * m] = center - a
        k += 2 * m
    return u[:n]


def synthetic_recording(plant: Plant, duration: float, sample_time: float = 1e-3,
                        seed: int = 0, noise: Mapping[str, float] | None = None,
                        amplitude: float = 0.25, hold: tuple[float, float] = (0.02, 0.12),
                        x0: float | None = None, rtol: float = 1e-9, atol: float = 1e-11
                        ) -> Recording:
    """An open-loop recording simulated by the workbench (CVODES), for tests and benches.

    The command is random doublets around the valve centre (:func:`_aprbs_doublets`);
    the piston starts at rest at ``x0`` (default mid-stroke) with 3.5 bar in both
    chambers. ``noise`` maps signals to white-noise standard deviations (SI).
    """
    from .. import simulate
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration / sample_time)) + 1) * sample_time
    center = (float(plant.params["valve.command_center"])
              + float(plant.params.get("valve.null_offset", 0.0)))
    u = _aprbs_doublets(duration, sample_time, rng, center, amplitude, hold)
    xs = 0.5 * plant.stroke if x0 is None else x0
    state = plant.initial_state(xs, p_a=3.5e5, p_b=3.5e5, u0=center)
    run = simulate.open_loop(plant, t, u, x0=state, rtol=rtol, atol=atol, progress=False)
    cols = {}
    for s in ("x", "p_a", "p_b"):
        y = np.asarray(run[s], dtype=float).copy()
        if noise and s in noise:
            y = y + float(noise[s]) * rng.standard_normal(len(y))
        cols[s] = y
    return Recording.from_arrays(t, source=f"<simulated {plant.name} seed {seed}>",
                                 metadata={"sample_time": repr(sample_time),
                                           "simulated_by": "grey_box.synthetic_recording"},
                                 u=u, **cols)
