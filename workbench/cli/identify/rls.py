"""``workbench identify rls``: recursive least squares with a forgetting factor."""

from __future__ import annotations

import argparse
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError, WorkbenchError
from ..common import nonnegative_int, prepare_output

__all__ = ["add_rls"]

#: Candidates of ``--forgetting auto`` (:data:`workbench.identify.rls.DEFAULT_CANDIDATES`;
#: a test keeps them equal).
DEFAULT_CANDIDATES = (0.9, 0.95, 0.98, 0.99, 0.995, 0.999, 1.0)
#: Files ``--out`` receives.
RLS_FILES = ("estimates.csv", "summary.json", "report.md", "rls.png")


def add_rls(subparsers: Any) -> argparse.ArgumentParser:
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
    p.add_argument("--orders", nargs=3, type=nonnegative_int, default=[2, 2, 1],
                   metavar=("NA", "NB", "NK"),
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
    p.add_argument("--burn-in", type=nonnegative_int, default=None, metavar="N",
                   help="estimates left out of the prediction error, 0 .. N-1 for N "
                        "estimates (default max(10 (na+nb), N/10))")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if needed)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--no-plot", action="store_true", help="do not write rls.png")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    from ..recording_args import add_recording_options
    add_recording_options(p)
    p.set_defaults(func=_cmd_rls)
    return p


def _parse_forgetting(text: str, npar: int) -> float | None:
    """--forgetting: 'auto' (None) or lambda in (0, 1] that remembers at least as many
    samples as there are parameters."""
    from ...identify.rls.estimator import check_forgetting
    if str(text).strip().lower() == "auto":
        return None
    try:
        val = float(text)
    except ValueError:
        raise InputError(f"--forgetting must be a number in (0, 1] or 'auto', got '{text}'") from None
    lam = check_forgetting(val, "--forgetting")
    # exponential forgetting weighs sample k-j by lambda^j: an effective memory of
    # 1 / (1 - lambda) samples. With fewer remembered samples than parameters the
    # information matrix is (numerically) singular and the estimates are not determined.
    if lam < 1.0 and 1.0 / (1.0 - lam) < npar:
        raise InputError(f"--forgetting {text} remembers about {1.0 / (1.0 - lam):.3g} "
                         f"samples (1 / (1 - lambda)), fewer than the {npar} parameters: "
                         f"the estimates are not determined; use at least "
                         f"{1.0 - 1.0 / npar:g} (0.99 remembers about 100 samples)")
    return lam


def _cmd_rls(args: argparse.Namespace) -> int:
    from ...recording import UNITS
    from ...identify.rls.estimator import default_burn_in
    from ..recording_args import load_from_args
    out = prepare_output(args.out, RLS_FILES, [args.recording])
    npar = args.orders[0] + args.orders[1]
    lam = _parse_forgetting(args.forgetting, max(npar, 1))
    rec = load_from_args(args, args.recording, required=("t",))  # input, output: checked below
    for opt, col in (("--input", args.input), ("--output", args.output)):
        if col not in rec.columns:
            raise InputError(f"{opt} {col}: the recording has no column '{col}'; its columns "
                             f"are {', '.join(rec.columns)}", source=str(args.recording))
    if args.burn_in is not None and args.burn_in >= len(rec):
        raise InputError(f"--burn-in {args.burn_in} leaves no estimate for the prediction "
                         f"error: the recording has {len(rec)} samples (use 0 .. "
                         f"{len(rec) - 2} at most)", location="--burn-in")
    res, choice = _rls_run(args, rec, lam)
    _check_finite(res, args)
    n_est = len(res)
    if args.burn_in is not None and args.burn_in >= n_est:
        raise InputError(f"--burn-in {args.burn_in} leaves no estimate for the prediction "
                         f"error: orders {tuple(args.orders)} give {n_est} estimates from "
                         f"{len(rec)} samples (use 0 .. {n_est - 1})", location="--burn-in")
    burn = args.burn_in if args.burn_in is not None else default_burn_in(n_est, len(res.names))
    mse = res.prediction_mse(burn)
    y_unit, u_unit = UNITS.get(args.output, ""), UNITS.get(args.input, "")
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
        summary["files"]["plot"] = str(out / "rls.png")
    _write_rls(args, out, res, summary, choice, y_unit, u_unit)
    if args.json:
        from ...output import strict_json
        print(json.dumps(strict_json(summary), indent=2))
        return 0
    _print_rls(args, res, choice, mse, burn, y_unit, out)
    return 0


def _check_finite(res, args: argparse.Namespace) -> None:
    """Non-finite estimates are an error with their cause, never a result."""
    bad = ~np.all(np.isfinite(res.theta), axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise WorkbenchError(
            f"the RLS estimates became non-finite at sample {k} (t = {res.time[k]:g} s) of "
            f"{len(res)}: the covariance lost its precision (forgetting factor "
            f"{res.forgetting:g}, p0 {args.p0}); use a forgetting factor closer to 1 or "
            f"--detrend mean for data with large offsets. Nothing was written.")


def _write_rls(args: argparse.Namespace, out: Path, res, summary: dict, choice,
               y_unit: str, u_unit: str) -> None:
    """estimates.csv, summary.json, report.md (and rls.png), all or none."""
    from ...identify.rls.report import report_md
    from ...output import result_set, write_json
    from ...params import atomic_write_text
    with result_set(out, inputs=[args.recording]) as stage:
        _write_estimates(stage / "estimates.csv", res)
        if not args.no_plot:
            _rls_plot(args, res, stage / "rls.png", y_unit, u_unit)
        write_json(stage / "summary.json", summary)
        atomic_write_text(stage / "report.md",
                          report_md(res, summary, choice, y_unit, u_unit))


def _rls_run(args: argparse.Namespace, rec, lam: float | None):
    """(result, forgetting choice or None) of RLS on the recording's columns."""
    from ...identify.rls import choose_forgetting, rls
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
    from ...params import atomic_write_text
    atomic_write_text(path, buf.getvalue())


def _rls_plot(args: argparse.Namespace, res, path: Path, y_unit: str, u_unit: str) -> None:
    from ...identify.plots import rls_figure
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
