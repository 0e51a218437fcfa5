"""Several recordings with different signals joined: each signal where it was recorded.

:func:`with_all_signals` gives the joined recording (:func:`.data.prepare_many`) every
signal some recording measured, with the mask of where (``Prepared.recorded``);
:func:`mixed_note` says what that gives the diagnosis. A recording with one chamber
pressure: :func:`unrecorded_pressure` estimates the other one (its own chamber equation
where the recorded side validates it, else the piston's force balance).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .data import Prepared

__all__ = ["with_all_signals", "mixed_note", "chamber_estimate", "unrecorded_pressure",
           "CHAMBER_TRUST", "start_pressures"]

#: The unrecorded pressure comes from its own chamber equation when that equation,
#: run the same way on the recorded chamber, misses the recorded pressure by less than
#: this share of the disagreement between the two estimates (:func:`unrecorded_pressure`).
#: Why 1/4: a valve or leakage fault makes the two chambers' equations drift by amounts
#: that differ by up to 1.8x (foreign rig, valve offset 0.2 V: 172 vs 316 kPa rms), so
#: the check on the recorded side bounds the unrecorded side's error only to within about
#: 2x; a further 2x margin leaves 1/4. Dry friction the plant file lacks (18/26 N on the
#: foreign rig): check 1.2 kPa against a 29 kPa disagreement (1/24).
CHAMBER_TRUST = 0.25


def chamber_estimate(plant: Any, side: str, p0: float, x: np.ndarray, v: np.ndarray,
                     p_other: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
    """Chamber ``side``'s pressure (Pa) integrated by the plant's own equations with the
    smoothed position ``x`` (m), velocity ``v`` (m/s) and the other chamber's pressure
    ``p_other`` (Pa) imposed at every sample: the chamber's mass balance (valve flow at
    the command ``u`` (V), volume change, leaks) and the states effects add (lines,
    spool, temperatures: from rest, :meth:`workbench.plant.Plant.rest_state`) run free,
    from ``p0`` (Pa), one linearly implicit Euler step per sample ``dt`` (s; L-stable for
    the lines' fast modes). The valve's flow falls as the pressure rises, so the
    integration forgets its start. The force balance is not used: unknown friction,
    load or mass do not bias it; a wrong valve law or leak makes it drift."""
    import casadi as ca
    i_s = plant.state_index(side)
    i_o = plant.state_index("p_b" if side == "p_a" else "p_a")
    ix, iv = plant.state_index("x"), plant.state_index("v")
    n = len(plant.state_names)
    free = [i for i in range(n) if i not in (ix, iv, i_o)]
    w, d = ca.SX.sym("w", len(free)), ca.SX.sym("d", 4)      # d: x, v, p_other, u
    z = [None] * n
    z[ix], z[iv], z[i_o] = d[0], d[1], d[2]
    for k, i in enumerate(free):
        z[i] = w[k]
    rate = plant.f(ca.vertcat(*z), d[3], plant.p0)[free]
    jac = ca.jacobian(rate, w)
    nxt = w + ca.solve(ca.DM.eye(len(free)) - dt * jac, dt * rate)
    step = ca.Function("chamber_step", [w, d], [nxt]).mapaccum("chamber", len(x))
    basic = np.zeros(n)
    basic[ix], basic[i_s], basic[i_o] = x[0], p0, p_other[0]
    w0 = np.asarray(plant.rest_state(basic, float(u[0]))).ravel()[free]
    out = np.asarray(step(w0, np.vstack([x, v, p_other, u])))[free.index(i_s)]
    return np.concatenate(([p0], out[:-1]))


def unrecorded_pressure(plant: Any, side: str, p_rec: np.ndarray, p_balance: np.ndarray,
                        x: np.ndarray, v: np.ndarray, u: np.ndarray, dt: float,
                        starts: list[int] | None = None) -> tuple[np.ndarray, str]:
    """The chamber pressure not recorded (Pa) and how it was estimated, in words.

    Two estimates with complementary blind spots: the piston's force balance
    ``p_balance`` (:func:`.data.other_side`: biased by any force the plant file lacks,
    by F_c / A = 37 kPa for 18 N of dry friction on a 25 mm bore, and undetermined
    while the piston sticks), and the chamber's own equation (:func:`chamber_estimate`:
    blind to forces, drifts under a valve or leak fault). The chamber equation is
    checked on the recorded chamber ``side`` (``p_rec``, Pa, smoothed): integrated the
    same way, it must stay within :data:`CHAMBER_TRUST` of the rms disagreement
    between the two estimates of the other side; then that disagreement is the force
    balance's, and the chamber equation gives the pressure; otherwise the force
    balance does (as before). Several recordings joined (``starts``: first sample of
    each): each integrated from its own start.
    """
    other = "p_b" if side == "p_a" else "p_a"
    cuts = list(starts or [0]) + [len(x)]

    def run(which, start, p_o):
        return np.concatenate([chamber_estimate(plant, which, float(start[a]), x[a:b], v[a:b],
                                                p_o[a:b], u[a:b], dt)
                               for a, b in zip(cuts[:-1], cuts[1:]) if b > a])
    ci, check = run(other, p_balance, p_rec), run(side, p_rec, p_balance)
    miss = float(np.sqrt(np.mean((check - p_rec) ** 2)))
    apart = float(np.sqrt(np.mean((ci - p_balance) ** 2)))
    p_atm, p_s = plant.params["gas.atmospheric_pressure"], plant.params["supply.pressure"]
    if np.all(np.isfinite(ci)) and miss < CHAMBER_TRUST * apart:
        return np.clip(ci, 0.5 * p_atm, 1.1 * p_s), (
            f"{other} estimated from its own chamber equation (valve flow at the recorded "
            f"command, volume change at the measured position): the piston's force balance "
            f"disagrees with it by {apart / 1e3:.3g} kPa rms, while the same equation "
            f"reproduces the recorded {side} within {miss / 1e3:.3g} kPa rms, so a force "
            "the plant file lacks (dry friction, load) would bias the force balance")
    return p_balance, (f"{other} estimated from the piston's force balance (nominal mass, "
                       "viscous friction and load; dry friction, unknown, biases it by F/A): "
                       f"its own chamber equation misses the recorded {side} by "
                       f"{miss / 1e3:.3g} kPa rms (a valve or leakage mismatch)")


def mixed_note(parts: list[Prepared]) -> str:
    """What a set of recordings with different signals gives the diagnosis, in words."""
    which = "; ".join(f"{p.rec.source}: {', '.join(p.signals)}" for p in parts)
    return ("the recordings measure different signals (" + which + "): each signal is "
            "compared only where it was recorded, so the pressures of one recording and "
            "the position of another inform the one model; the noise of each signal is "
            "that of the recordings that have it; where no chamber pressure is recorded "
            "the predictions run on the model's pressures, as for a position-only "
            "recording, and the flow and force witnesses are left out")


def with_all_signals(prep: Prepared, parts: list[Prepared], starts: list[int]) -> Prepared:
    """The joined ``prep`` (prepared on the signals every part shares) given every
    signal some part recorded, each where it was recorded (``Prepared.recorded``).

    Per chamber pressure: the measurement where recorded, NaN elsewhere; its rate
    likewise; the smoothed value (the predictions' anchors and the observer's input)
    the part's own (its force-balance estimate where the part has the other side
    only, :func:`.data.other_side`) or, in a part with no pressure, its start pressures
    (:func:`start_pressures`), else the plant's equilibrium
    at the part's first position (what a position-only recording alone starts from,
    :meth:`workbench.plant.Plant.initial_state`; the predictions re-anchor on it only
    at the part's start). The noise of a signal is the median over the parts that
    have it (each part's own, :func:`.data.prepare`).
    """
    n = prep.n
    cuts = list(starts) + [n]
    spans = list(zip(cuts[:-1], cuts[1:]))
    union = tuple(s for s in ("x", "p_a", "p_b") if any(s in p.signals for p in parts))
    fields: dict[str, Any] = {"signals": union, "noise": dict(prep.noise), "recorded": {}}
    plant = prep.plant
    ia, ib = plant.state_index("p_a"), plant.state_index("p_b")
    for side in union[1:]:
        short = side[-1]
        meas, sm, rate = np.full(n, np.nan), np.empty(n), np.full(n, np.nan)
        mask = np.zeros(n, dtype=bool)
        for p, (a, b) in zip(parts, spans):
            if side in p.signals:
                meas[a:b], rate[a:b] = p.measured(side), getattr(p, f"dp{short}")
                mask[a:b] = True
            if p.pressures:
                sm[a:b] = p.smoothed(side)
            elif p.start:          # fitted to the part's start (:func:`start_pressures`)
                sm[a:b] = p.start[side]
            else:
                z = plant.initial_state(float(np.clip(p.xs[0], 0.0, plant.stroke)))
                sm[a:b] = z[ia] if side == "p_a" else z[ib]
        fields[side], fields[f"p{short}s"], fields[f"dp{short}"] = meas, sm, rate
        fields["recorded"][side] = mask
        fields["noise"][side] = float(np.median([p.noise[side] for p in parts
                                                 if side in p.signals]))
    for side in ("p_a", "p_b"):       # a side no part recorded: its estimate, if any
        if side not in union and any(p.pressures for p in parts):
            fields[f"p{side[-1]}s"] = np.concatenate(
                [p.smoothed(side) if p.pressures else
                 np.full(b - a, p.start[side]) if p.start else
                 np.full(b - a, plant.initial_state(float(np.clip(p.xs[0], 0.0, plant.stroke)))
                         [ia if side == "p_a" else ib]) for p, (a, b) in zip(parts, spans)])
    return replace(prep, **fields)




def start_pressures(plant: Any, x0: float) -> tuple[dict[str, float], str]:
    """Chamber pressures (Pa) at the first sample of a recording of the position only,
    at the first position ``x0`` (m), and why, in words; ({}, "") when the plant file
    has no leakage (its equilibrium is then the start, as before).

    Not measured, so an equilibrium: the pressures the valve holds at rest at ``x0``
    (:func:`workbench.equilibrium.operating_point`) of the plant *without its leaks*.
    Why: with a leak to atmosphere the equilibrium of the whole plant is both chambers
    at 1 bar (a centred valve passes nothing, the leak drains them), a state a held
    rig reaches only after the leak's time constant with its loop off; in the loop the
    valve's null pressure is what the chambers hold (foreign rig started at 4.4 bar, null
    4.47 bar; x replayed at 99.9 % from there against 92.6 % from 1 bar). No fit: a
    start level fitted to the position on the nominal plant absorbs its errors and
    spoils the augmented replay (deadband rig: 85.7 % against 99.2 %), because while the
    spool sits in a deadband the chambers keep their level for the whole run.
    """
    if not plant.params.has_effect("leakage"):
        return {}, ""
    from ..plant import Plant
    sealed = Plant(plant.params.without_effect("leakage"), friction=plant.friction)
    z = sealed.initial_state(float(np.clip(x0, 0.0, plant.stroke)))
    out = {s: float(z[plant.state_index(s)]) for s in ("p_a", "p_b")}
    return out, (f"the chamber pressures at the start are not recorded: they start at the "
                 f"valve's null pressure of the plant without its leaks (p_a "
                 f"{out['p_a'] / 1e5:.3g} bar, p_b {out['p_b'] / 1e5:.3g} bar), not at the "
                 "plant's equilibrium, where the leaks have drained both chambers")
