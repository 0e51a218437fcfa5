"""Several recordings with different signals joined: each signal where it was recorded.

:func:`with_all_signals` gives the joined recording (:func:`.data.prepare_many`) every
signal some recording measured, with the mask of where (``Prepared.recorded``);
:func:`mixed_note` says what that gives the diagnosis.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .data import Prepared

__all__ = ["with_all_signals", "mixed_note"]


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
    only, :func:`.data.other_side`) or, in a part with no pressure, the plant's equilibrium
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
                 np.full(b - a, plant.initial_state(float(np.clip(p.xs[0], 0.0, plant.stroke)))
                         [ia if side == "p_a" else ib]) for p, (a, b) in zip(parts, spans)])
    return replace(prep, **fields)
