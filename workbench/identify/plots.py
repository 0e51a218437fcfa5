"""Figures for identification (matplotlib, no screen needed). Plotting only.

Each function takes a result object computed elsewhere (e.g.
:class:`workbench.identify.arx.ArxValidation`), draws it, and either saves it (``path``
given: written atomically, figure closed, path returned) or returns the figure.
"""

from __future__ import annotations

import os
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["residual_figure", "validation_figure"]


def _finish(fig, path: str | os.PathLike | None):
    if path is None:
        return fig
    from ..plots import save_figure
    save_figure(fig, path)
    return path


def residual_figure(result: Any, path: str | os.PathLike | None = None, title: str = "",
                    input_unit: str = "-", output_unit: str = "-", input_name: str = "u",
                    output_name: str = "y"):
    """Residual analysis: autocorrelation and input-residual cross-correlation.

    Parameters
    ----------
    result : ArxValidation
        From :func:`workbench.identify.arx.validate` (uses ``lags``,
        ``autocorrelation``, ``cross_lags``, ``cross_correlation``, ``band``, the
        verdicts and ``sample_time``).
    path : str or path-like, optional
        Where to save (PNG, PDF, ... by suffix). Without it the figure is returned.
    title : str, optional
        Figure title.
    input_unit, output_unit : str, optional
        Units of u and y (the correlations are normalised, -; named in the legend).
    input_name, output_name : str, optional
        Signal names for the labels (e.g. ``"r"``, ``"x"``).

    Returns
    -------
    matplotlib.figure.Figure or path
    """
    fig, (ax_e, ax_u) = plt.subplots(2, 1, figsize=(8.5, 6.0), constrained_layout=True)
    fig.suptitle(title or "Residual analysis", fontsize=11)
    band = float(result.band)
    ts = result.sample_time
    lag_label = "lag tau [samples]" + (f"  (1 sample = {ts:g} s)" if ts else "")

    def verdict(ok, p, what):
        if ok is None:
            return f"{what}: not tested"
        return f"{what}: {'pass' if ok else 'FAIL'} (p = {p:.3g}, 1 % level)"

    lags = np.asarray(result.lags)
    ax_e.vlines(lags, 0.0, result.autocorrelation, color="C0", lw=2)
    ax_e.plot(lags, result.autocorrelation, "o", color="C0", ms=3,
              label=f"residual e of {output_name} [{output_unit}]")
    ax_e.axhspan(-band, band, color="C1", alpha=0.2,
                 label=f"99 % band +-{band:.3f} (2.58/sqrt(N), N = {result.n_samples})")
    ax_e.axhline(0.0, color="k", lw=0.6)
    ax_e.set_xlabel(lag_label)
    ax_e.set_ylabel("autocorrelation r_e(tau) [-]")
    ax_e.set_title(verdict(result.whiteness_ok, result.whiteness_p_value,
                           "whiteness (Ljung-Box)"), fontsize=9)
    ax_e.legend(loc="upper right", fontsize=8)

    cl = np.asarray(result.cross_lags)
    ax_u.vlines(cl, 0.0, result.cross_correlation, color="C2", lw=2)
    ax_u.plot(cl, result.cross_correlation, "o", color="C2", ms=3,
              label=f"e [{output_unit}] with {input_name}(k - tau) [{input_unit}]")
    ax_u.axhspan(-band, band, color="C1", alpha=0.2, label="99 % band")
    ax_u.axhline(0.0, color="k", lw=0.6)
    ax_u.axvline(0.0, color="k", lw=0.6, ls=":")
    ax_u.set_xlabel(lag_label + "; tau < 0: future inputs (feedback)")
    ax_u.set_ylabel("cross-correlation r_eu(tau) [-]")
    ax_u.set_title(verdict(result.independence_ok, result.independence_p_value,
                           "independence of past inputs, tau >= 0"), fontsize=9)
    ax_u.legend(loc="upper right", fontsize=8)
    for ax in (ax_e, ax_u):
        ax.grid(True, alpha=0.3)
    return _finish(fig, path)


def validation_figure(result: Any, path: str | os.PathLike | None = None, title: str = "",
                      input_unit: str = "-", output_unit: str = "-", input_name: str = "u",
                      output_name: str = "y", t0: float = 0.0):
    """Measured vs simulated output on (held-out) data, with the fit in percent.

    Parameters
    ----------
    result : ArxValidation
        From :func:`workbench.identify.arx.validate` (uses ``y``, ``u``,
        ``y_simulated``, ``fit``, ``max_lag``, ``sample_time``).
    path : str or path-like, optional
        Where to save. Without it the figure is returned.
    title : str, optional
        Figure title.
    input_unit, output_unit : str, optional
        Units of u and y for the axis labels.
    input_name, output_name : str, optional
        Signal names for the labels (e.g. ``"r"``, ``"x"``).
    t0 : float, optional
        Time of the first sample, s (e.g. where the held-out part of a recording
        starts); ignored when the sample time is unknown.

    Returns
    -------
    matplotlib.figure.Figure or path
    """
    fig, (ax_y, ax_err, ax_u) = plt.subplots(
        3, 1, sharex=True, figsize=(8.5, 7.0), constrained_layout=True,
        gridspec_kw={"height_ratios": [3, 1.3, 1.3]})
    fig.suptitle(title or "Validation by simulation", fontsize=11)
    y = np.asarray(result.y)
    ys = np.asarray(result.y_simulated)
    ts = result.sample_time
    t = np.arange(y.size) * ts + t0 if ts else np.arange(y.size, dtype=float)
    t_label = "time t [s]" if ts else "sample k [-]"
    n0 = int(result.max_lag)
    ax_y.plot(t, y, color="k", lw=1.0, label="measured")
    ax_y.plot(t[n0:], ys[n0:], color="C3", lw=1.2,
              label=f"simulated (fit {result.fit:.1f} %)")
    ax_y.set_ylabel(f"output {output_name} [{output_unit}]")
    ax_y.legend(loc="best", fontsize=8)
    ax_err.plot(t[n0:], y[n0:] - ys[n0:], color="C3", lw=0.8)
    ax_err.axhline(0.0, color="k", lw=0.6)
    ax_err.set_ylabel(f"{output_name} - simulated [{output_unit}]")
    ax_u.step(t, result.u, where="post", color="C0", lw=0.9)
    ax_u.set_ylabel(f"input {input_name} [{input_unit}]")
    ax_u.set_xlabel(t_label)
    for ax in (ax_y, ax_err, ax_u):
        ax.grid(True, alpha=0.3)
    return _finish(fig, path)


def rls_figure(result: Any, truth: Any = None, path: str | os.PathLike | None = None,
               title: str = "", output_unit: str | None = None,
               input_unit: str | None = None, max_points: int = 20000):
    """Parameter tracks of recursive least squares with +-2 standard-deviation bands.

    One panel per parameter: ``a_i(k)`` on the left, ``b_i(k)`` on the right, the
    estimate as a line, the band ``theta +- 2 std`` shaded, the true trajectory (if
    known) dashed. Long records are thinned to ``max_points`` points per line (every
    n-th sample) for drawing only.

    Parameters
    ----------
    result : RlsResult
        From :func:`workbench.identify.rls.rls` (uses ``time``, ``theta``, ``std``,
        ``names``, ``orders``, ``forgetting``, ``sample_time``).
    truth : mapping or array_like, optional
        True parameters: a mapping name -> value or array of ``len(result)`` values
        (missing names are not drawn), or an array of shape ``(len(result), na + nb)``.
    path : str or path-like, optional
        Where to save (PNG, PDF, ... by suffix; atomically). Without it the figure is
        returned.
    title : str, optional
        Figure title.
    output_unit, input_unit : str, optional
        Units of y and u: ``a_i`` are dimensionless, ``b_i`` are in
        output unit / input unit.
    max_points : int, optional
        Most points drawn per line.

    Returns
    -------
    matplotlib.figure.Figure or path
    """
    na, nb = int(result.orders[0]), int(result.orders[1])
    names = tuple(result.names)
    n_est = int(np.asarray(result.time).shape[0])
    step = max(1, -(-n_est // int(max_points)))
    sel = slice(None, None, step)
    t = np.asarray(result.time)[sel]
    theta = np.asarray(result.theta)[sel]
    std = np.asarray(result.std)[sel]
    t_label = "time t [s]" if result.sample_time is not None else "sample k [-]"
    b_unit = f"{output_unit or '-'}/{input_unit or '-'}" if (output_unit or input_unit) else "-"

    true_tracks: dict[str, np.ndarray] = {}
    if truth is not None:
        if isinstance(truth, dict) or hasattr(truth, "items"):
            items = [(k, v) for k, v in truth.items() if k in names]
        else:
            arr = np.asarray(truth, dtype=float)
            if arr.ndim != 2 or arr.shape[1] != len(names):
                raise ValueError(f"truth must have shape ({n_est}, {len(names)}), "
                                 f"got {arr.shape}")
            items = list(zip(names, arr.T))
        for k, v in items:
            v = np.asarray(v, dtype=float)
            true_tracks[k] = np.full(t.shape, float(v)) if v.ndim == 0 else v[sel]

    ncols = (1 if na else 0) + (1 if nb else 0)
    nrows = max(na, nb)
    fig, axes = plt.subplots(nrows, ncols, sharex=True, squeeze=False,
                             figsize=(5.2 * ncols + 0.6, 1.9 * nrows + 1.2),
                             constrained_layout=True)
    fig.suptitle(title or f"Recursive least squares, lambda = {result.forgetting:g}",
                 fontsize=11)
    burn = max(1, t.size // 20)          # the prior-dominated start is left out of the y range
    for i, name in enumerate(names):
        col = 0 if (i < na or not na) else 1
        row = i if i < na else i - na
        ax = axes[row, col]
        est, s = theta[:, i], std[:, i]
        ax.fill_between(t, est - 2 * s, est + 2 * s, color=f"C{col}", alpha=0.25, lw=0,
                        label="+-2 std")
        ax.plot(t, est, color=f"C{col}", lw=1.0, label="estimate")
        vals = est[burn:] if est.size > burn else est
        if name in true_tracks:
            ax.plot(t, true_tracks[name], "k--", lw=1.0, label="true")
            vals = np.concatenate([vals, true_tracks[name]])
        vals = vals[np.isfinite(vals)]
        if vals.size:
            lo, hi = np.percentile(vals, [0.5, 99.5])
            pad = 0.25 * (hi - lo) if hi > lo else 0.1 * max(abs(hi), 1e-12)
            ax.set_ylim(lo - pad, hi + pad)
        unit = "-" if i < na else b_unit
        ax.set_ylabel(f"{name} [{unit}]")
        fin, fs = float(result.theta[-1, i]), float(result.std[-1, i])
        ax.set_title(f"{name} final {fin:.4g} +- {fs:.2g} (1 std)", fontsize=9, loc="right")
        ax.grid(True, alpha=0.3)
        if row == 0:
            ax.legend(loc="best", fontsize=7)
    for col in range(ncols):
        used = na if (col == 0 and na) else nb
        for row in range(used, nrows):
            axes[row, col].set_visible(False)
        axes[used - 1, col].set_xlabel(t_label)
        axes[used - 1, col].tick_params(labelbottom=True)
    if path is None:
        return fig
    from ..plots import save_figure
    save_figure(fig, path)
    return path


__all__ += ["rls_figure"]


# ---------------------------------------------------------------------- valve characteristic
# (paper 003; results from :mod:`workbench.identify.valve`)
_G = 1e3          # g/s per kg/s
_BAR = 1e5        # Pa per bar


def valve_curves_figure(curves: Any, path: str | os.PathLike | None = None, title: str = ""):
    """Valve characteristic q_m(u) at several pressures: table points and fitted lines.

    Parameters
    ----------
    curves : mapping
        From :func:`workbench.identify.valve.valve_curves`: ``pressures`` (Pa),
        ``data`` (one (u, q) pair per pressure, V and kg/s) and ``fits`` (label ->
        one (u, q) pair per pressure).
    path : str or path-like, optional
        Where to save. Without it the figure is returned.
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure or path
    """
    fits = dict(curves["fits"])
    n = max(1, len(fits))
    fig, axes = plt.subplots(1, n, sharey=True, squeeze=False, figsize=(5.2 * n + 0.8, 4.6),
                             constrained_layout=True)
    fig.suptitle(title or "Valve characteristic q_m(p, u)", fontsize=11)
    colors = plt.cm.viridis(np.linspace(0.0, 0.9, len(curves["pressures"])))
    for ax, label in zip(axes[0], fits or [""]):
        for k, p in enumerate(curves["pressures"]):
            u, q = curves["data"][k]
            ax.plot(u, np.asarray(q) * _G, "o", ms=3.5, color=colors[k],
                    label=f"table, p = {p / _BAR:.2f} bar")
            if label:
                uf, qf = fits[label][k]
                ax.plot(uf, np.asarray(qf) * _G, "-", lw=1.1, color=colors[k])
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_title(f"{label}: lines; table: points" if label else "table", fontsize=9)
        ax.set_xlabel("command u [V]")
        ax.grid(True, alpha=0.3)
    axes[0, 0].set_ylabel("mass flow into the port q_m [g/s]")
    axes[0, 0].legend(loc="best", fontsize=7)
    return _finish(fig, path)


def valve_error_figure(u: Any, p: Any, errors: Any, path: str | os.PathLike | None = None,
                       title: str = ""):
    """Map of the flow errors q_fit - q_table (g/s) over the table's (u, p) points.

    Parameters
    ----------
    u, p : array_like
        Commands (V) and pressures (Pa) of the table points.
    errors : mapping
        Label -> errors at those points, kg/s.
    path : str or path-like, optional
        Where to save. Without it the figure is returned.
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure or path
    """
    u = np.asarray(u, dtype=float)
    pb = np.asarray(p, dtype=float) / _BAR
    errs = {k: np.asarray(v, dtype=float) * _G for k, v in dict(errors).items()}
    n = max(1, len(errs))
    lim = max([float(np.max(np.abs(e))) for e in errs.values()] + [1e-12])
    fig, axes = plt.subplots(1, n, sharey=True, squeeze=False, figsize=(5.0 * n + 1.2, 4.4),
                             constrained_layout=True)
    fig.suptitle(title or "Flow errors of the approximations", fontsize=11)
    sc = None
    for ax, (label, e) in zip(axes[0], errs.items()):
        sc = ax.scatter(u, pb, c=e, cmap="coolwarm", vmin=-lim, vmax=lim, s=28,
                        edgecolors="0.3", linewidths=0.3)
        ax.set_title(f"{label}: max |error| {np.max(np.abs(e)):.3f} g/s, "
                     f"RMS {np.sqrt(np.mean(e ** 2)):.3f} g/s", fontsize=9)
        ax.set_xlabel("command u [V]")
        ax.grid(True, alpha=0.3)
    axes[0, 0].set_ylabel("port pressure p [bar abs]")
    if sc is not None:
        fig.colorbar(sc, ax=axes[0, :].tolist(), label="q_fit - q_table [g/s]")
    return _finish(fig, path)


def pressure_gain_figure(gains: Any, path: str | os.PathLike | None = None, title: str = "",
                         u_range: tuple[float, float] | None = None):
    """Pressure gain characteristic p_e(u) (q_m = 0) with Cp and Gu along it.

    Parameters
    ----------
    gains : sequence of PressureGain
        From :mod:`workbench.identify.valve` (``label``, ``u`` V, ``p_e`` Pa,
        ``cp`` kg/(s Pa), ``gu`` kg/(s V)); one labelled ``"data"`` is drawn as points.
    path : str or path-like, optional
        Where to save. Without it the figure is returned.
    title : str, optional
        Figure title.
    u_range : (low, high), optional
        Command range to show, V (default: where the data's equilibria lie strictly
        inside the pressure range, widened by half of it).

    Returns
    -------
    matplotlib.figure.Figure or path
    """
    gains = list(gains)
    fig, (ax_p, ax_c, ax_g) = plt.subplots(3, 1, sharex=True, figsize=(8.0, 8.6),
                                           constrained_layout=True)
    fig.suptitle(title or "Pressure gain characteristic q_m(p_e, u) = 0", fontsize=11)
    for k, g in enumerate(gains):
        u = np.asarray(g.u)
        style = dict(ls="none", marker="o", ms=4, color="k") if g.label == "data" else \
            dict(ls="-", lw=1.2, color=f"C{k}")
        lab = f"{g.label} ({g.method})"
        ax_p.plot(u, np.asarray(g.p_e) / _BAR, label=lab, **style)
        ax_c.plot(u, np.asarray(g.cp) * _G * _BAR, **style)
        ax_g.plot(u, np.asarray(g.gu) * _G, **style)
    if u_range is None:
        data = [g for g in gains if g.label == "data" and len(g.u)]
        ref = data[0] if data else (gains[0] if gains else None)
        if ref is not None and len(ref.u) > 1:
            pe = np.asarray(ref.p_e)
            lo, hi = np.min(pe), np.max(pe)
            inside = (pe > lo + 0.02 * (hi - lo)) & (pe < hi - 0.02 * (hi - lo))
            uu = np.asarray(ref.u)[inside] if np.any(inside) else np.asarray(ref.u)
            a, b = float(np.min(uu)), float(np.max(uu))
            w = max(b - a, 1e-3)
            u_range = (a - 0.5 * w, b + 0.5 * w)
    if u_range is not None:
        ax_g.set_xlim(*u_range)
        for ax, key, k in ((ax_c, "cp", _G * _BAR), (ax_g, "gu", _G)):
            vals = np.concatenate([np.asarray(getattr(g, key))[(np.asarray(g.u) >= u_range[0])
                                                               & (np.asarray(g.u) <= u_range[1])]
                                   for g in gains] + [np.zeros(0)]) * k
            vals = vals[np.isfinite(vals)]
            if vals.size:
                lo, hi = float(np.min(vals)), float(np.max(vals))
                pad = 0.08 * (hi - lo) if hi > lo else 0.1 * max(abs(hi), 1e-12)
                ax.set_ylim(lo - pad, hi + pad)
    ax_p.set_ylabel("equilibrium pressure p_e [bar abs]")
    ax_c.set_ylabel("Cp = -dq/dp [g/(s bar)]")
    ax_g.set_ylabel("Gu = dq/du [g/(s V)]")
    ax_g.set_xlabel("command u [V]")
    ax_p.legend(loc="best", fontsize=8)
    for ax in (ax_p, ax_c, ax_g):
        ax.grid(True, alpha=0.3)
    return _finish(fig, path)


def tank_steps_figure(tests: Any, path: str | os.PathLike | None = None, title: str = ""):
    """Tank step tests of paper 003: pressure after command steps, and error vs reference.

    Parameters
    ----------
    tests : TankStepTests
        From :func:`workbench.identify.valve.tank_steps` (``steps`` keyed by
        (law, du), ``reference``, ``u_e``, ``volume``).
    path : str or path-like, optional
        Where to save. Without it the figure is returned.
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure or path
    """
    labels = tests.labels()
    sizes = tests.step_sizes()
    big = [d for d in sizes if abs(d) >= 0.5]
    small = [d for d in sizes if abs(d) < 0.5]
    groups = [g for g in (big, small) if g]
    fig, axes = plt.subplots(2, len(groups), sharex="col", squeeze=False,
                             figsize=(6.0 * len(groups) + 0.6, 7.0), constrained_layout=True)
    fig.suptitle(title or (f"Tank steps at u_e = {tests.u_e:g} V, V = {tests.volume * 1e3:g} l, "
                           f"k = {tests.k:g}"), fontsize=11)
    ls = {d: s for d, s in zip(sizes, ["-", "--", "-.", ":"] * 4)}
    for col, group in enumerate(groups):
        ax_p, ax_e = axes[0, col], axes[1, col]
        for du in group:
            ref = tests.steps[(tests.reference, du)]
            for k, lab in enumerate(labels):
                st = tests.steps[(lab, du)]
                color = "k" if lab == tests.reference else f"C{k}"
                ax_p.plot(st.t, st.p / _BAR, color=color, ls=ls[du], lw=1.1,
                          label=f"{lab}, {du:+g} V")
                if lab != tests.reference:
                    ax_e.plot(st.t, 100.0 * (st.p - ref.p) / ref.p, color=color, ls=ls[du],
                              lw=1.0, label=f"{lab}, {du:+g} V")
        ax_p.set_ylabel("tank pressure p [bar abs]")
        ax_e.set_ylabel(f"(p - p_{tests.reference}) / p_{tests.reference} [%]")
        ax_e.set_xlabel("time t [s]")
        ax_p.set_title(f"steps of {', '.join(f'{d:+g}' for d in group)} V", fontsize=9)
        for ax in (ax_p, ax_e):
            ax.grid(True, alpha=0.3)
            ax.legend(loc="best", fontsize=7)
    return _finish(fig, path)


__all__ += ["valve_curves_figure", "valve_error_figure", "pressure_gain_figure",
            "tank_steps_figure"]


# ---------------------------------------------------------------------- grey-box
def greybox_figure(recordings: Any, result: Any, path: str | os.PathLike | None = None,
                   title: str = ""):
    """Recording vs nominal model vs estimated model, for each compared signal.

    Parameters
    ----------
    recordings : sequence of Recording
        The recordings the grey-box fit used, in the same order.
    result : GreyBoxResult
        From :func:`workbench.identify.grey_box.estimate` (uses its CVODES replays
        ``trajectories_before`` / ``trajectories_after`` and the fits).
    path : str or path-like, optional
        Where to save; without it the figure is returned.
    title : str, optional
        Figure title.
    """
    recs = list(recordings)
    scale = {"x": (1e3, "position x [mm]"), "v": (1.0, "velocity v [m/s]"),
             "p_a": (1e-5, "p_a [bar abs]"), "p_b": (1e-5, "p_b [bar abs]"),
             "p_s": (1e-5, "p_s [bar abs]"), "u": (1.0, "command u [V]")}
    sigs = [s for s in ("x", "v", "p_a", "p_b", "p_s")
            if any(s in fa for fa in result.fit_after)]
    rows = sigs + ["u"]
    ncol = len(recs)
    fig, axes = plt.subplots(len(rows), ncol, sharex="col", squeeze=False,
                             figsize=(8.0 * ncol + 0.6, 2.0 * len(rows) + 1.0),
                             constrained_layout=True)
    fig.suptitle(title or "Grey-box estimation: recording, nominal and estimated model",
                 fontsize=11)
    for c, rec in enumerate(recs):
        before = result.trajectories_before[c] if c < len(result.trajectories_before) else None
        after = result.trajectories_after[c] if c < len(result.trajectories_after) else None
        fb = result.fit_before[c] if c < len(result.fit_before) else {}
        fa = result.fit_after[c] if c < len(result.fit_after) else {}
        for r, s in enumerate(rows):
            ax = axes[r, c]
            k, lab = scale[s]
            if s == "u":
                ax.step(rec.t, rec["u"], where="post", color="0.3", lw=0.9)
            elif s in rec:
                ax.plot(rec.t, rec[s] * k, color="0.35", lw=1.3, label="recording")
                if before is not None:
                    ax.plot(before.time, before[s] * k, color="tab:blue", lw=0.9, ls="--",
                            label=f"nominal ({fb.get(s, float('nan')):.1f} %)")
                if after is not None:
                    ax.plot(after.time, after[s] * k, color="tab:red", lw=0.9,
                            label=f"estimated ({fa.get(s, float('nan')):.1f} %)")
                ax.legend(loc="best", fontsize=7)
            ax.set_ylabel(lab)
            ax.grid(True, alpha=0.3)
        axes[0, c].set_title(result.sources[c] if c < len(result.sources) else f"recording {c + 1}",
                             fontsize=9)
        axes[-1, c].set_xlabel("time t [s]")
    return _finish(fig, path)


__all__ += ["greybox_figure"]
