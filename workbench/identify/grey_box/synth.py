"""Synthetic recordings for tests and benchmarks: :func:`synthetic_recording`."""

from __future__ import annotations

from typing import Mapping

import numpy as np

from ...plant import Plant
from ...recording import Recording

__all__ = ["synthetic_recording"]


def _aprbs_doublets(duration: float, dt: float, rng: np.random.Generator, center: float,
                    amplitude: float, hold: tuple[float, float]) -> np.ndarray:
    """Command of random doublets (+a then -a, random a and hold) around ``center``, V.

    Doublets keep an open-loop cylinder near where it started: each excursion is
    undone by the next half.
    """
    n = int(round(duration / dt)) + 1
    u = np.empty(n)
    k = 0
    while k < n:
        a = rng.uniform(-amplitude, amplitude)
        m = max(1, int(rng.uniform(*hold) / dt))
        u[k:k + m] = center + a
        u[k + m:k + 2 * m] = center - a
        k += 2 * m
    return u[:n]


def synthetic_recording(plant: Plant, duration: float, sample_time: float = 1e-3,
                        seed: int = 0, noise: Mapping[str, float] | None = None,
                        amplitude: float = 0.25, hold: tuple[float, float] = (0.02, 0.12),
                        x0: float | None = None, rtol: float = 1e-9, atol: float = 1e-11
                        ) -> Recording:
    """An open-loop recording simulated by the workbench (CVODES), for tests and benches.

    The command is random doublets around the valve centre (:func:`_aprbs_doublets`);
    the piston starts at rest at ``x0`` (default mid-stroke) with 3.5 bar in both
    chambers. ``noise`` maps signals to white-noise standard deviations (SI).
    """
    from ... import simulate
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration / sample_time)) + 1) * sample_time
    center = (float(plant.params["valve.command_center"])
              + float(plant.params.get("valve.null_offset", 0.0)))
    u = _aprbs_doublets(duration, sample_time, rng, center, amplitude, hold)
    xs = 0.5 * plant.stroke if x0 is None else x0
    state = plant.initial_state(xs, p_a=3.5e5, p_b=3.5e5, u0=center)
    run = simulate.open_loop(plant, t, u, x0=state, rtol=rtol, atol=atol, progress=False)
    cols = {}
    for s in ("x", "p_a", "p_b"):
        y = np.asarray(run[s], dtype=float).copy()
        if noise and s in noise:
            y = y + float(noise[s]) * rng.standard_normal(len(y))
        cols[s] = y
    return Recording.from_arrays(t, source=f"<simulated {plant.name} seed {seed}>",
                                 metadata={"sample_time": repr(sample_time),
                                           "simulated_by": "grey_box.synthetic_recording"},
                                 u=u, **cols)
