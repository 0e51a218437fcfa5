"""Figures (matplotlib, no screen needed). Plotting only: nothing is computed here."""

from __future__ import annotations

import os
from typing import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["replay_figure", "trajectory_figure", "save_figure", "validation_figure",
           "compare_figure", "stability_map_figure", "pole_step_figure", "robustness_figure",
           "pressure_plan_figure"]


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
        if fits.get(n) is not None:
            ax.set_title(f"fit {fits[n]:.1f} %", fontsize=9, loc="right")
        ax.legend(loc="best", fontsize=8)
    save_figure(fig, path)


# ---------------------------------------------------------------------- validation
def _validation_title(v) -> str:
    verdict = "PASS" if v.passed else "FAIL: " + ", ".join(c.name for c in v.failed)
    return f"{v.label} -- {verdict}" if v.label else verdict


def _validation_axes(title: str):
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(9.0, 8.0), constrained_layout=True)
    fig.suptitle(title, fontsize=11)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    ax_x, ax_u, ax_p = axes
    ax_x.set_ylabel("position [mm]")
    ax_u.set_ylabel("command u [V]")
    ax_p.set_ylabel("chamber pressure [bar abs]")
    ax_p.set_xlabel("time t [s]")
    return fig, axes


def _limit_lines(v, ax_u, ax_p, with_labels: bool = True) -> None:
    u_min, u_max = v.command_range
    p_atm, p_sup = v.pressure_range
    ax_u.axhline(u_min, color="0.4", ls="--", lw=0.9,
                 label=f"saturation {u_min:g} / {u_max:g} V" if with_labels else None)
    ax_u.axhline(u_max, color="0.4", ls="--", lw=0.9)
    ax_p.axhline(p_sup / 1e5, color="0.2", ls="-.", lw=0.9,
                 label=f"supply {p_sup / 1e5:.2f} bar" if with_labels else None)
    ax_p.axhline(p_atm / 1e5, color="0.5", ls=":", lw=1.2,
                 label=f"atmosphere {p_atm / 1e5:.2f} bar" if with_labels else None)


def _stop_marker(v, axes) -> None:
    if v.error is None:
        return
    t_stop = v.metrics.simulated_time
    for ax in axes:
        ax.axvline(t_stop, color="tab:red", lw=1.2, alpha=0.8)
    axes[0].annotate("simulation stopped", (t_stop, 1.0), xycoords=("data", "axes fraction"),
                     xytext=(3, -12), textcoords="offset points", color="tab:red", fontsize=8)


def validation_figure(validation, band: bool = True, title: str | None = None):
    """Figure of one validation (:class:`workbench.validate.Validation`).

    Three panels sharing time (s): reference and position (mm) with the settling
    band of each step shaded (``band``); command u (V) with the valve's saturation
    limits dashed; chamber pressures p_a, p_b (bar abs) with supply and atmosphere.

    Returns
    -------
    matplotlib.figure.Figure
        Save it with :func:`save_figure`.
    """
    v = validation
    run = v.trajectory
    fig, (ax_x, ax_u, ax_p) = _validation_axes(_validation_title(v) if title is None else title)
    t_ref = np.linspace(0.0, v.reference.duration, 2000)
    t_ref = np.union1d(t_ref, v.reference.times)
    ax_x.plot(t_ref, v.reference(t_ref) * 1e3, "k--", lw=1.0, label="reference r")
    ax_x.plot(run.time, run["x"] * 1e3, color="tab:blue", lw=1.3, label="position x")
    if band:
        first = True
        for m in v.segments:
            if m.segment.kind != "step" or not np.isfinite(m.band):
                continue
            s = m.segment
            ax_x.fill_between([s.start, s.end], (s.r_end - m.band) * 1e3, (s.r_end + m.band) * 1e3,
                              color="tab:green", alpha=0.25, lw=0,
                              label="settling band" if first else None)
            first = False
    ax_u.step(run.time, run["u"], where="post", color="tab:purple", lw=1.0, label="command u")
    _limit_lines(v, ax_u, ax_p)
    ax_p.plot(run.time, run["p_a"] / 1e5, color="tab:orange", lw=1.1, label="p_a")
    ax_p.plot(run.time, run["p_b"] / 1e5, color="tab:green", lw=1.1, label="p_b")
    _stop_marker(v, (ax_x, ax_u, ax_p))
    ax_x.set_xlim(0.0, v.reference.duration)
    ax_x.legend(loc="best", fontsize=8, ncol=2, framealpha=0.85)
    for ax in (ax_u, ax_p):
        ax.legend(loc="upper right", fontsize=8, ncol=2, framealpha=0.85)
    return fig


def compare_figure(validations: Sequence, labels: Sequence[str], title: str = ""):
    """Several validations (e.g. P vs PD) on the same three panels as :func:`validation_figure`.

    The reference and the limits are drawn from the first validation; each run gets
    one colour (p_a solid, p_b dashed).

    Returns
    -------
    matplotlib.figure.Figure
    """
    if len(validations) != len(labels) or not validations:
        raise ValueError(f"give one label per validation: {len(validations)} validations, "
                         f"{len(labels)} labels")
    fig, (ax_x, ax_u, ax_p) = _validation_axes(title)
    v0 = validations[0]
    t_ref = np.union1d(np.linspace(0.0, v0.reference.duration, 2000), v0.reference.times)
    ax_x.plot(t_ref, v0.reference(t_ref) * 1e3, "k--", lw=1.0, label="reference r")
    _limit_lines(v0, ax_u, ax_p)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (v, lab) in enumerate(zip(validations, labels)):
        c = colors[i % len(colors)]
        run = v.trajectory
        verdict = "pass" if v.passed else "FAIL"
        ax_x.plot(run.time, run["x"] * 1e3, color=c, lw=1.2, label=f"x {lab} ({verdict})")
        ax_u.step(run.time, run["u"], where="post", color=c, lw=0.9, label=f"u {lab}")
        ax_p.plot(run.time, run["p_a"] / 1e5, color=c, lw=1.0, label=f"p_a {lab}")
        ax_p.plot(run.time, run["p_b"] / 1e5, color=c, lw=1.0, ls="--", label=f"p_b {lab}")
        if v.error is not None:
            for ax in (ax_x, ax_u, ax_p):
                ax.axvline(v.metrics.simulated_time, color=c, lw=1.0, alpha=0.7)
    ax_x.set_xlim(0.0, max(v.reference.duration for v in validations))
    ax_x.legend(loc="best", fontsize=8, ncol=2, framealpha=0.85)
    for ax in (ax_u, ax_p):
        ax.legend(loc="upper right", fontsize=8, ncol=2, framealpha=0.85)
    return fig


_AXIS_LABELS = {"load.mass": "moving mass M", "supply.pressure": "supply pressure p_s",
                "k0": "loop gain K0", "kp": "controller gain kp", "kd": "derivative gain kd",
                "ki": "integral gain ki", "lines.length": "line length",
                "load.viscous_friction": "viscous friction k_f"}


def _axis_scale(axis) -> tuple[float, str]:
    """Display factor and label for a map axis (bar for pressures, mm for positions)."""
    name = _AXIS_LABELS.get(axis.name, axis.name)
    if axis.unit == "Pa":
        return 1e-5, f"{name} [bar abs]"
    if axis.name == "position":
        return 1e3, "piston position x [mm]"
    if axis.name == "sample_time":
        return 1e3, "sample time T [ms]"
    return 1.0, f"{name} [{axis.unit}]" if axis.unit else name


def stability_map_figure(smap, title: str | None = None):
    """Colour map of |z|max with the exact (|z| = 1), PCT and continuous boundaries."""
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.lines import Line2D
    fx, lx = _axis_scale(smap.x)
    fy, ly = _axis_scale(smap.y)
    fig, ax = plt.subplots(figsize=(7.5, 5.2), constrained_layout=True)
    rho = np.ma.masked_invalid(smap.rho)
    lo = float(np.nanmin(smap.rho)) if np.any(np.isfinite(smap.rho)) else 0.5
    hi = float(np.nanmax(smap.rho)) if np.any(np.isfinite(smap.rho)) else 1.5
    lo, hi = min(lo, 0.999), max(hi, 1.001)
    norm = TwoSlopeNorm(vmin=lo, vcenter=1.0, vmax=hi)
    X, Y = smap.x.values * fx, smap.y.values * fy
    mesh = ax.pcolormesh(X, Y, rho, cmap="RdYlGn_r", norm=norm, shading="nearest")
    cb = fig.colorbar(mesh, ax=ax)
    cb.set_label("largest closed-loop pole magnitude |z|max [-]")
    handles = []
    if np.nanmin(smap.rho) < 1 < np.nanmax(smap.rho):
        ax.contour(X, Y, smap.rho, levels=[1.0], colors="k", linewidths=2.0)
        handles.append(Line2D([], [], color="k", lw=2.0, label="exact sampled-data limit |z| = 1"))
    b = smap.boundary
    if b is not None:
        bx, by = b["x"] * fx, b["y"] * fy
        for key, style, label in (("pct_ratio", "--", "PCT limit K0 = 2 zeta / Ts"),
                                  ("continuous_ratio", ":", "continuous limit K0 = 2 zeta w0")):
            r = b[key]
            if np.all(np.isfinite(r)) and r.min() < 1 < r.max() and min(r.shape) >= 2:
                ax.contour(bx, by, r, levels=[1.0], colors="#1f3a93", linestyles=style,
                           linewidths=1.6)
                handles.append(Line2D([], [], color="#1f3a93", ls=style, lw=1.6, label=label))
    ax.set_xlabel(lx)
    ax.set_ylabel(ly)
    ctrl = smap.controller
    desc = f"kp = {ctrl['kp']:g} V/m" if smap.x.name not in ("kp", "k0") and smap.y.name not in ("kp", "k0") else ""
    if ctrl.get("kd"):
        desc += f", kd = {ctrl['kd']:g} V s/m"
    T = "" if "sample_time" in (smap.x.name, smap.y.name) else f"T = {ctrl['sample_time'] * 1e3:g} ms"
    extra = ", ".join(s for s in (desc.strip(", "), T,
                                  f"{smap.delay_samples} sample delay" if smap.delay_samples else "")
                      if s)
    ax.set_title(title or f"Stability map{': ' + extra if extra else ''}", fontsize=11)
    if handles:
        ax.legend(handles=handles, loc="best", fontsize=8, framealpha=0.85)
    return fig


def pole_step_figure(poles: Mapping[str, np.ndarray], t: np.ndarray,
                     steps: Mapping[str, np.ndarray], title: str = ""):
    """z-plane poles (left, unit circle) and unit-step responses (right) of several models."""
    fig, (ax_z, ax_s) = plt.subplots(1, 2, figsize=(10, 4.2), constrained_layout=True,
                                     gridspec_kw={"width_ratios": [1, 1.35]})
    th = np.linspace(0, 2 * np.pi, 400)
    ax_z.plot(np.cos(th), np.sin(th), color="0.5", lw=0.8)
    markers = ["o", "x", "s", "^", "d"]
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (label, p) in enumerate(poles.items()):
        p = np.asarray(p)
        ax_z.plot(p.real, p.imag, markers[i % len(markers)], color=colours[i % len(colours)],
                  ms=8, mfc="none" if markers[i % len(markers)] in "osd^" else None, mew=1.6,
                  label=label)
    allp = np.concatenate([np.asarray(p) for p in poles.values()])
    lo = min(0.0, float(allp.real.min()) - 0.05)
    ax_z.set_xlim(lo, 1.05)
    half = max(0.2, float(np.abs(allp.imag).max()) + 0.05, (1.05 - lo) / 2)
    ax_z.set_ylim(-half, half)
    ax_z.set_aspect("equal", adjustable="box")
    ax_z.axhline(0, color="0.7", lw=0.6)
    ax_z.set_xlabel("Re z [-]")
    ax_z.set_ylabel("Im z [-]")
    ax_z.set_title("closed-loop poles (unit circle in grey)", fontsize=10)
    ax_z.grid(True, alpha=0.3)
    ax_z.legend(fontsize=8, loc="lower left")
    for i, (label, y) in enumerate(steps.items()):
        ax_s.step(t, np.asarray(y).ravel()[:len(t)], where="post", color=colours[i % len(colours)],
                  label=label)
    ax_s.set_xlabel("time t [s]")
    ax_s.set_ylabel("position / reference step [-]")
    ax_s.set_title("closed-loop unit-step responses", fontsize=10)
    ax_s.grid(True, alpha=0.3)
    ax_s.legend(fontsize=8, loc="lower right")
    if title:
        fig.suptitle(title, fontsize=11)
    return fig


def robustness_figure(result, x: np.ndarray, y: np.ndarray, xlabel: str, ylabel: str,
                      title: str = "", score_label: str = "IAE [mm s]", score_scale: float = 1e3):
    """Monte Carlo outcome (:class:`workbench.robustness.RobustnessResult`) per draw.

    Top row, one panel per controller: the draws in the (``x``, ``y``) plane (e.g.
    flow factor, mass factor), a green circle where it passed, a red cross where it
    failed. Bottom: each controller's score (scaled by ``score_scale``) against ``x``,
    filled where it passed, hollow where it failed (log axis when the scores span
    more than a decade).

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = list(result.passed)
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if len(x) != len(result.draws) or len(y) != len(result.draws):
        raise ValueError(f"give one x and y per draw ({len(result.draws)}), "
                         f"got {len(x)} and {len(y)}")
    n = len(names)
    fig = plt.figure(figsize=(max(8.5, 2.9 * n), 7.0), constrained_layout=True)
    gs = fig.add_gridspec(2, n, height_ratios=[1.0, 1.1])
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    first = None
    for j, name in enumerate(names):
        ax = fig.add_subplot(gs[0, j], sharex=first, sharey=first)
        first = first or ax
        ok = np.array(result.passed[name], dtype=bool)
        ax.scatter(x[ok], y[ok], marker="o", s=28, facecolors="none", edgecolors="tab:green",
                   label="pass")
        ax.scatter(x[~ok], y[~ok], marker="x", s=28, color="tab:red", label="fail")
        ax.set_title(f"{name}: {ok.mean():.0%} pass", fontsize=10)
        ax.set_xlabel(xlabel)
        if j == 0:
            ax.set_ylabel(ylabel)
            ax.legend(loc="best", fontsize=8)
        ax.grid(True, alpha=0.3)
    ax = fig.add_subplot(gs[1, :])
    all_scores = []
    for j, name in enumerate(names):
        s = np.array(result.scores.get(name, [np.nan] * len(x)), dtype=float) * score_scale
        ok = np.array(result.passed[name], dtype=bool)
        c = colors[j % len(colors)]
        order = np.argsort(x)
        ax.plot(x[order], s[order], color=c, lw=0.8, alpha=0.5)
        ax.scatter(x[ok], s[ok], color=c, s=26, label=f"{name} pass")
        ax.scatter(x[~ok], s[~ok], facecolors="none", edgecolors=c, s=26, label=f"{name} fail")
        all_scores.extend(s[np.isfinite(s)])
    pos = [v for v in all_scores if v > 0]
    if pos and max(pos) / min(pos) > 10.0:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(score_label)
    ax.grid(True, alpha=0.3, which="both")
    ax.legend(loc="best", fontsize=8, ncol=max(1, n))
    if title:
        fig.suptitle(title, fontsize=11)
    return fig


_PLAN_COLORS = {"mean": "tab:blue", "min_air": "tab:green", "single_valve": "tab:red"}


def pressure_plan_figure(plans: Mapping, leading: Sequence[tuple], title: str = ""):
    """Pressure plans (:func:`workbench.controllers.force.pressure_plan`) by rule.

    ``leading`` panels come first, each ``(ylabel, t, y, label)`` drawn in black (e.g.
    the force profile, the position trajectory); then the chamber pressures p_a
    (solid) and p_b (dashed) in bar abs, and the port commands in V (port B dotted,
    except for the single-valve plan where both ports share one command).

    Returns
    -------
    matplotlib.figure.Figure
    """
    n = len(leading) + 2
    fig, axes = plt.subplots(n, 1, sharex=True, figsize=(9.0, 2.5 * n + 0.5),
                             constrained_layout=True)
    for ax, (ylabel, t, y, label) in zip(axes, leading):
        ax.plot(t, y, "k", lw=1.2, label=label)
        ax.set_ylabel(ylabel)
    ax_p, ax_u = axes[-2], axes[-1]
    for rule, plan in plans.items():
        c = _PLAN_COLORS.get(rule)
        ax_p.plot(plan.time, plan.p_a / 1e5, color=c, lw=1.1, label=f"p_a {rule}")
        ax_p.plot(plan.time, plan.p_b / 1e5, color=c, lw=1.1, ls="--", label=f"p_b {rule}")
        ax_u.plot(plan.time, plan.command_a, color=c, lw=1.0, label=f"u port A {rule}")
        if rule != "single_valve":
            ax_u.plot(plan.time, plan.command_b, color=c, lw=1.0, ls=":", label=f"u port B {rule}")
    ax_p.set_ylabel("pressure [bar abs]")
    ax_u.set_ylabel("command [V]")
    ax_u.set_xlabel("time t [s]")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=7, ncol=3)
    if title:
        fig.suptitle(title, fontsize=11)
    return fig
