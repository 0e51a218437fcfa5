"""``workbench identify valve`` and ``valve-table``: paper 003's valve characteristic."""

from __future__ import annotations

import argparse
import json
import math
import shlex
from typing import Any

import numpy as np

from ...errors import InputError
from ...output import check_not_input
from ...params import PlantParams, atomic_write_text
from ..common import positive_int


def _lazy(name: str):
    """``workbench.identify.valve.<name>``, imported on first call (h15io: the parser is
    built at every start, and identify.valve loads SciPy and CasADi; ``--help`` < 1 s)."""
    def call(*args, **kwargs):
        from ...identify import valve
        return getattr(valve, name)(*args, **kwargs)
    call.__name__ = name
    return call


(ValveFitReport, affine_count, affine_structure, analyse, catalog_table, centre_dense_commands,
 compare_pressure_gain, flow_limit_problems, generate_valve_table, load_catalog_curve,
 load_valve_table, polynomial_degrees, valve_flow_law, write_figures) = map(_lazy, (
    "ValveFitReport", "affine_count", "affine_structure", "analyse", "catalog_table",
    "centre_dense_commands", "compare_pressure_gain", "flow_limit_problems",
    "generate_valve_table", "load_catalog_curve", "load_valve_table", "polynomial_degrees",
    "valve_flow_law", "write_figures"))

__all__ = ["add_valve"]


def add_valve(subparsers) -> None:
    """Add ``workbench identify valve`` and ``workbench identify valve-table``."""
    v = subparsers.add_parser(
        "valve", help="fit paper 003's valve characteristic approximations I and II",
        description="Fit a measured valve table (CSV: u [V], p [Pa abs], q_m [kg/s into the "
                    "port]) with approximation I (full polynomial, degrees n in p, m in u) "
                    "and/or II (input-affine q = phi(p) + psi(p, sgn Gamma) Gamma(u), Gamma odd, "
                    "fitted by IPOPT with Gamma(1) = 1 and Gamma monotone). Reports R "
                    "(multiple correlation coefficient) and errors in g/s, the pressure gain "
                    "characteristic (q_m = 0 curve) with Cp, Gu against the data, and tank "
                    "step tests (+-1 V and +-0.1 V at the command centre) against the table "
                    "(or against --reference-plant's valve when the table was generated).",
        epilog="Example: workbench identify valve tests/data/valve/rig25_table.csv --approx both "
               "--out fit/ --plant-toml fitted.toml --base designs/plants/rig25_mpye.toml")
    v.add_argument("table", metavar="TABLE.csv",
                   help="valve table (or, with --catalog, a nominal-flow curve u, q_n)")
    v.add_argument("--approx", "--approximation", dest="approx", choices=("I", "II", "both"),
                   default="both", help="which approximation (default both)")
    v.add_argument("--coefficients", type=int, metavar="N",
                   help="number of coefficients counted as paper 003 does: approximation I "
                        "(n+1)(m+1) (66: n = 5, m = 10), II (phi+1) + (psi+1) per branch + "
                        "(l+1) (15: degrees 5 5 2 with one psi; 21: two psi). Needs --approx "
                        "I or II")
    v.add_argument("--shared-psi", action="store_true",
                   help="approximation II: one psi for inlet and exhaust (paper 003's count)")
    v.add_argument("--phi-from", choices=("fit", "centre"), default="fit",
                   help="approximation II: fit phi with the rest (default) or to the centred "
                        "command's column alone (q(p, centre) = phi(p): the leakage measured "
                        "directly, but its slope, the tank's Cp at the centre, only from that "
                        "column's noisy points; --pressure-gain fixes the tangent model better)")
    v.add_argument("--pressure-gain", metavar="PG.csv",
                   help="measured blocked-port points (CSV header 'u,p': V, Pa absolute): "
                        "both fits pass through q(p_e, u) = 0 there exactly (the pressure "
                        "gain characteristic, which sets a closed tank's steady state and "
                        "tangent model far more precisely than flow readings near zero flow)")
    v.add_argument("--degrees", nargs=2, type=int, metavar=("N", "M"),
                   help="approximation I degrees in p and u (default 5 10, paper 003)")
    v.add_argument("--select", action="store_true",
                   help="choose approximation I degrees by 5-fold cross validation "
                        "(n 1..7, m 1..12)")
    v.add_argument("--affine-degrees", nargs=3, type=int, default=None,
                   metavar=("PHI", "PSI", "GAMMA"),
                   help="approximation II: degree of phi (-1: phi = 0), of psi_in/psi_out, "
                        "and number of odd Gamma terms (default 5 5 2, paper 003)")
    v.add_argument("--pin-ends", action="store_true",
                   help="approximation II: impose q(p_supply, full inlet) = 0 and "
                        "q(p_atm, full exhaust) = 0")
    v.add_argument("--tank-volume", type=float, default=1e-3, metavar="V",
                   help="tank volume of the step tests, m^3 (default 1e-3)")
    v.add_argument("--no-tank", action="store_true", help="skip the tank step tests")
    v.add_argument("--reference-plant", metavar="PLANT.toml",
                   help="the plant whose valve made the table (see valve-table): its true law "
                        "is the reference of the tank steps and adds its pressure gain curve")
    v.add_argument("--leakage", type=float, metavar="D",
                   help="underlap leakage of --reference-plant's valve (default: the table's "
                        "'leakage' metadata, else 0)")
    v.add_argument("--out", metavar="DIR", help="write DIR/valve_fit.json and figures")
    v.add_argument("--no-plot", action="store_true", help="no figures in DIR")
    v.add_argument("--json", action="store_true", help="print the results as JSON (SI; errors g/s)")
    v.add_argument("--plant-toml", metavar="OUT.toml",
                   help="write a copy of --base with its valve replaced by the fitted "
                        "approximation II")
    v.add_argument("--base", metavar="PLANT.toml", help="plant file for --plant-toml")
    _add_valve_checks(v)
    v.set_defaults(func=_cmd_valve)
    _add_valve_table(subparsers)


def _add_valve_checks(v) -> None:
    """The plausibility and catalog options of ``identify valve``."""
    v.add_argument("--plausibility-tolerance", type=float, default=0.25, metavar="F",
                   help="--plant-toml is refused when the fitted law's flow anywhere in the "
                        "table's range exceeds the ISO 6358 choked flow of --base's sonic "
                        "conductance by more than this fraction (default 0.25)")
    v.add_argument("--catalog", action="store_true",
                   help="TABLE.csv is a datasheet curve: columns u (V) and q_n (nominal flow, "
                        "l/min ANR, > 0 into the port, < 0 to the exhaust) at ISO 6358 "
                        "nominal conditions; with --critical-ratio and --supply-pressure the "
                        "ISO 6358 law makes the table that is fitted")
    v.add_argument("--critical-ratio", type=float, metavar="B",
                   help="--catalog: the datasheet's critical pressure ratio b")
    v.add_argument("--supply-pressure", type=float, metavar="PA",
                   help="--catalog: supply pressure of the table, Pa absolute")


def _add_valve_table(subparsers) -> None:
    """Add ``workbench identify valve-table``."""
    g = subparsers.add_parser(
        "valve-table", help="generate a valve table from a plant's four-edge valve",
        description="Write a valve table CSV (u, p, q_m) from the plant file's valve (four "
                    "ISO 6358 edges, its centre, span, offset, deadband) with a symmetric "
                    "geometric underlap --leakage (fraction of the span) and Gaussian noise "
                    "(kg/s). The header records the command and the settings.")
    g.add_argument("plant", metavar="PLANT.toml", help="plant file")
    g.add_argument("--out", required=True, metavar="TABLE.csv", help="output CSV")
    g.add_argument("--leakage", type=float, default=0.0, help="underlap, fraction of the span")
    g.add_argument("--noise", type=float, default=0.0, help="noise standard deviation, kg/s")
    g.add_argument("--seed", type=int, default=0, help="noise seed")
    g.add_argument("--u", metavar="LIST",
                   help="commands, V: a,b,c or START:STOP:NUM (default: 21, denser at the centre)")
    g.add_argument("--p", metavar="LIST",
                   help="pressures, Pa abs: a,b,c or START:STOP:NUM (default: 15 from "
                        "atmosphere to supply)")
    g.add_argument("--n-u", type=positive_int, default=21, help="number of default commands")
    g.add_argument("--n-p", type=positive_int, default=15, help="number of default pressures")
    g.set_defaults(func=_cmd_valve_table)


def _check_valve_args(args: argparse.Namespace) -> None:
    """Refuse option values and combinations the fit cannot honour, before any work."""
    if args.leakage is not None:
        if not (math.isfinite(args.leakage) and 0.0 <= args.leakage < 1.0):
            raise InputError(f"expected an underlap leakage in [0, 1) of the command span, "
                             f"got {args.leakage!r}", location="--leakage")
        if not args.reference_plant:
            raise InputError("--leakage describes --reference-plant's valve; give "
                             "--reference-plant PLANT.toml or drop --leakage",
                             location="--leakage")
    if not (math.isfinite(args.tank_volume) and args.tank_volume > 0):
        raise InputError(f"expected a tank volume > 0 m^3, got {args.tank_volume!r}",
                         location="--tank-volume")
    if not (math.isfinite(args.plausibility_tolerance) and args.plausibility_tolerance >= 0):
        raise InputError(f"expected a tolerance >= 0, got {args.plausibility_tolerance!r}",
                         location="--plausibility-tolerance")
    if args.coefficients is not None:
        if args.approx == "both":
            raise InputError("--coefficients names one approximation's size: add --approx I "
                             "or --approx II", location="--coefficients")
        if args.approx == "I":
            n_m = polynomial_degrees(args.coefficients)
            if args.degrees and tuple(args.degrees) != n_m and \
                    (args.degrees[0] + 1) * (args.degrees[1] + 1) != args.coefficients:
                raise InputError(f"--degrees {args.degrees[0]} {args.degrees[1]} give "
                                 f"{(args.degrees[0] + 1) * (args.degrees[1] + 1)} coefficients, "
                                 f"not {args.coefficients}", location="--coefficients")
            args.degrees = args.degrees or list(n_m)
        else:
            phi, psi, gam, shared = affine_structure(args.coefficients)
            if args.affine_degrees is not None and affine_count(
                    None if args.affine_degrees[0] < 0 else args.affine_degrees[0],
                    args.affine_degrees[1], args.affine_degrees[2],
                    args.shared_psi) != args.coefficients:
                raise InputError(f"--affine-degrees {' '.join(map(str, args.affine_degrees))} "
                                 f"do not give {args.coefficients} coefficients",
                                 location="--coefficients")
            if args.affine_degrees is None:
                args.affine_degrees, args.shared_psi = [phi, psi, gam], shared
    if args.affine_degrees is None:
        args.affine_degrees = [5, 5, 2]
    if args.catalog and (args.critical_ratio is None or args.supply_pressure is None):
        raise InputError("--catalog needs --critical-ratio B (the datasheet's b) and "
                         "--supply-pressure PA (absolute)", location="--catalog")
    if not args.catalog and (args.critical_ratio is not None or args.supply_pressure is not None):
        raise InputError("--critical-ratio and --supply-pressure belong to --catalog",
                         location="--catalog")


def _load_table(args: argparse.Namespace):
    if not args.catalog:
        return load_valve_table(args.table)
    return catalog_table(load_catalog_curve(args.table), args.critical_ratio, args.supply_pressure)


def _cmd_valve(args: argparse.Namespace) -> int:
    _check_valve_args(args)
    if args.out:
        from ...output import check_output_dir
        check_output_dir(args.out)
    table = _load_table(args)
    if args.plant_toml and not args.base:
        raise InputError("--plant-toml needs --base PLANT.toml (the plant whose valve is "
                         "replaced by the fitted law)", location="--plant-toml")
    if args.plant_toml and args.approx == "I":
        raise InputError("--plant-toml writes the input-affine law: use --approx II or both",
                         location="--plant-toml")
    base = PlantParams.from_toml(args.base) if args.base else None
    blocked = _lazy("load_pressure_gain")(args.pressure_gain) if args.pressure_gain else None
    phi_deg = None if args.affine_degrees[0] < 0 else args.affine_degrees[0]
    report = analyse(table, approx=args.approx,
                     degrees=tuple(args.degrees) if args.degrees else None, select=args.select,
                     affine_degrees=(phi_deg, args.affine_degrees[1], args.affine_degrees[2]),
                     pin_ends=args.pin_ends, shared_psi=args.shared_psi, phi_from=args.phi_from,
                     tank_volume=args.tank_volume, tank=not args.no_tank,
                     reference=_valve_reference(args, table), pressure_gain=blocked)
    result = report.to_dict()
    if args.plant_toml:
        report = _write_plant_toml(args, base, table, report, result)
    if args.out:
        from ...output import result_set
        inputs = [args.table, args.base, args.reference_plant, args.plant_toml,
                  args.pressure_gain]
        with result_set(args.out, inputs=inputs) as stage:     # all files or none
            (stage / "valve_fit.json").write_text(json.dumps(result, indent=2) + "\n")
            result["files"] = ["valve_fit.json"] + ([] if args.no_plot
                                                    else write_figures(report, stage))
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    _print_valve(report, table)
    if args.plant_toml:
        print(f"  wrote {args.plant_toml}")
    if args.out:
        print(f"  wrote {', '.join(result['files'])} in {args.out}")
    return 0


def _valve_reference(args: argparse.Namespace, table):
    """The true law of --reference-plant (leakage from --leakage or the table), or None."""
    if not args.reference_plant:
        return None
    leak = args.leakage
    if leak is None:
        leak = float(table.metadata.get("leakage", 0.0)) if _is_number(
            table.metadata.get("leakage", "0")) else 0.0
    return valve_flow_law(args.reference_plant, leak)


def _write_plant_toml(args: argparse.Namespace, base: PlantParams, table,
                      report: ValveFitReport, result: dict[str, Any]) -> ValveFitReport:
    """--plant-toml: --base with approximation II, written only if its flows are plausible
    for --base's stated conductance; a supply mismatch becomes a note."""
    new = base.replace(**report.approx_2.plant_values())
    if base.get("valve.sonic_conductance") is not None:
        problems = flow_limit_problems(
            report.approx_2.flow, base["valve.sonic_conductance"], table.supply_pressure,
            table.atmospheric_pressure, table.command_range, table.temperature,
            tolerance=args.plausibility_tolerance)
        if problems:
            raise InputError("the fitted law is not plausible for this valve, not writing it: "
                             + "; ".join(problems) + " (a table that does not cover the "
                             "range, or a different valve than --base states)",
                             location="--plant-toml")
    from ...plant import Plant
    Plant(new)                         # the written file must build a plant (raises if not)
    new.to_toml(args.plant_toml)
    result["plant_toml"] = str(args.plant_toml)
    p_base, p_tab = base["supply.pressure"], table.supply_pressure
    if abs(p_base - p_tab) > 0.01 * p_tab:
        note = (f"the base plant's supply pressure ({p_base:g} Pa) differs from the "
                f"table's ({p_tab:g} Pa): the input-affine law does not see the supply "
                "pressure, it holds only at the table's")
        result["notes"].append(note)
        report = ValveFitReport(**{**report.__dict__, "notes": report.notes + (note,)})
    return report


def _print_valve(report: ValveFitReport, table) -> None:
    """The text summary: fits, pressure gain comparisons, tank steps, notes."""
    print(f"valve table {table.source}: {len(table)} points, u {table.command_range[0]:g}.."
          f"{table.command_range[1]:g} V, p {table.pressure_range[0] / 1e5:.3f}.."
          f"{table.pressure_range[1] / 1e5:.3f} bar")
    for lab, fit in (("approximation I", report.approx_1), ("approximation II", report.approx_2)):
        if fit is None:
            continue
        qd = fit.quality
        what = (f"n = {fit.degrees[0]}, m = {fit.degrees[1]}" if lab.endswith(" I")
                else f"phi {len(fit.phi) - 1 if any(fit.phi) else '-'}, psi {len(fit.psi_in) - 1}"
                     f"{' (one for both directions)' if fit.psi_in == fit.psi_out else ''}, "
                     f"Gamma {len(fit.gamma)} odd terms")
        paper = (qd.coefficients if lab.endswith(" I") else affine_count(
            len(fit.phi) - 1 if any(fit.phi) else None, len(fit.psi_in) - 1, len(fit.gamma),
            fit.psi_in == fit.psi_out))
        print(f"  {lab:<17} {what}: {paper} coefficients by paper 003's count, "
              f"{qd.coefficients} stored ({qd.free} free), "
              f"R = {qd.r:.5f}, errors max {qd.max_error_g_s:.3f} g/s, RMS {qd.rms_g_s:.3f} g/s")
    refs = [r for r in ("data", report.reference) if r in report.gains]
    for lab, g in report.gains.items():
        for r in refs:
            if lab in refs[:refs.index(r) + 1]:
                continue
            cmp_ = compare_pressure_gain(report.gains[r], g, table.pressure_range)
            if cmp_["commands"]:
                gu = cmp_["median_rel_gu"]
                print(f"  pressure gain {lab} vs {r}: max |dp_e| "
                      f"{cmp_['max_abs_dp_e_Pa'] / 1e5:.4f} bar over {cmp_['commands']} "
                      f"commands; median relative difference Cp {100 * cmp_['median_rel_cp']:.1f} %"
                      f", Gu " + (f"{100 * gu:.1f} %" if gu is not None else "n/a"))
    if report.tank is not None:
        tk = report.tank
        for lab in tk.labels():
            if lab == tk.reference:
                continue
            errs = ", ".join(f"{du:+g} V: {100 * tk.max_error(lab, du):.2f} %"
                             for du in tk.step_sizes())
            print(f"  tank steps {lab} vs {tk.reference} (max pressure error): {errs}")
    for n_ in report.notes:
        print(f"  note: {n_}")


def _is_number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except (TypeError, ValueError):
        return False


def _float_list(text: str, option: str) -> np.ndarray:
    """``a,b,c`` or ``START:STOP:NUM`` -> array."""
    try:
        if ":" in text:
            a, b, n = text.split(":")
            return np.linspace(float(a), float(b), int(n))
        return np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise InputError(f"expected a,b,c or START:STOP:NUM, got {text!r}",
                         location=option) from None


def _cmd_valve_table(args: argparse.Namespace) -> int:
    check_not_input([args.out], [args.plant])       # h15io: never overwrite the input
    prm = PlantParams.from_toml(args.plant)
    cmd = ["workbench", "identify", "valve-table", str(args.plant), "--out", str(args.out),
           "--leakage", repr(args.leakage), "--noise", repr(args.noise), "--seed", str(args.seed)]
    cmd += ["--u", args.u] if args.u is not None else ["--n-u", str(args.n_u)]
    cmd += ["--p", args.p] if args.p is not None else ["--n-p", str(args.n_p)]
    made_with = " ".join(shlex.quote(c) for c in cmd)
    center, span = prm["valve.command_center"], prm["valve.command_span"]
    u = (centre_dense_commands(center, span, args.n_u) if args.u is None
         else _float_list(args.u, "--u"))
    p = (np.linspace(prm["gas.atmospheric_pressure"], prm["supply.pressure"], args.n_p)
         if args.p is None else _float_list(args.p, "--p"))
    table = generate_valve_table(prm, u, p, leakage=args.leakage, noise=args.noise,
                                 seed=args.seed, made_with=made_with)
    table.to_csv(args.out)
    print(f"wrote {args.out}: {len(table)} points")
    return 0
