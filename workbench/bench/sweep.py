"""``workbench bench sweep``: the stability map against a per-point python-control loop.

Timing numbers are for this machine at the time of the run; the ratios are what to
compare between runs. Nothing here is a test.
"""

from __future__ import annotations

import os
import time
import warnings
from pathlib import Path

import numpy as np

__all__ = ["bench"]

ROOT = Path(__file__).resolve().parents[2]


def bench(quick: bool = False) -> dict:
    """``workbench bench sweep``: a 200 x 200 map (position x supply pressure, so every
    point has its own equilibrium, tangent model, ZOH discretisation and eigenvalues) on
    the paper-000 rig, against a plain python loop of the same steps through the
    workbench's per-point API and python-control (ss, c2d, feedback, poles) on a
    random sample of the points, in the same run. Also checks the two agree.
    ``quick``: 60 x 60 points, 30 of them in the loop."""
    import control

    from ..controllers import from_plant
    from ..linearize import operating_point, tangent
    from ..plant import Plant
    from ..stability.maps import Axis, stability_map
    plant = Plant.from_toml(ROOT / "designs" / "plants" / "situm_rodless.toml")
    n = 60 if quick else 200
    xa = Axis.linspace("position", 0.05, 0.45, n)
    ya = Axis.linspace("supply.pressure", 3e5, 7e5, n)
    t0 = time.perf_counter()
    stability_map(plant, xa, ya, progress=False)           # compiles (or loads the cache)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    m = stability_map(plant, xa, ya, progress=False)
    warm = time.perf_counter() - t0
    ctrl = from_plant(plant)
    c_tf = ctrl.to_control()
    rng = np.random.default_rng(0)
    sample = rng.choice(n * n, 30 if quick else 100, replace=False)
    worst = 0.0
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k in sample:
            iy, ix = divmod(int(k), n)
            p = plant.with_params(**{"supply.pressure": float(ya.values[iy])})
            lin = tangent(p, operating_point(p, float(xa.values[ix])))
            c, d = lin.output("x")
            sd = control.c2d(control.ss(lin.A, lin.B, c, d), ctrl.sample_time, "zoh")
            poles = control.poles(control.feedback(c_tf * sd, 1))
            # the loop sees the hidden pressure-sum mode at |z| = 1; compare the rest
            poles = poles[np.abs(np.abs(poles) - 1.0) > 1e-6]
            worst = max(worst, abs(float(np.max(np.abs(poles))) - float(m.rho[iy, ix])))
    per_point = (time.perf_counter() - t0) / len(sample)
    return {"points": n * n, "points_per_s": n * n / warm,
            "speedup_vs_loop": per_point * n * n / warm,
            "map_s": warm, "first_run_s": first, "loop_points_per_s": 1.0 / per_point,
            "loop_sample": int(len(sample)), "max_abs_rho_difference": worst,
            "workers": os.cpu_count(), "target": ">= 20000 points/s and >= 50x the loop"}
