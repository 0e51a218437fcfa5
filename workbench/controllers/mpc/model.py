"""The NMPC's prediction model: the plant reduced to x, v, p_a, p_b, its scaled
interval map (RK4) with the interval Jacobians, and the reference over the horizon.

Scaled variables: states z = (x / L, v / (1 m/s), p_a / p_supply, p_b / p_supply),
command w = (u - command_center) / command_span.
"""

from __future__ import annotations

import math
from typing import Sequence

import casadi as ca
import numpy as np

from ...errors import InputError
from ...integrate import RK4, explicit_rk

__all__ = ["STATE_EFFECTS", "NMPC_STATES", "LINE_STATES", "LINE_MODELS", "DESIGN_LINES",
           "DESIGN_BREAKAWAY",
           "LUMPED_SEGMENTS", "line_states", "V_SCALE", "Q_SCALE", "VALVE_MAP_EFFECTS",
           "prediction_model", "planning_model", "horizon_reference", "interval_maps",
           "interior_map", "friction_velocity", "MIN_FRICTION_VELOCITY", "MAX_SUBSTEPS"]

#: Effects of the valve's static command map that the NMPC plans through (it plans in
#: the compensated command; see :func:`planning_model`).
VALVE_MAP_EFFECTS = ("valve_deadband", "valve_offset")
#: Fraction of the deadband over which the NMPC's deadband inverse is a straight line
#: through zero (as :class:`~workbench.controllers.compensation.DeadbandInverse`'s
#: default): its residual dead zone (0.5 % of the span for a 5 % overlap) is what
#: remains unmodelled, and it keeps the opening continuous when the rig's deadband is
#: smaller than the plant file's. Measured, rig25 with a 5 % deadband, 10 mm steps,
#: 1 s holds: command changes > 0.01 V per hold 1 / 0 at 0.1, 8 / 4 at 0.02.
INVERSE_WIDTH = 0.1

#: Effects that add states to a plant; :func:`prediction_model` removes them.
STATE_EFFECTS = ("valve_dynamics", "heat_transfer", "line_dynamics", "supply_droop")
#: The states the NMPC measures and predicts, in the plant's order.
NMPC_STATES = ("x", "v", "p_a", "p_b")
#: The states a lumped line adds to the prediction (``lines="lumped"``), in the plant's
#: order: each line as one segment, its node pressure (Pa) and its flow into the
#: chamber (kg/s). Not measured: :mod:`.lines` estimates them.
LINE_STATES = ("line_a_p0", "line_a_q0", "line_b_p0", "line_b_q0")
#: Segments per line of ``lines="lumped"`` (the NMPC accepts a model with this many).
#: Two segments put the line's mode at 70 Hz instead of 57 Hz (the rig line's quarter
#: wave 86 Hz) and measured better (precision rig, test profile, design with
#: "lumped", merged main of session 11, seeds 0-4): command activity on the sine
#: 0.25-0.27 V (one segment 0.34-0.37 V), sine worst 0.99/0.85/0.89/0.91/0.83 mm
#: (0.79-1.01 mm), every hold at rest; perturbed rig 2.26 mm with a hold pulsing
#: (2.53 mm, two). 12 states: with the line filter inside the compiled sample
#: (:mod:`.fast`), 0.78-0.94 ms CPU median per sample (N = 40, 2 ms; machine load
#: 9-13; the 4-state model 0.32-0.40 ms), within the NMPC's 1 ms; but its compiled
#: sample takes 120 s to build (load 13; one segment's is what the tests build), so
#: one segment stays the default.
LUMPED_SEGMENTS = 1


def line_states(segments: int) -> tuple[str, ...]:
    """The lumped lines' state names for ``segments`` per line, in the plant's order
    (:data:`LINE_STATES` for one)."""
    out = []
    for side in ("a", "b"):
        out += [f"line_{side}_p{j}" for j in range(segments)]
        out += [f"line_{side}_q{j}" for j in range(segments)]
    return tuple(out)
#: How :func:`prediction_model` keeps the plant's lines: ``"volume"`` (their volume added
#: to the dead volumes) or ``"lumped"`` (one segment per line as states).
LINE_MODELS = ("volume", "lumped")
#: How :func:`workbench.controllers.design` gives its NMPC a lined plant's lines
#: (:data:`LINE_MODELS`). "volume": with the lines lumped in (``"lumped"``) the command
#: activity on the precision rig's sine halves (test profile of
#: tests/test_precision_positioning.py, seeds 0-4: 0.69-0.76 -> 0.34-0.37 V; two
#: segments 0.25-0.27 V) and the tracking between reversals improves (0.4-0.5 -> 0.2-0.3
#: mm), but the piston sticks longer at the sine's top reversal: worst error 0.47-0.88
#: -> 0.79-1.01 mm (two segments 0.83-0.99 mm), the perturbed rig (friction 1.5x, mass
#: +10 %) 1.25 -> 2.53 mm (two segments 2.26 mm) with holds pulsing. The cause is not
#: the lines' model but the quiet command: the 4-state loop's 26 Hz oscillation
#: (+-0.5 V, +-0.25 bar across the piston: about +-12 N, the F_s - F_c of the rig) is a
#: dither that breaks every stick within a few ms. The 4-state model quietened by a
#: command-rate tolerance of 0.1 V (activity 0.14-0.15 V) sticks as the lined one does:
#: sine worst 0.52 -> 1.94 mm (seed 0), 0.79 -> 1.19 mm (seed 3). A quiet loop sticks
#: 30-45 ms before the top reversal, while the reference still moves at 25 mm/s (slow
#: motion against the Stribeck drop through the air's compliance: stick-slip), and stays
#: stuck 80-125 ms while the force swings from pushing up to breaking away down; the
#: chattering one sticks only at the reversal, 44 ms (seed 0; scratch
#: /tmp/h14m/look.py, rev.py). A narrower predicted friction does not help: one
#: segment with v_e 2.6 mm/s and 16 substeps (the 5.25 mm/s default's half), sine
#: 0.58 -> 1.13 mm (seed 0), 1.33 mm (seed 3), activity 0.38 -> 0.42-0.48 V. A quiet
#: NMPC therefore needs a friction compensation for the reversal (issue 14's item 1)
#: before the lines can be its default.
#: Tried with "lumped" (h14j): position tolerance 1 mm, sine 0.61-0.95 mm on seeds 0-4,
#: activity 0.39-0.43 V, perturbed rig 2.18 mm and a hold pulsing; command-rate
#: tolerance 0.1 V, activity 0.10-0.14 V but sine 1.16-1.24 mm (seeds 0, 3). Two
#: segments per line: :data:`LUMPED_SEGMENTS`.
#: tests/test_mpc_lines.py runs the design with "lumped".
DESIGN_LINES = "volume"
#: The NMPC setting ``breakaway`` (:mod:`.breakaway`) of :func:`workbench.controllers.design`.
#: Off: it removes the quiet NMPC's long stick at the reversals (test profile of
#: tests/test_precision_positioning.py, seeds 0-4, sine worst error / activity):
#: 4-state with command-rate tolerance 0.1 V 0.67/0.76/0.53/0.68/0.62 mm, 0.14-0.16 V
#: (1.94 / 1.19 mm on seeds 0 / 3 without); "lumped", one segment 0.73/0.88/0.47/0.59/0.54 mm,
#: 0.36-0.41 V; two segments 0.53/0.42/0.50/0.59/0.52 mm, 0.27-0.36 V; steady states
#: within the quantum, holds at rest. But the rest of the default's bar is not met:
#: perturbed rig (friction 1.5x the file's) 1.85 / 1.21 / 1.12 mm respectively, each
#: with a hold pulsing (default 1.25 mm); the foreign smooth-friction lumped-line rig
#: (tests/foreign_loop.py) hunts in a hold: 26 / 34 and 24 command changes, p2p
#: 0.13-0.26 mm (default: 10 changes, 0.095 mm). The chattering default with it:
#: sine 0.52 -> 0.87 mm (seed 0). Closest to the bar: "lumped" (one segment) with it:
#: tests/test_foreign_loop.py and test_precision_positioning.py pass; precision_positioning.py
#: --quick NMPC passes on seeds 0-2 (sine 0.32/0.89/0.80 mm, default 0.58/0.72/0.64;
#: activity 0.38 V, default 0.84) but seed 2 has a hold limit cycle, and the perturbed
#: rig's sine 1.25 -> 1.00 mm with overshoot 0.09 -> 5.3 %. (session 11, h14p;
#: /tmp/h14p/evalp.py, foreign.py, pp.py)
DESIGN_BREAKAWAY = False
#: kg/s: scale of a line's mass flow in the scaled state (about a quarter of the 25 mm
#: rig valve's full flow, 44 g/s at 6 bar).
Q_SCALE = 0.01
#: m/s: velocity scale of the scaled state (position and pressures scale by stroke
#: and supply pressure).
V_SCALE = 1.0
#: m/s: the sharpest default tanh width of the prediction's dry friction (the width
#: of :func:`workbench.physics.friction.smooth_friction`'s default).
MIN_FRICTION_VELOCITY = 1e-3
#: Most RK4 substeps per interval :func:`friction_velocity` raises the NMPC's
#: ``substeps`` to: twice the default, as the interval map's cost grows with them
#: (``workbench bench mpc``'s friction variant at 10 ms: 3.9x the 4-state model's
#: time with 16, against its target of 3x).
MAX_SUBSTEPS = 8


def prediction_model(plant, effects: Sequence[str] | None = None, lines: str = "volume"):
    """The plant reduced to the four states x, v, p_a, p_b, for prediction (with
    ``lines="lumped"``: and one segment per line, :data:`LINE_STATES`).

    Effects that add states are removed: spool dynamics, heat transfer, supply droop,
    and the lines, whose volume (pi/4 d^2 L_t each) is added to the dead volume of
    its chamber (the line's delay and resistance are left to the feedback). A delay
    of the command by the lines' L_t / a (2.9 ms for 1 m) in this model predicts the
    lined rig 10 ms ahead better (position error 166 -> 96 um rms, pressures 8 -> 5
    kPa; best at 2-2.5 ms), but it made the closed loop worse, in the form of the
    measured state predicted over the delay with the commands already sent (for a
    pure input delay the same plans as the delay inside the shooting intervals):
    precision rig (2 ms loop), sine worst error seeds 0-4 0.82-1.31 -> 1.18-2.61 mm
    and a limit cycle in a hold in every seed; ``designs/nmpc_position.py`` (10 ms)
    command std at the stroke margin 0.18 -> 0.74 V with 1 ms of delay, 1.5 V with
    2.9 ms. The chamber's modes of this model (1e3 1/s mid-stroke, 1e4 near an end)
    are faster than the delay: predicted over it, the pressures settle to what the
    last command holds, while the real chamber behind its line does not. Of the
    other effects only those in ``effects`` are kept (default: all of them, e.g. dry
    friction, deadband, leakage). Dry friction takes its smooth (differentiable) form;
    the NMPC predicts it with the width of :func:`friction_velocity`.

    ``lines="lumped"`` keeps a plant's lines instead as one segment each (the plant's
    own line law, :func:`workbench.physics.line.line_rates`, with the file's length
    and bore): a node of the line's volume at the valve port and the line's flow into
    the chamber through its inertance and friction. That puts the lines' lag between
    command and chamber into the prediction (first mode a / L rad/s, 55 Hz for 1 m).
    Measured (precision rig, NMPC's own closed-loop commands, seed 0, moving sections,
    10 ms ahead, measured x, v, p_a, p_b, 300 Pa pressure noise; scratch
    /tmp/h14j/pred2.py): position error 201 um rms with the line volume in the dead
    volume, 43 um with one segment per line started from the rig's own line state
    (its four segments averaged), 98 um with the line state estimated by
    :mod:`.lines` (161 um by the segment model alone, without its correction from the
    chamber pressures); pressures 11.5 / 4.0 / 6.6 kPa. Without lines in the plant it
    is the 4-state model.

    Parameters
    ----------
    plant : workbench.Plant
    effects : sequence of str, optional
        Effects to keep; one that adds states is refused (``line_dynamics``: see
        ``lines``).
    lines : {"volume", "lumped"}
        How the plant's lines enter (above).

    Returns
    -------
    workbench.Plant
    """
    from ...plant import Plant
    if lines not in LINE_MODELS:
        raise InputError(f"lines must be one of {', '.join(LINE_MODELS)}, got {lines!r}")
    params = plant.params
    have = tuple(plant.effects)
    lumped = lines == "lumped" and "line_dynamics" in have
    keep = tuple(e for e in have if e not in STATE_EFFECTS) if effects is None else tuple(effects)
    keep = tuple(e for e in keep if not (lumped and e == "line_dynamics"))
    bad = [e for e in keep if e in STATE_EFFECTS]
    if bad:
        raise InputError(f"the NMPC's prediction model has the states x, v, p_a, p_b only; "
                         f"effect(s) {', '.join(bad)} add states and cannot be kept")
    unknown = [e for e in keep if e not in have]
    if unknown:
        raise InputError(f"effect(s) {', '.join(unknown)} to keep are not in the plant "
                         f"(it has: {', '.join(have) or 'none'})")
    if lumped:
        keep = keep + ("line_dynamics",)
        params = params.replace(**{"lines.segments": LUMPED_SEGMENTS})
    elif "line_dynamics" in have:
        v_line = math.pi / 4.0 * params["lines.diameter"] ** 2 * params["lines.length"]
        params = params.replace(**{
            "cylinder.dead_volume_a": params["cylinder.dead_volume_a"] + v_line,
            "cylinder.dead_volume_b": params["cylinder.dead_volume_b"] + v_line})
    for e in have:
        if e not in keep:
            params = params.without_effect(e)
    return Plant(params, friction="smooth")


def planning_model(model):
    """The model the NMPC plans with, and the command map from its plan to the valve.

    A valve deadband (spool overlap) makes the opening's derivative with respect to
    the command zero over the whole overlap: an NMPC linearised there (at rest, at
    the centre) sees no control authority and never leaves the centre. A static
    map in front of the plant can be inverted exactly, so the NMPC plans in the
    *compensated* command instead: its model is the plant without deadband and
    null offset, and the command it applies is the plan passed through
    :class:`~workbench.controllers.compensation.DeadbandInverse` (physics.md's
    opening law inverted), so the valve opens as the plan says. This keeps the
    model exact outside a residual dead zone of ``INVERSE_WIDTH`` x deadband (the
    inverse's straight line through zero) instead of approximating the dead zone by
    a smoothed one, whose slope would still be near zero at the centre.

    Parameters
    ----------
    model : workbench.Plant
        The 4-state prediction model (:func:`prediction_model`).

    Returns
    -------
    (workbench.Plant, DeadbandInverse or None)
        The model without ``valve_deadband`` and ``valve_offset``, and the inverse
        (None when the model has neither: the command is applied as planned).
    """
    from ...plant import Plant
    from ..compensation import DeadbandInverse
    have = [e for e in VALVE_MAP_EFFECTS if e in tuple(model.effects)]
    if not have:
        return model, None
    inverse = DeadbandInverse.from_plant(model, width=INVERSE_WIDTH)
    params = model.params
    for e in have:
        params = params.without_effect(e)
    return Plant(params, friction=getattr(model, "friction", "smooth")), inverse


def horizon_reference(r: float, r_prev: float | None, sample_time: float, horizon: int,
                      rate_limit: float) -> tuple[np.ndarray, float]:
    """Reference over the horizon from its current and previous sample (no preview).

    Parameters
    ----------
    r, r_prev : m, reference now and one sample ago (``None``: first sample).
    sample_time : s. horizon : N. rate_limit : m/s.

    Returns
    -------
    (N + 1,) positions, m, at the shooting nodes, and the rate, m/s: r + rate k T
    if |rate| <= ``rate_limit`` (a ramp), else r held with rate 0 (a step).
    """
    rate = 0.0 if r_prev is None else (r - r_prev) / sample_time
    if not abs(rate) <= rate_limit:
        rate = 0.0
    return r + rate * sample_time * np.arange(horizon + 1), rate



def friction_velocity(model, sample_time: float, substeps: int,
                      width: float | None = None) -> tuple[float | None, int]:
    """Tanh width v_e (m/s) of the dry friction the NMPC predicts with, and the RK4
    substeps per interval that integrate it: ``(None, substeps)`` without dry friction.

    The smooth friction F_f = F_str(v) tanh(v / v_e) (+ viscous) has the slope
    k = F_s / v_e + beta at v = 0, so a coasting or stuck piston's velocity decays at
    the rate k / m. The interval map integrates it by RK4 with the step
    h = sample_time / n, whose amplification per step, 1 - k h/m + ... + (k h/m)^4 /
    24, exceeds 1 beyond k h / m = 2.785 (the real-axis stability limit): with the
    physics' width 1 mm/s and 4 substeps on the precision rig (F_s 25 N, m 1.2 kg,
    h 0.5 ms: k h / m = 10.4) one interval multiplied a velocity difference at rest
    by 1.5e10, the predicted motion of a stuck piston was a rounding artefact, and the
    plan iteration turned 1e-9 m in a measurement into volts of command within one
    sample. Two rules therefore:

    * the width is ``width`` if given, else half the plant file's Stribeck velocity
      v_s: then tanh(v_s / v_e) = 0.96 and the prediction follows the file's Stribeck
      curve from v_s on (a width near v_s flattens the drop from static to Coulomb
      friction that breaks a reversal away);
    * one RK4 step resolves the decay, k h / m <= 1 (RK4 then decays by 0.375 per
      step against the exact exp(-1) = 0.368): the substeps are raised from
      ``substeps`` to the fewest that do, at most :data:`MAX_SUBSTEPS` (the interval
      map's cost grows with them); beyond that the width is widened to
      F_s h / (m - beta h) instead.

    Precision rig, 2 ms: 9 substeps would resolve v_s / 2 = 5 mm/s; with 8, v_e =
    5.25 mm/s (at 10 ms: 27 mm/s). Below v_e the prediction's
    friction depends on the estimated velocity's sign no more than linearly, and the
    velocity decays within one substep, so the observer's velocity noise at rest
    (0.2 mm/s from 300 Pa pressure noise; up to K_v q / sqrt(12) = 12 mm/s while the
    12-bit position steps) moves the plan only over that substep.

    Parameters
    ----------
    model : workbench.Plant
        The 4-state prediction model. sample_time : s. substeps : int, at least.
    width : float, m/s, optional
        The tanh width wanted (default v_s / 2).

    Returns
    -------
    (float or None, int)
        v_e in m/s (None without dry friction), RK4 substeps per interval.
    """
    prm = model.params
    n = int(substeps)
    if not prm.has_effect("dry_friction"):
        return None, n
    T = float(sample_time)
    m, beta = float(prm["load.mass"]), float(prm["load.viscous_friction"])
    fs = max(float(prm["friction.static"]), float(prm["friction.coulomb"]))
    v_e = (max(0.5 * float(prm["friction.stribeck_velocity"]), MIN_FRICTION_VELOCITY)
           if width is None else float(width))

    def resolved(k: int) -> bool:                     # k h / m <= 1
        return (fs / v_e + beta) * (T / k) <= m * (1.0 + 1e-12)

    while not resolved(n) and n < MAX_SUBSTEPS:
        n += 1
    if not resolved(n):
        h = T / n
        room = m - beta * h
        v_e = fs * h / room if room > 0 else math.inf
    return v_e, n


def _scaled_rhs(model, scales, u_center: float, u_span: float,
                friction_width: float | None = None):
    """Symbols z, w, d, the scaled right-hand side fz (SX) and it as a Function.

    With ``friction_width`` (m/s) the model's dry friction is the smooth law with that
    tanh width (:func:`friction_velocity`) instead of the plant's own."""
    nx = len(scales)
    z = ca.SX.sym("z", nx)
    w = ca.SX.sym("w")
    d = ca.SX.sym("d")                                 # estimated disturbance force, N
    base, dry = model, None
    if friction_width is not None and model.params.has_effect("dry_friction"):
        from ...plant import Plant
        from ...physics.friction import smooth_friction
        prm = model.params
        dry = (float(prm["friction.coulomb"]), float(prm["friction.static"]),
               float(prm["friction.stribeck_velocity"]), float(prm["load.mass"]))
        base = Plant(prm.without_effect("dry_friction"), friction="smooth")
    pvec = ca.DM(base.p0) + d * ca.DM(
        np.eye(len(base.p0))[:, base.param_index("load.external_force")])
    xs = z * ca.DM(scales)
    xdot = base.f(xs, u_center + u_span * w, pvec)
    if dry is not None:
        fc, fs, vs, m = dry
        i_v = NMPC_STATES.index("v")
        acc = xdot[i_v] - smooth_friction(xs[i_v], fc, fs, vs, 0.0, friction_width) / m
        xdot = ca.vertcat(xdot[:i_v], acc, xdot[i_v + 1:])
    fz = xdot / ca.DM(scales)
    return z, w, d, fz, ca.Function("wb_nmpc_f", [z, w, d], [fz])


def _pade_jacobians(fz, z, w, z_end, tau: float):
    """(dz_end/dz, dz_end/dw) over a time ``tau`` (s): the (1, 2) Pade approximant
    (L-stable, 3rd order) of the exponential of the continuous Jacobian at the
    midpoint of z and z_end."""
    nx = z.shape[0]
    ja = ca.substitute(ca.jacobian(fz, ca.vertcat(z, w)), z, (z + z_end) / 2)
    xa = tau * ca.vertcat(ja, ca.SX.zeros(1, nx + 1))
    eye = ca.SX.eye(nx + 1)
    phi = ca.solve(eye - 2.0 / 3.0 * xa + ca.mtimes(xa, xa) / 6.0, eye + xa / 3.0)
    return phi[:nx, :nx], phi[:nx, nx]


def _rk4_states(fc, z, w, d, sample_time: float, substeps: int) -> list:
    """The state after each of the ``substeps`` RK4 steps of one interval."""
    h = sample_time / substeps
    out, zz = [], z
    for _ in range(substeps):
        zz = explicit_rk(RK4, lambda zi: fc(zi, w, d), zz, h)
        out.append(zz)
    return out


def interval_maps(model, scales: np.ndarray, u_center: float, u_span: float,
                  sample_time: float, substeps: int, sensitivities: str,
                  friction_width: float | None = None) -> tuple[ca.Function, ca.Function]:
    """One shooting interval of the scaled model, and its Jacobians.

    Parameters
    ----------
    model : workbench.Plant
        The 4-state prediction model.
    scales : (4,) m, m/s, Pa, Pa: z = state / scales.
    u_center, u_span : V: w = (u - u_center) / u_span.
    sample_time : s, the interval's length. substeps : RK4 steps per interval.
    sensitivities : {"pade", "exact"}
        Jacobians by the (1, 2) Pade approximant of the exponential of the
        continuous Jacobian at the interval's midpoint, or by differentiating the
        RK4 steps.
    friction_width : float, m/s, optional
        Tanh width of the dry friction (:func:`friction_velocity`); None: the
        model's own smooth law.

    Returns
    -------
    F : casadi.Function ``wb_nmpc_F(z, w, d) -> z+``, the state one interval on with
        the command w held and the disturbance force d (N, along -x, added to
        ``load.external_force``).
    Fj : casadi.Function ``wb_nmpc_Fj(z, w, d) -> (z+, dz+/dz, dz+/dw)``.
    """
    z, w, d, fz, fc = _scaled_rhs(model, scales, u_center, u_span, friction_width)
    zz = _rk4_states(fc, z, w, d, sample_time, substeps)[-1]
    F = ca.Function("wb_nmpc_F", [z, w, d], [zz])
    if sensitivities == "exact":
        jac = [ca.jacobian(zz, z), ca.jacobian(zz, w)]
    else:
        jac = list(_pade_jacobians(fz, z, w, zz, sample_time))
    return F, ca.Function("wb_nmpc_Fj", [z, w, d], [zz] + jac)


def interior_map(model, scales: np.ndarray, u_center: float, u_span: float,
                 sample_time: float, substeps: int, sensitivities: str,
                 points: Sequence[int] | None = None,
                 friction_width: float | None = None) -> ca.Function | None:
    """The states between the shooting nodes (RK4 substeps' ends), and their
    Jacobians, for limits enforced between the nodes.

    Same parameters as :func:`interval_maps` (and ``friction_width``); ``points`` are
    the substep ends j (1 ..
    ``substeps`` - 1; default all of them). The Jacobians of the point at time j h
    (h = sample_time / substeps) are the Pade approximant over j h, or exact.

    Returns
    -------
    casadi.Function or None
        ``wb_nmpc_Fi(z, w, d) -> (Z (nx, m), dZ/dz (nx, nx m), dZ/dw (nx, m))`` for
        the m points; None without any (one substep, or ``points`` empty).
    """
    pts_at = list(range(1, substeps)) if points is None else sorted(set(int(j) for j in points))
    if any(not 1 <= j < substeps for j in pts_at):
        raise InputError(f"interior points are substep ends 1 .. {substeps - 1}, got {pts_at}")
    if not pts_at:
        return None
    z, w, d, fz, fc = _scaled_rhs(model, scales, u_center, u_span, friction_width)
    ends = _rk4_states(fc, z, w, d, sample_time, substeps)
    pts = [ends[j - 1] for j in pts_at]
    jz, jw = [], []
    for j, zj in zip(pts_at, pts):
        if sensitivities == "exact":
            a, b = ca.jacobian(zj, z), ca.jacobian(zj, w)
        else:
            a, b = _pade_jacobians(fz, z, w, zj, j * sample_time / substeps)
        jz.append(a)
        jw.append(b)
    return ca.Function("wb_nmpc_Fi", [z, w, d],
                       [ca.horzcat(*pts), ca.horzcat(*jz), ca.horzcat(*jw)])
