"""Deadband and friction compensation that any position controller can wear.

* :class:`DeadbandInverse` -- the valve's spool overlap (``valve.deadband``, fraction
  d of the span) and null offset (``valve.null_offset``, V) inverted: a wanted
  opening s in [-1, 1] is commanded as s' = sign(s) (d + (1 - d) |s|) about the
  true null, so the plant's opening max(|s'| - d, 0) / (1 - d) is s again. Near
  s = 0 the inverse is a straight line through zero over |s| < ``width`` (a
  fraction of the deadband): a discontinuous inverse turns sensor noise into
  full-deadband command jumps (chatter); the line keeps a residual deadband of
  about ``width`` d instead.
* :func:`friction_force` -- the plant file's dry friction (Coulomb F_c, static F_s,
  Stribeck velocity v_s) as a smooth function of a velocity, for feedforward from
  the *desired* velocity: F_c tanh(v / v_e) + (F_s - F_c) exp(-(v / v_s)^2) tanh(v /
  v_e) with v_e = v_s / 10.
* :class:`Compensated` -- wraps a controller: applies the deadband inverse to its
  command and, with a :class:`~.hold.HoldPositioner` (``hold``; what
  :func:`~.design.design` gives a plant with dry friction), hands a hold over to it:
  net force held at zero, locked on the target's quantum, a stuck piston pulsed in
  (module :mod:`workbench.controllers.hold` says why, and why no limit cycle). Without
  one (the older lock, kept for callers that set ``lock_band``) it **closes the valve
  at a hold** once the piston has stopped within
  half a position quantum of a stationary reference (``lock_band``), until the error
  exceeds ``release_band``. With dry friction a closed valve keeps the chamber
  masses and the piston stays where it stopped; integral action or a disturbance
  observer pushing against stiction after that point is what produces hunting
  (stick-slip limit cycles). The lock is a relay with hysteresis on the position
  error: a limit cycle would need the piston to leave the release band while the
  valve is closed, which only an external force larger than the static friction
  (or leakage) can do.

Describing-function argument (no limit cycle in a hold). Inside the release band the
loop is open (valve closed): there is no feedback path, so no self-sustained
oscillation can exist. Outside it the compensated loop is the designed linear loop
(FL error dynamics, NMPC, PID), whose Nyquist plot stays away from -1 with the
designed margins; the relay with hysteresis (band h = lock_band .. release_band)
has the describing function N(A) = (4 M / (pi A)) exp(-j asin(h / A)) only for
amplitudes A > release_band, and an oscillation of amplitude A > release_band
would take the piston out of the band, where the loop is the linear stable one.
:func:`hold_limit_cycle` checks the simulation for it: after settling, the position
must stay constant and the valve closed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["DeadbandInverse", "friction_force", "FrictionModel", "Compensated",
           "hold_limit_cycle"]


@dataclass(frozen=True)
class DeadbandInverse:
    """Inverse of the valve's deadband and null offset (module docstring).

    Attributes
    ----------
    center : V, command_center. span : V, command_span. deadband : fraction of span.
    offset : V, null offset (the spool is centred at center + offset).
    u_min, u_max : V, command range. width : fraction of the deadband over which the
        inverse is a straight line through zero (default 0.1).
    """

    center: float
    span: float
    deadband: float = 0.0
    offset: float = 0.0
    u_min: float = -math.inf
    u_max: float = math.inf
    width: float = 0.1

    def __post_init__(self) -> None:
        if not (0.0 <= self.deadband < 1.0):
            raise InputError(f"deadband is a fraction of the span in [0, 1), got {self.deadband!r}")
        if not (self.span > 0):
            raise InputError(f"command span must be > 0 V, got {self.span!r}")
        if not (0.0 < self.width <= 1.0):
            raise InputError(f"width is a fraction of the deadband in (0, 1], got {self.width!r}")

    @classmethod
    def from_plant(cls, plant, width: float = 0.1) -> "DeadbandInverse":
        prm = plant.params
        return cls(center=float(prm["valve.command_center"]), span=float(prm["valve.command_span"]),
                   deadband=float(prm.get("valve.deadband", 0.0) or 0.0),
                   offset=float(prm.get("valve.null_offset", 0.0) or 0.0),
                   u_min=float(prm["valve.command_min"]), u_max=float(prm["valve.command_max"]),
                   width=width)

    @property
    def null(self) -> float:
        """Command that closes the valve, V: the spool's centre, a micro-span off it.

        The micro-span (1e-6 of the span, far inside any deadband, 1e-6 of full flow
        without one) keeps the valve law off its exact zero, where the plant model's
        stick-slip friction fails to integrate a piston whose velocity decays to a
        denormal number (workbench.simulate on a plant with dry friction at exactly
        the centre command).
        """
        return self.center + self.offset + 1e-6 * self.span

    def __call__(self, u: float) -> float:
        """Command (V) that opens the valve as ``u`` would on a valve without deadband
        and offset."""
        s = (float(u) - self.center) / self.span
        d = self.deadband
        eps = self.width * d
        if d == 0.0:
            s2 = s
        elif abs(s) >= eps:
            s2 = math.copysign(d + (1.0 - d) * min(abs(s), 1.0), s)
        else:
            s2 = s * (d + (1.0 - d) * eps) / eps
        return float(min(max(self.null + self.span * s2, self.u_min), self.u_max))


def friction_force(v, coulomb: float, static: float, stribeck_velocity: float):
    """Smooth dry friction (N, along -x for v > 0) at velocity ``v`` (m/s), numpy."""
    v = np.asarray(v, dtype=float)
    ve = 0.1 * stribeck_velocity
    sgn = np.tanh(v / ve)
    return coulomb * sgn + (static - coulomb) * np.exp(-(v / stribeck_velocity) ** 2) * sgn


@dataclass(frozen=True)
class FrictionModel:
    """The plant file's dry friction as a smooth law of velocity (:func:`friction_force`).

    Attributes
    ----------
    coulomb, static : N. stribeck_velocity : m/s.
    """

    coulomb: float
    static: float
    stribeck_velocity: float

    def __post_init__(self) -> None:
        for name in ("coulomb", "static", "stribeck_velocity"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InputError(f"friction {name} must be a number >= 0, got {v!r}")
        if self.stribeck_velocity <= 0:
            raise InputError("friction stribeck_velocity must be > 0 m/s")

    @classmethod
    def from_plant(cls, plant) -> "FrictionModel | None":
        """From ``friction.coulomb``, ``friction.static`` (default Coulomb) and
        ``friction.stribeck_velocity`` (default 10 mm/s); None without dry friction."""
        prm = plant.params
        if "dry_friction" not in set(plant.effects):
            return None
        fc = float(prm.get("friction.coulomb") or 0.0)
        fs = float(prm.get("friction.static") or fc)
        vs = float(prm.get("friction.stribeck_velocity") or 0.01)
        return cls(fc, max(fs, fc), vs)

    def __call__(self, v):
        """Friction force, N, along -x for v > 0 (m/s)."""
        return friction_force(v, self.coulomb, self.static, self.stribeck_velocity)

    def slope(self, v) -> np.ndarray | float:
        """dF/dv (N s/m) of :meth:`__call__` at ``v`` (m/s), exact: with s = tanh(v/v_e),
        v_e = v_s / 10, and g = F_c + (F_s - F_c) exp(-(v/v_s)^2), F = g s and
        F' = g (1 - s^2) / v_e - 2 v (F_s - F_c) exp(-(v/v_s)^2) s / v_s^2."""
        v = np.asarray(v, dtype=float)
        vs = self.stribeck_velocity
        ve = 0.1 * vs
        s = np.tanh(v / ve)
        ex = (self.static - self.coulomb) * np.exp(-(v / vs) ** 2)
        out = (self.coulomb + ex) * (1.0 - s * s) / ve - 2.0 * v * ex * s / vs ** 2
        return float(out) if out.ndim == 0 else out

    def to_dict(self) -> dict[str, float]:
        return {"coulomb": self.coulomb, "static": self.static,
                "stribeck_velocity": self.stribeck_velocity}


@dataclass(frozen=True)
class Compensated:
    """A position controller with deadband inverse and hold lock (a DiscreteController).

    Attributes
    ----------
    inner : DiscreteController (reads x, v, p_a, p_b; e.g. inside :class:`Observed`).
    deadband : DeadbandInverse or None.
    lock_band : m, |r - x_measured| at or below which a stopped piston is held with the
        valve closed (0: never); default half a quantum (see :func:`design`).
    release_band : m, |r - x_measured| above which it is controlled again.
    lock_speed : m/s, |v| below which the piston counts as stopped.
    hold : :class:`~.hold.HoldPositioner` or None. When given, it replaces the lock
        above: locked on the target's quantum, a stuck piston pulsed in (see
        :mod:`workbench.controllers.hold`).
    limits : (lo, hi) m or None: the stroke the law may use. The hold compares the
        reference clipped to it: a reference beyond it is one the law stops short of
        (the NMPC projects it onto its stroke margin), and a raw one beyond the
        stroke was never in the piston's quantum, so the hold never engaged there.
    preview : the reference known in advance (a :class:`~workbench.references.
        Trajectory`, time from the first sample), or None. With it a hold is
        released as soon as the preview leaves the held quantum within ``lead``:
        the law then starts the move with the trajectory, not after it (a smoothed
        step starts before the raw one; the NMPC plans a horizon ahead).
    lead : s, how far ahead the preview is looked at (the law's horizon).
    """

    inner: Any
    deadband: DeadbandInverse | None = None
    lock_band: float = 0.0
    release_band: float = 0.0
    lock_speed: float = 0.0
    hold: Any = None
    limits: Any = None
    preview: Any = None
    lead: float = 0.0

    def __post_init__(self) -> None:
        for name in ("lock_band", "release_band", "lock_speed"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InputError(f"{name} must be >= 0, got {v!r}")
        if self.release_band < self.lock_band:
            raise InputError("release_band must not be below lock_band")
        if not (isinstance(self.lead, (int, float)) and math.isfinite(self.lead)
                and self.lead >= 0):
            raise InputError(f"lead must be >= 0 s, got {self.lead!r}")
        if self.limits is not None and not (len(self.limits) == 2
                                            and float(self.limits[0]) <= float(self.limits[1])):
            raise InputError(f"limits must be (lo, hi) m with lo <= hi, got {self.limits!r}")
        if self.hold is not None and self.deadband is None:
            raise InputError("the hold's pulses need the valve's centre and span: give a "
                             "DeadbandInverse (DeadbandInverse.from_plant)")

    @property
    def sample_time(self) -> float:
        return float(self.inner.sample_time)

    @property
    def kind(self) -> str:
        return getattr(self.inner, "kind", type(self.inner).__name__)

    def reset(self):
        return (self.inner.reset(), False, None,
                None if self.hold is None else self.hold.reset(), None, 0.0)

    def leaving(self, t: float, r: float) -> bool:
        """Whether the preview leaves the quantum of ``r`` (m, clipped) within
        ``lead`` s of ``t`` (s): sampled at the controller's samples."""
        if self.preview is None or self.hold is None:
            return False
        T = self.sample_time
        n = int(math.floor(self.lead / T + 1e-9))
        tt = t + T * np.arange(n + 1)
        ahead = np.interp(tt, self.preview.table[:, 0], self.preview.table[:, 1])
        if self.limits is not None:
            ahead = np.clip(ahead, float(self.limits[0]), float(self.limits[1]))
        return bool(np.any(np.abs(ahead - r) > 0.5 * self.hold.quantum))

    def update(self, state, r: float, y: dict):
        inner_state, locked, r_prev, hold_state, entry, t = (*state, 0.0)[:6]
        before = inner_state
        inner_state, u = self.inner.update(inner_state, r, y)   # keeps time and estimates
        if self.deadband is not None:
            u = self.deadband(u)
        if self.limits is not None:
            r = min(max(float(r), float(self.limits[0])), float(self.limits[1]))
        if self.hold is not None:
            hold_state, opening = self.hold.step(hold_state, r, y,
                                                 release=self.leaving(t, r))
            if opening is None:
                entry = None
            else:
                u = self._opening(opening)
                entry = before if entry is None else entry
                inner_state = held(self.inner, inner_state, entry, opening)
        elif self.lock_band > 0:
            e = abs(r - float(y.get("x_measured", y["x"])))
            still = r_prev is not None and abs(r - r_prev) <= 1e-12
            if locked:
                locked = still and e <= self.release_band
            else:
                locked = still and e <= self.lock_band and abs(float(y["v"])) <= self.lock_speed
            if locked:
                u = self.deadband.null if self.deadband is not None else _centre(self.inner)
        return (inner_state, locked, r, hold_state, entry, t + self.sample_time), float(u)

    def _opening(self, s: float) -> float:
        """Command (V) for the valve opening ``s`` (fraction of the span, deadband
        inverted; 0: the null)."""
        return self.deadband(self.deadband.center + s * self.deadband.span)


def held(law, new, entry, opening: float):
    """The position law's state while the hold commands the valve (no windup).

    The law ran this sample on a command it did not send: its integral or force
    estimate would wind up against the stuck piston, and a wound-up estimate makes
    the next move after the hold a jump. ``law.held(new, entry, opening)`` if the law
    defines it (``entry``: the law's state when the hold took over); else a dataclass
    state with ``d`` (force estimate, N) and ``u_prev`` (the command last applied, as
    an opening: the NMPC's planning model has neither deadband nor offset) gets
    ``d = 0`` and ``u_prev = opening``: the hold keeps the net force on the stuck
    piston near zero, so the friction force that holds it is near zero too, and that
    is what the estimate of the unmodelled force says when the law takes over again.
    Otherwise unchanged.
    """
    own = getattr(law, "held", None)
    if own is not None:
        return own(new, entry, opening)
    import dataclasses
    if dataclasses.is_dataclass(new) and hasattr(new, "d") and hasattr(new, "u_prev"):
        return dataclasses.replace(new, d=0.0, u_prev=float(opening))
    return new


def _centre(inner) -> float:
    c = getattr(inner, "u_center", None)
    if c is None:
        raise InputError("the hold lock needs the valve centre: give a DeadbandInverse")
    return float(c)


def hold_limit_cycle(t, x, u, start: float, end: float, quantum: float) -> dict[str, float]:
    """Evidence of a limit cycle in a hold from ``start`` to ``end`` (s).

    Returns the position's peak-to-peak (m) and the number of command changes
    larger than a hundredth of a volt, over the hold. A hold without a limit
    cycle has a peak-to-peak below one quantum and no command activity after the
    piston stopped.
    """
    t, x, u = (np.asarray(a, dtype=float) for a in (t, x, u))
    sel = (t >= start) & (t <= end)
    if sel.sum() < 2:
        raise InputError("the hold has fewer than two samples")
    xs, us = x[sel], u[sel]
    return {"peak_to_peak": float(xs.max() - xs.min()),
            "command_changes": int(np.sum(np.abs(np.diff(us)) > 1e-2)),
            "quantum": float(quantum)}
