"""Figures of a diagnosis (matplotlib, no screen needed). Plotting only: nothing is computed."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["replay_figure", "signature_figure", "regime_figure", "ranking_figure"]

_SCALE = {"x": (1e3, "position x [mm]"), "p_a": (1e-5, "p_a [bar abs]"),
          "p_b": (1e-5, "p_b [bar abs]"), "u": (1.0, "command u [V]")}


def _shade(ax, spans, color, alpha, label=None):
    for i, (a, b) in enumerate(spans):
        ax.axvspan(a, b, color=color, alpha=alpha, lw=0, label=label if i == 0 else None)


def replay_figure(t, measured, nominal, augmented, located, finding_spans, reference=None,
                  title=""):
    """Recording vs nominal vs augmented replay per signal, mismatch intervals shaded.

    ``measured``, ``nominal``, ``augmented``: dicts signal -> array on ``t``
    (``augmented`` may be empty). ``located``: intervals (s) of the nominal mismatch
    (grey); ``finding_spans``: intervals where the first finding removes it (orange).
    """
    names = [n for n in ("x", "p_a", "p_b", "u") if n in measured]
    fig, axes = plt.subplots(len(names), 1, sharex=True, figsize=(9.0, 2.0 * len(names) + 0.8),
                             constrained_layout=True)
    axes = np.atleast_1d(axes)
    fig.suptitle(title, fontsize=11)
    for ax, n in zip(axes, names):
        k, lab = _SCALE[n]
        _shade(ax, located, "0.6", 0.25, "mismatch located" if n == names[0] else None)
        _shade(ax, finding_spans, "tab:orange", 0.18,
               "explained by the finding" if n == names[0] else None)
        ax.plot(t, measured[n] * k, color="0.15", lw=1.1, label="recording")
        if n in nominal:
            ax.plot(t, nominal[n] * k, color="tab:blue", lw=0.9, label="nominal model")
        if augmented and n in augmented:
            ax.plot(t, augmented[n] * k, color="tab:red", lw=0.9, ls="--",
                    label="augmented model")
        if n == "x" and reference is not None:
            ax.plot(t, reference * k, color="0.5", lw=0.7, ls=":", label="reference r")
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=7, ncol=3)
    axes[-1].set_xlabel("time t [s]")
    return fig


def signature_figure(t, witness, witness_after, err_nominal, err_after, located, title=""):
    """Residual signatures: flow witnesses (g/s), force witness (N), prediction error.

    Witnesses are shown as 20 ms moving averages.

    ``witness``/``witness_after``: dicts with ``force`` (N) and ``q_a``, ``q_b`` (kg/s)
    for the nominal and augmented model; ``err_*``: short-horizon prediction error per
    sample (noise units, NaN where not predicted).
    """
    panels = [p for p in ("q_a", "q_b", "force") if p in witness]
    n = len(panels) + 1
    fig, axes = plt.subplots(n, 1, sharex=True, figsize=(9.0, 1.9 * n + 0.8),
                             constrained_layout=True)
    axes = np.atleast_1d(axes)
    fig.suptitle(title, fontsize=11)
    labels = {"q_a": ("flow witness a [g/s]", 1e3), "q_b": ("flow witness b [g/s]", 1e3),
              "force": ("force witness [N]", 1.0)}
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    w = max(int(round(0.02 / dt)), 1)          # 20 ms moving average for display

    def sm(y):          # NaN (not formed there: several recordings) stays a gap
        return np.where(np.isfinite(y), np.convolve(np.nan_to_num(y), np.ones(w) / w,
                                                    mode="same"), np.nan)

    for ax, p in zip(axes, panels):
        lab, k = labels[p]
        _shade(ax, located, "0.6", 0.25)
        if witness_after and p in witness_after:
            ax.plot(t, sm(witness_after[p]) * k, color="tab:red", lw=0.7, label="augmented")
        ax.plot(t, sm(witness[p]) * k, color="tab:blue", lw=0.7, label="nominal", alpha=0.85)
        lim = np.nanpercentile(np.abs(sm(witness[p]) * k), 99.5)
        if np.isfinite(lim) and lim > 0:
            ax.set_ylim(-1.2 * lim, 1.2 * lim)
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
    ax = axes[-1]
    _shade(ax, located, "0.6", 0.25)
    ax.semilogy(t, np.where(np.isfinite(err_nominal), err_nominal, np.nan) + 1e-3,
                color="tab:blue", lw=0.6, label="nominal")
    if err_after is not None:
        ax.semilogy(t, np.where(np.isfinite(err_after), err_after, np.nan) + 1e-3,
                    color="tab:red", lw=0.6, label="augmented")
    ax.set_ylabel("prediction error\n[(residual/noise)^2]")
    ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=7)
    axes[-1].set_xlabel("time t [s]")
    return fig


def regime_figure(shares, title=""):
    """Share of the nominal mismatch vs share of time per operating regime."""
    names = list(shares)
    e = [100 * shares[k]["error_share"] for k in names]
    tt = [100 * shares[k]["time_share"] for k in names]
    fig, ax = plt.subplots(figsize=(8.0, 3.2), constrained_layout=True)
    y = np.arange(len(names))
    ax.barh(y - 0.2, tt, height=0.38, color="0.7", label="share of time")
    ax.barh(y + 0.2, e, height=0.38, color="tab:blue", label="share of the mismatch")
    ax.set_yticks(y, names)
    ax.invert_yaxis()
    ax.set_xlabel("%")
    ax.legend(fontsize=8)
    ax.grid(True, axis="x", alpha=0.3)
    ax.set_title(title, fontsize=10)
    return fig


def ranking_figure(names, gains, significant, title=""):
    """Share of the mismatch each candidate removes, significant ones highlighted."""
    fig, ax = plt.subplots(figsize=(8.0, 0.32 * len(names) + 1.2), constrained_layout=True)
    y = np.arange(len(names))
    colors = ["tab:green" if s else "0.6" for s in significant]
    ax.barh(y, [100 * max(g, 0.0) for g in gains], color=colors)
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("share of the short-horizon prediction error removed [%]")
    ax.grid(True, axis="x", alpha=0.3)
    ax.set_title(title, fontsize=10)
    return fig
