"""Break-away of a stuck piston in the NMPC's force estimate (setting ``breakaway``).

Why: the prediction's dry friction is smooth, F_str(v) tanh(v / v_e): at rest it
is zero and below v_e it is viscous-like (F_s / v_e, 4760 N s/m on the precision
rig), so the plan expects a stuck piston to creep under any force. The real
piston stays stuck until the force passes the static friction F_s. While it is
stuck the force estimate d (:meth:`.problem.Problem.estimate`) is the holding
force, which the friction supplies: once the wanted direction turns (a reversal)
that estimate points the wrong way (it seems to help the new motion) and it is
unlearnt only at the estimate's gain (T / 20 ms). A quiet plan then swings the
force through the band +-F_s slowly: the piston stays stuck 78-124 ms at the
precision sine's top reversal (1.9 mm behind, seed 0, session 11, h14m). The
chattering 4-state loop broke each stick with its 26 Hz +-12 N dither instead.

What: while a stuck piston must move (:func:`~..feedback_linearizing.breakaway`:
estimated speed below v_s, the reference's velocity beyond it; left once the
measured position has moved that way or the direction changes), the estimate is
set at entry to at least the static friction the model lacks at the wanted
speed, F_s - F_model(|v_r|), against the wanted direction (a larger estimate
against it, a holding force already learnt, is kept), so the plan builds the force
the real friction needs. The estimate then runs on from there (a rig with more
friction than its file: the estimate grows while the piston does not move). Once
the piston has moved, that static excess (at most what the estimate still holds
against the motion) is taken out again: the friction is the sliding one, which
the model has.
"""
from __future__ import annotations

from ...physics.friction import smooth_friction
from ..feedback_linearizing import breakaway

__all__ = ["dry_friction", "breakaway_force"]


def dry_friction(pb) -> tuple[float, float, float, float] | None:
    """(F_c N, F_s N, v_s m/s, v_e m/s) of the problem's prediction model; None
    without dry friction or without a smooth width."""
    prm = pb.model.params
    if not prm.has_effect("dry_friction") or pb.friction_width is None:
        return None
    return (float(prm["friction.coulomb"]), float(prm["friction.static"]),
            float(prm["friction.stribeck_velocity"]), float(pb.friction_width))


def breakaway_force(fr, brk, want: float, v: float, x_m: float, d: float):
    """(break-away state, force estimate N) for this sample.

    Parameters
    ----------
    fr : (F_c, F_s, v_s, v_e) of :func:`dry_friction`.
    brk : None or (direction, position m at entry, excess N) of the last sample.
    want : m/s, the reference's velocity now.
    v : m/s, estimated velocity. x_m : m, measured position.
    d : N, the force estimate (along -x) carried from the last sample.
    """
    fc, fs, vs, v_e = fr
    new = breakaway(None if brk is None else brk[:2], want, v, x_m, vs)
    if new is None:
        if brk is not None:                            # left: take the excess out
            s, excess = brk[0], brk[2]
            d -= s * min(max(s * d, 0.0), excess)
        return None, d
    if brk is not None and new is not None and new[0] == brk[0]:
        return brk, d
    s = new[0]
    excess = max(fs - float(smooth_friction(abs(want), fc, fs, vs, 0.0, v_e)), 0.0)
    if s * d < excess:
        d = s * excess
    return (s, new[1], excess), d
