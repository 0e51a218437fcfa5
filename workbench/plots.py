"""Figures (matplotlib, no screen needed). Plotting only: nothing is computed here."""

from __future__ import annotations

import os
from typing import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["replay_figure", "trajectory_figure", "save_figure"]


def save_figure(fig, path: str | os.PathLike, dpi: int = 130) -> None:
    """Save atomically (temporary file renamed into place) and close the figure."""
    path = os.fspath(path)
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    root, ext = os.path.splitext(path)
    tmp = f"{root}.tmp{ext}"
    try:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        if os.path.exists(tmp):
            os.unlink(tmp)


def _panels(n: int, title: str):
    fig, axes = plt.subplots(n, 1, sharex=True, figsize=(8.5, 2.2 * n + 0.8),
                             constrained_layout=True)
    axes = np.atleast_1d(axes)
    fig.suptitle(title, fontsize=11)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time t [s]")
    return fig, axes


def trajectory_figure(runs: Sequence, labels: Sequence[str], path: str | os.PathLike,
                      title: str = "") -> None:
    """Position (with reference), command and chamber pressures of one or more runs."""
    fig, (ax_x, ax_u, ax_p) = _panels(3, title)
    for run, lab in zip(runs, labels):
        ax_x.plot(run.time, run["x"] * 1e3, label=f"x {lab}")
        if run.reference is not None:
            ax_x.plot(run.time, run.reference * 1e3, "k--", lw=1, label=f"r {lab}")
        ax_u.step(run.time, run["u"], where="post", label=lab)
        ax_p.plot(run.time, run["p_a"] / 1e5, label=f"p_a {lab}")
        ax_p.plot(run.time, run["p_b"] / 1e5, label=f"p_b {lab}")
    ax_x.set_ylabel("position [mm]")
    ax_u.set_ylabel("command u [V]")
    ax_p.set_ylabel("pressure [bar abs]")
    for ax in (ax_x, ax_u, ax_p):
        ax.legend(loc="best", fontsize=8)
    save_figure(fig, path)


def replay_figure(rec, sim, fits: Mapping[str, float], path: str | os.PathLike,
                  title: str = "") -> None:
    """Recording vs simulation for x, u and the pressures that were recorded."""
    names = ["x", "u"] + [n for n in ("p_a", "p_b") if n in rec]
    fig, axes = _panels(len(names), title)
    scale = {"x": (1e3, "position x [mm]"), "u": (1.0, "command u [V]"),
             "p_a": (1e-5, "p_a [bar abs]"), "p_b": (1e-5, "p_b [bar abs]")}
    for ax, n in zip(axes, names):
        k, lab = scale[n]
        ax.plot(rec.t, rec[n] * k, color="0.3", lw=1.2, label="recording")
        ax.plot(sim.t, sim[n] * k, color="tab:red", lw=1.0, label="simulation")
        if n == "x" and "r" in rec:
            ax.plot(rec.t, rec["r"] * k, "k--", lw=0.8, label="reference r")
        ax.set_ylabel(lab)
        if n in fits:
            ax.set_title(f"fit {fits[n]:.1f} %", fontsize=9, loc="right")
        ax.legend(loc="best", fontsize=8)
    save_figure(fig, path)
