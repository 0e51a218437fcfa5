"""The NMPC's reference at the shooting nodes: extrapolated or previewed, then projected
onto the stroke it may use (used by :mod:`.update` and by :mod:`.fast` for a preview)."""

from __future__ import annotations

import numpy as np

from .model import horizon_reference

__all__ = ["node_reference", "admissible"]


def node_reference(pb, r: float, r_prev: float | None, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Reference position (m) and velocity (m/s) at the N + 1 shooting nodes.

    With the controller's ``preview`` (the whole reference r(t), s -> m) the nodes
    take it at t + k T and its velocity from the chord over one sample centred on
    each node (bounded by ``max_speed``); else :func:`horizon_reference` extrapolates
    the current sample (a ramp) or holds it (a step).
    """
    c = pb.c
    if c.preview is None:
        R, rate = horizon_reference(r, r_prev, pb.T, pb.N, c.reference_rate_limit)
        return np.asarray(R, dtype=float), np.full(pb.N + 1, rate)
    tk = t + pb.T * np.arange(pb.N + 1)
    R = np.asarray(c.preview(tk), dtype=float)
    h = 0.5 * pb.T
    VR = (np.asarray(c.preview(tk + h), dtype=float) - np.asarray(c.preview(tk - h), dtype=float)) / pb.T
    vmax = c.max_speed if c.max_speed is not None else np.inf
    return R, np.clip(VR, -vmax, vmax)


def admissible(pb, R: np.ndarray, VR: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The node reference projected onto the stroke the NMPC may use (m, m/s).

    A reference beyond ``stroke_margin`` cannot be reached: tracking it makes the
    stroke limit's exact (L1) penalty active, and the optimum sits on the kink where
    the tracking cost's pull balances the penalty's multiplier. Any model error (the
    lines' delay) then moves the plan from one side of the kink to the other every
    sample: the command chattered by +-0.5 V and p_b by +-1 bar at the margin. The
    projected reference is reachable, the constraint inactive, the cost smooth there;
    where it is clipped its velocity is zero.
    """
    lo, hi = pb.c.stroke_margin, pb.L - pb.c.stroke_margin
    clipped = (R < lo) | (R > hi)
    return np.clip(R, lo, hi), np.where(clipped, 0.0, VR)
