"""``workbench robustness``: Monte Carlo pass rate of the plant file's controller
(:func:`workbench.robustness.monte_carlo`)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from .common import nonnegative_int, positive_int, prepare_output

__all__ = ["register"]

#: Files ``--out`` receives.
ROBUSTNESS_FILES = ("robustness.csv", "robustness.json", "robustness.png")

DESCRIPTION = ("Monte Carlo robustness of the plant file's [controller]: validate it "
               "(workbench.validate, standard profile) on N plants drawn from uncertainty "
               "ranges and report the pass rate with its 95 %% interval, the median and worst "
               "IAE and what fails. Ranges: --ranges usual (heat coefficient 1..1.4, sonic "
               "conductance x0.7..1.3, mass x0.5..2, supply +-1 bar) or paper002 (paper 002's "
               "bounds: heat coefficient 1..1.3997, combined flow factor 0.075..1.3297 on kappa "
               "C, mass and supply as usual), or your own with --vary (repeatable). With --out, "
               "writes DIR/robustness.csv (one row per draw), robustness.json and robustness.png.")


def register(subparsers) -> None:
    """Add ``robustness`` to ``workbench``'s sub-parsers."""
    from ..robustness import UNCERTAINTY_SETS
    p = subparsers.add_parser("robustness", help="Monte Carlo pass rate of the plant file's "
                                                 "controller on drawn plants",
                              description=DESCRIPTION,
                              epilog="Units are SI (m, Pa absolute, kg, s, V). Example: workbench "
                                     "robustness designs/plants/situm_rodless_nominal.toml "
                                     "--draws 20 --ranges paper002 --out mc/")
    p.add_argument("plant", metavar="PLANT.toml", help="plant file with a [controller]")
    p.add_argument("--draws", type=positive_int, default=20, metavar="N",
                   help="drawn plants (default 20)")
    p.add_argument("--seed", type=nonnegative_int, default=0,
                   help="random seed, an integer >= 0 (default 0)")
    p.add_argument("--ranges", choices=tuple(UNCERTAINTY_SETS), default="usual",
                   help="built-in ranges (default usual)")
    p.add_argument("--vary", action="append", metavar="KEY=LOW:HIGH[:MODE]",
                   help="own range instead of --ranges (repeatable); MODE factor, offset, "
                        "value or flow")
    p.add_argument("--workers", type=positive_int, metavar="N",
                   help="processes (default: all cores)")
    p.add_argument("--out", metavar="DIR", help="write robustness.csv, .json and .png here")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_robustness)


def _robustness(args: argparse.Namespace) -> int:
    """Run the sub-command (user errors raise WorkbenchError: exit 2 in main)."""
    out = (prepare_output(args.out, ROBUSTNESS_FILES, [args.plant])
           if args.out is not None else None)
    from .. import robustness as rb
    from ..controllers import from_plant
    from ..errors import InputError
    from ..output import strict_json
    from ..plant import Plant
    plant = Plant.from_toml(args.plant)
    if not plant.params.has_controller:
        raise InputError(f"{args.plant} has no [controller] section to validate")
    unc = (tuple(rb.parse_vary(v) for v in args.vary) if args.vary
           else rb.UNCERTAINTY_SETS[args.ranges])
    controller = from_plant(plant)
    name = getattr(controller, "kind", "controller")
    show = not (args.quiet or args.json)
    if show:                        # a line even where no progress bar is drawn (no tty)
        print(f"robustness: validating {name} on {args.draws} drawn plants "
              f"({args.workers or 'all'} worker(s)) ...", file=sys.stderr, flush=True)
    res = rb.monte_carlo(plant, {name: lambda p: controller}, n=args.draws, seed=args.seed,
                         uncertainty=unc, workers=args.workers,
                         progress=None if show else False)
    if out is not None:
        _write(out, res, plant, args.plant)
    if args.json:
        d = res.to_dict()
        d["controllers"][name]["pass_interval"] = list(res.pass_interval(name))
        print(json.dumps(strict_json({"plant": str(args.plant), **d}), indent=1))
        return 0
    _print_table(args, res, unc, name)
    return 0


def _write(out: Path, res, plant, plant_file) -> None:
    """robustness.csv, robustness.json and robustness.png in ``out``, all or none."""
    from .. import plots
    from ..output import result_set, write_json
    from ..params import atomic_write_text
    from ..robustness import figure_axes
    with result_set(out, inputs=[plant_file]) as stage:
        atomic_write_text(stage / "robustness.csv", res.to_csv_text(plant))
        write_json(stage / "robustness.json", {"plant": str(plant_file), **res.to_dict()},
                   indent=1)
        (x, xl), (y, yl) = figure_axes(res, plant)
        fig = plots.robustness_figure(res, x, y, xl, yl, title=f"Monte Carlo: {plant_file}")
        plots.save_figure(fig, stage / "robustness.png")


def _print_table(args: argparse.Namespace, res, unc, name: str) -> None:
    _, rate, n, med, worst, check = res.table()[0]
    lo, hi = res.pass_interval(name)
    print(f"Monte Carlo robustness of {args.plant} ({name}), {n} draws, seed {args.seed}")
    for u in unc:
        print(f"  {u.key}: {u.low:g} .. {u.high:g} ({u.mode})")
    print(f"  pass rate {rate:.0%} (95 % interval {lo:.0%} .. {hi:.0%})")
    if math.isfinite(med):
        print(f"  IAE median {med * 1e3:.3g} mm s, worst {worst * 1e3:.3g} mm s")
    if check:
        print(f"  most frequent failing check: {check}")
    if res.first_error.get(name):
        print(f"  first solver error: {res.first_error[name]}")
    if args.out:
        print(f"  written: {Path(args.out) / 'robustness.csv'}, robustness.json, robustness.png")
