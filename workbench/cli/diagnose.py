"""``workbench diagnose PLANT.toml RECORDING [RECORDING ...] --out DIR`` (:func:`workbench.diagnose.diagnose`)."""

from __future__ import annotations

import argparse
import json
import sys

from .common import positive_int

__all__ = ["register"]

DESCRIPTION = (
    "Diagnose where the nominal plant and a recording differ and what physics is missing. "
    "Replays the recording (closed loop on r with the plant file's [controller] when both "
    "exist, else open loop on u re-anchored on the measured state), locates the mismatch in "
    "time and operating regime, refits every candidate effect of formats.md section 2 "
    "(dry_friction, valve_deadband, valve_offset, valve_dynamics, line_dynamics, leakage, "
    "supply_droop, heat_transfer) and wrong nominal values (parameter_error: load.mass, "
    "load.viscous_friction, valve.sonic_conductance, supply.pressure), ranks them by evidence, "
    "refits pairs and triples of the best jointly and keeps the set with the lowest BIC in "
    "which every member earns its place. Writes DIR/diagnosis.json (formats.md section 4), "
    "DIR/plant.augmented.toml, DIR/report.html (+ report.pdf) and DIR/details.json "
    "(every candidate's evidence), all or nothing. A replay that fails (non-finite, "
    "piston beyond the stroke) or fits worse than a constant, with no candidate to "
    "explain it, is an error with its cause (exit 2), never 'no finding'. Several "
    "recordings of the same rig are diagnosed together (one set of findings, the fit per "
    "recording), also when they measure different signals (e.g. one with x, p_a, p_b and "
    "one with x only: each signal counts where it was recorded); a recording with one chamber pressure uses it (the other is estimated "
    "from the force balance); a recorded supply pressure p_s that sags under flow is "
    "used sample by sample.")


def register(subparsers) -> None:
    """Add ``diagnose`` to ``workbench``'s sub-parsers."""
    from ..params import EFFECT_NAMES
    p = subparsers.add_parser("diagnose", help="locate and explain a model/recording mismatch",
                              description=DESCRIPTION,
                              epilog="Units are SI (m, Pa absolute, kg, s, V). Example: "
                                     "workbench diagnose plant.toml run.csv --out diag/")
    p.add_argument("plant", metavar="PLANT.toml", help="nominal plant file")
    p.add_argument("recording", metavar="RECORDING", nargs="+",
                   help="recording (.csv or .mat); several: experiments on the same rig "
                        "diagnosed together (one set of findings, the fit per recording)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if needed)")
    p.add_argument("--json", action="store_true", help="print diagnosis.json instead of a summary")
    p.add_argument("--quiet", action="store_true", help="no progress messages (on stderr)")
    p.add_argument("--effects", nargs="+", metavar="EFFECT",
                   choices=list(EFFECT_NAMES) + ["parameter_error"],
                   help="candidates to test (default: all effects and parameter_error)")
    p.add_argument("--mode", choices=("auto", "closed", "open"), default="auto",
                   help="replay mode (default auto: closed loop when r and [controller] exist)")
    p.add_argument("--workers", type=positive_int, metavar="N",
                   help="processes for the candidate refits (default: all cores)")
    p.add_argument("--no-report", action="store_true", help="do not write report.html/.pdf")
    from .recording_args import add_recording_options
    add_recording_options(p)
    p.set_defaults(func=_diagnose)


def _diagnose(args: argparse.Namespace) -> int:
    """Run the sub-command (errors a user can cause are WorkbenchError: exit 2 in main)."""
    from pathlib import Path

    from ..diagnose import diagnose
    from ..diagnose.result import OUTPUT_FILES
    from ..output import check_not_input, check_output_dir
    check_output_dir(args.out)            # refused before minutes of work, not after
    check_not_input([Path(args.out) / n for n in OUTPUT_FILES], [args.plant, *args.recording])
    verbose = not args.quiet and not args.json
    if verbose:
        print(f"diagnosing {', '.join(args.recording)} on {args.plant} ...", file=sys.stderr,
              flush=True)
    from ..params import PlantParams
    from .recording_args import load_from_args
    params = PlantParams.from_toml(args.plant)
    recs = [load_from_args(args, r, plant=params) for r in args.recording]
    d = diagnose(args.plant, recs if len(recs) > 1 else recs[0], effects=args.effects,
                 workers=args.workers, mode=args.mode, verbose=verbose)
    paths = d.write(args.out, report=not args.no_report, inputs=[args.plant, *args.recording])
    if args.json:
        print(json.dumps(d.to_dict(), indent=2))
    else:
        print(d.summary())
        print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0
