"""Markdown report of an RLS run (``report.md`` of ``workbench identify rls``)."""

from __future__ import annotations

import math

import numpy as np

from .estimator import RlsResult
from .forgetting import ForgettingChoice

__all__ = ["report_md"]


def report_md(res: RlsResult, summary: dict, choice: ForgettingChoice | None,
               y_unit: str, u_unit: str) -> str:
    na, nb, nk = res.orders
    b_unit = f"{y_unit or '-'}/{u_unit or '-'}"
    lines = [
        "# Recursive least squares",
        "",
        f"- recording: `{summary['recording']}`; output `{summary['output']}` "
        f"({y_unit or '-'}), input `{summary['input']}` ({u_unit or '-'})",
        f"- model: ARX orders na = {na}, nb = {nb}, nk = {nk} (MATLAB `arx` convention)"
        + ("; input and output minus their record means" if summary.get("detrend") == "mean"
           else ""),
        f"- forgetting factor lambda = {res.forgetting:g}"
        + (" (chosen by one-step prediction error)" if choice is not None else ""),
        f"- {len(res)} estimates from t = {res.time[0]:.6g} s to {res.time[-1]:.6g} s; "
        f"P(0) = diag({', '.join(f'{v:.3g}' for v in res.p0)}), trace bound {res.p_max:.3g} "
        f"(active on {100 * res.bound_active_fraction:.2f} % of samples)",
        f"- one-step (a priori) prediction error: RMS {summary['prediction_rmse']:.4g} "
        f"{y_unit} after {summary['prediction_mse_burn_in']} estimates; noise std estimate "
        f"{math.sqrt(res.noise_variance[-1]) if np.isfinite(res.noise_variance[-1]) else float('nan'):.4g} "
        f"{y_unit}",
        "",
        "## Final estimates",
        "",
        "| parameter | estimate | std | unit |",
        "|---|---:|---:|---|",
    ]
    for i, name in enumerate(res.names):
        unit = "-" if i < na else b_unit
        lines.append(f"| {name} | {res.theta[-1, i]:.6g} | {res.std[-1, i]:.3g} | {unit} |")
    if choice is not None:
        lines += ["", "## Forgetting factor by prediction error", "",
                  f"Mean squared a priori error after {choice.burn_in} estimates:", "",
                  "| lambda | MSE | RMS |", "|---:|---:|---:|"]
        for c, m in zip(choice.candidates, choice.mse):
            mark = " (chosen)" if c == choice.forgetting else ""
            lines.append(f"| {c:g}{mark} | {m:.4g} | {math.sqrt(m):.4g} |")
    lines += ["", "Standard deviations are the noise-driven spread of the estimate "
              "(sigma^2 P M P with sigma^2 estimated on line); they do not include the lag "
              "behind parameters that change.", ""]
    return "\n".join(lines)
