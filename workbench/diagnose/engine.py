"""Fast replays of a recording: the plant in a compiled fixed-step loop, parameters as inputs.

A diagnosis simulates the recording many times (every candidate effect, every
iteration of its refit). :class:`Engine` does that cheaply, in one pass over the
samples that can be **re-anchored** on the measurement wherever asked:

* a full replay (never re-anchored), in closed loop (the plant file's P/PD/PID on
  the recorded reference, reading the simulated position as
  :func:`workbench.simulate.closed_loop` does) or in open loop on the recorded command;
* a *segmented* replay: at chosen samples the measured state (position, velocity
  from the differentiated position, chamber pressures when recorded; for the
  controller its previous error) replaces the simulated one, so a model that drifts (open loop) or
  a loop that stops somewhere else (stick-slip, deadband) stays comparable;
* an *observer* pass: re-anchored at every sample, so the states that are not
  measured (spool, line nodes, gas temperatures, supply reservoir) are driven by the
  measured ones; it also returns the model's rates f(z, u) along the measurement,
  from which the equation errors of :mod:`.witness` are formed.

Integration: the 4-stage Rosenbrock method ROS4 of Hairer & Wanner (order 4,
L-stable; :data:`TABLEAU`) by :func:`workbench.integrate.rosenbrock`, with the
unpivoted sparse LU of :mod:`workbench.integrate.linalg` written out in SX, at
one step per sample. A spool lag (linear, driven by the command alone) is stepped
exactly and the rest of the plant along its exact motion (:func:`_split_spool`), at
the steps :func:`stiff_substeps` sizes for the spool candidate's 400 Hz bound. A plant
with line dynamics is stepped by ROS2 (Verwer et al. 1999, order 2) at one step per
sample, as every plant was until session 10 (why: :data:`LINE_TABLEAU`). ROS2's error was the replay
floor the diagnosis' extra effects absorbed (67 um rms in x for the exact model of
the 25 mm rig; :data:`TABLEAU` for the figures now). Positive diagonal entries of the
Jacobian (the negative damping of a Stribeck friction curve) are left out of the
matrix W of the step so that a falling friction curve cannot make the linear solve
singular; ROS4 is not a W-method, so such a step is of lower order (the friction
events, where :data:`EXPLICIT_LIMIT` flags it).

Step refinement: a sample whose input row ``refine`` is 1 is stepped with
:data:`REFINE` times smaller steps. The caller decides those samples once per
predictor (:func:`.predict.settle_refinement`: the recording's friction events and the
steps the nominal replay flags), never per replay: a decision taken from each replay's
own state switches steps between 1 and :data:`REFINE` sub-steps as the parameters move,
so the cost jumps and two replays of nearly equal parameters are stepped differently.
Each replay reports, per sample, whether its plain step could not be accurate (output
row ``inexact``: :data:`LOCAL_TOL`, :data:`EXPLICIT_LIMIT`, a friction switch inside
the step), which is what the decision is made from. The diagnosis leaves it off for
now (:data:`.predict.REFINE_STEPS`, where the measurements are). The per-sample
function (reset +
controller + step) is accumulated over a chunk of
samples (``mapaccum``) and compiled to C once per plant structure and controller
(:func:`workbench.integrate.jit.compiled`, cached by source hash); Python loops over the
chunks. One replay of 24 s at 1 kHz of the 4-state plant takes about 0.02 CPU s.

:meth:`Engine.run_sensitivity` also carries the exact forward sensitivities of the
replay with respect to chosen directions in parameter space (CasADi's forward mode
through the steps, the re-anchoring and the controller), compiled on first use.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass
from typing import Sequence

import casadi as ca
import numpy as np

from ..controllers.pd import clip_and_quantise, pid_law
from ..integrate import ROS2, ROS4, rosenbrock
from ..integrate.exact import lag2_split
from ..integrate.jit import compiled
from ..physics.friction import stribeck_level
from ..plant import Plant
from .candidates import SPOOL_BANDWIDTH_MAX

__all__ = ["Engine", "EngineInputs", "OUTPUTS", "INPUT_ROWS", "stiff_substeps", "line_substeps"]

#: Rows of the engine's output, per sample: simulated x, p_a, p_b (at the sample,
#: after any re-anchoring), command used, and (``rates``) the model rates dv/dt,
#: dp_a/dt, dp_b/dt at that state; the last row is always ``inexact`` (1 where the
#: sample's plain step could not be accurate, see the module docstring).
OUTPUTS = ("x", "p_a", "p_b", "u", "dv", "dp_a", "dp_b")

#: Rows of the per-sample input.
INPUT_ROWS = ("r", "u_rec", "control_instant", "closed_loop", "anchor", "anchor_p",
              "anchor_hidden", "x_m", "v_m", "p_a_m", "p_b_m", "e_prev_m", "use_p_s", "p_s_m",
              "refine")
# use_p_s, p_s_m: where use_p_s is 1 the supply pressure is the recorded p_s_m (Pa);
# refine: 1 where the sample's step is taken with REFINE times smaller steps

#: Samples per compiled chunk.
CHUNK = 1000

#: A sample whose step leaves the physical states, or whose step says it cannot be
#: accurate (:data:`EXPLICIT_LIMIT`, :data:`LOCAL_TOL`, friction events), is redone
#: with this many times smaller steps.
REFINE = 8
#: Largest h x (growth rate) of a mode the step treats explicitly: W leaves out the
#: positive diagonal of the Jacobian (the negative damping of a falling Stribeck curve,
#: up to 0.86 (F_s - F_c) / (m v_s): 480 1/s for 20/28 N, 1.2 kg, v_s = 12 mm/s), so
#: that mode is integrated as by an explicit method, accurate only while h x rate is
#: small (at 0.4 the one-step growth 1 + 0.4 + 0.08 of a second-order update is 0.8 %
#: short of e^0.4; at 0.95, a 2 ms step at that Stribeck peak, 5 %: one such step at a
#: break-away moved the piston 67 um less than the converged solution). A step over
#: the limit is redone with :data:`REFINE` times smaller steps.
EXPLICIT_LIMIT = 0.4
#: The Rosenbrock method of the engine's steps for a plant without lines
#: (those: :data:`LINE_TABLEAU`): ROS4 (Hairer & Wanner, the L-stable choice), order 4, four stages, three evaluations of f, one Jacobian and one LU per
#: step. Measured against CVODES from the true state over 0.2 s windows, 2 ms steps
#: (tests/test_diagnose_rig_engine.py, tests/test_diagnose_lines_replay.py): the
#: 25 mm rig without friction, noise-free recording, 67 um rms (ROS2, order 2, one step
#: per sample; 5.8 um at four) -> 5.4 um; with stick-slip (20 / 28 N, v_s 12 mm/s)
#: 162 -> 23 um; the candidate's 3-segment lines of 3.62 m 50 -> 1.2 um. With the sparse
#: LU (:mod:`workbench.integrate.linalg`) a step of the 4-state plant costs what a ROS2
#: step with a dense symbolic solve did (24 s replay: 0.022 CPU s either), of the
#: 16-state line structure less (0.047 against 0.072 s); a 64-state plant (15-segment
#: lines) is now SX with that LU too, not MX with a dense QR (0.15 against 0.50 CPU s
#: for 6 s of replay).
TABLEAU = ROS4
#: The method for a plant with line dynamics: ROS2 (Verwer et al. 1999, order 2,
#: L-stable, a W-method) at the given steps per sample, as until session 10. ROS4 with
#: :func:`stiff_substeps` replays the diagnosis's 3-segment lines within 1.2 um of
#: CVODES (3.62 m, 3.6 mm; ROS2: 50 um rms) but made the chain's own form show: on the
#: foreign rig's one-section lumped line (tests/test_diagnose_lines.py) the pair lines +
#: spool lag then fitted worse (137 against 115 noise units), the lag made the
#: pressures worse than the lines alone and a 228 Hz valve lag alone was named instead
#: of the lines; ROS2 at 2 ms damps the chain's upper modes (|R| <= 0.39 at h omega >= 2),
#: which are artifacts of lumping a distributed line into 3 segments. Nor did it change
#: the --sets rows offset + lines (named right, a valve lag said beside it) or lines +
#: supply droop (droop only said): what is left there is the 3 segments' form against
#: the recording's 15 (x 112 um, p 267 Pa rms in 0.2 s windows; 6 segments 42 um,
#: 104 Pa). Session 11 tried ROS4 + :func:`stiff_substeps` with 6-segment candidate
#: lines: the same foreign lumped line was again named as a valve lag alone (228 Hz,
#: damping 3: an effective 4 ms first-order lag), for a measured reason: the lag alone
#: predicts x better (308 against 627 noise units over the 0.2 s windows) and the
#: pressures worse (p_a 22.6 / p_b 11.4 against 8.1 / 4.3) than the lines alone (2.14 m,
#: 5.1 mm; true 2.5 m, 4 mm), the pair (141) is refused by the per-signal rule (the lag
#: makes p_a worse than the lines alone: 8.9 against 8.1), and x dominates the cost (its noise is
#: tiny). The accurately stepped chain has the line's transport delay (L/a = 7.3 ms),
#: which the one-section lumped model lacks and a lag without delay imitates in x. Row
#: 14 (offset + lines) stayed named right with the lag said, at 3.4x the time; row 23
#: (lines + supply droop) named the lines only, the droop no longer even said, at 14x
#: the time (1292 against 94 s, loaded). So ROS2
#: for lines until the selection weighs that trade (sets.py). A spool lag
#: was on ROS2 too until session 11: one ROS4 step per 2 ms sample of the spool as an
#: ordinary state (h omega ~5 at the 400 Hz a fit may move to) kept its mode weakly
#: damped in a wrong phase (|R(iy)| 0.52 at y = 4), and the single-effect bench case
#: (concealed dry friction) fitted dry friction + a spurious 222 Hz lag; now the spool
#: is stepped exactly (:func:`_split_spool`) with ROS4 for the rest.
#:
#: Session 13 (h12q) correction: session 12's "6 segments stepped by ROS4" numbers for
#: the foreign lumped line (lines alone, 2.30 m / 5.05 mm; with a 0.15 V offset
#: 2.30 m / 5.02 mm) were measured with **3** segments: the script set
#: ``candidates.LINE_SEGMENTS`` on the *function* ``workbench.diagnose.candidates``
#: (the package's name for it shadows the module), so only LINE_TABLEAU changed, and
#: its output said "chain of 3 segments". ROS4 at :func:`stiff_substeps` with 3
#: segments, re-run, gives the same values to every digit (2.29944 m; set costs 418.0 /
#: 342.2 / 138.5): the gain over ROS2 is the accurate step, not the segment count.
#: Its accuracy (x rms against scipy Radau, rtol 1e-8, over 0.2 s windows from the true
#: state, 3 segments of 5 mm tubing, 2 ms samples; /tmp/h12q/acc.py): 2.3 m ROS2 x1
#: 968 um, ROS4 x1 21, x2 (the count sized) 3.4; 1.0 m ROS2 1387, ROS4 x1 225, x2 18,
#: x4 2.5 (sized 3); 0.3 m ROS2 692, ROS4 x1 13 mm, x4 7.8 (sized 9); 0.12 m ROS2 288,
#: ROS4 x4 317, x16 4.1 (sized 21). A short line needs many steps (a set fitted at
#: 0.12 m ran its engine at 21 per sample). Per step (SX instructions, 3 / 6
#: segments): ROS2 2607 / 3843, ROS4 3644 / 5432. Not adopted for its time:
#: tests/test_diagnose_lines.py + test_diagnose_lines_replay.py 414 -> 441 s wall,
#: 199 -> 226 CPU s (lumped line 196 -> 27 s, lumped line + offset 106 -> 227 s,
#: position only 58 -> 99 s, friction + lines 41 -> 71 s; same loaded machine, one
#: after the other).
LINE_TABLEAU = ROS2
#: |C3| of ROS2's local error C3 h^3 J^2 f (the ``inexact`` flag of a ROS2 step).
ROS2_C3 = 1.0 / 6.0 - (4.0 * (1.0 + 0.5 ** 0.5) ** 3 - (1.0 + 2.0 ** 0.5) * 3.0
                       * (1.0 + 0.5 ** 0.5) ** 2)
#: Largest h x |lambda| of the fastest mode of the linearised plant (:func:`stiff_substeps`)
#: a step may take. ROS4's one-step error on an oscillatory mode e^(i y), |R(iy) - e^(iy)|,
#: is 1.6e-2 at y = 1, 7.3e-2 at 1.5 and 0.18 at 2, and its damping |R(iy)| still 0.84 at
#: 2 and 0.52 at 4: a mode stepped at y of 2-10 keeps a wrong phase instead of being
#: damped away (a 15-segment 3.62 m line: 0.47 mm rms at one step per 2 ms sample, y =
#: 7.3). Measured x rms against CVODES (lines of 0.3-3.62 m, 3-15 segments, from the true
#: state): <= 2.5 um wherever y <= 1.4; 3.5-10 um at y = 2.0-2.7; 25-200 um at 3.6-5.4.
STIFF_LIMIT = 1.5
#: Largest h x 2 pi f of a spool lag of bandwidth f a step may take (its motion is
#: exact, :func:`_split_spool`; the stages see it at 4 instants): measured x <= 3.5 um
#: rms off CVODES at 2.5 (400 Hz, 1 ms steps), 17-42 um at 2.8-5.0 (:func:`stiff_substeps`).
SPOOL_LIMIT = 2.6
#: Local error a step may leave in the position (fraction of the stroke) and in the
#: chamber pressures (fraction of the supply pressure) before it is redone with
#: :data:`REFINE` sub-steps: 1e-5 of the stroke is below the least significant bit of
#: a 16-bit position sensor over the stroke (1.5e-5), 1e-4 of a 6 bar supply (60 Pa) a
#: quarter of a 12-bit pressure sensor's over 0-10 bar (244 Pa).
LOCAL_TOL = (1e-5, 1e-4)
#: Physical bounds of any pressure state: above P_FLOOR x atmospheric, below
#: P_CEIL x supply pressure.
P_FLOOR = 0.02
P_CEIL = 2.0


@dataclass(frozen=True)
class EngineInputs:
    """Per-sample inputs (rows :data:`INPUT_ROWS`, one column per sample), read-only:
    a predictor's inputs are the same for every replay of a fit, so their chunks are
    laid out for the compiled pass once (:meth:`chunks`) and must not go stale."""

    data: np.ndarray

    def __post_init__(self) -> None:
        self.data.flags.writeable = False

    def chunks(self, n: int) -> list[np.ndarray]:
        """The columns in chunks of ``n``, each flattened column by column (a CasADi
        dense matrix's nonzeros, what the compiled pass reads), the last one padded
        with copies of the last column (no anchoring there); made once per ``n``, as a
        fit replays the same inputs some 20 times: converting a 15 x 1000 slice to a
        CasADi matrix at each call cost ~1.5 ms against 2.4-5 ms of compiled pass over
        it (:meth:`Engine._pass`)."""
        cache = self.__dict__.setdefault("_chunks", {})   # frozen: not a field
        if n not in cache:
            data = self.data
            N = data.shape[1]
            pad = (-N) % n
            if pad:
                data = np.concatenate([data, np.repeat(data[:, -1:], pad, axis=1)], axis=1)
                data[INPUT_ROWS.index("anchor"), N:] = 0.0
                data[INPUT_ROWS.index("anchor_hidden"), N:] = 0.0
                data[INPUT_ROWS.index("anchor_p"), N:] = 0.0
            flat = [np.ravel(data[:, i:i + n], order="F") for i in range(0, data.shape[1], n)]
            for f in flat:
                f.flags.writeable = False
            cache[n] = flat
        return cache[n]

    def with_rows(self, **rows: np.ndarray | float) -> "EngineInputs":
        d = self.data.copy()
        for k, v in rows.items():
            d[INPUT_ROWS.index(k)] = v
        return EngineInputs(d)


def _one_step(plant: Plant, h: float, substeps: int = 1, name: str = "engine_step",
              tableau=TABLEAU) -> ca.Function:
    """(z_{k+1}, inexact): one :data:`TABLEAU` step of h/substeps (:func:`_repeated`
    chains them); ``inexact`` is 1 where the step cannot be accurate
    (:data:`EXPLICIT_LIMIT`, and the friction events below), so that
    :func:`_guarded_step` redoes it with smaller steps. Its inputs are (z, u, p, g):
    ``g`` is the supply pressure the guards scale with (:data:`LOCAL_TOL`; see
    :class:`Engine` for why it is an input, not a constant of the code).

    Dry friction is stepped on its own (the Karnopp switch of the plant's ``f`` would
    put the two stages of a step on different branches): during a step the friction
    acts against the direction of motion at its start (or of the driving force, at
    rest); if the velocity crosses zero within the step and the driving force at rest
    is within the static level, the piston stops there (time-stepping stick), and a
    piston at rest stays at rest until the driving force exceeds the static level.

    Where this is only first-order accurate, the step says so (``inexact``): the
    velocity reverses within it (the friction keeps its start direction past the
    reversal), or a stuck piston's driving force exceeds the static level by the step's
    end (the break-away happens within it, not at its start). Both are discontinuities
    of the friction law inside the step, where a one-step method loses its order.
    """
    nx = len(plant.states)
    z = ca.SX.sym("z", nx)
    u = ca.SX.sym("u")
    p = ca.SX.sym("p", len(plant.p0))
    g = ca.SX.sym("g")
    dt = h / substeps
    fric = plant.params.has_effect("dry_friction")
    zs, plant_f, spool_end = _split_spool(plant, z, u, p, dt, exact=bool(tableau.e))
    if fric:
        base = Plant(plant.params.without_effect("dry_friction"))
        idx = [plant.param_index(n) for n in base.param_names]
        ix, iv = plant.state_index("x"), plant.state_index("v")
        pv = {n: p[i] for i, n in enumerate(plant.param_names)}
        fc, fs, vs = pv["friction.coulomb"], pv["friction.static"], pv["friction.stribeck_velocity"]
        m = pv["load.mass"]
        pb = ca.vertcat(*[p[i] for i in idx])
        ev = np.zeros(nx)
        ev[iv] = 1.0
        ev = ca.DM(ev)

        base_f = _split_spool(base, z, u, pb, dt, bool(tableau.e), zs)[1]  # (as the step)

        def drive(zz):
            """Every force on the piston but friction, at rest (N)."""
            z_rest = ca.vertcat(*[0.0 if i == iv else zz[i] for i in range(nx)])
            return m * base_f(z_rest)[iv]

        def rates(zz, direction):
            level = stribeck_level(zz[iv], fc, fs, vs)
            return base_f(zz) - ev * (direction * level / m)
    zk = zs                     # one step, from the symbolic state
    if fric:
        v0 = zk[iv]
        f_drive = drive(zk)
        direction = ca.if_else(v0 != 0, ca.sign(v0), ca.sign(f_drive))
        stuck = ca.logic_and(v0 == 0, ca.fabs(f_drive) <= fs)

        def f_of(zz):
            r_ = rates(zz, direction)
            return r_ - ev * (stuck * r_[iv])      # a stuck piston's velocity stays 0
    else:
        f_of = plant_f
    fz = f_of(zk)
    J = ca.jacobian(fz, zk)
    growth = ca.mmax(ca.diag(J))         # 1/s: fastest growing mode, left explicit in W
    J = J - ca.diag(ca.fmax(ca.diag(J), 0.0))
    # the default solve: the unpivoted LU of I/(h gamma) - W written out in SX, which
    # skips structural zeros (the line chains are banded). Its diagonal is at least
    # 1/(h gamma) (W's is <= 0), and the plant's couplings come in pairs of opposite
    # sign (x' = v against the pressure force, a node's pressure against its segment
    # flow), which add to the pivots rather than take from them
    if tableau.e:
        zn, err = rosenbrock(tableau, f_of, zk, dt, fx=fz, jacobian=J, error=True)
    else:                  # ROS2: its leading local error C3 h^3 J^2 f
        zn = rosenbrock(tableau, f_of, zk, dt, fx=fz, jacobian=J)
        err = ca.mtimes(J, ca.mtimes(J, fz)) * (ROS2_C3 * dt ** 3)
    inexact = ca.logic_or(growth * dt > EXPLICIT_LIMIT, _error_too_large(plant, err, g))
    if fric:
        v1 = zn[iv]
        den = v0 - v1
        frac = ca.fmin(ca.fmax(v0 / ca.if_else(den == 0, 1.0, den), 0.0), 1.0)
        x_stop = ca.if_else(stuck, zk[ix], zk[ix] + 0.5 * dt * v0 * frac)
        z_rest = ca.vertcat(*[x_stop if i == ix else (0.0 if i == iv else zn[i])
                              for i in range(nx)])
        crossed = ca.logic_and(v0 != 0, v0 * v1 <= 0)
        held = ca.fabs(drive(z_rest)) <= fs
        breaks = ca.logic_and(stuck, ca.logic_not(held))
        inexact = ca.logic_or(inexact, ca.logic_or(breaks, ca.logic_and(crossed,
                                                                        ca.logic_not(held))))
        zn = ca.if_else(ca.logic_or(stuck, ca.logic_and(crossed, held)), z_rest, zn)
    zn, inexact = spool_end(zn, inexact)
    return ca.Function(name, [z, u, p, g], [zn, inexact])


def _split_spool(plant: Plant, z, u, p, dt, exact: bool = True, zs=None):
    """(zs, f, end) of :func:`workbench.integrate.exact.lag2_split` for the plant's spool
    lag (``valve_dynamics``), or (z, plant.f, identity) without one or when ``exact`` is
    False. Why the split: a spool of 200-400 Hz is stepped at h omega 3-5 (2 ms samples),
    where an order-4 step keeps its mode weakly damped in a wrong phase
    (:data:`STIFF_LIMIT`) and an order-2 one damps it to the quasi-static limit; its
    exact motion is right at any bandwidth, so the fitted bandwidth is the recording's,
    not the step's. ``exact`` False (ROS2, a W-method, whose non-autonomous form is not
    its autonomous one: 0.6 mm off CVODES at 30 Hz against 0.2 mm with the spool as a
    state): the spool is an ordinary state. ``zs`` given: reuse it (the friction law's
    rates of the same step)."""
    if not (exact and plant.params.has_effect("valve_dynamics")):
        return z, (lambda zz: plant.f(zz, u, p)), (lambda zz, flag: (zz, flag))
    pv = {n: p[i] for i, n in enumerate(plant.param_names)}
    return lag2_split(lambda zz: plant.f(zz, u, p), z, plant.state_index("spool"),
                      plant.state_index("spool_rate"), u, pv["valve.bandwidth"],
                      pv["valve.damping"], dt, zs)


def _error_too_large(plant: Plant, err, p_s):
    """1 where the step's local error estimate in x, p_a or p_b exceeds :data:`LOCAL_TOL`
    (the pressures' as a fraction of ``p_s``, the guards' supply pressure).

    ``err`` is the tableau's embedded estimate (ROS4's order-4 solution minus its
    order-3 one: a bound on the local error of the order-3 solution, so of the step's
    own error with room to spare), or ROS2's leading term C3 h^3 J^2 f.
    """
    prm = plant.params
    tol = {"x": LOCAL_TOL[0] * plant.stroke,
           "p_a": LOCAL_TOL[1] * p_s,
           "p_b": LOCAL_TOL[1] * p_s}
    bad = ca.MX(0) if isinstance(err, ca.MX) else ca.SX(0)
    for name, t in tol.items():
        bad = ca.logic_or(bad, ca.fabs(err[plant.state_index(name)]) > t)
    return bad


def _repeated(one: ca.Function, n: int, nx: int, npar: int) -> ca.Function:
    """``n`` steps of ``one`` (z, u, p, g) -> (z, inexact) in a row (inexact: any of them)."""
    zm, um, pm, gm = ca.MX.sym("z", nx), ca.MX.sym("u"), ca.MX.sym("p", npar), ca.MX.sym("g")
    zk, flag = zm, ca.MX(0)
    for _ in range(n):
        zk, fk = one(zk, um, pm, gm)
        flag = ca.logic_or(flag, fk)
    return ca.Function(f"{one.name()}_x{n}", [zm, um, pm, gm], [zk, flag])


def _implausible(plant: Plant, z0, z1, p_s) -> ca.MX:
    """1 where the step z0 -> z1 left the physically possible states: a non-finite
    value, a pressure below :data:`P_FLOOR` of the atmosphere or above
    :data:`P_CEIL` of the supply, a pressure that moved by more than half the supply
    pressure in one step (the linearly implicit step overshooting the valve law's
    square root), or the piston further than 5 % of the stroke beyond an end stop
    (``p_s``: the guards' supply pressure)."""
    p_atm = plant.params["gas.atmospheric_pressure"]
    bad = ca.MX(0)
    for i in range(z1.shape[0]):            # NaN < inf is false as well
        bad = ca.logic_or(bad, ca.logic_not(ca.fabs(z1[i]) < np.inf))
    for i in plant.states_of_kind("pressure"):
        bad = ca.logic_or(bad, z1[i] < P_FLOOR * p_atm)
        bad = ca.logic_or(bad, z1[i] > P_CEIL * p_s)
        bad = ca.logic_or(bad, ca.fabs(z1[i] - z0[i]) > 0.5 * p_s)
    ix, L = plant.state_index("x"), plant.stroke
    bad = ca.logic_or(bad, ca.logic_or(z1[ix] < -0.05 * L, z1[ix] > 1.05 * L))
    return bad


def _project(plant: Plant, z, p_s):
    """The pressures clipped into [P_FLOOR p_atm, P_CEIL p_s] (last resort after the
    refined step, so that a replay stays bounded rather than overflowing; ``p_s``: the
    guards' supply pressure)."""
    lo, hi = P_FLOOR * plant.params["gas.atmospheric_pressure"], P_CEIL * p_s
    idx = set(plant.states_of_kind("pressure"))
    return ca.vertcat(*[ca.fmin(ca.fmax(z[i], lo), hi) if i in idx else z[i]
                        for i in range(z.shape[0])])


def _guarded_step(plant: Plant, h: float, substeps: int, tableau=TABLEAU) -> ca.Function:
    """(z_{k+1}, inexact) over one sample, given the guards' supply pressure ``g`` and
    ``refine`` (0 or 1) -- inputs (z, u, p, g, refine): ``substeps`` :data:`TABLEAU`
    steps, or steps of h / :data:`REFINE` where ``refine`` is 1 (evaluated only then;
    the plain steps where they are that small already: a friction event or an end stop
    asks for a step of that size, not for REFINE times the sized steps, which would put
    48 unrolled steps of a lined plant into the compiled code).

    Where the step leaves the physically possible states (:func:`_implausible`: at an
    end stop the chamber shrinks to its dead volume and its pressure time constant to
    well under a step), the sample is redone with the small steps as well, and its
    pressures are kept within their physical bounds: a last-resort guard for a replay
    that would otherwise diverge, not an accuracy control. A sample that starts or ends
    on an end stop is redone with the small steps too: the stop's contact mode
    (:data:`workbench.physics.piston.STOP_FREQUENCY`, with the payload) is far faster
    than a sample and its force is not smooth at contact, where the order-4 step of
    :data:`TABLEAU` is not accurate (a 2 ms ROS4 step into the stop and back missed x by
    2.3 mm against CVODES, with the 8 sub-steps 0.03 mm:
    ``tests/test_diagnose_failsafe.py``). Only replays that reach a stop pay for it.

    ``inexact`` is 1 where the plain step says it cannot be accurate (a friction event
    inside it, a growing mode too fast for its explicit treatment, a leading local
    error above :data:`LOCAL_TOL`: :func:`_one_step`). It does **not** decide the
    refinement of this replay: the caller decides ``refine`` for every sample once
    (:func:`.predict.settle_refinement`), so that within a fit the replay is a smooth
    function of the parameters (a decision taken sample by sample from the parameters'
    own replay switches steps between 1 and 8 sub-steps as the parameters move, and the
    cost jumps: the refits then fitted the static friction 7.7 % low)."""
    nx, npar = len(plant.states), len(plant.p0)
    coarse_one = _one_step(plant, h, substeps, "step_coarse", tableau)
    n_fine = max(REFINE, substeps)     # steps of at most h/REFINE, never coarser than the plain
    fine_one = _one_step(plant, h, n_fine, "step_fine", tableau)
    coarse = coarse_one if substeps == 1 else _repeated(coarse_one, substeps, nx, npar)
    fine = _repeated(fine_one, n_fine, nx, npar)
    zm, um, pm, gm = ca.MX.sym("z", nx), ca.MX.sym("u"), ca.MX.sym("p", npar), ca.MX.sym("g")
    refine = ca.MX.sym("refine")
    zc, inexact = coarse(zm, um, pm, gm)
    zf = fine(zm, um, pm, gm)[0]
    bad = _implausible(plant, zm, zc, gm)
    ix, L = plant.state_index("x"), plant.stroke     # on an end stop (either end of the step)
    contact = ca.logic_or(ca.logic_or(zm[ix] < 0, zm[ix] > L), ca.logic_or(zc[ix] < 0, zc[ix] > L))
    zn = ca.if_else(ca.logic_or(ca.logic_or(refine, bad), contact),
                    ca.if_else(bad, _project(plant, zf, gm), zf, True), zc, True)
    return ca.Function("engine_sample", [zm, um, pm, gm, refine], [zn, inexact])


def stiff_substeps(plant: Plant, h: float) -> int:
    """Steps per engine sample of ``h`` s for the plant's lines and spool lag: the more
    of :func:`line_substeps` (h/n x |lambda| <= :data:`STIFF_LIMIT` for the lines'
    fastest mode) and, with a spool lag, h/n x 2 pi f <= :data:`SPOOL_LIMIT` for the
    larger of its bandwidth f and the spool candidate's bound
    (:data:`.candidates.SPOOL_BANDWIDTH_MAX`, 400 Hz: a fit may move there from any
    start, and the count is fixed per engine).

    The spool itself is stepped exactly (:func:`_split_spool`); what the steps must
    resolve is its motion as the valve sees it at the stages. Measured (x rms against
    CVODES over 0.2 s from the true state, a 2 ms sample at a full valve opening, 25 mm
    rig; the same without a spool: 2.0 um): at one step per sample 5.1 / 3.5 / 17 /
    42 um for 30 / 100 / 222 / 400 Hz (h omega 0.4-5.0), at two 1.3 / 0.8 / 1.3 / 3.5 um
    (ROS2 at one step, the method until session 11: 150-590 um).

    Parameters
    ----------
    plant : the plant (its parameter values set the rates).
    h : engine sample period, s.
    """
    n = line_substeps(plant, h)
    if plant.params.has_effect("valve_dynamics"):
        f = max(float(plant.params["valve.bandwidth"]), SPOOL_BANDWIDTH_MAX)
        n = max(n, int(math.ceil(h * 2.0 * math.pi * f / SPOOL_LIMIT - 1e-9)))
    return max(n, 1)


def line_substeps(plant: Plant, h: float) -> int:
    """Steps per engine sample of ``h`` s so that h/n x |lambda| <= :data:`STIFF_LIMIT`
    for the fastest mode lambda of the plant's lines (1 without lines).

    |lambda| is the spectral radius of the line states' own block of df/dz
    (the chambers and the piston held) at mid-stroke with the chambers at rest, the
    valve closed or fully open either way: the fastest acoustic mode of a segment
    (about 2 a / segment length, a the speed of sound), the filling of a line's first
    node through the open valve (its volume against the valve's conductance).
    These are the oscillatory and valve-driven modes a step must resolve
    (a step at h |lambda| of 2-10 keeps their phase wrong rather than damping them:
    :data:`STIFF_LIMIT`); the chambers' own stiff modes (a leak's steep slope at equal
    pressures, a chamber at its dead volume) are real and damped, which the L-stable
    step handles at one step per sample. The rates are the plant's values, not the
    recording's: the count is fixed for an engine, so every replay of a fit is stepped
    alike (a fit that moves far from its start, e.g. to a much shorter line, is stepped
    as its start was). Measured: 1 for the plant without lines or with 3.62 m of
    3.6 mm tubing in 3 segments (550 1/s), 3 for 1 m in 3 segments
    (1990 1/s), 5-8 for the plant files' default of a segment per 0.25 m.

    Parameters
    ----------
    plant : the plant (its parameter values set the rates).
    h : engine sample period, s.
    """
    idx = [i for i, sig in enumerate(plant.states) if sig.part == "line"]
    if not idx:
        return 1
    nx = len(plant.states)
    z, u = ca.MX.sym("z", nx), ca.MX.sym("u")
    jac = ca.Function("stiff_jacobian", [z, u], [ca.jacobian(plant.f(z, u, plant.p0), z)])
    prm = plant.params
    z0 = plant.initial_state(0.5 * plant.stroke)
    rho = 0.0
    for cmd in (prm["valve.command_min"], prm["valve.command_center"], prm["valve.command_max"]):
        J = np.asarray(jac(z0, cmd), dtype=float)[np.ix_(idx, idx)]
        if np.all(np.isfinite(J)):
            rho = max(rho, float(np.max(np.abs(np.linalg.eigvals(J)))))
    return max(int(math.ceil(h * rho / STIFF_LIMIT - 1e-9)), 1)


def _hidden_rest(plant: Plant, z, u_prev, p):
    """State with the unmeasured states (those effects add) at their quiescent values
    given the basic ones in ``z`` and the command ``u_prev`` (expressions);
    :meth:`workbench.plant.Plant.rest_state`."""
    return plant.rest_state(z, u_prev, p)


class Engine:
    """Compiled replays of one plant structure (parameters are inputs).

    Parameters
    ----------
    plant : Plant
        Structure (effects, states); parameter values are passed to :meth:`run`.
    sample_time : engine sample period, s.
    controller : the plant file's PID (closed loop), or None (open loop only).
    substeps : least number of steps per sample; with ROS4, more when the plant's
        fastest mode asks for them (:func:`stiff_substeps`: long lines, a fast spool).
    tableau : the Rosenbrock method (default :data:`TABLEAU`, :data:`LINE_TABLEAU` for
        a plant with line dynamics).
    jit : compile to C when a compiler is present.
    rates : also return the model's rates (observer passes).

    The guards of a step (:data:`LOCAL_TOL`, :func:`_implausible`, :func:`_project`)
    scale with the supply pressure of ``plant`` as constructed, which is not the
    parameter passed to :meth:`run`. That value is an input of the compiled code
    (:attr:`guard`, passed with every call), not a literal in it: as a literal it made
    every start value of a fitted supply pressure (a ``parameter_error`` correction, a
    pair started from a single's values, a full refit from its screening values) a new
    C source, compiled again (a few s of gcc each; measured, the ``supply_droop``
    concealed case: 6 of its 26 compilations, and in a later diagnosis none of them came
    from the cache, the fitted value being new). The numbers are the same: the
    guards' thresholds are the same products of two doubles, taken in C instead of in
    Python.
    """

    def __init__(self, plant: Plant, sample_time: float, controller=None, substeps: int = 1,
                 jit: bool = True, chunk: int = CHUNK, rates: bool = False,
                 tableau=None) -> None:
        self.plant = plant
        self.h = float(sample_time)
        self.controller = controller
        self.chunk = int(chunk)
        nx = len(plant.states)
        npar = len(plant.p0)
        if tableau is None:
            fast = any(sig.part == "line" for sig in plant.states)
            tableau = LINE_TABLEAU if fast else TABLEAU
        if tableau.e:            # a method that resolves the modes it steps: size its steps
            substeps = max(int(substeps), stiff_substeps(plant, self.h))
        self.substeps, self.tableau = int(substeps), tableau
        step = _guarded_step(plant, self.h, substeps, tableau)
        zs = ca.MX.sym("z", nx)
        cs = ca.MX.sym("c", 3)          # previous error, integral, held command
        inp = ca.MX.sym("in", len(INPUT_ROWS))
        ps = ca.MX.sym("p", npar)
        gs = ca.MX.sym("g")             # the guards' supply pressure (see above)
        self.guard = float(plant.params["supply.pressure"])
        row = {n: inp[i] for i, n in enumerate(INPUT_ROWS)}
        p_k = ps                        # the parameters at this sample (a recorded p_s)
        if "supply.pressure" in plant.param_names:
            i_s = plant.param_index("supply.pressure")
            p_k = ca.vertcat(ps[:i_s], ca.if_else(row["use_p_s"], row["p_s_m"], ps[i_s]),
                             ps[i_s + 1:])
        ix, iv = plant.state_index("x"), plant.state_index("v")
        ia, ib = plant.state_index("p_a"), plant.state_index("p_b")
        # re-anchoring on the measurement
        measured = {ix: row["x_m"], iv: row["v_m"],
                    ia: ca.if_else(row["anchor_p"], row["p_a_m"], zs[ia]),
                    ib: ca.if_else(row["anchor_p"], row["p_b_m"], zs[ib])}
        meas = ca.vertcat(*[measured.get(i, zs[i]) for i in range(nx)])
        z_anch = ca.if_else(row["anchor"], meas, zs)
        z_anch = ca.if_else(row["anchor_hidden"], _hidden_rest(plant, z_anch, row["u_rec"], p_k),
                            z_anch)
        c_prev = ca.if_else(row["anchor"], row["e_prev_m"], cs[0])
        prm = plant.params
        lo, hi = prm["valve.command_min"], prm["valve.command_max"]
        if controller is not None:
            c = controller
            xm = z_anch[ix]
            res = prm.get("controller.position_resolution")
            if res:
                xm = ca.floor(xm / res + 0.5) * res
            e = row["r"] - xm
            u_pid, integ = pid_law(e, c_prev, cs[1], c.kp, c.kd, c.ki, c.sample_time,
                                   c.u_center, c.u_min, c.u_max)
            ucmd = clip_and_quantise(u_pid, lo, hi, prm.get("controller.command_resolution"))
            isc = row["control_instant"]
            u_held = ca.if_else(isc, ucmd, cs[2])
            e_prev = ca.if_else(isc, e, c_prev)
            integ = ca.if_else(isc, integ, cs[1])
            uu = ca.if_else(row["closed_loop"], u_held, row["u_rec"])
        else:
            u_held, e_prev, integ, uu = cs[2], c_prev, cs[1], row["u_rec"]
        zn, inexact = step(z_anch, uu, p_k, gs, row["refine"])
        outs = [z_anch[ix], z_anch[ia], z_anch[ib], uu]
        if rates:
            fz = plant.f(z_anch, uu, p_k)
            outs += [fz[iv], fz[ia], fz[ib]]
        outs.append(inexact)
        self.rows = (OUTPUTS if rates else OUTPUTS[:4]) + ("inexact",)
        self._sym = (zs, cs, inp, ps, gs, zn, ca.vertcat(e_prev, integ, u_held),
                     ca.vertcat(*outs))
        self._tag = hashlib.sha1(repr((
            plant.state_names, plant.param_names, self.h, substeps, tableau.name, self.chunk, rates,
            plant.friction, None if controller is None else
            (controller.kp, controller.kd, controller.ki, controller.sample_time,
             controller.u_center, lo, hi, prm.get("controller.position_resolution"),
             prm.get("controller.command_resolution")))).encode()).hexdigest()[:12]
        self.jit = jit
        self._fun = self._accumulated(0)
        self._sens: dict[int, ca.Function] = {}
        self._buffers: dict[tuple[int, int], tuple] = {}

    def _accumulated(self, k: int) -> ca.Function:
        """The per-sample function accumulated over a chunk, compiled; with ``k`` > 0 it
        also carries the forward sensitivities of the state, the controller memory and
        the outputs x, p_a, p_b along ``k`` directions in parameter space (seed ``D``,
        npar x k): exact derivatives of the discrete replay (the steps, re-anchoring,
        controller), by CasADi's forward mode."""
        zs, cs, inp, ps, gs, zn, cn, y = self._sym
        nx, npar, n = zs.shape[0], ps.shape[0], self.chunk
        g = ca.MX.sym("g")
        if k == 0:
            G = ca.Function("sample", [zs, cs, inp, ps, gs], [zn, cn, y])
            acc = G.mapaccum("acc", n, [0, 1], [0, 1])
            Z0, C0 = ca.MX.sym("Z0", nx), ca.MX.sym("C0", 3)
            In, P = ca.MX.sym("I", len(INPUT_ROWS), n), ca.MX.sym("P", npar)
            zf, cf, Y = acc(Z0, C0, In, ca.repmat(P, 1, n), ca.repmat(g, 1, n))
            f = ca.Function(f"diag_{self._tag}", [Z0, C0, In, P, g],
                            [zf[:, -1], cf[:, -1], Y])
            return compiled(f, flags=("-O2",)) if self.jit else f
        Sz, Sc, D = ca.MX.sym("Sz", nx, k), ca.MX.sym("Sc", 3, k), ca.MX.sym("D", npar, k)
        arg, seed = ca.vertcat(zs, cs, ps), ca.vertcat(Sz, Sc, D)
        Szn, Scn, Sy = (ca.jtimes(e, arg, seed) for e in (zn, cn, y[:3]))
        G = ca.Function("sample_s", [zs, cs, inp, ps, gs, Sz, Sc, D],
                        [zn, cn, y, ca.reshape(Szn, nx * k, 1), ca.reshape(Scn, 3 * k, 1),
                         ca.reshape(Sy, 3 * k, 1)])
        Sz1, Sc1 = ca.MX.sym("Sz1", nx * k), ca.MX.sym("Sc1", 3 * k)
        z1, c1, i1, p1, D1 = (ca.MX.sym("z1", nx), ca.MX.sym("c1", 3),
                              ca.MX.sym("i1", len(INPUT_ROWS)), ca.MX.sym("p1", npar),
                              ca.MX.sym("D1", npar * k))
        g1 = ca.MX.sym("g1")
        o = G(z1, c1, i1, p1, g1, ca.reshape(Sz1, nx, k), ca.reshape(Sc1, 3, k),
              ca.reshape(D1, npar, k))
        H = ca.Function("sample_sv", [ca.vertcat(z1, Sz1), ca.vertcat(c1, Sc1), i1,
                                      ca.vertcat(p1, D1), g1],
                        [ca.vertcat(o[0], o[3]), ca.vertcat(o[1], o[4]), ca.vertcat(o[2], o[5])])
        acc = H.mapaccum("acc", n, [0, 1], [0, 1])
        Z0, C0 = ca.MX.sym("Z0", nx * (k + 1)), ca.MX.sym("C0", 3 * (k + 1))
        In, P = ca.MX.sym("I", len(INPUT_ROWS), n), ca.MX.sym("P", npar * (k + 1))
        zf, cf, Y = acc(Z0, C0, In, ca.repmat(P, 1, n), ca.repmat(g, 1, n))
        f = ca.Function(f"diags{k}_{self._tag}", [Z0, C0, In, P, g],
                        [zf[:, -1], cf[:, -1], Y])
        return compiled(f, flags=("-O2",)) if self.jit else f

    def run(self, z0: np.ndarray, inputs: EngineInputs, p: Sequence[float],
            c0: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
        """Outputs (:data:`OUTPUTS` rows, one column per sample) of one pass.

        Parameters
        ----------
        z0 : initial state (the first sample is usually an anchor anyway).
        inputs : per-sample inputs.
        p : parameter vector of the plant structure.
        c0 : initial controller memory.
        """
        return self._pass(self._fun, np.asarray(z0, dtype=float), inputs,
                          np.asarray(p, dtype=float), np.asarray(c0, dtype=float), 0)[0]

    def run_sensitivity(self, z0: np.ndarray, inputs: EngineInputs, p: Sequence[float],
                        directions: np.ndarray, c0: Sequence[float] = (0.0, 0.0, 0.0)
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Outputs of one pass (as :meth:`run`) and the exact derivatives of the rows x,
        p_a, p_b along ``directions`` (npar x k: column j is dp/dz_j).

        The initial state and controller memory do not depend on the parameters (the
        first sample of a predictor is an anchor). Returns (outputs, dY) with dY of
        shape (3, k, samples): d(x, p_a, p_b)/dz_j at each sample.
        """
        D = np.asarray(directions, dtype=float)
        k = D.shape[1]
        if k not in self._sens:
            self._sens[k] = self._accumulated(k)
        z = np.concatenate([np.asarray(z0, dtype=float), np.zeros(len(z0) * k)])
        c = np.concatenate([np.asarray(c0, dtype=float), np.zeros(3 * k)])
        pd = np.concatenate([np.asarray(p, dtype=float), D.ravel(order="F")])
        out, sy = self._pass(self._sens[k], z, inputs, pd, c, k)
        return out, sy.reshape(3, k, -1, order="F")

    def _pass(self, fun: ca.Function, z: np.ndarray, inputs: EngineInputs, p: np.ndarray,
              c: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray | None]:
        """One pass of ``fun`` (plain, or with ``k`` sensitivity directions) over the
        samples, chunk by chunk; stops (NaN from there on) when the state is not finite."""
        N = inputs.data.shape[1]
        n = self.chunk
        chunks = inputs.chunks(n)
        fb, evaluate, (zb, cb, pb, gb, zo, co, yo) = self._buffer(fun)
        for buf, val in ((zb, z), (cb, c), (pb, p)):
            if val.size != buf.size:
                raise ValueError(f"{fun.name()}: an input of {val.size} values, {buf.size} expected")
            buf[:] = val
        gb[0] = self.guard
        nr = len(self.rows)
        Y = yo.reshape(-1, n, order="F")        # a view of the output buffer
        out = np.full((nr, n * len(chunks)), np.nan)
        sens = np.full((3 * k, n * len(chunks)), np.nan) if k else None
        for i, chunk in zip(range(0, n * len(chunks), n), chunks):
            fb.set_arg(2, memoryview(chunk))
            evaluate()
            if fb.ret() != 0:
                raise RuntimeError(f"{fun.name()}: evaluation failed (return code {fb.ret()})")
            out[:, i:i + n] = Y[:nr]
            if k:
                sens[:, i:i + n] = Y[nr:]
            zb[:], cb[:] = zo, co
            if not np.all(np.isfinite(zb)):
                break
        return out[:, :N], (sens[:, :N] if k else None)

    def _buffer(self, fun: ca.Function) -> tuple:
        """``fun`` evaluated in place (:meth:`casadi.Function.buffer`) on buffers of its
        own, made once per function and process: (buffer, evaluate, (z, c, p, g, z out,
        c out, outputs)); the input chunk is bound at each call. Why: a call with numpy
        arguments converts each to a CasADi matrix and each result back (~1 ms of
        2.6-5.6 ms per chunk of 1000 samples, the compiled pass itself the rest); the
        numbers are the same (the same compiled code on the same doubles)."""
        key = (os.getpid(), id(fun))
        if key not in self._buffers:
            fb, evaluate = fun.buffer()
            bufs = [np.zeros(fun.nnz_in(i)) for i in (0, 1, 3, 4)] + \
                [np.zeros(fun.nnz_out(i)) for i in range(3)]
            for i, b in zip((0, 1, 3, 4), bufs[:4]):
                fb.set_arg(i, memoryview(b))
            for i, b in enumerate(bufs[4:]):
                fb.set_res(i, memoryview(b))
            self._buffers[key] = (fb, evaluate, tuple(bufs), fun)   # fun kept alive
        return self._buffers[key][:3]
