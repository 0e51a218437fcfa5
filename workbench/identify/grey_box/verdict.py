"""The verdict on a grey-box fit: fits, residual whiteness, and the messages in words."""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from ...errors import InputError
from ...recording import fit as nrmse_fit
from ...signals import autocorrelation, fraction_outside
from ...replay import CONTROLLER_AGREEMENT


_SIGNAL_UNITS = {"x": "m", "v": "m/s", "p_a": "Pa", "p_b": "Pa", "p_s": "Pa"}


def _whiteness(e: np.ndarray, lags: int = 25) -> float:
    """Fraction of autocorrelation lags 1..lags outside the 99 % band +-2.58/sqrt(N)."""
    n = len(e)
    r = autocorrelation(e, lags) if n >= 4 * lags else np.full(lags + 1, np.nan)
    if not np.isfinite(r[0]):
        return float("nan")
    return fraction_outside(r[1:], n, band=2.58 / math.sqrt(n))


def _fits(rec_y: Mapping[str, np.ndarray], run) -> dict[str, float]:
    out = {}
    for s, y in rec_y.items():
        try:
            out[s] = nrmse_fit(y, run[s])
        except InputError:
            out[s] = float("nan")
    return out


def _verdict(data, fit_after, fit_ms, modes, res_rms, white, int_err, threshold, success,
             status, params, identifiable, at_bound, corr,
             agreement=None) -> tuple[bool, list[str]]:
    """Poor fit: the estimated model cannot follow a recording.

    Either a signal's fit is below ``threshold`` both in the fresh CVODES replay and
    along the model's own trajectory in the fit, or its residuals are strongly
    correlated (more than half of the autocorrelation lags outside the 99 % band) and
    more than 3 times the measurement noise. A replay that drifts while the model's own
    trajectory follows the data is reported, not counted as a poor fit.
    """
    poor = False
    msgs: list[str] = []
    worst, drift = [], []
    agreement = list(agreement) if agreement is not None else [None] * len(data)
    for d, fa, fm, mode, agree in zip(data, fit_after, fit_ms, modes, agreement):
        where = "" if len(data) == 1 else f" ({d.source})"
        for s, fv in fa.items():
            bad_replay = not math.isfinite(fv) or fv < threshold
            bad_model = not math.isfinite(fm.get(s, float("nan"))) or fm[s] < threshold
            if bad_replay and bad_model:
                worst.append(f"{s} {fv:.1f} %{where}")
            elif bad_replay:
                drift.append((s, fv, fm[s], mode, where, agree))
    if worst:
        poor = True
        msgs.append(f"Fit after estimation below {threshold:g} %: {', '.join(worst)}; the model "
                    "structure does not explain the recording (a missing effect?).")
    systematic = []
    for d, rr, ww in zip(data, res_rms, white):
        for s in rr:
            ratio = rr[s] / d.noise[s]
            if ratio > 3.0 and math.isfinite(ww.get(s, float("nan"))) and ww[s] > 0.5:
                systematic.append(f"{s} ({ratio:.1f} x noise)")
    if systematic:
        poor = True
        msgs.append("Residuals are correlated and well above the measurement noise for "
                    f"{', '.join(systematic)}: a systematic model error remains.")
    for s, fv, fm, mode, where, agree in drift:
        hint = ("" if mode == "closed_loop" else
                "; open-loop replay of a position drive integrates every small difference "
                "(give the recording's r and the plant's [controller] for a closed-loop check)")
        if mode == "closed_loop" and agree is not None and agree < CONTROLLER_AGREEMENT:
            hint = (f"; but the plant file's [controller] does not reproduce the recorded "
                    f"command (fit of u {agree:.0f} %): it is probably not the loop that ran "
                    "(a delay, other gains, a filter), so the closed-loop replay cannot be "
                    "judged -- give the controller that ran, or replay open loop "
                    "(--replay open)")
        msgs.append(f"The {mode.replace('_', '-')} replay of {s}{where} drifts (fit {fv:.1f} %) "
                    f"although the model follows it to {fm:.1f} % from the estimated initial "
                    f"state{hint}.")
    if not success:
        msgs.append(f"IPOPT did not converge ({status}); the estimates are not reliable.")
    for p, ok, ab in zip(params, identifiable, at_bound):
        if ab:
            msgs.append(f"{p.name} is at a bound ({p.lo:g} .. {p.hi:g}).")
        elif not ok:
            msgs.append(f"{p.name} is not identifiable from these data (std above half its size).")
    n = len(params)
    for i in range(n):
        for j in range(i + 1, n):
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) > 0.99:
                msgs.append(f"{params[i].name} and {params[j].name} are strongly correlated "
                            f"({corr[i, j]:+.3f}).")
    for d, ie in zip(data, int_err):
        for s, e in ie.items():
            if math.isfinite(e) and e > 0.5 * d.noise[s]:
                msgs.append(f"The fixed-step integration differs from CVODES by {e:.3g} "
                            f"{_SIGNAL_UNITS.get(s, '')} RMS on {s}, comparable with the noise: "
                            "use more substeps.")
                break
    if not poor and not msgs:
        msgs.append("The estimated model explains the recordings to the noise level.")
    elif not poor:
        msgs.insert(0, "Good fit.")
    return poor, msgs
