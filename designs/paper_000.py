"""Paper 000 (Situm, Novakovic, Petric) end to end: calibrate the rig, rerun Table I.

The rig model's uncertain values are estimated from what the paper reports:

* valve size: the grey-box estimator (:func:`workbench.identify.grey_box.estimate`:
  least squares on the nonlinear model, exact sensitivities, 95 % interval from the
  covariance) fits the sonic conductance to Fig. 6 -- a 1 V open-loop step giving
  Kv x 1 V = 0.7 m/s (eq. 5), with the shape of the paper's own model (Table II);
* supply convention: Table II's 5e5 Pa is read as absolute and as gauge; the paper's
  experiment runs on both calibrated rigs and the reading whose re-identified ARX is
  closer to Table I is kept;
* deadband: from Table I's closed-loop DC gain (0.984, the P loop's steady-state error)
  by bisection on the simulated experiment with Fig. 6 held, interval from the
  table's rounding.

Then the paper's experiment runs on the calibrated rig (P loop, kp = 10 V/m so that
K0 = 7 1/s, T = 10 ms, Table II's 12-bit converters, APRBS reference over the stroke),
is written to ``DIR/table1_experiment.csv`` (t, r, u, x) and identified as ARX [4 1 1]
with the workbench's ARX code (the same as ``workbench identify arx
DIR/table1_experiment.csv --input r --output x --orders 4 1 2``). The report's first
table is the paper's results beside the workbench's, then the calibration, the
experiment, Fig. 7's P loop and a section on each disagreement with its measured
cause; ``DIR/summary.json`` holds the rows in ``paper_results``; the calibrated plant
is written to ``DIR/situm_rodless.calibrated.toml`` (a full run's copy, with comments:
``designs/plants/papers/situm_rodless_calibrated.toml``).

Usage: python designs/paper_000.py [--quick] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from workbench import Plant, controllers, linearize, simulate
from workbench import report as rp
from workbench.identify.arx import fit_arx
from workbench.identify.arx import validate as arx_validate
from workbench.identify.excitation import aprbs, as_reference
from workbench.identify.grey_box import estimate
from workbench.errors import InputError
from workbench.output import check_output_dir
from workbench.params import atomic_write_text, json_safe
from workbench.recording import Recording

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PLANT = HERE / "plants" / "situm_rodless.toml"
#: The calibrated plant a full run writes (copied here from DIR/situm_rodless.calibrated.toml).
CALIBRATED = HERE / "plants" / "papers" / "situm_rodless_calibrated.toml"
TITLE = "Paper 000 reproduced: calibrated rodless rig, Table I re-identified"
P_ATM = 101325.0

#: Values quoted from paper 000: (value, unit, where).
PAPER = {
    "kv": (0.7, "m/(V s)", "Sec. III, eq. (5), from the 1 V step of Fig. 6"),
    "w0": (32.97, "rad/s", "Table II"),
    "zeta": (1.1, "-", "Table II"),
    "k0": (7.0, "1/s", "eq. (9) with Table II gains"),
    "p_s": (5e5, "Pa", "Table II (absolute or gauge not stated)"),
    "T": (0.01, "s", "Sec. II and Table II"),
    "K_AD": (204.8, "1/V", "Table II"),
    "K_DA": (2.44e-3, "V", "Table II"),
    "K_m": (20.0, "V/m", "Table II"),
    "n": (800, "samples", "Sec. II: 400 estimation + 400 validation"),
}
#: Table I, ARX [4 1 1]: magnitudes and standard deviations quoted from Table I; the
#: signs were lost in the text extraction and are restored as in physics.md (with
#: them the DC gain is 0.98, as a closed position loop must have).
TABLE1_A = np.array([-2.4478, 2.1352, -0.7742, 0.0995])
TABLE1_A_STD = np.array([0.0500, 0.1264, 0.1209, 0.0436])
TABLE1_B = 0.0125
TABLE1_B_STD = 0.0011
#: Reference range of the APRBS: the paper's 0..10 V is the full stroke (K_m = 20 V/m);
#: 5 % margins keep the piston off the end stops (the paper does not say how it did).
R_RANGE = (0.025, 0.475)
#: Parameters estimated from the paper's measurements.
CAL_PARAMS = ("valve.sonic_conductance",)
#: APRBS holds, samples: ASSUMED 0.1 .. 0.6 s (the paper does not give them; with these
#: a 400-sample half holds about a dozen levels).
HOLD = (10, 60)
#: A "large" steady-state error (Fig. 7, qualitative): larger than 1 % of Fig. 7's
#: 400 mm axis, i.e. visible on the printed figure.
LARGE_ERROR = 4e-3
#: Bisection bracket of the deadband (fraction of the command span): the DC gain of the
#: re-identified loop falls through Table I's 0.984 once in it (it is 0.996 at 0.02
#: and 0.953 at 0.12 on the calibrated rig).
DEADBAND_BRACKET = (0.02, 0.2)
#: Fig. 6 as a record: the curve sampled every 5 ms (a curve read off a figure has no
#: sampling of its own), its velocity known to the paper's one digit: 0.7 +- 0.05 m/s,
#: a uniform rounding error of std 0.05 / sqrt(3).
FIG6_DT = 5e-3
FIG6_V_STD = 0.05 / np.sqrt(3.0)
#: Start position of the 1 V steps (Fig. 6 record and the rig's step), m: ASSUMED (the
#: paper does not say); near one end so that 0.3 s at up to 1.5 m/s fit the stroke.
X_STEP = 0.02


def paper_setup(plant: Plant) -> dict:
    """Loop constants from Table II: kp (V/m), ADC and DAC steps, sample time."""
    kad, kda, km = PAPER["K_AD"][0], PAPER["K_DA"][0], PAPER["K_m"][0]
    kp = float(plant.params["controller.kp"])
    return {"kp": kp, "T": PAPER["T"][0], "x_step": 1.0 / (kad * km), "u_step": kda,
            "noise_x": 1.0 / (kad * km) / np.sqrt(12.0), "kp_table2": km * kad * kda}


def table1_response(r: np.ndarray) -> np.ndarray:
    """Output of Table I's ARX model driven by the reference r (m), from rest at r[0]."""
    a = np.r_[1.0, TABLE1_A]
    y = np.full(len(r), r[0])
    for k in range(4, len(r)):
        y[k] = -a[1:] @ y[k - 4:k][::-1] + TABLE1_B * r[k - 2]
    return y


def fig6_record(plant: Plant) -> Recording:
    """Fig. 6 as a record the grey-box estimator can fit: a 1 V step of the valve from
    its centre, the velocity following the paper's model Kv / (s^2/w0^2 + 2 zeta s/w0
    + 1) with Table II's values (Fig. 6 shows that model on the measured response).

    The piston starts at rest at ``X_STEP``; the chamber pressures of that rest state
    (the plant's centre balance) are given as columns only to fix the initial state
    (they are not compared): a closed-centre valve leaves the pressure level free, and
    a fit that may choose it would pre-charge the chambers to make the step faster.
    """
    import control
    kv, w0, zeta = PAPER["kv"][0], PAPER["w0"][0], PAPER["zeta"][0]
    dt = FIG6_DT
    t = np.arange(0.0, 0.6 + 1e-9, dt)
    step = (t >= 0.05).astype(float)
    v = control.forced_response(control.tf([kv], [1 / w0 ** 2, 2 * zeta / w0, 1.0]), t,
                                step).outputs
    x = X_STEP + np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    u0 = plant.params["valve.command_center"]
    rest = plant.initial_state(X_STEP)
    ones = np.ones_like(t)
    return Recording.from_arrays(t, source="paper 000 Fig. 6 (1 V step, Kv = 0.7)",
                                 u=u0 + step, x=x, v=v,
                                 p_a=rest[plant.state_index("p_a")] * ones,
                                 p_b=rest[plant.state_index("p_b")] * ones)


def table1_distance(model) -> float:
    """RMS over a1..a4, b1 of (re-identified - Table I) / combined std, -."""
    d = np.r_[(model.a - TABLE1_A) / np.hypot(TABLE1_A_STD, model.std_a),
              (model.b[0] - TABLE1_B) / np.hypot(TABLE1_B_STD, model.std_b[0])]
    return float(np.sqrt(np.mean(d ** 2)))


def calibrate(plant: Plant, setup: dict, quick: bool) -> dict:
    """Valve size from Fig. 6, supply convention from Table I.

    For each reading of Table II's 5e5 Pa (absolute; gauge = 6.01e5 Pa absolute) the
    grey-box estimator fits the valve's sonic conductance to the Fig. 6 record (the
    step alone cannot tell the two apart: a larger valve makes up for a lower
    pressure). Then the paper's experiment runs on each calibrated rig and the
    reading whose re-identified ARX lies closer to Table I (:func:`table1_distance`)
    is kept. Quick mode starts from the committed calibrated plant.
    """
    c0 = plant.params["valve.sonic_conductance"]
    if quick and CALIBRATED.exists():
        cprm = Plant.from_toml(CALIBRATED).params       # its valve carries the deadband
        d, s1 = cprm.get("valve.deadband", 0.0), 1.0 / cprm["valve.command_span"]
        c0 = cprm["valve.sonic_conductance"] * (s1 - d) / (s1 * (1 - d))
    fits, exps = {}, {}
    for conv, p_s in (("absolute", PAPER["p_s"][0]), ("gauge", PAPER["p_s"][0] + P_ATM)):
        start = plant.with_params(**{"supply.pressure": p_s, "valve.sonic_conductance": c0})
        rec = fig6_record(start)
        res = estimate(start, [rec], list(CAL_PARAMS), signals=("x", "v"), x0="from_recording",
                       noise={"x": setup["noise_x"], "v": FIG6_V_STD},
                       max_iter=15 if quick else 60, progress=False)
        fits[conv] = res
        exps[conv] = experiment(res.plant_, setup, PAPER["n"][0])
        print(f"    supply {conv} ({p_s * 1e-5:.2f} bar abs): "
              + ", ".join(f"{k} = {v:.4g}" for k, v in res.estimates.items())
              + f" ({res.status}); Table I distance {table1_distance(exps[conv]['model']):.2f}")
    best = min(exps, key=lambda c: table1_distance(exps[c]["model"]))
    return {"fits": fits, "experiments": exps, "convention": best, "result": fits[best],
            "record": rec}


def with_deadband(plant: Plant, d: float, c_open: float) -> Plant:
    """``plant`` with spool overlap ``d`` (fraction of the span) and the sonic
    conductance that keeps the 1 V opening's flow area: C (0.2 - d)/(1 - d) = 0.2 c_open
    (opening = (|s| - d)/(1 - d), s = 0.2 at 1 V), so Fig. 6's step is unchanged."""
    s1 = 1.0 / float(plant.params["valve.command_span"])
    return plant.with_params(**{"valve.deadband": d,
                                "valve.sonic_conductance": c_open * s1 * (1 - d) / (s1 - d)})


def table1_dc_band() -> tuple[float, float]:
    """Table I's closed-loop DC gain B(1)/A(1) and its standard deviation from the
    table's 4-decimal rounding (uniform +-5e-5 per coefficient; the printed std of
    the coefficients, without covariances, cannot be propagated to a sum of them)."""
    a1 = 1.0 + TABLE1_A.sum()
    grad = np.r_[np.full(4, -TABLE1_B / a1 ** 2), 1.0 / a1]
    return TABLE1_B / a1, float(np.linalg.norm(grad) * 5e-5 / np.sqrt(3.0))


def estimate_deadband(rig: Plant, setup: dict, quick: bool) -> dict:
    """Spool overlap from Table I's closed-loop DC gain (0.984: the P loop stops short of
    its reference, the steady-state error the paper attributes to deadband and static
    friction), by bisection on the simulated experiment with Fig. 6 held (:func:`with_deadband`),
    with the 95 % interval from the DC gain's rounding band (+- 1.96 std)."""
    c_open = float(rig.params["valve.sonic_conductance"])
    dc0, sd = table1_dc_band()
    cache: dict[float, float] = {}

    def dc(d: float) -> float:
        if d not in cache:
            m = experiment(with_deadband(rig, d, c_open), setup, PAPER["n"][0])["model"]
            cache[d] = float(m.b.sum() / (1.0 + m.a.sum()))
        return cache[d]

    def solve(target: float) -> float:
        lo, hi = DEADBAND_BRACKET
        for _ in range(4 if quick else 8):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if dc(mid) > target else (lo, mid)
        return 0.5 * (lo + hi)

    d_hat = solve(dc0)
    ci = (solve(dc0 + 1.96 * sd), solve(dc0 - 1.96 * sd))
    print(f"    deadband {d_hat:.4f} [{ci[0]:.4f}, {ci[1]:.4f}] from DC gain {dc0:.4f} +- {sd:.4f}")
    return {"deadband": d_hat, "ci95": ci, "dc_target": dc0, "dc_std": sd,
            "evaluations": sorted(cache.items()), "c_open": c_open,
            "plant": with_deadband(rig, d_hat, c_open)}


def step_velocity(plant: Plant, volts: float = 1.0) -> tuple[np.ndarray, np.ndarray, float]:
    """Open-loop step of ``volts`` from the valve centre at x = 20 mm, 1 ms samples.

    Returns (t s, v m/s, steady velocity m/s = mean over 0.15 .. 0.30 s after the step:
    the paper's model of Fig. 6 has settled by 0.15 s, its slower time constant being
    47 ms, and up to 1.5 m/s the piston is still short of the far end at 0.30 s).
    """
    t = np.arange(0.0, 0.3 + 1e-9, 1e-3)
    u = plant.params["valve.command_center"] + volts * np.ones_like(t)
    tr = simulate.open_loop(plant, t, u, x0=X_STEP, progress=False)
    v = np.asarray(tr["v"])
    return t, v, float(np.mean(v[t >= 0.15]))


def run_p_loop(plant: Plant, setup: dict, r: np.ndarray):
    """The paper's P loop (sampled at T, Table II's converters) on a sampled reference."""
    ctrl = controllers.PID(kp=setup["kp"], sample_time=setup["T"],
                           u_center=plant.params["valve.command_center"],
                           u_min=plant.params["valve.command_min"],
                           u_max=plant.params["valve.command_max"])
    ref = as_reference(r, setup["T"])
    return simulate.closed_loop(plant, ctrl, ref, t_end=(len(r) - 1) * setup["T"] + 1e-9,
                                position_resolution=setup["x_step"],
                                command_resolution=setup["u_step"], progress=False)


def experiment(plant: Plant, setup: dict, n: int, seed: int = 3) -> dict:
    """Table I's experiment on ``plant``: APRBS reference, P loop, ARX [4 1 1] identified
    on the first half, validated on the second (as ``workbench identify arx``)."""
    r = aprbs(n, hold_min=HOLD[0], low=R_RANGE[0], high=R_RANGE[1], seed=seed,
              hold_max=HOLD[1])
    tr = run_p_loop(plant, setup, r)
    t, x, u = tr.time[:n], np.asarray(tr["x"])[:n], np.asarray(tr["u"])[:n]
    rr = np.asarray(tr.reference)[:n]
    half = n // 2
    model = fit_arx(x[:half], rr[:half], orders=(4, 1, 2), sample_time=setup["T"])
    check = arx_validate(model, x[half:], rr[half:])
    return {"t": t, "r": rr, "u": u, "x": x, "model": model, "validation": check}


def pole_std(model, pole: complex) -> float:
    """Standard deviation of a pole of the re-identified A(q), m-free, from the model's
    full coefficient covariance.

    A root p of A(z) = z^4 + a1 z^3 + ... + a4 moves by dp = -sum_k p^(4-k) da_k / A'(p)
    (implicit function theorem, exact to first order); var(Re dp) + var(Im dp) from
    the covariance of a1..a4. Table I gives standard deviations without covariances,
    which cannot be propagated to its poles (a1..a4 are strongly correlated), so the
    comparison uses this interval and Table I's rounding.
    """
    a = np.asarray(model.a)
    na = len(a)
    cov = np.asarray(model.covariance)[:na, :na]
    sens = -np.array([pole ** (na - k) for k in range(1, na + 1)]) / np.polyval(
        np.polyder(np.r_[1.0, a]), pole)
    return float(np.sqrt(sens.real @ cov @ sens.real + sens.imag @ cov @ sens.imag))


def dominant(poles: np.ndarray) -> complex:
    """The pole of largest magnitude with non-negative imaginary part."""
    p = [z for z in poles if z.imag >= -1e-12]
    return complex(max(p, key=abs))


def staircase(plant: Plant, setup: dict, quick: bool):
    """Fig. 7-like run: the P loop on steps within 40 .. 400 mm; steady-state error of
    each hold = mean |r - x| over its last 0.5 s. Returns (trajectory, errors m)."""
    levels = [0.10, 0.30, 0.20, 0.36, 0.12] if not quick else [0.10, 0.30, 0.20]
    hold = 4.0 if not quick else 2.5
    n_hold = int(round(hold / setup["T"]))
    r = np.repeat(levels, n_hold)
    tr = run_p_loop(plant, setup, r)
    x, t = np.asarray(tr["x"]), tr.time
    errs = []
    for i in range(1, len(levels)):
        sel = (t > (i + 1) * hold - 0.5) & (t < (i + 1) * hold - setup["T"])
        errs.append(float(np.mean(np.abs(levels[i] - x[sel]))))
    return tr, np.array(errs)


def spring_w0_zeta(plant: Plant, x: float = 0.25) -> tuple[float, float, float]:
    """w0 (rad/s) and zeta of the piston on its air springs: the oscillatory (or the
    two real non-zero) eigenvalues p1, p2 of the exact tangent model at rest at x,
    w0^2 = p1 p2 and 2 zeta w0 = -(p1 + p2). Valid with a deadband too (the spring
    of the closed chambers does not need the valve)."""
    op = linearize.operating_point(plant, x)
    ev = linearize.tangent(plant, op).eigenvalues
    ev = ev[np.abs(ev) > 1e-6]
    osc = ev[np.abs(ev.imag) > 1e-9]
    pair = osc[:2] if len(osc) >= 2 else ev[np.argsort(np.abs(ev))][:2]
    w0 = float(np.sqrt(np.real(pair[0] * pair[1])))
    return w0, float(-np.real(pair[0] + pair[1]) / (2 * w0)), float(op.p_a)


def table1_equivalent(quick: bool) -> dict:
    """The paper's linear loop (Kv / (s (s^2/w0^2 + 2 zeta s/w0 + 1)), zeta of Table II,
    ZOH at T) whose closed-loop poles come nearest Table I's dominant pair: grid over w0
    (rad/s) and K0 (1/s), refined once around the best point in a full run."""
    from workbench import stability
    target = dominant(np.roots(np.r_[1.0, TABLE1_A]))
    zeta, T = PAPER["zeta"][0], PAPER["T"][0]

    def best_on(w0s, k0s):
        out = None
        for w0 in w0s:
            for k0 in k0s:
                p = stability.closed_loop_poles(float(w0), zeta, T, float(k0))
                d = float(np.min(np.abs(p - target)))
                if out is None or d < out[0]:
                    out = (d, float(w0), float(k0), p)
        return out

    d, w0, k0, p = best_on(np.arange(30.0, 91.0, 10.0), np.arange(3.0, 30.5, 1.0))
    if not quick:
        d, w0, k0, p = best_on(np.arange(w0 - 7.5, w0 + 7.6, 2.5), np.arange(k0 - 1, k0 + 1.01, 0.25))
    return {"w0": w0, "k0": k0, "distance": d, "poles": p,
            "k0_table2": best_on([PAPER["w0"][0]], np.arange(3.0, 30.5, 0.5))}


def sweep(plant: Plant, setup: dict, changes: list[dict], quick: bool) -> list[dict]:
    """Rerun the paper's measurements on variants of ``plant``: 1 V step velocity,
    full-opening velocity, re-identified ARX (dominant pole, distance to Table I) and
    the P loop's steady-state error."""
    rows = []
    for ch in changes:
        pl = plant.with_params(**ch)
        ex = experiment(pl, setup, PAPER["n"][0])
        _, v_full, _ = step_velocity(pl, 5.0)
        rows.append({"change": ch, "v_step": step_velocity(pl)[2], "v_full": float(v_full.max()),
                     "pole": dominant(ex["model"].poles), "distance": table1_distance(ex["model"]),
                     "sse": float(np.mean(staircase(pl, setup, quick)[1])),
                     "fit": ex["validation"].fit})
        print("    " + ", ".join(f"{k} = {v:.4g}" for k, v in ch.items())
              + f": v(1 V) = {rows[-1]['v_step']:.3f} m/s, |z|dom = {abs(rows[-1]['pole']):.4f}, "
              f"Table I distance {rows[-1]['distance']:.2f}, error {rows[-1]['sse'] * 1e3:.2f} mm")
    return rows


def row(result, paper, workbench, unit, source, how, agrees) -> dict:
    """One paper_results entry (summary.json contract)."""
    return {"result": result, "paper": paper, "workbench": workbench, "unit": unit,
            "source": source, "how": how, "agrees": bool(agrees)}


def arx_rows(model) -> list[dict]:
    """Table I beside the re-identified coefficients; agreement within 2 combined std."""
    rows = []
    names = [f"a{i + 1}" for i in range(4)] + ["b1"]
    paper = list(TABLE1_A) + [TABLE1_B]
    p_std = list(TABLE1_A_STD) + [TABLE1_B_STD]
    ours = list(model.a) + [float(model.b[0])]
    o_std = list(model.std_a) + [float(model.std_b[0])]
    for nm, p, ps, o, os_ in zip(names, paper, p_std, ours, o_std):
        tol = 2.0 * np.hypot(ps, os_)
        rows.append(row(f"Table I ARX [4 1 1] {nm} (std {ps:g})", p, float(o), "-",
                        "Table I (magnitude and std quoted; sign restored, physics.md)",
                        f"ARX [4 1 1] least squares on the simulated experiment (std "
                        f"{os_:.2g}); agrees within 2 combined std = {tol:.3g}",
                        abs(o - p) <= tol))
    return rows


def pole_rows(model) -> list[dict]:
    """Dominant and fast pole pairs of Table I (derived) beside the re-identified ones."""
    p_poles = np.roots(np.r_[1.0, TABLE1_A])
    o_poles = model.poles
    out = []
    for label, pick in (("dominant", dominant),
                        ("fast", lambda ps: complex(min((z for z in ps if z.imag >= -1e-12),
                                                        key=abs)))):
        pp, po = pick(p_poles), pick(o_poles)
        tol = 2.0 * pole_std(model, po) + 0.0005 * np.sqrt(2.0)
        out.append(row(f"closed-loop {label} poles", f"{pp.real:.3f} +- {abs(pp.imag):.3f}j",
                       f"{po.real:.3f} +- {abs(po.imag):.3f}j", "-",
                       "derived from Table I (physics.md), not printed in the paper",
                       f"roots of the re-identified A(q); agrees within 2 std of the pole "
                       f"(from the ARX covariance) plus Table I's rounding = {tol:.3g}",
                       abs(po - pp) <= tol))
    dc_p = TABLE1_B / (1.0 + TABLE1_A.sum())
    dc_o = float(model.b.sum() / (1.0 + model.a.sum()))
    out.append(row("closed-loop DC gain", round(dc_p, 3), dc_o, "-",
                   "derived from Table I (physics.md: 0.98)",
                   "B(1)/A(1) of the re-identified model; agrees within 0.01 (2 std of Table "
                   "I's rounding). Used to estimate the deadband: agreement by construction",
                   abs(dc_o - dc_p) <= 0.01))
    return out


# ---------------------------------------------------------------------- figures
def _axes(n=1, h=3.2):
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(n, 1, figsize=(7.0, h), sharex=True, squeeze=False)
    for a in axes[:, 0]:
        a.grid(alpha=0.3)
    return fig, list(axes[:, 0])


def fig_step(t, curves: dict):
    fig, (ax,) = _axes()
    for name, v in curves.items():
        ax.plot(t, v, label=name)
    ax.set_xlabel("time after the 1 V step [s]")
    ax.set_ylabel("piston velocity [m/s]")
    ax.legend(fontsize=8)
    return fig


def fig_experiment(ex: dict):
    fig, (a1, a2) = _axes(2, 4.8)
    half = len(ex["t"]) // 2
    a1.plot(ex["t"], ex["r"] * 1e3, "k", lw=0.8, label="reference r")
    a1.plot(ex["t"], ex["x"] * 1e3, label="calibrated rig x")
    a1.plot(ex["t"], table1_response(ex["r"]) * 1e3, ":", label="Table I model on the same r")
    a1.plot(ex["t"][half:], ex["validation"].y_simulated * 1e3, "--",
            label="re-identified ARX, validation half")
    a1.set_ylabel("position [mm]")
    a1.legend(fontsize=7, loc="upper right", ncol=2)
    a2.plot(ex["t"], ex["u"], lw=0.8)
    a2.set_ylabel("command u [V]")
    a2.set_xlabel("time [s]")
    return fig


def fig_poles(sets: dict):
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.0, 4.0))
    th = np.linspace(0, np.pi, 200)
    ax.plot(np.cos(th), np.sin(th), "k", lw=0.6)
    for (name, poles), mk in zip(sets.items(), "o^sx"):
        ax.plot(poles.real, np.abs(poles.imag), mk, mfc="none", ms=8, label=name)
    ax.set(xlim=(0.2, 1.05), ylim=(-0.02, 0.5), xlabel="Re z", ylabel="|Im z|")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return fig


def fig_staircase(runs: dict):
    fig, (ax,) = _axes()
    first = next(iter(runs.values()))
    ax.plot(first.time, np.asarray(first.reference) * 1e3, "k", lw=0.8, label="reference")
    for name, tr in runs.items():
        ax.plot(tr.time, np.asarray(tr["x"]) * 1e3, label=name)
    ax.set(xlabel="time [s]", ylabel="position [mm]")
    ax.legend(fontsize=8)
    return fig


# ---------------------------------------------------------------------- report
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="smoke mode: warm-started calibration, shorter runs, smaller sweeps")
    ap.add_argument("--out", default=str(ROOT / "reports" / "paper_000"),
                    help="output folder (default reports/paper_000)")
    args = ap.parse_args(argv)
    try:
        out = check_output_dir(args.out)          # a bad --out is refused before any work
    except InputError as exc:
        ap.error(str(exc))
    t_start = time.perf_counter()
    return rp.run_design(TITLE, out, PLANT, lambda done: _design(args, out, done, t_start))


def _design(args, out: Path, done: list, t_start: float) -> int:
    quick = args.quick
    with rp.step("calibrate (Fig. 6, Table I)"):
        nominal = Plant.from_toml(PLANT)
        setup = paper_setup(nominal)
        cal = calibrate(nominal, setup, quick)
        cal["deadband"] = estimate_deadband(cal["result"].plant_, setup, quick)
        rig = cal["deadband"]["plant"]
        rig.to_toml(out / "situm_rodless.calibrated.toml")
        meas = {"kv": step_velocity(rig), "kv_nom": step_velocity(nominal)}
        meas["w0"], meas["zeta"], meas["p_rest"] = spring_w0_zeta(rig)
        sections = [_calibration_section(cal, meas)]
    with rp.step("Table I experiment"):
        ex = experiment(rig, setup, PAPER["n"][0])
        _write_experiment(out / "table1_experiment.csv", ex, setup)
        sections.append(_experiment_section(ex, experiment(nominal, setup, PAPER["n"][0])))
    with rp.step("P loop steady-state error (Fig. 7)"):
        tr_cal, err = staircase(rig, setup, quick)
        meas["sse"] = err
        sections.append(_fig7_section(tr_cal, err))
    with rp.step("causes of the disagreements"):
        c = float(rig.params["valve.sonic_conductance"])
        d_hat, c_open = cal["deadband"]["deadband"], cal["deadband"]["c_open"]
        sizes = [1.0, 2.0] if quick else [0.5, 1.0, 2.0, 4.0]
        meas["equivalent"] = table1_equivalent(quick)
        sweeps = {"valve": sweep(rig, setup, [{"valve.sonic_conductance": c * f} for f in sizes],
                                 quick),
                  "deadband": sweep(rig, setup, [
                      {k: float(with_deadband(rig, d, c_open).params[k])
                       for k in ("valve.deadband", "valve.sonic_conductance")}
                      for d in ([0.0] if quick else [0.0, 0.5 * d_hat, 2.0 * d_hat])], quick)}
    with rp.step("write report"):
        results = _results(cal, meas, setup, ex)
        sections.insert(0, _results_section(results))
        sections.append(_disagreement_section(results, sweeps, meas, ex))
        done.extend(sections)
        return _finish(out, results, cal, ex, sweeps, meas, done, t_start, quick)


def _calibration_section(cal: dict, meas: dict) -> rp.Section:
    rows = []
    for conv, res in cal["fits"].items():
        lo, hi = res.ci95_[0]
        rows.append([conv, float(res.plant_.params["supply.pressure"]) * 1e-5,
                     float(res.values_[0]), f"[{lo:.3e}, {hi:.3e}]",
                     res.fit_after[0]["x"], res.fit_after[0]["v"],
                     table1_distance(cal["experiments"][conv]["model"]), conv == cal["convention"]])
    t, v_cal, kv_cal = meas["kv"]
    _, v_nom, kv_nom = meas["kv_nom"]
    import control
    kv, w0, zeta = PAPER["kv"][0], PAPER["w0"][0], PAPER["zeta"][0]
    t_rec = cal["record"].data["t"] - 0.05
    v_rec = np.interp(t, t_rec, cal["record"].data["v"])
    return rp.Section("Calibration from the paper's measurements", [
        rp.Paragraph(
            "Valve size from Fig. 6: the paper reads Kv = 0.7 m/(V s) off a 1 V open-loop step "
            "(Sec. III, eq. 5). As a record: the step with the velocity of the paper's own model "
            "(Table II's Kv, w0, zeta), which Fig. 6 shows on the measurement. The grey-box "
            "estimator fits the valve's sonic conductance to it (IPOPT, exact sensitivities, 95 % "
            "interval from the covariance; velocity known to 0.05 m/s, position to the 12-bit "
            "converter's step). Supply convention from Table I: Table II's 5e5 Pa is read as "
            "absolute and as gauge; each reading gets its own valve size, the paper's experiment "
            "runs on both rigs, and the reading whose re-identified ARX is closer to Table I "
            f"(RMS of the coefficient differences in combined std) is kept: {cal['convention']}. "
            "Deadband from Table I's closed-loop DC gain (below). Dead volumes (2 cm^3) and "
            "friction (Table II's k_f only) keep the plant file's values: the paper gives no "
            "number that fixes them, and static friction would act on the DC gain like the "
            "deadband (one number cannot separate the two)."),
        rp.Table(["supply", "p_s", "sonic conductance", "95 % interval", "fit x", "fit v",
                  "Table I distance", "kept"], rows,
                 units=["", "bar abs", "m^3/(s Pa)", "m^3/(s Pa)", "%", "%", "-", ""],
                 caption="Valve size fitted to Fig. 6 under both supply readings"),
        rp.Paragraph(f"1 V step: calibrated rig {kv_cal:.3f} m/s, plant file {kv_nom:.3f} m/s "
                     "(its valve was sized for a small-signal slope of 0.7 m/(V s); Fig. 6 is a "
                     "large-signal step, so the valve must be larger). Estimator verdict: "
                     + cal["result"].message),
        rp.Figure(fig_step(t, {"Fig. 6 record (paper's model, Kv = 0.7)": v_rec,
                               "calibrated rig": v_cal, "plant file": v_nom}),
                  "Piston velocity after a 1 V valve step (the workbench's Fig. 6)"),
        _deadband_block(cal["deadband"]),
    ])


def _deadband_block(db: dict) -> rp.Table:
    lo, hi = db["ci95"]
    dc0, sd = db["dc_target"], db["dc_std"]
    return rp.Table(
        ["", "Table I DC gain", "deadband (fraction of span)"],
        [["estimate", f"{dc0:.4f}", f"{db['deadband']:.4f}"],
         ["95 % bound (DC gain + 1.96 std)", f"{dc0 + 1.96 * sd:.4f}", f"{lo:.4f}"],
         ["95 % bound (DC gain - 1.96 std)", f"{dc0 - 1.96 * sd:.4f}", f"{hi:.4f}"]],
        caption=f"Deadband from Table I's closed-loop DC gain (derived; std {sd:.4f} from the "
                f"table's 4-decimal rounding), by bisection on the simulated experiment "
                f"({len(db['evaluations'])} runs); the valve's conductance follows so that the "
                "1 V opening, and Fig. 6, are unchanged")


def _write_experiment(path: Path, ex: dict, setup: dict) -> None:
    """``t, r, u, x`` at the paper's sampling, with the sample time as metadata."""
    lines = [f"# sample_time: {setup['T']:g}",
             "# source: designs/paper_000.py, P loop K0 = 7 on the calibrated rig model",
             "# units: t=s, r=m, u=V, x=m", "t,r,u,x"]
    lines += [f"{t:.4f},{r:.6f},{u:.5f},{x:.7f}"
              for t, r, u, x in zip(ex["t"], ex["r"], ex["u"], ex["x"])]
    atomic_write_text(path, "\n".join(lines) + "\n")


def _experiment_section(ex: dict, ex_nom: dict) -> rp.Section:
    m, mn = ex["model"], ex_nom["model"]
    cols = zip(["a1", "a2", "a3", "a4", "b1"], list(TABLE1_A) + [TABLE1_B],
               list(TABLE1_A_STD) + [TABLE1_B_STD], list(m.a) + [m.b[0]],
               list(m.std_a) + [m.std_b[0]], list(mn.a) + [mn.b[0]])
    rows = [[n] + [f"{v:.4f}" for v in (p, ps, o, os_, q)] for n, p, ps, o, os_, q in cols]
    poles = {"Table I (rig)": np.roots(np.r_[1.0, TABLE1_A]), "calibrated rig model": m.poles,
             "plant file": mn.poles}
    return rp.Section("Table I re-identified on the calibrated rig", [
        rp.Paragraph(
            f"The paper's experiment on the calibrated rig: P loop, kp = 10 V/m (K0 = 7 1/s with "
            f"Table II's gains), T = 10 ms, Table II's 12-bit converters, {len(ex['t'])} samples "
            "of an APRBS reference over the stroke (Sec. II: 0 .. 10 V = the whole stroke; "
            "5 % margins keep the piston off the end stops). Written to table1_experiment.csv "
            "(t, r, u, x). ARX [4 1 1] (orders 4 1 2 in MATLAB's convention) by least squares "
            f"on the first half, simulated on the second: fit {ex['validation'].fit:.1f} % "
            f"(plant file: {ex_nom['validation'].fit:.1f} %). The same as: workbench identify "
            "arx table1_experiment.csv --input r --output x --orders 4 1 2."),
        rp.Table(["coefficient", "Table I", "Table I std", "calibrated rig", "std", "plant file"],
                 rows, units=["", "-", "-", "-", "-", "-"],
                 caption="ARX [4 1 1] coefficients: Table I beside the re-identified ones "
                         "(4 decimals, as Table I prints them)"),
        rp.Figure(fig_experiment(ex), "The experiment on the calibrated rig (cf. Figs. 2, 3): "
                  "reference, position, Table I's model and the re-identified ARX, command"),
        rp.Figure(fig_poles(poles), "Closed-loop poles of the ARX models (upper half plane)",
                  width=0.7),
    ])


def _fig7_section(tr, err) -> rp.Section:
    return rp.Section("P loop steady-state error (Fig. 7)", [
        rp.Paragraph(
            "Sec. IV: the P loop 'is able to track the reference value, but with large "
            "steady-state error' (Fig. 7; no number is printed). The P loop on steps within "
            "Fig. 7's range: mean |r - x| over the last 0.5 s of each hold is "
            f"{np.mean(err) * 1e3:.2f} mm on the calibrated rig (worst {np.max(err) * 1e3:.2f} mm). "
            f"'Large' is read as more than {LARGE_ERROR * 1e3:g} mm, 1 % of Fig. 7's 400 mm "
            "axis: visible on the printed figure."),
        rp.Figure(fig_staircase({"calibrated rig": tr}), "P loop (K0 = 7) on steps, "
                  "calibrated rig (the workbench's Fig. 7)"),
    ])


def _results(cal, meas, setup, ex) -> list[dict]:
    kv_cal = meas["kv"][2]
    p_s = float(cal["result"].plant_.params["supply.pressure"])
    dist = {c: table1_distance(e["model"]) for c, e in cal["experiments"].items()}
    sse = float(np.mean(meas["sse"]))
    rows = [
        row("velocity after a 1 V valve step (Kv x 1 V)", PAPER["kv"][0], kv_cal, "m/s",
            PAPER["kv"][2], "calibrated rig, open-loop 1 V step from the centre at x = 20 mm, "
            "mean velocity 0.15 .. 0.30 s after it; agrees within 0.05 (the paper gives one "
            "digit: 'approximately 0.7')", abs(kv_cal - PAPER["kv"][0]) <= 0.05),
        row("loop gain K0 of the P loop", PAPER["k0"][0], setup["kp"] * kv_cal, "1/s",
            PAPER["k0"][2], "kp = 10 V/m times the calibrated rig's 1 V step velocity (the "
            "paper's Kv); agrees within 0.5 (Kv's 0.05 times kp)",
            abs(setup["kp"] * kv_cal - PAPER["k0"][0]) <= 0.5),
        row("supply pressure", PAPER["p_s"][0], p_s, "Pa", PAPER["p_s"][2],
            f"read as {cal['convention']} (absolute value shown): its re-identified ARX is "
            "closer to Table I (distance " + ", ".join(f"{c} {d:.2f}" for c, d in dist.items())
            + "); consistent with the paper's value under that reading", True),
        row("natural frequency w0", PAPER["w0"][0], meas["w0"], "rad/s", PAPER["w0"][2],
            "eigenvalues of the exact tangent model at rest at mid-stroke (calibrated rig); "
            "agrees within 10 % (a formula value in the paper, not a measurement)",
            abs(meas["w0"] / PAPER["w0"][0] - 1) <= 0.10),
        row("damping ratio zeta", PAPER["zeta"][0], meas["zeta"], "-", PAPER["zeta"][2],
            "same eigenvalues; agrees within 10 %",
            abs(meas["zeta"] / PAPER["zeta"][0] - 1) <= 0.10),
    ]
    rows += arx_rows(ex["model"]) + pole_rows(ex["model"])
    rows.append(row("P loop steady-state error (Fig. 7)", "large (qualitative)", sse, "m",
                    "Sec. IV on Fig. 7", "calibrated rig, P loop on steps; mean |r - x| over "
                    "the last 0.5 s of each hold; 'large' = above 4 mm (1 % of Fig. 7's "
                    "400 mm axis)", sse > LARGE_ERROR))
    return rows


def _cell(v) -> str:
    return f"{v:.4g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v)


def _results_section(results: list[dict]) -> rp.Section:
    n_ok = sum(r["agrees"] for r in results)
    return rp.Section("Paper 000's results beside the workbench", [
        rp.Table(["result", "paper", "workbench", "unit", "source in the paper",
                  "how obtained", "agrees?"],
                 [[r["result"], _cell(r["paper"]), _cell(r["workbench"]), r["unit"],
                   r["source"], r["how"], r["agrees"]] for r in results],
                 caption="Paper 000 row by row: paper value | workbench value | how obtained "
                         "| agrees?"),
        rp.Paragraph(f"{n_ok} of {len(results)} rows agree. Paper values are quoted from the "
                     "paper at the place given; rows marked 'derived' are computed from the "
                     "paper's numbers (physics.md), not printed in it. Each disagreement is "
                     "taken up below with its measured cause."),
    ])


def _sweep_table(rows: list[dict], caption: str) -> rp.Table:
    return rp.Table(
        ["change", "v after 1 V", "v max, full opening", "dominant |z|", "Table I distance",
         "P-loop error"],
        [[", ".join(f"{k} = {v:.3g}" for k, v in s["change"].items()), f"{s['v_step']:.3f}",
          f"{s['v_full']:.3f}", f"{abs(s['pole']):.4f}", f"{s['distance']:.2f}",
          f"{s['sse'] * 1e3:.2f}"] for s in rows],
        units=["", "m/s", "m/s", "-", "-", "mm"], caption=caption)


def _disagreement_section(results, sweeps, meas, ex) -> rp.Section:
    bad = [r["result"] for r in results if not r["agrees"]]
    blocks = [rp.Paragraph("Rows that do not agree: " + ("; ".join(bad) if bad else "none")
                           + ". What was measured about each cause:")]
    target = abs(dominant(np.roots(np.r_[1.0, TABLE1_A])))
    v_table1 = float(np.max(np.abs(np.diff(table1_response(ex["r"]))) / PAPER["T"][0]))
    vs = sweeps["valve"]
    blocks += [
        rp.Heading("Table I: the rig model's P loop is slower"),
        rp.Paragraph(
            f"The re-identified dominant pole has |z| = {abs(dominant(ex['model'].poles)):.3f} "
            f"against Table I's {target:.3f} (derived). Three measurements locate the cause. "
            f"(1) On the same reference, Table I's linear model moves at up to {v_table1:.2f} m/s; "
            f"the calibrated rig's valve fully open gives at most {vs[0]['v_full'] if len(vs) < 3 else vs[1]['v_full']:.2f} "
            "m/s, so the large APRBS steps saturate the valve and the rig follows them more "
            "slowly than any linear model of K0 = 7 would. (2) Scaling the valve (table below) "
            "does not bring the pole to Table I's: a larger valve breaks Fig. 6 (0.7 m/s at "
            "1 V) long before the loop is as fast. The paper's own PCT model (Kv = 0.7) misses "
            "the measurement too (Fig. 7) and Sec. IV names 'unmodeled effects like static "
            "friction, varying of the supply pressure, servovalve deadband, air leakage'. "
            "Deadband, friction and leakage slow a P loop rather than speed it up (measured for "
            "the deadband in Table 6); a higher supply speeds it (the gauge reading is both "
            "faster and closer to Table I, Section 2) but raises Fig. 6's velocity with it. With "
            "one valve characteristic, linear in the opening, Fig. 6 and Table I cannot both "
            "hold."),
        _sweep_table(vs, "Valve size scaled: Fig. 6 against Table I"),
        rp.Paragraph(_equivalent_text(meas["equivalent"])),
        rp.Heading("Fig. 7's steady-state error and the deadband"),
        rp.Paragraph(
            f"With the deadband estimated from Table I's DC gain the P loop stops "
            f"{np.mean(meas['sse']) * 1e3:.1f} mm off its reference on average (Section 4); "
            "without it the error is at the position quantisation (table below, first row): "
            "the 'large' error of Fig. 7 needs the deadband (or static friction, which the "
            "paper's numbers cannot tell from it). The table also shows what the deadband does "
            "to the Table I distance and to the dominant pole: little, so it is not the cause "
            "of the slower loop."),
        _sweep_table(sweeps["deadband"], "Deadband of the calibrated rig varied (Fig. 6 held)"),
    ]
    if any(r.startswith(("velocity after", "loop gain")) for r in bad):
        t, v, kv = meas["kv"]
        at = {tt: float(np.interp(tt, t, v)) for tt in (0.05, 0.15, 0.30)}
        blocks += [rp.Heading("Kv and K0: the rig's velocity does not level off"), rp.Paragraph(
            "The paper's model of Fig. 6 settles at 0.7 m/s within 0.15 s (its slower time "
            "constant is 47 ms). The calibrated rig jumps to "
            f"{at[0.05]:.2f} m/s within 50 ms and then creeps up ({at[0.15]:.2f} m/s at 0.15 s, "
            f"{at[0.30]:.2f} m/s at 0.30 s) while the exhaust chamber drains and the "
            "pressure level of the closed-centre valve settles: a slow mode the paper's "
            "third-order model does not have. The least-squares fit to the whole curve "
            f"splits the difference, so the plateau the paper reads as Kv comes out at "
            f"{kv:.2f} m/s on the 0.15 .. 0.30 s window (Figure 1).")]
    if any(r.startswith(("natural", "damping")) for r in bad):
        blocks += [rp.Heading("w0 and zeta"), rp.Paragraph(_spring_cause(meas))]
    return rp.Section("Disagreements and their measured causes", blocks)


def _equivalent_text(eq: dict) -> str:
    p = sorted(eq["poles"], key=lambda z: (-abs(z), -z.imag))
    d2, _, k2, p2 = eq["k0_table2"]
    dom2 = max(p2, key=abs)
    return (f"(3) What Table I asks of the paper's own linear model (ZOH at T = 10 ms, zeta = "
            f"1.1): with Table II's w0 = 32.97 rad/s no loop gain reaches Table I's dominant "
            f"poles (nearest: K0 = {k2:.1f} 1/s, {dom2.real:.3f} +- {abs(dom2.imag):.3f}j); they "
            f"need w0 = {eq['w0']:.1f} rad/s and K0 = {eq['k0']:.2f} 1/s (poles "
            + ", ".join(f"{z.real:.3f}" + (f" +- {abs(z.imag):.3f}j" if abs(z.imag) > 1e-6 else "")
                        for z in p if z.imag >= -1e-9)
            + f"; distance {eq['distance']:.3f}), an air spring "
            f"{eq['w0'] / PAPER['w0'][0]:.1f} x stiffer in frequency and a loop gain "
            f"{eq['k0'] / PAPER['k0'][0]:.1f} x the paper's K0 = 7. The rig that produced Table I "
            "was faster and stiffer than Table II says; one valve size cannot do both.")


def _spring_cause(meas) -> str:
    return (f"Table II's w0 = 32.97 rad/s and zeta = 1.1 are the paper's formulas with the "
            f"chamber pressure equal to the 5e5 Pa supply and no dead volume. The rig model "
            f"rests at the closed-centre valve's balance pressure, {meas['p_rest'] * 1e-5:.2f} "
            f"bar abs in chamber a, and its chambers include 2 cm^3 dead volumes: a softer air "
            f"spring, w0 = {meas['w0']:.2f} rad/s, and with Table II's k_f a damping ratio "
            f"zeta = {meas['zeta']:.3f} (zeta = k_f / (2 M w0)).")


def _finish(out, results, cal, ex, sweeps, meas, done, t_start, quick) -> int:
    n_ok = sum(r["agrees"] for r in results)
    status = rp.Status("PASS" if n_ok == len(results) else "FAIL",
                       f"{n_ok} of {len(results)} paper results agree; each disagreement is "
                       "explained with its measured cause")
    doc = rp.Report(TITLE, subtitle="Calibration from the paper's measurements, Table I "
                                    "re-identified on the calibrated rig",
                    status=status, sections=list(done),
                    provenance=rp.provenance(plant_file=PLANT, command_line=" ".join(sys.argv)))
    html, pdf = rp.write(doc, out)
    res, m = cal["result"], ex["model"]
    summary = {
        "paper": "000", "quick": bool(quick),
        "paper_results": results,
        "calibration": {"supply_convention": cal["convention"], "names": list(res.names),
                        "estimates": res.estimates, "ci95": res.ci95_.tolist(),
                        "deadband": cal["deadband"]["deadband"],
                        "deadband_ci95": list(cal["deadband"]["ci95"]),
                        "sonic_conductance_with_deadband": float(
                            cal["deadband"]["plant"].params["valve.sonic_conductance"]),
                        "status": res.status, "message": res.message,
                        "table1_distance": {c: table1_distance(e["model"])
                                            for c, e in cal["experiments"].items()}},
        "arx": {"a": m.a.tolist(), "b": m.b.tolist(), "std_a": m.std_a.tolist(),
                "std_b": m.std_b.tolist(), "poles": [[z.real, z.imag] for z in m.poles],
                "validation_fit": ex["validation"].fit},
        "step_velocity_1v": meas["kv"][2], "w0": meas["w0"], "zeta": meas["zeta"],
        "table1_equivalent": {"w0": meas["equivalent"]["w0"], "k0": meas["equivalent"]["k0"],
                              "distance": meas["equivalent"]["distance"]},
        "steady_state_errors": meas["sse"].tolist(),
        "sweeps": {k: [{**s, "pole": [s["pole"].real, s["pole"].imag]} for s in v]
                   for k, v in sweeps.items()},
        "run_time_s": time.perf_counter() - t_start,
    }
    plain = json_safe(json.loads(json.dumps(summary, default=rp.json_default)))
    atomic_write_text(out / "summary.json", json.dumps(plain, indent=1, allow_nan=False) + "\n")
    print(f"paper 000: {n_ok} of {len(results)} paper results agree")
    print(f"  report: {html}\n          {pdf}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
