"""Command line: ``python -m workbench`` / ``workbench``.

Sub-commands: ``check``, ``simulate``, ``linearize``, ``limits``, ``bench``. Every error a user
can cause (a bad file, a bad argument) is reported in one readable line, exit 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from .errors import WorkbenchError
from .params import json_safe

__all__ = ["main", "build_parser"]

EPILOG = "Units are SI (m, Pa absolute, kg, s, V) unless an option says otherwise."


def _cmd_check(args: argparse.Namespace) -> int:
    from .plant import Plant
    from . import units
    plant = Plant.from_toml(args.plant)
    s = plant.summary()
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    prm = plant.params
    rows = [
        ("plant", f"{s['name']}  ({args.plant})"),
        ("supply", f"{units.pa_to_bar(prm['supply.pressure']):.2f} bar abs"),
        ("piston area a / b", f"{s['area_a_m2'] * 1e4:.3f} / {s['area_b_m2'] * 1e4:.3f} cm^2"),
        ("stroke", f"{s['stroke_m'] * 1e3:.0f} mm"),
        ("chamber volume a / b (max)", f"{s['volume_a_max_m3'] * 1e6:.1f} / "
                                       f"{s['volume_b_max_m3'] * 1e6:.1f} cm^3"),
        ("max force extend / retract", f"{s['max_force_extend_N']:.1f} / "
                                       f"{s['max_force_retract_N']:.1f} N"),
        ("valve flow, one edge fully open",
         f"{s['valve_flow_full_opening_l_min_anr']:.0f} l/min ANR "
         f"({s['valve_flow_full_opening_kg_s'] * 1e3:.2f} g/s, supply -> atmosphere)"),
        ("moving mass", f"{prm['load.mass']:.3f} kg"),
        ("valve law", s.get("valve_law", "iso6358")),
        ("effects", ", ".join(s["effects"]) or "none (nominal model)"),
        ("states", f"{len(s['states'])}: {', '.join(s['states'][:8])}"
                   + (" ..." if len(s["states"]) > 8 else "")),
        ("controller", ", ".join(f"{k}={v}" for k, v in s["controller"].items()) or "none"),
    ]
    width = max(len(r[0]) for r in rows)
    print("plant file OK")
    for k, v in rows:
        print(f"  {k:<{width}}  {v}")
    return 0


def _cmd_linearize(args: argparse.Namespace) -> int:
    from .plant import Plant
    from . import linearize
    plant = Plant.from_toml(args.plant)
    op = linearize.operating_point(plant, args.x)
    lin = linearize.tangent(plant, op)
    red_err = None
    try:
        red = linearize.reduced_position_model(lin).as_dict()
    except WorkbenchError as exc:
        red, red_err = None, str(exc)
    ev = lin.eigenvalues
    out = {
        "plant": str(args.plant),
        "equilibrium": {"x": op.x, "u": op.u, "p_a": op.p_a, "p_b": op.p_b,
                        "state": {k: float(v) for k, v in zip(op.state_names, op.state)}},
        "states": list(lin.state_names),
        "inputs": list(lin.input_names),
        "outputs": list(lin.output_names),
        "A": lin.A.tolist(), "B": lin.B.tolist(), "C": lin.C.tolist(), "D": lin.D.tolist(),
        "eigenvalues": [{"re": float(e.real), "im": float(e.imag)} for e in ev],
        "reduced_model": red,
        "notes": list(lin.notes) + ([red_err] if red_err else []),
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"equilibrium at x = {op.x:.4g} m: u = {op.u:.4f} V, p_a = {op.p_a / 1e5:.4f} bar, "
          f"p_b = {op.p_b / 1e5:.4f} bar")
    print("eigenvalues (1/s): " + ", ".join(f"{e.real:.4g}{e.imag:+.4g}j" for e in ev))
    if red:
        print(f"reduced position model: Kv = {red['Kv']:.4g} m/(V s), w0 = {red['w0']:.4g} rad/s, "
              f"zeta = {red['zeta']:.4g}  (fit error {red['fit_error']:.1e})")
    for n in out["notes"]:
        print("note: " + n)
    np.set_printoptions(precision=4, linewidth=120)
    print("A =\n", lin.A, "\nB =\n", lin.B.ravel())
    return 0


def _cmd_limits(args: argparse.Namespace) -> int:
    from .errors import InputError
    from . import stability
    model_opts = [o for o, v in (("--w0", args.w0), ("--zeta", args.zeta), ("--kv", args.kv))
                  if v is not None]
    notes: list[str] = []
    if args.k0 is not None and args.kp is not None:
        raise InputError("give the loop gain --k0 (1/s) or the controller gain --kp (V/m), "
                         "not both")
    if args.plant is not None:
        if model_opts:
            raise InputError(f"{', '.join(model_opts)} cannot be combined with PLANT.toml: "
                             "with a plant file Kv, w0 and zeta come from its linearisation "
                             "at --x")
        if args.x is None:
            raise InputError("with PLANT.toml the position --x (m) is needed")
        from .plant import Plant
        plant = Plant.from_toml(args.plant)
        lim = stability.limits_from_plant(plant, args.x, sample_time=args.sample_time,
                                          kp=args.kp, k0=args.k0)
        where = f"{args.plant} at x = {args.x:g} m"
        kind = plant.params.get("controller.kind") if plant.params.has_controller else None
        if kind not in (None, "p"):
            notes.append(f"the plant file's controller is {kind}; these limits are for a P "
                         "controller with its kp")
    else:
        if args.x is not None:
            raise InputError("--x needs PLANT.toml; for a model give --w0, --zeta and "
                             "--sample-time instead")
        missing = [o for o, v in (("--w0", args.w0), ("--zeta", args.zeta),
                                  ("--sample-time", args.sample_time)) if v is None]
        if missing:
            raise InputError("give PLANT.toml with --x, or the model --w0, --zeta and "
                             f"--sample-time (missing: {', '.join(missing)})")
        k0 = args.k0
        if args.kp is not None:
            if args.kv is None:
                raise InputError("--kp (V/m) needs --kv (m/(V s)) to form K0 = kp Kv; "
                                 "or give --k0 directly")
            k0 = args.kp * args.kv
        lim = stability.gain_limits(args.w0, args.zeta, args.sample_time, k0=k0, kv=args.kv)
        where = "model"
    if args.json:
        out = lim.as_dict()
        if args.plant is not None:
            out = {**out, "plant": str(args.plant), "x": args.x, "notes": notes}
        print(json.dumps(json_safe(out), indent=2))
        return 0

    def num(v, fmt=".4g"):
        return "-" if v is None else ("inf" if not np.isfinite(v) else format(v, fmt))

    print(f"gain limits of the sampled P position loop ({where})")
    kv_txt = f"Kv = {lim.kv:.4g} m/(V s), " if lim.kv is not None else ""
    print(f"  model: {kv_txt}w0 = {lim.w0:.4g} rad/s, zeta = {lim.zeta:.4g}, "
          f"T = {lim.sample_time * 1e3:.4g} ms, Ts = T/2 + 1/w0 = "
          f"{lim.pct_time_constant * 1e3:.4g} ms")
    if lim.k0 is None:
        print("  loop gain K0: not given (no margins)")
    else:
        kp_txt = f"  (kp = {lim.kp:.4g} V/m)" if lim.kp is not None else ""
        print(f"  loop gain K0 = kp Kv = {lim.k0:.4g} 1/s{kp_txt}")
    rows = [("continuous (Hurwitz, 2 zeta w0)", "continuous"),
            ("PCT (2 zeta / Ts)", "pct"),
            ("sampled data (ZOH at T)", "sampled"),
            ("sampled data + 1 sample delay", "sampled_delay")]
    width = max(len(r[0]) for r in rows)
    print()
    print(f"  {'limit':<{width}}  {'K0 (1/s)':>10}  {'kp (V/m)':>10}  {'K0/limit':>9}")
    for label, name in rows:
        val = getattr(lim, name)
        ratio = None if lim.k0 is None else lim.k0 / val
        print(f"  {label:<{width}}  {num(val):>10}  {num(lim.kp_limit(name)):>10}  "
              f"{num(ratio, '.3f'):>9}")
    if lim.k0 is not None:
        gm = lim.gain_margin
        gm_db = f" ({20 * np.log10(gm):.1f} dB)" if np.isfinite(gm) and gm > 0 else ""
        print()
        print(f"  margins at K0 = {lim.k0:.4g} 1/s (sampled loop, no delay): "
              f"gain {num(gm)}{gm_db}, phase {num(lim.phase_margin_deg, '.1f')} deg")
    for n in notes:
        print("note: " + n)
    return 0


def _cmd_map(args: argparse.Namespace) -> int:
    from .plant import Plant
    from .controllers import from_plant
    from .errors import InputError
    from .stability import maps
    from . import plots
    plant = Plant.from_toml(args.plant)
    xa, ya = maps.parse_axis(args.x_axis), maps.parse_axis(args.y_axis)
    if plant.params.has_controller:
        ctrl = from_plant(plant)
        ctrl_d = {"kp": ctrl.kp, "kd": ctrl.kd, "ki": ctrl.ki, "sample_time": ctrl.sample_time}
    else:
        ctrl_d = {"kp": None, "kd": 0.0, "ki": 0.0, "sample_time": None}
    for key in ("kp", "kd", "ki", "sample_time"):
        val = getattr(args, key)
        if val is not None:
            ctrl_d[key] = val
    axes = {xa.name, ya.name}
    if ctrl_d["sample_time"] is None and "sample_time" not in axes:
        raise InputError("no sample time: the plant file has no [controller]; give --sample-time")
    if ctrl_d["kp"] is None and not axes & {"kp", "k0"}:
        raise InputError("no gain: the plant file has no [controller]; give --kp or sweep kp/k0")
    ctrl_d["kp"] = ctrl_d["kp"] or 1.0
    ctrl_d["sample_time"] = ctrl_d["sample_time"] or 0.01
    smap = maps.stability_map(plant, xa, ya, position=args.position, controller=ctrl_d,
                              delay_samples=args.delay, scheduler=args.scheduler,
                              workers=args.workers, progress=not args.quiet and None)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    smap.to_csv(out / "map.csv")
    from .params import atomic_write_text
    summary = {k: v for k, v in smap.as_dict().items() if k != "rho"}
    summary["files"] = {"csv": str(out / "map.csv"), "json": str(out / "map.json"),
                        "png": str(out / "map.png")}
    atomic_write_text(out / "map.json", json.dumps(smap.as_dict(), indent=1) + "\n")
    if not args.no_plot:
        plots.save_figure(plots.stability_map_figure(smap), out / "map.png")
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    rho = smap.rho
    print(f"stability map {len(xa)} x {len(ya)} = {rho.size} points in {smap.elapsed_s:.2f} s "
          f"({smap.points_per_s:,.0f} points/s)")
    print(f"  x: {xa.label} {xa.values[0]:g} .. {xa.values[-1]:g};  y: {ya.label} "
          f"{ya.values[0]:g} .. {ya.values[-1]:g}")
    print(f"  stable: {100 * np.mean(smap.stable):.1f} % of points;  |z|max "
          f"{np.nanmin(rho):.4f} .. {np.nanmax(rho):.4f}")
    for note in smap.notes:
        print(f"  note: {note}")
    print(f"  wrote {out / 'map.csv'}, {out / 'map.json'}"
          + ("" if args.no_plot else f", {out / 'map.png'}"))
    return 0


def _cmd_simulate(args: argparse.Namespace) -> int:
    from .plant import Plant
    from .recording import Recording, fit_signals
    plant = Plant.from_toml(args.plant)
    rec = Recording.load(args.recording)
    out_dir = Path(args.out)
    run = replay(plant, rec, progress=None if not args.quiet else False,
                 mode=args.mode)
    sim_rec = _as_recording_columns(run, rec)
    fits = fit_signals(rec, sim_rec, names=[n for n in ("x", "p_a", "p_b") if n in rec])
    out_dir.mkdir(parents=True, exist_ok=True)
    sim_rec.to_csv(out_dir / "simulation.csv")
    from .params import atomic_write_text
    atomic_write_text(out_dir / "fit.json", json.dumps(fits, indent=2) + "\n")
    if not args.no_plot:
        from .plots import replay_figure
        replay_figure(rec, sim_rec, fits, out_dir / "simulation.png",
                      title=f"{plant.name}: {run.info['mode'].replace('_', ' ')} replay of "
                            f"{Path(args.recording).name}")
    mode = run.info["mode"].replace("_", " ")
    print(f"{mode} replay of {args.recording} ({len(rec)} samples, {rec.duration:.3g} s)")
    for k, v in fits.items():
        print(f"  fit {k:<4} {v:7.2f} %")
    print(f"wrote {out_dir / 'simulation.csv'} and {out_dir / 'fit.json'}")
    return 0


def replay(plant, rec, progress=None, mode: str = "auto"):
    """Simulate a recording: closed loop on ``r`` with the plant's controller, else open loop on ``u``."""
    from . import controllers, simulate
    from .errors import InputError
    closed = "r" in rec and plant.params.has_controller
    if mode == "closed":
        if "r" not in rec:
            raise InputError("closed-loop replay needs an 'r' column", source=rec.source)
        if not plant.params.has_controller:
            raise InputError("closed-loop replay needs a [controller] section",
                             source=plant.params.source)
        closed = True
    elif mode == "open":
        closed = False
    t = rec.t
    x_first = float(np.clip(rec["x"][0], 0.0, plant.stroke))
    pa = float(rec["p_a"][0]) if "p_a" in rec else None
    pb = float(rec["p_b"][0]) if "p_b" in rec else None
    x0 = plant.initial_state(x_first, p_a=pa, p_b=pb)
    if closed:
        ctrl = controllers.from_plant(plant)
        ref = simulate.Reference(times=t - t[0], values=np.asarray(rec["r"]), hold=True)
        run = simulate.closed_loop(plant, ctrl, ref, x0=x0, output_times=t - t[0],
                                   progress=progress)
    else:
        run = simulate.open_loop(plant, t - t[0], rec["u"], x0=x0, progress=progress)
    return run


def _as_recording_columns(run, rec):
    """Simulated recording with the same columns as ``rec`` (r and unknown columns copied)."""
    from .recording import Recording
    data = {}
    for c in rec.columns:
        if c == "t":
            continue
        if c in ("u", "x", "p_a", "p_b", "p_s", "v"):
            data[c] = np.asarray(run[c], dtype=float)
        else:
            data[c] = np.asarray(rec[c], dtype=float)
    meta = dict(rec.metadata)
    meta["simulated_by"] = "workbench simulate"
    data["t"] = rec.t
    return Recording(columns=tuple(rec.columns), data=data, metadata=meta,
                     source="<simulation>")


#: ``workbench bench NAME``: "module:function" taking ``quick`` and returning a dict.
BENCHMARKS = {
    "simulate": "workbench.bench:bench_simulate",
    "sweep": "workbench.stability.maps:bench",
    "rls": "workbench.bench.rls:bench",
    "greybox": "workbench.identify.grey_box:bench",
    "mpc": "workbench.controllers.mpc:bench",
    "diagnose": "workbench.diagnose.bench:bench",
}


def _cmd_bench(args: argparse.Namespace) -> int:
    import importlib
    mod_name, fun_name = BENCHMARKS[args.name].split(":")
    try:
        fun = getattr(importlib.import_module(mod_name), fun_name)
    except (ImportError, AttributeError) as exc:
        raise WorkbenchError(f"benchmark '{args.name}' is not available: {exc}") from exc
    result = fun(quick=args.quick)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for k, v in result.items():
            print(f"{k}: {v}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (also used by the tests to check ``--help``)."""
    p = argparse.ArgumentParser(
        prog="workbench",
        description="Design and validation workbench for electropneumatic servodrives.",
        epilog=EPILOG)
    from . import __version__
    p.add_argument("--version", action="version", version=f"workbench {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    c = sub.add_parser("check", help="validate a plant file and print a summary",
                       description="Validate PLANT.toml (formats.md sections 1-2) and print "
                                   "areas, volumes, maximum force, valve flow at full opening "
                                   "(l/min ANR) and the effects that are switched on.",
                       epilog=EPILOG)
    c.add_argument("plant", metavar="PLANT.toml", help="plant file")
    c.add_argument("--json", action="store_true", help="print the summary as JSON (SI units)")
    c.set_defaults(func=_cmd_check)

    s = sub.add_parser("simulate", help="replay a recording on the plant model",
                       description="Replay RECORDING on the plant model: closed loop on the "
                                   "recording's 'r' with the plant file's [controller] when both "
                                   "exist, else open loop on its 'u'. The simulation starts from "
                                   "the recording's first position (and pressures, if recorded). "
                                   "Writes DIR/simulation.csv (the recording's columns; 'r' and "
                                   "unknown columns copied), DIR/fit.json (NRMSE fit in percent "
                                   "of x, p_a, p_b as recorded) and DIR/simulation.png.",
                       epilog=EPILOG)
    s.add_argument("plant", metavar="PLANT.toml", help="plant file")
    s.add_argument("recording", metavar="RECORDING", help="recording (.csv or .mat, formats.md section 3)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder (created if needed)")
    s.add_argument("--mode", choices=("auto", "closed", "open"), default="auto",
                   help="force closed-loop or open-loop replay (default: auto)")
    s.add_argument("--no-plot", action="store_true", help="do not write simulation.png")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_simulate)

    lz = sub.add_parser("linearize", help="equilibrium and exact tangent model at a position",
                        description="Find the equilibrium with the piston at rest at X (valve "
                                    "command, chamber pressures), the exact A, B, C, D from "
                                    "CasADi's automatic differentiation, the eigenvalues, and "
                                    "the reduced position model Kv / (s (s^2/w0^2 + 2 zeta s/w0 "
                                    "+ 1)) of paper 000 fitted to it.",
                        epilog=EPILOG)
    lz.add_argument("plant", metavar="PLANT.toml", help="plant file")
    lz.add_argument("--x", type=float, required=True, metavar="X", help="piston position, m")
    lz.add_argument("--json", action="store_true", help="print JSON")
    lz.set_defaults(func=_cmd_linearize)

    li = sub.add_parser("limits", help="gain limits of the P position loop and margins",
                        description="Upper limits on the loop gain K0 = kp Kv (1/s) of the "
                                    "sampled P position loop K0 / (s (s^2/w0^2 + 2 zeta s/w0 "
                                    "+ 1)) of paper 000: continuous Hurwitz 2 zeta w0, PCT "
                                    "2 zeta/Ts with Ts = T/2 + 1/w0, the exact sampled-data "
                                    "limit (ZOH at T) and the same with one sample of "
                                    "computation delay; gain and phase margins of the sampled "
                                    "loop (no extra delay) at K0. Either PLANT.toml with --x "
                                    "(Kv, w0, zeta from the exact linearisation there; kp and "
                                    "T from its [controller] unless given) or the model "
                                    "--w0, --zeta, --sample-time. In JSON an infinite margin "
                                    "(no crossover) is written as null; without a loop gain "
                                    "k0 and the margins are null.",
                        epilog=EPILOG)
    li.add_argument("plant", metavar="PLANT.toml", nargs="?", default=None,
                    help="plant file (optional: else give --w0, --zeta, --sample-time)")
    li.add_argument("--x", type=float, metavar="X", help="piston position, m (with PLANT.toml)")
    li.add_argument("--w0", type=float, metavar="W0", help="natural frequency, rad/s (model)")
    li.add_argument("--zeta", type=float, metavar="ZETA", help="damping ratio, - (model)")
    li.add_argument("--sample-time", type=float, metavar="T",
                    help="sample time, s (model: required; plant: default controller.sample_time)")
    li.add_argument("--k0", type=float, metavar="K0",
                    help="loop gain kp Kv, 1/s, for the margins "
                         "(plant: default controller.kp * Kv)")
    li.add_argument("--kp", type=float, metavar="KP",
                    help="controller gain, V/m, instead of --k0 (model: needs --kv)")
    li.add_argument("--kv", type=float, metavar="KV",
                    help="velocity gain, m/(V s) (model only): shows the limits as kp = K0/Kv")
    li.add_argument("--json", action="store_true",
                    help="print JSON: k0, continuous, pct, sampled, sampled_delay (1/s), "
                         "gain_margin, phase_margin_deg, and context; inf is written as null")
    li.set_defaults(func=_cmd_limits)

    mp = sub.add_parser("map", help="stability map over two swept parameters",
                        description="Sweep two parameters and colour the plane by the largest "
                                    "closed-loop pole magnitude |z|max of the exact sampled-data "
                                    "position loop (equilibrium, exact tangent model, ZOH at T, "
                                    "the discrete controller, optional computation delay) at "
                                    "every point; for a P controller the PCT and continuous "
                                    "limits are drawn over it. An axis is NAME=START:STOP[:NUM]"
                                    "[:log]; NAME is a plant parameter (dotted, SI: load.mass, "
                                    "supply.pressure, lines.length, ...; short: mass, "
                                    "supply_pressure, line_length), position (m), kp (V/m), kd "
                                    "(V s/m), ki (V/(m s)), k0 (loop gain kp*Kv, 1/s) or "
                                    "sample_time (s). Runs on all local cores, or on a Dask "
                                    "cluster with --scheduler. Writes DIR/map.csv (one row per "
                                    "point), DIR/map.json and DIR/map.png.",
                        epilog=EPILOG + " Example: workbench map designs/plants/situm_rodless.toml "
                                        "--x-axis k0=1:90:100 --y-axis mass=0.3:5:100 --out map/")
    mp.add_argument("plant", metavar="PLANT.toml", help="plant file")
    mp.add_argument("--x-axis", required=True, metavar="NAME=START:STOP[:NUM]", help="horizontal axis")
    mp.add_argument("--y-axis", required=True, metavar="NAME=START:STOP[:NUM]", help="vertical axis")
    mp.add_argument("--out", required=True, metavar="DIR", help="output folder (created if needed)")
    mp.add_argument("--position", type=float, metavar="X",
                    help="piston position of the equilibrium, m (default mid-stroke)")
    mp.add_argument("--kp", type=float, help="controller gain, V/m (default: plant file)")
    mp.add_argument("--kd", type=float, help="derivative gain, V s/m (default: plant file)")
    mp.add_argument("--ki", type=float, help="integral gain, V/(m s) (default: plant file)")
    mp.add_argument("--sample-time", dest="sample_time", type=float, metavar="T",
                    help="sample time, s (default: plant file)")
    mp.add_argument("--delay", type=int, default=0, metavar="N",
                    help="samples of computation delay (default 0)")
    mp.add_argument("--scheduler", metavar="ADDRESS",
                    help="Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: local cores)")
    mp.add_argument("--workers", type=int, metavar="N",
                    help="local worker processes (default: all cores)")
    mp.add_argument("--json", action="store_true", help="print a JSON summary")
    mp.add_argument("--no-plot", action="store_true", help="do not write map.png")
    mp.add_argument("--quiet", action="store_true", help="no progress bar")
    mp.set_defaults(func=_cmd_map)

    from .cli.identify import register as register_identify
    register_identify(sub)
    import importlib

    try:
        importlib.import_module("workbench.diagnose.cli").add_cli(sub)
    except (ImportError, AttributeError):
        pass                    # diagnosis not (yet) built
    importlib.import_module("workbench.robustness").add_cli(sub)

    b = sub.add_parser("bench", help="run a benchmark and print ratios",
                       description="Benchmarks measure against a baseline in the same run and "
                                   "print ratios. NAME: simulate (closed-loop 24 s, 25 mm "
                                   "reference plant, vs scipy solve_ivp LSODA); sweep (200 x 200 "
                                   "stability map vs a python-control loop); rls (RLS over 10^6 "
                                   "samples vs a numpy loop); greybox (4 parameters from a 20 s, "
                                   "1 kHz recording); mpc (NMPC solve times over a 20 s closed "
                                   "loop, vs do-mpc when installed); diagnose (24 s, 1 kHz "
                                   "recording, all candidate effects).",
                       epilog=EPILOG)
    b.add_argument("name", choices=tuple(BENCHMARKS), help="benchmark")
    b.add_argument("--json", action="store_true", help="print JSON")
    b.add_argument("--quick", action="store_true", help="shorter run (smoke test)")
    b.set_defaults(func=_cmd_bench)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except WorkbenchError as exc:
        print(f"workbench {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:          # output piped into e.g. `head`: not an error
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
