"""``workbench identify arx``: ARX models, their residual tests and figures."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any, Mapping

from typing import TYPE_CHECKING

from ...errors import InputError
from ..common import nonnegative_int, positive_int, prepare_output

if TYPE_CHECKING:                   # imported in the handler: `--help` stays fast
    from ...identify.arx import ArxModel, ArxValidation

__all__ = ["add_arx"]

#: Order selection criteria (:data:`workbench.identify.arx.CRITERIA`; a test keeps them equal).
CRITERIA = ("aic", "bic", "fpe", "loss", "fit")
#: Files ``--out`` receives.
ARX_FILES = ("arx.json", "residuals.png", "validation.png")


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
    if lo < 0:
        raise argparse.ArgumentTypeError(f"orders are >= 0, got {text!r}")
    return range(lo, hi + 1)


def add_arx(subparsers: Any) -> argparse.ArgumentParser:
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
    p.add_argument("--orders", nargs=3, type=nonnegative_int, metavar=("NA", "NB", "NK"),
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
    p.add_argument("--lags", type=positive_int, default=None, metavar="M",
                   help="correlation lags of the residual tests, samples (default 25 or a "
                        "quarter of the validation residuals if fewer; at most that quarter)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--out", metavar="DIR",
                   help="also write DIR/arx.json, DIR/residuals.png and DIR/validation.png")
    from ..recording_args import add_recording_options
    add_recording_options(p)
    p.set_defaults(func=_cmd_arx)
    return p


def _cmd_arx(args: argparse.Namespace) -> int:
    from ...identify.arx import validate
    from ...identify.arx.checks import finite_or_none
    if args.out is not None:
        prepare_output(args.out, ARX_FILES, [args.recording])
    rec, y, u, n_est = _arx_data(args)
    ye, ue, yv, uv = y[:n_est], u[:n_est], y[n_est:], u[n_est:]
    model, check, selection = _arx_fit(args, ye, ue, yv, uv, rec.sample_time, rec.source)
    result = _arx_result(args, model, check, rec, n_est,
                         finite_or_none(validate(model, ye, ue, lags=args.lags).fit))
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
    import numpy as np
    from ..recording_args import load_from_args

    rec = load_from_args(args, args.recording, required=("t",))  # input, output: checked below
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
    from ...identify.arx import fit_arx, select_order, validate
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
        args.lags = _check_lags(args.lags, len(yv) - model.max_lag)
        check = validate(model, yv, uv, lags=args.lags)
    except InputError as exc:
        if exc.source:
            raise
        raise InputError(str(exc), source=src,
                         location=f"columns '{args.input}' -> '{args.output}'") from None
    return model, check, selection


def _check_lags(lags: int | None, residuals: int) -> int:
    """--lags within what the residual tests can use: a quarter of the residuals (a
    correlation at lag k averages N - k products; beyond N/4 it is noise, Box-Jenkins).
    Not given: 25, or that quarter when it is smaller."""
    limit = max(1, residuals // 4)
    if lags is None:
        return min(25, limit)
    if lags > limit:
        raise InputError(f"--lags {lags} is more than the residual tests can use: the "
                         f"validation part has {residuals} residuals, so at most "
                         f"{limit} lags (a quarter of them)", location="--lags")
    return lags


def _arx_result(args: argparse.Namespace, model: ArxModel, check: ArxValidation, rec,
                n_est: int, fit_estimation: float | None) -> dict[str, Any]:
    """The JSON result of ``identify arx`` (keys as printed by ``--json``)."""
    from ...identify.arx.checks import complex_pairs as _pairs, finite_or_none as _num
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
    """DIR/arx.json, DIR/residuals.png and DIR/validation.png, all or none."""
    from ...output import result_set, write_json

    with result_set(args.out, inputs=[args.recording]) as out:
        write_json(out / "arx.json", result)
        _arx_figures(args, model, check, out, t0)


def _arx_figures(args: argparse.Namespace, model: ArxModel, check: ArxValidation,
                 out: Path, t0: float) -> None:
    from ...identify import plots
    names = {"input_unit": _unit(args.input), "output_unit": _unit(args.output),
             "input_name": args.input, "output_name": args.output}
    label = (f"ARX [{model.na} {model.nb} {model.nk}] {args.input} -> {args.output}, "
             f"{Path(args.recording).name}")
    plots.residual_figure(check, out / "residuals.png",
                          title=f"{label}: residuals on held-out data", **names)
    plots.validation_figure(check, out / "validation.png",
                            title=f"{label}: simulation on held-out data", t0=t0, **names)


def _unit(column: str) -> str:
    from ...recording import UNITS
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
