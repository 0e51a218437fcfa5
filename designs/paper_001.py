"""Paper 001 (Iliev, Hristov) end to end: 1 m against 10 m lines, PID positioning.

Paper 001 simulates and measures an electropneumatic positioning drive with lines of
1 m and 10 m between the proportional valve and the cylinder, under a PID loop with
setpoint steps, and finds the longer lines delay and attenuate the chamber pressures
and make the position transient about 0.4 s longer. The paper gives the model's form
but not the drive's sizes; designs/plants/papers/iliev_lines_1m.toml states every assumed
value (bore, load, supply, tube bore 4 mm, ...). This script:

1. steps the valve open loop and measures the chamber pressures' delay and
   attenuation on both line lengths (lumped-segment lines, :mod:`workbench.physics.line`);
2. designs one PID for both (on the 10 m drive, the harder one: loop gain a third of
   the exact sampled-data limit, derivative zero at the air spring's natural frequency,
   integral a quarter of the specified settling time, collected only within 2 mm of the
   setpoint) and validates it on both, beside a PD and on a valve with a null offset
   (:func:`workbench.validate.validate`, the paper's uniform setpoint steps);
3. compares the position transients (settling time per step) and shows how the
   difference depends on the tube bore the paper does not give.

The report's first table is the paper's results beside the workbench's;
``DIR/summary.json`` holds the same rows in ``paper_results``.

Usage: python designs/paper_001.py [--quick] [--out DIR]
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from workbench import Plant, controllers, linearize, plots, references, simulate, stability
from workbench import report as rp
from workbench import validate
from workbench.controllers.pd import pid_law
from workbench.params import atomic_write_text, json_safe

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PLANT = HERE / "plants" / "papers" / "iliev_lines_1m.toml"
TITLE = "Paper 001 reproduced: 1 m against 10 m pneumatic lines, PID positioning"

#: Values quoted from paper 001: (value, unit, where).
PAPER = {
    "lengths": ((1.0, 10.0), "m", "Sec. 'Experimental study': two experiments, 1 m and 10 m"),
    "dt": (0.4, "s", "Sec. 'Modelling and simulation', after Fig. 9: 'the time of the "
                     "transition process differs by 0.4 s'"),
    "effects": ("time delay and amplitude decay", "", "Sec. 'Modelling and simulation', after "
                                                      "Fig. 9"),
}
#: Speed of sound of eq. (4)'s a_s, m/s (physics.md; the paper gives no number).
A_SOUND = 343.0
#: Pressure delay: time for chamber a to rise 1 kPa after the valve step (well above
#: the solver's noise, far below the 1e5 Pa swing).
DELAY_THRESHOLD = 1e3
#: Segments per line: about 0.25 m each (quick: 0.5 m on the 10 m line). Measured on the
#: quick staircase: transient shift 0.0510 s (20) against 0.0513 s (40 segments) with the
#: 4 mm bore, 0.4137 s against 0.4140 s with 2 mm; the delay differs by 1 ms.
SEGMENTS = {1.0: 8, 10.0: 40}
SEGMENTS_QUICK = {1.0: 8, 10.0: 20}
#: PID design rules (see the module docstring) and the back-off per failed validation.
GAIN_MARGIN = 3.0
#: Ti = (specified settling time) / TI_SETTLING: an offset decays as exp(-t/Ti), to
#: e^-4 = 1.8 % (inside the 2 % band) within it. Measured (quick): Ti = 10/K0 = 1.55 s
#: leaves 1.6 mm of a 3 mm offset at the hold ends.
TI_SETTLING = 4.0
#: Integral separation band = BAND_FLOORS x the spec's 1 mm band floor: it removes rest
#: errors that fail the 1 mm spec (null offsets up to kp x 2 mm = 0.02 V) while the error
#: area collected on a >= 100 mm step stays small. Measured (quick, Ti = 0.375 s): 2 mm
#: and 3 mm pass on both lines (hold-end errors 0.41, 0.65 mm); no band fails.
BAND_FLOORS = 2.0
#: Valve null offset of the demonstration, V (zero-flow command 5.015 V, controller's
#: centre 5 V): ASSUMED; a PD loop then rests offset / kp = 1.5 mm short.
NULL_OFFSET = 0.015
BACKOFF, TRIES = 0.8, 5
#: Tube bores of the sensitivity study, m (the paper gives none; 2 .. 6 mm are the
#: usual polyurethane tubes of 4 .. 8 mm outside diameter).
BORES = [0.002, 0.003, 0.006]
#: Single setpoint steps of the sensitivity study, m (the paper: 'within the working
#: stroke', no size). Measured (quick): 0.1 m steps shift 0.045 s, 0.4 m 0.14 s.
STEPS = [0.1, 0.4]
#: Agreement with the paper's 0.4 s: +- 0.2 s. The paper's bore, load, supply, tube
#: bore and gains are unknown; the report measures how far the tube bore alone moves it.
DT_TOL = 0.2
#: Transport delay: +- 5 ms (the lumped line's wave front is smeared over a few
#: segments of 1 .. 1.5 ms transit each).
DELAY_TOL = 5e-3


def plants(quick: bool, diameter: float | None = None) -> dict[float, Plant]:
    """The drive with 1 m and 10 m lines (optionally another tube bore, m)."""
    base = Plant.from_toml(PLANT)
    seg = SEGMENTS_QUICK if quick else SEGMENTS
    out = {}
    for L in PAPER["lengths"][0]:
        ch = {"lines.length": L, "lines.segments": seg[L]}
        if diameter is not None:
            ch["lines.diameter"] = diameter
        out[L] = base.with_params(**ch)
    return out


def line_step(plant: Plant) -> dict:
    """Valve step 5 -> 8 V at t = 10 ms, piston at rest at mid-stroke, 0.1 ms samples.

    Returns t (s), p_a, p_b (Pa), the mass flows into chamber a and out of chamber b
    at the line ends (kg/s), the delay (s) until p_a has risen DELAY_THRESHOLD, the
    peak rate of rise of p_a (Pa/s) and the peak flow into chamber a (kg/s): eq. (4)
    attenuates the mass flow.
    """
    t = np.arange(0.0, 0.12 + 1e-12, 1e-4)
    u = np.where(t >= 0.01, 8.0, 5.0)
    tr = simulate.open_loop(plant, t, u, x0=0.25, progress=False)
    p_a, p_b = np.asarray(tr["p_a"]), np.asarray(tr["p_b"])
    k = int(np.argmax(p_a - p_a[0] > DELAY_THRESHOLD))
    rate = np.gradient(p_a, t)
    last = plant.segments - 1                     # the segment that ends in the chamber
    q_a = np.asarray(tr[f"line_a_q{last}"])       # kg/s into chamber a
    q_b = -np.asarray(tr[f"line_b_q{last}"])      # kg/s out of chamber b
    return {"t": t, "p_a": p_a, "p_b": p_b, "q_a": q_a, "q_b": q_b,
            "delay": float(t[k] - 0.01), "peak_rate": float(rate.max()),
            "peak_flow": float(q_a.max()), "x": np.asarray(tr["x"])}


@dataclass(frozen=True)
class BandedPID:
    """:func:`workbench.controllers.pd.pid_law` (integral held while saturated) with the
    integral also held while |e| > integral_band (m): integral separation. A no-load
    integrating drive rests at the valve's null, so the integral must end each step
    where it began and the error area it collects comes back as overshoot; collected
    only inside the band, that area is small. Not a PID subclass on purpose: code that
    re-runs a PID's gains (compiled loop, diagnosis) must refuse it, not drop the band.
    """

    kp: float
    sample_time: float
    kd: float = 0.0
    ki: float = 0.0
    u_center: float = 0.0
    u_min: float = float("-inf")
    u_max: float = float("inf")
    integral_band: float = float("inf")

    kind = "pid"

    def reset(self):
        return (None, 0.0)

    def update(self, state, r: float, y: dict) -> tuple[tuple, float]:
        e_prev, held = state
        e = r - y["x"]
        u, integ = pid_law(e, e if e_prev is None else e_prev, held, self.kp, self.kd,
                           self.ki, self.sample_time, self.u_center, self.u_min, self.u_max)
        if abs(e) > self.integral_band:
            u, integ = u - self.ki * (integ - held), held
        return (e, integ), u


def design_pid(plant10: Plant, spec: validate.Specification) -> tuple:
    """(PID, the same without integral, design figures) from the 10 m drive's exact
    tangent model at mid-stroke: K0 = (exact sampled-data P limit) / GAIN_MARGIN,
    kp = K0 / Kv; Td = 1/w0 (derivative zero at the air spring's natural frequency,
    phase lead at the lightly damped mode); Ti = spec.max_settling_time / TI_SETTLING;
    integral band BAND_FLOORS x spec.band_floor (:class:`BandedPID`)."""
    red = linearize.reduced_position_model(linearize.tangent(plant10, x=0.25))
    T = float(plant10.params["controller.sample_time"])
    lim = stability.limits_from_plant(plant10, 0.25, sample_time=T, k0=1.0)
    k0 = lim.sampled / GAIN_MARGIN
    kp = k0 / red.kv
    prm = plant10.params
    pd = controllers.PID(kp=kp, kd=kp / red.w0, sample_time=T,
                         u_center=prm["valve.command_center"], u_min=prm["valve.command_min"],
                         u_max=prm["valve.command_max"])
    ti = spec.max_settling_time / TI_SETTLING
    pid = BandedPID(kp=kp, kd=kp / red.w0, ki=kp / ti, sample_time=T,
                    u_center=pd.u_center, u_min=pd.u_min, u_max=pd.u_max,
                    integral_band=BAND_FLOORS * spec.band_floor)
    return pid, pd, {"kv": red.kv, "w0": red.w0, "zeta": red.zeta, "k0": k0, "ti": ti,
                     "limit": lim.sampled, "fit_error": red.fit_error}


def staircase(quick: bool) -> references.Reference:
    """The paper's input: setpoint steps of equal size up the stroke and back."""
    levels = [0.1, 0.2, 0.3, 0.4, 0.3, 0.2] if not quick else [0.1, 0.25, 0.4, 0.25]
    return references.steps(levels, hold=2.0 if not quick else 1.5)


def scaled(pid: controllers.PID, f: float) -> controllers.PID:
    """The PID with every gain times f (same zero and integral time)."""
    return replace(pid, kp=pid.kp * f, kd=pid.kd * f, ki=pid.ki * f)


def validate_both(pls: dict, pid0, ref, spec) -> tuple[controllers.PID, dict, list]:
    """Validate on both drives; lower all gains by BACKOFF while either fails."""
    tries = []
    for i in range(TRIES):
        pid = scaled(pid0, BACKOFF ** i)
        vals = {L: validate.validate(pl, pid, spec=spec, reference=ref, progress=False,
                                     label=f"PID, {L:g} m lines") for L, pl in pls.items()}
        tries.append((pid, {L: v.passed for L, v in vals.items()}))
        print(f"    kp = {pid.kp:.2f} V/m: " + ", ".join(
            f"{L:g} m {'pass' if v.passed else 'fail: ' + ', '.join(c.name for c in v.failed)}"
            for L, v in vals.items()))
        if all(v.passed for v in vals.values()):
            break
    return pid, vals, tries


def integral_comparison(plant10: Plant, pid, pd, ref, spec) -> dict:
    """What the integral is for, measured on the 10 m drive: the PID, the PD (ki = 0),
    and the PID without its separation band, on the nominal valve; the PD and the PID
    on a valve whose zero-flow command is NULL_OFFSET above the controller's centre.
    Returns {name: Validation}."""
    off = plant10.with_params(**{"valve.command_center":
                                 float(plant10.params["valve.command_center"]) + NULL_OFFSET})
    runs = {"PID": (plant10, pid), "PD (ki = 0)": (plant10, pd),
            "PID without band": (plant10, replace(pid, integral_band=float("inf"))),
            "PD, valve null offset": (off, pd), "PID, valve null offset": (off, pid)}
    out = {}
    for name, (pl, c) in runs.items():
        out[name] = validate.validate(pl, c, spec=spec, reference=ref, progress=False, label=name)
        print(f"    {name}: " + ("pass" if out[name].passed else
                                 "fail: " + ", ".join(x.name for x in out[name].failed)))
    return out


def step_times(v) -> tuple[np.ndarray, np.ndarray]:
    """Per setpoint step of a validation: time (s) until the position has covered half
    the step, and the settling time (s) into the validation's band."""
    t, x = v.trajectory.time, np.asarray(v.trajectory["x"])
    half, settle = [], []
    for s in v.segments:
        if s.segment.kind != "step":
            continue
        sel = t >= s.segment.start
        frac = (x[sel] - s.segment.r_start) / (s.segment.r_end - s.segment.r_start)
        half.append(float(t[sel][np.argmax(frac >= 0.5)] - s.segment.start)
                    if np.any(frac >= 0.5) else np.inf)
        settle.append(s.settling_time)
    return np.array(half), np.array(settle)


def transient_difference(vals: dict) -> dict:
    """10 m minus 1 m, mean over the setpoint steps: the shift of the position transient
    (time to half the step; the paper reads the longer lines as a 'signal delay') and
    the settling-time difference, s."""
    h1, s1 = step_times(vals[1.0])
    h10, s10 = step_times(vals[10.0])
    return {"shift": float(np.mean(h10 - h1)), "settling": float(np.mean(s10 - s1)),
            "half_1m": h1, "half_10m": h10, "settle_1m": s1, "settle_10m": s10}


def sensitivity(pid, ref, spec, cases, quick: bool) -> list[dict]:
    """The same PID with another tube bore (m; the paper gives none) or on single
    setpoint steps of another size (m, up from 50 mm and back; the paper gives none):
    ``cases`` of (bore or None, step or None)."""
    rows = []
    for d, step in cases:
        pls = plants(quick, diameter=d)
        r = ref if step is None else references.steps([0.05, 0.05 + step, 0.05], hold=2.0)
        vals = {L: validate.validate(pl, pid, spec=spec, reference=r, progress=False)
                for L, pl in pls.items()}
        td = transient_difference(vals)
        rows.append({"diameter": float(pls[1.0].params["lines.diameter"]), "step": step,
                     "shift": td["shift"], "settling": td["settling"],
                     "delay": line_step(pls[10.0])["delay"] - line_step(pls[1.0])["delay"],
                     "passed": all(v.passed for v in vals.values())})
        print(f"    tube bore {rows[-1]['diameter'] * 1e3:g} mm, steps "
              f"{'staircase' if step is None else f'{step:g} m'}: shift {td['shift']:.3f} s")
    return rows


# ---------------------------------------------------------------------- figures
def fig_lines(steps: dict):
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(3, 1, figsize=(7.0, 6.4), sharex=True)
    for L, st in steps.items():
        ls = "-" if L < 5 else "--"
        axes[0].plot(st["t"] * 1e3, st["p_a"] * 1e-5, ls, label=f"{L:g} m")
        axes[1].plot(st["t"] * 1e3, st["p_b"] * 1e-5, ls, label=f"{L:g} m")
        axes[2].plot(st["t"] * 1e3, st["q_a"] * 1e3, ls, label=f"into a, {L:g} m")
        axes[2].plot(st["t"] * 1e3, st["q_b"] * 1e3, ls, lw=0.8, label=f"out of b, {L:g} m")
    axes[0].set_ylabel("chamber a [bar abs]")
    axes[1].set_ylabel("chamber b [bar abs]")
    axes[2].set_ylabel("mass flow [g/s]")
    axes[2].set_xlabel("time [ms] (valve step 5 -> 8 V at 10 ms)")
    for a in axes:
        a.axvline(10.0, color="grey", lw=0.6)
        a.grid(alpha=0.3)
        a.legend(fontsize=7, ncol=2)
    return fig


# ---------------------------------------------------------------------- report
def main(argv=None) -> int:
    args, out = rp.design_arguments(__doc__.splitlines()[0], ROOT / "reports" / "paper_001",
                                    "coarser 10 m line, shorter staircase, one other tube bore", argv)
    t_start = time.perf_counter()
    return rp.run_design(TITLE, out, PLANT, lambda done: _design(args, out, done, t_start))


def _design(args, out: Path, done: list, t_start: float) -> int:
    quick = args.quick
    with rp.step("plants"):
        pls = plants(quick)
        sections = [_config_section(pls)]
    with rp.step("line delay and attenuation"):
        steps = {L: line_step(pl) for L, pl in pls.items()}
        sections.append(_lines_section(steps))
    with rp.step("PID design and validation"):
        ref, spec = staircase(quick), validate.Specification()
        pid0, pd0, info = design_pid(pls[10.0], spec)
        pid, vals, tries = validate_both(pls, pid0, ref, spec)
        for L, v in vals.items():
            v.trajectory.to_csv(out / f"validation_{L:g}m.csv")
        compare = integral_comparison(pls[10.0], pid, scaled(pd0, pid.kp / pid0.kp), ref, spec)
        sections.append(_pid_section(pid, info, vals, compare, tries))
    with rp.step("position transients"):
        td = transient_difference(vals)
        cases = [(d, None) for d in ([0.002] if quick else BORES)] + [
            (None, st) for st in ([0.4] if quick else STEPS)]
        bores = sensitivity(pid, ref, spec, cases, quick)
        sections.append(_transient_section(td, bores, pls))
    with rp.step("write report"):
        results = _results(steps, td, vals)
        sections.insert(0, _results_section(results))
        sections.append(_disagreement_section(results, steps, td, bores))
        done.extend(sections)
        return _finish(out, results, steps, pid, info, vals, td, bores, done, t_start, quick,
                       compare)


def _config_section(pls: dict) -> rp.Section:
    prm = pls[1.0].params
    rows = [["line lengths", "1 and 10 m", "paper (Sec. 'Experimental study')"],
            ["valve flow law", "eq. (2), Cv = 0.274, X_T = 1", "paper; not used: no agreed "
             "conversion of its Cv to ISO 6358"],
            ["chamber process", "isothermal (k = 1)", "paper, eq. (6) has no heat-capacity ratio"],
            ["piston", "viscous + static friction", "paper, eq. (5); the static friction is "
             "left out (no value given)"],
            ["line model", "lumped segments (volume, resistance, inertance)", "workbench; "
             "eq. (4)'s delay L/a and attenuation emerge from it"],
            ["tube bore", f"{prm['lines.diameter'] * 1e3:g} mm", "ASSUMED (6 mm tube)"],
            ["cylinder bore / stroke", f"{prm['cylinder.bore'] * 1e3:g} / "
             f"{prm['cylinder.stroke'] * 1e3:g} mm", "ASSUMED"],
            ["moving mass / viscous friction", f"{prm['load.mass']:g} kg / "
             f"{prm['load.viscous_friction']:g} N s/m", "ASSUMED"],
            ["supply pressure", f"{prm['supply.pressure'] * 1e-5:g} bar abs", "ASSUMED"],
            ["valve sonic conductance", f"{prm['valve.sonic_conductance']:.3g} m^3/(s Pa)",
             "ASSUMED"],
            ["sample time", f"{prm['controller.sample_time'] * 1e3:g} ms", "ASSUMED"],
            ["segments per line", ", ".join(f"{L:g} m: {p.segments}" for L, p in pls.items()),
             "workbench (about 0.25 m each; 0.5 m on the 10 m line in quick mode)"]]
    return rp.Section("The paper's configuration and what is assumed", [
        rp.Paragraph("Paper 001 gives the model's form, the two line lengths and the valve's "
                     "Cv, but no sizes of the drive. Every number its text prints: Cv = 0.274 "
                     "and X_T = 1 (eq. 2, with the constant 8.6e-8), the line lengths 1 m and "
                     "10 m (Sec. 'Experimental study') and the 0.4 s (after Fig. 9); eqs. (1) to "
                     "(6) carry symbols only and the figures' values are not in the text. None "
                     "fixes the cylinder, load, supply, tube bore, setpoint steps, sample time "
                     "or gains. The Cv is not used: eq. (2) as printed, with (1 - X/X_T) and "
                     "X_T = 1, gives zero flow at the largest pressure drop (X = 1) instead of "
                     "choked flow, so it has no consistent reading as an ISO 6358 conductance. "
                     "The plant file designs/plants/papers/iliev_lines_1m.toml marks every "
                     "assumed value."),
        rp.Table(["item", "value", "source"], rows, caption="Configuration"),
    ])


def _lines_section(steps: dict) -> rp.Section:
    rows = [[f"{L:g} m", f"{st['delay'] * 1e3:.1f}", f"{L / A_SOUND * 1e3:.1f}",
             f"{st['peak_rate'] * 1e-5:.1f}", f"{st['peak_flow'] * 1e3:.2f}"]
            for L, st in steps.items()]
    return rp.Section("Pressure and flow delay and attenuation (Figs. 6 to 9)", [
        rp.Paragraph(
            "Open loop, piston at rest at mid-stroke, valve stepped from 5 to 8 V. Delay: time "
            f"until chamber a has risen {DELAY_THRESHOLD * 1e-3:g} kPa. Attenuation: the peak "
            "mass flow into the chamber and the peak rate of rise of its pressure (the line's "
            "resistance and volume smooth the front). Eq. (4) of the paper: the flow arrives "
            "delayed by L_t/a_s and attenuated by exp(-R_r L_t / (2 rho a_s)). The 10 m line "
            "also halves the flow it settles at (its resistance), which is what slows the "
            "piston."),
        rp.Table(["line", "delay, measured", "L / a (a = 343 m/s)", "peak dp_a/dt",
                  "peak flow into a"], rows, units=["", "ms", "ms", "bar/s", "g/s"],
                 caption="Chamber response to a valve step"),
        rp.Figure(fig_lines(steps), "Chamber pressures and the mass flows at the chamber ends "
                  "of the lines after a valve step, 1 m (solid) and 10 m (dashed) lines (the "
                  "workbench's Figs. 6 to 9)"),
    ])


def _metric(v, item: str) -> float:
    """A validation check's value in the units of its report table (%, s, mm)."""
    return float(next((val for it, val, *_ in v.table() if it == item), "nan"))


def _pid_section(pid, info, vals, compare, tries) -> rp.Section:
    rows = []
    for (item, val1, lim, unit, ok1), (_, val10, _, _, ok10) in zip(vals[1.0].table(),
                                                                     vals[10.0].table()):
        rows.append([item, lim, unit, val1, ok1 == "pass", val10, ok10 == "pass"])
    items = ("overshoot", "settling time", "steady-state error")
    crow = [[name] + [f"{_metric(v, it):.2f}" for it in items]
            + [v.passed, ", ".join(c.name for c in v.failed) or "-"] for name, v in compare.items()]
    off = compare["PD, valve null offset"]
    return rp.Section("PID designed by the workbench, validated on both lines", [
        rp.Paragraph(
            f"Designed on the 10 m drive (the harder one) from its exact tangent model at "
            f"mid-stroke: Kv = {info['kv']:.3f} m/(V s), w0 = {info['w0']:.1f} rad/s, zeta = "
            f"{info['zeta']:.2f} (third-order fit error {info['fit_error']:.2f}: the line adds "
            f"modes). Exact sampled-data P limit {info['limit']:.1f} 1/s; K0 = limit / "
            f"{GAIN_MARGIN:g} = {info['k0']:.2f} 1/s; derivative zero at w0; Ti = the "
            f"specification's settling time / {TI_SETTLING:g} = {info['ti']:.3f} s (an "
            f"offset decays to e^-4 = 1.8 % within it). Gains after {len(tries)} "
            f"validation round(s): kp = {pid.kp:.3f} V/m, kd = {pid.kd:.4f} V s/m, ki = "
            f"{pid.ki:.3f} V/(m s). The integral is frozen while the command saturates and "
            f"while |e| > {pid.integral_band * 1e3:g} mm (integral separation): the drive "
            "integrates and carries no constant load, so it rests at the valve's null and the "
            "integral must end each step where it began; the error area it collects on the "
            "way comes back as overshoot and a slow tail. Collected only near the setpoint, "
            "that area is small (table below: without the band the same gains fail)."),
        rp.Table(["item", "limit", "unit", "1 m", "1 m verdict", "10 m", "10 m verdict"], rows,
                 caption="Validation of the PID on the paper's setpoint steps"),
        rp.Figure(plots.compare_figure([vals[1.0], vals[10.0]], ["1 m lines", "10 m lines"],
                                       title="PID on 1 m and 10 m lines"),
                  "Position, command and chamber pressures with 1 m and 10 m lines (the "
                  "workbench's Figs. 5, 6, 7)"),
        rp.Paragraph(
            "What the integral is for: a valve whose zero-flow command is not the "
            f"controller's centre (here {NULL_OFFSET:g} V above it, ASSUMED) makes a PD loop rest "
            f"where kp e = offset, {NULL_OFFSET / pid.kp * 1e3:.1f} mm short (measured: "
            f"{_metric(off, 'steady-state error'):.2f} mm mean at the hold ends); the PID removes it."),
        rp.Table(["controller (10 m lines)", "overshoot", "settling time", "steady-state error",
                  "passed", "failed items"], crow, units=["", "%", "s", "mm", "", ""],
                 caption="PID against PD and against the PID without its band, 10 m drive"),
    ])


def _transient_section(td, bores, pls) -> rp.Section:
    rows = [[i + 1] + [f"{v:.3f}" for v in (a, b, b - a, c, d, d - c)] for i, (a, b, c, d)
            in enumerate(zip(td["half_1m"], td["half_10m"], td["settle_1m"], td["settle_10m"]))]
    prm = pls[1.0].params
    return rp.Section("Position transients: 1 m against 10 m (Fig. 5)", [
        rp.Paragraph(
            "The paper: 'the time of the transition process differs by 0.4 s' and reads it as "
            "'a signal delay'. Measured per setpoint step: the time until the piston has "
            "covered half the step (the shift of the transient) and the settling time into the "
            f"validation's band. Mean shift {td['shift']:.3f} s, mean settling difference "
            f"{td['settling']:.3f} s (the PID's damping makes the settling times close even "
            "where the curves are shifted)."),
        rp.Table(["step", "half-way 1 m", "half-way 10 m", "shift", "settling 1 m",
                  "settling 10 m", "difference"], rows, units=["", "s", "s", "s", "s", "s", "s"],
                 caption="Transient of each setpoint step"),
        rp.Table(["tube bore", "setpoint steps", "pressure delay 10 m - 1 m", "transient shift",
                  "settling difference", "PID validated on both"],
                 [[f"{b['diameter'] * 1e3:g}", "as above" if b["step"] is None else
                   f"{b['step'] * 1e3:g} mm up and back", f"{b['delay'] * 1e3:.1f}",
                   f"{b['shift']:.3f}", f"{b['settling']:.3f}", b["passed"]] for b in bores],
                 units=["mm", "", "ms", "s", "s", ""],
                 caption=f"The same PID with other tube bores (the plant file's: "
                         f"{prm['lines.diameter'] * 1e3:g} mm) and step sizes; the paper gives "
                         "neither"),
    ])


def _results(steps, td, vals) -> list[dict]:
    d_paper = (PAPER["lengths"][0][1] - PAPER["lengths"][0][0]) / A_SOUND
    d_wb = steps[10.0]["delay"] - steps[1.0]["delay"]
    ratio = steps[10.0]["peak_flow"] / steps[1.0]["peak_flow"]
    both = all(v.passed for v in vals.values())
    shift = td["shift"]
    return [
        _row("pressure delay, 10 m line against 1 m", round(d_paper, 4), d_wb, "s",
             "derived from eq. (4), f(t - L_t/a_s), with a_s = 343 m/s (physics.md): 9 m / a_s",
             f"valve step, time until chamber a rises {DELAY_THRESHOLD * 1e-3:g} kPa, 10 m minus "
             f"1 m; agrees within {DELAY_TOL * 1e3:g} ms (the lumped line smears the front over "
             "a few segments)", abs(d_wb - d_paper) <= DELAY_TOL),
        _row("amplitude decay with the longer line", "yes (qualitative)", ratio, "-",
             PAPER["effects"][2], "peak mass flow into chamber a after a valve step (eq. 4 "
             "attenuates the flow), 10 m over 1 m; agrees when below 1", ratio < 1.0),
        _row("position transient later with 10 m lines", "yes (Figs. 5, 5a)", shift, "s",
             "Figs. 5, 5a", "mean shift of the half-way time over the setpoint steps; agrees "
             "when above 0", shift > 0),
        _row("transition time difference, 10 m minus 1 m", PAPER["dt"][0], shift, "s",
             PAPER["dt"][2], f"PID loop on the paper's uniform setpoint steps, mean shift of the "
             f"half-way time; agrees within {DT_TOL:g} s (the drive's sizes are assumed; see the "
             "tube-bore table)", abs(shift - PAPER["dt"][0]) <= DT_TOL),
        _row("PID positioning works with both line lengths", "yes (Figs. 5, 5a)",
             "validated on both" if both else "not validated on both", "",
             "Figs. 5, 5a", "one PID designed by the workbench, workbench.validate on the "
             "setpoint steps with both lines; agrees when both pass", both),
    ]


def _row(result, paper, workbench, unit, source, how, agrees) -> dict:
    return {"result": result, "paper": paper, "workbench": workbench, "unit": unit,
            "source": source, "how": how, "agrees": bool(agrees)}


def _cell(v) -> str:
    return f"{v:.4g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v)


def _results_section(results) -> rp.Section:
    n_ok = sum(r["agrees"] for r in results)
    return rp.Section("Paper 001's results beside the workbench", [
        rp.Table(["result", "paper", "workbench", "unit", "source in the paper", "how obtained",
                  "agrees?"],
                 [[r["result"], _cell(r["paper"]), _cell(r["workbench"]), r["unit"], r["source"],
                   r["how"], r["agrees"]] for r in results],
                 caption="Paper 001 row by row: paper value | workbench value | how obtained "
                         "| agrees?"),
        rp.Paragraph(f"{n_ok} of {len(results)} rows agree. Paper values are quoted at the place "
                     "given; the delay is derived from the paper's eq. (4) with physics.md's "
                     "speed of sound. Disagreements are taken up below."),
    ])


def _disagreement_section(results, steps, td, bores) -> rp.Section:
    bad = [r["result"] for r in results if not r["agrees"]]
    blocks = [rp.Paragraph("Rows that do not agree: " + ("; ".join(bad) if bad else "none") + ".")]
    if any(r.startswith(("transition time", "position transient")) for r in bad):
        steps_ = [b for b in bores if b["step"] is not None]
        bores = [b for b in bores if b["step"] is None]
        near = min(bores, key=lambda b: abs(b["shift"] - PAPER["dt"][0])) if bores else None
        blocks.append(rp.Paragraph(
            f"Transient shift {td['shift']:.3f} s against the paper's 0.4 s. The transport delay "
            f"of 9 m of line is only {9 / A_SOUND * 1e3:.0f} ms; the rest comes from the line's "
            "resistance and volume, set by the tube bore and by the drive's flow demand (bore, "
            "load, supply) and on the size of the setpoint steps, none of which the paper "
            "gives. Measured with the same PID on the same steps: "
            + "; ".join(f"{b['diameter'] * 1e3:g} mm bore: shift {b['shift']:.2f} s"
                        for b in bores)
            + (f". The paper's 0.4 s is closest with a {near['diameter'] * 1e3:g} mm bore "
               f"({near['shift']:.2f} s): the paper's rig likely had narrower tubes than "
               "assumed here" if near else "")
            + "".join(f"; with single {b['step'] * 1e3:g} mm steps (assumed bore) the shift is "
                      f"{b['shift']:.2f} s" for b in steps_)
            + ": the shift grows with the step size. The paper's numbers fix neither."))
    if any(r.startswith("pressure delay") for r in bad):
        blocks.append(rp.Paragraph(
            f"Measured delays: 1 m {steps[1.0]['delay'] * 1e3:.1f} ms, 10 m "
            f"{steps[10.0]['delay'] * 1e3:.1f} ms; the 1 kPa threshold adds the time the front "
            "needs to build up behind a lumped line."))
    if any(r.startswith("PID positioning") for r in bad):
        blocks.append(rp.Paragraph("The PID did not pass the validation on both lines after "
                                   f"{TRIES} gain reductions; see the validation table."))
    return rp.Section("Disagreements and their measured causes", blocks)


def _finish(out, results, steps, pid, info, vals, td, bores, done, t_start, quick,
            compare) -> int:
    n_ok = sum(r["agrees"] for r in results)
    status = rp.Status("PASS" if n_ok == len(results) else "FAIL",
                       f"{n_ok} of {len(results)} paper results agree")
    doc = rp.Report(TITLE, subtitle="Line delay and attenuation, PID on 1 m and 10 m lines",
                    status=status, sections=list(done),
                    provenance=rp.provenance(plant_file=PLANT, command_line=" ".join(sys.argv)))
    html, pdf = rp.write(doc, out)
    summary = {
        "paper": "001", "quick": bool(quick), "paper_results": results,
        "delays_s": {f"{L:g}": st["delay"] for L, st in steps.items()},
        "peak_rate_pa_s": {f"{L:g}": st["peak_rate"] for L, st in steps.items()},
        "peak_flow_kg_s": {f"{L:g}": st["peak_flow"] for L, st in steps.items()},
        "pid": {"kp": pid.kp, "kd": pid.kd, "ki": pid.ki, "sample_time": pid.sample_time,
                "integral_band": pid.integral_band},
        "integral_comparison": {k: {"passed": v.passed, "failed": [c.name for c in v.failed],
                                    "steady_state_error_mm": _metric(v, "steady-state error")}
                                for k, v in compare.items()},
        "design": info, "validation": {f"{L:g}": v.to_dict() for L, v in vals.items()},
        "transients_s": {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                         for k, v in td.items()},
        "tube_bore_sweep": bores, "run_time_s": time.perf_counter() - t_start,
    }
    plain = json_safe(json.loads(json.dumps(summary, default=rp.json_default)))
    atomic_write_text(out / "summary.json", json.dumps(plain, indent=1, allow_nan=False) + "\n")
    print(f"paper 001: {n_ok} of {len(results)} paper results agree")
    print(f"  report: {html}\n          {pdf}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
