"""``workbench design``: a controller from a plant file, validated, with its report."""

from __future__ import annotations

import argparse
import json

from .common import EPILOG

__all__ = ["register"]

DESCRIPTION = (
    "Design a position controller for PLANT.toml (workbench.controllers.design: PID, "
    "feedback linearisation or NMPC, with a Kalman observer for velocity and unmodelled "
    "force from x, p_a, p_b, the valve deadband inverted, a hold lock against "
    "stick-slip hunting, and the reference smoothed to the axis's limits), run it on the "
    "plant file's full plant behind rig sensors (position ADC, noisy pressures, no "
    "velocity) over the precision validation profile (steps, ramps, holds and a 60 mm x "
    "stroke/0.5 m, 0.5 Hz sine), judge it by the precision specification and write "
    "DIR/report.html, DIR/report.pdf, DIR/design.json and DIR/validation.csv. The "
    "folder is written whole or not at all.")


def register(subparsers) -> None:
    """Add ``design`` to ``workbench``'s sub-parsers."""
    p = subparsers.add_parser("design", help="design, validate and report a position controller",
                              description=DESCRIPTION, epilog=EPILOG)
    p.add_argument("plant", metavar="PLANT.toml", help="plant file")
    p.add_argument("--kind", choices=("pid", "fl", "nmpc"), default="nmpc",
                   help="controller law (default nmpc)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--position-bits", type=int, default=12, metavar="BITS",
                   help="position ADC resolution over the stroke (default 12)")
    p.add_argument("--pressure-noise", type=float, default=300.0, metavar="PA",
                   help="pressure sensor noise, Pa std (default 300)")
    p.add_argument("--quick", action="store_true",
                   help="short profile (holds 1 s, one sine period): a smoke run")
    p.add_argument("--no-jit", dest="jit", action="store_false",
                   help="NMPC in CasADi's virtual machine (no C compiler needed; slower)")
    p.set_defaults(func=_design)


def _design(args: argparse.Namespace) -> int:
    from .. import report as rp
    from .. import validate
    from ..controllers.evaluation import evaluate_design
    from ..errors import InputError
    from ..output import check_output_dir, result_set
    from ..params import json_safe
    from ..plant import Plant
    out = check_output_dir(args.out)
    if not 1 <= args.position_bits <= 32:
        raise InputError(f"--position-bits must be in 1..32, got {args.position_bits}")
    if not args.pressure_noise >= 0:
        raise InputError(f"--pressure-noise must be >= 0 Pa, got {args.pressure_noise}")
    plant = Plant.from_toml(args.plant)
    ref = validate.precision_profile(plant, hold=1.0 if args.quick else 2.5,
                                     sine_periods=1 if args.quick else 3)
    ev = evaluate_design(plant, args.kind, reference=ref, position_bits=args.position_bits,
                         pressure_noise=args.pressure_noise, jit=args.jit, progress=None)
    verdict = "PASS" if ev.validation.passed else "FAIL"
    doc = rp.Report(
        title=f"{args.kind.upper()} position controller for {plant.name}",
        subtitle=f"workbench design {args.plant} --kind {args.kind}",
        status=rp.Status(verdict, f"precision specification {'met' if verdict == 'PASS' else 'not met'}: "
                         + (", ".join(c.name for c in ev.validation.failed) or "all checks pass")),
        sections=ev.sections(),
        provenance=rp.provenance(plant_file=args.plant))
    with result_set(out, inputs=[args.plant]) as stage:
        rp.write(doc, stage)
        (stage / "design.json").write_text(json.dumps(json_safe(ev.to_dict()), indent=2))
        ev.validation.trajectory.to_csv(stage / "validation.csv",
                                        columns=("t", "u", "x", "v", "p_a", "p_b", "r"))
    print(ev.summary())
    print(f"wrote {out}/report.html, report.pdf, design.json, validation.csv")
    return 0
