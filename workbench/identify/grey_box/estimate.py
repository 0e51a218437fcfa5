"""Grey-box estimation: :func:`estimate`, in steps that read top to bottom.

Check the options, resolve the parameters (:mod:`.parameters`), prepare the data
(:mod:`.data`), build the multiple-shooting problem (:mod:`.problem`), start it from the
data, solve it with IPOPT, compute the covariance (:mod:`.covariance`) and the residual
statistics, replay the recordings before and after on CVODES (:mod:`workbench.replay`),
and give the verdict (:mod:`.verdict`).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from ... import replay as _rp
from ...errors import InputError, WorkbenchError
from ...integrate import jit as _jit
from ...plant import Plant
from ...recording import Recording, fit as nrmse_fit
from .covariance import _covariance, _stationary
from .data import _Data, _first_value, _initial_state, _prepare, _smooth_derivative, _state_bounds
from .parameters import _TYPICAL, _Param, _resolve_parameters
from .problem import _Problem
from .result import GreyBoxResult
from .verdict import _fits, _verdict, _whiteness

__all__ = ["estimate"]

#: Largest integration step (s) by default, without and with dry friction.
MAX_STEP = 1e-3
MAX_STEP_FRICTION = 1.25e-4

_Z95 = 1.959963984540054
_SCHEMES = {"radau1": 1, "radau2": 2, "radau3": 3}


# ---------------------------------------------------------------------- replays
def _replay(plant: Plant, t: np.ndarray, u: np.ndarray, x0: np.ndarray,
            params: np.ndarray | None = None, anchors: np.ndarray | None = None,
            every: int = 0):
    """Open-loop CVODES replay, u held on [t_k, t_k+1): :func:`workbench.replay.hold_runs`
    (:func:`simulate.open_loop`'s integrator, once over each run of equal commands).

    With ``anchors`` (one state per ``every`` samples) the state is reset to
    ``anchors[j]`` at sample ``j * every``: CVODES over each shooting interval from its
    node, which checks the fixed-step integration without the drift of a long replay.
    """
    if anchors is None:
        return _rp.hold_runs(plant, t, u, x0, params)
    return _rp.hold_runs(plant, t, u, anchors, params, anchor_every=every)


def _closed_replay(plant: Plant, rec: Recording, x0: np.ndarray):
    """Closed-loop CVODES replay on the recorded reference r with the plant's controller
    (:class:`workbench.replay.ClosedLoop`, as ``workbench simulate`` does), from ``x0``."""
    return _rp.run(plant, rec, _rp.ClosedLoop(), x0=x0)


def _use_closed_loop(replay: str, rec: Recording, plant: Plant) -> bool:
    """Whether the before/after fits replay in closed loop (:func:`workbench.replay.is_closed`)."""
    return _rp.is_closed(plant, rec, replay)


# ---------------------------------------------------------------------- estimate


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
    _check_options(plant, method, x0, replay, integrator, shooting_interval, substeps,
                   newton_iterations, signals, weights)
    params = _resolve_parameters(plant, parameters, bounds)
    data = _prepare(plant, recordings, signals, noise)
    model, friction, substeps, M = _discretisation(plant, data, method, shooting_interval,
                                                   substeps)
    sig_names = tuple(s for s in signals if any(s in d.y for d in data))
    prob = _Problem(model, params, data, sig_names, M, _SCHEMES[integrator], int(substeps),
                    int(newton_iterations), dict(weights or {}), compiler_flags)
    start = _start(prob, model, params, data, x0)
    sol = _solve(prob, start, max_iter, tol, verbose, progress)
    z, s_nodes, p_hat = prob.split(sol.w)
    values = np.array([p_hat[p.index] for p in params])
    std, corr, cov_ok = _covariance(prob, sol.w, start.fixed, params, z)
    if not sol.success and _stationary(prob.iteration, std, params, z):
        # IPOPT gave up (kinks), but the last iterates agree to a fraction of the std
        sol.status = f"Parameters_Converged ({sol.status})"
        sol.success = True
    res_rms, white, resid, Ydisc = _residual_statistics(prob, data, sol.w)
    est_plant = _estimated_plant(plant, model, params, values)
    chk = _check_replays(plant, est_plant, model, prob, data, start.x_init, s_nodes, p_hat,
                         resid, Ydisc, replay)
    # ---- verdict
    lo = np.array([p.lo for p in params])
    hi = np.array([p.hi for p in params])
    zb = np.array([p.z_bounds for p in params])
    at_bound = np.minimum(z - zb[:, 0], zb[:, 1] - z) <= 1e-5 * (zb[:, 1] - zb[:, 0])
    size = np.array([max(abs(v), _TYPICAL.get(p.name, 0.0) if not p.log else 0.0)
                     for p, v in zip(params, values)])
    identifiable = np.isfinite(std) & (std <= 0.5 * np.where(size > 0, size, np.inf))
    ci = np.column_stack([values - _Z95 * std, values + _Z95 * std])
    poor, msgs = _verdict(data, chk.fit_after, chk.fit_ms, chk.modes, res_rms, white,
                          chk.int_err, fit_threshold, sol.success, sol.status, params,
                          identifiable, at_bound, corr, agreement=chk.agreement)
    method_info = {
        "method": method, "integrator": integrator, "substeps": int(substeps),
        "newton_iterations": int(newton_iterations),
        "compiled": compiler_flags is not None and _jit.have_compiler(),
        "shooting_interval_samples": int(M), "shooting_intervals": int(prob.n_int),
        "x0": x0, "signals": list(sig_names), "replay": chk.modes,
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
        fit_before=tuple(chk.fit_before), fit_after=tuple(chk.fit_after),
        fit_ms_=tuple(chk.fit_ms), x0_=tuple(chk.x0_hat),
        noise=tuple(dict(d.noise) for d in data), residual_rms_=tuple(res_rms),
        whiteness_=tuple(white), integration_error_=tuple(chk.int_err),
        residuals_=tuple(resid), cost=float(sol.cost),
        iterations=sol.iterations, status=sol.status, success=sol.success,
        wall_time=time.perf_counter() - t_start, poor_fit=poor, message=" ".join(msgs),
        plant_=est_plant, method=method_info, sources=tuple(d.source for d in data),
        trajectories_before=tuple(chk.runs_before), trajectories_after=tuple(chk.runs_after))


# ---------------------------------------------------------------------- steps
def _check_options(plant, method, x0, replay, integrator, shooting_interval, substeps,
                   newton_iterations, signals, weights) -> None:
    """Raise :class:`InputError` on a bad option of :func:`estimate`."""
    if not isinstance(plant, Plant):
        raise InputError(f"plant must be a workbench Plant, got {type(plant).__name__}")
    if method not in ("multiple_shooting", "single_shooting"):
        raise InputError("method must be 'multiple_shooting' or 'single_shooting', "
                         f"got {method!r}")
    if x0 not in ("estimate", "from_recording"):
        raise InputError(f"x0 must be 'estimate' or 'from_recording', got {x0!r}")
    if replay not in ("auto", "open", "closed"):
        raise InputError(f"replay must be 'auto', 'open' or 'closed', got {replay!r}")
    if integrator not in _SCHEMES:
        raise InputError(f"integrator must be one of {', '.join(_SCHEMES)}, "
                         f"got {integrator!r}")
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


def _discretisation(plant: Plant, data: list[_Data], method: str, shooting_interval: float,
                    substeps: int | None) -> tuple[Plant, bool, int, int]:
    """(model, dry friction?, substeps per sample, samples per shooting interval M).

    The model is the plant with smooth friction when it has dry friction (the Karnopp
    form is not differentiable); steps of at most :data:`MAX_STEP` (s),
    :data:`MAX_STEP_FRICTION` with dry friction.
    """
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
    return model, friction, substeps, M


@dataclass
class _Start:
    """Start point and bounds of the decision vector (scaled), fixed entries, and the
    initial state of each recording from its data."""

    w0: np.ndarray
    lbw: np.ndarray
    ubw: np.ndarray
    fixed: np.ndarray
    x_init: list[np.ndarray]


def _start(prob: _Problem, model: Plant, params: list[_Param], data: list[_Data],
           x0: str) -> _Start:
    """Parameters at their start values, nodes on the measured states (velocity from the
    differenced position, the rest from a replay with the start values); with
    ``x0="from_recording"`` the measured components of the first node fixed."""
    nx, nsel, M = prob.nx, prob.nsel, prob.M
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
        for d in data:
            sl = prob.node_slice(d.first)
            for s in ("x", "p_a", "p_b", "p_s"):
                if s in names and s in d.rec:
                    i = sl.start + names.index(s)
                    w0[i] = lbw[i] = ubw[i] = _first_value(d.t, d.rec[s]) / prob.sc[names.index(s)]
                    fixed[i] = True
    return _Start(w0, lbw, ubw, fixed, x_init)


@dataclass
class _Solution:
    """IPOPT's answer: decision vector, status, success, iterations, final cost."""

    w: np.ndarray
    status: str
    success: bool
    iterations: int
    cost: float


def _solve(prob: _Problem, start: _Start, max_iter: int, tol: float, verbose: bool,
           progress: bool | None) -> _Solution:
    """IPOPT from ``start`` (with a progress bar unless ``progress`` is False)."""
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
        sol = solver(x0=start.w0, lbx=start.lbw, ubx=start.ubw, lbg=0.0, ubg=0.0)
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
    return _Solution(w, status, success, int(stats.get("iter_count", 0)), prob.f_g(w)[0])


def _residual_statistics(prob: _Problem, data: list[_Data], w: np.ndarray):
    """Per recording and signal: residual RMS (SI), whiteness, residuals (measured minus
    the discrete model); and the discrete model's outputs on the padded grid."""
    _, _, Ydisc = prob.primal(w)
    res_rms, white, resid = [], [], []
    for d in data:
        a = d.first * prob.M
        n = len(d.t)
        rr, ww, ee = {}, {}, {}
        for i, s in enumerate(prob.sig):
            if s in d.y:
                e = d.y[s] - Ydisc[i, a:a + n]
                rr[s] = float(np.sqrt(np.mean(e * e)))
                ww[s] = _whiteness(e)
                ee[s] = e
        res_rms.append(rr)
        white.append(ww)
        resid.append(ee)
    return res_rms, white, resid, Ydisc


def _estimated_plant(plant: Plant, model: Plant, params: list[_Param],
                     values: np.ndarray) -> Plant:
    """``plant`` with the estimates (friction form as given)."""
    changes: dict[str, Any] = {p.name: float(v) for p, v in zip(params, values)}
    if model.segments and "lines.segments" not in plant.params:
        # the number of line segments follows the length unless the file fixes it: keep
        # the one the fit used, so the estimated plant is the model that was fitted
        changes["lines.segments"] = int(model.segments)
    try:
        return plant.with_params(**changes)
    except InputError as exc:
        raise WorkbenchError(f"the estimates break a rule of the plant file ({exc}); give "
                             "bounds that respect it") from None


@dataclass
class _Checks:
    """Fresh CVODES replays before and after, per recording."""

    fit_before: list = field(default_factory=list)
    fit_after: list = field(default_factory=list)
    fit_ms: list = field(default_factory=list)
    runs_before: list = field(default_factory=list)
    runs_after: list = field(default_factory=list)
    int_err: list = field(default_factory=list)
    x0_hat: list = field(default_factory=list)
    modes: list = field(default_factory=list)
    #: fit (%) of the recorded u by the plant file's controller (None: not judged)
    agreement: list = field(default_factory=list)


def _check_replays(plant: Plant, est_plant: Plant, model: Plant, prob: _Problem,
                   data: list[_Data], x_init: list[np.ndarray], s_nodes: np.ndarray,
                   p_hat: np.ndarray, resid: list[dict], Ydisc: np.ndarray,
                   replay: str) -> _Checks:
    """The honest check: the nominal plant from the recording's first sample and the
    estimated plant from the estimated initial state, replayed on CVODES
    (:mod:`workbench.replay`; closed loop on r when asked and possible); the fit of the
    model's own trajectory; the fixed-step scheme against CVODES interval by interval."""
    out = _Checks()
    M = prob.M
    for d, xi in zip(data, x_init):
        a = d.first * M
        n = len(d.t)
        xs = s_nodes[d.first] * prob.sc
        out.x0_hat.append(xs)
        closed = _use_closed_loop(replay, d.rec, plant)
        out.modes.append("closed_loop" if closed else "open_loop")
        out.agreement.append(_rp.command_agreement(plant, d.rec) if closed else None)
        runs = []
        for pl, xstart, fits in ((plant, xi, out.fit_before), (est_plant, xs, out.fit_after)):
            try:
                run = (_closed_replay(pl, d.rec, xstart) if closed
                       else _replay(pl, d.t, d.u, xstart))
                fits.append(_fits(d.y, run))
            except WorkbenchError:
                run = None
                fits.append({s: float("nan") for s in d.y})
            runs.append(run)
        out.runs_before.append(runs[0])
        out.runs_after.append(runs[1])
        e_ms = resid[len(out.fit_ms)]
        out.fit_ms.append({s: nrmse_fit(d.y[s], d.y[s] - e_ms[s]) for s in d.y})
        try:
            anchors = s_nodes[d.first:d.first + d.n_int] * prob.sc
            rc = _replay(model, d.t, d.u, anchors[0], params=p_hat, anchors=anchors, every=M)
            out.int_err.append({s: float(np.sqrt(np.mean(
                (rc[s] - Ydisc[prob.sig.index(s), a:a + n]) ** 2))) for s in d.y})
        except WorkbenchError:
            out.int_err.append({s: float("nan") for s in d.y})
    return out
