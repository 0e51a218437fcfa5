"""Replay a recording on a plant model: the one place that does it.

A replay simulates the plant along a recording, from a state at its first sample, with
one of a few small immutable strategies passed in (as diffrax passes a solver):

* :class:`ClosedLoop` -- CVODES closed loop on the recording's reference ``r`` (held
  between samples) with a controller (default: the plant file's ``[controller]``).
* :class:`OpenLoop` -- CVODES open loop on the recorded command ``u`` (zero-order
  hold), per sample (:func:`workbench.simulate.open_loop`) or once over each run of
  equal commands (:meth:`workbench.simulate.Simulator.hold`), optionally re-anchored
  on given states every so many samples.
* :class:`Fallback` -- a first strategy, and a second one when the first fails.

Any callable ``strategy(plant, recording, x0, params, progress)`` returning something
indexed by signal name (a :class:`workbench.simulate.Trajectory`) is a strategy too:
the diagnosis passes its fixed-step engine re-anchored on the measured state
(:class:`workbench.diagnose.core.EngineOpenLoop`), which is not CVODES.

:func:`run` replays with a strategy; :func:`initial_state` is the state at the
recording's first sample; :func:`replay` is what ``workbench simulate`` computes
(closed loop when the recording has ``r`` and the plant a ``[controller]``, else open
loop, from :func:`initial_state`). Callers: the CLI (:func:`replay`), the grey-box
estimator's before/after fits and integration check
(:mod:`workbench.identify.grey_box`), the diagnosis (:func:`workbench.diagnose.core.replay`).

>>> from workbench import Plant
>>> from workbench.recording import Recording
>>> from workbench import replay as rp
>>> plant = Plant.from_toml("designs/plants/rig25_mpye.toml")
>>> rec = Recording.load("tests/data/recordings/step_small.csv")
>>> result = rp.replay(plant, rec)
>>> result.mode                                  # the recording has r, the plant a [controller]
'closed_loop'
>>> run = rp.run(plant, rec, rp.OpenLoop(steps="run"))
>>> len(run["x"]) == len(rec)                    # one simulated sample per recorded one
True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, Sequence

import numpy as np

from .errors import InputError, WorkbenchError
from .output import reraise_interrupt, stop_on_signals

__all__ = ["Replay", "replay", "run", "initial_state", "is_closed", "ClosedLoop", "OpenLoop",
           "Fallback", "Strategy", "SIMULATED_COLUMNS", "command_agreement",
           "controller_agreement", "controller_phase", "CONTROLLER_AGREEMENT"]

#: %: fit of the recorded command by the plant file's controller below which that
#: controller is taken not to be the loop that ran (see :func:`command_agreement`).
CONTROLLER_AGREEMENT = 90.0

#: Columns of a recording that the simulation replaces; the others ("r", unknown
#: columns) are copied from the recording.
SIMULATED_COLUMNS = ("u", "x", "p_a", "p_b", "p_s", "v")

_MODES = ("auto", "closed", "open")


class Strategy(Protocol):
    """How a recording is replayed: ``(plant, recording, x0, params, progress) -> run``.

    ``x0`` is the state (SI, plant order) at the first sample, ``params`` the plant's
    parameter vector (None: ``plant.p0``); the run is indexed by signal name.
    """

    def __call__(self, plant, recording, x0: np.ndarray, params: Sequence[float] | None,
                 progress: bool | None) -> Any: ...


@dataclass(frozen=True)
class ClosedLoop:
    """CVODES closed loop on the recording's ``r`` (m, held between samples).

    Attributes
    ----------
    controller : object or None
        The controller (None: :func:`workbench.controllers.from_plant`).

    The trajectory's time runs from 0 s at the recording's first sample.
    """

    controller: Any = None

    def __call__(self, plant, recording, x0, params=None, progress=False):
        from . import controllers, simulate
        t = np.asarray(recording.t, dtype=float) - float(recording.t[0])
        ctrl = controllers.from_plant(plant) if self.controller is None else self.controller
        ref = simulate.Reference(times=t, values=np.asarray(recording["r"], dtype=float),
                                 hold=True)
        return simulate.closed_loop(plant, ctrl, ref, x0=x0, output_times=t, params=params,
                                    progress=progress)


@dataclass(frozen=True)
class OpenLoop:
    """CVODES open loop on the recorded command ``u`` (V, held between samples).

    Attributes
    ----------
    steps : {"sample", "run"}
        "sample": :func:`workbench.simulate.open_loop` (one CVODES call per sample; the
        trajectory's time from 0 s). "run": one :meth:`Simulator.hold
        <workbench.simulate.Simulator.hold>` over each run of equal commands (at most
        64 samples; the trajectory's time as recorded).
    anchor_every : int or None
        With ``steps="run"``: the state is reset to ``x0[j]`` at sample ``j *
        anchor_every`` (``x0`` then holds one state per anchor), which checks another
        integration over each interval without the drift of a long replay.
    """

    steps: str = "sample"
    anchor_every: int | None = None

    def __post_init__(self) -> None:
        if self.steps not in ("sample", "run"):
            raise InputError(f"OpenLoop steps must be 'sample' or 'run', got {self.steps!r}")
        if self.anchor_every is not None and (self.steps != "run" or self.anchor_every < 1):
            raise InputError("OpenLoop anchor_every needs steps='run' and a positive number "
                             f"of samples, got {self.anchor_every!r}")

    def __call__(self, plant, recording, x0, params=None, progress=False):
        from . import simulate
        if self.steps == "sample":
            t = recording.t
            return simulate.open_loop(plant, t - t[0], recording["u"], x0=x0, params=params,
                                      progress=progress)
        return hold_runs(plant, np.asarray(recording.t, dtype=float),
                         np.asarray(recording["u"], dtype=float), x0, params,
                         self.anchor_every)


@dataclass(frozen=True)
class Fallback:
    """``first``; when it fails (:class:`WorkbenchError`), ``then``."""

    first: Strategy
    then: Strategy

    def __call__(self, plant, recording, x0, params=None, progress=False):
        try:
            return self.first(plant, recording, x0, params, progress)
        except WorkbenchError as exc:
            reraise_interrupt(exc)          # an interrupted first try is no reason to fall back
            return self.then(plant, recording, x0, params, progress)


def run(plant, recording, strategy: Strategy, x0: np.ndarray | None = None,
        params: Sequence[float] | None = None, progress: bool | None = False):
    """Replay ``recording`` on ``plant`` with ``strategy``.

    Parameters
    ----------
    plant : workbench.Plant
    recording : workbench.recording.Recording
        Time ``t`` (s), and ``u`` (V) or ``r`` (m) as the strategy needs.
    strategy : Strategy
        :class:`ClosedLoop`, :class:`OpenLoop`, :class:`Fallback` or another callable.
    x0 : array, optional
        State (SI, plant order) at the first sample; default :func:`initial_state`.
    params : sequence of float, optional
        Parameter vector (default ``plant.p0``).
    progress : bool or None
        Progress bar (None: when on a terminal).

    Returns
    -------
    workbench.simulate.Trajectory (or what the strategy returns)
    """
    x0 = initial_state(plant, recording) if x0 is None else np.asarray(x0, dtype=float)
    with stop_on_signals():             # a Ctrl-C inside CasADi stops, never falls back
        return strategy(plant, recording, x0, params, progress)


def initial_state(plant, recording, u0: float | None = None, p_a: float | None = None,
                  p_b: float | None = None, recorded_pressures: bool = True) -> np.ndarray:
    """State at the recording's first sample, SI.

    Parameters
    ----------
    plant : workbench.Plant
    recording : workbench.recording.Recording
        Its first position ``x`` (m) is clipped into the stroke.
    u0 : float, optional
        Command (V) at the first sample, for the spool state (default: the
        equilibrium command).
    p_a, p_b : float, optional
        Chamber pressures (Pa absolute), e.g. smoothed ones; default the recorded first
        values when ``recorded_pressures`` and recorded, else the equilibrium.
    recorded_pressures : bool
        Take missing ``p_a``, ``p_b`` from the recording.

    Returns
    -------
    numpy.ndarray
        :meth:`workbench.Plant.initial_state` at that position and those pressures.
    """
    x_first = float(np.clip(recording["x"][0], 0.0, plant.stroke))
    if recorded_pressures and p_a is None and "p_a" in recording:
        p_a = float(recording["p_a"][0])
    if recorded_pressures and p_b is None and "p_b" in recording:
        p_b = float(recording["p_b"][0])
    kw = {} if u0 is None else {"u0": float(u0)}
    return plant.initial_state(x_first, p_a=p_a, p_b=p_b, **kw)


def is_closed(plant, recording, mode: str) -> bool:
    """Whether a replay in ``mode`` ("auto", "closed", "open") runs in closed loop.

    Raises
    ------
    InputError
        "closed" without an ``r`` column or a ``[controller]``; an unknown mode.
    """
    if mode not in _MODES:
        raise InputError(f"replay mode must be one of {', '.join(_MODES)}, got {mode!r}")
    if mode == "closed":
        if "r" not in recording:
            raise InputError("closed-loop replay needs an 'r' column", source=recording.source)
        if not plant.params.has_controller:
            raise InputError("closed-loop replay needs a [controller] section",
                             source=plant.params.source)
        return True
    if mode == "open":
        return False
    return "r" in recording and plant.params.has_controller


def hold_runs(plant, t: np.ndarray, u: np.ndarray, x0: np.ndarray,
              params: Sequence[float] | None = None, anchor_every: int | None = None):
    """Open-loop CVODES, u held on [t_k, t_k+1), one :meth:`Simulator.hold
    <workbench.simulate.Simulator.hold>` per run of equal commands (at most 64 samples).

    ``t`` (s), ``u`` (V) per sample; ``x0`` the first state, or with ``anchor_every``
    one state per anchor (reset at sample ``j * anchor_every``). The trajectory's time
    is ``t``.
    """
    from . import simulate
    anchors = None
    if anchor_every is not None:
        anchors, every = np.asarray(x0, dtype=float), int(anchor_every)
        x0 = anchors[0]
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


@dataclass(frozen=True)
class Replay:
    """Result of :func:`replay`.

    Attributes
    ----------
    trajectory : workbench.simulate.Trajectory
        The simulation at the recording's sample times (time from 0 s).
    recording : workbench.recording.Recording
        The simulation as a recording with the recorded columns in their order: the
        simulated signals of :data:`SIMULATED_COLUMNS`, the others copied; its time
        column is the recording's; metadata ``simulated_by = "workbench simulate"``.
    mode : str
        ``"closed_loop"`` or ``"open_loop"`` (the trajectory's ``info["mode"]``).
    """

    trajectory: object
    recording: object
    mode: str


def replay(plant, recording, mode: str = "auto", progress: bool | None = None) -> Replay:
    """Simulate ``recording`` on ``plant``: what ``workbench simulate`` computes.

    Parameters
    ----------
    plant : workbench.Plant
        The plant model (with a ``[controller]`` for a closed-loop replay).
    recording : workbench.recording.Recording
        Columns ``t`` (s), ``x`` (m) and ``u`` (V) for open loop or ``r`` (m) for closed
        loop; ``p_a``, ``p_b`` (Pa absolute) set the initial pressures when present.
    mode : {"auto", "closed", "open"}
        "auto": closed loop when ``r`` and a ``[controller]`` both exist, else open
        loop; "closed" requires both; "open" replays ``u``.
    progress : bool or None
        Progress bar (None: when on a terminal; False: none).

    Returns
    -------
    Replay
        The trajectory, the simulated recording and the mode that ran: closed loop
        with the plant's controller (:class:`ClosedLoop`) or open loop per sample
        (:class:`OpenLoop`), from :func:`initial_state`.

    Raises
    ------
    InputError
        A closed-loop replay asked for without an ``r`` column or a ``[controller]``,
        or an unknown ``mode``; a recording that is implausible on its own or for this
        plant (:meth:`~workbench.recording.Recording.check`: time in ms, x outside the
        stroke, u outside the valve's range, ...), before anything is simulated.
    """
    if hasattr(recording, "check"):
        recording.check(plant)
    strategy = ClosedLoop() if is_closed(plant, recording, mode) else OpenLoop()
    traj = run(plant, recording, strategy, progress=progress)
    return Replay(trajectory=traj, recording=_as_recording(traj, recording),
                  mode=str(traj.info["mode"]))


def _as_recording(run, rec):
    """Simulated recording with the same columns as ``rec`` (r and unknown columns copied)."""
    from .recording import Recording
    data = {}
    for c in rec.columns:
        if c == "t":
            continue
        if c in SIMULATED_COLUMNS:
            data[c] = np.asarray(run[c], dtype=float)
        else:
            data[c] = np.asarray(rec[c], dtype=float)
    meta = dict(rec.metadata)
    meta["simulated_by"] = "workbench simulate"
    data["t"] = rec.t
    return Recording(columns=tuple(rec.columns), data=data, metadata=meta,
                     source="<simulation>")


def controller_phase(u: np.ndarray, ratio: int) -> tuple[int, float]:
    """Phase (sample index mod ratio) at which u changes, and the share of changes there."""
    changes = np.flatnonzero(np.abs(np.diff(u)) > 1e-12) + 1
    if len(changes) == 0 or ratio <= 1:
        return 0, 1.0
    counts = np.bincount(changes % ratio, minlength=ratio)
    ph = int(np.argmax(counts))
    return ph, float(counts[ph] / counts.sum())


def controller_agreement(plant, controller: Any, rec, x: np.ndarray,
                         phase: int, ratio: int) -> float:
    """Fit (%) of the recorded command by the plant file's controller at its instants."""
    idx = np.arange(len(x))[phase::ratio]
    state = controller.reset()
    u_pred = np.empty(len(idx))
    r_rec = np.asarray(rec["r"])
    for j, i in enumerate(idx):
        state, u_pred[j] = controller.update(state, float(r_rec[i]), {"x": float(x[i])})
    u_pred = np.clip(u_pred, plant.params["valve.command_min"],
                     plant.params["valve.command_max"])
    u_rec = np.asarray(rec["u"])[idx]
    from .signals import fit
    if np.ptp(u_rec) > 0:
        return fit(u_rec, u_pred)
    # A constant recorded command has no spread to normalise the fit by. It agrees only
    # if the controller's own command is that constant too: judged by the prediction's
    # spread (the same fit with the roles swapped), or, both constant, by equality to
    # the DAC's resolution scale (1e-9 of the command range). Before, any constant u
    # counted as 100 %, so a log of the wrong channel (u stuck at the centre while the
    # piston moves) was replayed in closed loop on r and came out as "no finding".
    if np.ptp(u_pred) > 0:
        return fit(u_pred, u_rec)
    span = plant.params["valve.command_max"] - plant.params["valve.command_min"]
    return 100.0 if abs(float(u_pred[0]) - float(u_rec[0])) <= 1e-9 * span else 0.0

def command_agreement(plant, rec) -> float | None:
    """Fit (%) of the recorded command ``u`` by the plant file's ``[controller]`` run on
    the recorded ``r`` and ``x`` at its own update instants (the phase at which ``u``
    changes); None when that cannot be judged (no ``[controller]``, no ``r``, ``u`` or
    ``x``, or a controller period that is not a multiple of the sample time).

    A low value (diagnose uses 90 %) says the plant file's controller is not the loop
    that ran (a delay, other gains, a filter): a closed-loop replay then drifts for
    that reason, not because of the plant model.
    """
    if not plant.params.has_controller or not all(c in rec for c in ("r", "u", "x")):
        return None
    from .controllers import from_plant
    controller = from_plant(plant)
    t = np.asarray(rec["t"], dtype=float)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    if dt <= 0.0:
        return None
    ratio = int(round(controller.sample_time / dt))
    if ratio < 1 or abs(ratio * dt - controller.sample_time) > 0.02 * dt:
        return None
    phase, _share = controller_phase(np.asarray(rec["u"], dtype=float), ratio)
    return controller_agreement(plant, controller, rec, np.asarray(rec["x"], dtype=float),
                                phase, ratio)
