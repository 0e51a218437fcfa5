"""Simulation of the nonlinear plant: open loop and sampled-data closed loop.

The plant's ``f`` is integrated by CasADi's CVODES (BDF, variable order and step)
over each interval in which the command is held, in scaled states so that one
tolerance fits position, pressures and line flows alike.

Examples
--------
>>> from workbench import Plant, simulate, controllers
>>> plant = Plant.from_toml("designs/plants/rig25_mpye.toml")               # doctest: +SKIP
>>> ref = simulate.steps([0.1, 0.4, 0.25], hold=2.0)                       # doctest: +SKIP
>>> run = simulate.closed_loop(plant, controllers.from_plant(plant), ref,  # doctest: +SKIP
...                            t_end=6.0, x0=0.25)
>>> run.to_pandas().head()                                                 # doctest: +SKIP
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import casadi as ca
import numpy as np

from .errors import InputError, WorkbenchError
from .plant import Plant

__all__ = [
    "Trajectory", "Reference", "steps", "profile", "Simulator",
    "open_loop", "closed_loop", "DEFAULT_RTOL", "DEFAULT_ATOL",
]

DEFAULT_RTOL = 1e-7  #: CVODES relative tolerance
DEFAULT_ATOL = 1e-9  #: CVODES absolute tolerance on the scaled states


def _scales(plant: Plant) -> np.ndarray:
    out = []
    for name in plant.state_names:
        if name == "x":
            out.append(plant.stroke)
        elif name == "v":
            out.append(1.0)
        elif name in ("p_a", "p_b", "p_s") or "_p" in name:
            out.append(1e5)
        elif name in ("T_a", "T_b"):
            out.append(300.0)
        elif "_q" in name:
            out.append(1e-3)
        elif name == "spool":
            out.append(10.0)
        elif name == "spool_rate":
            out.append(1e4)
        else:
            out.append(1.0)
    return np.array(out)


@dataclass(frozen=True)
class Trajectory:
    """Result of a simulation: samples of states, command, outputs and reference.

    Attributes
    ----------
    time : (N,) s. states : (N, nx). inputs : (N, 1) command u applied, V.
    outputs : (N, ny). reference : (N,) m or None.
    """

    time: np.ndarray
    states: np.ndarray
    inputs: np.ndarray
    outputs: np.ndarray
    state_names: tuple[str, ...]
    output_names: tuple[str, ...]
    input_names: tuple[str, ...] = ("u",)
    reference: np.ndarray | None = None
    units: Mapping[str, str] = field(default_factory=dict)
    info: Mapping[str, Any] = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        """A signal by name: an output, a state, ``u`` or ``r``."""
        if name in self.output_names:
            return self.outputs[:, self.output_names.index(name)]
        if name in self.state_names:
            return self.states[:, self.state_names.index(name)]
        if name in self.input_names:
            return self.inputs[:, self.input_names.index(name)]
        if name == "r" and self.reference is not None:
            return self.reference
        if name == "t":
            return self.time
        raise KeyError(f"no signal '{name}'; signals: "
                       + ", ".join(("t",) + self.input_names + self.output_names
                                   + self.state_names + (("r",) if self.reference is not None else ())))

    def columns(self) -> dict[str, np.ndarray]:
        """Every signal by name (outputs, then remaining states), with t, u and r."""
        cols: dict[str, np.ndarray] = {"t": self.time}
        for i, n in enumerate(self.input_names):
            cols[n] = self.inputs[:, i]
        for i, n in enumerate(self.output_names):
            cols[n] = self.outputs[:, i]
        for i, n in enumerate(self.state_names):
            cols.setdefault(n, self.states[:, i])
        if self.reference is not None:
            cols["r"] = self.reference
        return cols

    def to_pandas(self):
        """DataFrame indexed by time (s) with every signal as a column."""
        import pandas as pd
        cols = self.columns()
        t = cols.pop("t")
        return pd.DataFrame(cols, index=pd.Index(t, name="t"))

    def to_recording(self, columns: Sequence[str] = ("t", "u", "x", "p_a", "p_b"),
                     metadata: Mapping[str, str] | None = None):
        """A :class:`workbench.recording.Recording` of the chosen signals."""
        from .recording import Recording
        cols = self.columns()
        data = {c: np.asarray(cols[c], dtype=float) for c in columns if c != "t"}
        meta = dict(metadata or {})
        if len(self.time) > 1:
            meta.setdefault("sample_time", repr(float(np.median(np.diff(self.time)))))
        return Recording.from_arrays(self.time, metadata=meta, **data)

    def to_csv(self, path: str | os.PathLike,
               columns: Sequence[str] = ("t", "u", "x", "v", "p_a", "p_b", "p_s", "r")) -> None:
        """Write chosen signals as a recording CSV (formats.md section 3), atomically."""
        cols = [c for c in columns if c != "r" or self.reference is not None]
        self.to_recording(cols).to_csv(path)


# ---------------------------------------------------------------------- references
# Defined in workbench.references; re-exported here (simulate.steps, simulate.Reference).
from .references import Reference, profile, steps  # noqa: E402


# ---------------------------------------------------------------------- simulator
class Simulator:
    """Integrates a plant over intervals of constant command.

    Parameters
    ----------
    plant : Plant
    rtol, atol : CVODES tolerances (atol on states scaled to ~1).
    params : parameter vector (default the plant's nominal ``p0``).
    """

    def __init__(self, plant: Plant, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL,
                 params: Sequence[float] | None = None) -> None:
        self.plant = plant
        self.params = np.asarray(plant.p0 if params is None else params, dtype=float)
        if self.params.shape != plant.p0.shape:
            raise InputError(f"expected {len(plant.p0)} parameters, got {self.params.shape}")
        self.scale = _scales(plant)
        self.rtol, self.atol = rtol, atol
        self._integrators: dict[int, ca.Function] = {}
        nx = len(plant.states)
        z = ca.SX.sym("z", nx)
        up = ca.SX.sym("up", 2 + len(plant.p0))   # [duration, u, p...]
        sc = ca.DM(self.scale)
        xdot = plant.f(z * sc, up[1], up[2:])
        self._dae = {"x": z, "p": up, "ode": up[0] * xdot / sc}

    def _integrator(self, m: int) -> ca.Function:
        if m not in self._integrators:
            grid = list(np.arange(1, m + 1) / m)
            opts = {"abstol": self.atol, "reltol": self.rtol, "max_num_steps": 100000,
                    "print_stats": False}
            self._integrators[m] = ca.integrator(f"F{m}", "cvodes", self._dae, 0.0, grid, opts)
        return self._integrators[m]

    def step(self, state: np.ndarray, u: float, duration: float, m: int = 1) -> np.ndarray:
        """States at ``m`` equally spaced instants over ``duration`` s (last = end), (m, nx)."""
        F = self._integrator(m)
        pv = np.concatenate(([duration, u], self.params))
        try:
            res = F(x0=state / self.scale, p=pv)
        except RuntimeError as exc:
            raise WorkbenchError(f"integration failed over a {duration:g} s interval with "
                                 f"u = {u:g} V: {str(exc).splitlines()[0]}") from None
        return (np.asarray(res["xf"]).T) * self.scale

    def outputs(self, states: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Outputs for rows of states and commands."""
        return _outputs(self.plant, self.params, states, u)


def _outputs(plant: Plant, params: np.ndarray, states: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Plant outputs for rows of states and commands, (N, ny)."""
    hm = plant.h.map(states.shape[0])
    return np.asarray(hm(states.T, np.asarray(u).reshape(1, -1),
                         np.tile(params.reshape(-1, 1), (1, states.shape[0])))).T


def _progress(total: int, desc: str, show: bool | None):
    from tqdm.auto import tqdm
    return tqdm(total=total, desc=desc, unit="step", disable=(None if show is None else not show),
                leave=False, mininterval=0.5)


def open_loop(plant: Plant, t: Sequence[float], u: Sequence[float],
              x0: Sequence[float] | float | None = None, params: Sequence[float] | None = None,
              rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL,
              progress: bool | None = None) -> Trajectory:
    """Simulate with a given command: u[k] held on [t[k], t[k+1]) (ZOH).

    Parameters
    ----------
    t : sample times, s, strictly increasing. u : commands at those times, V.
    x0 : full initial state, or a position (m) to start at rest in equilibrium.
    params : parameter vector (default nominal).

    Returns
    -------
    Trajectory sampled at ``t``.
    """
    t = np.asarray(t, dtype=float)
    u = np.asarray(u, dtype=float)
    if t.ndim != 1 or t.shape != u.shape or len(t) < 2:
        raise InputError("t and u must be 1-D arrays of the same length (>= 2)")
    if np.any(np.diff(t) <= 0):
        raise InputError("time must be strictly increasing")
    sim = Simulator(plant, rtol, atol, params)
    state = _initial(plant, x0)
    states = np.empty((len(t), len(state)))
    states[0] = state
    dts = np.diff(t)
    with _progress(len(t) - 1, "simulate", progress) as bar:
        for k in range(len(t) - 1):
            state = sim.step(state, u[k], dts[k])[-1]
            states[k + 1] = state
            if k % 200 == 0:
                bar.update(min(200, len(t) - 1 - k))
    outs = sim.outputs(states, u)
    return Trajectory(time=t, states=states, inputs=u.reshape(-1, 1), outputs=outs,
                      state_names=plant.state_names, output_names=plant.output_names,
                      units=_units(plant), info={"mode": "open_loop"})


def _initial(plant: Plant, x0) -> np.ndarray:
    if x0 is None:
        return plant.initial_state(0.5 * plant.stroke)
    arr = np.atleast_1d(np.asarray(x0, dtype=float))
    if arr.size == 1:
        return plant.initial_state(float(arr[0]))
    if arr.size != len(plant.states):
        raise InputError(f"initial state has {arr.size} entries, the plant has "
                         f"{len(plant.states)} states ({', '.join(plant.state_names)})")
    return arr


def _units(plant: Plant) -> dict[str, str]:
    u = {s.name: s.unit for s in plant.states}
    u.update({s.name: s.unit for s in plant.outputs})
    u.update({"u": "V", "r": "m", "t": "s"})
    return u


def _quantise(value: float, step: float | None) -> float:
    if not step:
        return value
    return float(np.round(value / step) * step)


def closed_loop(plant: Plant, controller, reference: Callable[[float], float] | Reference,
                t_end: float | None = None, x0: Sequence[float] | float | None = None,
                output_times: Sequence[float] | None = None, params: Sequence[float] | None = None,
                position_resolution: float | None = None, command_resolution: float | None = None,
                delay_samples: int = 0, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL,
                progress: bool | None = None) -> Trajectory:
    """Sampled-data closed loop: the controller samples every ``sample_time``.

    At each sample t_k the controller reads the position (quantised by the ADC
    step ``position_resolution``, m) and the reference r(t_k); its command is
    clipped to the valve's [command_min, command_max], quantised by the DAC step
    ``command_resolution`` (V), and held (ZOH) until the next sample
    (``delay_samples`` samples later when computation takes time).

    Parameters
    ----------
    reference : callable r(t) in m (e.g. :func:`steps`, :func:`profile`).
    t_end : s; default the reference's duration.
    x0 : full initial state, or a position (m) to start at rest; default r(0).
    output_times : times (s) at which to report; default every sample.

    Returns
    -------
    Trajectory at ``output_times`` with the command applied and the reference.
    """
    T = float(controller.sample_time)
    if t_end is None:
        t_end = getattr(reference, "duration", None)
        if t_end is None:
            raise InputError("give t_end for a reference without a duration")
    prm = plant.params
    u_min, u_max = prm["valve.command_min"], prm["valve.command_max"]
    if position_resolution is None:
        position_resolution = prm.get("controller.position_resolution")
    if command_resolution is None:
        command_resolution = prm.get("controller.command_resolution")
    n_samples = int(np.floor(t_end / T + 1e-9))
    t_ctrl = T * np.arange(n_samples + 1)
    if output_times is None:
        out_t = t_ctrl.copy()
    else:
        out_t = np.asarray(output_times, dtype=float)
        if np.any(np.diff(out_t) <= 0):
            raise InputError("output_times must be strictly increasing")
    t0 = out_t[0]
    t_ctrl = t0 + T * np.arange(int(np.floor((out_t[-1] - t0) / T + 1e-9)) + 1)
    if x0 is None:
        x0 = float(np.clip(reference(t0), 0.0, plant.stroke))
    sim = Simulator(plant, rtol, atol, params)
    state = _initial(plant, x0)
    ix = plant.state_index("x")
    iv = plant.state_index("v")
    ipa, ipb = plant.state_index("p_a"), plant.state_index("p_b")

    events = np.union1d(t_ctrl, out_t)
    # merge events closer than 1e-9 s
    keep = np.concatenate(([True], np.diff(events) > 1e-9))
    events = events[keep]
    is_ctrl = np.zeros(len(events), dtype=bool)
    is_ctrl[np.clip(np.searchsorted(events, t_ctrl - 1e-9), 0, len(events) - 1)] = True
    out_idx = np.clip(np.searchsorted(events, out_t - 1e-9), 0, len(events) - 1)

    # fast path: the same number of output points in every control interval
    ctrl_pos = np.flatnonzero(is_ctrl)
    per = np.diff(ctrl_pos)
    uniform = len(per) > 0 and np.all(per == per[0]) and ctrl_pos[-1] == len(events) - 1 \
        and ctrl_pos[0] == 0
    if uniform:
        ev_dt = np.diff(events)
        uniform = np.allclose(ev_dt, ev_dt[0], rtol=1e-9, atol=1e-12)

    cstate = controller.reset()
    pending = [None] * delay_samples
    u_now = float(np.clip(state[plant.state_names.index("spool")], u_min, u_max)) \
        if "spool" in plant.state_names else prm["valve.command_center"]
    states = np.empty((len(events), len(state)))
    u_hist = np.empty(len(events))
    r_hist = np.empty(len(events))

    def control_at(k_ev: int) -> None:
        nonlocal cstate, u_now
        y = {"x": _quantise(float(state[ix]), position_resolution), "v": float(state[iv]),
             "p_a": float(state[ipa]), "p_b": float(state[ipb])}
        r = float(reference(events[k_ev]))
        cstate, u_cmd = controller.update(cstate, r, y)
        u_cmd = _quantise(float(np.clip(u_cmd, u_min, u_max)), command_resolution)
        u_cmd = float(np.clip(u_cmd, u_min, u_max))
        if delay_samples:
            pending.append(u_cmd)
            u_cmd = pending.pop(0)
            if u_cmd is None:
                u_cmd = u_now
        u_now = u_cmd

    with _progress(len(events) - 1, "closed loop", progress) as bar:
        if uniform:
            m = int(per[0])
            dur = float(events[ctrl_pos[1]] - events[ctrl_pos[0]]) if len(ctrl_pos) > 1 else T
            states[0] = state
            for j, k in enumerate(ctrl_pos[:-1]):
                control_at(k)
                r_hist[k:k + m] = reference(events[k:k + m])
                u_hist[k:k + m] = u_now
                block = sim.step(state, u_now, dur, m)
                states[k + 1:k + m + 1] = block
                state = block[-1]
                if j % 50 == 0:
                    bar.update(min(50 * m, len(events) - 1 - k))
            last = len(events) - 1
            control_at(last)
            u_hist[last], r_hist[last] = u_now, reference(events[last])
        else:
            for k in range(len(events)):
                if is_ctrl[k]:
                    control_at(k)
                states[k] = state
                u_hist[k] = u_now
                r_hist[k] = reference(events[k])
                if k + 1 < len(events):
                    state = sim.step(state, u_now, events[k + 1] - events[k])[-1]
                    if k % 200 == 0:
                        bar.update(min(200, len(events) - 1 - k))

    states, u_hist, r_hist = states[out_idx], u_hist[out_idx], r_hist[out_idx]
    outs = sim.outputs(states, u_hist)
    return Trajectory(time=out_t, states=states, inputs=u_hist.reshape(-1, 1), outputs=outs,
                      state_names=plant.state_names, output_names=plant.output_names,
                      reference=r_hist, units=_units(plant),
                      info={"mode": "closed_loop", "sample_time": T})


# ---------------------------------------------------------------------- compiled loop
class CompiledLoop:
    """The whole sampled-data PID loop as compiled code (fast path for long runs).

    Each control period is integrated with ``substeps`` fixed steps of an L-stable
    one-step method, built symbolically (SX) from the plant's ``f`` with the
    parameters folded in as constants:

    * ``"ros4"`` (default): the 4-stage Rosenbrock method of order 4 of Hairer &
      Wanner (L-stable), exact Jacobian at every step, 3 evaluations of ``f``;
    * ``"rodas4"``: RODAS, 6 stages, order 4, L-stable and stiffly accurate (5 of ``f``);
    * ``"radau"``: 3-stage Radau IIA (order 5) with ``newton_iterations`` simplified
      Newton iterations in the eigenbasis of the Butcher matrix (one real and one
      complex n x n system per step, Jacobian once per step, stages started from
      the previous step's collocation polynomial);
    * ``"ros2"``: the 2-stage Rosenbrock ROS2 (order 2): cheap and inaccurate.

    Rosenbrock methods are linearly implicit: no iteration, a fixed cost per step.
    The n x n solves are LU factorisations written out in the expression (no
    pivoting: the iteration matrices c I - J, c ~ 1/h, are dominated by their
    diagonal), so one step is a single straight-line function. With ``jit=True`` the
    control law, the step and the outputs are generated as C, and a small C driver
    runs every period and substep without Python; the shared library is built with
    the system C compiler once and cached in the temp directory (:attr:`compile_s`
    is the time that took). Without a working compiler (:attr:`native_error`), or
    with ``jit=False``, the same kernels run as a CasADi ``mapaccum`` in the virtual
    machine, identical up to rounding.

    The controller law, clipping and DAC/ADC quantisation are those of :func:`closed_loop`.
    The steps are fixed, so the accuracy is measured, not controlled: on the 25 mm
    reference plant the default 14 ROS4 substeps per 10 ms stay within ~2e-5 m of
    scipy Radau (rtol 1e-9) over 24 s of steps (``workbench bench simulate``; the
    error is set by the pressure laws' kinks, choked/subsonic and the laminar patch,
    not by stiffness). Runs that bounce on the end stops (a discontinuous contact
    force) or with stick-slip friction need many more substeps, and 1 m lines (kHz
    acoustic modes) about 100: use :func:`closed_loop` there, or compare the two.
    A run whose states stop being finite raises :class:`WorkbenchError`.
    """

    def __init__(self, plant: Plant, controller, substeps: int = 14, jit: bool = False,
                 method: str = "ros4",
                 params: Sequence[float] | None = None,
                 position_resolution: float | None = None,
                 command_resolution: float | None = None,
                 newton_iterations: int = 3) -> None:
        from .controllers.pd import PID
        if method not in _STEP_BUILDERS:
            raise InputError(f"method must be one of {', '.join(map(repr, _STEP_BUILDERS))}, "
                             f"got {method!r}")
        if not isinstance(controller, PID):
            raise InputError("the compiled loop runs the plant file's P/PD/PID controller only")
        if int(substeps) < 1 or int(newton_iterations) < 1:
            raise InputError("substeps and newton_iterations must be at least 1")
        self.method = method
        self.plant, self.controller, self.substeps = plant, controller, int(substeps)
        self.newton_iterations = int(newton_iterations)
        self.params = np.asarray(plant.p0 if params is None else params, dtype=float)
        if self.params.shape != plant.p0.shape:
            raise InputError(f"expected {len(plant.p0)} parameters, got {self.params.shape}")
        prm = plant.params
        pos_res = position_resolution or prm.get("controller.position_resolution")
        cmd_res = command_resolution or prm.get("controller.command_resolution")
        nx = len(plant.states)
        T = controller.sample_time
        h = T / self.substeps
        p = ca.DM(self.params)
        self._ctrl = _pid_kernel(plant, controller, pos_res, cmd_res)
        xo, uo = ca.SX.sym("x", nx), ca.SX.sym("u")
        self._out = ca.Function("wb_out", [xo, uo], [ca.densify(plant.h(xo, uo, p))])
        self._kernel = _STEP_BUILDERS[method](lambda z, u: plant.f(z, u, p), nx, h,
                                              self.newton_iterations)
        nz = self._kernel.size1_in(2)
        # one control period (the virtual-machine path, and for inspection)
        xc = ca.MX.sym("xc", nx + _NC)
        r = ca.MX.sym("r")
        u, cnext = self._ctrl(xc[:nx], xc[nx:], r)
        zk, aux, traj = xc[:nx], ca.MX.zeros(nz), []
        for _ in range(self.substeps):
            zk, aux = self._kernel(zk, u, aux)
            traj.append(zk)
        #: one period: ([x; controller state], r) -> ([x; controller state] next, states at
        #: the substeps (nx x substeps), command held)
        self.period = ca.Function("period", [xc, r], [ca.vertcat(zk, cnext), ca.horzcat(*traj), u])
        self._jit = bool(jit)
        self._loops: dict[int, ca.Function] = {}
        self._native: _NativeLoop | None | bool = None
        #: seconds spent generating, compiling and loading the C loop (a fraction of a
        #: second when the library was already in the cache, see :attr:`compile_cached`)
        self.compile_s = 0.0
        self.compile_cached = False
        #: why the C loop is not used, when ``jit=True`` but it could not be built
        self.native_error: str | None = None

    def compile(self) -> bool:
        """Build the C loop (or load it from the cache); False when that is not possible."""
        if self._native is None:
            import time
            t0 = time.perf_counter()
            try:
                self._native = _NativeLoop.build(self._ctrl, self._kernel, self._out,
                                                 self.substeps)
                self.compile_cached = self._native.cached
            except _NativeUnavailable as exc:
                self._native, self.native_error = False, str(exc)
            self.compile_s = time.perf_counter() - t0
        return bool(self._native)

    @property
    def native(self) -> bool:
        """Whether :meth:`run` executes the compiled C loop."""
        return self._jit and self.compile()

    def _loop(self, n: int) -> ca.Function:
        if n not in self._loops:
            self._loops[n] = self.period.mapaccum("loop", n, [0], [0])
        return self._loops[n]

    def run(self, reference, t_end: float, x0, every_substep: bool = False) -> Trajectory:
        """Simulate to ``t_end``: states at every control instant (or every substep).

        Parameters
        ----------
        reference : callable r(t) in m, sampled at the control instants.
        t_end : s, rounded down to whole control periods.
        x0 : full initial state, or a position (m) to start at rest.
        every_substep : report at every substep instead of every control instant.
        """
        T = self.controller.sample_time
        n = int(np.floor(t_end / T + 1e-9))
        if n < 1:
            raise InputError(f"t_end must cover at least one control period ({T:g} s)")
        t_ctrl = T * np.arange(n + 1)
        r_all = np.asarray(reference(t_ctrl), dtype=float).ravel()
        r = r_all[:n]
        state = _initial(self.plant, x0)
        nx, m = len(state), self.substeps
        xc0 = np.concatenate((state, np.zeros(_NC)))
        native = self._native if self.native else None
        if native:
            traj, u, xc_end = native(xc0, r, every_substep)
        else:
            xcs, traj, u = self._loop(n)(xc0, r.reshape(1, -1))
            xc_end = np.asarray(xcs)[:, -1]
            traj = np.asarray(traj).T                     # (n * m, nx)
            if not every_substep:
                traj = traj[m - 1::m]
            u = np.asarray(u).ravel()
        if not np.all(np.isfinite(traj)):
            raise WorkbenchError(f"the compiled loop ({self.method}, {m} substeps per period) "
                                 "diverged; use more substeps or simulate.closed_loop")
        states = np.vstack((state, traj))
        # the command the controller would apply at t_end, for a complete last row
        u_last = float(self._ctrl(xc_end[:nx], xc_end[nx:], r_all[n])[0])
        if every_substep:
            t = np.concatenate(([0.0], np.arange(1, n * m + 1) * (T / m)))
            u_full = np.concatenate((np.repeat(u, m), [u_last]))
            r_full = np.concatenate((np.repeat(r, m), [r_all[n]]))
        else:
            t = t_ctrl
            u_full = np.append(u, u_last)
            r_full = r_all
        if native:
            outs = native.outputs(states, u_full)
        else:
            outs = _outputs(self.plant, self.params, states, u_full)
        return Trajectory(time=t, states=states, inputs=u_full.reshape(-1, 1), outputs=outs,
                          state_names=self.plant.state_names,
                          output_names=self.plant.output_names, reference=r_full,
                          units=_units(self.plant),
                          info={"mode": "closed_loop", "method": f"{self.method}-compiled",
                                "substeps": m, "sample_time": T, "native": bool(native)})


#: controller state carried by the compiled loop: previous error, integral, started flag
_NC = 3


def _pid_kernel(plant: Plant, c, pos_res: float | None, cmd_res: float | None) -> ca.Function:
    """The PID law of :func:`closed_loop` as ``wb_ctrl(x, cstate, r) -> (u, cstate_next)``."""
    nx = len(plant.states)
    xs = ca.SX.sym("x", nx)
    cs = ca.SX.sym("c", _NC)
    r = ca.SX.sym("r")
    T = c.sample_time
    ix = plant.state_index("x")
    y = xs[ix] if not pos_res else ca.floor(xs[ix] / pos_res + 0.5) * pos_res
    e = r - y
    e_prev = ca.if_else(cs[2] > 0, cs[0], e)
    u_free = c.u_center + c.kp * e + c.kd * (e - e_prev) / T
    integ = cs[1] + e * T
    if c.ki:
        u_try = u_free + c.ki * integ
        sat = ca.logic_or(u_try <= c.u_min, u_try >= c.u_max)
        integ = ca.if_else(sat, cs[1], integ)
    u = u_free + c.ki * integ
    prm = plant.params
    lo, hi = prm["valve.command_min"], prm["valve.command_max"]
    u = ca.fmin(ca.fmax(u, lo), hi)
    if cmd_res:
        u = ca.fmin(ca.fmax(ca.floor(u / cmd_res + 0.5) * cmd_res, lo), hi)
    return ca.Function("wb_ctrl", [xs, cs, r],
                       [ca.densify(u), ca.densify(ca.vertcat(e, integ, 1.0))])


# -- small dense linear algebra on SX scalars (structural zeros skipped)
def _nz(a) -> bool:
    return not (a.nnz() == 0 or a.is_zero())


def _shifted(J: ca.SX, c: float) -> list:
    """c I - J as a list of rows of SX scalars."""
    n = J.shape[0]
    return [[(c if i == j else 0.0) - J[i, j] for j in range(n)] for i in range(n)]


def _lu_factor(M: list) -> list:
    """In-place LU (no pivoting) of rows of SX scalars; the diagonal holds 1/U_ii."""
    n = len(M)
    A = [list(row) for row in M]
    for k in range(n):
        inv = 1.0 / A[k][k]
        for i in range(k + 1, n):
            if not _nz(A[i][k]):
                continue
            A[i][k] = A[i][k] * inv
            for j in range(k + 1, n):
                if _nz(A[k][j]):
                    A[i][j] = A[i][j] - A[i][k] * A[k][j]
        A[k][k] = inv
    return A


def _lu_solve(A: list, b) -> ca.SX:
    n = len(A)
    y = [b[i] for i in range(n)]
    for i in range(n):
        for j in range(i):
            if _nz(A[i][j]):
                y[i] = y[i] - A[i][j] * y[j]
    for i in reversed(range(n)):
        for j in range(i + 1, n):
            if _nz(A[i][j]):
                y[i] = y[i] - A[i][j] * y[j]
        y[i] = y[i] * A[i][i]
    return ca.vertcat(*y)


# complex scalars as (re, im) pairs of SX scalars
def _cmul(a, b):
    return (a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0])


def _cnz(a) -> bool:
    return _nz(a[0]) or _nz(a[1])


def _clu_factor(M: list) -> list:
    n = len(M)
    A = [list(row) for row in M]
    for k in range(n):
        d = 1.0 / (A[k][k][0] * A[k][k][0] + A[k][k][1] * A[k][k][1])
        inv = (A[k][k][0] * d, -A[k][k][1] * d)
        for i in range(k + 1, n):
            if not _cnz(A[i][k]):
                continue
            A[i][k] = _cmul(A[i][k], inv)
            for j in range(k + 1, n):
                if _cnz(A[k][j]):
                    t = _cmul(A[i][k], A[k][j])
                    A[i][j] = (A[i][j][0] - t[0], A[i][j][1] - t[1])
        A[k][k] = inv
    return A


def _clu_solve(A: list, b: list) -> list:
    n = len(A)
    y = list(b)
    for i in range(n):
        for j in range(i):
            if _cnz(A[i][j]):
                t = _cmul(A[i][j], y[j])
                y[i] = (y[i][0] - t[0], y[i][1] - t[1])
    for i in reversed(range(n)):
        for j in range(i + 1, n):
            if _cnz(A[i][j]):
                t = _cmul(A[i][j], y[j])
                y[i] = (y[i][0] - t[0], y[i][1] - t[1])
        y[i] = _cmul(y[i], A[i][i])
    return y


def _step_function(x, u, z, x_next, z_next) -> ca.Function:
    return ca.Function("wb_step", [x, u, z],
                       [ca.densify(ca.cse(x_next)), ca.densify(ca.cse(z_next))])


# -- the one-step methods: (f(z, u) on SX, nx, h, iterations) -> wb_step(x, u, aux) -> (x+, aux+)
def _ros2_step(f, nx: int, h: float, newton_iterations: int = 0) -> ca.Function:
    """ROS2 (Verwer et al. 1999, gamma = 1 + 1/sqrt 2), order 2, L-stable."""
    g = 1.0 + 1.0 / np.sqrt(2.0)
    x, u, z = ca.SX.sym("x", nx), ca.SX.sym("u"), ca.SX.sym("z", 0)
    fx = f(x, u)
    lu = _lu_factor(_shifted(ca.jacobian(fx, x), 1.0 / (g * h)))
    k1 = _lu_solve(lu, fx / (g * h))
    k2 = _lu_solve(lu, (f(x + h * k1, u) - 2.0 * k1) / (g * h))
    return _step_function(x, u, z, x + 1.5 * h * k1 + 0.5 * h * k2, ca.SX(0, 1))


@dataclass(frozen=True)
class _Rosenbrock:
    """A Rosenbrock method in the form of Hairer & Wanner (Solving ODEs II, sec. IV.7):
    (1/(h gamma) I - J) k_i = f(x + sum_j a_ij k_j) + sum_j c_ij / h k_j, x+ = x + sum_i m_i k_i,
    with J = f'(x). A stage whose argument equals the previous one reuses its f."""

    gamma: float
    a: tuple
    c: tuple
    m: tuple


#: ROS4: the L-stable 4-stage method of order 4 of Hairer & Wanner (Solving ODEs II,
#: sec. IV.7; the L-stable choice of ros4.f), stages 3 and 4 share one f
_ROS4 = _Rosenbrock(
    gamma=0.57282,
    a=((), (2.0,), (1.867943637803922, 0.2344449711399156),
       (1.867943637803922, 0.2344449711399156, 0.0)),
    c=((), (-7.137615036412310,), (2.580708087951457, 0.6515950076447975),
       (-2.137148994382534, -0.3214669691237626, -0.6949742501781779)),
    m=(2.255570073418735, 0.2870493262186792, 0.4353179431840180, 1.093502252409163),
)

_RODAS_A5 = (1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950)
#: RODAS, 6 stages, order 4, L-stable and stiffly accurate (Hairer & Wanner, rodas.f)
_RODAS4 = _Rosenbrock(
    gamma=0.25,
    a=((), (1.544,), (0.9466785280815826, 0.2557011698983284),
       (3.314825187068521, 2.896124015972201, 0.9986419139977817),
       _RODAS_A5, _RODAS_A5 + (1.0,)),
    c=((), (-5.6688,), (-2.430093356833875, -0.2063599157091915),
       (-0.1073529058151375, -9.594562251023355, -20.47028614809616),
       (7.496443313967647, -10.24680431464352, -33.99990352819905, 11.70890893206160),
       (8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136,
        -6.058818238834054)),
    m=_RODAS_A5 + (1.0, 1.0),
)


def _rosenbrock_step(method: _Rosenbrock):
    def build(f, nx: int, h: float, newton_iterations: int = 0) -> ca.Function:
        x, u, z = ca.SX.sym("x", nx), ca.SX.sym("u"), ca.SX.sym("z", 0)
        fx = f(x, u)
        lu = _lu_factor(_shifted(ca.jacobian(fx, x), 1.0 / (method.gamma * h)))
        k: list = []
        fi, prev = fx, ()
        for i, (a, c) in enumerate(zip(method.a, method.c)):
            a = tuple(a)
            while a and not a[-1]:
                a = a[:-1]
            if i and a != prev:
                fi = f(x + sum(aj * kj for aj, kj in zip(a, k) if aj), u)
            prev = a
            rhs = fi + sum((cj / h) * kj for cj, kj in zip(c, k) if cj)
            k.append(_lu_solve(lu, rhs))
        x_next = x + sum(mi * ki for mi, ki in zip(method.m, k) if mi)
        return _step_function(x, u, z, x_next, ca.SX(0, 1))
    build.__name__ = build.__qualname__ = "_rosenbrock_step"
    return build


_ros4_step = _rosenbrock_step(_ROS4)
_rodas4_step = _rosenbrock_step(_RODAS4)


#: Radau IIA, 3 stages (order 5): Butcher matrix; the last row is also b.
_S6 = np.sqrt(6.0)
RADAU3_A = np.array([
    [(88 - 7 * _S6) / 360, (296 - 169 * _S6) / 1800, (-2 + 3 * _S6) / 225],
    [(296 + 169 * _S6) / 1800, (88 + 7 * _S6) / 360, (-2 - 3 * _S6) / 225],
    [(16 - _S6) / 36, (16 + _S6) / 36, 1.0 / 9.0],
])


def _radau_constants():
    """Eigenbasis of A^-1 (T, T^-1, gamma, alpha, beta) and the stage extrapolation E."""
    Ai = np.linalg.inv(RADAU3_A)
    w, V = np.linalg.eig(Ai)
    ir, ic = int(np.argmin(np.abs(w.imag))), int(np.argmax(w.imag))
    T = np.column_stack([V[:, ir].real, V[:, ic].real, V[:, ic].imag])
    Ti = np.linalg.inv(T)
    L = Ti @ Ai @ T      # [[gamma, 0, 0], [0, alpha, -beta], [0, beta, alpha]]
    c = RADAU3_A.sum(axis=1)
    nodes = np.concatenate(([0.0], c))

    def lag(j, t):
        return np.prod([(t - nodes[q]) / (nodes[j] - nodes[q]) for q in range(4) if q != j])
    # the collocation polynomial q (q(0) = 0, q(c_j) = Z_j) continued one step:
    # next stage guesses Z_i = q(1 + c_i) - q(1)
    E = np.array([[lag(j + 1, 1.0 + c[i]) - lag(j + 1, 1.0) for j in range(3)] for i in range(3)])
    return T, Ti, L[0, 0], L[1, 1], L[2, 1], E


def _radau_step(f, nx: int, h: float, newton_iterations: int = 3) -> ca.Function:
    """One Radau IIA (3-stage) step by simplified Newton in the eigenbasis of A.

    The stage increments Z solve Z = h (A x I) F(x + Z). With A^-1 = T L T^-1 the
    Newton matrix (A^-1/h x I - I x J) splits into (gamma/h - J) and the complex
    ((alpha + i beta)/h - J), each factorised once per step at J(x). The auxiliary
    in/output is the stages of the step (3 nx), extrapolated as the starting guess
    of the next step (zero at the start of a control period).
    """
    T, Ti, gam, alp, bet, E = _radau_constants()
    x, u, zp = ca.SX.sym("x", nx), ca.SX.sym("u"), ca.SX.sym("z", 3 * nx)
    J = ca.jacobian(f(x, u), x)
    lu1 = _lu_factor(_shifted(J, gam / h))
    lu2 = _clu_factor([[(v, ca.SX(bet / h) if i == j else ca.SX(0)) for j, v in enumerate(row)]
                       for i, row in enumerate(_shifted(J, alp / h))])
    Zo = [zp[i * nx:(i + 1) * nx] for i in range(3)]
    Z = [sum(E[i, j] * Zo[j] for j in range(3)) for i in range(3)]
    W = [sum(Ti[i, j] * Z[j] for j in range(3)) for i in range(3)]
    for _ in range(newton_iterations):
        F = [f(x + Z[i], u) for i in range(3)]
        G = [Ti[i, 0] * F[0] + Ti[i, 1] * F[1] + Ti[i, 2] * F[2] for i in range(3)]
        r1 = G[0] - (gam / h) * W[0]
        r2 = G[1] - (alp * W[1] - bet * W[2]) / h
        r3 = G[2] - (bet * W[1] + alp * W[2]) / h
        d1 = _lu_solve(lu1, r1)
        d23 = _clu_solve(lu2, [(r2[i], r3[i]) for i in range(nx)])
        W = [W[0] + d1, W[1] + ca.vertcat(*[d[0] for d in d23]),
             W[2] + ca.vertcat(*[d[1] for d in d23])]
        Z = [T[i, 0] * W[0] + T[i, 1] * W[1] + T[i, 2] * W[2] for i in range(3)]
    return _step_function(x, u, zp, x + Z[2], ca.vertcat(*Z))


_STEP_BUILDERS: dict[str, Callable[..., ca.Function]] = {
    "ros4": _ros4_step, "rodas4": _rodas4_step, "radau": _radau_step, "ros2": _ros2_step,
}


# -- the C loop
class _NativeUnavailable(Exception):
    """No C compiler, or the loop did not compile."""


_DRIVER_C = r"""
#include <stdlib.h>

/* workbench.simulate.CompiledLoop: n control periods, each wb_ctrl then WB_M x wb_step */
#define WB_NX %(nx)d
#define WB_NC %(nc)d
#define WB_NZ %(nz)d
#define WB_NY %(ny)d
#define WB_M %(m)d

typedef struct {
  const casadi_real** arg;
  casadi_real** res;
  casadi_int* iw;
  casadi_real* w;
} wb_work;

static void wb_grow(casadi_int* mx, casadi_int v) { if (v > *mx) *mx = v; }

static int wb_alloc(wb_work* m) {
  casadi_int na, nr, ni, nw, ma = 3, mr = 2, mi = 1, mw = 1;
  wb_ctrl_work(&na, &nr, &ni, &nw);
  wb_grow(&ma, na); wb_grow(&mr, nr); wb_grow(&mi, ni); wb_grow(&mw, nw);
  wb_step_work(&na, &nr, &ni, &nw);
  wb_grow(&ma, na); wb_grow(&mr, nr); wb_grow(&mi, ni); wb_grow(&mw, nw);
  wb_out_work(&na, &nr, &ni, &nw);
  wb_grow(&ma, na); wb_grow(&mr, nr); wb_grow(&mi, ni); wb_grow(&mw, nw);
  m->arg = (const casadi_real**) malloc(sizeof(casadi_real*) * ma);
  m->res = (casadi_real**) malloc(sizeof(casadi_real*) * mr);
  m->iw = (casadi_int*) malloc(sizeof(casadi_int) * mi);
  m->w = (casadi_real*) malloc(sizeof(casadi_real) * mw);
  return !m->arg || !m->res || !m->iw || !m->w;
}

static void wb_free(wb_work* m) {
  free((void*) m->arg); free(m->res); free(m->iw); free(m->w);
}

/* Runs n periods from [x; controller state] xc0 with references r[0..n-1]. Writes the
   states after every substep (every != 0, n * WB_M rows) or every period (n rows) to
   traj, the commands to u_out and the final [x; controller state] to xc_end. */
CASADI_SYMBOL_EXPORT int wb_loop(casadi_int n, const casadi_real* xc0, const casadi_real* r,
                                 casadi_int every, casadi_real* traj, casadi_real* u_out,
                                 casadi_real* xc_end) {
  casadi_int i, k, s;
  casadi_real x[WB_NX], xn[WB_NX], c[WB_NC], cn[WB_NC], z[WB_NZ + 1], zn[WB_NZ + 1], u = 0.;
  wb_work m;
  int flag = wb_alloc(&m) ? 2 : 0;
  for (i = 0; i < WB_NX; ++i) x[i] = xc0[i];
  for (i = 0; i < WB_NC; ++i) c[i] = xc0[WB_NX + i];
  for (k = 0; k < n && !flag; ++k) {
    m.arg[0] = x; m.arg[1] = c; m.arg[2] = r + k;
    m.res[0] = &u; m.res[1] = cn;
    if (wb_ctrl(m.arg, m.res, m.iw, m.w, 0)) { flag = 1; break; }
    u_out[k] = u;
    for (i = 0; i < WB_NC; ++i) c[i] = cn[i];
    for (i = 0; i < WB_NZ; ++i) z[i] = 0.;
    for (s = 0; s < WB_M; ++s) {
      m.arg[0] = x; m.arg[1] = &u; m.arg[2] = z;
      m.res[0] = xn; m.res[1] = zn;
      if (wb_step(m.arg, m.res, m.iw, m.w, 0)) { flag = 1; break; }
      for (i = 0; i < WB_NX; ++i) x[i] = xn[i];
      for (i = 0; i < WB_NZ; ++i) z[i] = zn[i];
      if (every) for (i = 0; i < WB_NX; ++i) traj[(k * WB_M + s) * WB_NX + i] = x[i];
    }
    if (!every) for (i = 0; i < WB_NX; ++i) traj[k * WB_NX + i] = x[i];
  }
  for (i = 0; i < WB_NX; ++i) xc_end[i] = x[i];
  for (i = 0; i < WB_NC; ++i) xc_end[WB_NX + i] = c[i];
  wb_free(&m);
  return flag;
}

/* The plant outputs y (n x WB_NY) for rows of states x (n x WB_NX) and commands u. */
CASADI_SYMBOL_EXPORT int wb_outputs(casadi_int n, const casadi_real* x, const casadi_real* u,
                                    casadi_real* y) {
  casadi_int k;
  wb_work m;
  int flag = wb_alloc(&m) ? 2 : 0;
  for (k = 0; k < n && !flag; ++k) {
    m.arg[0] = x + k * WB_NX; m.arg[1] = u + k; m.res[0] = y + k * WB_NY;
    if (wb_out(m.arg, m.res, m.iw, m.w, 0)) flag = 1;
  }
  wb_free(&m);
  return flag;
}
"""

#: compiler flags of the C loop. C89 makes CasADi's fmin/fmax plain comparisons instead
#: of libm calls, and without semantic interposition they (and sign, fabs) are inlined
#: in the shared object (together ~1.6x faster); no errno, traps or signed zeros, and
#: x/c as x*(1/c) (last-bit changes only; not -ffast-math, whose shared objects switch
#: denormals off process-wide). The second set is the fallback for other compilers.
_CFLAGS = ("-O2", "-std=c89", "-fno-math-errno", "-fno-trapping-math", "-fno-signed-zeros",
           "-freciprocal-math", "-fno-semantic-interposition", "-fPIC", "-shared")
_CFLAGS_FALLBACK = ("-O2", "-fPIC", "-shared")


def _c_compiler() -> list[str] | None:
    import shlex
    import shutil
    cc = os.environ.get("CC")
    if cc:
        return shlex.split(cc)
    for name in ("gcc", "cc", "clang"):
        path = shutil.which(name)
        if path:
            return [path]
    return None


class _NativeLoop:
    """The compiled loop: a shared library with ``wb_loop`` and ``wb_outputs``."""

    def __init__(self, path: str, nx: int, ny: int, m: int, cached: bool = False) -> None:
        import ctypes
        self.path, self.nx, self.ny, self.m, self.cached = path, nx, ny, m, cached
        self._lib = ctypes.CDLL(path)
        P = ctypes.POINTER(ctypes.c_double)
        n_t = ctypes.c_longlong
        self._loop = self._lib.wb_loop
        self._loop.argtypes = [n_t, P, P, n_t, P, P, P]
        self._loop.restype = ctypes.c_int
        self._out = self._lib.wb_outputs
        self._out.argtypes = [n_t, P, P, P]
        self._out.restype = ctypes.c_int
        self._P = P

    @classmethod
    def build(cls, ctrl: ca.Function, kernel: ca.Function, out: ca.Function,
              substeps: int) -> "_NativeLoop":
        import hashlib
        import subprocess
        import tempfile
        cc = _c_compiler()
        if cc is None:
            raise _NativeUnavailable("no C compiler found (set CC)")
        cg = ca.CodeGenerator("wb_loop.c", {"with_header": False})
        for fn in (ctrl, kernel, out):
            cg.add(fn)
        nx, nz, ny = kernel.size1_in(0), kernel.size1_in(2), out.size1_out(0)
        src = cg.dump() + _DRIVER_C % {"nx": nx, "nc": _NC, "nz": nz, "ny": ny, "m": substeps}
        key = hashlib.sha256("\0".join([src, " ".join(cc), " ".join(_CFLAGS),
                                        " ".join(_CFLAGS_FALLBACK), ca.__version__]
                                       ).encode()).hexdigest()[:24]
        folder = os.path.join(tempfile.gettempdir(), "workbench-jit")
        so = os.path.join(folder, f"wb_loop_{key}.so")
        cached = os.path.exists(so)
        if not cached:
            os.makedirs(folder, exist_ok=True)
            stem = os.path.join(folder, f"wb_loop_{key}_{os.getpid()}")
            c_file, tmp_so = stem + ".c", stem + ".so"
            with open(c_file, "w") as fh:
                fh.write(src)
            try:
                for flags in (_CFLAGS, _CFLAGS_FALLBACK):
                    proc = subprocess.run([*cc, *flags, c_file, "-o", tmp_so, "-lm"],
                                          capture_output=True, text=True)
                    if proc.returncode == 0:
                        break
                else:
                    raise _NativeUnavailable("the C loop did not compile: "
                                             + (proc.stderr.strip().splitlines() or ["?"])[-1])
                os.replace(tmp_so, so)      # atomic: concurrent builds of one key agree
            except OSError as exc:
                raise _NativeUnavailable(f"the C compiler failed: {exc}") from None
            finally:
                for leftover in (c_file, tmp_so):
                    if os.path.exists(leftover):
                        os.remove(leftover)
        try:
            return cls(so, nx, ny, substeps, cached)
        except (OSError, AttributeError) as exc:
            raise _NativeUnavailable(f"the C loop did not load: {exc}") from None

    def _ptr(self, a: np.ndarray):
        return a.ctypes.data_as(self._P)

    def __call__(self, xc0: np.ndarray, r: np.ndarray, every_substep: bool):
        """(states after each period or substep (rows, nx), commands (n,), final [x; c])."""
        n = len(r)
        traj = np.empty((n * self.m if every_substep else n, self.nx))
        u = np.empty(n)
        xc_end = np.empty(len(xc0))
        xc0 = np.ascontiguousarray(xc0, dtype=float)
        r = np.ascontiguousarray(r, dtype=float)
        flag = self._loop(n, self._ptr(xc0), self._ptr(r), int(bool(every_substep)),
                          self._ptr(traj), self._ptr(u), self._ptr(xc_end))
        if flag:
            raise WorkbenchError(f"the compiled loop failed (code {flag})")
        return traj, u, xc_end

    def outputs(self, states: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Plant outputs (rows, ny) for rows of states and commands."""
        states = np.ascontiguousarray(states, dtype=float)
        u = np.ascontiguousarray(u, dtype=float)
        y = np.empty((len(states), self.ny))
        if self._out(len(states), self._ptr(states), self._ptr(u), self._ptr(y)):
            raise WorkbenchError("the compiled outputs failed")
        return y
