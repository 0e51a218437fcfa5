"""Simulation of the nonlinear plant: open loop and sampled-data closed loop.

The plant's ``f`` is integrated by CasADi's CVODES (BDF, variable order and step)
over each interval in which the command is held, in scaled states so that one
tolerance fits position, pressures and line flows alike.

Examples
--------
>>> from workbench import Plant, simulate, controllers
>>> plant = Plant.from_toml("designs/plants/rig25_mpye.toml")
>>> ref = simulate.steps([0.1, 0.4, 0.25], hold=2.0)
>>> run = simulate.closed_loop(plant, controllers.from_plant(plant), ref,
...                            t_end=6.0, x0=0.25)
>>> run.to_pandas().shape                     # 10 ms samples over 6 s; u, x, v, ... r
(601, 9)
>>> round(float(run["x"][-1]), 3)               # back at the last step's 0.25 m
0.25
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import casadi as ca
import numpy as np

from .errors import InputError, WorkbenchError
from .output import reraise_interrupt, stop_on_signals
from .plant import Plant

__all__ = [
    "Trajectory", "Reference", "steps", "profile", "Simulator",
    "open_loop", "closed_loop", "DEFAULT_RTOL", "DEFAULT_ATOL",
]

DEFAULT_RTOL = 1e-7  #: CVODES relative tolerance
DEFAULT_ATOL = 1e-9  #: CVODES absolute tolerance on the scaled states


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
        self.scale = plant.state_scales()   # CVODES integrates state / scale
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
        reraise_interrupt()         # a Ctrl-C swallowed earlier (e.g. by IPOPT): stop now
        F = self._integrator(m)
        pv = np.concatenate(([duration, u], self.params))
        try:
            res = F(x0=state / self.scale, p=pv)
        except RuntimeError as exc:
            reraise_interrupt(exc)  # CVODES reports a Ctrl-C as a failed right-hand side
            raise WorkbenchError(f"integration failed over a {duration:g} s interval with "
                                 f"u = {u:g} V: {str(exc).splitlines()[0]}") from None
        return (np.asarray(res["xf"]).T) * self.scale

    def hold(self, state: np.ndarray, u: float, dts: Sequence[float]) -> np.ndarray:
        """States after each of the intervals ``dts`` (s, equal up to rounding) with
        ``u`` (V) held, (len(dts), nx).

        CVODES runs over blocks of a power of two intervals (13 intervals: 8, 4, 1;
        a block of b intervals lasts b times its first one), which keeps the number
        of distinct output grids (one integrator each) small.
        """
        n = len(dts)
        out = np.empty((n, len(state)))
        done = 0
        while done < n:
            b = 1 << ((n - done).bit_length() - 1)
            out[done:done + b] = self.step(state, u, b * float(dts[done]), b)
            state = out[done + b - 1]
            done += b
        return out

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
    with stop_on_signals(), _progress(len(t) - 1, "simulate", progress) as bar:
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
    duration = _duration(reference, t_end)
    _check_memory(T, duration, output_times, len(plant.states))
    grid = _grid(T, duration, output_times)
    if x0 is None:
        x0 = float(np.clip(reference(grid.out_t[0]), 0.0, plant.stroke))
    sim = Simulator(plant, rtol, atol, params)
    state = _initial(plant, x0)
    sampler = _Sampler(plant, controller, reference, state, position_resolution,
                       command_resolution, delay_samples)
    run = _run_uniform if grid.per else _run_events
    with stop_on_signals(), _progress(len(grid.events) - 1, "closed loop", progress) as bar:
        states, u_hist, r_hist = run(grid, sim, sampler, reference, state, bar)
    states, u_hist, r_hist = states[grid.out_idx], u_hist[grid.out_idx], r_hist[grid.out_idx]
    outs = sim.outputs(states, u_hist)
    return Trajectory(time=grid.out_t, states=states, inputs=u_hist.reshape(-1, 1), outputs=outs,
                      state_names=plant.state_names, output_names=plant.output_names,
                      reference=r_hist, units=_units(plant),
                      info={"mode": "closed_loop", "sample_time": T})


def _duration(reference, t_end: float | None) -> float:
    """``t_end``, else the reference's duration (s)."""
    if t_end is None:
        t_end = getattr(reference, "duration", None)
        if t_end is None:
            raise InputError("give t_end for a reference without a duration")
    return t_end


def _available_memory() -> float | None:
    """Bytes of memory available to a new allocation (Linux MemAvailable), or None."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return None


def _check_memory(T: float, duration: float, output_times, nx: int) -> None:
    """Refuse a closed-loop run whose sample grid cannot fit in memory.

    Every control sample (every ``T`` over the run) and output time is an event with a
    state (``nx`` floats), a command, a reference and ~8 float/int/bool grid entries of
    bookkeeping; a run needing more than the memory available would be stopped by the
    OOM killer after minutes of swapping (issue 15: ``sample_time = 1e-9`` asked for
    23 GB), so it is an error naming the cause instead.
    """
    if not (np.isfinite(T) and T > 0):
        raise InputError(f"the controller's sample time must be a finite number > 0 s, "
                         f"got {T:g}")
    if not np.isfinite(duration) or duration < 0:
        raise InputError(f"the run's duration must be a finite number >= 0 s, got "
                         f"{duration:g}")
    span = duration
    if output_times is not None and len(output_times):
        span = float(np.max(output_times) - np.min(output_times))
    n_events = span / T + 1 + (0 if output_times is None else len(output_times))
    need = n_events * 8.0 * (nx + 10)
    avail = _available_memory()
    if avail is not None and need > 0.5 * avail:
        raise InputError(
            f"a closed-loop run over {span:g} s at a sample time of {T:g} s has "
            f"{n_events:.3g} control samples and needs ~{need / 1e9:.3g} GB, more than half "
            f"the {avail / 1e9:.3g} GB of memory available: check the controller's "
            f"sample_time (s, not ms) and the run's duration (a time column in ms? a gap "
            f"in t?)")


@dataclass(frozen=True)
class _Grid:
    """The times of a closed-loop run.

    Attributes
    ----------
    events : s, the control samples and the output times merged (closer than 1e-9 s: one).
    is_ctrl : bool per event, a control sample.
    ctrl_pos : indices of the control samples in ``events``.
    out_t : s, the output times. out_idx : index of each output time in ``events``.
    per : events per control interval when every interval has the same number of
        equidistant events, from the first event to the last (the fast path: one
        CVODES call per interval); else 0.
    """

    events: np.ndarray
    is_ctrl: np.ndarray
    ctrl_pos: np.ndarray
    out_t: np.ndarray
    out_idx: np.ndarray
    per: int


def _grid(T: float, t_end: float, output_times: Sequence[float] | None) -> _Grid:
    """Control samples every T from the first output time, merged with the output times
    (default: the samples 0 .. t_end)."""
    if output_times is None:
        out_t = T * np.arange(int(np.floor(t_end / T + 1e-9)) + 1)
    else:
        out_t = np.asarray(output_times, dtype=float)
        if np.any(np.diff(out_t) <= 0):
            raise InputError("output_times must be strictly increasing")
    t0 = out_t[0]
    t_ctrl = t0 + T * np.arange(int(np.floor((out_t[-1] - t0) / T + 1e-9)) + 1)
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
    return _Grid(events=events, is_ctrl=is_ctrl, ctrl_pos=ctrl_pos, out_t=out_t,
                 out_idx=out_idx, per=int(per[0]) if uniform else 0)


class _Sampler:
    """The controller as the loop sees it: measure, update, clip, quantise, delay.

    The position is quantised by the ADC step ``position_resolution`` (m), the
    command clipped to [command_min, command_max], quantised by the DAC step
    ``command_resolution`` (V) and applied ``delay_samples`` samples later (until
    then the spool's initial position, or the valve centre, is held). ``u`` is the
    command applied now, V.
    """

    def __init__(self, plant: Plant, controller, reference, state: np.ndarray,
                 position_resolution: float | None, command_resolution: float | None,
                 delay_samples: int) -> None:
        prm = plant.params
        self.controller, self.reference = controller, reference
        self.u_min, self.u_max = prm["valve.command_min"], prm["valve.command_max"]
        self.position_resolution = (prm.get("controller.position_resolution")
                                    if position_resolution is None else position_resolution)
        self.command_resolution = (prm.get("controller.command_resolution")
                                   if command_resolution is None else command_resolution)
        self.ix, self.iv = plant.state_index("x"), plant.state_index("v")
        self.ipa, self.ipb = plant.state_index("p_a"), plant.state_index("p_b")
        self.cstate = controller.reset()
        self.pending = [None] * delay_samples
        spool = plant.states_of_kind("spool")
        self.u = float(np.clip(state[spool[0]], self.u_min, self.u_max)) \
            if spool else prm["valve.command_center"]

    def sample(self, state: np.ndarray, t: float) -> None:
        """The controller's update at time ``t`` (s) from the plant's ``state``."""
        y = {"x": _quantise(float(state[self.ix]), self.position_resolution),
             "v": float(state[self.iv]), "p_a": float(state[self.ipa]),
             "p_b": float(state[self.ipb])}
        r = float(self.reference(t))
        self.cstate, u_cmd = self.controller.update(self.cstate, r, y)
        u_cmd = _quantise(float(np.clip(u_cmd, self.u_min, self.u_max)), self.command_resolution)
        u_cmd = float(np.clip(u_cmd, self.u_min, self.u_max))
        if self.pending:
            self.pending.append(u_cmd)
            u_cmd = self.pending.pop(0)
            if u_cmd is None:
                u_cmd = self.u
        self.u = u_cmd


def _run_uniform(grid: _Grid, sim: Simulator, sampler: _Sampler, reference,
                 state: np.ndarray, bar) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The loop when every control interval holds ``grid.per`` equidistant events: one
    CVODES call per interval. Returns states, commands and references at the events."""
    events, ctrl_pos, m = grid.events, grid.ctrl_pos, grid.per
    states = np.empty((len(events), len(state)))
    u_hist, r_hist = np.empty(len(events)), np.empty(len(events))
    dur = float(events[ctrl_pos[1]] - events[ctrl_pos[0]])
    states[0] = state
    for j, k in enumerate(ctrl_pos[:-1]):
        sampler.sample(state, events[k])
        r_hist[k:k + m] = reference(events[k:k + m])
        u_hist[k:k + m] = sampler.u
        block = sim.step(state, sampler.u, dur, m)
        states[k + 1:k + m + 1] = block
        state = block[-1]
        if j % 50 == 0:
            bar.update(min(50 * m, len(events) - 1 - k))
    last = len(events) - 1
    sampler.sample(state, events[last])
    u_hist[last], r_hist[last] = sampler.u, reference(events[last])
    return states, u_hist, r_hist


def _run_events(grid: _Grid, sim: Simulator, sampler: _Sampler, reference,
                state: np.ndarray, bar) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The loop event by event: a control update at the control samples, one CVODES call
    to the next event. Returns states, commands and references at the events."""
    events = grid.events
    states = np.empty((len(events), len(state)))
    u_hist, r_hist = np.empty(len(events)), np.empty(len(events))
    for k in range(len(events)):
        if grid.is_ctrl[k]:
            sampler.sample(state, events[k])
        states[k] = state
        u_hist[k] = sampler.u
        r_hist[k] = reference(events[k])
        if k + 1 < len(events):
            state = sim.step(state, sampler.u, events[k + 1] - events[k])[-1]
            if k % 200 == 0:
                bar.update(min(200, len(events) - 1 - k))
    return states, u_hist, r_hist
