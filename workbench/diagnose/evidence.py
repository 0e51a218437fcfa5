"""What a finding says: its evidence sentence and its confidence.

:func:`evidence_text` turns a ranked candidate into one or two sentences a rig engineer
can check on the replay plot (where the mismatch lives, what the effect does there at
the fitted values, how much of the mismatch it removes); :func:`confidence` weighs its
information criterion against the runner-up and against "nothing to add".
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from .candidates import Candidate
from .data import Prepared
from .explain import Ranked

__all__ = ["evidence_text", "confidence", "where_text"]


def where_text(conc: Mapping[str, Mapping[str, float]]) -> str:
    """The (at most two) operating regimes where the mismatch concentrates, in words.

    Parameters
    ----------
    conc : per regime, ``ratio`` (share of the error / share of time, -) and
        ``time_share`` (-), as :func:`.locate.concentration` gives.
    """
    best = sorted(conc.items(), key=lambda kv: -kv[1]["ratio"])
    top = [(k, v) for k, v in best if v["time_share"] > 0.01 and v["ratio"] >= 1.3][:2]
    parts = [f"{k} ({v['ratio']:.1f}x its share of time)" for k, v in top]
    return ("mostly " + " and ".join(parts)) if parts else "throughout the recording"


def evidence_text(r: Ranked, cand: Candidate, conc: Mapping[str, Mapping[str, float]],
                  prep: Prepared) -> str:
    """The evidence sentence of a finding (``evidence`` of the diagnosis JSON).

    Parameters
    ----------
    r : the ranked candidate (fitted values in SI units of the plant keys).
    cand : its candidate. conc : where the mismatch it removes lives (:func:`where_text`).
    prep : the prepared recording (for the nominal plant's values).
    """
    return f"Mismatch {where_text(conc)}: {_what(r, prep)}; " \
           f"adding it removes {100 * r.gain:.0f} % of the short-horizon prediction error."


def _what(r: Ranked, prep: Prepared) -> str:
    """What the effect does at its fitted values, as seen on the rig."""
    v = r.result.values
    pv = r.result.plant_values
    name = r.name
    if name == "dry_friction":
        return (f"the piston sticks and the pressures build up to a break-away force of "
                f"{pv['friction.static']:.3g} N before it moves, then slides against "
                f"{pv['friction.coulomb']:.3g} N")
    if name == "valve_deadband":
        return (f"commands within {100 * v['valve.deadband']:.2g} % of the span around the "
                f"centre move no air (pressures flat, piston stopped short of r)")
    if name == "valve_offset":
        closed_at = prep.plant.params["valve.command_center"] + v["valve.null_offset"]
        return (f"the valve is closed at u = {closed_at:.3g} V, not at the nominal centre "
                f"(steady error and drifting pressures at rest)")
    if name == "valve_dynamics":
        return (f"the pressures answer command steps with a lag "
                f"({v['valve.bandwidth']:.3g} Hz, damping {v['valve.damping']:.2g})")
    if name == "line_dynamics":
        return (f"pressure transients are delayed and damped as by {v['lines.length']:.3g} m "
                f"lines of {1e3 * v['lines.diameter']:.2g} mm")
    if name == "leakage":
        return (f"the chamber pressures decay while the valve is closed "
                f"(leak conductance {v['leakage.conductance_to_atmosphere']:.3g} m^3/(s Pa) "
                f"to atmosphere, {v['leakage.cross_piston']:.3g} kg/(s Pa) across the piston)")
    if name == "supply_droop":
        return (f"the pressures rise more slowly at large openings, as from a "
                f"{1e3 * v['supply.reservoir_volume']:.3g} l reservoir behind a regulator")
    if name == "heat_transfer":
        return (f"pressures overshoot in fast transients and relax afterwards, as gas "
                f"heated by compression cools through the walls "
                f"({v['gas.heat_transfer_coefficient']:.3g} W/K)")
    nominal = prep.plant.params
    return "; ".join(f"{k} fits as {v:.4g} instead of the nominal {nominal[k]:.4g} "
                     f"({100 * (v / nominal[k] - 1):+.1f} %)" if nominal[k] else
                     f"{k} fits as {v:.4g} instead of the nominal {nominal[k]:.4g}"
                     for k, v in pv.items())


def confidence(r: Ranked, runner_up: Ranked | None) -> float:
    """BIC weight against the runner-up and "nothing", tempered by the share explained.

    Returns
    -------
    float
        0..0.99 (-).
    """
    if runner_up is None or not np.isfinite(runner_up.dbic):
        w = 1.0 / (1.0 + math.exp(-0.5 * r.dbic)) if r.dbic < 60 else 1.0
    else:
        d = r.dbic - runner_up.dbic
        w = 1.0 / (1.0 + math.exp(-0.5 * d)) if abs(d) < 60 else (1.0 if d > 0 else 0.0)
        w = min(w, 1.0 / (1.0 + math.exp(-0.5 * r.dbic)) if r.dbic < 60 else 1.0)
    w *= 0.6 + 0.4 * min(max(r.gain, 0.0), 1.0)
    if r.consistency is not None and r.consistency < 0.5:
        w *= 0.85
    return float(min(max(w, 0.0), 0.99))
