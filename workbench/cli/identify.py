"""``workbench identify``: arx, rls, valve, valve-table, greybox.

Each sub-command parses its options, calls :mod:`workbench.identify` and prints or
writes what it returns; no estimation happens here. :func:`register` adds the group.
"""

from __future__ import annotations

import argparse
import io
import json
import math
import shlex
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import InputError
from ..identify.arx import CRITERIA, ArxModel, ArxValidation, fit_arx, select_order, validate
from ..identify.arx.checks import complex_pairs as _pairs, finite_or_none as _num
from ..identify.rls import DEFAULT_CANDIDATES, choose_forgetting, rls
from ..identify.rls.estimator import check_forgetting, default_burn_in
from ..identify.rls.report import report_md
from ..identify.valve import (ValveFitReport, analyse, centre_dense_commands,
                              compare_pressure_gain, generate_valve_table, load_valve_table,
                              valve_flow_law, write_figures)
from ..params import PlantParams, atomic_write_text, json_safe

__all__ = ["register"]

EPILOG = "Units are SI (m, Pa absolute, kg, s, V) unless an option says otherwise."


def register(subparsers: Any) -> None:
    """Add the ``identify`` command group (arx, rls, valve, valve-table, greybox).

    Parameters
    ----------
    subparsers : argparse sub-parsers action of the ``workbench`` parser.
    """
    ident = subparsers.add_parser("identify",
                                  help="models from recordings: arx, rls, valve, greybox",
                                  description="Identification from recorded data. Each method "
                                              "has its own sub-command; --help on each.",
                                  epilog=EPILOG)
    isub = ident.add_subparsers(dest="method", metavar="METHOD")
    isub.required = True
    _add_arx(isub)
    _add_rls(isub)
    _add_valve(isub)
    _add_greybox(isub)


# ====================================================================== arx
def _int_range(text: str) -> range:
    """``"1:5"`` or ``"3"`` -> range (inclusive)."""
    try:
        if ":" in text:
            lo, hi = (int(s) for s in text.split(":", 1))
        else:
            lo = hi = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected N or LO:HI, got {text!r}") from None
    if hi < lo:
        raise argparse.ArgumentTypeError(f"empty range {text!r}")
    return range(lo, hi + 1)


def _add_arx(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``workbench identify arx`` to the ``identify`` sub-parsers."""
    p = subparsers.add_parser(
        "arx", help="ARX model by least squares, with validation on held-out data",
        description="Fit an ARX model y(k) + a1 y(k-1) + ... = b1 u(k-nk) + ... + e(k) "
                    "(MATLAB arx orders na nb nk) to two columns of RECORDING by least "
                    "squares on the first SPLIT fraction of the samples; simulate it on "
                    "the rest (fit %) and test the one-step residuals there: "
                    "autocorrelation (Ljung-Box) and input-residual cross-correlation "
                    "against 99 % bands, each at the 1 % level. Paper 000's closed loop "
                    "[na nb d] = [4 1 1]: --input r --output x --orders 4 1 2. With "
                    "--select, orders are chosen over a grid first and the table printed.",
        epilog="Units are those of the recording's columns (SI). Example: workbench "
               "identify arx run.csv --input r --output x --orders 4 1 2 --split 0.5 --json")
    p.add_argument("recording", metavar="RECORDING",
                   help="recording (.csv or .mat, formats.md section 3)")
    p.add_argument("--input", default="r", metavar="COL", help="input column (default r)")
    p.add_argument("--output", default="x", metavar="COL", help="output column (default x)")
    p.add_argument("--orders", nargs=3, type=int, metavar=("NA", "NB", "NK"),
                   help="orders na nb nk (required unless --select)")
    p.add_argument("--split", type=float, default=0.5, metavar="F",
                   help="fraction of the samples used for estimation, 0 < F < 1; the rest "
                        "validates (default 0.5)")
    p.add_argument("--offset", action="store_true",
                   help="estimate a constant offset (operating point) along with a and b")
    p.add_argument("--select", action="store_true",
                   help="choose the orders over a grid (--na, --nb, --nk) and print the table")
    p.add_argument("--criterion", choices=CRITERIA, default="aic",
                   help="order selection criterion (default aic; loss and fit are on the "
                        "validation part)")
    p.add_argument("--na", type=_int_range, default=range(1, 6), metavar="LO:HI",
                   help="na grid for --select (default 1:5)")
    p.add_argument("--nb", type=_int_range, default=range(1, 4), metavar="LO:HI",
                   help="nb grid for --select (default 1:3)")
    p.add_argument("--nk", type=_int_range, default=range(0, 5), metavar="LO:HI",
                   help="nk grid for --select (default 0:4)")
    p.add_argument("--lags", type=int, default=25, metavar="M",
                   help="correlation lags of the residual tests, samples (default 25)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--out", metavar="DIR",
                   help="also write DIR/arx.json, DIR/residuals.png and DIR/validation.png")
    p.set_defaults(func=_cmd_arx)
    return p


def _cmd_arx(args: argparse.Namespace) -> int:
    rec, y, u, n_est = _arx_data(args)
    ye, ue, yv, uv = y[:n_est], u[:n_est], y[n_est:], u[n_est:]
    model, check, selection = _arx_fit(args, ye, ue, yv, uv, rec.sample_time, rec.source)
    result = _arx_result(args, model, check, rec, n_est,
                         _num(validate(model, ye, ue, lags=args.lags).fit))
    if selection is not None:
        result["selection"] = selection.to_dict()
    if args.out:
        _arx_write(args, model, check, result, float(rec.t[n_est]))
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    if selection is not None:
        print(f"order selection by {selection.criterion} "
              f"({n_est} estimation, {len(rec) - n_est} validation samples):")
        print(selection.table(limit=15))
        print()
    _print_summary(model, check, result, args)
    if args.out:
        print(f"wrote {Path(args.out) / 'arx.json'}, residuals.png, validation.png")
    return 0


def _arx_data(args: argparse.Namespace):
    """The recording, output and input columns, and the number of estimation samples."""
    from ..recording import load_recording

    rec = load_recording(args.recording)
    for role, col in (("input", args.input), ("output", args.output)):
        if not rec.has(col):
            raise InputError(f"no column '{col}' for the {role}; the recording has: "
                             f"{', '.join(rec.columns)}", source=rec.source)
    if not (math.isfinite(args.split) and 0.0 < args.split < 1.0):
        raise InputError(f"--split must be a fraction between 0 and 1 (exclusive), got "
                         f"{args.split}")
    if args.orders is None and not args.select:
        raise InputError("give --orders NA NB NK, or --select to choose them")
    y, u = np.asarray(rec[args.output]), np.asarray(rec[args.input])
    n_est = int(round(args.split * len(rec)))
    if n_est < 2 or len(rec) - n_est < 2:
        raise InputError(f"--split {args.split} leaves {n_est} estimation and "
                         f"{len(rec) - n_est} validation samples of {len(rec)}",
                         source=rec.source)
    return rec, y, u, n_est


def _arx_fit(args: argparse.Namespace, ye, ue, yv, uv, ts, src):
    """(model, validation on the held-out part, order selection or None)."""
    selection = None
    try:
        if args.select:
            selection = select_order(ye, ue, args.na, args.nb, args.nk,
                                     criterion=args.criterion, validation=(yv, uv),
                                     sample_time=ts, offset=args.offset)
            model = selection.model
        else:
            model = fit_arx(ye, ue, tuple(args.orders), sample_time=ts,
                            offset=args.offset)
        check = validate(model, yv, uv, lags=args.lags)
    except InputError as exc:
        if exc.source:
            raise
        raise InputError(str(exc), source=src,
                         location=f"columns '{args.input}' -> '{args.output}'") from None
    return model, check, selection


def _arx_result(args: argparse.Namespace, model: ArxModel, check: ArxValidation, rec,
                n_est: int, fit_estimation: float | None) -> dict[str, Any]:
    """The JSON result of ``identify arx`` (keys as printed by ``--json``)."""
    return {
        "a": model.a.tolist(), "b": model.b.tolist(),
        "std_a": model.std_a.tolist(), "std_b": model.std_b.tolist(),
        "fit_validation": _num(check.fit),
        "residual_whiteness_ok": check.whiteness_ok,
        "poles": _pairs(model.poles),
        "residual_independence_ok": check.independence_ok,
        "orders": [model.na, model.nb, model.nk],
        "nk": model.nk,
        "fit_estimation": fit_estimation,
        "whiteness_p_value": _num(check.whiteness_p_value),
        "independence_p_value": _num(check.independence_p_value),
        "noise_variance": _num(model.noise_variance),
        "loss": _num(model.loss), "aic": _num(model.aic), "fpe": _num(model.fpe),
        "dc_gain": _num(model.dc_gain), "zeros": _pairs(model.zeros),
        "stable": model.is_stable, "sample_time": rec.sample_time,
        "input": args.input, "output": args.output, "recording": str(args.recording),
        "n_estimation": n_est, "n_validation": len(rec) - n_est,
        "offset": bool(args.offset), "y_offset": model.y_offset,
        "u_offset": model.u_offset,
    }


def _arx_write(args: argparse.Namespace, model: ArxModel, check: ArxValidation,
               result: Mapping[str, Any], t0: float) -> None:
    """DIR/arx.json, DIR/residuals.png and DIR/validation.png."""
    from ..identify import plots

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "arx.json", json.dumps(result, indent=2) + "\n")
    names = {"input_unit": _unit(args.input), "output_unit": _unit(args.output),
             "input_name": args.input, "output_name": args.output}
    label = (f"ARX [{model.na} {model.nb} {model.nk}] {args.input} -> {args.output}, "
             f"{Path(args.recording).name}")
    plots.residual_figure(check, out / "residuals.png",
                          title=f"{label}: residuals on held-out data", **names)
    plots.validation_figure(check, out / "validation.png",
                            title=f"{label}: simulation on held-out data", t0=t0, **names)


def _unit(column: str) -> str:
    from ..recording import UNITS
    return UNITS.get(column, "-")


def _print_summary(model: ArxModel, check: ArxValidation, result: Mapping[str, Any],
                   args: argparse.Namespace) -> None:
    na, nb, nk = model.orders
    print(f"ARX [na nb nk] = [{na} {nb} {nk}] from {args.input} to {args.output}, "
          f"{result['n_estimation']} estimation samples, T = {model.sample_time} s")
    for name, vals, stds in (("a", model.a, model.std_a), ("b", model.b, model.std_b)):
        for i, (v, s) in enumerate(zip(vals, stds), start=1):
            print(f"  {name}{i} = {v: .6g}  +- {s:.2g} (1 std)")
    print(f"  noise variance {model.noise_variance:.4g}, DC gain {model.dc_gain:.4g}, "
          f"{'stable' if model.is_stable else 'NOT stable'}")
    print("  poles " + ", ".join(f"{p.real:.4f}{p.imag:+.4f}j" for p in model.poles))
    print(f"validation ({result['n_validation']} held-out samples): fit "
          f"{check.fit:.2f} %")

    def verdict(ok: bool | None, p: float) -> str:
        return "n/a" if ok is None else f"{'pass' if ok else 'FAIL'} (p = {p:.3g})"

    print(f"  residual whiteness   {verdict(check.whiteness_ok, check.whiteness_p_value)}, "
          f"{check.autocorrelation_outside}/{int(check.lags[-1])} lags outside the 99 % band")
    print(f"  input independence   "
          f"{verdict(check.independence_ok, check.independence_p_value)}, "
          f"{check.cross_correlation_outside}/{check.cross_lags.size} lags outside")


# ====================================================================== rls
def _add_rls(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``workbench identify rls`` to the ``identify`` sub-parsers."""
    p = subparsers.add_parser(
        "rls", help="recursive least squares with forgetting: time-varying ARX tracks",
        description="Track the parameters of a time-varying ARX model y(k) + a1 y(k-1) + ... "
                    "= b1 u(k-nk) + ... + e(k) (MATLAB arx orders na nb nk) through a "
                    "recording by recursive least squares with forgetting factor lambda "
                    "(paper 002). Writes DIR/estimates.csv (columns t,a1..a_na,b1..b_nb: the "
                    "estimate after each sample), DIR/rls.png (tracks with +-2 std bands), "
                    "DIR/summary.json and DIR/report.md (final estimates with standard "
                    "deviations, lambda, one-step prediction error).",
        epilog="Units are SI (m, Pa absolute, kg, s, V). Example: workbench identify rls "
               "run.csv --input u --output x --orders 2 2 1 --forgetting 0.99 --out rls/")
    p.add_argument("recording", metavar="RECORDING", help="recording (.csv or .mat)")
    p.add_argument("--input", default="u", metavar="COLUMN", help="input column (default u)")
    p.add_argument("--output", default="x", metavar="COLUMN", help="output column (default x)")
    p.add_argument("--orders", nargs=3, type=int, default=[2, 2, 1], metavar=("NA", "NB", "NK"),
                   help="ARX orders na nb nk, MATLAB convention (default 2 2 1)")
    p.add_argument("--forgetting", default="0.99", metavar="LAMBDA",
                   help="forgetting factor in (0, 1], or 'auto' to choose it by one-step "
                        "prediction error among " + ", ".join(f"{c:g}" for c in DEFAULT_CANDIDATES)
                        + " (default 0.99)")
    p.add_argument("--p0", default="auto", metavar="P0",
                   help="initial covariance P(0) = p0 I, or 'auto' (default): "
                        "P(0) = diag(1e4 / mean(phi_i^2)), a weak prior whatever the units")
    p.add_argument("--detrend", choices=("none", "mean"), default="none",
                   help="'mean': subtract the record mean of input and output first (ARX has "
                        "no constant term, so offsets such as a 5 V valve centre or a 0.25 m "
                        "mid-stroke position bias the estimates); default none")
    p.add_argument("--burn-in", type=int, default=None, metavar="N",
                   help="estimates left out of the prediction error (default max(10 (na+nb), N/10))")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if needed)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--no-plot", action="store_true", help="do not write rls.png")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_rls)
    return p


def _parse_forgetting(text: str) -> float | None:
    if str(text).strip().lower() == "auto":
        return None
    try:
        val = float(text)
    except ValueError:
        raise InputError(f"--forgetting must be a number in (0, 1] or 'auto', got '{text}'") from None
    return check_forgetting(val, "--forgetting")


def _cmd_rls(args: argparse.Namespace) -> int:
    from ..recording import UNITS, load_recording
    rec = load_recording(args.recording)
    for opt, col in (("--input", args.input), ("--output", args.output)):
        if col not in rec.columns:
            raise InputError(f"{opt} {col}: the recording has no column '{col}'; its columns "
                             f"are {', '.join(rec.columns)}", source=str(args.recording))
    res, choice = _rls_run(args, rec)
    n_est = len(res)
    burn = args.burn_in if args.burn_in is not None else default_burn_in(n_est, len(res.names))
    burn = min(max(int(burn), 0), n_est - 1)
    mse = res.prediction_mse(burn)

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    _write_estimates(out / "estimates.csv", res)
    y_unit = UNITS.get(args.output, "")
    u_unit = UNITS.get(args.input, "")
    summary = {
        "recording": str(args.recording), "input": args.input, "output": args.output,
        "detrend": args.detrend,
        "units": {"output": y_unit, "input": u_unit},
        **res.to_dict(),
        "prediction_mse": mse, "prediction_rmse": math.sqrt(mse), "prediction_mse_burn_in": burn,
        "forgetting_choice": None if choice is None else choice.to_dict(),
        "files": {"estimates": str(out / "estimates.csv"), "report": str(out / "report.md"),
                  "summary": str(out / "summary.json")},
    }
    if not args.no_plot:
        _rls_plot(args, res, out / "rls.png", y_unit, u_unit)
        summary["files"]["plot"] = str(out / "rls.png")
    summary = json_safe(summary)
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    atomic_write_text(out / "report.md", report_md(res, summary, choice, y_unit, u_unit))
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    _print_rls(args, res, choice, mse, burn, y_unit, out)
    return 0


def _rls_run(args: argparse.Namespace, rec):
    """(result, forgetting choice or None) of RLS on the recording's columns."""
    lam = _parse_forgetting(args.forgetting)
    p0: Any = "auto"
    if str(args.p0).strip().lower() != "auto":
        try:
            p0 = float(args.p0)
        except ValueError:
            raise InputError(f"--p0 must be a positive number or 'auto', got '{args.p0}'") from None
    y, u = rec[args.output], rec[args.input]
    if args.detrend == "mean":
        y, u = y - np.mean(y), u - np.mean(u)
    progress = (not args.quiet) and y.size >= 500_000
    common = dict(time=rec.t, sample_time=rec.sample_time, p0=p0, progress=progress)
    try:
        if lam is None:
            choice = choose_forgetting(y, u, args.orders, burn_in=args.burn_in, **common)
            return choice.result, choice
        return rls(y, u, args.orders, forgetting=lam, **common), None
    except InputError as exc:
        raise InputError(str(exc).replace("output y", f"output '{args.output}'")
                         .replace("input u", f"input '{args.input}'"),
                         source=str(args.recording)) from None


def _write_estimates(path: Path, res) -> None:
    """estimates.csv: exactly t, a1.., b1.."""
    table = np.column_stack([res.time, res.theta])
    buf = io.StringIO()
    buf.write(",".join(("t",) + res.names) + "\n")
    np.savetxt(buf, table, delimiter=",", fmt="%.12g")
    atomic_write_text(path, buf.getvalue())


def _rls_plot(args: argparse.Namespace, res, path: Path, y_unit: str, u_unit: str) -> None:
    from ..identify.plots import rls_figure
    rls_figure(res, path=path, output_unit=y_unit or None,
               input_unit=u_unit or None,
               title=f"RLS: {args.output} from {args.input}, orders {tuple(res.orders)}, "
                     f"lambda = {res.forgetting:g}")


def _print_rls(args: argparse.Namespace, res, choice, mse: float, burn: int, y_unit: str,
               out: Path) -> None:
    print(f"RLS on {args.recording}: {args.output} from {args.input}, orders "
          f"{tuple(res.orders)}, lambda = {res.forgetting:g}"
          + (" (chosen by prediction error)" if choice is not None else ""))
    for name in res.names:
        print(f"  {name} = {res.final[name]: .6g}  +- {res.final_std[name]:.2g} (1 std)")
    print(f"  one-step prediction error RMS {math.sqrt(mse):.4g} {y_unit} "
          f"(after {burn} estimates)")
    print(f"  wrote {out / 'estimates.csv'}, {out / 'report.md'}, {out / 'summary.json'}"
          + ("" if args.no_plot else f", {out / 'rls.png'}"))


# ====================================================================== valve, valve-table
def _add_valve(subparsers) -> None:
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
    v.add_argument("table", metavar="TABLE.csv", help="valve table")
    v.add_argument("--approx", choices=("I", "II", "both"), default="both",
                   help="which approximation (default both)")
    v.add_argument("--degrees", nargs=2, type=int, metavar=("N", "M"),
                   help="approximation I degrees in p and u (default 5 10, paper 003)")
    v.add_argument("--select", action="store_true",
                   help="choose approximation I degrees by 5-fold cross validation "
                        "(n 1..7, m 1..12)")
    v.add_argument("--affine-degrees", nargs=3, type=int, default=[5, 5, 2],
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
    v.set_defaults(func=_cmd_valve)

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
    g.add_argument("--n-u", type=int, default=21, help="number of default commands")
    g.add_argument("--n-p", type=int, default=15, help="number of default pressures")
    g.set_defaults(func=_cmd_valve_table)


def _cmd_valve(args: argparse.Namespace) -> int:
    table = load_valve_table(args.table)
    if args.plant_toml and not args.base:
        raise InputError("--plant-toml needs --base PLANT.toml (the plant whose valve is "
                         "replaced by the fitted law)", location="--plant-toml")
    if args.plant_toml and args.approx == "I":
        raise InputError("--plant-toml writes the input-affine law: use --approx II or both",
                         location="--plant-toml")
    base = PlantParams.from_toml(args.base) if args.base else None
    phi_deg = None if args.affine_degrees[0] < 0 else args.affine_degrees[0]
    report = analyse(table, approx=args.approx,
                     degrees=tuple(args.degrees) if args.degrees else None, select=args.select,
                     affine_degrees=(phi_deg, args.affine_degrees[1], args.affine_degrees[2]),
                     pin_ends=args.pin_ends, tank_volume=args.tank_volume, tank=not args.no_tank,
                     reference=_valve_reference(args, table))
    result = report.to_dict()
    if args.plant_toml:
        report = _write_plant_toml(args, base, table, report, result)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / "valve_fit.json", json.dumps(result, indent=2) + "\n")
        result["files"] = ["valve_fit.json"] + ([] if args.no_plot else write_figures(report, out))
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
    """--plant-toml: --base with approximation II; a supply mismatch becomes a note."""
    new = base.replace(**report.approx_2.plant_values())
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
                else f"phi {len(fit.phi) - 1 if any(fit.phi) else '-'}, psi {len(fit.psi_in) - 1}, "
                     f"Gamma {len(fit.gamma)} odd terms")
        print(f"  {lab:<17} {what}: {qd.coefficients} coefficients ({qd.free} free), "
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


# ====================================================================== greybox
def _add_greybox(subparsers) -> None:
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
    p.add_argument("--shooting-interval", type=float, default=0.05, metavar="S",
                   help="shooting interval, s (default 0.05)")
    p.add_argument("--x0", choices=("estimate", "from_recording"), default="estimate",
                   help="initial state: estimated (default) or measured values fixed")
    p.add_argument("--replay", choices=("auto", "open", "closed"), default="auto",
                   help="before/after check: closed loop on r when the recording has r and "
                        "the plant a [controller] (auto), or always open loop on u")
    p.add_argument("--substeps", type=int, default=None, metavar="N",
                   help="integration steps per sample (default: steps <= 1 ms, 0.125 ms "
                        "with dry friction)")
    p.add_argument("--max-iter", type=int, default=50, metavar="N",
                   help="IPOPT iterations (default 50)")
    p.add_argument("--out", metavar="DIR", help="output folder (created if needed)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--verbose", action="store_true", help="print IPOPT's iteration log")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
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
    from ..identify.grey_box import estimate
    from ..plant import Plant
    from ..recording import load_recording
    plant = Plant.from_toml(args.plant)
    recs = [load_recording(p) for p in args.recordings]
    res = estimate(plant, recs, args.params, bounds=_parse_bounds(args.bounds),
                   signals=tuple(args.signals), shooting_interval=args.shooting_interval,
                   x0=args.x0, replay=args.replay, substeps=args.substeps,
                   max_iter=args.max_iter,
                   verbose=args.verbose, progress=False if args.quiet or args.json else None)
    out = res.to_dict()
    out["plant"] = str(args.plant)
    if args.out:
        d = Path(args.out)
        d.mkdir(parents=True, exist_ok=True)
        atomic_write_text(d / "estimates.json", json.dumps(out, indent=2) + "\n")
        res.plant_.params.to_toml(d / "plant_estimated.toml")
        from ..identify.plots import greybox_figure
        greybox_figure(recs, res, d / "fit.png",
                       title=f"grey-box fit: {plant.name}, {', '.join(res.names)}")
        out["files"] = [str(d / "estimates.json"), str(d / "plant_estimated.toml"),
                        str(d / "fit.png")]
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(res.table())
        if args.out:
            print(f"wrote {args.out}/estimates.json, plant_estimated.toml, fit.png")
    return 0
