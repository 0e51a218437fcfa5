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
from pathlib import Path

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


# ---------------------------------------------------------------------- rigs unlike ours
#: The precision rig's plant file, the base of the files below.
PRECISION = Path(__file__).resolve().parents[1] / "designs" / "plants" / "rigs" / "precision_rig25.toml"

#: Foreign rigs that differ from the workbench's plant files as real rigs do, each as
#: (the plant file a user would have: changes to PRECISION's keys, what the rig really
#: is: changes to that file's values, the rig's friction law and line model, position
#: ADC bits). Keys are the plant file's dotted keys.
FOREIGN_RIGS = {
    # a larger bore on a shorter stroke with a heavier carriage and shorter lines;
    # the user's file is 5-10 % off the rig on mass, supply and valve conductance
    # (the rig: mass +8 %, supply -6 %, conductance -8 %), friction a smooth Stribeck
    # curve (no stiction plateau), lines as 5 pi-segments
    "bore32": ({"name": "foreign-bore32", "cylinder.bore": 0.032, "cylinder.stroke": 0.2, "load.mass": 2.0,
                "friction.coulomb": 22.0, "friction.static": 34.0, "lines.length": 0.6,
                "controller.position_resolution": 0.2 / 4096},
               {"load.mass": 2.16, "supply.pressure": 5.64e5,
                "valve.sonic_conductance": 0.92 * 6.25e-8},
               "smooth", "pi5", 12),
    # the precision rig with a 5 % spool overlap (in its file too), a 10-bit position
    # sensor (0.49 mm over 0.5 m), LuGre friction 20 % above the file's and the
    # coarse lumped line model
    "overlap5_10bit": ({"name": "foreign-overlap5-10bit", "valve.deadband": 0.05,
                        "controller.position_resolution": 0.5 / 1024},
                       {"friction.coulomb": 18.0, "friction.static": 30.0},
                       "lugre", "lumped", 10),
}


def write_plant(path, changes: dict, base=PRECISION) -> Path:
    """Write ``base`` with ``changes`` (dotted keys -> numbers) to ``path`` as a plant
    file (TOML of flat sections; comments dropped)."""
    import tomllib
    doc = tomllib.loads(Path(base).read_text(encoding="utf-8"))
    for key, value in changes.items():
        if "." not in key:
            doc[key] = value
            continue
        sec, name = key.split(".", 1)
        doc.setdefault(sec, {})[name] = value
    lines = []
    for sec, tab in doc.items():
        if not isinstance(tab, dict):
            lines.append(f"{sec} = {tab!r}" if not isinstance(tab, str) else f'{sec} = "{tab}"')
    for sec, tab in doc.items():
        if isinstance(tab, dict):
            lines.append(f"\n[{sec}]")
            for k, v in tab.items():
                lines.append(f'{k} = "{v}"' if isinstance(v, str) else f"{k} = {v!r}")
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return Path(path)


def foreign_rig(name: str, directory):
    """(plant file path the user has, the ForeignRig, position bits) of FOREIGN_RIGS[name];
    the plant file is written into ``directory``."""
    file_changes, truth, law, line_model, bits = FOREIGN_RIGS[name]
    path = write_plant(Path(directory) / f"{name}.toml", file_changes)
    return path, rig_for(path, law=law, line_model=line_model, overrides=truth), bits


def step_profile(stroke: float, hold: float = 1.5, lead: float = 0.3):
    """Two steps of 12 % of the stroke about mid-stroke (60 mm on 0.5 m, the precision
    profile's scaling) and back, each held ``hold`` s; (Reference, duration s)."""
    from workbench import references
    c, h = 0.5 * stroke, 0.12 * stroke
    p = references.profile([(0, c), (lead, c), (lead, c + h), (lead + hold, c + h),
                            (lead + hold, c), (lead + 2 * hold, c)])
    return references.Reference(p.times, p.values), lead + 2 * hold
