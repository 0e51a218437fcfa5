"""A ready position controller from a plant file, in one call.

:func:`design` returns a :class:`~workbench.controllers.base.DiscreteController` that
needs only ``x``, ``p_a``, ``p_b`` in its measurements (it never reads ``v``):

    sensors -> Observed( Compensated( PID | FL | NMPC ) )

* :class:`~.observer.Observed` with a :func:`~.observer.kalman_observer`: velocity and
  unmodelled force from the position and the pressures;
* :class:`~.compensation.Compensated`: the valve's deadband and null offset inverted
  (when the plant file has them) and, when it has dry friction, the precision hold
  (:func:`~.hold.hold_for_plant`: net force held at zero, locked on the target's
  quantum, a stuck piston pulsed in; :mod:`workbench.controllers.hold`). Only
  friction holds a piston whose valve is closed: without it the closed chambers are
  two gas springs, and a piston locked before its forces balance swings out of the
  band and back (a deadband-only rig, NMPC, 1 s hold: 0.44 mm peak-to-peak and 57
  command changes with the older lock, 0.0000 mm and 1 without);
* the position law: ``"pid"`` (PID on the estimated state, derivative on the
  estimated velocity, zero placed on the reduced model, the preview's derivatives
  and the model friction's rate fed forward through that model's inverse, the
  integral only on a still reference near its target: :class:`VelocityPID`),
  ``"fl"`` (feedback linearisation on the observer's force estimate at the
  bandwidth the sampling and the lines' delay allow, the plant file's dry friction
  fed forward at the reference's velocity (its sliding part while it slows):
  :class:`~.feedback_linearizing.FeedbackLinearizing`'s ``friction``) or
  ``"nmpc"`` (RTI NMPC whose model keeps the plant's dry friction, smooth). PID
  and FL drive a stuck piston that the reference moves on to the static friction
  (:func:`~.feedback_linearizing.breakaway`): the observer's force estimate of a
  stuck piston is only the force that holds it.

The hold compares the reference clipped to the stroke the law may use (the NMPC's
stroke margin) and, given the reference in advance, hands over to the law
:func:`release_lead` before the reference leaves the held quantum (the NMPC's
horizon; else the lines' round trip and a sample); it takes a stuck piston over
within :func:`hold_range`.

Given the whole reference in advance (``reference=``), a step is turned into a
feasible smooth trajectory (:func:`workbench.references.smooth`, limits from
:func:`axis_limits`: the valve's flow, or the lines' if they pass less) and PID, FL
and NMPC track it with feedforward of its derivatives;
without it they work on the reference sample by sample (FL through its reference
model, NMPC extrapolating the current rate).

Examples
--------
>>> from workbench import Plant
>>> from workbench.controllers.design import design
>>> plant = Plant.from_toml("designs/plants/rig25_mpye.toml")
>>> ctrl = design(plant, kind="fl")
>>> ctrl.needs
('x', 'p_a', 'p_b')
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import InputError
from .compensation import Compensated, DeadbandInverse, FrictionModel
from .hold import hold_for_plant
from .observer import Observed, kalman_observer

__all__ = ["design", "axis_limits", "AxisLimits", "KINDS", "VelocityPID", "line_flow", "line_delay",
           "breakaway_jump", "breakaway_probe", "release_samples"]

KINDS = ("pid", "fl", "nmpc")
#: m/s: speed below which a piston in the lock band is held by closing the valve
#: (dry friction F_c/m of 12 m/s^2 stops 20 mm/s within 0.02 mm).
LOCK_SPEED = 0.02
#: Share of the valve's flow, the force range and the force rate that a planned
#: trajectory may use; the rest is for the feedback (friction, lines, model error).
TRAJECTORY_MARGIN = 0.3
#: Share of the valve's span the PID's integral may command: a null offset or a
#: leakage the plant file does not give (proportional valves: about 1-2 % of the span).
INTEGRAL_SHARE = 0.02
#: RHO0 kg/m^3 and T0 K of ISO 6358's standard reference atmosphere.
_RHO0, _T0, _R = 1.185, 293.15, 287.0


@dataclass(frozen=True)
class AxisLimits:
    """Speed (m/s), acceleration (m/s^2) and jerk (m/s^3) a trajectory may ask for."""

    speed: float
    acceleration: float
    jerk: float

    def to_dict(self) -> dict[str, float]:
        return {"speed": self.speed, "acceleration": self.acceleration, "jerk": self.jerk}


def axis_limits(plant, margin: float = TRAJECTORY_MARGIN) -> AxisLimits:
    """Trajectory limits from the valve's flow and the pressure range (SI).

    * speed: the fully open edge's choked mass flow q = C p_s rho0 sqrt(T0/T)
      (with lines, at most what the line passes from p_s to p_m: :func:`line_flow`)
      fills chamber a at the mid pressure p_m = (p_s + p_atm)/2 with q r T / p_m of
      volume per second: v = q r T / (p_m A_a);
    * acceleration: the full pressure difference over the piston less the static
      friction, ((p_s - p_atm) A_a - F_s) / m;
    * jerk: the force rate of that flow into the mid-stroke chamber (volume V_m),
      k r T q A_a / V_m, over the mass;

    each times ``margin`` (default 0.3: the rest is for the feedback).
    """
    prm = plant.params
    if not (0.0 < margin <= 1.0):
        raise InputError(f"margin is a share in (0, 1], got {margin!r}")
    T = float(prm["gas.temperature"])
    p_s, p_atm = float(prm["supply.pressure"]), float(prm["gas.atmospheric_pressure"])
    A = float(plant.area_a)
    m = float(prm["load.mass"])
    k = float(prm["gas.polytropic_index"])
    q = float(prm["valve.sonic_conductance"]) * p_s * _RHO0 * math.sqrt(_T0 / T)
    p_m = 0.5 * (p_s + p_atm)
    if "line_dynamics" in set(plant.effects):
        q = min(q, line_flow(float(prm["lines.length"]), float(prm["lines.diameter"]), p_s, p_m, T))
    speed = q * _R * T / (p_m * A)
    f_s = float(prm.get("friction.static") or prm.get("friction.coulomb") or 0.0)
    acc = max((p_s - p_atm) * A - f_s, 0.1 * (p_s - p_atm) * A) / m
    v_mid = A * 0.5 * plant.stroke + float(prm["cylinder.dead_volume_a"])
    jerk = k * _R * T * q * A / v_mid / m
    return AxisLimits(margin * speed, margin * acc, margin * jerk)


def line_flow(length: float, diameter: float, p_in: float, p_out: float,
              temperature: float, steps: int = 200) -> float:
    """Steady mass flow (kg/s) through a line from ``p_in`` to ``p_out`` (Pa).

    The friction drop of the plant's line model (:func:`workbench.physics.line.
    pressure_drop`: laminar plus Blasius) integrated along the line in ``steps``
    pieces at the local density, the flow found by bisection. A 1 m line of 4 mm
    bore from 6 bar into 3.5 bar passes 10.7 g/s, a quarter of what the precision
    rig's valve passes fully open (44 g/s): with lines it is the line that limits
    how fast a chamber fills (trajectories planned on the valve alone were four
    times too fast for the precision rig and the piston stalled half-way through a
    10 mm step).
    """
    from ..physics.line import pressure_drop
    if not (length > 0 and diameter > 0 and p_in > p_out > 0):
        raise InputError("line_flow needs a line length and diameter > 0 m and "
                         f"p_in > p_out > 0 Pa, got {length!r}, {diameter!r}, {p_in!r}, {p_out!r}")
    seg = length / steps

    def end_pressure(q: float) -> float:
        p = p_in
        for _ in range(steps):
            p -= float(pressure_drop(q, p, diameter, seg, temperature))
            if p <= 0.0:
                return -math.inf
        return p

    lo, hi = 0.0, p_in * math.pi / 4.0 * diameter ** 2 / math.sqrt(_R * temperature)  # choked
    while end_pressure(hi) > p_out:
        hi *= 2.0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if end_pressure(mid) > p_out else (lo, mid)
    return lo


@dataclass(frozen=True)
class VelocityPID:
    """PID on the estimated state, with acceleration feedback and feedforward (V):

        u = u_c + kp e + kd (r1 - v) + ka (r2 - a) + ff . (r1, r2, r3) + ki int(e)

    e = r - x, with r the preview's trajectory when given (else the reference as it
    comes, r1 its difference, r2 = r3 = 0 and no ``ff``; r1, r2, r3 the first three
    derivatives);
    x, v, a the observer's estimates (``a``: the pneumatic force less the observer's
    force estimate, over the mass; ka = 0 in :func:`design`, see :func:`_pid`).
    ``ff`` is the reduced model's inverse, so the loop works only on what the model
    misses (without it a ramp lags by r1 / (kp kv): 9 mm at 100 mm/s on the precision
    rig).

    The integral is for what holds a piston off its target with the valve at its
    null (an unmodelled null offset, leakage), a few per cent of the span at most:

    * it integrates only while the reference is still and |e| <= ``integral_zone``
      (m): on a move its error is the trajectory's, not an offset's (integrated over a
      250 mm step it wound up to -0.2 V and held a piston 11 mm short of its target
      with the valve closed in the deadband: precision rig);
    * its contribution is clamped to +-``integral_limit`` (V);
    * it is held while |e| is below ``integral_band`` (m; half a quantum: below it
      the sensor cannot tell the error, and integrating noise into a stuck piston
      makes it hunt) and while the command saturates.

    Friction (``friction``, the plant file's :class:`~.compensation.FrictionModel`;
    None: off): in the reduced model the command sets the force's rate
    (``force_rate`` = m kv w0^2, N/s per V), so the model friction's rate at the
    reference is fed forward, and a stuck piston that must move is driven to the
    static friction (:meth:`_friction`; ``mass`` kg, ``viscous`` N s/m for the
    force from the observer's estimates, ``force_time`` s its time constant;
    ``breakaway_time`` s, that of a stuck piston's drive to F_s, default
    ``force_time``; ``release`` samples of the break-away release, 0: none).
    ``loop_gain`` (1/s): kp kv, for reference.
    """

    kp: float
    kd: float
    ki: float
    sample_time: float
    u_center: float
    u_min: float
    u_max: float
    integral_band: float = 0.0
    preview: Any = None
    ka: float = 0.0
    ff: tuple = (0.0, 0.0, 0.0)
    integral_zone: float = math.inf
    integral_limit: float = math.inf
    friction: Any = None
    force_rate: float = 0.0
    mass: float = 0.0
    viscous: float = 0.0
    loop_gain: float = 0.0
    force_time: float = 0.0
    breakaway_time: float = 0.0
    release: int = 0

    kind = "pid"
    needs = ("x", "v")

    def reset(self):
        return (0.0, None, 0.0, None)

    def _friction(self, brk, rs: float, r1: float, r2: float, y: dict, t: float = 0.0):
        """(command V, break-away state) of the friction compensation.

        The law works on the reduced model, in which the valve command sets the
        force's rate (``force_rate`` N/s per V, m kv w0^2): a force the model lacks
        is compensated by its rate. (1) Given the preview, the plant file's friction
        at the reference's velocity changes at F'(r1) r2: fed forward as that rate.
        (2) A stuck piston that must move (:func:`~.feedback_linearizing.breakaway`)
        needs the static friction in that direction: the force, known from the
        observer (m a + beta v + d), is driven to it with the reduced model's time
        constant 1/w0 (``force_time``) until the piston moves (not beyond the
        model's F_s as FL does: on the precision rig the sine's worst error went
        3.3 -> 6.4 mm, seed 0). Without it the
        proportional term builds the force at kp e (4 mV per mm on the precision
        rig): a 10 mm step stalled half-way for 170 ms, then broke away 1.9 mm past
        its target. (3) Once it has moved, the friction is the sliding one: the
        force built to F_s is an excess of F_s - F_c that the position terms remove
        only at the loop gain (11 1/s on the precision rig: 27 N held for 40 ms after
        the sine's reversal, the piston 3.2 mm ahead). It is driven back to the
        sliding need F_c + m r2 + beta r1 with the same time constant until it gets
        there (or for three time constants at most); the break-away state then holds
        (direction, None, end time). The rate term (1) feeds the sliding law
        (:func:`~.feedback_linearizing.fed_friction`) while the reference slows
        into a reversal (the preview's velocity turned at twice the time to stop):
        the Stribeck rise fed at the reference's velocity pushed the still sliding
        piston 1 mm past the sine's reversal. Not at a stop: this loop (kp kv = 11
        1/s on the precision rig) needs that push to arrive; without it it stopped
        0.1-0.2 mm further off its targets (test profile seeds 0-1, steady state
        0.41 / 0.37 -> 0.48 / 0.59 mm; on the foreign LuGre rig 0.003 -> 0.54 mm).
        Precision sine (seed 0) 3.22 -> 1.87 mm; test profile seeds 0-1 3.49 / 3.44
        -> 2.15 / 1.88 mm, steady state and holds as before.
        (4) Optional (off in :func:`design`): ``breakaway_time`` drives a stuck
        piston to F_s faster than 1/w0, and ``release`` adds, on the sample that
        sees the break-away and for that many samples, the command that takes an
        excess force to the sliding need (as FL's :meth:`~.feedback_linearizing.
        FeedbackLinearizing._release`). With both at the lines' round trip (6 ms,
        3 samples) the test profile's sine (seeds 0-4) went 2.16/1.88/1.87/2.15/
        2.21 -> 0.98/0.98/1.44/1.36/1.32 mm, but the precision sine started 0.3 s
        after rest went 1.87 -> 3.82 mm (drive at 12 / 25 ms: 1.79 / 1.99 mm).
        """
        from .feedback_linearizing import breakaway, fed_friction
        fr, c = self.friction, self.force_rate
        if fr is None or c <= 0 or self.force_time <= 0 or "d" not in y or "a" not in y:
            return 0.0, None
        law = fr
        if r1 * r2 < 0.0 and self.preview is not None:
            # slowing: a reversal if the preview's velocity has turned by twice the
            # time to stop at this deceleration
            ahead = float(self.preview.derivatives(t + 2.0 * abs(r1 / r2))[1])
            if ahead * r1 < 0.0:
                law = fed_friction(fr, r1, r2)
        u = float(law.slope(r1)) * r2 / c
        x, v = float(y["x"]), float(y["v"])
        force = self.mass * float(y["a"]) + self.viscous * v + float(y["d"])
        rel = None
        if brk is not None and brk[1] is None:         # handing the break-away force back
            rel, brk = brk, None
        was = brk
        brk = breakaway(brk, r1, v,
                        float(y.get("x_measured", x)), fr.stribeck_velocity)
        if brk is not None:
            want = brk[0] * fr.static + self.mass * r2 + self.viscous * r1
            u += (want - force) / (c * (self.breakaway_time or self.force_time))
            return u, brk
        if was is not None:
            n = self.release * self.sample_time
            want = was[0] * fr.coulomb + self.mass * r2 + self.viscous * r1
            excess = min(was[0] * (want - force), 0.0) * was[0]     # an excess only
            rel = (was[0], None, t + 3.0 * self.force_time, t + n - 0.5 * self.sample_time,
                   excess / (c * n) if n > 0 else 0.0)
        if rel is not None and t < rel[2] and r1 * rel[0] > 0:
            want = rel[0] * fr.coulomb + self.mass * r2 + self.viscous * r1
            pulse = len(rel) > 3 and t < rel[3]
            u += rel[4] if pulse else 0.0
            if rel[0] * (force - want) > 0:
                u += (want - force) / (c * self.force_time)
                return u, rel
            if pulse:
                return u, rel
        return u, brk

    def held(self, new, entry, opening: float):
        """State while a hold commands the valve: the integral frozen at ``entry``'s
        (:func:`~.compensation.held`)."""
        return (new[0] if entry is None else entry[0], *new[1:])

    def update(self, state, r: float, y: dict):
        integ, r_prev, t, brk = (*state, None)[:4]
        T = self.sample_time
        ff = self.ff
        if self.preview is not None:
            rs, r1, r2, r3 = (float(d) for d in self.preview.derivatives(t))
        else:
            # a step's difference is no velocity to feed forward (a 30 mm step at
            # 10 ms asked for 3 m/s: 1.2 V for a sample, 3.8 mm overshoot)
            rs, r1, r2, r3 = r, 0.0 if r_prev is None else (r - r_prev) / T, 0.0, 0.0
            ff = (0.0, 0.0, 0.0)
        e = rs - float(y["x"])
        a = float(y.get("a", 0.0)) if self.ka else 0.0
        u = (self.u_center + self.kp * e + self.kd * (r1 - float(y["v"])) + self.ka * (r2 - a)
             + ff[0] * r1 + ff[1] * r2 + ff[2] * r3 + self.ki * integ)
        u_f, brk = self._friction(brk, rs, r1, r2 if self.preview is not None else 0.0, y, t)
        u += u_f
        still = r_prev is not None and abs(r - r_prev) <= 1e-12 and r1 == 0.0
        if still and self.integral_band < abs(e) <= self.integral_zone:
            cap = self.integral_limit / self.ki if self.ki > 0 else math.inf
            new = min(max(integ + e * T, -cap), cap)
            u_try = u + self.ki * (new - integ)
            if self.u_min < u_try < self.u_max:
                integ, u = new, u_try
        return (integ, r, t + T, brk), float(u)


def design(plant, kind: str = "nmpc", spec=None, *, sample_time: float | None = None,
           reference=None, quantum: float | None = None, pressure_noise: float = 0.0,
           bandwidth: float | None = None, jit: bool = True, lock: bool | None = None):
    """A controller for ``plant`` that needs only x, p_a, p_b (module docstring).

    Parameters
    ----------
    plant : workbench.Plant
        The plant file as a user has it (effects included as identified).
    kind : {"pid", "fl", "nmpc"}
    spec : workbench.validate.Specification, optional
        Default :meth:`Specification.precision` of the plant: its steady-state
        error sets the hold lock band (half of it).
    sample_time : float, s
        Default the plant file's ``controller.sample_time``, else 10 ms.
    reference : Reference, optional
        The whole reference, known in advance: smoothed to the axis's limits and
        tracked with feedforward. The returned controller then expects to run on it
        from t = 0.
    quantum : float, m
        Position-sensor step (default the plant file's, else 12 bits over the stroke).
    pressure_noise : float, Pa
        Pressure sensor noise (std) for the observer.
    bandwidth : float, rad/s
        FL error bandwidth (default :func:`_fl_bandwidth`: the sampling rule's phase
        spent on the command's hold and the lines' transport delay, at most a third
        of the observer's bandwidth; lowered to what the valve's flow allows).
    jit : bool
        Compile the NMPC to C.
    lock : bool, optional
        Hold lock (default: when the plant file has dry friction; module docstring).

    Returns
    -------
    Observed
        With ``needs == ("x", "p_a", "p_b")``; ``.inner`` is the compensated law.
    """
    if kind not in KINDS:
        raise InputError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    prm = plant.params
    T = float(sample_time if sample_time is not None else prm.get("controller.sample_time") or 0.01)
    if not (math.isfinite(T) and T > 0):
        raise InputError(f"sample_time must be > 0 s, got {sample_time!r}")
    q = float(quantum if quantum is not None else
              prm.get("controller.position_resolution") or plant.stroke / 4096.0)
    # the precision specification's steady-state limit is one quantum
    ss_limit = q if spec is None else float(spec.max_steady_state_error)
    preview = None
    if reference is not None:
        from ..references import smooth
        lim = axis_limits(plant)
        preview = smooth(reference, lim.speed, lim.acceleration, lim.jerk)
    obs = kalman_observer(plant, T, quantum=q, pressure_noise=pressure_noise)
    law = _law(plant, kind, T, preview, q, bandwidth, jit, 1.0 / obs.bandwidth)
    has = set(plant.effects)
    dead = DeadbandInverse.from_plant(plant)         # identity without deadband and offset
    if lock is None:
        lock = "dry_friction" in has              # only friction holds a locked piston
    band = min(0.5 * q, 0.5 * ss_limit) if lock else 0.0
    hold = (hold_for_plant(plant, T, 2.0 * band, pressure_noise, lock_speed=LOCK_SPEED,
                           range=hold_range(law, dead, plant if kind == "fl" else None),
                           line_flow=hold_line_flow(plant), aim=hold_aims(law))
            if lock else None)
    margin = float(getattr(law, "stroke_margin", 0.0))
    comp = Compensated(law, deadband=dead, lock_band=band, release_band=4.0 * band,
                       lock_speed=LOCK_SPEED if lock else 0.0, hold=hold,
                       limits=(margin, plant.stroke - margin), preview=preview,
                       lead=release_lead(law, hold, T))
    return Observed(comp, obs, plant, preview=preview)


def hold_range(law, dead, plant=None) -> float:
    """|r - x| (m) up to which the hold takes a stuck piston over: 2 mm, or twice the
    position law's own dead zone, or (given the plant: :func:`design` does for FL)
    the break-away jump :func:`breakaway_jump`, whichever is widest.

    A law that moves a stuck piston by raising its force from the position error
    must reach the static friction before anything moves, and the excess over the
    sliding friction then carries the piston on: within that jump of the target
    it cannot land without passing it (FL on the precision rig: stuck 2.4 mm short
    after a 10 mm step, broke away 280 ms later and stopped 3.1 mm past, the next
    break-away as far back: a stick-slip cycle just outside a 2 mm range; precision
    profile --quick seeds 0/1/2, overshoot 58/58/48 % -> 2.9/10.9/4.7 %, steady
    state worst 2.9/2.6/2.5 -> 0.16/0.03/0.20 mm). Not for the PID: its range is
    already twice its dead zone (4.6 mm), and from 5-14 mm the hold's pulses did
    worse than the PID with its break-away (same seeds: steady state worst
    0.35/0.06/0.10 -> 1.2/1.7/1.4 mm); not for the NMPC, which plans the
    break-away with the friction in its model.

    A proportional law whose error opens the valve less than the deadband inverse's
    residual overlap (its straight piece, ``dead.width`` of the deadband) cannot move
    a stuck piston; for the PID that is |e| < width d span / kp (0.2 % of the span
    at kp = 4.4 V/m: 2.3 mm on the precision rig, where the piston stuck 2.1-2.5 mm
    off, beyond the 2 mm the hold took over, for the rest of the hold while the
    integral crept up by 0.01 V/s).
    """
    kp = getattr(law, "kp", None)
    residual = dead.width * dead.deadband * dead.span
    zone = residual / kp if kp else 0.0
    jump = 0.0 if plant is None or getattr(law, "horizon", None) is not None else breakaway_jump(plant)
    return max(2e-3, 2.0 * zone, jump)


def hold_aims(law) -> bool:
    """Whether the hold aims its pulses on the rig's own outcomes
    (:class:`~.hold.HoldPositioner` ``aim``): for every law but the NMPC.

    What differs is what the law hands over. PID and FL stop where their force meets
    the static friction, 1.7-2.5 mm (14-20 quanta) from the target after the 60 mm
    steps of the precision rig: the bracket alone, grown x 1.5 per pulse from below
    the break-away, walked such a piston in at 80 ms per pulse into the hold's second
    half (PID, test profile seeds 0/1: a hold still pulsing, steady state 0.41/0.37
    mm). The NMPC plans the break-away with the friction in its model and lands
    within a few quanta; for it the aimed pulses changed which stop lands where and
    cost its precision pass (session 10, precision profile --quick: steady state
    0.125 mm > the 0.122 mm quantum, a hold pulsing on seed 1, overshoot 3.3 % on
    seed 2), so it keeps the bracket that passes.
    """
    return getattr(law, "horizon", None) is None


def hold_line_flow(plant) -> float | None:
    """kg/s the plant's lines pass from the supply into a chamber at the mid pressure
    (:func:`line_flow`), None without lines: the hold's first pulse far off."""
    prm = plant.params
    if "line_dynamics" not in set(plant.effects):
        return None
    p_s, p_atm = float(prm["supply.pressure"]), float(prm["gas.atmospheric_pressure"])
    return line_flow(float(prm["lines.length"]), float(prm["lines.diameter"]), p_s,
                     0.5 * (p_s + p_atm), float(prm["gas.temperature"]))


def breakaway_jump(plant) -> float:
    """How far (m) a piston breaking away at the static friction slides on the
    closed chambers' gas spring: 2 (F_s - F_c) / k, with k = n p_m (A_a^2 / V_a +
    A_b^2 / V_b) at mid-stroke (p_m the mid pressure (p_s + p_atm) / 2, the
    volumes with their dead volume and line); 0 without dry friction. The
    undamped spring released with the excess F_s - F_c swings to twice its
    equilibrium (precision rig: 10 N over 1.7 kN/m, 11.8 mm).
    """
    prm = plant.params
    if "dry_friction" not in set(plant.effects):
        return 0.0
    fc = float(prm.get("friction.coulomb") or 0.0)
    fs = float(prm.get("friction.static") or fc)
    line = 0.0
    if "line_dynamics" in set(plant.effects):
        line = float(prm["lines.length"]) * math.pi / 4 * float(prm["lines.diameter"]) ** 2
    p_m = 0.5 * (float(prm["supply.pressure"]) + float(prm["gas.atmospheric_pressure"]))
    half = 0.5 * plant.stroke
    a_a, a_b = float(plant.area_a), float(plant.area_b)
    k = float(prm["gas.polytropic_index"]) * p_m * (
        a_a ** 2 / (a_a * half + float(prm["cylinder.dead_volume_a"]) + line)
        + a_b ** 2 / (a_b * half + float(prm["cylinder.dead_volume_b"]) + line))
    return 2.0 * max(fs - fc, 0.0) / k


#: Share of the Stribeck excess F_s - F_c by which FL's force may pass a stuck
#: piston's break-away point before the law can see the piston move.
PROBE_SHARE = 0.3


def breakaway_probe(plant, bandwidth: float, quantum: float) -> float:
    """FL's ``probe`` (:class:`~.feedback_linearizing.FeedbackLinearizing`): the share
    of F_s - F_c by which a stuck piston's force target leads its force beyond the
    file's F_s, so that the force overshoots the break-away by at most
    :data:`PROBE_SHARE` of F_s - F_c before the law sees the piston move (at most 1).

    Beyond F_s the force rises at k2 probe (F_s - F_c) (k2 = 3 ``bandwidth``, 1/s);
    the law sees a break-away after tau = sqrt(2 q m / (F_s - F_c)) (a ``quantum`` q
    of travel under the jump's acceleration) plus the lines' delay
    (:func:`line_delay`), so probe = PROBE_SHARE / (k2 tau). Precision rig (40 rad/s,
    q 0.122 mm): tau = 5.4 + 2.9 ms, probe 0.30. With probe 1 (session 9) the force
    passed the break-away by about F_s - F_c and the jump doubled: precision profile
    --quick seed 0, overshoot of a 10 mm step 4.1 -> 1.8 %, sine 2.3 -> 1.6 mm; on
    the rig with 1.5x friction (test profile, seed 0) worst steady state 0.21 ->
    0.10 mm. 1 without a Stribeck excess.
    """
    prm = plant.params
    fc = float(prm.get("friction.coulomb") or 0.0)
    fs = float(prm.get("friction.static") or fc)
    if fs <= fc or not (bandwidth > 0 and quantum > 0):
        return 1.0
    tau = math.sqrt(2.0 * quantum * float(prm["load.mass"]) / (fs - fc)) + line_delay(plant)
    return float(min(1.0, PROBE_SHARE / (3.0 * bandwidth * tau)))


def release_lead(law, hold, T: float) -> float:
    """How far ahead (s) a hold looks at the preview to hand over before a move: the
    NMPC's horizon (it plans the move that far ahead), else the lines' round trip
    (the hold's pulse half, ``hold.width`` samples) and a sample: a command reaches
    the chambers only after it."""
    if getattr(law, "horizon", None) is not None:
        return float(law.horizon) * T
    return (getattr(hold, "width", 0) + 1) * T


def _law(plant, kind: str, T: float, preview, q: float, bandwidth, jit: bool,
         estimate_lag: float = 0.0):
    """The position law of :func:`design` (uncompensated, reads x, v, p_a, p_b);
    ``estimate_lag`` s, the observer's time constant (FL's friction handover)."""
    prm = plant.params
    if kind == "nmpc":
        from .mpc import NMPC, STATE_EFFECTS
        from .mpc.model import DESIGN_BREAKAWAY, DESIGN_LINES
        keep = [e for e in plant.effects if e not in STATE_EFFECTS
                and e not in ("valve_deadband", "valve_offset")]
        return NMPC.for_plant(plant, effects=keep, lines=DESIGN_LINES, sample_time=T,
                              max_speed=2.0, horizon=nmpc_horizon(T), jit=jit, preview=preview,
                              disturbance_gain=nmpc_disturbance_gain(T),
                              breakaway=DESIGN_BREAKAWAY)
    if kind == "fl":
        lam = (bandwidth if bandwidth is not None else
               _fl_bandwidth(T, line_delay(plant), 1.0 / estimate_lag if estimate_lag > 0 else math.inf))
        fl = _fl(plant, lam, T, preview)
        fr = FrictionModel.from_plant(plant)
        # handed over to the force estimate in the observer's time constant: no double
        # counting (handed over in 1/bandwidth instead, 40 ms, the friction counted
        # twice meanwhile: 78-110 % overshoot on the precision profile's 10 mm steps).
        # Precision rig, FL sine worst error seeds 0/1: precision profile 13.3/13.2 ->
        # 9.1/13.4 mm, test profile 13.7/13.8 -> 11.3/9.9 mm; overshoot unchanged
        if fr is None:
            return fl
        return replace(fl, friction=fr, friction_lag=estimate_lag,
                       probe=breakaway_probe(plant, fl.bandwidth, q),
                       release=release_samples(plant, T))
    # no friction feedforward: FL's (the plant file's friction at the reference's
    # velocity handed over to the observer's estimate) made this loop hunt in its holds
    # (precision profile --quick: 300 command changes, 5 mm peak-to-peak)
    return _pid(plant, T, preview, q)


def nmpc_disturbance_gain(T: float) -> float:
    """Gain of the NMPC's force estimate: T / DISTURBANCE_TIME (at most 1).

    The estimate d += g m (v_pred - v) / T is a first-order filter of time constant
    T / g on the force the model mispredicts; g = 1 (deadbeat) passes every sample's
    velocity error into the force. On a rig with dry friction the prediction model's
    smooth friction (slope F_s / v_e at v = 0) turns the observer's velocity noise of
    a stuck piston into +-F_s force jumps, and the NMPC answers each with the valve:
    the command chattered (1.2 V hf std on the precision rig, seed 0) and a hold
    hunted (0.53 mm peak-to-peak). The observer's own disturbance model says the
    force changes by its size within DISTURBANCE_TIME (20 ms); filtering the estimate
    with that time constant keeps the integral action (offset-free) and removes the
    sample-to-sample noise (0.64 V, no hold limit cycle in seeds 0-4).
    """
    from .observer import DISTURBANCE_TIME
    return float(min(1.0, T / DISTURBANCE_TIME))


def nmpc_horizon(T: float) -> int:
    """Shooting intervals: about 0.1 s of prediction, 20 .. 40 intervals (the solve
    time grows with N; 40 at 2 ms solves in about 0.7 ms)."""
    return int(min(40, max(20, round(0.1 / T))))


def _fl(plant, lam: float, T: float, preview):
    """FL at ``lam`` rad/s (or the largest feasible bandwidth below it), without the
    law's own integral: the observer's force estimate d already removes a constant
    unmodelled force, and on top of it the integral (gain lambda^4) turned every
    stick into a break-away overshoot (hunting, 3 mm on the precision rig)."""
    from dataclasses import replace
    from .feedback_linearizing import feedback_linearizing
    # the valve's flow is checked on what the law will track: the preview when given
    # (the reference model is then unused), else the validation profile
    try:
        fl = feedback_linearizing(plant, bandwidth=lam, sample_time=T, integral=False,
                                  reference=preview)
    except InputError as exc:
        import re
        m = re.search(r"about ([0-9.]+) rad/s", str(exc))
        if not m:
            raise
        fl = feedback_linearizing(plant, bandwidth=0.95 * float(m.group(1)), sample_time=T,
                                  integral=False, reference=preview)
    return replace(fl, preview=preview)


def _pid(plant, T: float, preview, q: float) -> VelocityPID:
    """PID gains from the reduced linear model at mid-stroke (paper 000's structure).

    Loop gain k0 = kp kv at a third of the continuous Hurwitz limit 2 zeta w0 and
    below 0.2 / T (the sampled loop's phase); kd puts the PD zero on the slower real
    pole for zeta > 1, else at w0 (it damps the pole pair); ki = k0 kp / 10 (the
    integral an order slower than the loop), limited to ``INTEGRAL_SHARE`` of the
    span. ff = (w0^2, 2 zeta w0, 1) / (kv w0^2) inverts the reduced model
    x''' + 2 zeta w0 x'' + w0^2 x' = kv w0^2 u for the preview's derivatives.

    Tried and not kept: the three poles placed at the FL's bandwidth with
    acceleration feedback (ka, the PVA structure): precision profile --quick worst
    steady state 1.87 mm vs 2.46 mm, but 68-81 command changes in four holds' second
    halves (the pressure loop rings with the 1 m lines), and a 30 mm step at 10 ms
    stuck 2.5 mm off (pole 25 rad/s; 6.7 mm at 20, 0.02 mm at 30: stick-slip).
    """
    from .. import linearize
    from .mpc import prediction_model
    prm = plant.params
    # friction and deadband have no small-signal gain at rest: linearise without them
    smooth = prediction_model(plant, effects=[e for e in plant.effects if e not in
                                              ("dry_friction", "valve_deadband", "valve_offset",
                                               "valve_dynamics", "heat_transfer",
                                               "line_dynamics", "supply_droop")])
    red = linearize.reduced_position_model(linearize.tangent(smooth, x=0.5 * plant.stroke))
    k0 = min(2.0 * red.zeta * red.w0 / 3.0, 0.2 / T)
    kv, w2 = red.kv, red.w0 ** 2
    kp = k0 / kv
    tau = ((red.zeta + math.sqrt(red.zeta ** 2 - 1.0)) / red.w0 if red.zeta > 1.0
           else 1.0 / red.w0)
    limit = INTEGRAL_SHARE * float(prm["valve.command_span"])
    m = float(prm["load.mass"])
    return VelocityPID(kp=kp, kd=kp * tau, ki=0.1 * k0 * kp, sample_time=T,
                       u_center=float(prm["valve.command_center"]),
                       u_min=float(prm["valve.command_min"]),
                       u_max=float(prm["valve.command_max"]),
                       integral_band=0.5 * q, preview=preview,
                       ff=(1.0 / kv, 2.0 * red.zeta / (red.w0 * kv), 1.0 / (kv * w2)),
                       integral_zone=limit / kp, integral_limit=limit,
                       friction=FrictionModel.from_plant(plant), force_rate=m * kv * w2,
                       mass=m, viscous=float(prm["load.viscous_friction"]), loop_gain=k0,
                       force_time=1.0 / red.w0)


def _fl_bandwidth(T: float, line_delay: float = 0.0,
                  observer_bandwidth: float = math.inf) -> float:
    """The FL's default error bandwidth (rad/s) at sample time ``T`` (s).

    The sampling rule (:data:`~.feedback_linearizing.SAMPLING_LIMIT`) allows the
    command's hold a phase lag of lambda T / 2 = pi / 20 at its bound; the lines'
    transport delay ``line_delay`` (s, :func:`line_delay`) lags the force the same
    way, so the same phase is spent on both: lambda (T / 2 + tau) <= pi / 20,
    with 0.8 of the sampling bound as before (25 rad/s at 10 ms without lines),
    and at most a third of the observer's slowest pole (the estimates the law runs
    on settle before the loop does).

    The default was 25 rad/s for every sample time: on the precision rig (2 ms,
    1 m lines: 40 rad/s now) the break-away jumps of its stick-slip friction were
    caught at k2 = 3 lambda (75 1/s), and the sine's worst error was 3.3-3.6 mm
    (precision sine seed 0; test profile seeds 0-4), with limit cycles in 1-2 of
    the 5 holds of every seed. At 40 rad/s: 1.9 mm and 2.2-2.4 mm, no limit cycle
    (30 rad/s 2.6 mm with one; 60 and 80 rad/s 1.6 / 1.5 mm with two to three times
    the command activity of 25 rad/s).
    """
    from .feedback_linearizing import SAMPLING_LIMIT
    delay = 0.5 * T + max(float(line_delay), 0.0)
    return float(min(0.8 * SAMPLING_LIMIT / T, 0.5 * SAMPLING_LIMIT / delay,
                     observer_bandwidth / 3.0))


def release_samples(plant, T: float) -> int:
    """Samples of FL's break-away release (:meth:`~.feedback_linearizing.
    FeedbackLinearizing._release`): the lines' round trip 2 L / c (:func:`line_delay`)
    in samples, at least one: a force change sent into a line is felt whole at the
    chamber only after its reflection has come back (the hold's pulse half,
    :mod:`~.hold`, is sized the same way; 3 samples on the precision rig)."""
    return max(1, int(math.ceil(2.0 * line_delay(plant) / T - 1e-9)))


def line_delay(plant) -> float:
    """Transport delay (s) of the plant file's lines: length over the adiabatic
    speed of sound sqrt(gamma R T) (the line model's waves, :mod:`workbench.physics.
    line`); 0 without ``line_dynamics`` (1 m at 20 degC: 2.9 ms)."""
    from ..physics.gas import GAMMA
    if "line_dynamics" not in set(plant.effects):
        return 0.0
    prm = plant.params
    return float(prm["lines.length"]) / math.sqrt(GAMMA * _R * float(prm["gas.temperature"]))
