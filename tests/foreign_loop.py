"""A workbench controller in closed loop with the foreign rig (test helper, not a test file).

:mod:`foreign_rig` simulates a rig with other code than the workbench's (scipy, its own
valve, line and friction models: smooth Stribeck or LuGre friction, 5 pi-segment or one
lumped line) but runs only the plant file's PD loop. :func:`run` puts any
:class:`workbench.controllers.base.DiscreteController` in that loop instead: every
``sample_time`` the controller gets what a rig's sensors read (the position through a
``position_bits`` ADC over the stroke, with optional white position noise before it;
both chamber pressures with white noise; no velocity), its command is clipped to the
valve's range and held (ZOH) for one ``solve_ivp`` (LSODA) call over the sample.

Nothing here imports ``workbench.physics``, ``workbench.plant`` or the workbench's
sensor model: the loop, the sensors and the rig are independent of the code under test.
:func:`holds` finds the reference's holds and measures, over each, what the precision
must-shows judge (steady-state error, and over the hold's second half the
peak-to-peak and the command changes of a limit cycle).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from foreign_rig import ForeignRig, load_plant


@dataclass
class LoopRun:
    """Samples of a closed-loop run (SI): time, reference, true position and velocity,
    chamber pressures, command (V, as applied), measured position."""

    t: np.ndarray
    r: np.ndarray
    x: np.ndarray
    v: np.ndarray
    p_a: np.ndarray
    p_b: np.ndarray
    u: np.ndarray
    x_meas: np.ndarray


def rig_for(plant_file, law="smooth", line_model="pi5", overrides=None, friction_scale=1.0,
            **friction_kw) -> ForeignRig:
    """The foreign rig of a plant file with its dry friction (``friction.*`` keys, times
    ``friction_scale``) in the friction law ``law`` ("smooth" or "lugre")."""
    P = load_plant(plant_file, overrides)
    fc = friction_scale * float(P.get("friction.coulomb", 0.0))
    fs = friction_scale * float(P.get("friction.static", fc))
    kw = dict(coulomb=fc, static=fs, stribeck=float(P.get("friction.stribeck_velocity", 0.01)),
              law=law, line_model=line_model)
    kw.update(friction_kw)
    return ForeignRig(P, **kw)


def run(controller, rig: ForeignRig, reference, duration, *, seed=0, position_bits=12,
        position_noise=0.0, pressure_noise=300.0, p0=(4.4e5, 4.4e5), rtol=1e-6) -> LoopRun:
    """Closed loop of ``controller`` on ``rig`` over ``reference`` (r(t), m) for ``duration`` s.

    The piston starts at rest at r(0) with chamber (and line) pressures ``p0`` (Pa).
    Returns a :class:`LoopRun` sampled at the controller's sample time.
    """
    P = rig.P
    T = float(controller.sample_time)
    n = int(round(duration / T)) + 1
    t = np.arange(n) * T
    rng = np.random.default_rng(seed)
    q = rig.L / 2 ** position_bits
    u_lo, u_hi = P["valve.command_min"], P["valve.command_max"]
    z = rig.initial(float(reference(0.0)), p0[0], p0[1], P["valve.command_center"])
    atol = np.full(rig.n, 1e-2)
    atol[:2] = 1e-9, 1e-7
    if rig.lugre:
        atol[rig.i_z] = 1e-10
    if rig.lines:
        nn = rig.nodes
        for s in (nn, 3 * nn):
            atol[rig.i_line + s:rig.i_line + s + nn] = 1e-9
    out = {k: np.empty(n) for k in ("r", "x", "v", "p_a", "p_b", "u", "x_meas")}
    state = controller.reset()
    for i in range(n):
        xm = z[0] + position_noise * rng.standard_normal()
        xm = min(max(round(xm / q), 0), 2 ** position_bits - 1) * q
        y = {"x": xm, "p_a": z[2] + pressure_noise * rng.standard_normal(),
             "p_b": z[3] + pressure_noise * rng.standard_normal()}
        r = float(reference(t[i]))
        state, u = controller.update(state, r, y)
        u = min(max(float(u), u_lo), u_hi)
        for k, val in (("r", r), ("x", z[0]), ("v", z[1]), ("p_a", z[2]), ("p_b", z[3]),
                       ("u", u), ("x_meas", xm)):
            out[k][i] = val
        if i == n - 1:
            break
        sol = solve_ivp(rig.rhs, (t[i], t[i + 1]), z, method="LSODA", args=(u,), rtol=rtol,
                        atol=atol)
        if not sol.success:
            raise RuntimeError(f"foreign rig integration failed at t = {t[i]:.3f} s: "
                               f"{sol.message}")
        z = sol.y[:, -1]
    return LoopRun(t=t, **out)


def holds(run_: LoopRun, quantum: float, min_duration=0.5, settle=0.5, lead=0.0):
    """Per hold of the reference (r constant for at least ``min_duration`` s):
    steady-state error mean |r - x| over its last ``settle`` s (m), and over its second
    half less its last ``lead`` s (the controller's hand-over to the next move, as in
    workbench.controllers.evaluation.hold_evidence) the position's peak-to-peak (m)
    and the command changes > 10 mV."""
    t, r = run_.t, run_.r
    edges = np.flatnonzero(np.abs(np.diff(r)) > 1e-12)
    starts = np.r_[0, edges + 1]
    ends = np.r_[edges, len(r) - 1]
    out = []
    for a, b in zip(starts, ends):
        if t[b] - t[a] < min_duration:
            continue
        last = (t >= t[b] - settle) & (t <= t[b])
        half = (t >= 0.5 * (t[a] + t[b])) & (t <= max(t[b] - lead, 0.5 * (t[a] + t[b])))
        xs, us = run_.x[half], run_.u[half]
        out.append({"start": float(t[a]), "end": float(t[b]), "target": float(r[a]),
                    "steady_state_error": float(np.mean(np.abs(r[last] - run_.x[last]))),
                    "peak_to_peak": float(xs.max() - xs.min()),
                    "command_changes": int(np.sum(np.abs(np.diff(us)) > 1e-2)),
                    "quantum": quantum})
    return out
