"""``workbench bench mpc``, part two: the NMPC with the friction, deadband and line
versions of its prediction model, timed against the plain 4-state model.

Each variant is the benchmark plant with one effect added (the values of
``designs/plants/rigs/precision_rig25.toml``); its NMPC predicts with
:func:`~workbench.controllers.mpc.prediction_model` of that plant: smooth dry friction,
the valve's spool overlap, or (lines) the lines' volume added to the chambers' dead
volumes (their delay is left to the feedback). The variant's controller and the 4-state
one run in lockstep on the variant plant, so their ratio is measured under the same
load; the target is a variant within 3x of the 4-state model.
"""

from __future__ import annotations

import numpy as np

__all__ = ["VARIANTS", "variants"]

#: effect name -> parameters added to the benchmark plant
VARIANTS = {
    "friction": {"friction.coulomb": 15.0, "friction.static": 25.0,
                 "friction.stribeck_velocity": 0.01},
    "deadband": {"valve.deadband": 0.02},
    "lines": {"lines.length": 1.0, "lines.diameter": 0.004},
}


def variants(plant, ref, duration: float, nmpc, make, lockstep, score) -> dict:
    """Time per sample of each variant's NMPC and of the 4-state one, in lockstep.

    Parameters
    ----------
    plant : the benchmark plant (4 states). ref : reference r(t), m. duration : s.
    nmpc : the 4-state NMPC (its settings are used for every variant).
    make : NMPC -> controller (the compiled sample, or the NMPC itself).
    lockstep, score : :func:`workbench.bench.mpc.lockstep` and its scores (passed in:
        this module is imported by that one).

    Returns
    -------
    {name: {"median_s", "cpu_median_s", "cpu_p99_ms", "cost", "ratio", "effects",
    "plant_states"}}: ``ratio`` is the variant's median over the 4-state model's
    median in the same run.
    """
    from ..controllers.mpc import NMPC
    settings = {k: getattr(nmpc, k) for k in ("horizon", "sample_time", "disturbance_gain",
                                              "substeps", "jit", "interior_limits")}
    out = {}
    for name, params in VARIANTS.items():
        pv = plant.with_params(**params)
        nv = NMPC.for_plant(pv, **settings)
        runs = lockstep(pv, {"four_state": make(nmpc), name: make(nv)}, ref, duration, nmpc)
        sc = {k: score(v, nmpc, nmpc.sample_time) for k, v in runs.items()}
        mine, base = sc[name], sc["four_state"]
        out[name] = {"median_s": mine["median_s"], "cpu_median_s": mine["cpu_median_s"],
                     "cpu_p99_ms": mine["cpu_p99_ms"], "cost": mine["cost"],
                     "ratio": mine["median_s"] / base["median_s"],
                     "four_state_median_s": base["median_s"],
                     "effects": list(nv.model.effects),
                     "plant_states": int(np.size(pv.state_names))}
    return out
