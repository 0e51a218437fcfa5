"""Recordings prepared for the fit (:class:`_Data`): command, compared signals, noise
levels (:func:`workbench.signals.noise_floor`), and start values taken from the data."""

from __future__ import annotations

import difflib
import math
import os
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from ... import replay
from ...errors import InputError, WorkbenchError
from ...plant import Plant
from ...recording import Recording, load_recording
from ...signals import derivative, noise_floor, odd_window


#: Recorded signals the estimator can compare with the model (plant output names).
SIGNALS: tuple[str, ...] = ("x", "p_a", "p_b", "v", "p_s")



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
    """State at the first sample from the recording (:func:`workbench.replay.initial_state`
    with the first command): measured states, v from x, the rest from the equilibrium
    at the first position (or resting values)."""
    names = plant.state_names
    try:
        st = replay.initial_state(plant, d.rec, u0=float(d.u[0]))
    except WorkbenchError:
        # no equilibrium there: 3 bar where a pressure is not recorded
        p_a = float(d.rec["p_a"][0]) if "p_a" in d.rec else None
        p_b = float(d.rec["p_b"][0]) if "p_b" in d.rec else None
        st = replay.initial_state(plant, d.rec, u0=float(d.u[0]), p_a=p_a if p_a else 3e5,
                                  p_b=p_b if p_b else 3e5)
    v = _smooth_derivative(d.t, np.asarray(d.rec["x"], dtype=float))
    st[names.index("v")] = float(v[0]) if "v" not in d.rec else float(d.rec["v"][0])
    if "p_s" in names and "p_s" in d.rec:
        st[names.index("p_s")] = float(d.rec["p_s"][0])
    return st
