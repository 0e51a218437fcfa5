"""Replay a recording on a plant model: what ``workbench simulate`` computes.

Closed loop on the recording's reference ``r`` with the plant file's ``[controller]``
when both exist, else open loop on its command ``u``. The simulation starts from the
recording's first position (clipped into the stroke) and, when recorded, its first
chamber pressures; the rest of the initial state is the plant's equilibrium there
(:meth:`workbench.Plant.initial_state`).

>>> from workbench import Plant
>>> from workbench.recording import Recording
>>> from workbench.replay import replay
>>> plant = Plant.from_toml("designs/plants/rig25_mpye.toml")       # doctest: +SKIP
>>> result = replay(plant, Recording.load("run.csv"))              # doctest: +SKIP
>>> result.mode, result.recording["x"][:3]                         # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError

__all__ = ["Replay", "replay", "SIMULATED_COLUMNS"]

#: Columns of a recording that the simulation replaces; the others ("r", unknown
#: columns) are copied from the recording.
SIMULATED_COLUMNS = ("u", "x", "p_a", "p_b", "p_s", "v")

_MODES = ("auto", "closed", "open")


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
    """Simulate ``recording`` on ``plant``.

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
        The trajectory, the simulated recording and the mode that ran.

    Raises
    ------
    InputError
        A closed-loop replay asked for without an ``r`` column or a ``[controller]``,
        or an unknown ``mode``.
    """
    if mode not in _MODES:
        raise InputError(f"replay mode must be one of {', '.join(_MODES)}, got {mode!r}")
    run = _simulate(plant, recording, _is_closed(plant, recording, mode), progress)
    return Replay(trajectory=run, recording=_as_recording(run, recording),
                  mode=str(run.info["mode"]))


def _is_closed(plant, rec, mode: str) -> bool:
    """Whether the replay runs in closed loop (see :func:`replay`'s ``mode``)."""
    if mode == "closed":
        if "r" not in rec:
            raise InputError("closed-loop replay needs an 'r' column", source=rec.source)
        if not plant.params.has_controller:
            raise InputError("closed-loop replay needs a [controller] section",
                             source=plant.params.source)
        return True
    if mode == "open":
        return False
    return "r" in rec and plant.params.has_controller


def _simulate(plant, rec, closed: bool, progress: bool | None):
    """The trajectory at the recording's sample times, from its first measured state."""
    from . import controllers, simulate
    t = rec.t
    x_first = float(np.clip(rec["x"][0], 0.0, plant.stroke))
    pa = float(rec["p_a"][0]) if "p_a" in rec else None
    pb = float(rec["p_b"][0]) if "p_b" in rec else None
    x0 = plant.initial_state(x_first, p_a=pa, p_b=pb)
    if closed:
        ctrl = controllers.from_plant(plant)
        ref = simulate.Reference(times=t - t[0], values=np.asarray(rec["r"]), hold=True)
        return simulate.closed_loop(plant, ctrl, ref, x0=x0, output_times=t - t[0],
                                    progress=progress)
    return simulate.open_loop(plant, t - t[0], rec["u"], x0=x0, progress=progress)


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
