"""Nonlinear model predictive position control (NMPC) on the symbolic plant.

:class:`NMPC` predicts with the plant's own CasADi model ``f(x, u, p)`` (states x, v,
p_a, p_b) by **multiple shooting**: N intervals of one sample time each, the command
held (ZOH) on every interval, each interval integrated by classical Runge-Kutta (RK4)
with ``substeps`` fixed steps. In scaled variables it minimises

    1/2 sum_k [ ((x_k - r_k)/x_tol)^2 + ((v_k - r'_k)/v_tol)^2 ]   k = 1..N (node N
    + 1/2 sum_k ((u_k - u_{k-1})/du_tol)^2                          x terminal_factor)
    + slack penalties

subject to the command range ``valve.command_min .. command_max`` (hard bounds) and,
as soft constraints at the shooting nodes, the stroke ``stroke_margin .. L -
stroke_margin``, the chamber pressures atmosphere .. supply (tightened by
``pressure_margin``) and the speed ``max_speed``: one slack per kind over the
horizon with an exact L1 penalty plus a small quadratic term, so a limit gives way
only where no admissible command can keep it and the problem is always feasible.

Three solution modes share that problem:

``"rti"`` (real-time iteration, the default)
    One Gauss-Newton SQP step per sample from the previous solution shifted by one
    sample (warm start). The QP is condensed onto the N command moves (plus the
    slacks): a dense, strictly convex QP of about 20 variables and 160 rows, solved
    by DAQP, a dual active-set solver made for embedded MPC. Linearisation and
    condensing, and the update of the plan from the QP step, are CasADi functions
    compiled to C through :func:`workbench._jit.compiled`; with the QP between them
    they form one CasADi function, so a sample costs one call from Python.
``"sqp"``
    The same Gauss-Newton steps repeated until the command step is below
    ``tolerance`` (at most ``max_iterations``).
``"ipopt"``
    The full multiple-shooting NLP solved by IPOPT with exact Hessians (the accurate
    reference), warm started with the previous primal and dual solution shifted.

Integrator and sensitivities: the chamber modes of the 25 mm rig reach 1e3 1/s at
mid-stroke and 1e4 .. 2.5e4 1/s within 10 mm of an end (small chamber, pressure
ratio near 1) and the end stops are a 300 Hz contact. A fixed number of simplified
Newton iterations of an implicit Runge-Kutta step (Radau IIA) diverged in such
states; RK4's error stays bounded there (the fast modes exist only near a pressure
ratio of 1, in the valve law's laminar patch, which limits their growth) and is
typically 1e-4 mm in position per sample on the trajectories the loop runs. The interval map is therefore RK4 (defects exact); its
Jacobians are by default the (1, 2) Pade approximant (L-stable, 3rd order) of the
exponential of the continuous Jacobian at the interval's midpoint, 5x cheaper than
differentiating the RK4 steps (``sensitivities="exact"``) with the same closed-loop
tracking. With inexact Jacobians the SQP fixed point satisfies the dynamics exactly
but is only close to optimal (on the tests, 1e-3 V from IPOPT's commands);
``"exact"`` converges to the NLP's optimum.

The controller reads the full state (x, v, p_a, p_b) from the measurements the
simulator passes; its prediction model must therefore be a 4-state plant
(:meth:`NMPC.for_plant` reduces any plant file to one: lines, spool dynamics, heat
transfer and supply droop are left to the feedback). A force observer
(``disturbance_gain``) estimates what the model lacks (dry friction, a load) from
the velocity it mispredicted, which gives the loop integral action. The reference
is known only at the current sample (no preview): over the horizon it is
extrapolated along the current reference rate when that rate is below
``reference_rate_limit`` (a ramp), else held (a step).

Examples
--------
>>> from workbench import Plant, simulate, validate
>>> from workbench.controllers.mpc import NMPC
>>> plant = Plant.from_toml("designs/plants/rig25_mpye.toml")            # doctest: +SKIP
>>> nmpc = NMPC.for_plant(plant, horizon=20)                            # doctest: +SKIP
>>> run = simulate.closed_loop(plant, nmpc, validate.validation_profile(plant))  # doctest: +SKIP
>>> sol = nmpc.solve({"x": 0.25, "v": 0.0, "p_a": 4.5e5, "p_b": 4.5e5}, r=0.3)  # doctest: +SKIP
>>> sol.commands[0], sol.states[-1]                # V; x, v, p_a, p_b at the horizon's end
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import casadi as ca
import numpy as np

from ..errors import InputError

__all__ = ["NMPC", "NMPCState", "StepInfo", "Solution", "Recorder", "DoMPC", "prediction_model",
           "horizon_reference", "bench_reference", "bench"]

#: Effects that add states to a plant; :func:`prediction_model` removes them.
STATE_EFFECTS = ("valve_dynamics", "heat_transfer", "line_dynamics", "supply_droop")
#: The states the NMPC measures and predicts, in the plant's order.
NMPC_STATES = ("x", "v", "p_a", "p_b")
_MODES = ("rti", "sqp", "ipopt")
_SENSITIVITIES = ("pade", "exact")
_QP_SOLVERS = ("daqp", "qpoases", "osqp", "qrqp")
#: m/s: velocity scale of the scaled state (position and pressures scale by stroke
#: and supply pressure).
_V_SCALE = 1.0


def _meta(unit: str, doc: str) -> dict:
    return {"unit": unit, "doc": doc}


def prediction_model(plant, effects: Sequence[str] | None = None):
    """The plant reduced to the four states x, v, p_a, p_b, for prediction.

    Effects that add states are removed: spool dynamics, heat transfer, supply droop,
    and the lines, whose volume (pi/4 d^2 L_t each) is added to the dead volume of
    its chamber (the line's delay and resistance are left to the feedback). Of the
    other effects only those in ``effects`` are kept (default: all of them, e.g. dry
    friction, deadband, leakage). Dry friction takes its smooth (differentiable) form.

    Parameters
    ----------
    plant : workbench.Plant
    effects : sequence of str, optional
        Effects to keep; one that adds states is refused.

    Returns
    -------
    workbench.Plant
    """
    from ..plant import Plant
    params = plant.params
    have = tuple(plant.effects)
    keep = tuple(e for e in have if e not in STATE_EFFECTS) if effects is None else tuple(effects)
    bad = [e for e in keep if e in STATE_EFFECTS]
    if bad:
        raise InputError(f"the NMPC's prediction model has the states x, v, p_a, p_b only; "
                         f"effect(s) {', '.join(bad)} add states and cannot be kept")
    unknown = [e for e in keep if e not in have]
    if unknown:
        raise InputError(f"effect(s) {', '.join(unknown)} to keep are not in the plant "
                         f"(it has: {', '.join(have) or 'none'})")
    if "line_dynamics" in have:
        v_line = math.pi / 4.0 * params["lines.diameter"] ** 2 * params["lines.length"]
        params = params.replace(**{
            "cylinder.dead_volume_a": params["cylinder.dead_volume_a"] + v_line,
            "cylinder.dead_volume_b": params["cylinder.dead_volume_b"] + v_line})
    for e in have:
        if e not in keep:
            params = params.without_effect(e)
    return Plant(params, friction="smooth")


def horizon_reference(r: float, r_prev: float | None, sample_time: float, horizon: int,
                      rate_limit: float) -> tuple[np.ndarray, float]:
    """Reference over the horizon from its current and previous sample (no preview).

    Parameters
    ----------
    r, r_prev : m, reference now and one sample ago (``None``: first sample).
    sample_time : s. horizon : N. rate_limit : m/s.

    Returns
    -------
    (N + 1,) positions, m, at the shooting nodes, and the rate, m/s: r + rate k T
    if |rate| <= ``rate_limit`` (a ramp), else r held with rate 0 (a step).
    """
    rate = 0.0 if r_prev is None else (r - r_prev) / sample_time
    if not abs(rate) <= rate_limit:
        rate = 0.0
    return r + rate * sample_time * np.arange(horizon + 1), rate


# ---------------------------------------------------------------------- results
@dataclass(frozen=True)
class StepInfo:
    """What one controller update did.

    Attributes
    ----------
    iterations : SQP steps (RTI: 1) or IPOPT iterations.
    success : the QP / NLP solver succeeded (on failure the previous plan, shifted,
        is applied).
    restarted : the warm start was abandoned and the problem re-solved from rest
        (after a failed or diverged step).
    solve_time : s, wall time of the update (linearisation, QP, bookkeeping).
    slack_stroke : m, largest predicted violation of the stroke limits.
    slack_pressure : Pa, largest predicted violation of the pressure limits.
    slack_speed : m/s, largest predicted violation of the speed limit.
    """

    iterations: int
    success: bool
    solve_time: float
    restarted: bool = False
    slack_stroke: float = 0.0
    slack_pressure: float = 0.0
    slack_speed: float = 0.0


@dataclass(frozen=True, eq=False)
class NMPCState:
    """Controller memory between samples (the warm start).

    Attributes
    ----------
    X : casadi.DM (4, N + 1), predicted states, scaled (x/L, v/(1 m/s), p/p_supply).
    U : casadi.DM (1, N), planned commands, scaled ((u - centre)/span).
    u_prev : scaled command applied last. r_prev : m, reference at the last sample.
    z : (4,) measured state at the last sample, scaled.
    d : N, estimated disturbance force (along -x, like ``load.external_force``).
    lam : (lam_x, lam_g) of the last IPOPT solve (mode "ipopt"), else None.
    info : StepInfo of the last update.
    """

    X: Any
    U: Any
    u_prev: float
    r_prev: float
    z: np.ndarray
    d: float = 0.0
    lam: Any = None
    info: StepInfo | None = None


@dataclass(frozen=True, eq=False)
class Solution:
    """One solved NMPC problem in SI units.

    Attributes
    ----------
    time : (N + 1,) s from now. states : (N + 1, 4) predicted x, v, p_a, p_b (SI).
    commands : (N,) V, held over each interval. reference : (N + 1,) m.
    info : StepInfo. state : NMPCState to warm start the next problem.
    """

    time: np.ndarray
    states: np.ndarray
    commands: np.ndarray
    reference: np.ndarray
    info: StepInfo
    state: NMPCState


# ---------------------------------------------------------------------- controller
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
        RK4 steps per shooting interval.
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
    jit : bool
        Compile the linearisation to C (cached; needs a C compiler, else CasADi's
        virtual machine evaluates it).
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
    jit: bool = field(default=True, metadata=_meta("", "compile to C"))

    # ------------------------------------------------------------------ checks
    def __post_init__(self) -> None:
        model = self.model
        names = getattr(model, "state_names", None)
        if names is None:
            raise InputError(f"model must be a workbench.Plant, got {type(model).__name__}")
        if tuple(names) != NMPC_STATES:
            raise InputError(
                f"the NMPC predicts the states {', '.join(NMPC_STATES)} it measures; this "
                f"model has {', '.join(names)}. Build the prediction model with "
                "mpc.prediction_model(plant) or NMPC.for_plant(plant, ...)")
        if getattr(model, "friction", "smooth") != "smooth" and model.params.has_effect("dry_friction"):
            object.__setattr__(self, "model", model.with_friction("smooth"))
        pm = self.pressure_margin
        span = float(model.params["supply.pressure"]) - float(model.params["gas.atmospheric_pressure"])
        if isinstance(pm, bool) or not isinstance(pm, (int, float)) or not 0.0 <= pm < 0.25 * span:
            raise InputError(f"NMPC pressure_margin must be in [0, {0.25 * span:g}) Pa (a quarter "
                             f"of supply - atmosphere), got {pm!r}")
        if self.max_speed is not None and not (isinstance(self.max_speed, (int, float))
                                               and math.isfinite(self.max_speed)
                                               and self.max_speed > 0):
            raise InputError(f"NMPC max_speed must be > 0 m/s or None, got {self.max_speed!r}")
        for name in ("sample_time", "position_tolerance", "velocity_tolerance",
                     "command_rate_tolerance", "reference_rate_limit", "tolerance"):
            v = getattr(self, name)
            unit = self.__dataclass_fields__[name].metadata["unit"]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise InputError(f"NMPC {name} must be a finite number > 0 {unit}, got {v!r}")
        if not (isinstance(self.disturbance_gain, (int, float)) and 0.0 <= self.disturbance_gain <= 1.0):
            raise InputError(f"NMPC disturbance_gain must be in [0, 1], got {self.disturbance_gain!r}")
        if not (isinstance(self.terminal_factor, (int, float)) and self.terminal_factor >= 0):
            raise InputError(f"NMPC terminal_factor must be >= 0, got {self.terminal_factor!r}")
        for name, lo in (("horizon", 2), ("substeps", 1), ("max_iterations", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
                raise InputError(f"NMPC {name} must be an integer >= {lo}, got {v!r}")
        if self.mode not in _MODES:
            raise InputError(f"NMPC mode must be one of {', '.join(_MODES)}, got {self.mode!r}")
        if self.sensitivities not in _SENSITIVITIES:
            raise InputError(f"NMPC sensitivities must be 'pade' or 'exact', got {self.sensitivities!r}")
        if self.qp_solver not in _QP_SOLVERS:
            raise InputError(f"NMPC qp_solver must be one of {', '.join(_QP_SOLVERS)}, "
                             f"got {self.qp_solver!r}")
        if not ca.has_conic(self.qp_solver):
            raise InputError(f"this CasADi build has no QP solver '{self.qp_solver}'")
        L = model.stroke
        if not (isinstance(self.stroke_margin, (int, float)) and 0.0 <= self.stroke_margin < 0.25 * L):
            raise InputError(f"NMPC stroke_margin must be in [0, {0.25 * L:g}) m (a quarter of "
                             f"the stroke), got {self.stroke_margin!r}")
        w = tuple(self.slack_weights)
        if len(w) != 2 or not all(isinstance(x, (int, float)) and x > 0 for x in w):
            raise InputError(f"NMPC slack_weights are two numbers > 0 (L1, L2), got {self.slack_weights!r}")
        object.__setattr__(self, "slack_weights", (float(w[0]), float(w[1])))
        object.__setattr__(self, "_problem", _Problem(self))

    @classmethod
    def for_plant(cls, plant, effects: Sequence[str] | None = None, **settings) -> "NMPC":
        """NMPC whose prediction model is ``plant`` reduced by :func:`prediction_model`.

        ``sample_time`` defaults to the plant file's ``controller.sample_time`` when it
        has one.
        """
        if "sample_time" not in settings and plant.params.get("controller.sample_time"):
            settings["sample_time"] = float(plant.params["controller.sample_time"])
        return cls(prediction_model(plant, effects), **settings)

    def with_settings(self, **changes) -> "NMPC":
        """A copy with some settings changed (the model is kept)."""
        return replace(self, **changes)

    @property
    def kind(self) -> str:
        return f"NMPC ({self.mode}, N = {self.horizon})"

    # ------------------------------------------------------------------ protocol
    def reset(self) -> None:
        """No memory before the first sample (it starts from rest at the measured state)."""
        return None

    def update(self, state: NMPCState | None, r: float, y: dict) -> tuple[NMPCState, float]:
        """(new state, command in V) from the reference (m) and measured x, v, p_a, p_b (SI)."""
        pb = self._problem
        new = pb.advance(y, float(r), state)
        return new, pb.u_c + pb.u_s * new.u_prev

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
        new = pb.advance(y, float(r), state)
        return pb.solution(new, float(r), None if state is None else state.r_prev)


class _Problem:
    """The discretised problem and its compiled functions (built once per NMPC)."""

    def __init__(self, c: NMPC) -> None:
        self.c = c
        m = c.model
        prm = m.params
        self.N = N = int(c.horizon)
        self.T = T = float(c.sample_time)
        self.L = L = float(m.stroke)
        self.p_sup = p_sup = float(prm["supply.pressure"])
        self.p_atm = p_atm = float(prm["gas.atmospheric_pressure"])
        self.u_c = float(prm["valve.command_center"])
        self.u_s = float(prm["valve.command_span"])
        self.w_lo = (float(prm["valve.command_min"]) - self.u_c) / self.u_s
        self.w_hi = (float(prm["valve.command_max"]) - self.u_c) / self.u_s
        self.sx = np.array([L, _V_SCALE, p_sup, p_sup])
        self.nx = nx = 4
        # scaled limits of the constrained states
        mg = float(c.stroke_margin)
        pm = float(c.pressure_margin) / p_sup
        self.lo = {0: mg / L, 2: p_atm / p_sup + pm, 3: p_atm / p_sup + pm}
        self.hi = {0: (L - mg) / L, 2: 1.0 - pm, 3: 1.0 - pm}
        # soft constraints: (state index, slack index); slacks: stroke, pressure, speed
        self.soft = [(0, 0), (2, 1), (3, 1)]
        if c.max_speed is not None:
            self.lo[1], self.hi[1] = -c.max_speed / _V_SCALE, c.max_speed / _V_SCALE
            self.soft.append((1, 2))
        self.ns = 1 + max(j for _, j in self.soft)
        # weights of the 1/2-sum-of-squares cost in scaled variables
        wx = (L / c.position_tolerance) ** 2
        wv = (_V_SCALE / c.velocity_tolerance) ** 2
        tf = float(c.terminal_factor)
        self.P = np.concatenate([
            [wx] * (N - 1) + [tf * wx], [wv] * (N - 1) + [tf * wv],
            [(self.u_s / c.command_rate_tolerance) ** 2, *c.slack_weights],
            [self.lo.get(i, -1e3) for i in range(nx)], [self.hi.get(i, 1e3) for i in range(nx)],
            [c.disturbance_gain]])

        # ---- model, scaled: z = x / sx, w = (u - u_c) / u_s
        z = ca.SX.sym("z", nx)
        w = ca.SX.sym("w")
        d = ca.SX.sym("d")                                 # estimated disturbance force, N
        pvec = ca.DM(m.p0) + d * ca.DM(np.eye(len(m.p0))[:, m.param_index("load.external_force")])
        fz = m.f(z * ca.DM(self.sx), self.u_c + self.u_s * w, pvec) / ca.DM(self.sx)
        fc = ca.Function("wb_nmpc_f", [z, w, d], [fz])
        h = T / c.substeps
        zz = z
        for _ in range(c.substeps):
            k1 = fc(zz, w, d)
            k2 = fc(zz + h / 2 * k1, w, d)
            k3 = fc(zz + h / 2 * k2, w, d)
            k4 = fc(zz + h * k3, w, d)
            zz = zz + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        self.F = ca.Function("wb_nmpc_F", [z, w, d], [zz])
        if c.sensitivities == "exact":
            jac = [ca.jacobian(zz, z), ca.jacobian(zz, w)]
        else:
            zm = (z + zz) / 2
            ja = ca.substitute(ca.jacobian(fz, ca.vertcat(z, w)), z, zm)
            xa = T * ca.vertcat(ja, ca.SX.zeros(1, nx + 1))
            eye = ca.SX.eye(nx + 1)
            # (1, 2) Pade approximant of expm: L-stable, 3rd order
            phi = ca.solve(eye - 2.0 / 3.0 * xa + ca.mtimes(xa, xa) / 6.0, eye + xa / 3.0)
            jac = [phi[:nx, :nx], phi[:nx, nx]]
        self.Fj = ca.Function("wb_nmpc_Fj", [z, w, d], [zz] + jac)
        self.mass = float(prm["load.mass"])
        self.d_max = 0.5 * (p_sup - p_atm) * m.area_a   # N, estimate bound (anti wind-up)
        prep, post = self._build_prep(), self._build_post()
        if c.jit:
            from .._jit import compiled
            prep, post = compiled(prep), compiled(post)
        self.qp = self._conic(N + self.ns, 2 * N * len(self.soft))
        self.step = self._build_step(prep, post)
        self._nlp = None

    def _unpack(self, P):
        N, nx = self.N, self.nx
        return (P[:N], P[N:2 * N], P[2 * N], P[2 * N + 1], P[2 * N + 2],
                P[2 * N + 3:2 * N + 3 + nx], P[2 * N + 3 + nx:2 * N + 3 + 2 * nx])

    def _estimate(self, zprev, wprev, dprev, x0, est, gain):
        """Disturbance force (N) from the velocity the model predicted for this sample.

        d_k = d_{k-1} + gain m (v_pred - v_meas) / T, v_pred from the previous measured
        state and the command applied since; bounded by +-d_max.
        """
        vpred = self.F(zprev, wprev, dprev)[1]
        d = dprev + est * gain * self.mass * (vpred - x0[1]) * _V_SCALE / self.T
        return ca.fmin(ca.fmax(d, -self.d_max), self.d_max)

    # ------------------------------------------------------------------ QP data
    def _build_condense(self) -> ca.Function:
        """Condensed Gauss-Newton QP from interval sensitivities (SX, scalar code)."""
        N, nx, ns = self.N, self.nx, self.ns
        A_ = ca.SX.sym("A", nx, nx * N)
        B_ = ca.SX.sym("B", nx, N)
        c = ca.SX.sym("c", nx, N)                          # shooting defects
        dz0 = ca.SX.sym("dz0", nx)                         # measured - guessed x_0
        X = ca.SX.sym("X", nx, N + 1)
        U = ca.SX.sym("U", 1, N)
        R = ca.SX.sym("R", 1, N + 1)
        VR = ca.SX.sym("VR", 1, N + 1)
        up = ca.SX.sym("up")
        P = ca.SX.sym("P", self.P.size)
        wx, wv, wdu, rho1, rho2, lo, hi = self._unpack(P)
        # dz_k = h_k + G_k dw, G_k with k non-zero columns
        hs, Gs = [dz0], [ca.SX(nx, 0)]
        for k in range(N):
            A = A_[:, k * nx:(k + 1) * nx]
            Gs.append(ca.horzcat(ca.mtimes(A, Gs[-1]), B_[:, k]))
            hs.append(ca.mtimes(A, hs[-1]) + c[:, k])
        Gf = [ca.horzcat(G, ca.SX(nx, N - G.shape[1])) for G in Gs]
        Hh = ca.horzcat(*hs)
        Xp = X + Hh                                        # states at dw = 0
        S = [ca.vertcat(*[Gf[k][i, :] for k in range(1, N + 1)]) for i in range(nx)]
        ex = (Xp[0, 1:] - R[0, 1:]).T
        ev = (Xp[1, 1:] - VR[0, 1:]).T
        D = np.eye(N) - np.eye(N, k=-1)
        e0 = np.zeros(N)
        e0[0] = 1.0
        Wx = ca.repmat(wx, 1, N)
        Wv = ca.repmat(wv, 1, N)
        Hc = (ca.mtimes(S[0].T, S[0] * Wx) + ca.mtimes(S[1].T, S[1] * Wv)
              + wdu * ca.DM(D.T @ D))
        gc = (ca.mtimes(S[0].T, wx * ex) + ca.mtimes(S[1].T, wv * ev)
              + wdu * ca.mtimes(ca.DM(D.T), ca.mtimes(ca.DM(D), U.T) - ca.DM(e0) * up))
        H = ca.diagcat(Hc, rho2 * ca.SX.eye(ns))
        g = ca.vertcat(gc, rho1 * ca.SX.ones(ns))
        one = ca.DM.ones(N, 1)
        rows, lb, ub = [], [], []
        for i, j in self.soft:
            v = Xp[i, 1:].T
            e = ca.DM.zeros(N, ns)
            e[:, j] = 1.0
            rows += [ca.horzcat(S[i], e), ca.horzcat(S[i], -e)]
            lb += [lo[i] - v, -ca.inf * one]
            ub += [ca.inf * one, hi[i] - v]
        lbx = ca.vertcat(self.w_lo - U.T, ca.DM.zeros(ns))
        ubx = ca.vertcat(self.w_hi - U.T, ca.inf * ca.DM.ones(ns))
        return ca.Function("wb_nmpc_condense", [A_, B_, c, dz0, X, U, R, VR, up, P],
                           [ca.densify(H), ca.densify(g), ca.densify(ca.vertcat(*rows)),
                            ca.vertcat(*lb), ca.vertcat(*ub), lbx, ubx, Hh,
                            ca.densify(ca.vertcat(*Gf))])

    def _build_prep(self) -> ca.Function:
        """(previous plan, shift?, measured state, reference, settings) -> QP data."""
        N, nx = self.N, self.nx
        Xp = ca.MX.sym("Xp", nx, N + 1)
        Up = ca.MX.sym("Up", 1, N)
        shift = ca.MX.sym("shift")
        x0 = ca.MX.sym("x0", nx)
        r = ca.MX.sym("r")                                 # reference now, scaled
        rate = ca.MX.sym("rate")                           # its rate, scaled per s
        up = ca.MX.sym("up")
        zprev = ca.MX.sym("zprev", nx)                     # measured state one sample ago
        dprev = ca.MX.sym("dprev")                         # disturbance estimate then, N
        est = ca.MX.sym("est")                             # 1: update the estimate
        P = ca.MX.sym("P", self.P.size)
        d = self._estimate(zprev, up, dprev, x0, est, P[-1])
        X = ca.if_else(shift, ca.horzcat(Xp[:, 1:], Xp[:, N]), Xp)
        U = ca.if_else(shift, ca.horzcat(Up[:, 1:], Up[:, N - 1]), Up)
        kk = ca.DM(np.arange(N + 1)).T
        R = r + rate * self.T * kk
        VR = ca.repmat(rate * self.L / _V_SCALE, 1, N + 1)
        Xn, A, B = self.Fj.map(N)(X[:, :N], U, ca.repmat(d, 1, N))
        out = self._build_condense()(A, B, Xn - X[:, 1:], x0 - X[:, 0], X, U, R, VR, up, P)
        return ca.Function("wb_nmpc_prep", [Xp, Up, shift, x0, r, rate, up, zprev, dprev, est, P],
                           [*out, X, U, d])

    def _build_post(self) -> ca.Function:
        """Apply the QP step: new plan, first command, predicted violations, sanity."""
        N, nx, ns = self.N, self.nx, self.ns
        X = ca.SX.sym("X", nx, N + 1)
        U = ca.SX.sym("U", 1, N)
        h = ca.SX.sym("h", nx, N + 1)
        G = ca.SX.sym("G", nx * (N + 1), N)
        dw = ca.SX.sym("dw", N + ns)
        P = ca.SX.sym("P", self.P.size)
        _, _, _, _, _, lo, hi = self._unpack(P)
        du = dw[:N]
        Un = U + du.T
        Xn = X + h + ca.reshape(ca.mtimes(G, du), nx, N + 1)
        viol = ca.vertcat(*[ca.fmax(0.0, ca.fmax(ca.mmax(lo[i] - Xn[i, 1:]),
                                                   ca.mmax(Xn[i, 1:] - hi[i])))
                            for i in range(nx)])
        tot = ca.sum1(dw) + ca.sum1(ca.sum2(Xn))
        ok = ca.logic_and(tot == tot,                      # no NaN
                          ca.logic_and(ca.mmax(ca.fabs(ca.vec(Xn))) < 1e2,
                                       ca.logic_and(ca.mmin(Un) >= self.w_lo - 1e-6,
                                                    ca.mmax(Un) <= self.w_hi + 1e-6)))
        Un = ca.fmin(ca.fmax(Un, self.w_lo), self.w_hi)    # the QP's tolerance, not a clip
        return ca.Function("wb_nmpc_post", [X, U, h, G, dw, P],
                           [Xn, Un, Un[0], viol, ok, ca.mmax(ca.fabs(du))])

    def _conic(self, nz: int, nc: int) -> ca.Function:
        hs, As = ca.Sparsity.dense(nz, nz), ca.Sparsity.dense(nc, nz)
        name = self.c.qp_solver
        opts: dict[str, Any] = {"error_on_fail": False}
        if name == "qpoases":
            opts.update(printLevel="none", sparse=False)
        elif name == "osqp":
            opts.update(warm_start_primal=True,
                        osqp={"verbose": False, "eps_abs": 1e-8, "eps_rel": 1e-8,
                              "polish": True, "max_iter": 20000})
        elif name == "qrqp":
            opts.update(print_iter=False, print_header=False, print_info=False)
        return ca.conic("wb_nmpc_qp", name, {"h": hs, "a": As}, opts)

    def _build_step(self, prep: ca.Function, post: ca.Function) -> ca.Function:
        """One Gauss-Newton SQP step as a single call: prep (C), QP, post (C)."""
        ins = [ca.MX.sym(prep.name_in(i), prep.sparsity_in(i)) for i in range(prep.n_in())]
        o = prep(*ins)
        sol = self.qp(h=o[0], g=o[1], a=o[2], lba=o[3], uba=o[4], lbx=o[5], ubx=o[6])
        res = post(o[9], o[10], o[7], o[8], sol["x"], ins[-1])
        return ca.Function("wb_nmpc_step", ins, [*res, o[11]],
                           ["Xp", "Up", "shift", "x0", "r", "rate", "up", "zprev", "dprev",
                            "est", "P"],
                           ["X", "U", "u0", "viol", "ok", "step", "d"])

    # ------------------------------------------------------------------ solving
    def _cold(self, zm: np.ndarray):
        return ca.DM(np.tile(zm[:, None], (1, self.N + 1))), ca.DM.zeros(1, self.N)

    def _sqp(self, X, U, shift: bool, zm, r, rate, u_prev, zprev, dprev, est, iters: int):
        """Up to ``iters`` full Gauss-Newton steps; stops at a step below tolerance."""
        ok, it, viol, d = False, 0, None, dprev
        sh = 1.0 if shift else 0.0
        for it in range(1, iters + 1):
            Xn, Un, _, viol, okk, stp, dd = self.step(X, U, sh, zm, r, rate, u_prev, zprev,
                                                      dprev, est, self.P)
            ok = bool(okk)
            if it == 1:
                d = dprev = float(dd)
                est = 0.0
            if not ok:
                break
            X, U, sh = Xn, Un, 0.0
            if float(stp) < self.c.tolerance:
                break
        return X, U, it, ok, viol, d

    def advance(self, y: dict, r: float, state: NMPCState | None) -> NMPCState:
        """One controller update: the new memory (its U[0] is the command)."""
        t0 = time.perf_counter()
        c = self.c
        try:
            zm = np.array([y["x"], y["v"], y["p_a"], y["p_b"]], dtype=float) / self.sx
        except KeyError as exc:
            raise InputError(f"the NMPC needs the measured {exc} (it measures x, v, p_a, p_b)") from None
        _, rate = horizon_reference(r, None if state is None else state.r_prev, self.T, 1,
                                    c.reference_rate_limit)
        rs, rates = r / self.L, rate / self.L
        if state is None:
            u_prev, zprev, dprev, est = 0.0, zm, 0.0, 0.0
        else:
            u_prev, zprev, dprev, est = state.u_prev, state.z, state.d, 1.0
        warm = state is not None and c.warm_start
        restarted, lam = False, None
        if c.mode == "ipopt":
            d = float(self._estimate(zprev, u_prev, dprev, zm, est, c.disturbance_gain))
            X, U = (state.X, state.U) if warm else self._cold(zm)
            X, U, it, ok, lam = self._ipopt(X, U, warm, zm, rs, rates, u_prev, d,
                                            state.lam if warm else None)
            viol = None
        else:
            if warm:
                iters = 1 if c.mode == "rti" else c.max_iterations
                X, U, it, ok, viol, d = self._sqp(state.X, state.U, True, zm, rs, rates, u_prev,
                                                  zprev, dprev, est, iters)
                dprev, est = d, 0.0
            else:
                ok = False
            if not ok:                                     # first sample, or the warm start failed
                restarted = warm
                iters = c.max_iterations if (state is None or c.mode != "rti" or restarted) else 1
                X, U = self._cold(zm)
                X, U, it, ok, viol, d = self._sqp(X, U, False, zm, rs, rates, u_prev,
                                                  zprev, dprev, est, iters)
        if not ok:                                         # keep the previous plan, shifted
            if state is not None:
                X = ca.horzcat(state.X[:, 1:], state.X[:, -1])
                U = ca.horzcat(state.U[:, 1:], state.U[:, -1])
            else:
                X, U = self._cold(zm)
        w0 = float(U[0])
        v = np.zeros(4) if viol is None or not ok else np.asarray(viol).ravel()
        info = StepInfo(iterations=it, success=ok, solve_time=time.perf_counter() - t0,
                        restarted=restarted, slack_stroke=max(v[0], 0.0) * self.L,
                        slack_pressure=max(v[2], v[3]) * self.p_sup,
                        slack_speed=v[1] * _V_SCALE if c.max_speed is not None else 0.0)
        return NMPCState(X=X, U=U, u_prev=w0, r_prev=r, z=zm, d=d, lam=lam, info=info)

    def solution(self, state: NMPCState, r: float, r_prev: float | None) -> Solution:
        """The memory of an update as a Solution in SI units."""
        R, _ = horizon_reference(r, r_prev, self.T, self.N, self.c.reference_rate_limit)
        X = np.asarray(state.X)
        return Solution(time=self.T * np.arange(self.N + 1), states=(X * self.sx[:, None]).T,
                        commands=self.u_c + self.u_s * np.asarray(state.U).ravel(),
                        reference=R, info=state.info, state=state)

    # ------------------------------------------------------------------ IPOPT
    def _build_nlp(self):
        """The multiple-shooting NLP (same discretisation, cost and limits) for IPOPT."""
        N, nx, ns = self.N, self.nx, self.ns
        X = ca.MX.sym("X", nx, N + 1)
        U = ca.MX.sym("U", 1, N)
        s = ca.MX.sym("s", ns)
        x0 = ca.MX.sym("x0", nx)
        r = ca.MX.sym("r")
        rate = ca.MX.sym("rate")
        up = ca.MX.sym("up")
        d = ca.MX.sym("d")
        P = ca.MX.sym("P", self.P.size)
        wx, wv, wdu, rho1, rho2, lo, hi = self._unpack(P)
        R = r + rate * self.T * ca.DM(np.arange(N + 1)).T
        Xn = self.F.map(N)(X[:, :N], U, ca.repmat(d, 1, N))
        ex = (X[0, 1:] - R[0, 1:]).T
        ev = X[1, 1:].T - rate * self.L / _V_SCALE
        du = ca.vertcat(U[0, 0] - up, (U[0, 1:] - U[0, :-1]).T)
        J = 0.5 * (ca.dot(wx * ex, ex) + ca.dot(wv * ev, ev) + wdu * ca.dot(du, du)) \
            + rho1 * ca.sum1(s) + 0.5 * rho2 * ca.dot(s, s)
        g = [X[:, 0] - x0, ca.vec(Xn - X[:, 1:])]
        for i, k_s in self.soft:
            g += [X[i, 1:].T + s[k_s] - lo[i], X[i, 1:].T - s[k_s] - hi[i]]
        n_eq = nx * (N + 1)
        nlp = {"x": ca.vertcat(ca.vec(X), U.T, s), "p": ca.vertcat(x0, r, rate, up, d, P),
               "f": J, "g": ca.vertcat(*g)}
        ip = {"print_level": 0, "sb": "yes", "max_iter": 10 * self.c.max_iterations, "tol": 1e-8}
        opts = {"print_time": False, "ipopt": ip}
        self._nlp = ca.nlpsol("wb_nmpc_nlp", "ipopt", nlp, opts)
        # warm start: primal and dual guesses from the previous solution, shifted;
        # small bound pushes and barrier so IPOPT does not move away from them first
        warm = dict(ip, warm_start_init_point="yes", warm_start_bound_push=1e-8,
                    warm_start_mult_bound_push=1e-8, warm_start_slack_bound_push=1e-8,
                    mu_init=1e-6)
        self._nlp_warm_args = ("wb_nmpc_nlp_warm", "ipopt", nlp, dict(opts, ipopt=warm))
        self._nlp_warm = None
        self._lbg = np.concatenate([np.zeros(n_eq)]
                                   + [np.zeros(N), -np.inf * np.ones(N)] * len(self.soft))
        self._ubg = np.concatenate([np.zeros(n_eq)]
                                   + [np.inf * np.ones(N), np.zeros(N)] * len(self.soft))
        nw = nx * (N + 1) + N + ns
        lbw, ubw = -np.inf * np.ones(nw), np.inf * np.ones(nw)
        lbw[nx * (N + 1):nx * (N + 1) + N] = self.w_lo
        ubw[nx * (N + 1):nx * (N + 1) + N] = self.w_hi
        lbw[-ns:] = 0.0
        self._lbw, self._ubw = lbw, ubw

    def _shift_duals(self, lam):
        """Multipliers of the previous NLP moved one sample on (last one repeated)."""
        N, nx = self.N, self.nx
        lam_x, lam_g = (np.asarray(v, dtype=float).ravel().copy() for v in lam)
        n_eq = nx * (N + 1)
        eq = lam_g[:n_eq].reshape(N + 1, nx)
        lam_g[:n_eq] = np.vstack([eq[1:], eq[-1:]]).ravel()
        rows = lam_g[n_eq:].reshape(-1, N)
        lam_g[n_eq:] = np.hstack([rows[:, 1:], rows[:, -1:]]).ravel()
        lu = lam_x[n_eq:n_eq + N]
        lam_x[n_eq:n_eq + N] = np.append(lu[1:], lu[-1])
        return lam_x, lam_g

    def _ipopt(self, X, U, shift: bool, zm, r, rate, u_prev, d, lam=None):
        if self._nlp is None:
            self._build_nlp()
        N, nx = self.N, self.nx
        X, U = np.asarray(X), np.asarray(U).ravel()
        if shift:
            X = np.hstack([X[:, 1:], X[:, -1:]])
            U = np.append(U[1:], U[-1])
        w0 = np.concatenate([X.ravel(order="F"), U, np.zeros(self.ns)])
        p = np.concatenate([zm, [r, rate, u_prev, d], self.P])
        args = dict(x0=w0, p=p, lbx=self._lbw, ubx=self._ubw, lbg=self._lbg, ubg=self._ubg)
        solver = self._nlp
        if shift and lam is not None:
            args["lam_x0"], args["lam_g0"] = self._shift_duals(lam)
            if self._nlp_warm is None:
                self._nlp_warm = ca.nlpsol(*self._nlp_warm_args)
            solver = self._nlp_warm
        sol = solver(**args)
        st = solver.stats()
        w = np.asarray(sol["x"]).ravel()
        X = ca.DM(w[:nx * (N + 1)].reshape(N + 1, nx).T)
        U = ca.DM(w[nx * (N + 1):nx * (N + 1) + N][None, :])
        return (X, U, int(st.get("iter_count", 0)), bool(st.get("success", False)),
                (np.asarray(sol["lam_x"]), np.asarray(sol["lam_g"])))


# ---------------------------------------------------------------------- recorder
class Recorder:
    """Wraps a controller and keeps every update's wall time and (NMPC) StepInfo.

    Runs in :func:`workbench.simulate.closed_loop` like the controller it wraps.

    Attributes
    ----------
    times : list of float, s, wall time of each ``update``.
    infos : list of StepInfo (None for controllers without one).
    commands : list of float, V, the command returned (before the simulator clips it).
    """

    def __init__(self, controller) -> None:
        self.controller = controller
        self.sample_time = controller.sample_time
        self.times: list[float] = []
        self.infos: list[StepInfo | None] = []
        self.commands: list[float] = []

    @property
    def kind(self) -> str:
        return getattr(self.controller, "kind", type(self.controller).__name__)

    def reset(self):
        self.times.clear()
        self.infos.clear()
        self.commands.clear()
        return self.controller.reset()

    def update(self, state, r, y):
        t0 = time.perf_counter()
        new, u = self.controller.update(state, r, y)
        self.times.append(time.perf_counter() - t0)
        self.infos.append(getattr(new, "info", None))
        self.commands.append(float(u))
        return new, u


# ---------------------------------------------------------------------- do-mpc baseline
class DoMPC:
    """The same NMPC problem set up in do-mpc (optional baseline for :func:`bench`).

    do-mpc discretises the continuous model by its default orthogonal collocation
    (Radau, degree 2, one element per sample) and solves the NLP with IPOPT, its
    defaults (output silenced). Same horizon, scaled variables, cost (stage terms
    at nodes 1..N-1, terminal factor at N, command-move penalty including the last
    applied command) and limits (command range as bounds; stroke, pressure and speed
    as soft constraints with one slack per constraint over the horizon and the same
    L1 weight; ours adds a small quadratic slack term). The disturbance observer is
    not part of it: compare against ``disturbance_gain=0``.

    Needs ``do-mpc`` (5.1.2 works with CasADi 3.8); raises ImportError without it.
    do-mpc objects are mutable: the instance keeps the solver's memory itself.
    """

    def __init__(self, nmpc: NMPC) -> None:
        import warnings
        with warnings.catch_warnings():
            # do-mpc warns about its optional features (ONNX, OPC UA, torch) on import and
            # casadi about do-mpc's numpy calls on casadi values: noise for a baseline
            warnings.simplefilter("ignore")
            self._setup(nmpc)

    def _setup(self, nmpc: NMPC) -> None:
        import do_mpc
        self.version = getattr(do_mpc, "__version__", "?")
        self.nmpc = nmpc
        self.sample_time = nmpc.sample_time
        pb = nmpc._problem
        self._pb = pb
        N, T = pb.N, pb.T
        model = do_mpc.model.Model("continuous", "SX")
        z = model.set_variable("_x", "z", shape=(4, 1))
        w = model.set_variable("_u", "w")
        r = model.set_variable("_tvp", "r")
        vr = model.set_variable("_tvp", "vr")
        sx = ca.DM(pb.sx)
        m = nmpc.model
        model.set_rhs("z", m.f(z * sx, pb.u_c + pb.u_s * w, ca.DM(m.p0)) / sx)
        model.setup()
        mpc = do_mpc.controller.MPC(model)
        mpc.settings.n_horizon = N
        mpc.settings.t_step = T
        mpc.settings.store_full_solution = False
        mpc.settings.nl_cons_single_slack = True
        mpc.settings.supress_ipopt_output()
        wx, wv, wdu, rho1, _, lo, hi = pb._unpack(pb.P)
        wx_s, wv_s, tf = float(wx[0]), float(wv[0]), float(wx[-1] / wx[0])
        stage = 0.5 * (wx_s * (z[0] - r) ** 2 + wv_s * (z[1] - vr) ** 2)
        mpc.set_objective(lterm=stage, mterm=tf * stage)
        mpc.set_rterm(w=0.5 * float(wdu))
        mpc.bounds["lower", "_u", "w"] = pb.w_lo
        mpc.bounds["upper", "_u", "w"] = pb.w_hi
        names = {0: "stroke", 1: "speed", 2: "p_a", 3: "p_b"}
        for i, _ in pb.soft:
            mpc.set_nl_cons(f"{names[i]}_lo", float(lo[i]) - z[i], ub=0.0, soft_constraint=True,
                            penalty_term_cons=float(rho1))
            mpc.set_nl_cons(f"{names[i]}_hi", z[i] - float(hi[i]), ub=0.0, soft_constraint=True,
                            penalty_term_cons=float(rho1))
        tvp = mpc.get_tvp_template()
        self._ref = (0.0, None)

        def tvp_fun(t_now):
            r_now, r_prev = self._ref
            R, rate = horizon_reference(r_now, r_prev, T, N, nmpc.reference_rate_limit)
            for k in range(N + 1):
                tvp["_tvp", k, "r"] = R[k] / pb.L
                tvp["_tvp", k, "vr"] = rate / _V_SCALE
            return tvp

        mpc.set_tvp_fun(tvp_fun)
        mpc.setup()
        self.mpc = mpc

    @property
    def kind(self) -> str:
        return f"do-mpc {self.version} (IPOPT, N = {self._pb.N})"

    def reset(self):
        return None

    def update(self, state, r: float, y: dict):
        pb = self._pb
        z0 = np.array([y["x"], y["v"], y["p_a"], y["p_b"]]) / pb.sx
        if state is None:
            self.mpc.reset_history()
            self.mpc.x0 = z0
            self.mpc.u0 = np.zeros(1)
            self.mpc.set_initial_guess()
            self._ref = (float(r), None)
        else:
            self._ref = (float(r), state)
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            w = float(np.asarray(self.mpc.make_step(z0.reshape(-1, 1))).ravel()[0])
        return float(r), pb.u_c + pb.u_s * w


# ---------------------------------------------------------------------- benchmark
#: Plant of the benchmark (issue: the 25 mm reference plant, 4 states).
BENCH_PLANT = "designs/plants/rig25_mpye.toml"


def bench_reference(plant, duration: float = 20.0):
    """The standard validation profile compressed to ``duration`` (>= 9 s) seconds.

    Its holds are shortened so that the whole profile (steps of 125, 250 and 10 mm
    both ways, ramps at 0.1 m/s) lasts ``duration``.
    """
    from ..references import validation_profile
    L = plant.stroke
    fixed = 0.5 + (0.9 * L - 0.25 * L) / (0.2 * L) + (0.8 * L) / (0.2 * L)   # start hold + ramps
    hold = (duration - fixed) / 6.0
    if hold <= 0.2:
        raise InputError(f"the validation profile needs more than {fixed + 1.2:g} s")
    return validation_profile(plant, hold=hold)


def _timed(controller):
    """Recorder that also keeps the thread CPU time of each update."""
    rec = Recorder(controller)
    cpu: list[float] = []
    inner = rec.update

    def update(state, r, y):
        t0 = time.thread_time()
        out = inner(state, r, y)
        cpu.append(time.thread_time() - t0)
        return out

    rec.update = update
    rec.cpu = cpu
    return rec


def _iae(run) -> float:
    e = np.abs(run.reference - run["x"])
    return float(np.sum(0.5 * (e[1:] + e[:-1]) * np.diff(run.time)))


def bench(quick: bool = False, jit: bool = True) -> dict:
    """NMPC solve time per control step, ours against do-mpc on the same problem.

    Horizon 20 samples of 10 ms on ``designs/plants/rig25_mpye.toml`` (4 states), the
    standard validation profile compressed to 20 s (``quick``: its first 3 s), run in
    :func:`workbench.simulate.closed_loop` on the nominal plant. Times are wall
    clock per ``update`` call (everything the controller does in a sample; the
    first sample, which runs SQP to convergence, included), with the thread CPU
    time beside them (robust to other load on the machine). The disturbance observer
    is off (do-mpc has none), so every controller solves the same problem.

    Ours runs twice: the default real-time iteration (one Gauss-Newton step per
    sample; the headline ``median_ms``, ``p99_ms``) and SQP to convergence capped at
    5 steps per sample (``sqp_*``), which reaches the optimum do-mpc's IPOPT finds.

    Returns
    -------
    dict
        ``median_ms``, ``p99_ms`` (ours, RTI), ``do_mpc_median_ms`` (None without
        do-mpc), ``speedup_vs_do_mpc`` (do-mpc median / ours), ``iae_m_s`` and
        ``do_mpc_iae_m_s`` (integral of |r - x|, m s), the same for SQP, maximum
        errors, CPU times and notes.
    """
    from pathlib import Path

    from .. import simulate
    from ..plant import Plant
    root = Path(__file__).resolve().parents[2]
    plant = Plant.from_toml(root / BENCH_PLANT)
    duration = 3.0 if quick else 20.0
    ref = bench_reference(plant, 20.0)
    t_build = time.perf_counter()
    nmpc = NMPC.for_plant(plant, horizon=20, sample_time=0.01, disturbance_gain=0.0, jit=jit)
    t_build = time.perf_counter() - t_build
    sqp = nmpc.with_settings(mode="sqp", max_iterations=5)
    out: dict[str, Any] = {"plant": BENCH_PLANT, "horizon": nmpc.horizon,
                           "sample_time_s": nmpc.sample_time, "simulated_s": duration,
                           "mode": nmpc.mode, "qp_solver": nmpc.qp_solver,
                           "substeps": nmpc.substeps, "sensitivities": nmpc.sensitivities,
                           "jit": jit, "build_s": t_build}

    def run(ctrl, prefix: str) -> None:
        rec = _timed(ctrl)
        traj = simulate.closed_loop(plant, rec, ref, t_end=duration, x0=ref(0.0), progress=False)
        ms = np.array(rec.times) * 1e3
        cpu = np.array(rec.cpu) * 1e3
        out.update({f"{prefix}median_ms": float(np.median(ms)),
                    f"{prefix}p99_ms": float(np.percentile(ms, 99)),
                    f"{prefix}max_ms": float(np.max(ms)),
                    f"{prefix}cpu_median_ms": float(np.median(cpu)),
                    f"{prefix}cpu_p99_ms": float(np.percentile(cpu, 99)),
                    f"{prefix}iae_m_s": _iae(traj),
                    f"{prefix}max_error_m": float(np.max(np.abs(traj.reference - traj["x"])))})
        infos = [i for i in rec.infos if i is not None]
        if infos:
            out.update({f"{prefix}iterations_mean": float(np.mean([i.iterations for i in infos])),
                        f"{prefix}qp_failures": int(sum(not i.success for i in infos)),
                        f"{prefix}restarts": int(sum(i.restarted for i in infos))})
        else:
            out[f"{prefix}steps"] = len(ms)

    run(nmpc, "")
    out["steps"] = int(round(duration / nmpc.sample_time)) + 1
    run(sqp, "sqp_")
    notes = []
    try:
        dm = DoMPC(nmpc)
    except ImportError:
        dm = None
        notes.append("do-mpc is not installed (pip install do-mpc==5.1.2): no baseline")
    keys = ("median_ms", "p99_ms", "max_ms", "cpu_median_ms", "cpu_p99_ms", "iae_m_s",
            "max_error_m")
    if dm is not None:
        out["do_mpc_version"] = dm.version
        run(dm, "do_mpc_")
        out.pop("do_mpc_steps", None)
        for pre in ("", "sqp_"):
            out[f"{pre}speedup_vs_do_mpc"] = out["do_mpc_median_ms"] / out[f"{pre}median_ms"]
            out[f"{pre}iae_ratio_vs_do_mpc"] = out[f"{pre}iae_m_s"] / out["do_mpc_iae_m_s"]
    else:
        out["do_mpc_version"] = None
        out.update({f"do_mpc_{k}": None for k in keys})
        for pre in ("", "sqp_"):
            out[f"{pre}speedup_vs_do_mpc"] = None
            out[f"{pre}iae_ratio_vs_do_mpc"] = None
    out["target"] = {"median_ms": 1.0, "p99_ms": 5.0, "speedup_vs_do_mpc": 10.0}
    out["meets_target"] = bool(out["median_ms"] < 1.0 and out["p99_ms"] < 5.0)
    out["notes"] = notes
    return out
