"""Figures, report sections and summary of designs/paper_001.py (the report part)."""

from __future__ import annotations

import sys
import time

import numpy as np

from workbench import plots
from workbench import report as rp
from paper_001 import (A_SOUND, BAND_FLOORS, DELAY_THRESHOLD, DELAY_TOL, DT_INTERVAL, GAIN_MARGIN,
                       HOLD, NULL_OFFSET, PAPER, PLANT, STEP, TI_SETTLING, TITLE, TRANSIENT_BAND,
                       TRIES, eq4_attenuation)

#: Tube bores of common polyurethane tubing, m: about 2 mm (3 mm outside diameter) to
#: 6 mm (8 mm), the lower end 10 % below 2 mm (the fitted bore 'is a real tube' inside).
TUBE_RANGE = (0.0018, 0.006)


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


def fig_fit(fit: dict):
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.0, 3.4))
    g = fit["grid"]
    d = np.array([r["diameter"] for r in g]) * 1e3
    for key, lab, ls in (("dt", f"transition time (+-{TRANSIENT_BAND * 100:g} % band)", "o-"),
                         ("dt2", "settling time (+-2 % band)", "s--"),
                         ("shift", "half-way time", "^:")):
        y = np.array([r[key] for r in g])
        ok = np.isfinite(y)
        ax.plot(d[ok], y[ok], ls, label=lab)
    ax.axhspan(*DT_INTERVAL, color="grey", alpha=0.25, label="paper: 0.4 s (0.35 .. 0.45)")
    if fit["d"] is not None:
        ax.axvline(fit["d"] * 1e3, color="k", lw=0.8, label=f"fitted bore {fit['d'] * 1e3:.2f} mm")
    ax.set_xscale("log")
    ax.set_xticks([1.6, 2, 2.5, 3, 4, 6])
    ax.set_xticklabels(["1.6", "2", "2.5", "3", "4", "6"])
    ax.set_xlabel("tube bore [mm]")
    ax.set_ylabel("10 m minus 1 m [s]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return fig


def _mm(v) -> str:
    return "-" if v is None else f"{v * 1e3:.2f}"


def config_section(pls: dict, valve: tuple, fit: dict) -> rp.Section:
    prm = pls[1.0].params
    c, b, dev = valve
    rows = [["line lengths", "1 and 10 m", "paper (Sec. 'Experimental study')"],
            ["valve sonic conductance C", f"{c:.4g} m^3/(s Pa) (file: "
             f"{prm['valve.sonic_conductance']:.4g})",
             "DERIVED from eq. (2)'s Cv = 0.274, X_T = 1"],
            ["valve critical ratio b", f"{b:.3f} (file: {prm['valve.critical_pressure_ratio']:g})",
             f"DERIVED: ISO ellipse nearest eq. (2)'s shape (within {dev:.1%} of choked flow)"],
            ["chamber process", "isothermal (k = 1)", "paper, eq. (6) has no heat-capacity ratio"],
            ["piston", "viscous + static friction", "paper, eq. (5); the static friction is "
             "left out (no value given)"],
            ["line model", "lumped segments (volume, resistance, inertance)", "workbench; "
             "eq. (4)'s delay L/a and attenuation emerge from it"],
            ["tube bore", f"{_mm(fit['d'])} mm [{_mm(fit['lo'])}, {_mm(fit['hi'])}]",
             "ESTIMATED from the paper's 0.4 s (below); the file: "
             f"{plant_file_bore():g} mm"],
            ["setpoint steps", f"uniform {STEP * 1e3:g} mm, held {HOLD:g} s", "ASSUMED (paper: "
             "uniform steps within the stroke)"],
            ["controller", "one PID tuned on the 1 m drive, both runs", "paper: 'identical "
             "conditions'; tuning rule: workbench"],
            ["cylinder bore / stroke", f"{prm['cylinder.bore'] * 1e3:g} / "
             f"{prm['cylinder.stroke'] * 1e3:g} mm", "ASSUMED"],
            ["moving mass / viscous friction", f"{prm['load.mass']:g} kg / "
             f"{prm['load.viscous_friction']:g} N s/m", "ASSUMED"],
            ["supply pressure", f"{prm['supply.pressure'] * 1e-5:g} bar abs", "ASSUMED"],
            ["sample time", f"{prm['controller.sample_time'] * 1e3:g} ms", "ASSUMED"],
            ["segments per line", ", ".join(f"{L:g} m: {p.segments}" for L, p in pls.items()),
             "workbench (about 0.25 m each; 0.5 m on the 10 m line in quick mode)"]]
    return rp.Section("The paper's configuration and what is assumed", [
        rp.Paragraph(
            "Paper 001's stored text gives the model's form, the two line lengths, the valve's "
            "Cv = 0.274 and X_T = 1 (eq. 2, with the constant 8.6e-8) and the 0.4 s (after "
            "Fig. 9); the figures' values are not in it. Eq. (2) is the ISA/IEC 60534 gas "
            "sizing law with its expansion factor misprinted: as printed, (1 - X/X_T) makes the "
            "flow vanish at X = X_T, where the law chokes; with the standard Y = 1 - X/(3 X_T) "
            "and the law's SI constant (1.156e-6; the printed 8.6e-8 is 13.4x smaller and would "
            "make the valve 13x smaller than its own Cv says) the Cv gives the ISO 6358 "
            f"conductance C = {c:.4g} m^3/(s Pa) = {c * 1e8:.2f} l/(s bar) and b = {b:.3f} "
            "(X_T = 1: the flow keeps rising to x = 1). The tube bore, which sets the line's "
            "resistance and volume, is estimated from the 0.4 s itself; every other value is "
            "ASSUMED and marked so in designs/plants/papers/iliev_lines_1m.toml."),
        rp.Table(["item", "value", "source"], rows, caption="Configuration"),
    ])


def plant_params() -> dict:
    """The plant file's parameters."""
    from workbench import Plant
    return Plant.from_toml(PLANT).params


def plant_file_bore() -> float:
    """The plant file's tube bore, mm."""
    return float(plant_params()["lines.diameter"]) * 1e3


def lines_section(steps: dict, d: float) -> rp.Section:
    rows = [[f"{L:g} m", f"{st['delay'] * 1e3:.1f}", f"{L / A_SOUND * 1e3:.1f}",
             f"{st['peak_rate'] * 1e-5:.1f}", f"{st['peak_flow'] * 1e3:.2f}"]
            for L, st in steps.items()]
    eq4 = eq4_attenuation(d, 9.0, steps[10.0]["p_rest"])
    return rp.Section("Pressure and flow delay and attenuation (Figs. 6 to 9)", [
        rp.Paragraph(
            f"At the fitted bore ({d * 1e3:.2f} mm). Open loop, piston at rest at mid-stroke, "
            f"valve stepped from 5 to 8 V. Delay: time until chamber a has risen "
            f"{DELAY_THRESHOLD:g} Pa. Attenuation: the peak mass flow into the chamber "
            "and the peak rate of rise of its pressure. Eq. (4) of the paper: the flow arrives "
            "delayed by L_t/a_s and attenuated by exp(-R_r L_t / (2 rho a_s)); with the laminar "
            f"R_r = 32 mu / d^2 and rho at the rest pressure ({steps[10.0]['p_rest'] * 1e-5:.2f} "
            f"bar) 9 m more line give a factor {eq4:.2f} on the wave front; the measured peak "
            f"flow ratio is {steps[10.0]['peak_flow'] / steps[1.0]['peak_flow']:.2f}: the peak "
            "also loses what the longer line's volume stores and its resistance holds back. "
            "The tube, not the valve, limits the flow at this bore: up to "
            f"{valve_limit(steps) * 1e3:.1f} "
            f"g/s could pass the valve at 8 V (choked, C p_s rho0 times the 0.6 opening), "
            f"{steps[1.0]['q_a'][-1] * 1e3:.2f} g/s enter chamber a through 1 m of tube at the "
            "step's end."),
        rp.Table(["line", "delay, measured", "L / a (a = 343 m/s)", "peak dp_a/dt",
                  "peak flow into a"], rows, units=["", "ms", "ms", "bar/s", "g/s"],
                 caption="Chamber response to a valve step"),
        rp.Figure(fig_lines(steps), "Chamber pressures and the mass flows at the chamber ends "
                  "of the lines after a valve step, 1 m (solid) and 10 m (dashed) lines (the "
                  "workbench's Figs. 6 to 9)"),
    ])


def valve_limit(steps: dict) -> float:
    """The valve's choked mass flow at line_step's 8 V command, kg/s (physics.md's ISO
    6358 law at the plant file's C and supply: opening (8 - 5) / 5)."""
    from workbench.physics.gas import RHO_ANR
    prm = plant_params()
    return 0.6 * prm["valve.sonic_conductance"] * prm["supply.pressure"] * RHO_ANR


def metric(v, item: str) -> float:
    """A validation check's value in the units of its report table (%, s, mm)."""
    return float(next((val for it, val, *_ in v.table() if it == item), "nan"))


def _num(v) -> str:
    """A validation value with three decimals (one format for the mixed-unit column)."""
    try:
        return f"{float(v):.3f}"
    except (TypeError, ValueError):
        return str(v)


def pid_section(ex: dict, compare: dict) -> rp.Section:
    pid, info, vals, tries = ex["pid"], ex["info"], ex["vals"], ex["tries"]
    rows = []
    for (item, val1, lim, unit, ok1), (_, val10, _, _, ok10) in zip(vals[1.0].table(),
                                                                     vals[10.0].table()):
        rows.append([item, lim, unit, _num(val1), ok1 == "pass", _num(val10), ok10 == "pass"])
    items = ("overshoot", "settling time", "steady-state error")
    crow = [[name] + [f"{metric(v, it):.2f}" for it in items]
            + [v.passed, ", ".join(c.name for c in v.failed) or "-"] for name, v in compare.items()]
    off = compare["PD, valve null offset"]
    return rp.Section("PID designed by the workbench, validated on both lines", [
        rp.Paragraph(
            f"Designed on the 1 m drive (the rig as normally run; the paper then swaps the "
            f"lines under 'identical conditions') from its exact tangent model at mid-stroke: "
            f"Kv = {info['kv']:.3f} m/(V s), w0 = {info['w0']:.1f} rad/s, zeta = "
            f"{info['zeta']:.2f} (third-order fit error {info['fit_error']:.2f}: the line adds "
            f"modes). Exact sampled-data P limit {info['limit']:.1f} 1/s; K0 = limit / "
            f"{GAIN_MARGIN:g} = {info['k0']:.2f} 1/s; derivative zero at w0; Ti = the "
            f"specification's settling time / {TI_SETTLING:g} = {info['ti']:.3f} s. Gains after "
            f"{len(tries)} validation round(s): kp = {pid.kp:.3f} V/m, kd = {pid.kd:.4f} V s/m, "
            f"ki = {pid.ki:.3f} V/(m s). The integral is frozen while the command saturates and "
            f"while |e| > {pid.integral_band * 1e3:g} mm ({BAND_FLOORS:g} x the band floor; "
            "integral separation): the drive integrates and carries no constant load, so the "
            "integral must end each step where it began; collected only near the setpoint, the "
            "error area it returns as overshoot is small (table below: without the band the "
            "same gains fail)."),
        rp.Table(["item", "limit", "unit", "1 m", "1 m verdict", "10 m", "10 m verdict"], rows,
                 caption="Validation of the PID on the paper's setpoint steps"),
        rp.Figure(plots.compare_figure([vals[1.0], vals[10.0]], ["1 m lines", "10 m lines"],
                                       title="PID on 1 m and 10 m lines"),
                  "Position, command and chamber pressures with 1 m and 10 m lines at the "
                  "fitted bore (the workbench's Figs. 5, 6, 7)"),
        rp.Paragraph(
            "What the integral is for: a valve whose zero-flow command is not the "
            f"controller's centre (here {NULL_OFFSET * 1e-3 * pid.kp:.3f} V above it, ASSUMED: "
            f"{NULL_OFFSET:g} mm x kp) makes a PD loop rest where kp e = offset, "
            f"{NULL_OFFSET:g} mm short (measured: "
            f"{metric(off, 'steady-state error'):.2f} mm mean at the hold ends); the PID "
            "removes it."),
        rp.Table(["controller (10 m lines)", "overshoot", "settling time", "steady-state error",
                  "passed", "failed items"], crow, units=["", "%", "s", "mm", "", ""],
                 caption="PID against PD and against the PID without its band, 10 m drive"),
    ])


def _s(v: float) -> str:
    return f"{v:.3f}" if np.isfinite(v) else "not settled"


def _assumption_block(fit: dict):
    """The bore fit with one assumed value changed (full mode), or a line saying so."""
    cases = fit.get("assumptions") or []
    if not cases:
        return rp.Paragraph("The fit's dependence on the assumed drive values (cylinder bore, "
                            "moving mass, supply, viscous friction) is measured in full mode.")
    rows = [["as in the plant file", f"{_mm(fit['d'])} [{_mm(fit['lo'])}, {_mm(fit['hi'])}]"]]
    rows += [[c["case"], f"{_mm(c['d'])} [{_mm(c['lo'])}, {_mm(c['hi'])}]"] for c in cases]
    return rp.Table(["assumed value changed", "bore for 0.4 s [0.35, 0.45 s]"], rows,
                    units=["", "mm"], caption="The tube-bore estimate with one assumed drive "
                    "value changed ('-': outside the grid of 1.2 .. 3.5 mm)")


def transient_section(td: dict, fit: dict, sizes: list, d: float) -> rp.Section:
    rows = [[i + 1] + [_s(v) for v in (a, b, b - a, c, e, e - c)] for i, (a, b, c, e)
            in enumerate(zip(td["settle_1m"], td["settle_10m"], td["half_1m"], td["half_10m"]))]
    grid = [[f"{r['diameter'] * 1e3:.2f}", _s(r["dt"]), _s(r["dt2"]), _s(r["shift"]),
             f"{r['delay'] * 1e3:.1f}", f"{r['flow_ratio']:.2f}", f"{r['eq4']:.2f}",
             f"{r['kp']:.1f}", r["passed"]] for r in fit["grid"]]
    srow = [[f"{s['step'] * 1e3:g}", _s(s["dt"]), _s(s["dt2"]), _s(s["shift"]), s["passed"]]
            + ([f"{_mm(s['fit_d'])} [{_mm(s['fit_lo'])}, {_mm(s['fit_hi'])}]"] if "fit_d" in s
               else []) for s in sizes]
    fitted = any("fit_d" in s for s in sizes)
    return rp.Section("Position transients: 1 m against 10 m (Fig. 5), and the tube bore", [
        rp.Paragraph(
            "The paper: 'the time of the transition process differs by 0.4 s'. The time of "
            f"the transition process is read as the classical settling time into +-"
            f"{TRANSIENT_BAND * 100:g} % of the step; the settling time into 2 % and the time to "
            "half the step (a 'signal delay' reading) are shown beside it. The same "
            "experiment on a grid of tube bores: the PID is retuned on each bore's 1 m drive "
            "and run on both. The bore at which the 10 m drive settles 0.4 s later is "
            "interpolated on the grid; the interval is the bores for 0.35 .. 0.45 s (the "
            f"paper's one significant digit): {_mm(fit['d'])} mm [{_mm(fit['lo'])}, "
            f"{_mm(fit['hi'])}]. Read as the 2 % settling time the same 0.4 s asks for "
            f"{_mm(fit.get('d_dt2'))} mm, read as a shift of the half-way time "
            f"{_mm(fit.get('d_shift'))} mm ('-': not reached on the grid)."),
        rp.Table(["tube bore", "transition time 10 m - 1 m", "2 % settling 10 m - 1 m",
                  "half-way shift", "pressure delay 10 m - 1 m", "peak flow ratio",
                  "eq. (4) factor", "kp", "PID validated on both"], grid,
                 units=["mm", "s", "s", "s", "ms", "-", "-", "V/m", ""],
                 caption="The paper's experiment on a grid of tube bores"),
        rp.Figure(fig_fit(fit), "10 m minus 1 m against the tube bore: the paper's 0.4 s "
                  "(band) fixes the bore"),
        _assumption_block(fit),
        rp.Table(["step", "settling 1 m", "settling 10 m", "difference", "half-way 1 m",
                  "half-way 10 m", "shift"], rows, units=["", "s", "s", "s", "s", "s", "s"],
                 caption=f"Each setpoint step at the fitted bore ({d * 1e3:.2f} mm), +-"
                         f"{TRANSIENT_BAND * 100:g} % band"),
        rp.Table(["single step", "transition time 10 m - 1 m", "2 % settling", "half-way shift",
                  "PID validated on both"] + (["bore for 0.4 s [0.35, 0.45 s]"] if fitted else []),
                 srow, units=["mm", "s", "s", "s", ""] + (["mm"] if fitted else []),
                 caption=f"Single steps up from 50 mm and back at the fitted bore (the staircase: "
                         f"{STEP * 1e3:g} mm steps); the paper gives no step size"
                         + ("; last column: the bore that gives 0.4 s with that step size"
                            if fitted else "")),
    ])


def results(steps, ex, fit, d) -> list[dict]:
    td, vals = ex["td"], ex["vals"]
    d_paper = (PAPER["lengths"][0][1] - PAPER["lengths"][0][0]) / A_SOUND
    d_wb = steps[10.0]["delay"] - steps[1.0]["delay"]
    ratio = steps[10.0]["peak_flow"] / steps[1.0]["peak_flow"]
    both = all(v.passed for v in vals.values())
    fitted = fit["d"] is not None and TUBE_RANGE[0] <= fit["d"] <= TUBE_RANGE[1]
    return [
        row("pressure delay, 10 m line against 1 m", round(d_paper, 4), d_wb, "s",
            "derived from eq. (4), f(t - L_t/a_s), with a_s = 343 m/s (physics.md): 9 m / a_s",
            f"valve step at the fitted bore, time until chamber a rises "
            f"{DELAY_THRESHOLD:g} Pa, 10 m minus 1 m; agrees within {DELAY_TOL * 1e3:g} ms "
            "(the lumped line smears the front over a few segments)",
            abs(d_wb - d_paper) <= DELAY_TOL),
        row("amplitude decay with the longer line", "yes (qualitative)", ratio, "-",
            PAPER["effects"][2], "peak mass flow into chamber a after a valve step (eq. 4 "
            "attenuates the flow), 10 m over 1 m, at the fitted bore; agrees when below 1",
            ratio < 1.0),
        row("position transient later with 10 m lines", "yes (Figs. 5, 5a)", td["shift"], "s",
            "Figs. 5, 5a", "mean shift of the half-way time over the setpoint steps at the "
            "fitted bore; agrees when above 0", td["shift"] > 0),
        row("transition time difference, 10 m minus 1 m", PAPER["dt"][0], td["dt"], "s",
            PAPER["dt"][2], f"settling time into +-{TRANSIENT_BAND * 100:g} % of each "
            f"{STEP * 1e3:g} mm step, 10 m minus 1 m, one PID tuned on the 1 m drive; FITTED: "
            f"the tube bore is estimated from this number ({_mm(fit['d'])} mm), so it agrees "
            "when a bore in the range of real tubes (1.8 .. 6 mm) reproduces it within "
            f"{DT_INTERVAL[0]:g} .. {DT_INTERVAL[1]:g} s",
            fitted and DT_INTERVAL[0] <= td["dt"] <= DT_INTERVAL[1]),
        row("PID positioning works with both line lengths", "yes (Figs. 5, 5a)",
            "validated on both" if both else "not validated on both", "",
            "Figs. 5, 5a", "one PID designed by the workbench, workbench.validate on the "
            "setpoint steps with both lines at the fitted bore; agrees when both pass", both),
    ]


def row(result, paper, workbench, unit, source, how, agrees) -> dict:
    return {"result": result, "paper": paper, "workbench": workbench, "unit": unit,
            "source": source, "how": how, "agrees": bool(agrees)}


def _cell(v) -> str:
    return f"{v:.4g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v)


def results_section(res) -> rp.Section:
    n_ok = sum(r["agrees"] for r in res)
    return rp.Section("Paper 001's results beside the workbench", [
        rp.Table(["result", "paper", "workbench", "unit", "source in the paper", "how obtained",
                  "agrees?"],
                 [[r["result"], _cell(r["paper"]), _cell(r["workbench"]), r["unit"], r["source"],
                   r["how"], r["agrees"]] for r in res],
                 caption="Paper 001 row by row: paper value | workbench value | how obtained "
                         "| agrees?"),
        rp.Paragraph(f"{n_ok} of {len(res)} rows agree. Paper values are quoted at the place "
                     "given; the delay is derived from the paper's eq. (4) with physics.md's "
                     "speed of sound. The 0.4 s is used to estimate the tube bore, so its row "
                     "is a calibration, not a prediction: the test is whether a real tube "
                     "reproduces it and whether the other rows hold on that setup. "
                     "Disagreements are taken up below."),
    ])


def _fit_span(fits: list) -> str:
    """One sentence on the spread of the per-step-size bore fits."""
    ds = [s["fit_d"] for s in fits if s["fit_d"] is not None]
    miss = [f"{s['step'] * 1e3:g} mm" for s in fits if s["fit_d"] is None]
    out = (f"The fitted bore spans {min(ds) * 1e3:.2f} .. {max(ds) * 1e3:.2f} mm over these step "
           "sizes: the paper's 0.4 s fixes the bore only together with the step size"
           if ds else "No step size reaches 0.4 s on the bore grid")
    return out + (f"; not reached on the bore grid with {', '.join(miss)} steps." if miss else ".")


def disagreement_section(res, steps, td, fit, sizes) -> rp.Section:
    bad = [r["result"] for r in res if not r["agrees"]]
    g = {round(r["diameter"] * 1e4): r for r in fit["grid"]}
    prior = g.get(40)
    blocks = [rp.Paragraph("Rows that do not agree: " + ("; ".join(bad) if bad else "none") + ".")]
    text = ("What it takes to reach the paper's 0.4 s, measured. The transport delay of 9 m "
            f"of line is only {9 / A_SOUND * 1e3:.0f} ms; the rest comes from the line's "
            "resistance and volume, set by the tube bore. ")
    if prior is not None:
        text += (f"With the a-priori 4 mm bore the 10 m drive settles {prior['dt']:+.3f} s "
                 f"relative to 1 m (half-way shift {prior['shift']:.3f} s): the paper's 0.4 s "
                 "does not appear. ")
    other = {r["result"]: r["agrees"] for r in res}
    held = [k for k, name in (("pressure delay", "pressure delay, 10 m line against 1 m"),
                              ("attenuation", "amplitude decay with the longer line"),
                              ("the PID's validation on both lines",
                               "PID positioning works with both line lengths"))
            if other.get(name)]
    text += (f"It appears at a {_mm(fit['d'])} mm bore [{_mm(fit['lo'])}, {_mm(fit['hi'])}] "
             "(polyurethane tubes of 3 and 4 mm outside diameter have bores of about 2 and "
             "2.5 mm); "
             + (f"there the {', '.join(held)} agree with the paper (rows above). " if held else
                "there none of the other rows agrees. ")
             + "The fit depends on the step size the paper does not give: at the fitted bore "
             + "; ".join(f"{s['step'] * 1e3:g} mm steps give {_s(s['dt'])} s" for s in sizes)
             + " (the staircase's 100 mm steps: fitted): the tube's flow limit makes large "
             "steps slow on the 10 m line.")
    fits = [s for s in sizes if "fit_d" in s]
    if fits:
        text += (" The bore that gives the paper's 0.4 s with single steps of each size: "
                 + "; ".join(f"{s['step'] * 1e3:g} mm: {_mm(s['fit_d'])} mm "
                             f"[{_mm(s['fit_lo'])}, {_mm(s['fit_hi'])}]" for s in fits)
                 + ". " + _fit_span(fits))
    cases = fit.get("assumptions") or []
    if cases:
        text += (" The drive's assumed values move it as much: "
                 + "; ".join(f"{c['case']}: {_mm(c['d'])} mm" for c in cases)
                 + f" ('-': outside 1.2 .. 3.5 mm). The estimate, {_mm(fit['d'])} mm, is the "
                 "tube for the assumed drive, not a measurement of the paper's tube.")
    blocks.append(rp.Paragraph(text))
    if any(r.startswith("pressure delay") for r in bad):
        blocks.append(rp.Paragraph(
            f"Measured delays: 1 m {steps[1.0]['delay'] * 1e3:.1f} ms, 10 m "
            f"{steps[10.0]['delay'] * 1e3:.1f} ms; the threshold adds the time the front "
            "needs to build up behind a narrow lumped line."))
    if any(r.startswith("PID positioning") for r in bad):
        blocks.append(rp.Paragraph("The PID did not pass the validation on both lines after "
                                   f"{TRIES} gain reductions; see the validation table."))
    return rp.Section("Disagreements and their measured causes", blocks)


def finish(out, res, steps, ex, fit, sizes, valve, compare, done, t_start, quick) -> int:
    n_ok = sum(r["agrees"] for r in res)
    status = rp.Status("PASS" if n_ok == len(res) else "FAIL",
                       f"{n_ok} of {len(res)} paper results agree")
    doc = rp.Report(TITLE, subtitle="Line delay and attenuation, PID on 1 m and 10 m lines",
                    status=status, sections=list(done),
                    provenance=rp.provenance(plant_file=PLANT, command_line=" ".join(sys.argv)))
    html, pdf = rp.write(doc, out)
    pid = ex["pid"]
    summary = {
        "paper": "001", "quick": bool(quick), "paper_results": res,
        "valve": {"sonic_conductance": valve[0], "critical_pressure_ratio": valve[1],
                  "shape_error": valve[2]},
        "tube_bore_fit": fit, "step_sizes": sizes,
        "delays_s": {f"{L:g}": st["delay"] for L, st in steps.items()},
        "peak_rate_pa_s": {f"{L:g}": st["peak_rate"] for L, st in steps.items()},
        "peak_flow_kg_s": {f"{L:g}": st["peak_flow"] for L, st in steps.items()},
        "pid": {"kp": pid.kp, "kd": pid.kd, "ki": pid.ki, "sample_time": pid.sample_time,
                "integral_band": pid.integral_band,
                "null_offset_v": NULL_OFFSET * 1e-3 * ex["pd"].kp},
        "integral_comparison": {k: {"passed": v.passed, "failed": [c.name for c in v.failed],
                                    "steady_state_error_mm": metric(v, "steady-state error")}
                                for k, v in compare.items()},
        "design": ex["info"], "validation": {f"{L:g}": v.to_dict() for L, v in ex["vals"].items()},
        "transients_s": {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                         for k, v in ex["td"].items()},
        "run_time_s": time.perf_counter() - t_start,
    }
    rp.write_summary(out, summary, f"paper 001: {n_ok} of {len(res)} paper results agree", html, pdf)
    return 0
