"""``workbench identify greybox``: physical parameters of the plant from recordings."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

from ...errors import InputError
from ..common import finite_float, positive_int, prepare_output

__all__ = ["add_greybox"]

#: Files ``--out`` receives.
GREYBOX_FILES = ("estimates.json", "plant_estimated.toml", "fit.png")


def add_greybox(subparsers) -> None:
    """Add ``workbench identify greybox``."""
    epilog = ("Units are SI (m, Pa absolute, kg, s, V). Example: workbench identify greybox "
              "designs/plants/rig25_mpye.toml run1.csv run2.csv --params load.mass "
              "load.viscous_friction valve.sonic_conductance --out fit/")
    p = subparsers.add_parser(
        "greybox", help="estimate physical plant parameters from recordings",
        description="Grey-box estimation: fit the named parameters of PLANT.toml to one or "
                    "more recordings by replaying their command u open loop (multiple "
                    "shooting, fixed-step Radau IIA, IPOPT with a Gauss-Newton Hessian). "
                    "Prints the estimates with standard deviations and 95 % intervals and "
                    "the fit (%) before and after from fresh CVODES simulations (closed loop "
                    "on the recorded r with the plant's [controller] when both exist). With "
                    "--out writes DIR/estimates.json, DIR/plant_estimated.toml and "
                    "DIR/fit.png. Effect parameters (friction.coulomb, "
                    "leakage.conductance_to_atmosphere, ...) need the effect in the plant "
                    "file (its start values).",
        epilog=epilog)
    p.add_argument("plant", metavar="PLANT.toml", help="plant file with start values")
    p.add_argument("recordings", metavar="RECORDING", nargs="+",
                   help="recordings (.csv or .mat) with t, u and the compared signals")
    p.add_argument("--params", nargs="+", required=True, metavar="NAME",
                   help="dotted parameter names, e.g. load.mass load.viscous_friction")
    p.add_argument("--bounds", nargs="+", default=[], metavar="NAME=LOW:HIGH",
                   help="bounds in SI units (default: x0.1 .. x10 of the start value)")
    p.add_argument("--signals", nargs="+", default=["x", "p_a", "p_b"], metavar="SIG",
                   help="signals to compare when recorded (default: x p_a p_b)")
    p.add_argument("--shooting-interval", type=finite_float, default=0.05, metavar="S",
                   help="shooting interval, s (default 0.05)")
    p.add_argument("--x0", choices=("estimate", "from_recording"), default="estimate",
                   help="initial state: estimated (default) or measured values fixed")
    p.add_argument("--replay", choices=("auto", "open", "closed"), default="auto",
                   help="before/after check: closed loop on r when the recording has r and "
                        "the plant a [controller] (auto), or always open loop on u")
    p.add_argument("--substeps", type=positive_int, default=None, metavar="N",
                   help="integration steps per sample (default: steps <= 1 ms, 0.125 ms "
                        "with dry friction)")
    p.add_argument("--max-iter", type=positive_int, default=50, metavar="N",
                   help="IPOPT iterations (default 50)")
    p.add_argument("--out", metavar="DIR", help="output folder (created if needed)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--verbose", action="store_true", help="print IPOPT's iteration log")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    from ..recording_args import add_recording_options
    add_recording_options(p)
    p.set_defaults(func=_cmd_greybox)


def _parse_bounds(items: Sequence[str]) -> dict[str, tuple[float, float]]:
    out = {}
    for it in items or ():
        name, sep, rng = it.partition("=")
        lo, sep2, hi = rng.partition(":")
        try:
            if not sep or not sep2:
                raise ValueError
            out[name.strip()] = (float(lo), float(hi))
        except ValueError:
            raise InputError(f"--bounds expects NAME=LOW:HIGH in SI units, got '{it}'",
                             location="--bounds") from None
    return out


def _cmd_greybox(args) -> int:
    out_dir = (prepare_output(args.out, GREYBOX_FILES, [args.plant, *args.recordings])
               if args.out is not None else None)
    if not args.shooting_interval > 0:
        raise InputError(f"--shooting-interval must be > 0 s, got {args.shooting_interval:g}",
                         location="--shooting-interval")
    bounds = _parse_bounds(args.bounds)
    from ...identify.grey_box import estimate
    from ...output import strict_json
    from ...plant import Plant
    from ..recording_args import load_from_args
    plant = Plant.from_toml(args.plant)
    recs = [load_from_args(args, p, plant=plant) for p in args.recordings]
    if not (args.quiet or args.json):   # a line even where no progress bar is drawn (no tty)
        import sys
        print(f"greybox: estimating {', '.join(args.params)} from {len(recs)} recording(s) "
              f"({sum(len(r) for r in recs)} samples) ...", file=sys.stderr, flush=True)
    res = estimate(plant, recs, args.params, bounds=bounds,
                   signals=tuple(args.signals), shooting_interval=args.shooting_interval,
                   x0=args.x0, replay=args.replay, substeps=args.substeps,
                   max_iter=args.max_iter,
                   verbose=args.verbose, progress=False if args.quiet or args.json else None)
    out = res.to_dict()
    out["plant"] = str(args.plant)
    if out_dir is not None:
        _write(args, out_dir, out, res, recs, plant.name)
        out["files"] = [str(out_dir / f) for f in GREYBOX_FILES]
    if args.json:
        print(json.dumps(strict_json(out), indent=2))
    else:
        print(res.table())
        if args.out:
            print(f"wrote {args.out}/estimates.json, plant_estimated.toml, fit.png")
    return 0


def _write(args, out_dir: Path, out: dict, res, recs, plant_name: str) -> None:
    """estimates.json, plant_estimated.toml and fit.png, all or none."""
    from ...identify.plots import greybox_figure
    from ...output import result_set, write_json
    with result_set(out_dir, inputs=[args.plant, *args.recordings]) as stage:
        write_json(stage / "estimates.json", out)
        res.plant_.params.to_toml(stage / "plant_estimated.toml")
        greybox_figure(recs, res, stage / "fit.png",
                       title=f"grey-box fit: {plant_name}, {', '.join(res.names)}")
