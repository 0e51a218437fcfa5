"""Locate a mismatch: in which time intervals and operating regimes it lives.

Operating regimes are masks over the samples, computed from the measurement only:

=========================  ===================================================
at rest                    piston speed below 3 velocity-noise levels
moving                     the rest
velocity reversal          within 50 ms of a change of the direction of motion
near valve centre          command within 5 % of the span of the valve centre
high flow                  command beyond 90 % of the recording's openings (>= 5 % span)
fast pressure transient    a chamber pressure changing faster than 90 % of the time
accelerating               acceleration larger than 90 % of the time
=========================  ===================================================

:func:`concentration` says how much of a per-sample error falls into each regime,
relative to the time spent there (a ratio above 1: the mismatch lives there).
:func:`intervals` turns a per-sample error into time intervals.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from ..signals import dilate
from .data import Prepared

__all__ = ["REGIMES", "EXPECTED", "regimes", "concentration", "intervals", "smooth_error",
           "consistency"]

REGIMES = ("at rest", "moving", "velocity reversal", "near valve centre", "high flow",
           "fast pressure transient", "accelerating")

#: Where each candidate's signature is expected to show.
EXPECTED: dict[str, tuple[str, ...]] = {
    "dry_friction": ("at rest", "velocity reversal"),
    "valve_deadband": ("near valve centre",),
    "valve_offset": ("at rest", "near valve centre"),
    "valve_dynamics": ("fast pressure transient",),
    "line_dynamics": ("fast pressure transient",),
    "leakage": ("at rest",),
    "supply_droop": ("high flow",),
    "heat_transfer": ("fast pressure transient", "at rest"),
    "parameter_error:load.mass": ("accelerating",),
    "parameter_error:load.viscous_friction": ("moving",),
    "parameter_error:valve.sonic_conductance": ("high flow", "moving"),
    "parameter_error:supply.pressure": ("high flow",),
    "parameter_error:nominal values": ("accelerating", "moving", "high flow"),
}


def regimes(prep: Prepared, v_rest: float) -> dict[str, np.ndarray]:
    """Boolean masks of the operating regimes (see the module docstring)."""
    n = prep.n
    prm = prep.plant.params
    v = prep.v
    rest = np.abs(v) < v_rest
    moving = ~rest
    sgn = np.sign(np.where(moving, v, 0.0))
    # direction changes between moving samples (ignoring rest in between up to 50 ms)
    k50 = max(int(round(0.05 / prep.dt)), 1)
    last = np.zeros(n)
    cur = 0.0
    for i in range(n):
        if sgn[i] != 0:
            cur = sgn[i]
        last[i] = cur
    flips = np.flatnonzero(np.diff(last) != 0) + 1
    flips = flips[last[flips - 1] != 0]
    rev = np.zeros(n, dtype=bool)
    rev[flips] = True
    reversal = dilate(rev, k50)
    u = np.asarray(prep.rec["u"], dtype=float)
    s = (u - prm["valve.command_center"]) / prm["valve.command_span"]
    centre = np.abs(s) < 0.05
    # high flow: the largest openings of this recording (a gentle loop may never open
    # the valve far), at least 5 % of the span
    high = np.abs(s) > max(float(np.quantile(np.abs(s), 0.9)), 0.05)
    out = {"at rest": rest, "moving": moving, "velocity reversal": reversal,
           "near valve centre": centre, "high flow": high}
    if prep.has_pressures:     # NaN where a side was not recorded (several recordings)
        rate = np.fmax(np.abs(prep.dpa), np.abs(prep.dpb))
        seen = np.isfinite(rate)
        out["fast pressure transient"] = seen & (
            np.where(seen, rate, 0.0) > (np.quantile(rate[seen], 0.9) if seen.any() else 0.0))
    else:
        out["fast pressure transient"] = np.zeros(n, dtype=bool)
    out["accelerating"] = np.abs(prep.a) > np.quantile(np.abs(prep.a), 0.9)
    return out


def concentration(err: np.ndarray, masks: Mapping[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Share of ``err`` (non-negative per sample, NaN ignored) and of time in each regime."""
    e = np.where(np.isfinite(err), np.maximum(err, 0.0), 0.0)
    valid = np.isfinite(err)
    total = float(e.sum())
    out = {}
    for name, m in masks.items():
        t_share = float(np.mean(m[valid])) if valid.any() else 0.0
        e_share = float(e[m].sum() / total) if total > 0 else 0.0
        out[name] = {"error_share": e_share, "time_share": t_share,
                     "ratio": e_share / t_share if t_share > 0 else 0.0}
    return out


def consistency(gain_per_sample: np.ndarray, masks: Mapping[str, np.ndarray],
                name: str) -> float | None:
    """How much more of a candidate's gain lies in its expected regimes than time does
    (ratio of shares; None when no regime is expected or no gain)."""
    exp = EXPECTED.get(name)
    if not exp:
        return None
    union = np.zeros(len(gain_per_sample), dtype=bool)
    for r in exp:
        union |= masks.get(r, np.zeros_like(union))
    g = np.where(np.isfinite(gain_per_sample), np.maximum(gain_per_sample, 0.0), 0.0)
    total = g.sum()
    t = float(np.mean(union))
    if total <= 0 or t <= 0:
        return None
    return float((g[union].sum() / total) / t)


def smooth_error(err: np.ndarray, dt: float, seconds: float = 0.1) -> np.ndarray:
    """Moving average of a per-sample error (NaN counted as 0)."""
    k = max(int(round(seconds / dt)), 1)
    e = np.where(np.isfinite(err), err, 0.0)
    return np.convolve(e, np.ones(k) / k, mode="same")


def intervals(score: np.ndarray, t: np.ndarray, threshold: float, merge_gap: float = 0.2,
              min_length: float = 0.03, max_count: int = 12) -> list[list[float]]:
    """Time intervals (s) where ``score`` exceeds ``threshold``, merged across short gaps;
    the ``max_count`` with the largest integrated score, in time order."""
    above = score > threshold
    if not above.any():
        return []
    edges = np.diff(above.astype(int))
    starts = list(np.flatnonzero(edges == 1) + 1)
    ends = list(np.flatnonzero(edges == -1) + 1)
    if above[0]:
        starts.insert(0, 0)
    if above[-1]:
        ends.append(len(score))
    spans = []
    for a, b in zip(starts, ends):
        if spans and t[a] - t[spans[-1][1] - 1] < merge_gap:
            spans[-1][1] = b
        else:
            spans.append([a, b])
    spans = [s for s in spans if t[s[1] - 1] - t[s[0]] >= min_length]
    spans.sort(key=lambda s: -float(np.sum(score[s[0]:s[1]])))
    spans = sorted(spans[:max_count])
    return [[round(float(t[a]), 3), round(float(t[b - 1]), 3)] for a, b in spans]
