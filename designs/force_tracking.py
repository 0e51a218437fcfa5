"""Force tracking by pressure-trajectory inversion on the 25 mm rig (issue 5, part 2).

Scenario: the piston rod is locked at mid-stroke by a clamping unit (rod lock) and the
cylinder must apply a prescribed force to it -- a press-fit or test-bench situation.
The lock is modelled as dry friction with a holding force of 1000 N, well above the
245 N the chambers can give, so the piston never moves (the plant's stick model
holds it exactly); the pneumatic force is then what the lock (and the workpiece)
feel.

1. Pressure-trajectory inversion (paper 003, conclusion): for the force profile,
   chamber pressures under three rules for the free pressure level -- constant mean
   pressure, minimum air, and what one 5/3 valve does -- then the mass flows from the
   chamber balance and the commands from the valve inversion.
2. A sampled force controller: feedforward of the planned force rate through the
   inverted valve law, and feedback of the force measured by the chamber pressures.
3. Closed-loop runs on the nominal plant with the controller's own (input-affine)
   valve law, on the rig's four-edge valve, and on the rig with 1 m lines and a valve
   deadband the controller does not know; feedforward alone for comparison.
4. Monte Carlo robustness: both controllers, designed once on the nominal rig, on rigs
   drawn from workbench.robustness.DEFAULT_UNCERTAINTY (with the lock, and with the
   lock, lines and deadband), judged by a force-tracking specification
   (:func:`force_judge`). Reported, not part of the design verdict.

Writes ``reports/force_tracking/report.html`` and ``report.pdf``, ``summary.json``
and the runs as CSV.

Usage: python designs/force_tracking.py [--quick] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from workbench.output import write_json
from workbench import Plant, plots, simulate
from workbench import report as rp
from workbench.controllers.force import (PLAN_RULES, DriveModel, force_tracker,
                                         pressure_plan, smooth_profile)
from workbench.controllers.inversion import ValveInversion
from workbench.errors import InputError, WorkbenchError
from workbench.params import atomic_write_text, json_safe
from workbench.robustness import DEFAULT_UNCERTAINTY, Outcome, monte_carlo

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PLANT = HERE / "plants" / "rig25_mpye.toml"
AFFINE_PLANT = ROOT / "tests" / "data" / "plants" / "input_affine.toml"
TITLE = "Force tracking by pressure-trajectory inversion, 25 mm rig"

#: Rod lock: dry friction holding 1000 N (> the 245 N pneumatic force range).
LOCK = {"friction.coulomb": 1000.0, "friction.static": 1000.0,
        "friction.stribeck_velocity": 0.01}
#: Unmodelled effects of the robustness run: 1 m lines, 0.3 % spool overlap.
EXTRA = {"lines.length": 1.0, "lines.diameter": 0.004, "valve.deadband": 0.003}
X_LOCK = 0.25                 #: m, where the rod is locked
#: rad/s, force-error pole: bandwidth x T = 0.6 keeps 55 % of the error per period.
#: Faster is still better on this rig (see the sweep in the report) up to dead-beat
#: (pi/T = 314 rad/s); 60 rad/s leaves the measured-pressure noise of a real rig,
#: which the model does not have, a gain of 1 - 0.55 = 0.45 per period.
BANDWIDTH = 60.0
#: Bandwidths of the sweep on the rig with lines and deadband (full mode only).
SWEEP = [15.0, 30.0, 60.0, 120.0, 300.0]
#: Force profile (time s, force N): press to 150 N, hold, pull -100 N, hold, a
#: 2 Hz oscillation 20..60 N, release. Cosine blends between the points.
PROFILE = [(0.0, 0.0), (0.3, 0.0), (0.8, 150.0), (1.5, 150.0), (2.0, -100.0), (2.7, -100.0),
           (3.1, 60.0), (3.35, 20.0), (3.6, 60.0), (3.85, 20.0), (4.1, 60.0), (4.6, 0.0),
           (5.0, 0.0)]
QUICK_PROFILE = PROFILE[:6] + [(2.9, 0.0)]
#: Stated accuracy on the nominal plant: largest |F - F*| within 1 % of the profile's
#: force span (250 N -> 2.5 N), RMS within 0.2 %.
MAX_ERROR_FRACTION = 0.01
RMS_ERROR_FRACTION = 0.002
#: Specification of the Monte Carlo judge (:func:`force_judge`): what the rig must
#: deliver on a plant the controller was not designed on, as fractions of the
#: profile's force span (250 N). The nominal bounds above check the inversion against
#: its own model; these are looser and say what a rig engineer would accept:
#: * hold: |F - F*| <= 1 % of the span (2.5 N) on every plateau of the profile, from
#:   HOLD_SETTLE after it is reached to its end -- the force a press-fit or a test bench
#:   is judged on. 0.1 s is six error time constants of the 60 rad/s loop, so a working
#:   loop has settled; the valve's 0.3 % overlap alone (EXTRA) leaves ~1.7 N on the
#:   holds, so a tighter bound would judge the valve, not the controller.
#: * peak: |F - F*| <= 5 % of the span (12.5 N) over the whole run, ramps and the 2 Hz
#:   oscillation included -- no force spike on the part beyond 8 % of the 150 N press
#:   force. The profile has no jumps (cosine blends between its points), so no window
#:   after a profile change is exempt.
#: * RMS: RMS |F - F*| over the run <= 2 % of the span (5 N): the profile's shape is
#:   followed, not only its plateaus (the tracker gives 0.1 N on the nominal rig, 1.8 N
#:   with lines and deadband).
ROBUST_HOLD_FRACTION = 0.01
ROBUST_PEAK_FRACTION = 0.05
ROBUST_RMS_FRACTION = 0.02
HOLD_SETTLE = 0.1             #: s, settling allowed at the start of each plateau
#: Monte Carlo: seed, number of drawn rigs (full / quick mode).
MC_SEED = 2026
MC_DRAWS = 16
MC_DRAWS_QUICK = 2


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smoke mode: shorter profile, fewer runs")
    ap.add_argument("--out", default=str(ROOT / "reports" / "force_tracking"),
                    help="output folder (default reports/force_tracking)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    t_start = time.perf_counter()
    return rp.run_design(TITLE, out, PLANT, lambda done: _design(args, out, done, t_start))




def force_metrics(run, profile) -> dict:
    """Tracking and effort figures of a force run (SI)."""
    t = run.time
    e = run["force"] - profile(t)
    dt = np.diff(t)
    air = float(np.sum(0.5 * (run["q_supply"][1:] + run["q_supply"][:-1]) * dt))
    return {"rms_error": float(np.sqrt(np.mean(e ** 2))), "max_error": float(np.max(np.abs(e))),
            "iae": float(np.sum(0.5 * (np.abs(e[1:]) + np.abs(e[:-1])) * dt)),
            "air_kg": air, "command_tv": float(np.sum(np.abs(np.diff(run["u"])))),
            "x_drift": float(np.max(np.abs(run["x"] - run["x"][0]))),
            "p_min": float(min(run["p_a"].min(), run["p_b"].min())),
            "p_max": float(max(run["p_a"].max(), run["p_b"].max())),
            "duration": float(t[-1])}


def hold_mask(profile, t, settle: float = HOLD_SETTLE) -> np.ndarray:
    """Times ``t`` on a plateau of a :func:`smooth_profile` (two consecutive points with
    the same force), ``settle`` s after the plateau is reached."""
    pts = profile.points
    mask = np.zeros(np.shape(t), dtype=bool)
    for (t0, f0), (t1, f1) in zip(pts[:-1], pts[1:]):
        if f0 == f1:
            mask |= (t >= t0 + settle) & (t <= t1)
    return mask


def force_judge(profile, x_lock: float = X_LOCK):
    """Judge for :func:`workbench.robustness.monte_carlo`: ``judge(plant, controller)``
    runs the force profile on the locked plant and returns an Outcome.

    Checks (bounds in N from the ROBUST_* fractions of the profile's span): "hold
    error", "peak error", "RMS error"; a run that does not complete fails "simulation".
    Score: RMS |F - F*| in N. ``judge.bounds`` holds the bounds.
    """
    t = np.arange(0.0, profile.duration + 1e-9, 1e-3)
    ref = profile(t)
    span = float(np.ptp(ref))
    hold = hold_mask(profile, t)
    bounds = {"hold error": ROBUST_HOLD_FRACTION * span, "peak error": ROBUST_PEAK_FRACTION * span,
              "RMS error": ROBUST_RMS_FRACTION * span}

    def judge(plant, controller) -> Outcome:
        try:
            run = simulate.closed_loop(plant, controller, profile, t_end=profile.duration,
                                       x0=plant.initial_state(x_lock), output_times=t)
        except InputError:
            raise                   # a set-up error, the same on every draw: not a failure
        except (WorkbenchError, RuntimeError, ArithmeticError) as exc:
            return Outcome(False, ("simulation",), math.nan, f"{type(exc).__name__}: {exc}")
        e = np.asarray(run["force"]) - ref
        if not np.all(np.isfinite(e)):
            return Outcome(False, ("simulation",), math.nan, "the force is not finite")
        got = {"hold error": float(np.max(np.abs(e[hold]))) if hold.any() else 0.0,
               "peak error": float(np.max(np.abs(e))),
               "RMS error": float(np.sqrt(np.mean(e ** 2)))}
        failed = tuple(k for k, b in bounds.items() if not got[k] <= b)
        return Outcome(not failed, failed, got["RMS error"])

    judge.bounds = bounds
    return judge


def _design(args, out: Path, done: list, t_start: float) -> int:
    quick = args.quick
    # figure resolution: lower in quick mode, where rendering dominates a smoke run
    dpi = 60 if quick else 170

    def _figure(fig, caption: str):
        return rp.Figure(fig, caption, dpi=dpi)
    profile = smooth_profile(QUICK_PROFILE if quick else PROFILE)
    duration = profile.duration
    with rp.step("plants"):
        rig = Plant.from_toml(PLANT)
        prm = rig.params
        T = prm["controller.sample_time"]
        locked = rig.with_params(**LOCK)
        affine_locked = Plant.from_toml(AFFINE_PLANT).with_params(**LOCK)
        extra = dict(EXTRA, **({"lines.segments": 1} if quick else {}))
        locked_extra = locked.with_params(**extra)
        model = DriveModel.from_plant(rig, valve=ValveInversion.from_plant(rig, law="input_affine"))
        f_lo, f_hi = model.force_range
        done.append(rp.Section("Scenario", [
            rp.Paragraph(
                "The rod of the 25 mm rodless rig is locked at mid-stroke by a clamping unit and "
                "the cylinder must press on it with a prescribed force: press to 150 N, hold, "
                "pull with 100 N, hold, a 2 Hz oscillation between 20 and 60 N, release. The lock "
                "is modelled as dry friction with a holding force of 1000 N (more than the "
                f"{f_hi:.0f} N the chambers can give), which the plant's stick model holds "
                "exactly: the piston does not move and the pneumatic force is the force on the "
                "lock. The plant files have no external spring, so a friction lock is the "
                "simplest physical clamp. The force is measured through the chamber pressures, "
                "F = p_a A_a - p_b A_b - p_atm (A_a - A_b)."),
            rp.KeyValues([
                ("plant file", str(PLANT.relative_to(ROOT))),
                ("piston area", rig.area_a * 1e4, "cm^2"),
                ("lock position", X_LOCK * 1e3, "mm"),
                ("chamber volumes there", f"{model.volumes(X_LOCK)[0] * 1e6:.1f} / "
                                          f"{model.volumes(X_LOCK)[1] * 1e6:.1f} cm^3"),
                ("pneumatic force range", f"{f_lo:.1f} .. {f_hi:.1f} N"),
                ("sample time", T * 1e3, "ms"),
                ("controller's valve law", model.valve.describe()),
            ]),
        ]))

    with rp.step("pressure plans"):
        tp = np.arange(0.0, duration + 1e-9, 1e-3)
        plans = {rule: pressure_plan(model, tp, profile, x=X_LOCK, rule=rule) for rule in PLAN_RULES}
        rows = []
        for rule, plan in plans.items():
            s = plan.to_dict()
            rows.append([rule, s["p_min"] / 1e5, s["p_max"] / 1e5, s["level_min"] / 1e5,
                         s["level_max"] / 1e5, s["q_max"] * 1e3, s["air_mass"] * 1e3,
                         round(s["command_mismatch"], 6),   # to 1 uV: 8.9e-16 V is 0
                         "yes" if s["command_mismatch"] < 1e-6 else "no (two valves)",
                         plan.feasible])
        done.append(rp.Section("Pressure-trajectory inversion", [
            rp.Paragraph(
                "A force fixes p_a A_a - p_b A_b; the pressure level (p_a + p_b)/2 is free only "
                "if each chamber has its own valve. 'mean' keeps the level at the valve's balance "
                f"pressure ({model.balance_pressure() / 1e5:.2f} bar, equal fill and exhaust "
                "authority: constant air-spring stiffness); 'min_air' keeps the lower chamber at "
                f"{plans['min_air'].info['floor'] / 1e5:.2f} bar (10 % of the range above "
                "atmosphere, where the exhaust edge still has authority) and lets the other carry "
                "the force; 'single_valve' is what the rig's one 5/3 valve can do: its spool fills "
                "one chamber while it exhausts the other, so the level is not free but follows "
                "from the valve law (the force's zero dynamics), integrated along the profile. "
                "For each plan the chamber balance gives the mass flows, "
                "q = (V dp/dt / k + p dV/dt)/(r T), and the valve inversion the commands of port "
                "A for chamber a and port B for chamber b. Only the single-valve plan needs the "
                "same command for both (mismatch 0); the others need one valve per chamber. "
                "With the rod locked the air drawn per force cycle is the same for every level "
                "(the supply only replaces what a force change moves between the chambers and "
                "the exhaust); the level sets the air stored and the stiffness."),
            rp.Table(["rule", "p min", "p max", "level min", "level max", "largest |q|",
                      "air drawn", "command mismatch a/b", "one 5/3 valve", "feasible"],
                     rows, units=["", "bar", "bar", "bar", "bar", "g/s", "g", "V", "", ""],
                     caption="Pressure plans for the force profile at the lock position"),
            _figure(plots.pressure_plan_figure(plans, [("force [N]", tp, profile(tp), "force F*")],
                                                title="Pressure-trajectory inversion: plans for the force profile"), "Force profile and the planned chamber "
                                                    "pressures and commands of the three rules"),
        ]))

    with rp.step("closed loop"):
        ctrl = force_tracker(rig, BANDWIDTH, preview=profile, model=model)
        ff_only = force_tracker(rig, 1e-6, preview=profile, model=model)
        cases = [("nominal affine plant", affine_locked, ctrl),
                 ("rig (four-edge valve)", locked, ctrl)]
        if not quick:
            cases += [("rig + 1 m lines + deadband", locked_extra, ctrl),
                      ("rig, feedforward only", locked, ff_only)]
        sv_plan = plans["single_valve"]
        out_t = np.arange(0.0, duration + 1e-9, 1e-3)
        runs, mets, errors = {}, {}, {}
        for name, plant, c in cases:
            x0 = plant.initial_state(X_LOCK)
            try:
                run = simulate.closed_loop(plant, c, profile, t_end=duration, x0=x0,
                                           output_times=out_t)
            except WorkbenchError as exc:
                errors[name] = str(exc)
                print(f"    {name}: simulation failed: {exc}")
                continue
            runs[name] = run
            mets[name] = force_metrics(run, profile)
            slug = "".join(ch if ch.isalnum() else "_" for ch in name).strip("_")
            run.to_pandas()[["u", "x", "p_a", "p_b", "force", "q_supply", "r"]].rename(
                columns={"r": "force_ref"}).to_csv(out / f"run_{slug}.csv")
            print(f"    {name}: RMS {mets[name]['rms_error']:.3f} N, max {mets[name]['max_error']:.3f} N")
        span = float(np.ptp(profile(out_t)))
        nominal = mets.get("nominal affine plant")
        ok_nominal = bool(nominal and nominal["max_error"] <= MAX_ERROR_FRACTION * span
                          and nominal["rms_error"] <= RMS_ERROR_FRACTION * span)
        plan_dev = {}
        for name, run in runs.items():
            pa_plan = np.interp(run.time, sv_plan.time, sv_plan.p_a)
            plan_dev[name] = float(np.max(np.abs(run["p_a"] - pa_plan)))
        table = [[name, m["rms_error"], m["max_error"], m["iae"], m["air_kg"] * 1e3,
                  m["command_tv"], m["x_drift"] * 1e3, plan_dev[name] / 1e5]
                 for name, m in mets.items()]
        blocks = [
            rp.Paragraph(
                "Controller (workbench.controllers.force.ForceTracker), every T = 10 ms: the force "
                "F_k from the measured pressures; the wanted force change over the next period "
                "F*(t_k+1) - F*(t_k) from the planned profile (feedforward) plus the fraction "
                f"1 - exp(-{BANDWIDTH:g} T) of the error F*(t_k) - F_k (feedback, error pole at "
                f"-{BANDWIDTH:g} rad/s; bandwidths beyond the Nyquist frequency pi/T are refused); the valve "
                "characteristic from the force-rate model dF/dt = f0 + g(sgn G) G at the measured "
                "pressures, and the command from the inverted valve law. 'Feedforward only' "
                "keeps the inversion at the measured pressures but drops the error term."),
            rp.Table(["plant", "RMS |F - F*|", "max |F - F*|", "IAE", "air drawn",
                      "command activity", "piston drift", "max |p_a - single-valve plan|"],
                     table, units=["", "N", "N", "N s", "g", "V", "mm", "bar"],
                     caption="Force tracking on the locked rod"),
            rp.Status("PASS" if ok_nominal else "FAIL",
                      f"nominal plant: max error {nominal['max_error']:.3f} N <= "
                      f"{MAX_ERROR_FRACTION * span:.2f} N and RMS {nominal['rms_error']:.3f} N <= "
                      f"{RMS_ERROR_FRACTION * span:.2f} N (1 % / 0.2 % of the {span:.0f} N span)"
                      if nominal else "the nominal run did not complete"),
        ]
        for name, msg in errors.items():
            blocks.append(rp.Status("FAIL", f"{name}: simulation failed: {msg}"))
        if not quick:
            sweep_rows = []
            for lam in rp.progress(SWEEP, "bandwidth sweep"):
                c = force_tracker(rig, lam, preview=profile, model=model)
                try:
                    r_s = simulate.closed_loop(locked_extra, c, profile, t_end=duration,
                                               x0=locked_extra.initial_state(X_LOCK),
                                               output_times=out_t)
                except WorkbenchError as exc:
                    sweep_rows.append([lam, lam * T, None, None, None, f"failed: {exc}"])
                    continue
                m_s = force_metrics(r_s, profile)
                sweep_rows.append([lam, lam * T, m_s["rms_error"], m_s["max_error"],
                                   m_s["command_tv"], ""])
            blocks.append(rp.Table(["bandwidth", "bandwidth x T", "RMS |F - F*|", "max |F - F*|",
                                    "command activity", "note"], sweep_rows,
                                   units=["rad/s", "-", "N", "N", "V", ""],
                                   caption="Bandwidth sweep on the rig with 1 m lines and deadband"))
        if runs:
            blocks.append(_figure(_runs_figure(runs, profile, sv_plan),
                                    "Force and its error, chamber pressures (with the "
                                    "single-valve plan) and commands of the closed-loop runs"))
        done.append(rp.Section("Force tracking in closed loop", blocks))

    with rp.step("robustness (Monte Carlo)"):
        t_mc = time.perf_counter()
        judge = force_judge(profile)
        n_mc = MC_DRAWS_QUICK if quick else MC_DRAWS
        # built once on the nominal rig: the controllers do not know the drawn plant
        mc_ctrls = {"tracker (FF + FB)": lambda p: ctrl, "feedforward only": lambda p: ff_only}
        mc_plants = {"locked rig": locked, "locked rig + lines + deadband": locked_extra}
        # the same seed draws the same factors on both plant variants (common random numbers)
        mc = {pname: monte_carlo(plant, mc_ctrls, n=n_mc, seed=MC_SEED,
                                 uncertainty=DEFAULT_UNCERTAINTY, judge=judge,
                                 workers=1 if quick else None, progress=True)
              for pname, plant in mc_plants.items()}
        # the undrawn plants, for reference
        mc_nominal = {(pname, cname): judge(plant, make(plant))
                      for pname, plant in mc_plants.items() for cname, make in mc_ctrls.items()}
        t_mc = time.perf_counter() - t_mc
        mc_rows = []
        for pname, res in mc.items():
            for cname, rate, runs_n, med, worst_s, check in res.table():
                lo, hi = res.pass_interval(cname)
                nom = mc_nominal[(pname, cname)]
                mc_rows.append([cname, pname, f"{sum(res.passed[cname])}/{runs_n}",
                                f"{rate * 100:.0f} % ({lo * 100:.0f} .. {hi * 100:.0f} %)",
                                med, worst_s, check or "-",
                                "PASS" if nom.passed else "FAIL: " + ", ".join(nom.failed)])
                print(f"    {cname}, {pname}: pass {rate * 100:.0f} % "
                      f"[{lo * 100:.0f}..{hi * 100:.0f} %], RMS median {med:.3f} N, worst {worst_s:.3f} N")
        print(f"    Monte Carlo: {2 * n_mc * len(mc_ctrls)} runs in {t_mc:.1f} s")
        nom_prm = rig.params
        ranges = "; ".join([
            f"polytropic index {DEFAULT_UNCERTAINTY[0].low:g} .. {DEFAULT_UNCERTAINTY[0].high:g} "
            f"(nominal {nom_prm['gas.polytropic_index']:g})",
            f"sonic conductance x{DEFAULT_UNCERTAINTY[1].low:g} .. x{DEFAULT_UNCERTAINTY[1].high:g}",
            f"moving mass x{DEFAULT_UNCERTAINTY[2].low:g} .. x{DEFAULT_UNCERTAINTY[2].high:g}",
            f"supply pressure {nom_prm['supply.pressure'] / 1e5:g} bar "
            f"{DEFAULT_UNCERTAINTY[3].low / 1e5:+g} .. {DEFAULT_UNCERTAINTY[3].high / 1e5:+g} bar"])
        b = judge.bounds
        mc_blocks = [
            rp.Paragraph(
                f"Both controllers of the closed-loop section, built once on the nominal rig (they "
                f"do not know the drawn plant), run the force profile on {n_mc} rigs drawn "
                f"uniformly (seed {MC_SEED}; the same draws for both controllers and both plant "
                f"variants) from the workbench's default ranges: {ranges}. The plants are the "
                "rig with the rod lock, and the same with the 1 m lines and the valve deadband "
                "of the closed-loop section. A run passes if |F - F*| stays within "
                f"{b['hold error']:.1f} N (1 % of the {span:.0f} N span) on every plateau "
                f"from {HOLD_SETTLE:g} s after it is reached (hold error: the force a press-fit "
                f"or test bench is judged on), within {b['peak error']:.1f} N (5 %) everywhere "
                f"(peak error: no force spike on the part; the profile has no jumps, so no "
                f"window is exempt) and its RMS over the run is at most {b['RMS error']:.1f} N "
                "(2 %: the shape of the profile is followed, ramps and oscillation included). "
                "A run the solver cannot finish fails 'simulation'. With the rod locked the "
                "piston does not move, so the drawn mass cannot matter: it is drawn only "
                "because the default ranges include it."),
            rp.Table(["controller", "plants", "passed", "pass rate (95 % interval)",
                      "median RMS |F - F*|", "worst RMS |F - F*|", "most frequent failing check",
                      "on the nominal plant"], mc_rows,
                     units=["", "", "", "", "N", "N", "", ""],
                     caption=f"Monte Carlo robustness on {n_mc} drawn rigs (Wilson 95 % "
                             "intervals of the pass rate)"),
        ]
        mc_blocks += _robustness_findings(mc, model, nom_prm)
        mc_blocks.append(_figure(
            _robustness_figure(mc, nom_prm, b["RMS error"]),
            "RMS force error of every drawn rig against the drawn sonic-conductance factor, "
            "mass factor, polytropic index and supply pressure; filled markers passed, crosses "
            "failed (any check); dashed: the RMS bound. Runs that did not complete are not drawn."))
        mc_blocks.append(rp.Status(
            "NOTE", "robustness is reported, not part of the design verdict: a drawn rig "
                    "that fails the specification does not fail the design"))
        done.append(rp.Section("Robustness (Monte Carlo)", mc_blocks))

    with rp.step("write report"):
        design_ok = ok_nominal and not errors
        msg = (f"force follows the profile on the nominal plant within "
               f"{nominal['max_error']:.2f} N (RMS {nominal['rms_error']:.3f} N); on the rig's "
               f"four-edge valve within {mets['rig (four-edge valve)']['max_error']:.2f} N"
               if design_ok else "force tracking not met: see the closed-loop section")
        status = rp.Status("PASS" if design_ok else "FAIL", msg + (" (quick mode)" if quick else ""))
        summ = rp.Section("Summary", [rp.KeyValues(
            [("verdict", status.outcome), ("bandwidth", BANDWIDTH, "rad/s")]
            + [(f"{n}: RMS / max error", f"{m['rms_error']:.3f} / {m['max_error']:.3f} N")
               for n, m in mets.items()]
            + [(f"Monte Carlo pass rate, {cname}, {pname}",
                f"{sum(res.passed[cname])}/{len(res.passed[cname])} = "
                f"{res.pass_rate(cname) * 100:.0f} % (95 % interval "
                f"{res.pass_interval(cname)[0] * 100:.0f} .. {res.pass_interval(cname)[1] * 100:.0f} %)"
                + ("" if quick else ", not part of the verdict"))
               for pname, res in mc.items() for cname in res.passed]
            + [("run time", f"{time.perf_counter() - t_start:.1f} s" + (" (quick mode)" if quick else ""))])])
        doc = rp.Report(TITLE, subtitle="Pressure-trajectory inversion (paper 003) and a sampled "
                                        "force controller on a locked rod",
                        status=status, sections=[summ, *done],
                        provenance=rp.provenance(plant_file=PLANT, command_line=" ".join(sys.argv),
                                                 extra=[("quick mode", bool(quick))]))
        html, pdf = rp.write(doc, out)
        summary = {"design_passed": bool(design_ok), "quick": bool(quick), "bandwidth": BANDWIDTH,
                   "span": span, "bounds": {"max": MAX_ERROR_FRACTION * span,
                                            "rms": RMS_ERROR_FRACTION * span},
                   "metrics": mets, "errors": errors, "plan_deviation": plan_dev,
                   "plans": {k: p.to_dict() for k, p in plans.items()},
                   "robustness": {"spec": judge.bounds, "hold_settle": HOLD_SETTLE,
                                  "run_time": t_mc,
                                  "nominal": {f"{c} | {pn}": {"passed": o.passed,
                                                               "failed": list(o.failed),
                                                               "rms_error": o.score}
                                              for (pn, c), o in mc_nominal.items()},
                                  "results": {pn: res.to_dict() for pn, res in mc.items()}}}
        write_json(out / "summary.json", summary, indent=1, default=rp.json_default)
    print(f"design {status.outcome}: {status.message}\n  report: {html}\n          {pdf}")
    return 0 if design_ok else 1


def _robustness_findings(mc, model, prm) -> list:
    """Where the controllers fail on the drawn rigs, in numbers (paragraphs)."""
    blocks = []
    tracker, ff = "tracker (FF + FB)", "feedforward only"
    p_s = prm["supply.pressure"] / 1e5
    parts, above = [], True
    for pname, res in mc.items():
        ok = np.array(res.passed[tracker])
        if ok.all():
            continue
        supply = res.drawn("supply.pressure") / 1e5
        parts.append(f"{pname}: fails with supply " + ", ".join(
            f"{v:.2f}" for v in np.sort(supply[~ok])) + " bar"
            + (f", passes on every draw up to {supply[ok].max():.2f} bar" if ok.any() else ""))
        above = above and bool((supply[~ok] > p_s).all())
    if parts:
        text = "Where the tracker fails -- " + "; ".join(parts) + "."
        p_hi = max(float(res.drawn("supply.pressure").max()) for res in mc.values())
        psi_in = model.valve.terms(np.array([5e5, p_hi]))[1]
        if above and psi_in[1] < 0:
            text += (f" Every failing draw has a supply above the nominal {p_s:g} bar that the "
                     "controller's input-affine valve model was fitted at, and a chamber pressure "
                     "then rises above it. There the fitted inlet flow of a fully open port, "
                     f"psi_in(p) ({psi_in[0] * 1e3:.1f} g/s at 5 bar, pinned to zero at {p_s:g} "
                     f"bar), is extrapolated to {psi_in[1] * 1e3:.0f} g/s at {p_hi / 1e5:.2f} bar: "
                     "the model believes the supply edge empties the chamber, the inversion asks "
                     "for a saturated command and the force overshoots (peak error).")
        blocks.append(rp.Paragraph(text))
    if all(ff in res.passed for res in mc.values()) and all(
            res.pass_rate(ff) < res.pass_rate(tracker) for res in mc.values()):
        blocks.append(rp.Paragraph(
            "Feedforward alone passes on " + ", ".join(
                f"{res.pass_rate(ff) * 100:.0f} % ({pname})" for pname, res in mc.items())
            + " of the drawn rigs: without the error term every mismatch between the nominal "
              "model and the drawn rig integrates into a force error that nothing removes, "
              "and the holds keep it."))
    return blocks


def _robustness_figure(mc, prm, rms_bound):
    import matplotlib.pyplot as plt
    panels = [("valve.sonic_conductance", prm["valve.sonic_conductance"], "sonic conductance factor C/C0"),
              ("load.mass", prm["load.mass"], "mass factor m/m0"),
              ("gas.polytropic_index", 1.0, "polytropic index"),
              ("supply.pressure", 1e5, "supply pressure [bar abs]")]
    fig, axes = plt.subplots(2, 2, sharey=True, figsize=(9.0, 6.5), constrained_layout=True)
    colors = iter(["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown"])
    for pname, res in mc.items():
        for cname in res.passed:
            color = next(colors)
            ok = np.array(res.passed[cname])
            sc = np.array(res.scores[cname], dtype=float)
            for ax, (key, scale, _) in zip(axes.flat, panels):
                x = res.drawn(key) / scale
                ax.scatter(x[ok], sc[ok], color=color, marker="o", s=28,
                           label=f"{cname}, {pname}")
                ax.scatter(x[~ok], sc[~ok], color=color, marker="x", s=36)
    for ax, (key, scale, label) in zip(axes.flat, panels):
        ax.axhline(rms_bound, color="k", ls="--", lw=0.9)
        ax.set_yscale("log")
        ax.set_xlabel(label)
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("RMS |F - F*| [N]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    handles += [plt.Line2D([], [], color="gray", marker="o", ls=""),
                plt.Line2D([], [], color="gray", marker="x", ls=""),
                plt.Line2D([], [], color="k", ls="--", lw=0.9)]
    labels += ["passed", "failed", "RMS bound"]
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=7)
    fig.suptitle("Monte Carlo: RMS force error per drawn rig", fontsize=11)
    return fig


def _runs_figure(runs, profile, plan):
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(9.0, 10.0), constrained_layout=True)
    ax_f, ax_e, ax_p, ax_u = axes
    t = next(iter(runs.values())).time
    ax_f.plot(t, profile(t), "k--", lw=1.0, label="F*")
    for name, run in runs.items():
        ax_f.plot(run.time, run["force"], lw=1.0, label=name)
        ax_e.plot(run.time, run["force"] - profile(run.time), lw=1.0, label=name)
        ax_p.plot(run.time, run["p_a"] / 1e5, lw=1.0, label=f"p_a {name}")
        ax_u.step(run.time, run["u"], where="post", lw=0.9, label=name)
    ax_p.plot(plan.time, plan.p_a / 1e5, "k:", lw=1.2, label="p_a single-valve plan")
    ax_p.plot(plan.time, plan.p_b / 1e5, "k-.", lw=1.0, label="p_b single-valve plan")
    ax_f.set_ylabel("force [N]")
    ax_e.set_ylabel("F - F* [N]")
    ax_p.set_ylabel("pressure [bar abs]")
    ax_u.set_ylabel("command [V]")
    ax_u.set_xlabel("time t [s]")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=7, ncol=2)
    fig.suptitle("Force tracking on the locked rod", fontsize=11)
    return fig


if __name__ == "__main__":
    sys.exit(main())
