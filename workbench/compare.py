"""Side-by-side figures of validated position loops (the numbers a design report compares).

:func:`run_figures` turns one :class:`workbench.validate.Validation` into the whole-run
figures a reviewer compares controllers on -- tracking error (IAE, largest error,
largest error once settled), settling, overshoot, steady-state error, ramp error, air
consumption, command activity, saturation and the ranges of command, pressures and
position -- and :func:`comparison_rows` lays several runs out as table rows (with
the ratio to a baseline). Every figure is SI in the dictionary; :data:`FIGURES`
says how each is displayed.

Definitions
-----------
air consumption
    integral of the valve's supply mass flow ``q_supply`` over the run (trapezoid on
    the output grid), also as litres ANR (air at 20 degC, 1 bar, 65 % RH).
command activity
    total variation of the command at the control samples per second of run,
    sum |u_k - u_k-1| / duration (V/s): 0 for a constant command, 2 A f for a
    square wave of amplitude A and frequency f toggling every half period.
largest error once settled
    max |r - x| outside the first ``settle_window`` seconds after each step.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from .errors import InputError
from .physics.gas import RHO_ANR

__all__ = ["FIGURES", "RESOLUTION", "SETTLE_WINDOW", "run_figures", "comparison_rows"]

#: s after each step of the reference from which the error counts as "settled".
SETTLE_WINDOW = 0.5

#: (key, label, display scale, display unit) in report order; lower is better for all.
FIGURES: tuple[tuple[str, str, float, str], ...] = (
    ("iae", "IAE (integral of |r - x|)", 1e3, "mm s"),
    ("max_error", "largest |r - x|", 1e3, "mm"),
    ("max_error_settled", f"largest |r - x| from {SETTLE_WINDOW:g} s after each step", 1e3, "mm"),
    ("settling_time", "worst settling time", 1.0, "s"),
    ("overshoot", "worst overshoot", 1.0, "%"),
    ("steady_state_error", "worst steady-state error", 1e3, "mm"),
    ("ramp_error", "largest ramp error", 1e3, "mm"),
    ("air_kg", "air drawn from the supply", 1e3, "g"),
    ("air_l_anr", "air drawn from the supply (ANR)", 1.0, "l"),
    ("command_activity", "command activity (sum |u_k - u_k-1| per s)", 1.0, "V/s"),
    ("saturation", "time at a command limit", 100.0, "%"),
)


#: Resolution of each figure (SI): a ratio to a value below it is not shown (the ratio
#: of two numerically-zero overshoots says nothing).
RESOLUTION = {"iae": 1e-6, "max_error": 1e-6, "max_error_settled": 1e-6, "settling_time": 1e-3,
              "overshoot": 1e-2, "steady_state_error": 1e-6, "ramp_error": 1e-6,
              "air_kg": 1e-6, "air_l_anr": 1e-3, "command_activity": 1e-3, "saturation": 1e-4}


def _finite_max(values) -> float:
    vals = [float(v) for v in values if not math.isnan(float(v))]
    return max(vals) if vals else math.nan


def run_figures(v, settle_window: float = SETTLE_WINDOW) -> dict[str, Any]:
    """Whole-run figures of one validation (SI units; see the module text).

    Parameters
    ----------
    v : workbench.validate.Validation
    settle_window : s after each step excluded from ``max_error_settled``.

    Returns
    -------
    dict with the keys of :data:`FIGURES` plus ``overshoot_abs`` (m), ``u_min``,
    ``u_max`` (V), ``p_min``, ``p_max`` (Pa), ``x_min``, ``x_max`` (m), ``passed``
    and ``failed`` (names of the failed checks).
    """
    if not settle_window >= 0.0:
        raise InputError(f"settle_window must be >= 0 s, got {settle_window!r}")
    run = v.trajectory
    t = np.asarray(run.time, dtype=float)
    if len(t) < 2:
        raise InputError("the validation holds fewer than two samples; nothing to compare")
    x, u = run["x"], run["u"]
    r = np.asarray(v.reference(t), dtype=float)
    e = np.abs(r - x)
    settled = np.ones_like(t, dtype=bool)
    for m in v.segments:
        if m.segment.kind == "step":
            settled &= ~((t >= m.segment.start) & (t < m.segment.start + settle_window))
    q = run["q_supply"]
    air_kg = float(np.sum(0.5 * (q[1:] + q[:-1]) * np.diff(t)))
    steps = [m for m in v.segments if m.segment.kind == "step"]
    holds = [m for m in v.segments if m.segment.kind in ("step", "hold")]
    T = float(run.info.get("sample_time", 0.0) or 0.0)
    if T > 0.0:
        k = t / T
        u_s = u[np.isclose(k, np.round(k), rtol=0.0, atol=1e-6)]
    else:                                       # no sampling information: every output
        u_s = u
    duration = float(t[-1] - t[0])
    p_all = np.concatenate([run["p_a"], run["p_b"]])
    return {
        "iae": float(v.metrics.iae),
        "max_error": float(np.max(e)),
        "max_error_settled": float(np.max(e[settled])) if settled.any() else math.nan,
        "settling_time": _finite_max(m.settling_time for m in steps),
        "overshoot": _finite_max(m.overshoot for m in steps),
        "overshoot_abs": _finite_max(m.overshoot_abs for m in steps),
        "steady_state_error": _finite_max(m.steady_state_error for m in holds),
        "ramp_error": float(v.metrics.ramp_error_max),
        "air_kg": air_kg,
        "air_l_anr": air_kg / RHO_ANR * 1e3,
        "command_activity": float(np.sum(np.abs(np.diff(u_s))) / duration),
        "saturation": float(v.metrics.saturation_fraction),
        "u_min": float(np.min(u)), "u_max": float(np.max(u)),
        "p_min": float(np.min(p_all)), "p_max": float(np.max(p_all)),
        "x_min": float(np.min(x)), "x_max": float(np.max(x)),
        "passed": bool(v.passed),
        "failed": [c.name for c in v.failed],
    }


def comparison_rows(figures: Mapping[str, Mapping[str, Any]], baseline: str | None = None,
                    keys: Sequence[str] | None = None) -> tuple[list[str], list[list]]:
    """Rows of a comparison table: one per figure, one column per run.

    Parameters
    ----------
    figures : {run name: :func:`run_figures` dict}, in column order.
    baseline : a run name; adds one column per other run with baseline / run
        (> 1: that run is better by this factor; all figures are lower-is-better).
        A ratio is left empty (None) when either value is below the figure's
        :data:`RESOLUTION` or not finite.
    keys : which figures (default all of :data:`FIGURES`).

    Returns
    -------
    (header, rows) ready for ``report.Table``; values in display units.
    """
    names = list(figures)
    if not names:
        raise InputError("nothing to compare: give at least one run")
    if baseline is not None and baseline not in figures:
        raise InputError(f"baseline {baseline!r} is not one of the runs {names}")
    defs = {k: (lab, f, unit) for k, lab, f, unit in FIGURES}
    keys = [k for k, *_ in FIGURES] if keys is None else list(keys)
    unknown = [k for k in keys if k not in defs]
    if unknown:
        raise InputError(f"unknown figures {unknown}; known: {sorted(defs)}")
    others = [n for n in names if n != baseline] if baseline is not None else []
    header = ["quantity", "unit"] + names + [f"{baseline} / {n}" for n in others]
    rows = []
    for k in keys:
        lab, f, unit = defs[k]
        row = [lab, unit] + [float(figures[n][k]) * f for n in names]
        for n in others:
            b, o = float(figures[baseline][k]), float(figures[n][k])
            ok = (math.isfinite(b) and math.isfinite(o) and o >= RESOLUTION[k]
                  and b >= RESOLUTION[k])
            row.append(b / o if ok else None)
        rows.append(row)
    return header, rows
