"""Precision hold for a piston with dry friction: lock on the target's quantum, pulse in.

Why a position loop alone hunts. A piston stuck a little off its target holds any
force below the static friction F_s. A loop with integral action (PID, a force
estimate) raises the force until the piston breaks away; the friction then falls to
its Coulomb level F_c and the excess F_s - F_c (10 N on the precision rig) accelerates
the piston before the loop can see it: the position sensor shows motion only after a
quantum of travel, and a command reaches the chamber only after the lines' delay. The
jump (0.3-1 mm on the precision rig, 2.5-8 quanta) is larger than the band a stop must
land in, so the next stop is a coin toss and the loop hunts. Closing the valve does not
help: the closed chambers are a gas spring of stiffness k = n A^2 (p_a / V_a + p_b /
V_b) (about 1.5 kN/m at mid-stroke on that rig), so a released excess would travel
2 (F_s - F_c) / k (about 14 mm) before the spring stops it.

What :class:`HoldPositioner` does instead, once the reference is still:

1. **Hold the net force at zero, not the valve closed.** The hold takes over from the
   position law when the piston is slow in the target's quantum, or when its measured
   position has not changed for ``dwell`` within ``range`` of the target. From then on
   a slow force loop (time constant ``UNLOAD_SAMPLES`` samples) brings the net
   pneumatic force, measured from the two pressures and filtered over the dwell (line
   ringing averages out), within ``force_band`` of zero, with hysteresis, and closes
   the valve. A piston under zero net force stops and stays on any friction law: a
   sliding one decelerates at F_c / m, a stuck one is not pushed, and a smooth
   friction law (which creeps under any force) has nothing to creep under. Closing the
   valve alone leaves whatever force the law had built: on the precision rig -20 to
   -33 N, above F_c, which carried a piston 6 mm with the valve closed.
2. **Lock on the target's quantum.** The measured position is a quantiser level; r lies
   in exactly one level's bin (|r - x_m| <= q / 2), and a piston in that bin is within
   one quantum of r whatever its sub-quantum place: there the hold leaves the valve
   closed and does nothing more.
3. **Stuck outside it: force pulses, no integral.** Once stuck (position still and the
   force's spread over the dwell within ``force_band``) with the force unloaded, a pulse
   is sent: the valve opened by ``amplitude`` towards the target for ``width`` samples
   and by the same the other way for as many, then the force loop again. The chambers
   get back about the gas they lost, so the piston feels a force *bump* that ends on
   its own; a bump that crosses F_s moves it, then it sticks again. The width is twice
   the lines' acoustic delay (a shorter pulse does not reach the chamber before its
   reverse half follows). After the piston has stopped again, the outcome adapts the
   strength of the next pulse (after Yang and Tomizuka 1988, adaptive pulse-width
   control under stiction and Coulomb friction): a bracket per direction between the
   strongest pulse that did not move the piston a quantum and the weakest that carried
   it past the target's bin, bisected (geometric mean); x ``grow`` without an upper end,
   x ``shrink`` without a lower one. Once the rig has shown moves shorter and longer
   than the distance left, the strength is interpolated between them instead
   (:meth:`HoldPositioner._aim`: a walk towards a target 2 mm off grown x 1.5 per
   pulse stepped from 0.3 to 1.1 mm moves and overshot), below the bracket's upper
   end; a direction without pulses yet starts at the other direction's threshold. Beyond full opening a pulse gets longer (through
   1 m lines the chamber's force rise is limited by the line's flow: 0.45 and 0.67
   opening gave the same 31 N bump on the precision rig), fully open but its last
   sample, which is graded so the bump grows continuously with the strength, and by
   at most half a sample per pulse (:meth:`HoldPositioner.pulse_openings`,
   :meth:`HoldPositioner._next`).
4. **Far off** (beyond ``range``), or the reference moving: the position law acts.

Why it works on rigs the plant file does not describe exactly: nothing in the pulse
logic uses F_s, F_c or the mass. The width needs only the lines' length; the strength
is found on the rig, pulse by pulse, from moves the position sensor sees; the force
loop needs only the areas and the valve's flow (its rate only sets how fast it
unloads). The plant file's static friction sets the first pulse (the opening that
would raise the force by F_s in one width at the valve's flow, from below the
break-away; more than ``FAR`` quanta off, at the flow the lines pass: a starting point).

No limit cycle. In a hold the loop is closed only through discrete pulses, each sent
on a stuck, unloaded piston and followed by the force loop until the piston is still
and the force steady again: there is no continuous position feedback to sustain an
oscillation. A pulse that brings the piston closer to the target's bin shortens the
distance by at least a quantum (at most ``range`` / q of them); after ``max_pulses``
others in one hold the hold stops pulsing (termination by construction; the piston is
then held where it is, off the quantum, and the steady-state error says so). Nor does
it pulse when no pulse can land closer (:meth:`HoldPositioner.no_better`): the
smallest jump a pulse at the threshold has made (bracket narrower than one ``grow``)
is the rig's shortest move, and a piston within half of it stays. A bracket that
keeps overshooting narrows geometrically. What the bisection cannot remove is the
smallest move a bump that breaks the piston away makes: on the precision rig (F_s -
F_c = 10 N, 1 m lines) about 0.1-0.3 mm, one to three quanta, so a stop is not
certain to land in the target's bin at the first pulses; the bracket makes the
outcomes converge, not each pulse.

Aiming (``aim``, :func:`~.design.hold_aims`: PID and FL, which hand the hold a piston
stuck 1.7-2.5 mm off). The strength is interpolated on the rig's own (strength, move)
outcomes (:meth:`HoldPositioner._aim`), the first pulse far off is sized on the flow
the lines pass, a new direction starts at the other's threshold, the stop rule takes
the median of the three smallest moves (:meth:`HoldPositioner.no_better`); a pulse
waits for the ringing only down to F_c / 4 (:attr:`HoldPositioner.quiet`), the force
loop does not follow the ringing (:meth:`HoldPositioner._unload`), and after ``HOPS``
moves that left the piston no closer than its closest, the hold stops
(:meth:`HoldPositioner._hopped`). Without it (the NMPC): the bracket alone, as its
precision pass was measured.

An aiming hold unloads a still piston in its bin instead of
leaving it. Why: the pulses leave a net force behind (their reverse half does not
return all the gas: 5-10 N on the precision rig), which a friction that creeps turns
into motion (foreign rig, smooth Stribeck law, FL: -5.7 N moved a locked piston 0.11
mm out of its bin in 0.24 s, and the hold pulsed it back, 14-27 command changes per
hold). Unloading a stuck piston cannot move it under any friction law (the force only
falls), so the stuck piston stays where it is. Only beyond ``ring_band``
(F_c / 4): the loop's smallest opening changes the force by up to 1.25 N per sample
near a stroke end, and a narrower band ticked with the piston at rest (precision
profile --quick, hold at 450 mm: 22 command changes). The NMPC keeps its rules (as
:attr:`quiet`).

The NMPC's hold balances a piston that creeps (:meth:`HoldPositioner._balance`). Once
a held piston has been seen to change its measured level with the valve closed (its
friction does not hold it: a smooth Stribeck law, LuGre's pre-sliding), every held
piston's net force is taken to zero, one sample sized on the whole force and then a
wait, never reversed; and a held piston that creeps one level out, still within a
quantum of r, stays held (balanced) instead of being pulsed (a pulse's smallest jump,
1-4 quanta, cannot land closer). Until then nothing changes: on a rig whose friction
sticks (the precision rig, Karnopp) a held piston never moves, and the hold is as
its pass was measured.

The law underneath: while the hold commands, :func:`~.compensation.held` keeps the
law's integral or force estimate from winding up (the NMPC's force estimate is set to
the zero the hold keeps, its last command to the opening applied).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import InputError

__all__ = ["HoldPositioner", "hold_for_plant"]

#: m/s, speed of sound in air at 20 degC (the lines' delay).
SOUND_SPEED = 343.0

TRACK, LOCKED, READY, PULSE, SETTLE = "track", "locked", "ready", "pulse", "settle"
#: Samples over which the unloading force loop removes the force (its time constant).
UNLOAD_SAMPLES = 10
#: Pulse outcomes kept per direction (:meth:`HoldPositioner._aim`, :meth:`~HoldPositioner.no_better`).
SEEN = 8
#: The smallest moves among them whose median is the rig's typical shortest jump.
JUMPS = 3
#: Quanta beyond which the first pulse is the stronger ``far_amplitude``: the first
#: pulse sized on the lines' flow moved the piston 2-3 quanta on the precision rig
#: (10 stretched), well within twice this distance.
FAR = 8
#: Moves that left the piston no closer than its closest in a hold, after which an
#: aiming hold stops pulsing (:meth:`HoldPositioner._hopped`).
HOPS = 3
#: Smallest opening the force loop commands (fraction of the span): a smaller one
#: stays inside the residual overlap a deadband inverse leaves (its linear piece).
MIN_OPENING = 0.01


@dataclass(frozen=True)
class HoldPositioner:
    """Lock and pulse logic of a hold (module docstring). All openings are fractions of
    the valve's span in [-1, 1] (positive fills chamber a, moves +x).

    Attributes
    ----------
    quantum : m, the position sensor's step.
    sample_time : s.
    width : int, samples of each half of a pulse (at openings up to 1).
    amplitude : opening of the first pulse.
    dwell : s, time the measured position must stay on one level to count as still
        (default 20 ms: a piston moving faster than a quantum per ``dwell`` is seen).
    range : m, |r - x_measured| up to which the hold acts (beyond it the law does).
    lock_speed : m/s, |v| below which a piston in the target's bin is taken over.
    grow, shrink : strength factors without a move and after an overshoot while the
        bracket has only one end.
    force_rate : N/s, rate of the net force at full opening (0: no force loop).
    force_band : N, the force loop's band (and the steadiness a pulse waits for).
    area_a, area_b : m^2. p_atm : Pa. external_force : N (the net force's terms).
    max_width : int, longest pulse half, samples.
    reverse : the reverse half's length as a share of the forward half's.
    max_pulses : int, pulses per hold that did not bring the piston closer (no move,
        or past the target's bin) before the hold stops trying.
    far_amplitude : strength of the first pulse of all when the piston is more than
        ``FAR`` quanta off (0: ``amplitude``), :meth:`_strength`; with ``aim`` only.
    ring_band : N, with ``aim`` the force's spread a pulse waits for (:attr:`quiet`).
    aim : the strength aimed on the rig's own outcomes (:meth:`_aim`, ``far_amplitude``,
        a new direction at the other's threshold, the stop rule on the typical jump),
        for a law that hands the hold a piston stuck far off; False: the bracket alone
        (:func:`hold_for_plant` says which law gets which, and why).
    stroke : m, and volumes : (V_a0, V_b0) m^3, the chambers' volumes at x = 0 and
        x = stroke (dead volume and line). With them a pulse's strength and
        ``force_rate`` are taken at mid-stroke and scaled to the piston's position
        (:meth:`rate_scale`); stroke 0: no scaling.
    """

    quantum: float
    sample_time: float
    width: int = 1
    amplitude: float = 0.1
    dwell: float = 0.02
    range: float = 2e-3
    lock_speed: float = 0.02
    grow: float = 1.5
    shrink: float = 0.6
    force_rate: float = 0.0
    force_band: float = 0.0
    area_a: float = 0.0
    area_b: float = 0.0
    p_atm: float = 101325.0
    external_force: float = 0.0
    max_width: int = 16
    reverse: float = 1.0
    max_pulses: int = 10
    stroke: float = 0.0
    volumes: tuple = (0.0, 0.0)
    far_amplitude: float = 0.0
    aim: bool = False
    ring_band: float = 0.0
    force_noise: float = 0.0

    def __post_init__(self) -> None:
        for name in ("quantum", "sample_time", "dwell", "range", "lock_speed"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"hold {name} must be > 0, got {v!r}")
        if not (isinstance(self.width, int) and self.width >= 1):
            raise InputError(f"hold width must be an integer >= 1 sample, got {self.width!r}")
        if not (0.0 < self.amplitude <= 1.0):
            raise InputError(f"hold amplitude is an opening in (0, 1], got {self.amplitude!r}")
        if not (self.grow > 1.0 and 0.0 < self.shrink < 1.0):
            raise InputError("hold grow must be > 1 and shrink in (0, 1)")
        for name in ("force_rate", "force_band", "area_a", "area_b", "far_amplitude",
                     "ring_band", "force_noise"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InputError(f"hold {name} must be >= 0, got {v!r}")
        if not (isinstance(self.max_pulses, int) and self.max_pulses >= 0):
            raise InputError(f"hold max_pulses must be an integer >= 0, got {self.max_pulses!r}")

    @property
    def dwell_samples(self) -> int:
        return max(3, int(math.ceil(self.dwell / self.sample_time - 1e-9)))

    def reset(self) -> dict:
        return {"mode": TRACK, "r": None, "x": None, "still": 0, "k": 0, "dir": 0.0,
                "x0": 0.0, "a": self.amplitude, "pulses": 0}

    def force(self, p_a: float, p_b: float) -> float:
        """Net pneumatic force on the piston less the external load, N (+x)."""
        return (p_a * self.area_a - p_b * self.area_b - self.p_atm * (self.area_a - self.area_b)
                - self.external_force)

    def rate_scale(self, x: float) -> float:
        """Force rate of an opening at ``x`` (m) over that at mid-stroke: the closed
        chambers' stiffness, sum over both of A / V(x) (the same flow changes the
        pressure of a small chamber faster). Near a stroke end it is about twice the
        mid-stroke value (precision rig at 450 of 500 mm: 1.96): pulses sized at
        mid-stroke hopped the piston 5-10 quanta past its target there (NMPC,
        precision profile, hold at 450 mm: 73 command changes in its second half).
        1 without ``stroke``.
        """
        if self.stroke <= 0:
            return 1.0
        L = self.stroke
        xc = min(max(float(x), 0.0), L)
        va, vb = self.volumes

        def stiff(xx):
            return 1.0 / (va + self.area_a * xx) + 1.0 / (vb + self.area_b * (L - xx))

        return stiff(xc) / stiff(0.5 * L)

    def pulse_shape(self, strength: float, x: float | None = None) -> tuple[int, float]:
        """(samples per half, opening of its first sample) of a pulse of ``strength``
        (:meth:`pulse_openings` gives every sample's). ``x`` m: the strength is the
        mid-stroke one, divided by :meth:`rate_scale` there."""
        seq = self.pulse_openings(strength, x)
        return len(seq), seq[0]

    def pulse_openings(self, strength: float, x: float | None = None) -> tuple:
        """Openings of the forward half of a pulse of ``strength``, sample by sample.

        Up to 1: ``width`` samples at that opening. Beyond: ceil(strength x ``width``)
        samples, all fully open but the last, which opens by the rest of the
        opening-time product strength x ``width``. Through lines the force's rise is
        limited by the line's flow (0.45 and 0.67 opening gave the same 31 N bump on
        the precision rig), so the bump's peak is set by how long the valve is open,
        and a pulse stretched at a lower opening moved it by whole samples: 37.9, 49
        and 61 N for 3, 4 and 5 samples (friction 1.5x, F_s = 37.5 N); the bisection
        could not put a bump between them, and jumps of 0.33 and 1.2 mm alternated
        (hold after the 0.3 s step: 52 command changes). With the graded last sample
        the peak rises continuously with the strength from one sample count to the
        next, so the bracket can close on the break-away. ``x`` m: as
        :meth:`pulse_shape`.
        """
        if x is not None:
            strength = strength / self.rate_scale(x)
        if strength <= 1.0:
            return (strength,) * self.width
        total = self.width * strength
        w = int(math.ceil(total - 1e-9))
        return (1.0,) * (w - 1) + (min(1.0, total - (w - 1)),)

    def step(self, s: dict, r: float, y: dict,
             release: bool = False) -> tuple[dict, float | None]:
        """Next state and the valve opening to command, or None: the position law's.

        ``r`` m reference; ``y``: ``x_measured`` (else ``x``) m, ``v`` m/s (estimated),
        ``p_a``, ``p_b`` Pa (the net force the hold keeps at zero); ``release``: the
        reference is about to move (a preview says so): the law's, as for a moving
        reference.
        """
        s = dict(s)
        q = self.quantum
        x_m = float(y.get("x_measured", y["x"]))
        moved_ref = s["r"] is None or abs(r - s["r"]) > 1e-12 or bool(release)
        s["still"] = s["still"] + 1 if s["x"] is not None and abs(x_m - s["x"]) < 0.5 * q else 0
        s["r"], s["x"] = r, x_m
        f = self.force(float(y["p_a"]), float(y["p_b"])) if self.force_rate > 0 else 0.0
        # the force's spread over the dwell (exponential window): steady, or ringing
        g = 2.0 / (self.dwell_samples + 1)
        fm = s.get("fm", f)
        s["fm"] = fm + g * (f - fm)
        s["fv"] = (1.0 - g) * (s.get("fv", 0.0) + g * (f - fm) ** 2)
        if moved_ref:
            if s["mode"] != TRACK:                   # a new hold later: let the bracket widen
                for sign in "+-":
                    s["lo" + sign] = 0.8 * s.get("lo" + sign, 0.0)
                    s["hi" + sign] = 1.25 * s.get("hi" + sign, math.inf)
                    if s.get("short" + sign):
                        s["short" + sign] = (0.8 * s["short" + sign][0], s["short" + sign][1])
            s["mode"], s["pending"], s["tries"], s["hops"], s["best"] = TRACK, False, 0, 0, math.inf
            s["bal"] = 0.0
            return s, None
        e = r - x_m
        in_bin = abs(e) <= 0.5 * q * (1 + 1e-9)
        still = s["still"] >= self.dwell_samples
        if s["mode"] == LOCKED and s["still"] == 0 and not self.aim:
            s["creeps"] = True                       # moved while held: :meth:`_balance`
        if s.get("creeps") and s["mode"] == LOCKED and abs(e) <= q * (1 + 1e-9):
            in_bin = True                            # crept a level out: held (_balance)
        if s["mode"] == PULSE:
            s["k"] += 1
            seq = self.pulse_openings(s["a"], s["x0"])
            w = len(seq)
            if s["k"] <= w:
                return s, s["dir"] * seq[s["k"] - 1]
            if s["k"] <= w + int(math.ceil(self.reverse * w - 1e-9)):
                return s, -s["dir"] * seq[min(s["k"] - w, w) - 1]
            s["mode"], s["still"], s["pending"] = SETTLE, 0, True
            return s, 0.0
        if s["mode"] == TRACK:
            slow = abs(float(y.get("v", 0.0))) <= self.lock_speed
            if not ((in_bin and slow) or (still and abs(e) <= self.range)):
                return s, None
            s["mode"] = SETTLE
        if abs(e) > self.range:                      # carried far off: the law takes over
            if s.get("pending"):
                self._adapt(s, x_m, e)
            s["mode"] = TRACK
            return s, None
        quiet = self.force_rate <= 0 or math.sqrt(s["fv"]) <= self.quiet
        if still and quiet:                          # stuck, the force steady
            if s.get("pending"):
                self._adapt(s, x_m, e)
            s["mode"] = LOCKED if in_bin else READY
            if (s.get("tries", 0) >= self.max_pulses or self.no_better(s, e)
                    or (self.aim and s.get("hops", 0) >= HOPS)):
                s["unloading"] = False                   # given up: held where it is
                return s, 0.0 if self.aim else self._balance(s, x_m)
            if not in_bin and not s.get("unloading") and (self.force_rate <= 0
                                                          or abs(s["fm"]) <= self.force_band):
                d = math.copysign(1.0, e)
                s.update(mode=PULSE, k=1, dir=d, x0=x_m, pulses=s["pulses"] + 1, bal=0.0,
                         tries=s.get("tries", 0) + 1, a=self._strength(s, d, e))
                return s, d * self.pulse_shape(s["a"], x_m)[1]
        if in_bin and still and not self.aim:        # held: balanced, then left
            s["unloading"] = False
            return s, self._balance(s, x_m) if quiet else 0.0
        # aiming: a piston in its bin is unloaded too, beyond F_c / 4 (module docstring)
        u = self._unload(s, s["fm"], x_m, self.ring_band if in_bin and still else 0.0)
        if u and s["mode"] == LOCKED:
            s["bal"] = math.copysign(1.0, u)         # a held piston's: not reversed either
        return s, u

    @property
    def quiet(self) -> float:
        """N, the force's spread over the dwell under which a stuck piston is pulsed:
        ``force_band``, with ``aim`` at least ``ring_band``.

        After a pulse the chambers and lines ring (40 Hz on the precision rig and on
        a foreign rig with one lumped line section and laminar resistance only). The
        ringing is zero-mean: it neither loads the piston nor, below the friction,
        moves it; what it does is add its phase to the next bump's peak. Waiting
        until it had decayed into the sensor's band took 60-80 ms per pulse on the
        precision rig and 300 ms on that foreign rig (4 pulses in a 1.5 s hold: PID
        ended 0.6-0.9 mm off, pulsing, 42-47 command changes). ``ring_band`` F_c / 4
        (:func:`hold_for_plant`): the ring's peak (about sqrt 2 times its spread) and
        the mean (within the band, F_c / 10) stay below half the sliding friction, so
        the ringing alone cannot move a piston the friction holds, and a still piston
        has stopped. The ring's phase scatters the next bump's peak by up to a third
        of F_c; the strength is found on the rig's outcomes, scatter included. Only
        far off (more than ``FAR`` quanta) it was worse: PID, precision profile
        --quick seed 0, holds with a limit cycle 2 -> 4 of 9 (pulses near the target
        waited for the sensor's band). The NMPC keeps the sensor's band: its
        outcomes follow the hold's end state, and it keeps the rules its pass was
        measured with.
        """
        return max(self.force_band, self.ring_band) if self.aim else self.force_band

    def _unload(self, s: dict, f: float, x: float | None = None, floor: float = 0.0) -> float:
        """Opening of the force loop that holds the net force ``f`` (N) at zero, against
        it with a time constant of ``UNLOAD_SAMPLES`` samples (``force_rate`` N/s at
        full opening); with hysteresis: it starts beyond ``force_band`` (and beyond
        ``floor``, N) and stops within half of it (else it would tick at the band's
        edge).

        With ``aim`` it starts only beyond the band plus the force's spread over the
        dwell: while the chambers ring, the mean over the dwell still swings with the
        ringing (an exponential mean over N samples passes about 0.37 of a 40 Hz ring
        at 2 ms, N = 10: about half the ring's spread), and a loop that followed it
        ticked at the minimum opening in time with the ring (PID on the foreign rig
        with one lumped line section: 31-47 command changes per hold, in its second
        half, the piston still). Not for the NMPC: its outcomes on the precision
        profile follow the hold's end state (seed 0 with this rule: sine 0.58 ->
        0.92 mm, overshoot 0.29 -> 0.89 %), and it keeps the rule its pass was
        measured with.
        """
        if self.force_rate <= 0:
            return 0.0
        ring = math.sqrt(s.get("fv", 0.0)) if self.aim else 0.0
        if abs(f) > max(self.force_band + ring, floor):
            s["unloading"] = True
        elif abs(f) <= 0.5 * self.force_band:
            s["unloading"] = False
        if not s.get("unloading"):
            return 0.0
        rate = self.force_rate * (1.0 if x is None else self.rate_scale(x))
        w = f / (UNLOAD_SAMPLES * rate * self.sample_time)
        # at least MIN_OPENING: smaller openings stay inside a valve's residual overlap
        return -math.copysign(min(1.0, max(abs(w), MIN_OPENING)), w)

    def _balance(self, s: dict, x: float) -> float:
        """Opening that takes the net force on a held piston (the dwell's mean, N) to
        zero in one sample, then waits for the mean to show the result; 0 once the
        force is within what the loop can resolve. Without ``aim`` (the NMPC).

        Why zero and not "within ``force_band``". On a closed valve the chambers are a
        gas spring: a piston whose friction does not hold it (a smooth friction law
        without a stiction plateau, or one that creeps) moves until the net force is
        zero, so the net force left on a held piston is where it goes: F / k away (k
        the spring's stiffness) at the speed the friction lets it creep. The force
        loop's band (F_c / 10 on the precision rig's file: 2.2 N on the foreign bore32
        rig) is fine where the friction sticks, not where it creeps: locked with
        1.2-2.2 N, the bore32 piston crept 0.03 mm (most of a 0.049 mm quantum) in
        0.35 s out of its bin, and the hold pulsed it back, each pulse leaving as much
        force again (7 / 17 command changes in the holds' second halves,
        tests/test_foreign_loop.py). Unloading a stuck piston cannot move it on any
        friction law (the force only falls), so where the friction does stick this
        costs a few command changes as the hold settles and nothing else, but those
        changes move the hold's end state, and the NMPC's next move follows it
        (balancing every held piston on the precision rig: seed 0 of the --quick
        profile 4 command changes in a hold's second half, overshoot 0.29 -> 1.33 %).
        So it acts only once the hold has seen a held piston creep (``creeps``: its
        measured level changed while locked with the valve closed, which a friction
        that sticks never lets happen), and that piston, a level out and within a
        quantum of r, stays held rather than pulsed: it crept just past its bin's
        edge, and a pulse's smallest jump (1-4 quanta) cannot land closer (bore32
        rig: targets on a bin's edge, a piston 1 um past it pulsed, 7 command
        changes).

        What the loop can resolve: one sample at ``MIN_OPENING`` changes the force
        by MIN_OPENING x the force rate at ``x`` x T (1.5 N on bore32, 0.6 N on the
        precision rig), so it acts beyond half of that (it would otherwise overshoot
        by more than it removes), and beyond 4 standard deviations of the mean's
        noise (``force_noise`` / sqrt(dwell samples): the exponential mean over N
        samples passes 1/N of white noise's variance). One sample sized on the whole
        force, then two dwells' wait (the exponential mean has then passed 98 % of the
        change: a loop that acts on the lagging mean overshoots, as the unloading loop
        ticks). It never reverses: once the force has passed zero what is left is
        within one sample's change, and correcting that back and forth ticked (precision
        rig, 4 s hold: +-0.35 N, 19 command changes); nor does it reverse the force
        loop's unloading of a held piston (:meth:`step`), for the same reason.
        """
        if self.force_rate <= 0 or not s.get("creeps"):
            return 0.0
        if s.get("wait", 0) > 0:
            s["wait"] -= 1
            return 0.0
        rate = self.force_rate * self.rate_scale(x) * self.sample_time   # N per sample open
        f = s["fm"]
        if (abs(f) <= max(0.5 * MIN_OPENING * rate,
                          4.0 * self.force_noise / math.sqrt(self.dwell_samples))
                or s.get("bal", 0.0) * f > 0.0):        # passed zero: within a step, left
            return 0.0
        s["wait"], s["bal"] = 2 * self.dwell_samples, -math.copysign(1.0, f)
        w = f / rate
        return -math.copysign(min(1.0, max(abs(w), MIN_OPENING)), w)

    def no_better(self, s: dict, e: float) -> bool:
        """True when no pulse can be expected to land closer than ``e`` (m, r - x):
        the rig's typical shortest move towards r, m, is at least twice |e|, so a
        move ends at least m - |e| >= |e| from r. m is the median of the ``JUMPS``
        smallest moves among the last ``SEEN`` pulses that way (kept over all holds):
        the jump's size is the rig's (the excess F_s - F_c over the mass, the lines'
        delay), not in the plant file, and it scatters at one strength (1-2 quanta on
        the precision rig, 2-3 with 1.5x friction). The smallest alone kept a piston
        a quantum off pulsing over its target's bin for the rest of a hold after one
        lucky 1-quantum move (FL, test profile: 17 command changes in the second half;
        1.5x friction, NMPC: 19); counted only at the bracket's lower end, as before,
        a walk's strong pulses set it (a stretched pulse's 9 quanta stopped a PID hold
        0.43 mm off). A single move counts only from a pulse at the threshold (within
        x ``grow`` of the strongest that did not move): a first pulse that already
        moved the piston 3 quanta says nothing of a weaker one (NMPC on the foreign
        LuGre rig, tests/test_foreign_loop.py: held one quantum off, 0.142 mm)."""
        sign = "+" if e > 0 else "-"
        if not self.aim:                             # the smallest jump at the threshold
            m = s.get("min" + sign)
            return m is not None and abs(e) <= 0.5 * m * self.quantum * (1 + 1e-9)
        seen = [(a, j) for a, j in s.get("seen" + sign, ()) if j >= 0.5]
        moves = sorted(round(j) for _, j in seen)[:JUMPS]
        top = s.get("stay" + sign, 0.0) * self.grow * (1 + 1e-9)
        if not moves or (len(moves) == 1 and seen[0][0] > top):
            return False                             # one move, not at the threshold
        m = moves[len(moves) // 2]
        return abs(e) <= 0.5 * m * self.quantum * (1 + 1e-9)

    def _adapt(self, s: dict, x_m: float, e: float) -> None:
        """Strength of the next pulse from the move this one made (quanta towards r).

        A bracket per direction: ``lo`` the strongest pulse that did not move the piston
        a visible quantum, ``hi`` the weakest that carried it past the target's bin;
        the next pulse is their geometric mean (bisection), x ``grow`` above ``lo``
        without a ``hi`` yet, x ``shrink`` below ``hi`` without a ``lo``. A move
        towards the target that stopped short keeps the strength if it covered at
        least half the distance (the next one starts nearer); one that covered less
        counts as too weak (``lo``): kept, a piston stuck 7 quanta short was walked in
        one quantum per pulse, 80 ms apart, into the hold's second half (FL, precision
        profile --quick, hold after the 0.5 s step: 40 command changes there).
        Without ``aim`` such a pulse is kept with its move (``short``) and is the lower
        end only while more is left than it moved (:meth:`_next`).
        """
        key = "lo+" if s["dir"] > 0 else "lo-"
        lo, hi = s.get(key, 0.0), s.get("hi" + key[2], math.inf)
        moved = (x_m - s["x0"]) * s["dir"] / self.quantum
        a = s["a"]
        if self.aim:
            self._hopped(s, moved, abs(e), abs(e + x_m - s["x0"]))
        if moved >= 0.5 and a <= lo * math.sqrt(self.grow):   # a jump at the threshold
            s["min" + key[2]] = min(s.get("min" + key[2], math.inf), round(moved))
        s["seen" + key[2]] = (*s.get("seen" + key[2], ())[1 - SEEN:], (a, max(moved, 0.0)))
        if moved >= 0.5:
            s["mv" + key[2]] = min(s.get("mv" + key[2], math.inf), a)
        if moved < 0.5:
            s["stay" + key[2]] = max(s.get("stay" + key[2], 0.0), a)
            lo = max(lo, a)
        elif e * s["dir"] < -0.5 * self.quantum:          # past the target's bin
            hi = min(hi, a)
        else:                                             # closer: not counted as a try
            s["tries"] = max(0, s.get("tries", 0) - 1)
            if moved < abs(e) / self.quantum:             # not half way: too weak
                if self.aim:
                    lo = max(lo, a)
                elif a >= s.get("short" + key[2], (0.0, 0.0))[0]:
                    s["short" + key[2]] = (a, moved)      # too weak while farther (_next)
        if lo >= hi:                                      # outcomes scatter: reopen
            lo, hi = 0.8 * hi, 1.25 * lo
        s[key], s["hi" + key[2]] = lo, hi
        s["pending"] = False

    def _hopped(self, s: dict, moved: float, after: float, before: float) -> None:
        """Count a pulse that moved the piston (``moved`` quanta) but left it no closer
        to r than the closest it has been in this hold (``after``, ``before``: m from
        r after and before it). :meth:`step` stops pulsing after ``HOPS`` of them.

        Such moves say that at the strengths the bracket allows the outcomes scatter
        wider than the distance left: the piston hops over its target. On a rig
        whose friction creeps (a smooth Stribeck law) one strength either creeps the
        piston a fraction of a quantum or, when its bump's peak meets the ringing's,
        breaks it into a Stribeck slide: FL on the foreign lumped-line rig, one
        strength gave three 0.03 mm creeps, then a 1.2 mm slide past the target, and
        the hold went on drawing. Further pulses are further draws from that scatter,
        each a burst of command activity (a pulse and the force loop after it: about
        ten command changes); no-moves are the bracket's search, not counted. Not
        enough for that FL: seeds 0/1 still end one hold of two with 53/42 command
        changes in its second half (three hops and their settling take most of it).
        """
        best = min(s.get("best", math.inf), before)
        if moved >= 0.5 and after > best - 0.5 * self.quantum:
            s["hops"] = s.get("hops", 0) + 1
        s["best"] = min(best, after)

    def _strength(self, s: dict, direction: float, e: float) -> float:
        """Strength of the next pulse towards r, ``e`` m away: :meth:`_aim`, below the
        weakest pulse that carried the piston past the target's bin (the bracket's
        ``hi``: at or above it, the bracket's bisection, :meth:`_next`).

        The first pulse in a direction nothing is known of (no pulse that way, no
        threshold the other way): ``amplitude`` (from below the break-away: near the
        target an overshoot is a failure of the step, 0.29 mm past a 10 mm step's
        target, 2.9 %, NMPC, precision profile, with the stronger first pulse), or,
        more than ``FAR`` quanta off, ``far_amplitude`` (sized on the lines' flow: a
        move of up to twice the distance still lands closer, and the weak first
        pulses cost 80 ms each: a PID or FL piston 2 mm off walked into the hold's
        second half)."""
        if not self.aim:
            return self._next(s, direction, e)
        sign = "+" if direction > 0 else "-"
        if (self.far_amplitude > 0 and abs(e) > FAR * self.quantum
                and not s.get("seen" + sign) and self._next(s, direction) == self.amplitude):
            return self.far_amplitude            # nothing known of this way yet, far off
        a = self._aim(s, direction, e)
        hi = s.get("hi+" if direction > 0 else "hi-", math.inf)
        return a if a is not None and a < hi else self._next(s, direction)

    def _aim(self, s: dict, direction: float, e: float) -> float | None:
        """Strength whose move should cover the distance ``e`` (m), interpolated on the
        rig's own outcomes in ``direction`` (the last ``SEEN`` pulses' strengths and
        moves): between the strongest pulse that moved the piston at most |e| and the
        weakest that moved it further, log-linear in the strength. None without an
        outcome on both sides (then the bracket: :meth:`_next`).

        A pulse's move grows with its strength (the bump's excess over the static
        friction), by a law that is the rig's (the friction's Stribeck drop, the mass,
        the lines), not the file's: a walk towards a far target grown x ``grow`` per
        pulse overshot (FL, precision test profile, 1.7 mm off: 0.1, 0.2, then 0.9
        and 1.0 mm moves, 0.5 mm past) and came back a quantum per pulse.
        """
        sign = "+" if direction > 0 else "-"
        d = abs(e) / self.quantum
        seen = s.get("seen" + sign, ())
        below = [p for p in seen if p[1] <= d]
        above = [p for p in seen if p[1] > d]
        if below and not above:                  # further than any move so far
            j, a = max((j, a) for a, j in below)
            if j >= 0.5 * d:                     # half way or more: again (two land near)
                return a
            return self._grown(a) if j >= 0.5 else None
        if not below or not above:
            return None
        # the moves nearest the distance on either side (outcomes scatter: the
        # stronger of the two may have moved less, then the strength is between)
        j_lo, a_lo = max((j, a) for a, j in below)
        j_hi, a_hi = min((j, -a) for a, j in above)
        return a_lo * (-a_hi / a_lo) ** ((d - j_lo) / (j_hi - j_lo))

    def _next(self, s: dict, direction: float, e: float | None = None) -> float:
        """Strength of a pulse in ``direction`` from that direction's bracket.

        Without a ``hi`` the strength grows x ``grow``, but beyond full opening by at
        most half a sample of full flow (0.5 / ``width``) per pulse: there each sample
        adds the line-limited force rise to the bump's peak (about 11 N on the
        precision rig, as much as its F_s - F_c), so x 1.5 from just below full
        opening put the first bump that broke the piston away 20 N above its static
        friction and jumped it 1.2 mm (friction 1.5x: 0.31 mm with the cap, the
        hold's steady state 0.38 -> 0.04 mm).

        Without ``aim``, ``e`` (m, r - x): a pulse that moved the piston towards r but
        less than the distance then left (too weak, :meth:`_adapt`) is the lower end
        only while the distance left now is more than it moved; nearer, the same pulse
        carries the piston past r's bin (moves grow with the strength), and a bisection
        above it can only overshoot again. Precision profile --quick, NMPC seed 0,
        hold at 50 mm: 0.287 moved the piston 3 quanta of 6.6 and stayed the lower
        end when the piston was 0.6 quanta off; 0.351 then jumped it 5 quanta past,
        the hold's pulses ran into its second half (10 command changes, 0.216 mm
        peak-to-peak); without it 0.258, and the hold was locked 5 um off at 16.02 s.
        """
        sign = "+" if direction > 0 else "-"
        lo, hi = s.get("lo" + sign, 0.0), s.get("hi" + sign, math.inf)
        short = s.get("short" + sign)
        if (e is not None and short is not None and short[0] < hi
                and short[1] < abs(e) / self.quantum):
            lo = max(lo, short[0])                 # moved less than is left: too weak
        if lo > 0 and math.isfinite(hi):
            return math.sqrt(lo * hi)
        if lo > 0:
            return self._grown(lo)
        if math.isfinite(hi):
            return hi * self.shrink
        if not self.aim:
            return s["a"]
        other = "-" if sign == "+" else "+"
        held, moved = s.get("stay" + other, 0.0), s.get("mv" + other, math.inf)
        if held > 0 and math.isfinite(moved) and held < moved:
            return math.sqrt(held * moved)     # the other way's threshold (friction is even)
        if math.isfinite(moved):
            return max(self.amplitude, moved * self.shrink)   # below its weakest move
        return self.amplitude

    def _grown(self, a: float) -> float:
        """``a`` x ``grow``, beyond full opening at most half a sample more (:meth:`_next`)."""
        up = a * self.grow
        if up > 1.0:
            up = min(up, max(1.0, a) + 0.5 / self.width)
        return min(float(self.max_width) / self.width, up)

    def to_dict(self) -> dict:
        return {"quantum": self.quantum, "sample_time": self.sample_time, "width": self.width,
                "amplitude": self.amplitude, "dwell": self.dwell, "range": self.range,
                "lock_speed": self.lock_speed, "grow": self.grow, "shrink": self.shrink,
                "far_amplitude": self.far_amplitude}

    def summary(self) -> str:
        return (f"held on the target's quantum ({self.quantum * 1e3:.4f} mm) once slow "
                f"(< {self.lock_speed * 1e3:g} mm/s) or still for "
                f"{self.dwell_samples * self.sample_time * 1e3:g} ms within "
                f"{self.range * 1e3:.3g} mm: net force held near 0 (band "
                f"{self.force_band:.2g} N), a piston stuck off the quantum pulsed in "
                f"(2 x {self.width} samples, first opening {self.amplitude:.2g}, strength "
                f"bisected between no move and overshoot)")


def hold_for_plant(plant, sample_time: float, quantum: float, pressure_noise: float = 0.0,
                   line_flow: float | None = None, **kw) -> HoldPositioner:
    """:class:`HoldPositioner` for a plant file (module docstring for the choices).

    * width: the lines' acoustic delay L / c (``lines.length``, c = 343 m/s) in samples,
      rounded up, at least one;
    * amplitude: the opening that changes the net force by F_s (``friction.static``,
      else ``friction.coulomb``, else 2 % of p_s A) in one width: force rate of the
      fully open valve 2 A n r T q / V_m (choked flow q = C p_s rho0 into the
      mid-stroke chamber of volume V_m with its line, and as much out of the other),
      times the width; with ``line_flow`` (kg/s, what the lines pass from p_s into a
      chamber at mid pressure: :func:`~.design.line_flow`) at most that flow's rate
      (the first pulses at the valve's rate raised 11-14 N against the precision
      rig's F_s = 25 N: 3-4 pulses of 80 ms before one moved the piston). The force
      loop keeps the valve's rate (its small openings are the valve's to limit).
    """
    prm = plant.params
    T = float(sample_time)
    length = float(prm.get("lines.length") or 0.0) if "line_dynamics" in set(plant.effects) else 0.0
    width = max(1, int(math.ceil(2.0 * length / SOUND_SPEED / T - 1e-9)))
    A = float(plant.area_a)
    p_s = float(prm["supply.pressure"])
    temp = float(prm["gas.temperature"])
    flow = float(prm["valve.sonic_conductance"]) * p_s * 1.185 * math.sqrt(293.15 / temp)
    v_mid = A * 0.5 * plant.stroke + float(prm["cylinder.dead_volume_a"])
    if length:
        v_mid += length * math.pi / 4 * float(prm["lines.diameter"]) ** 2
    rate = 2.0 * A * float(prm["gas.polytropic_index"]) * 287.0 * temp * flow / v_mid
    fc = float(prm.get("friction.coulomb") or 0.02 * p_s * A)
    fs = float(prm.get("friction.static") or fc)
    # the bump's rise is limited by what the lines pass (0.45 and 0.67 opening gave the
    # same 31 N bump on the precision rig): the first pulse sized on that flow
    amp = min(1.0, max(1e-3, fs / (rate * width * T)))
    if line_flow:
        lim = rate * min(1.0, float(line_flow) / flow)
        kw.setdefault("far_amplitude", min(1.0, max(1e-3, fs / (lim * width * T))))
    noise = math.hypot(A, float(plant.area_b)) * float(pressure_noise)
    kw.setdefault("ring_band", 0.25 * fc)
    kw.setdefault("width", width)
    kw.setdefault("amplitude", amp)
    kw.setdefault("force_rate", rate)
    kw.setdefault("force_band", max(4.0 * noise, 0.1 * fc))
    kw.setdefault("force_noise", noise)
    line = length * math.pi / 4 * float(prm["lines.diameter"]) ** 2 if length else 0.0
    kw.setdefault("stroke", float(plant.stroke))
    kw.setdefault("volumes", (float(prm["cylinder.dead_volume_a"]) + line,
                              float(prm["cylinder.dead_volume_b"]) + line))
    return HoldPositioner(quantum=float(quantum), sample_time=T, area_a=A,
                          area_b=float(plant.area_b),
                          p_atm=float(prm["gas.atmospheric_pressure"]),
                          external_force=float(prm.get("load.external_force", 0.0) or 0.0), **kw)
