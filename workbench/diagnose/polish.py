"""Polish a finding's values with the grey-box estimator on its most telling windows.

The refit of :mod:`.refit` uses a fast fixed-step engine (ROS2 at about 2 ms) on the
whole recording; it names the effect and puts its values close. The grey-box
estimator (:func:`workbench.identify.grey_box.estimate`: multiple shooting, Radau IIA
at 1 ms or finer, IPOPT, covariance from the KKT system) is more exact but costs more
per second of data, so it is run on a few short windows where the finding removes
most of the mismatch (the largest smoothed gain of the short-horizon predictions),
starting from the refit's values. Its values replace the refit's when the estimator
converged to a good fit within a factor :data:`TRUST` of them (a local refinement; a
larger jump means the windows were not representative, and the refit stands).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..params import PlantParams
from ..plant import Plant
from ..recording import Recording
from .candidates import Candidate
from .data import Prepared
from .locate import smooth_error

__all__ = ["Polished", "polish", "WINDOW", "WINDOWS", "SKIP", "TRUST"]

#: s: length of a polishing window.
WINDOW = 1.5
#: Windows used.
WINDOWS = 2
#: Candidates not polished: the estimator's smooth friction needs 0.125 ms steps and
#: lines bring many states, either costs more than the diagnosis' time budget allows.
SKIP = ("dry_friction", "line_dynamics")
#: Largest factor between the polished and the refitted value that is trusted (the
#: polish refines locally; a larger jump means the windows were not representative).
TRUST = 2.0


@dataclass
class Polished:
    """Grey-box values (candidate keys), their std and 95 % intervals, and what it cost."""

    values: dict[str, float]
    std: dict[str, float]
    ci95: dict[str, tuple[float, float]]
    wall_s: float
    status: str
    windows: list[tuple[float, float]]


def _windows(prep: Prepared, gain: np.ndarray, length: float, count: int) -> list[tuple[int, int]]:
    g = smooth_error(np.where(np.isfinite(gain), np.maximum(gain, 0.0), 0.0), prep.dt, 0.3)
    n = int(round(length / prep.dt))
    out: list[tuple[int, int]] = []
    g = g.copy()
    for _ in range(count):
        if not np.any(g > 0):
            break
        c = int(np.argmax(g))
        a = int(np.clip(c - n // 4, 0, max(prep.n - n, 0)))
        out.append((a, min(a + n, prep.n)))
        g[max(a - n, 0):a + 2 * n] = 0.0
    return sorted(out)


def polish(prep: Prepared, base: PlantParams, cand: Candidate, values: Mapping[str, float],
           gain: np.ndarray, max_iter: int = 25) -> Polished | None:
    """Grey-box estimate of ``cand``'s values on the windows of largest ``gain``.

    Parameters
    ----------
    prep : the prepared recording.
    base : nominal parameters plus the earlier findings.
    cand : the candidate; ``values`` its refitted values (candidate keys).
    gain : per-sample gain of the finding (nominal minus augmented prediction error).

    Returns None when the estimator is not available, fails or has nothing to do.
    """
    try:
        from ..identify.grey_box import estimate
    except ImportError:             # pragma: no cover - estimator not built
        return None
    if not prep.pressures or cand.name in SKIP:
        return None
    t0 = time.perf_counter()
    full = np.ones(prep.n, dtype=bool)    # every recorded signal there (several recordings)
    for s in prep.signals:
        full &= prep.mask(s)
    spans = [(a, b) for a, b in _windows(prep, np.where(full, gain, 0.0), WINDOW, WINDOWS)
             if full[a:b].all()]
    if not spans:
        return None
    recs = []
    for a, b in spans:
        # one side recorded: the other's force-balance estimate starts the replay,
        # only the recorded signals are compared
        cols = {"u": prep.rec["u"][a:b], "x": prep.x[a:b],
                **{s: (prep.measured(s) if s in prep.pressures else prep.smoothed(s))[a:b]
                   for s in ("p_a", "p_b")}}
        recs.append(Recording.from_arrays(prep.t[a:b] - prep.t[a],
                                          metadata={"sample_time": repr(prep.dt)}, **cols))
    pv = cand.plant_values(values)
    frees = {f.key: f for f in cand.free}

    def worth(k: str, v: float) -> bool:
        f = frees.get(k)
        # a leak fitted to (almost) nothing stays out: its interval would be meaningless
        return not (f is not None and f.low == 0.0 and not f.log and v < 0.05 * f.scale)

    keys = [k for k, v in pv.items() if k != "lines.segments" and worth(k, v)]
    if not keys:
        return None
    bounds: dict[str, tuple[float, float]] = {}
    for k in keys:
        if k in frees:
            f = frees[k]
            lo = max(f.low, pv[k] / 10.0) if pv[k] > 0 else f.low
            bounds[k] = (lo, min(f.high, pv[k] * 10.0) if pv[k] > 0 else f.high)
    plant = Plant(base.replace(**pv))
    try:
        res = estimate(plant, recs, keys, signals=("x",) + prep.pressures, bounds=bounds or None,
                       replay="open", max_iter=max_iter)
    except Exception as exc:  # noqa: BLE001 - a polish is optional; the refit's values stand
        from ..output import reraise_interrupt
        reraise_interrupt(exc)          # a Ctrl-C polled by CasADi is a stop, not a failed polish
        return None
    if not np.all(np.isfinite(res.values_)) or res.poor_fit:
        return None
    for k, v in zip(res.names, res.values_):
        old = pv[k]
        if old != 0 and not (old / TRUST <= v <= old * TRUST if old > 0
                             else old * TRUST <= v <= old / TRUST):
            return None
    est = dict(zip(res.names, (float(v) for v in res.values_)))
    std = dict(zip(res.names, (float(s) for s in res.std_)))
    ci = {k: (float(a), float(b)) for k, (a, b) in zip(res.names, res.ci95_)}
    new = dict(values)
    for k, v in est.items():
        if k in new:
            new[k] = v
    if "friction.static_excess" in new:
        fc = est.get("friction.coulomb", new["friction.coulomb"])
        fs = est.get("friction.static", pv.get("friction.static", fc))
        new["friction.static_excess"] = max(fs / fc - 1.0, 0.0) if fc > 0 else 0.0
        new["friction.coulomb"] = fc
    return Polished(values=new, std={k: v for k, v in std.items() if math.isfinite(v)},
                    ci95=ci, wall_s=time.perf_counter() - t0, status=str(res.status),
                    windows=[(float(prep.t[a]), float(prep.t[b - 1])) for a, b in spans])
