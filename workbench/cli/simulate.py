"""``workbench simulate``: replay a recording on the plant model (:func:`workbench.replay.replay`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import EPILOG, prepare_output
from .recording_args import add_recording_options

__all__ = ["register"]

#: Files ``--out`` receives.
SIMULATE_FILES = ("simulation.csv", "fit.json", "simulation.png")


def register(subparsers) -> None:
    """Add ``simulate`` to ``workbench``'s sub-parsers."""
    s = subparsers.add_parser(
        "simulate", help="replay a recording on the plant model",
        description="Replay RECORDING on the plant model: closed loop on the recording's 'r' "
                    "with the plant file's [controller] when both exist, else open loop on "
                    "its 'u'. The simulation starts from the recording's first position (and "
                    "pressures, if recorded). Writes DIR/simulation.csv (the recording's "
                    "columns; 'r' and unknown columns copied), DIR/fit.json (NRMSE fit in "
                    "percent of x, p_a, p_b as recorded) and DIR/simulation.png.",
        epilog=EPILOG)
    s.add_argument("plant", metavar="PLANT.toml", help="plant file")
    s.add_argument("recording", metavar="RECORDING",
                   help="recording (.csv or .mat, formats.md section 3)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder (created if needed)")
    s.add_argument("--mode", choices=("auto", "closed", "open"), default="auto",
                   help="force closed-loop or open-loop replay (default: auto)")
    s.add_argument("--no-plot", action="store_true", help="do not write simulation.png")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    add_recording_options(s)
    s.set_defaults(func=_simulate)


def _simulate(args: argparse.Namespace) -> int:
    out_dir = prepare_output(args.out, SIMULATE_FILES, [args.plant, args.recording])
    from ..plant import Plant
    from ..recording import fit_signals
    from ..replay import replay
    plant = Plant.from_toml(args.plant)
    from .recording_args import load_from_args
    rec = load_from_args(args, args.recording, plant=plant)
    if not args.quiet:              # a line even where no progress bar is drawn (no tty)
        print(f"simulate: replaying {len(rec)} samples ({rec.duration:.3g} s) of "
              f"{args.recording} ...", file=sys.stderr, flush=True)
    result = replay(plant, rec, mode=args.mode, progress=None if not args.quiet else False)
    sim_rec = result.recording
    fits = fit_signals(rec, sim_rec, names=[n for n in ("x", "p_a", "p_b") if n in rec])
    mode = result.mode.replace("_", " ")
    _write(args, out_dir, rec, sim_rec, fits, f"{plant.name}: {mode} replay of "
                                               f"{Path(args.recording).name}")
    print(f"{mode} replay of {args.recording} ({len(rec)} samples, {rec.duration:.3g} s)")
    for k, v in fits.items():
        print(f"  fit {k:<4} " + (f"{v:7.2f} %" if v is not None and v == v else
                                   "    n/a (the recorded signal is constant: NRMSE "
                                   "undefined)"))
    print(f"wrote {out_dir / 'simulation.csv'} and {out_dir / 'fit.json'}")
    return 0


def _write(args: argparse.Namespace, out_dir: Path, rec, sim_rec, fits, title: str) -> None:
    """simulation.csv, fit.json (strict JSON: an undefined fit is null) and
    simulation.png, all or none."""
    from ..output import result_set, write_json
    with result_set(out_dir, inputs=[args.plant, args.recording]) as stage:
        sim_rec.to_csv(stage / "simulation.csv")
        write_json(stage / "fit.json", fits)
        if not args.no_plot:
            from ..plots import replay_figure
            replay_figure(rec, sim_rec, fits, stage / "simulation.png", title=title)
