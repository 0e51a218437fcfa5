"""What a chosen set cannot tell apart: trade-offs of its members' values and the
operating regimes that would separate two explanations (:mod:`.sets` reports both).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from .candidates import Candidate
from .locate import EXPECTED
from .refit import FitResult

if TYPE_CHECKING:
    from .sets import SetScore

__all__ = ["TRADE_OFF", "by_member", "tells_apart", "trade_offs"]

#: |correlation| of two members' fitted values above which they are reported as trading off.
TRADE_OFF = 0.8


def by_member(joint: FitResult, members: Sequence[Candidate]) -> dict[str, dict[str, float]]:
    """The joint fit's values split by member name."""
    return {m.name: {f.key: joint.values[f.key] for f in m.free} for m in members}


def _shows(name: str, by: Mapping[str, Candidate], masks: Mapping[str, np.ndarray]) -> str:
    """Where candidate ``name``'s signature shows (:data:`.locate.EXPECTED`) and the
    share of this recording's time spent there."""
    regimes = EXPECTED.get(name, EXPECTED.get(by[name].effect, ())) if name in by else ()
    if not regimes:
        return "throughout"
    union = None
    for r in regimes:
        m = masks.get(r)
        if m is not None:
            union = m.copy() if union is None else union | m
    share = f" ({100 * float(np.mean(union)):.0f} % of this recording)" \
        if union is not None and union.size else ""
    return " / ".join(regimes) + share


def tells_apart(a: Sequence[str], b: Sequence[str], by: Mapping[str, Candidate],
                masks: Mapping[str, np.ndarray]) -> str:
    """What data would separate explanation ``a`` from ``b`` (member names): the
    operating regimes where the members that only one of them has show, with the share
    of this recording spent in each (little time there: record more of it)."""
    only_a = [m for m in a if m not in b] or list(a)
    only_b = [m for m in b if m not in a] or list(b)
    side = [" and ".join(f"{m} shows {_shows(m, by, masks)}" for m in ms)
            for ms in (only_a, only_b)]
    return f"{side[0]}; {side[1]}: a recording with more of those regimes separates them"


def trade_offs(best: "SetScore", by: Mapping[str, Candidate],
               masks: Mapping[str, np.ndarray] | None = None) -> list[dict[str, Any]]:
    """Pairs of values of different members whose joint-fit correlation exceeds
    :data:`TRADE_OFF`, with the regimes where each member's signature shows and the
    share of the recording spent there (data rich in those regimes tells them apart)."""
    corr = best.result.corr if best.result is not None else {}
    owner = {f.key: m for m in best.names for f in by[m].free}
    out = []
    for (a, b), c in corr.items():
        if owner.get(a) == owner.get(b) or abs(c) < TRADE_OFF:
            continue
        out.append({"values": [a, b], "members": [owner[a], owner[b]],
                    "correlation": round(float(c), 2),
                    "tells_apart": tells_apart([owner[a]], [owner[b]], by, masks or {})})
    return out
