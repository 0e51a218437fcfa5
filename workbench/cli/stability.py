"""``workbench limits`` and ``workbench map``: gain limits and stability maps of the position loop."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from .common import EPILOG, finite_float, nonnegative_int, positive_int, prepare_output

__all__ = ["register"]

#: Files ``map --out`` receives.
MAP_FILES = ("map.csv", "map.json", "map.png")

LIMITS_DESCRIPTION = (
    "Upper limits on the loop gain K0 = kp Kv (1/s) of the sampled P position loop "
    "K0 / (s (s^2/w0^2 + 2 zeta s/w0 + 1)) of paper 000: continuous Hurwitz 2 zeta w0, PCT "
    "2 zeta/Ts with Ts = T/2 + 1/w0, the exact sampled-data limit (ZOH at T) and the same "
    "with one sample of computation delay; gain and phase margins of the sampled loop (no "
    "extra delay) at K0. Either PLANT.toml with --x (Kv, w0, zeta from the exact "
    "linearisation there; kp and T from its [controller] unless given) or the model --w0, "
    "--zeta, --sample-time. In JSON an infinite margin (no crossover) is written as null; "
    "without a loop gain k0 and the margins are null.")

MAP_DESCRIPTION = (
    "Sweep two parameters and colour the plane by the largest closed-loop pole magnitude "
    "|z|max of the exact sampled-data position loop (equilibrium, exact tangent model, ZOH at "
    "T, the discrete controller, optional computation delay) at every point; for a P "
    "controller the PCT and continuous limits are drawn over it. An axis is "
    "NAME=START:STOP[:NUM][:log]; NAME is a plant parameter (dotted, SI: load.mass, "
    "supply.pressure, lines.length, ...; short: mass, supply_pressure, line_length), position "
    "(m), kp (V/m), kd (V s/m), ki (V/(m s)), k0 (loop gain kp*Kv, 1/s) or sample_time (s). "
    "Runs on all local cores, or on a Dask cluster with --scheduler. Writes DIR/map.csv (one "
    "row per point), DIR/map.json and DIR/map.png.")


def register(subparsers) -> None:
    """Add ``limits`` and ``map`` to ``workbench``'s sub-parsers."""
    _register_limits(subparsers)
    _register_map(subparsers)


def _register_limits(subparsers) -> None:
    li = subparsers.add_parser("limits", help="gain limits of the P position loop and margins",
                               description=LIMITS_DESCRIPTION, epilog=EPILOG)
    li.add_argument("plant", metavar="PLANT.toml", nargs="?", default=None,
                    help="plant file (optional: else give --w0, --zeta, --sample-time)")
    li.add_argument("--x", type=finite_float, metavar="X", help="piston position, m (with PLANT.toml)")
    li.add_argument("--w0", type=finite_float, metavar="W0", help="natural frequency, rad/s (model)")
    li.add_argument("--zeta", type=finite_float, metavar="ZETA", help="damping ratio, - (model)")
    li.add_argument("--sample-time", type=finite_float, metavar="T",
                    help="sample time, s (model: required; plant: default controller.sample_time)")
    li.add_argument("--k0", type=finite_float, metavar="K0",
                    help="loop gain kp Kv, 1/s, for the margins "
                         "(plant: default controller.kp * Kv)")
    li.add_argument("--kp", type=finite_float, metavar="KP",
                    help="controller gain, V/m, instead of --k0 (model: needs --kv)")
    li.add_argument("--kv", type=finite_float, metavar="KV",
                    help="velocity gain, m/(V s) (model only): shows the limits as kp = K0/Kv")
    li.add_argument("--json", action="store_true",
                    help="print JSON: k0, continuous, pct, sampled, sampled_delay (1/s), "
                         "gain_margin, phase_margin_deg, and context; inf is written as null")
    li.set_defaults(func=_limits)


def _register_map(subparsers) -> None:
    mp = subparsers.add_parser(
        "map", help="stability map over two swept parameters", description=MAP_DESCRIPTION,
        epilog=EPILOG + " Example: workbench map designs/plants/situm_rodless_nominal.toml "
                        "--x-axis k0=1:90:100 --y-axis mass=0.3:5:100 --out map/")
    mp.add_argument("plant", metavar="PLANT.toml", help="plant file")
    mp.add_argument("--x-axis", required=True, metavar="NAME=START:STOP[:NUM]",
                    help="horizontal axis")
    mp.add_argument("--y-axis", required=True, metavar="NAME=START:STOP[:NUM]",
                    help="vertical axis")
    mp.add_argument("--out", required=True, metavar="DIR", help="output folder (created if needed)")
    mp.add_argument("--position", type=finite_float, metavar="X",
                    help="piston position of the equilibrium, m (default mid-stroke)")
    mp.add_argument("--kp", type=finite_float, help="controller gain, V/m (default: plant file)")
    mp.add_argument("--kd", type=finite_float, help="derivative gain, V s/m (default: plant file)")
    mp.add_argument("--ki", type=finite_float, help="integral gain, V/(m s) (default: plant file)")
    mp.add_argument("--sample-time", dest="sample_time", type=finite_float, metavar="T",
                    help="sample time, s (default: plant file)")
    mp.add_argument("--delay", type=nonnegative_int, default=0, metavar="N",
                    help="samples of computation delay (default 0)")
    mp.add_argument("--scheduler", metavar="ADDRESS",
                    help="Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: local cores)")
    mp.add_argument("--workers", type=positive_int, metavar="N",
                    help="local worker processes (default: all cores)")
    mp.add_argument("--json", action="store_true", help="print a JSON summary")
    mp.add_argument("--no-plot", action="store_true", help="do not write map.png")
    mp.add_argument("--quiet", action="store_true", help="no progress bar")
    mp.set_defaults(func=_map)


# ---------------------------------------------------------------------- limits
def _limits(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..params import json_safe
    if args.k0 is not None and args.kp is not None:
        raise InputError("give the loop gain --k0 (1/s) or the controller gain --kp (V/m), "
                         "not both")
    if args.plant is not None:
        lim, where, notes = _limits_of_plant(args)
    else:
        lim, where, notes = _limits_of_model(args), "model", []
    if args.json:
        out = lim.to_dict()
        if args.plant is not None:
            out = {**out, "plant": str(args.plant), "x": args.x, "notes": notes}
        print(json.dumps(json_safe(out), indent=2))
        return 0
    _print_limits(lim, where, notes)
    return 0


def _limits_of_plant(args: argparse.Namespace):
    """(GainLimits, where, notes) from PLANT.toml at --x."""
    from .. import stability
    from ..errors import InputError
    from ..plant import Plant
    model_opts = [o for o, v in (("--w0", args.w0), ("--zeta", args.zeta), ("--kv", args.kv))
                  if v is not None]
    if model_opts:
        raise InputError(f"{', '.join(model_opts)} cannot be combined with PLANT.toml: "
                         "with a plant file Kv, w0 and zeta come from its linearisation "
                         "at --x")
    if args.x is None:
        raise InputError("with PLANT.toml the position --x (m) is needed")
    plant = Plant.from_toml(args.plant)
    lim = stability.limits_from_plant(plant, args.x, sample_time=args.sample_time,
                                      kp=args.kp, k0=args.k0)
    notes = []
    kind = plant.params.get("controller.kind") if plant.params.has_controller else None
    if kind not in (None, "p"):
        notes.append(f"the plant file's controller is {kind}; these limits are for a P "
                     "controller with its kp")
    return lim, f"{args.plant} at x = {args.x:g} m", notes


def _limits_of_model(args: argparse.Namespace):
    """GainLimits of the model --w0, --zeta, --sample-time (and --k0 or --kp with --kv)."""
    from .. import stability
    from ..errors import InputError
    if args.x is not None:
        raise InputError("--x needs PLANT.toml; for a model give --w0, --zeta and "
                         "--sample-time instead")
    missing = [o for o, v in (("--w0", args.w0), ("--zeta", args.zeta),
                              ("--sample-time", args.sample_time)) if v is None]
    if missing:
        raise InputError("give PLANT.toml with --x, or the model --w0, --zeta and "
                         f"--sample-time (missing: {', '.join(missing)})")
    k0 = args.k0
    if args.kv is not None and not (np.isfinite(args.kv) and args.kv > 0):
        raise InputError(f"--kv must be a positive velocity gain, m/(V s), got {args.kv:g}")
    if args.kp is not None:
        if args.kv is None:
            raise InputError("--kp (V/m) needs --kv (m/(V s)) to form K0 = kp Kv; "
                             "or give --k0 directly")
        k0 = args.kp * args.kv
    return stability.gain_limits(args.w0, args.zeta, args.sample_time, k0=k0, kv=args.kv)


def _num(v, fmt=".4g"):
    return "-" if v is None else ("inf" if not np.isfinite(v) else format(v, fmt))


def _print_limits(lim, where: str, notes: list[str]) -> None:
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
        print(f"  {label:<{width}}  {_num(val):>10}  {_num(lim.kp_limit(name)):>10}  "
              f"{_num(ratio, '.3f'):>9}")
    if lim.k0 is not None:
        gm = lim.gain_margin
        gm_db = f" ({20 * np.log10(gm):.1f} dB)" if np.isfinite(gm) and gm > 0 else ""
        print()
        print(f"  margins at K0 = {lim.k0:.4g} 1/s (sampled loop, no delay): "
              f"gain {_num(gm)}{gm_db}, phase {_num(lim.phase_margin_deg, '.1f')} deg")
    for n in notes:
        print("note: " + n)


# ---------------------------------------------------------------------- map
def _map(args: argparse.Namespace) -> int:
    out = prepare_output(args.out, MAP_FILES, [args.plant])
    from ..plant import Plant
    from ..stability import maps
    from ..stability.loop import map_controller
    plant = Plant.from_toml(args.plant)
    xa, ya = maps.parse_axis(args.x_axis), maps.parse_axis(args.y_axis)
    ctrl = map_controller(plant, {xa.name, ya.name}, kp=args.kp, kd=args.kd, ki=args.ki,
                          sample_time=args.sample_time)
    if not args.quiet:              # a line even where no progress bar is drawn (no tty)
        import sys
        print(f"map: {len(xa)} x {len(ya)} = {len(xa) * len(ya)} points ...", file=sys.stderr,
              flush=True)
    smap = maps.stability_map(plant, xa, ya, position=args.position, controller=ctrl,
                              delay_samples=args.delay, scheduler=args.scheduler,
                              workers=args.workers, progress=not args.quiet and None)
    summary = {k: v for k, v in smap.to_dict().items() if k != "rho"}
    summary["files"] = {"csv": str(out / "map.csv"), "json": str(out / "map.json"),
                        "png": str(out / "map.png")}
    _write_map(args, out, smap)
    if args.json:
        from ..output import strict_json
        print(json.dumps(strict_json(summary), indent=2))
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


def _write_map(args: argparse.Namespace, out: Path, smap) -> None:
    """map.csv, map.json (and map.png), all or none."""
    from .. import plots
    from ..output import result_set, write_json
    with result_set(out, inputs=[args.plant]) as stage:
        smap.to_csv(stage / "map.csv")
        write_json(stage / "map.json", smap.to_dict(), indent=1)
        if not args.no_plot:
            plots.save_figure(plots.stability_map_figure(smap), stage / "map.png")
