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

Integration: the 2-stage Rosenbrock method ROS2 (Verwer et al. 1999), L-stable,
one step per recorded sample (or ``substeps``), by :func:`workbench.integrate.rosenbrock`
with :data:`workbench.integrate.ROS2`. ROS2 keeps its order 2 for any
approximation W of the Jacobian, which is used here: positive diagonal entries of
the Jacobian (the negative damping of a Stribeck friction curve) are left out of W
so that a falling friction curve cannot make the linear solve singular.

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
chunks. One replay of 24 s at 1 kHz of the 4-state plant takes about 0.1 s.

:meth:`Engine.run_sensitivity` also carries the exact forward sensitivities of the
replay with respect to chosen directions in parameter space (CasADi's forward mode
through the steps, the re-anchoring and the controller), compiled on first use.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Sequence

import casadi as ca
import numpy as np

from ..controllers.pd import clip_and_quantise, pid_law
from ..integrate import ROS2, rosenbrock
from ..integrate.jit import compiled
from ..physics.friction import stribeck_level
from ..plant import Plant

__all__ = ["Engine", "EngineInputs", "OUTPUTS", "INPUT_ROWS"]

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

#: More states than this: numeric linear solves (a symbolic inverse grows too big).
_SX_LIMIT = 16

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
#: |C3| of ROS2's local error C3 h^3 J^2 f (:func:`_error_too_large`).
ROS2_C3 = 1.0 / 6.0 - (4.0 * (1.0 + 0.5 ** 0.5) ** 3 - (1.0 + 2.0 ** 0.5) * 3.0
                       * (1.0 + 0.5 ** 0.5) ** 2)
#: Local error a step may leave in the position (fraction of the stroke) and in the
#: chamber pressures (fraction of the supply pressure) before it is redone with
#: :data:`REFINE` sub-steps: 1e-5 of the stroke is below the least significant bit of
#: a 16-bit position sensor over the stroke (1.5e-5), 1e-4 of a 6 bar supply (60 Pa) a
#: quarter of a 12-bit pressure sensor's over 0-10 bar (244 Pa).
LOCAL_TOL = (1e-5, 1e-4)
#: ROS2 steps per sample are multiplied by this for a plant with line dynamics. The
#: lumped line's segment modes are far faster than a 2 ms step: in a 0.2 s window
#: that starts a reference step, from the true state, the candidate structure (3
#: segments per line) missed CVODES by 0.61 mm rms at one step per sample (3 m of 4 mm
#: tubing; 0.16 mm for 4 m of 3 mm), 0.17 / 0.04 mm at two and 0.037 / 0.030 mm at four
#: (tests/test_diagnose_lines_replay.py): the replay mismatch that the set search
#: explained with a spurious ~40 Hz valve lag (offset + lines). Four steps cost: a 24 s
#: replay of that structure 0.23 CPU s instead of 0.072, and the single-effect bench
#: (``workbench bench diagnose``) 32.9 CPU s instead of 24.2-24.9 (loaded machine),
#: which would take its wall time past its 15 s target; tests/test_diagnose_lines.py and
#: the line case of tests/test_diagnose.py pass with either. With four, the set case
#: valve_offset + line_dynamics of designs/diagnose_concealed.py (--sets, seed 2026) still
#: named a spurious valve lag (66 Hz; length 2.70 m vs 3.62): the rest of its mismatch
#: is the line model's 3 segments against the recording's 15 (0.20 against 0.11 mm rms
#: for 3 m of 4 mm tubing) and the hidden states started at rest in the first window.
#: So one step (no change) until a fix of those shows a gain worth the time.
LINE_SUBSTEPS = 1
#: Physical bounds of any pressure state: above P_FLOOR x atmospheric, below
#: P_CEIL x supply pressure.
P_FLOOR = 0.02
P_CEIL = 2.0


@dataclass(frozen=True)
class EngineInputs:
    """Per-sample inputs (rows :data:`INPUT_ROWS`, one column per sample)."""

    data: np.ndarray

    def with_rows(self, **rows: np.ndarray | float) -> "EngineInputs":
        d = self.data.copy()
        for k, v in rows.items():
            d[INPUT_ROWS.index(k)] = v
        return EngineInputs(d)


def _ros2_step(plant: Plant, h: float, substeps: int = 1, name: str = "ros2_step"
               ) -> ca.Function:
    """(z_{k+1}, inexact) = ROS2(z_k, u, p): one step of h/substeps (:func:`_repeated`
    chains them); ``inexact`` is 1 where the step cannot be accurate
    (:data:`EXPLICIT_LIMIT`, and the friction events below), so that
    :func:`_guarded_step` redoes it with smaller steps.

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
    sx = nx <= _SX_LIMIT
    Sym = ca.SX if sx else ca.MX
    z = Sym.sym("z", nx)
    u = Sym.sym("u")
    p = Sym.sym("p", len(plant.p0))
    dt = h / substeps
    fric = plant.params.has_effect("dry_friction")
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

        def drive(zz):
            """Every force on the piston but friction, at rest (N)."""
            z_rest = ca.vertcat(*[0.0 if i == iv else zz[i] for i in range(nx)])
            return m * base.f(z_rest, u, pb)[iv]

        def rates(zz, direction):
            level = stribeck_level(zz[iv], fc, fs, vs)
            return base.f(zz, u, pb) - ev * (direction * level / m)
    zk = z                      # one step, from the symbolic state
    if fric:
        v0 = zk[iv]
        f_drive = drive(zk)
        direction = ca.if_else(v0 != 0, ca.sign(v0), ca.sign(f_drive))
        stuck = ca.logic_and(v0 == 0, ca.fabs(f_drive) <= fs)

        def f_of(zz):
            r_ = rates(zz, direction)
            return r_ - ev * (stuck * r_[iv])      # a stuck piston's velocity stays 0
    else:
        def f_of(zz):
            return plant.f(zz, u, p)
    fz = f_of(zk)
    J = ca.jacobian(fz, zk)
    growth = ca.mmax(ca.diag(J))         # 1/s: fastest growing mode, left explicit in W
    inexact = ca.logic_or(growth * dt > EXPLICIT_LIMIT,
                          _error_too_large(plant, J, fz, dt))
    J = J - ca.diag(ca.fmax(ca.diag(J), 0.0))

    def solve(M, rhs):
        return ca.solve(M, rhs) if sx else ca.solve(M, rhs, "qr")
    zn = rosenbrock(ROS2, f_of, zk, dt, fx=fz, jacobian=J, solve=solve)
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
    return ca.Function(name, [z, u, p], [zn, inexact])


def _error_too_large(plant: Plant, J, fz, dt: float):
    """1 where the step's leading local error in x, p_a or p_b exceeds :data:`LOCAL_TOL`.

    ROS2's local error is C3 h^3 J^2 f + O(h^4) on the linear part of the dynamics
    (its stability function R(z) = (1 - (2 gamma - 1) z) / (1 - gamma z)^2 has the z^3
    coefficient -1.207 where e^z has 1/6: C3 = -1.374); the position's is all of it,
    since x' = v is linear (its h^3 term is the jerk, (J f)_v). The jerk is large where
    the valve opens on the chambers (pressure rates of 1e7 Pa/s at a command step):
    one 2 ms step then moves the piston 52 um backwards relative to the converged
    solution (estimated 86 um), against 1.1 um with eight sub-steps.
    """
    prm = plant.params
    tol = {"x": LOCAL_TOL[0] * plant.stroke,
           "p_a": LOCAL_TOL[1] * prm["supply.pressure"],
           "p_b": LOCAL_TOL[1] * prm["supply.pressure"]}
    e = ca.mtimes(J, ca.mtimes(J, fz)) * (ROS2_C3 * dt ** 3)
    bad = ca.MX(0) if isinstance(fz, ca.MX) else ca.SX(0)
    for name, t in tol.items():
        bad = ca.logic_or(bad, ca.fabs(e[plant.state_index(name)]) > t)
    return bad


def _repeated(one: ca.Function, n: int, nx: int, npar: int) -> ca.Function:
    """``n`` steps of ``one`` (z, u, p) -> (z, inexact) in a row (inexact: any of them)."""
    zm, um, pm = ca.MX.sym("z", nx), ca.MX.sym("u"), ca.MX.sym("p", npar)
    zk, flag = zm, ca.MX(0)
    for _ in range(n):
        zk, fk = one(zk, um, pm)
        flag = ca.logic_or(flag, fk)
    return ca.Function(f"{one.name()}_x{n}", [zm, um, pm], [zk, flag])


def _implausible(plant: Plant, z0, z1) -> ca.MX:
    """1 where the step z0 -> z1 left the physically possible states: a non-finite
    value, a pressure below :data:`P_FLOOR` of the atmosphere or above
    :data:`P_CEIL` of the supply, a pressure that moved by more than half the supply
    pressure in one step (the linearly implicit step overshooting the valve law's
    square root), or the piston further than 5 % of the stroke beyond an end stop."""
    prm = plant.params
    p_atm, p_s = prm["gas.atmospheric_pressure"], prm["supply.pressure"]
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


def _project(plant: Plant, z):
    """The pressures clipped into [P_FLOOR p_atm, P_CEIL p_s] (last resort after the
    refined step, so that a replay stays bounded rather than overflowing)."""
    prm = plant.params
    lo, hi = P_FLOOR * prm["gas.atmospheric_pressure"], P_CEIL * prm["supply.pressure"]
    idx = set(plant.states_of_kind("pressure"))
    return ca.vertcat(*[ca.fmin(ca.fmax(z[i], lo), hi) if i in idx else z[i]
                        for i in range(z.shape[0])])


def _guarded_step(plant: Plant, h: float, substeps: int) -> ca.Function:
    """(z_{k+1}, inexact) over one sample, given ``refine`` (0 or 1): ``substeps`` ROS2
    steps, or :data:`REFINE` times as many where ``refine`` is 1 (evaluated only then).

    Where the step leaves the physically possible states (:func:`_implausible`: at an
    end stop the chamber shrinks to its dead volume and its pressure time constant to
    well under a step), the sample is redone with the small steps as well, and its
    pressures are kept within their physical bounds: a last-resort guard for a replay
    that would otherwise diverge, not an accuracy control.

    ``inexact`` is 1 where the plain step says it cannot be accurate (a friction event
    inside it, a growing mode too fast for its explicit treatment, a leading local
    error above :data:`LOCAL_TOL`: :func:`_ros2_step`). It does **not** decide the
    refinement of this replay: the caller decides ``refine`` for every sample once
    (:func:`.predict.settle_refinement`), so that within a fit the replay is a smooth
    function of the parameters (a decision taken sample by sample from the parameters'
    own replay switches steps between 1 and 8 sub-steps as the parameters move, and the
    cost jumps: the refits then fitted the static friction 7.7 % low)."""
    nx, npar = len(plant.states), len(plant.p0)
    coarse_one = _ros2_step(plant, h, substeps, "ros2_coarse")
    fine_one = _ros2_step(plant, h, substeps * REFINE, "ros2_fine")
    coarse = coarse_one if substeps == 1 else _repeated(coarse_one, substeps, nx, npar)
    fine = _repeated(fine_one, substeps * REFINE, nx, npar)
    zm, um, pm = ca.MX.sym("z", nx), ca.MX.sym("u"), ca.MX.sym("p", npar)
    refine = ca.MX.sym("refine")
    zc, inexact = coarse(zm, um, pm)
    zf = fine(zm, um, pm)[0]
    bad = _implausible(plant, zm, zc)
    zn = ca.if_else(ca.logic_or(refine, bad), ca.if_else(bad, _project(plant, zf), zf, True),
                    zc, True)
    return ca.Function("ros2", [zm, um, pm, refine], [zn, inexact])


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
    sample_time : recording period, s (one ROS2 step per sample by default).
    controller : the plant file's PID (closed loop), or None (open loop only).
    substeps : ROS2 steps per sample (times :data:`LINE_SUBSTEPS` for a plant with line
        dynamics).
    jit : compile to C when a compiler is present.
    rates : also return the model's rates (observer passes).
    """

    def __init__(self, plant: Plant, sample_time: float, controller=None, substeps: int = 1,
                 jit: bool = True, chunk: int = CHUNK, rates: bool = False) -> None:
        self.plant = plant
        self.h = float(sample_time)
        self.controller = controller
        self.chunk = int(chunk)
        nx = len(plant.states)
        npar = len(plant.p0)
        if any(sig.part == "line" for sig in plant.states):
            substeps *= LINE_SUBSTEPS
        step = _guarded_step(plant, self.h, substeps)
        zs = ca.MX.sym("z", nx)
        cs = ca.MX.sym("c", 3)          # previous error, integral, held command
        inp = ca.MX.sym("in", len(INPUT_ROWS))
        ps = ca.MX.sym("p", npar)
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
        zn, inexact = step(z_anch, uu, p_k, row["refine"])
        outs = [z_anch[ix], z_anch[ia], z_anch[ib], uu]
        if rates:
            fz = plant.f(z_anch, uu, p_k)
            outs += [fz[iv], fz[ia], fz[ib]]
        outs.append(inexact)
        self.rows = (OUTPUTS if rates else OUTPUTS[:4]) + ("inexact",)
        self._sym = (zs, cs, inp, ps, zn, ca.vertcat(e_prev, integ, u_held), ca.vertcat(*outs))
        self._tag = hashlib.sha1(repr((
            plant.state_names, plant.param_names, self.h, substeps, self.chunk, rates,
            plant.friction, None if controller is None else
            (controller.kp, controller.kd, controller.ki, controller.sample_time,
             controller.u_center, lo, hi, prm.get("controller.position_resolution"),
             prm.get("controller.command_resolution")))).encode()).hexdigest()[:12]
        self.jit = jit
        self._fun = self._accumulated(0)
        self._sens: dict[int, ca.Function] = {}

    def _accumulated(self, k: int) -> ca.Function:
        """The per-sample function accumulated over a chunk, compiled; with ``k`` > 0 it
        also carries the forward sensitivities of the state, the controller memory and
        the outputs x, p_a, p_b along ``k`` directions in parameter space (seed ``D``,
        npar x k): exact derivatives of the discrete replay (ROS2 steps, re-anchoring,
        controller), by CasADi's forward mode."""
        zs, cs, inp, ps, zn, cn, y = self._sym
        nx, npar, n = zs.shape[0], ps.shape[0], self.chunk
        if k == 0:
            G = ca.Function("sample", [zs, cs, inp, ps], [zn, cn, y])
            acc = G.mapaccum("acc", n, [0, 1], [0, 1])
            Z0, C0 = ca.MX.sym("Z0", nx), ca.MX.sym("C0", 3)
            In, P = ca.MX.sym("I", len(INPUT_ROWS), n), ca.MX.sym("P", npar)
            zf, cf, Y = acc(Z0, C0, In, ca.repmat(P, 1, n))
            f = ca.Function(f"diag_{self._tag}", [Z0, C0, In, P], [zf[:, -1], cf[:, -1], Y])
            return compiled(f, flags=("-O2",)) if self.jit else f
        Sz, Sc, D = ca.MX.sym("Sz", nx, k), ca.MX.sym("Sc", 3, k), ca.MX.sym("D", npar, k)
        arg, seed = ca.vertcat(zs, cs, ps), ca.vertcat(Sz, Sc, D)
        Szn, Scn, Sy = (ca.jtimes(e, arg, seed) for e in (zn, cn, y[:3]))
        G = ca.Function("sample_s", [zs, cs, inp, ps, Sz, Sc, D],
                        [zn, cn, y, ca.reshape(Szn, nx * k, 1), ca.reshape(Scn, 3 * k, 1),
                         ca.reshape(Sy, 3 * k, 1)])
        Sz1, Sc1 = ca.MX.sym("Sz1", nx * k), ca.MX.sym("Sc1", 3 * k)
        z1, c1, i1, p1, D1 = (ca.MX.sym("z1", nx), ca.MX.sym("c1", 3),
                              ca.MX.sym("i1", len(INPUT_ROWS)), ca.MX.sym("p1", npar),
                              ca.MX.sym("D1", npar * k))
        o = G(z1, c1, i1, p1, ca.reshape(Sz1, nx, k), ca.reshape(Sc1, 3, k),
              ca.reshape(D1, npar, k))
        H = ca.Function("sample_sv", [ca.vertcat(z1, Sz1), ca.vertcat(c1, Sc1), i1,
                                      ca.vertcat(p1, D1)],
                        [ca.vertcat(o[0], o[3]), ca.vertcat(o[1], o[4]), ca.vertcat(o[2], o[5])])
        acc = H.mapaccum("acc", n, [0, 1], [0, 1])
        Z0, C0 = ca.MX.sym("Z0", nx * (k + 1)), ca.MX.sym("C0", 3 * (k + 1))
        In, P = ca.MX.sym("I", len(INPUT_ROWS), n), ca.MX.sym("P", npar * (k + 1))
        zf, cf, Y = acc(Z0, C0, In, ca.repmat(P, 1, n))
        f = ca.Function(f"diags{k}_{self._tag}", [Z0, C0, In, P], [zf[:, -1], cf[:, -1], Y])
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
        data = inputs.data
        N = data.shape[1]
        n = self.chunk
        pad = (-N) % n
        if pad:
            data = np.concatenate([data, np.repeat(data[:, -1:], pad, axis=1)], axis=1)
            data[INPUT_ROWS.index("anchor"), N:] = 0.0
            data[INPUT_ROWS.index("anchor_hidden"), N:] = 0.0
            data[INPUT_ROWS.index("anchor_p"), N:] = 0.0
        nr = len(self.rows)
        out = np.full((nr, data.shape[1]), np.nan)
        sens = np.full((3 * k, data.shape[1]), np.nan) if k else None
        for i in range(0, data.shape[1], n):
            zf, cf, y = fun(z, c, data[:, i:i + n], p)
            z, c = np.asarray(zf).ravel(), np.asarray(cf).ravel()
            y = np.asarray(y)
            out[:, i:i + n] = y[:nr]
            if k:
                sens[:, i:i + n] = y[nr:]
            if not np.all(np.isfinite(z)):
                break
        return out[:, :N], (sens[:, :N] if k else None)
