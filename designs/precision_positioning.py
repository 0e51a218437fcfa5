"""Precision positioning: PID, FL and NMPC with compensation on a rig with friction, deadband, lines.

1. The rig (``designs/plants/rigs/precision_rig25.toml``): the 25 mm rodless cylinder with
   dry friction (Coulomb 15 N, static 25 N, Stribeck 10 mm/s), 2 % spool overlap, 1 m
   lines of 4 mm bore, 12-bit position sensor, 2 ms loop. The controllers see it
   through rig sensors: the position quantised to 12 bits (0.122 mm), both pressures
   with 300 Pa white noise, no velocity.
2. Each controller is what ``workbench.controllers.design(plant, kind)`` returns from
   the plant file alone: a Kalman observer (velocity and unmodelled force from x,
   p_a, p_b), the deadband inverted, a precision hold against stick-slip hunting
   (workbench.controllers.hold: net force held at zero, locked on the target's
   quantum, a stuck piston moved by adapted force pulses), the
   reference smoothed to the axis's limits (the valve's flow, or the lines' where
   they pass less) and fed forward (PID through the reduced model's inverse, FL,
   NMPC), the plant file's dry friction fed forward (FL at the reference's
   velocity, PID its rate, both only its sliding part while the reference slows;
   the NMPC predicts with it), and PID and FL drive a stuck piston that the
   reference moves on to the static friction (break-away; the PID then hands that
   force back to the sliding level). FL's error bandwidth is what the 2 ms loop
   and the lines' transport delay allow (40 rad/s).
3. Each is validated on the full plant over the precision profile and judged by the
   precision specification (steady state within one quantum, overshoot <= 2 %, worst
   error on the 60 mm, 0.5 Hz sine <= 1 mm); the published rig results (0.05 mm
   steady state, 0.7 mm worst on the sine) are the reference line.
4. Robustness: the NMPC designed from the plant file runs on a rig that is not the
   file (friction 1.5x, mass +10 %).

Writes ``reports/precision_positioning/report.html`` and ``report.pdf``, plus
``summary.json``. A design that fails to run still leaves a report saying where.

Usage: python designs/precision_positioning.py [--quick] [--out DIR] [--no-jit]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from workbench import Plant, validate
from workbench import report as rp
from workbench.controllers.evaluation import evaluate_design

HERE = Path(__file__).resolve().parent
PLANT = HERE / "plants" / "rigs" / "precision_rig25.toml"
ROOT = HERE.parent
TITLE = "Precision positioning: PID, FL and NMPC with friction and deadband compensation"
#: Published real-rig results (issue 14): steady state on a 60 mm step, worst error on
#: a 60 mm, 0.5 Hz sine (model-reference adaptive friction compensation, sliding mode).
PUBLISHED = {"steady_state": 0.05e-3, "sine": 0.7e-3}
#: The rig that is not the plant file: friction 1.5x, mass +10 %.
PERTURBED = {"friction.coulomb": 22.5, "friction.static": 37.5, "load.mass": 1.32}
PRESSURE_NOISE = 300.0        # Pa std
KINDS = ("pid", "fl", "nmpc")
#: Sensor-noise realisations the NMPC is run with (quick mode: 2).
SEEDS = 5


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="smoke mode: holds of 1 s, one sine period")
    ap.add_argument("--out", default=str(ROOT / "reports" / "precision_positioning"))
    ap.add_argument("--no-jit", dest="jit", action="store_false",
                    help="NMPC in CasADi's virtual machine (no C compiler needed)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    return rp.run_design(TITLE, out, PLANT, lambda done: _design(args, out, done))


def figures(ev) -> dict:
    """The figures a reader compares with the published ones (SI)."""
    v = ev.validation
    holds = [h for h in ev.holds if h["segment"].startswith("step")]
    return {"steady_state_worst": max((h["steady_state_error"] for h in holds), default=math.nan),
            "steady_state_median": float(np.median([h["steady_state_error"] for h in holds]))
            if holds else math.nan,
            "overshoot_pct": v.check("overshoot").value,
            "sine_worst": v.metrics.sine_error_max,
            "median_update_ms": ev.median_update_ms,
            "command_activity": ev.command_activity(),
            "limit_cycle_free": ev.limit_cycle_free,
            "passed": v.passed}


def _design(args, out: Path, done: list) -> int:
    t0 = time.perf_counter()
    with rp.step("plant"):
        plant = Plant.from_toml(PLANT)
        ref = validate.precision_profile(plant, hold=1.5 if args.quick else 2.5,
                                         sine_periods=1 if args.quick else 3)
        done.append(rp.Section("Rig", [rp.Paragraph(
            "The 25 mm rodless rig with dry friction (Karnopp stick-slip with a Stribeck "
            "curve, Coulomb 15 N, static 25 N), 2 % spool overlap and 1 m lines of 4 mm bore "
            f"({len(plant.states)} states), a 2 ms loop; the controllers see a 12-bit position "
            f"(0.122 mm), pressures with {PRESSURE_NOISE:g} Pa noise and no velocity. Every "
            "controller is designed from the plant file alone by "
            "workbench.controllers.design and validated on the full plant over the "
            "precision profile (steps, ramps, holds, a 60 mm 0.5 Hz sine).")]))
    evs = {}
    for kind in KINDS:
        with rp.step(f"{kind} design and validation"):
            evs[kind] = evaluate_design(plant, kind, reference=ref, jit=args.jit,
                                        pressure_noise=PRESSURE_NOISE)
            print(evs[kind].summary())
            done.extend(evs[kind].sections())
    with rp.step("perturbed rig"):
        rig = plant.with_params(**PERTURBED)
        pert = evaluate_design(plant, "nmpc", reference=ref, jit=args.jit, rig=rig,
                               pressure_noise=PRESSURE_NOISE)
        print("perturbed rig:\n" + pert.summary())
    with rp.step("noise seeds"):
        seeds = {0: evs["nmpc"]}
        for seed in range(1, 3 if args.quick else SEEDS):
            seeds[seed] = evaluate_design(plant, "nmpc", reference=ref, jit=args.jit, seed=seed,
                                          pressure_noise=PRESSURE_NOISE)
        done.append(_seed_section(seeds))
    with rp.step("comparison"):
        figs = {k: figures(e) for k, e in evs.items()}
        figs["nmpc (rig: friction 1.5x, mass +10 %)"] = figures(pert)
        rows = [[k, *_cells(f), _cell(f["median_update_ms"], 3),
                 _cell(f["command_activity"], 2), "yes" if f["limit_cycle_free"] else "NO", "pass" if f["passed"] else "FAIL"]
                for k, f in figs.items()]
        rows.append(["published rig result", _cell(PUBLISHED["steady_state"] * 1e3, 3), "-", "-",
                     _cell(PUBLISHED["sine"] * 1e3, 2), "-", "-", "-", "-"])
        done.insert(1, rp.Section("Comparison", [
            rp.Paragraph("Worst and median steady-state error after the steps (mean |r - x| "
                         "over 0.5 s ending where the controller hands over to the next move: "
                         "given the reference in advance, the NMPC is handed it one horizon, "
                         "80 ms, early and may start it; the validation tables judge up to "
                         "the hold's end), largest overshoot, worst error on "
                         "the sine, median computation per sample (wall time of the controller "
                         "update on this machine, other jobs included), command activity "
                         "while the reference moves (std of the command less its 25 ms "
                         "moving mean: chatter faster than any motion asked for), whether every hold is "
                         "free of a limit cycle (over its second half, less the hand-over: "
                         "peak-to-peak within one quantum and no command activity), and the "
                         "precision verdict. The last row is the published real-rig "
                         "result the issue quotes."),
            rp.Table(["controller", "steady state worst", "steady state median", "overshoot",
                      "sine worst", "computation", "command activity", "no limit cycle",
                      "precision spec"], rows,
                     units=["", "mm", "mm", "%", "mm", "ms", "V", "", ""],
                     caption="Precision figures on the full plant (12-bit x, noisy p, no v)"),
            rp.Paragraph(_verdict_text(evs, pert)),
        ]))
        best = min(KINDS, key=lambda k: (figs[k]["sine_worst"], figs[k]["steady_state_worst"]))
        summary = {"figures": figs, "best": best, "published": PUBLISHED,
                   "quantum": evs["nmpc"].quantum, "quick": bool(args.quick),
                   "wall_time": time.perf_counter() - t0}
        # issue 14's must-show for the best controller is its precision checks AND no
        # limit cycle in any hold: the banner passes only on both, and names a hold that
        # is not at rest (the precision checks alone judge the steady state, not the walk)
        walking = evs[best].holds_not_at_rest
        status = rp.Status("PASS" if figs[best]["passed"] and not walking else "FAIL",
                           f"best controller {best.upper()}: steady state worst "
                           f"{figs[best]['steady_state_worst'] * 1e3:.3f} mm, sine worst "
                           f"{figs[best]['sine_worst'] * 1e3:.2f} mm "
                           f"(published {PUBLISHED['steady_state'] * 1e3:g} / "
                           f"{PUBLISHED['sine'] * 1e3:g} mm)"
                           + "".join(f"; {h['segment']} not at rest in its second half "
                                     f"({h['command_changes']} command changes, "
                                     f"{h['peak_to_peak'] * 1e3:.3f} mm peak-to-peak)"
                                     for h in walking))
        doc = rp.Report(TITLE, subtitle="designs/precision_positioning.py"
                        + (" --quick" if args.quick else ""), status=status, sections=done,
                        provenance=rp.provenance(plant_file=PLANT))
        rp.write(doc, out)
        (out / "summary.json").write_text(json.dumps(summary, indent=2, default=rp.json_default))
    print(f"best: {best}; report: {out / 'report.html'}")
    return 0


def _verdict_text(evs: dict, pert) -> str:
    """Which controller passes the precision specification, and what each failing
    one misses (the failed checks' names, and holds with a limit cycle)."""
    runs = dict(evs)
    runs["NMPC on the rig with friction 1.5x, mass +10 %"] = pert
    passed, failed = [], []
    for name, ev in runs.items():
        label = name.upper() if name in KINDS else name
        if ev.validation.passed:
            passed.append(label + ("" if ev.limit_cycle_free else
                                   " (its checks; a hold has a limit cycle)"))
        else:
            missed = [c.name for c in ev.validation.checks if not c.passed]
            if not ev.limit_cycle_free:
                missed.append("a hold with a limit cycle")
            failed.append(f"{label} ({', '.join(missed) or 'see its table'})")
    return ("Passes the precision specification: " + (", ".join(passed) or "none")
            + ". " + ("Fails: " + "; ".join(failed) + "." if failed else "Every run passes."))


def _cell(x: float, decimals: int) -> str:
    """A table cell with a fixed number of decimals (one format per column)."""
    return "-" if not math.isfinite(x) else f"{x:.{decimals}f}"


def _cells(f: dict) -> list[str]:
    """Steady state worst and median (mm), overshoot (%), sine worst (mm) of
    :func:`figures`, as table cells."""
    return [_cell(f["steady_state_worst"] * 1e3, 3), _cell(f["steady_state_median"] * 1e3, 3),
            _cell(f["overshoot_pct"], 2), _cell(f["sine_worst"] * 1e3, 2)]


def _seed_section(seeds: dict) -> "rp.Section":
    """The NMPC's precision figures for each sensor-noise realisation."""
    rows = []
    for seed, ev in seeds.items():
        f = figures(ev)
        rows.append([seed, *_cells(f),
                     "yes" if f["limit_cycle_free"] else "NO", "pass" if f["passed"] else "FAIL"])
    return rp.Section("NMPC: other sensor-noise realisations", [
        rp.Paragraph("The same NMPC on the same rig, with the position quantiser and the "
                     "pressure noise drawn from other seeds. Each stop is decided by "
                     "stick-slip: a stuck piston breaks away and jumps 0.3-1 mm when its "
                     "force is raised through the static friction, more than the quantum "
                     "a stop must land in. The precision hold (controllers.hold) therefore "
                     "holds the net force at zero once the piston is slow or still near "
                     "its target, locks it when it is in the target's quantum, and moves "
                     "a piston stuck outside by force pulses (a bump that ends on its own, "
                     "strength bisected between no move and overshoot) with the valve "
                     "closed in between: there is no continuous position feedback in a "
                     "hold to sustain a limit cycle. The smallest move a breaking-away "
                     "bump makes on this rig is 0.1-0.3 mm (1 m lines), so landing in the "
                     "quantum can take several pulses. A design is judged by its worst "
                     "seed, not by seed 0."),
        rp.Table(["seed", "steady state worst", "steady state median", "overshoot",
                  "sine worst", "no limit cycle", "precision spec"], rows,
                 units=["", "mm", "mm", "%", "mm", "", ""],
                 caption="NMPC per sensor-noise seed (12-bit x, noisy p, no v)"),
    ])


if __name__ == "__main__":
    raise SystemExit(main())
