"""The NMPC controller object: its settings, their checks, and the controller protocol
(``reset``, ``update``) that :func:`workbench.simulate.closed_loop` runs."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import casadi as ca
import numpy as np

from ...errors import InputError
from .model import NMPC_STATES, line_states, prediction_model
from .problem import Problem
from .results import NMPCState, Solution
from .update import advance, solution

__all__ = ["NMPC"]

_MODES = ("rti", "sqp", "ipopt")
_SENSITIVITIES = ("pade", "exact")
_QP_SOLVERS = ("daqp", "qpoases", "osqp", "qrqp")


def _meta(unit: str, doc: str) -> dict:
    return {"unit": unit, "doc": doc}


@dataclass(frozen=True)
class NMPC:
    """Nonlinear MPC of the piston position (a DiscreteController).

    Parameters
    ----------
    model : workbench.Plant
        Prediction model with exactly the states x, v, p_a, p_b (see
        :func:`prediction_model`); dry friction is used in its smooth form.
    sample_time : float, s
        Control period T; also the length of each shooting interval.
    horizon : int
        Number N of shooting intervals (>= 2); the horizon is N T.
    mode : {"rti", "sqp", "ipopt"}
        Real-time iteration, SQP to convergence, or IPOPT (see the module text).
    position_tolerance : float, m
        Position error that costs as much as one command-rate tolerance.
    velocity_tolerance : float, m/s
        Velocity error (against the reference's rate) of the same cost.
    command_rate_tolerance : float, V
        Change of command from one sample to the next of the same cost.
    terminal_factor : float, -
        Weight of the last node's position and velocity errors relative to the others.
    stroke_margin : float, m
        Distance kept from each end stop (soft constraint).
    max_speed : float or None, m/s
        Speed limit (soft constraint); None: none. The 1.2 kg payload on the 25 mm
        bore reaches 4-5 m/s within 50 ms, and braking from there compresses the far
        chamber to 6.7 bar (supply 6 bar) between the shooting nodes; 3 m/s keeps the
        pressures within their limits on the tests' end-to-end steps.
    pressure_margin : float, Pa
        The pressure limits are atmosphere + margin .. supply - margin at the nodes,
        so that the peak of a braking chamber between nodes stays within supply.
    slack_weights : (float, float), -
        L1 and L2 weights of the constraint slacks; the slacks are measured as
        fractions of the stroke and of the supply pressure. The L1 weight must exceed
        the constraints' multipliers for the penalty to be exact.
    substeps : int
        RK4 steps per shooting interval, at least: with dry friction the problem
        takes more, up to :data:`.model.MAX_SUBSTEPS`, if the friction's width
        needs them (:func:`.model.friction_velocity`).
    sensitivities : {"pade", "exact"}
        Interval Jacobians: Pade approximant of the exponential of the midpoint
        Jacobian (cheap) or the derivative of the RK4 steps (exact).
    qp_solver : {"daqp", "qpoases", "osqp", "qrqp"}
        CasADi conic plugin for the condensed QP.
    max_iterations : int
        SQP steps per sample (mode "sqp", the first sample of "rti" and a restart
        after a failed step); IPOPT may take ten times as many.
    tolerance : float, -
        SQP stops when the largest scaled command step is below this.
    warm_start : bool
        Start each sample from the previous solution shifted by one sample (True) or
        from rest at the measured state (False; for comparison only).
    reference_rate_limit : float, m/s
        A reference moving slower than this is extrapolated as a ramp over the
        horizon; faster (a jump) it is held.
    disturbance_gain : float, -
        Gain in [0, 1] of the disturbance-force observer (0: off). The force the model
        lacks (dry friction, a load) is estimated each sample from the velocity it
        mispredicted, d += gain m (v_pred - v_meas) / T, and predicted as constant
        over the horizon; this gives the loop integral action (offset-free tracking).
    interior_limits : bool
        Enforce the stroke, pressure and speed limits also between the shooting
        nodes, at RK4 substep ends at most :data:`.limits.LIMIT_SPACING` (2.5 ms)
        apart (:func:`.limits.interior_points`: none when the sample time is that
        short already), from the second interval on (:data:`.limits.FIRST_INTERVAL`:
        within the first sample a limit is decided by the measured state, and
        pricing what no command can change there made the closed loop brake
        bang-bang in mid-stroke). A braking chamber's pressure peaks, and a piston
        reverses, between nodes: a converged plan keeps a 0.5 m/s speed limit to
        0.504 m/s with the rows, 0.68 m/s without. Modes rti and sqp; mode ipopt keeps
        the limits at the nodes (cold-started IPOPT did not converge within 300
        iterations with the interior rows on the test's 0.1 m step). On by default
        (the compiled sample has them too): nmpc_position --quick with / without
        them, limit steps peak 5.618 / 5.614 bar, validation 5.622 / 5.628 bar, IAE
        40.94 / 40.88 mm s.
    jit : bool
        Compile the linearisation to C (cached; needs a C compiler, else CasADi's
        virtual machine evaluates it).
    preview : callable or None
        The whole reference r(t) (s -> m, vectorised, time from the first update),
        known in advance: the nodes then follow it (position, and velocity from its
        chord over one sample) instead of extrapolating the current sample. It must
        be the reference the loop runs on (e.g. a
        :class:`~workbench.references.Trajectory`).
    friction_width : float or None, m/s
        Tanh width v_e of the model's dry friction, F_str(v) tanh(v / v_e); None
        (default): half the Stribeck velocity, with the substeps raised so that RK4
        integrates it accurately (:func:`.model.friction_velocity`; 5.25 mm/s and 8
        substeps on the 2 ms precision rig: the physics' 1 mm/s with 4 substeps made
        the prediction of a stuck piston a rounding artefact).
    pressure_noise : float, Pa
        Std of the pressure sensors' noise, for the estimate of a lumped line's states
        (:mod:`.lines`; a model without lines does not use it).
    compiled_sample : bool
        With ``jit``, modes rti and sqp and DAQP: run each update as one
        compiled C call (:mod:`.fast`; same plans). :attr:`compiled_reason` says why
        an NMPC runs the Python update instead.
    breakaway : bool
        A stuck piston that must move: the force estimate set to the static friction
        the smooth prediction lacks, against the wanted direction, until it has moved
        (:mod:`.breakaway`; a model with dry friction). Lets a quiet NMPC (a small
        ``command_rate_tolerance``) break away at a reversal as fast as a chattering
        one.
    """

    model: Any
    sample_time: float = field(default=0.01, metadata=_meta("s", "control period"))
    horizon: int = field(default=20, metadata=_meta("-", "shooting intervals N"))
    mode: str = field(default="rti", metadata=_meta("", "rti, sqp or ipopt"))
    position_tolerance: float = field(default=2e-3, metadata=_meta("m", "position error scale"))
    velocity_tolerance: float = field(default=0.05, metadata=_meta("m/s", "velocity error scale"))
    command_rate_tolerance: float = field(default=0.5, metadata=_meta("V", "command step scale"))
    terminal_factor: float = field(default=20.0, metadata=_meta("-", "terminal weight factor"))
    stroke_margin: float = field(default=0.01, metadata=_meta("m", "distance from end stops"))
    max_speed: float | None = field(default=3.0, metadata=_meta("m/s", "speed limit"))
    pressure_margin: float = field(default=4e4, metadata=_meta("Pa", "tightening of the pressure limits"))
    slack_weights: tuple[float, float] = field(default=(1e6, 1e8),
                                               metadata=_meta("-", "L1, L2 slack weights"))
    substeps: int = field(default=4, metadata=_meta("-", "RK4 steps per interval"))
    sensitivities: str = field(default="pade", metadata=_meta("", "pade or exact"))
    qp_solver: str = field(default="daqp", metadata=_meta("", "conic plugin"))
    max_iterations: int = field(default=30, metadata=_meta("-", "SQP / IPOPT iterations"))
    tolerance: float = field(default=1e-6, metadata=_meta("-", "SQP step tolerance"))
    warm_start: bool = field(default=True, metadata=_meta("", "shift previous solution"))
    reference_rate_limit: float = field(default=0.5, metadata=_meta("m/s", "ramp detection"))
    disturbance_gain: float = field(default=1.0, metadata=_meta("-", "force observer gain"))
    interior_limits: bool = field(default=True, metadata=_meta("", "limits between nodes"))
    jit: bool = field(default=True, metadata=_meta("", "compile to C"))
    preview: Any = field(default=None, metadata=_meta("", "reference known in advance"))
    compiled_sample: bool = field(default=True, metadata=_meta("", "one C call per sample"))
    friction_width: float | None = field(default=None,
                                         metadata=_meta("m/s", "tanh width of dry friction"))
    pressure_noise: float = field(default=300.0, metadata=_meta("Pa", "pressure sensor noise"))
    breakaway: bool = field(default=False, metadata=_meta("", "static friction while stuck"))

    #: Measurements read (wrap in :class:`~workbench.controllers.observer.Observed` to
    #: run on x, p_a, p_b only).
    needs = NMPC_STATES

    # ------------------------------------------------------------------ checks
    def __post_init__(self) -> None:
        if self.preview is not None and not callable(self.preview):
            raise InputError("NMPC preview must be a reference r(t) (callable, s -> m) or None")
        _check_model(self)
        _check_limits(self)
        _check_numbers(self)
        _check_choices(self)
        _check_stroke_and_slacks(self)
        object.__setattr__(self, "_problem", Problem(self))

    @classmethod
    def for_plant(cls, plant, effects: Sequence[str] | None = None, lines: str = "volume",
                  **settings) -> "NMPC":
        """NMPC whose prediction model is ``plant`` reduced by :func:`prediction_model`
        (``lines``: how the plant's lines enter it, "volume" or "lumped").

        ``sample_time`` defaults to the plant file's ``controller.sample_time`` when it
        has one.
        """
        if "sample_time" not in settings and plant.params.get("controller.sample_time"):
            settings["sample_time"] = float(plant.params["controller.sample_time"])
        return cls(prediction_model(plant, effects, lines=lines), **settings)

    def with_settings(self, **changes) -> "NMPC":
        """A copy with some settings changed (the model is kept)."""
        return replace(self, **changes)

    @property
    def kind(self) -> str:
        return f"NMPC ({self.mode}, N = {self.horizon})"

    @property
    def compiled_reason(self) -> str | None:
        """None when each update is one compiled C call, else why not (builds it)."""
        from .update import compiled_sample
        return compiled_sample(self._problem)[1]

    # ------------------------------------------------------------------ protocol
    def reset(self) -> None:
        """No memory before the first sample (it starts from rest at the measured state)."""
        return None

    def update(self, state: NMPCState | None, r: float, y: dict) -> tuple[NMPCState, float]:
        """(new state, command in V) from the reference (m) and measured x, v, p_a, p_b (SI)."""
        pb = self._problem
        new = advance(pb, y, float(r), state)
        return new, pb.command(new.u_prev)

    def solve(self, y: dict | Sequence[float], r: float, state: NMPCState | None = None) -> Solution:
        """Solve one problem from the measured state ``y`` (x m, v m/s, p_a, p_b Pa).

        ``state`` is the memory of the previous sample (its solution is shifted as
        the initial guess); None starts from rest at ``y``.
        """
        if not isinstance(y, dict):
            vals = np.asarray(y, dtype=float).ravel()
            if vals.size != 4:
                raise InputError("the measured state is x (m), v (m/s), p_a, p_b (Pa)")
            y = dict(zip(NMPC_STATES, vals))
        pb = self._problem
        new = advance(pb, y, float(r), state)
        return solution(pb, new, float(r), None if state is None else state.r_prev)


# ---------------------------------------------------------------------- checks
def _check_model(c: NMPC) -> None:
    """A 4-state Plant (x, v, p_a, p_b); dry friction switched to its smooth form."""
    model = c.model
    names = getattr(model, "state_names", None)
    if names is None:
        raise InputError(f"model must be a workbench.Plant, got {type(model).__name__}")
    from . import model as _model
    lumped = line_states(_model.LUMPED_SEGMENTS)
    if tuple(names) not in (NMPC_STATES, NMPC_STATES + lumped):
        raise InputError(
            f"the NMPC predicts the states {', '.join(NMPC_STATES)} it measures (and "
            f"lumped lines' {', '.join(lumped)}); this model has {', '.join(names)}. "
            "Build the prediction model with mpc.prediction_model(plant) or "
            "NMPC.for_plant(plant, ...)")
    if getattr(model, "friction", "smooth") != "smooth" and model.params.has_effect("dry_friction"):
        object.__setattr__(c, "model", model.with_friction("smooth"))


def _check_limits(c: NMPC) -> None:
    """Pressure margin below a quarter of supply - atmosphere; speed limit > 0 or None."""
    pm = c.pressure_margin
    prm = c.model.params
    span = float(prm["supply.pressure"]) - float(prm["gas.atmospheric_pressure"])
    if isinstance(pm, bool) or not isinstance(pm, (int, float)) or not 0.0 <= pm < 0.25 * span:
        raise InputError(f"NMPC pressure_margin must be in [0, {0.25 * span:g}) Pa (a quarter "
                         f"of supply - atmosphere), got {pm!r}")
    if c.max_speed is not None and not (isinstance(c.max_speed, (int, float))
                                        and math.isfinite(c.max_speed) and c.max_speed > 0):
        raise InputError(f"NMPC max_speed must be > 0 m/s or None, got {c.max_speed!r}")


def _check_numbers(c: NMPC) -> None:
    """Positive tolerances and times, gains in range, integer counts."""
    pn = c.pressure_noise
    if isinstance(pn, bool) or not isinstance(pn, (int, float)) or not (math.isfinite(pn) and pn >= 0):
        raise InputError(f"NMPC pressure_noise must be a finite number >= 0 Pa, got {pn!r}")
    for name in ("sample_time", "position_tolerance", "velocity_tolerance",
                 "command_rate_tolerance", "reference_rate_limit", "tolerance"):
        v = getattr(c, name)
        unit = c.__dataclass_fields__[name].metadata["unit"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
            raise InputError(f"NMPC {name} must be a finite number > 0 {unit}, got {v!r}")
    if not (isinstance(c.disturbance_gain, (int, float)) and 0.0 <= c.disturbance_gain <= 1.0):
        raise InputError(f"NMPC disturbance_gain must be in [0, 1], got {c.disturbance_gain!r}")
    fw = c.friction_width
    if fw is not None and (isinstance(fw, bool) or not isinstance(fw, (int, float))
                           or not (math.isfinite(fw) and fw > 0)):
        raise InputError(f"NMPC friction_width must be a finite number > 0 m/s or None, "
                         f"got {fw!r}")
    if not (isinstance(c.terminal_factor, (int, float)) and c.terminal_factor >= 0):
        raise InputError(f"NMPC terminal_factor must be >= 0, got {c.terminal_factor!r}")
    for name, lo in (("horizon", 2), ("substeps", 1), ("max_iterations", 1)):
        v = getattr(c, name)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise InputError(f"NMPC {name} must be an integer >= {lo}, got {v!r}")


def _check_choices(c: NMPC) -> None:
    """Mode, sensitivities and QP solver among the known ones (and in this CasADi)."""
    if c.mode not in _MODES:
        raise InputError(f"NMPC mode must be one of {', '.join(_MODES)}, got {c.mode!r}")
    if c.sensitivities not in _SENSITIVITIES:
        raise InputError(f"NMPC sensitivities must be 'pade' or 'exact', got {c.sensitivities!r}")
    if c.qp_solver not in _QP_SOLVERS:
        raise InputError(f"NMPC qp_solver must be one of {', '.join(_QP_SOLVERS)}, "
                         f"got {c.qp_solver!r}")
    if not ca.has_conic(c.qp_solver):
        raise InputError(f"this CasADi build has no QP solver '{c.qp_solver}'")


def _check_stroke_and_slacks(c: NMPC) -> None:
    """Stroke margin below a quarter of the stroke; two positive slack weights (as floats)."""
    L = c.model.stroke
    if not (isinstance(c.stroke_margin, (int, float)) and 0.0 <= c.stroke_margin < 0.25 * L):
        raise InputError(f"NMPC stroke_margin must be in [0, {0.25 * L:g}) m (a quarter of "
                         f"the stroke), got {c.stroke_margin!r}")
    w = tuple(c.slack_weights)
    if len(w) != 2 or not all(isinstance(x, (int, float)) and x > 0 for x in w):
        raise InputError(f"NMPC slack_weights are two numbers > 0 (L1, L2), got {c.slack_weights!r}")
    object.__setattr__(c, "slack_weights", (float(w[0]), float(w[1])))
