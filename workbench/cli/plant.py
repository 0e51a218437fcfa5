"""``workbench check`` and ``workbench linearize``: a plant file and its tangent model."""

from __future__ import annotations

import argparse
import json

import numpy as np

from .common import EPILOG

__all__ = ["register"]


def register(subparsers) -> None:
    """Add ``check`` and ``linearize`` to ``workbench``'s sub-parsers."""
    c = subparsers.add_parser("check", help="validate a plant file and print a summary",
                              description="Validate PLANT.toml (formats.md sections 1-2), "
                                          "check its physical plausibility (valve flows "
                                          "within the ISO 6358 limit of the stated "
                                          "conductance, controller period vs the fastest "
                                          "pole, memory of a run) and print areas, volumes, maximum force, valve flow at "
                                          "full opening (l/min ANR) and the effects that are "
                                          "switched on.",
                              epilog=EPILOG)
    c.add_argument("plant", metavar="PLANT.toml", help="plant file")
    c.add_argument("--json", action="store_true", help="print the summary as JSON (SI units)")
    c.set_defaults(func=_check)

    lz = subparsers.add_parser("linearize", help="equilibrium and exact tangent model at a "
                                                 "position",
                               description="Find the equilibrium with the piston at rest at X "
                                           "(valve command, chamber pressures), the exact A, B, "
                                           "C, D from CasADi's automatic differentiation, the "
                                           "eigenvalues, and the reduced position model Kv / "
                                           "(s (s^2/w0^2 + 2 zeta s/w0 + 1)) of paper 000 "
                                           "fitted to it.",
                               epilog=EPILOG)
    lz.add_argument("plant", metavar="PLANT.toml", help="plant file")
    lz.add_argument("--x", type=float, required=True, metavar="X", help="piston position, m")
    lz.add_argument("--json", action="store_true", help="print JSON")
    lz.set_defaults(func=_linearize)


def _check(args: argparse.Namespace) -> int:
    from .. import units
    from ..plant import Plant
    from ..plausibility import check_plant
    plant = Plant.from_toml(args.plant)
    s = plant.to_dict()
    plaus = check_plant(plant)
    if args.json:
        print(json.dumps({**s, "plausibility": plaus.to_dict()}, indent=2))
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
        ("plausibility", plaus.summary().replace("\n", "; ")),
    ]
    width = max(len(r[0]) for r in rows)
    print("plant file OK")
    for k, v in rows:
        print(f"  {k:<{width}}  {v}")
    return 0


def _linearize(args: argparse.Namespace) -> int:
    from .. import linearize
    from ..errors import WorkbenchError
    from ..plant import Plant
    plant = Plant.from_toml(args.plant)
    op = linearize.operating_point(plant, args.x)
    lin = linearize.tangent(plant, op)
    red_err = None
    try:
        red = linearize.reduced_position_model(lin).to_dict()
    except WorkbenchError as exc:
        red, red_err = None, str(exc)
    ev = lin.eigenvalues
    tangent = lin.to_dict()
    notes = tangent.pop("notes") + ([red_err] if red_err else [])
    out = {"plant": str(args.plant), **tangent, "reduced_model": red, "notes": notes}
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
