"""Paper 000: dead volumes and dry friction from the paper's numbers (designs/paper_000.py).

* Dead volumes: Table II's w0 and zeta are eq. (4)'s values; the rig's air spring at
  mid stroke (exact tangent model at rest) must give the w0 band that zeta's printed
  digit allows, w0 = k_f / (2 M zeta). The spring fixes only the combination
  p_rest / (V0 + Vc/2) (rest pressure over chamber volume); with the rest pressure the
  calibrated valve sets, it bounds the dead volume V0 (both chambers). Fig. 6 cannot
  help: the grey-box estimator's interval for V0 fitted to it is reported as measured.
* Dry friction vs deadband: Table I's DC gain is one number; every Coulomb friction
  F_c on a grid gets the deadband that gives the DC gain (with its 95 % interval), the
  valve re-sized so that Fig. 6's 1 V step keeps its velocity. The family is the
  interval of the combination; the point nearest both measurements (Table I's
  coefficients and Fig. 6's curve, each as an RMS in standard deviations) goes into the
  plant file.
"""

from __future__ import annotations

import numpy as np

from workbench import Plant
from workbench.identify.grey_box import estimate
from paper_000_model import (PAPER, FIG6_V_STD, table1_distance, dominant, arx_rows,
    pole_rows)

#: Static over Coulomb friction and Stribeck velocity (m/s) of the friction family:
#: ASSUMED (the paper gives no friction but k_f); the static peak a bit above Coulomb
#: as for small rodless cylinders (the Karnopp model needs F_s > F_c to integrate).
STATIC_RATIO = 1.5
STRIBECK = 0.01

#: Coulomb friction grid (N): up to about half the force the P loop's valve can give
#: at mid stroke (0.5 * 5e5 Pa * A = 44 N).
FC_FULL = (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0)

#: Table II: M (kg), k_f (N s/m); zeta printed with one decimal (rounding +- 0.05).
ZETA_HALF_DIGIT = 0.05


def w0_band() -> tuple[float, float, float]:
    """w0 (rad/s) from zeta's printed digit: k_f / (2 M zeta) at zeta = 1.1 -+ 0.05
    (Table II's k_f = 65 N s/m, M = 0.91 kg): (low, centre, high)."""
    c = 65.0 / (2.0 * 0.91)
    z = PAPER["zeta"][0]
    return c / (z + ZETA_HALF_DIGIT), c / z, c / (z - ZETA_HALF_DIGIT)


def _with_v0(plant: Plant, v0: float) -> Plant:
    return plant.with_params(**{"cylinder.dead_volume_a": v0, "cylinder.dead_volume_b": v0})


def estimate_dead_volume(rig: Plant, spring, fig6_fit) -> dict:
    """Dead volume per chamber (m^3) from Table II's w0 band (:func:`w0_band`), by
    bisection on the rig's exact spring w0 at mid stroke (``spring(plant)`` ->
    (w0, zeta, p_rest)), which falls as V0 grows. Where w0 = 32.97 is out of reach for
    V0 >= 0 the estimate is the middle of the admissible interval [0, V0(w0 low)].
    ``fig6_fit(plant)`` gives the grey-box result for (C, V0) fitted to Fig. 6."""
    lo_w, mid_w, hi_w = w0_band()
    tiny = 1e-9
    w_at = {}

    def w0(v0):
        if v0 not in w_at:
            w_at[v0] = spring(_with_v0(rig, v0))[0]
        return w_at[v0]

    def solve(target):
        if w0(tiny) <= target:
            return 0.0
        lo, hi = tiny, 5e-5
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if w0(mid) > target else (lo, mid)
        return 0.5 * (lo + hi)

    v_hi, v_table = solve(lo_w), solve(PAPER["w0"][0])
    v_lo = solve(hi_w)
    reach = v_table > 0.0
    v_hat = v_table if reach else 0.5 * (v_lo + v_hi)
    _, zeta0, p_rest = spring(_with_v0(rig, tiny))
    vc2 = rig.area_a * float(rig.params["cylinder.stroke"]) / 2
    g = fig6_fit(_with_v0(rig, max(v_hat, 2e-6)))
    print(f"    dead volume {v_hat * 1e6:.3f} cm^3 [{v_lo * 1e6:.3f}, {v_hi * 1e6:.3f}] from "
          f"w0 in [{lo_w:.2f}, {hi_w:.2f}] (w0 at V0 = 0: {w0(tiny):.2f} rad/s); Fig. 6 "
          f"alone: {g.estimates['cylinder.dead_volume_a'] * 1e6:.2g} cm^3, 95 % "
          f"[{g.ci95_[1][0] * 1e6:.3g}, {g.ci95_[1][1] * 1e6:.3g}]")
    return {"dead_volume": v_hat, "ci": (v_lo, v_hi), "w0_band": (lo_w, mid_w, hi_w),
            "w0_at_zero": w0(tiny), "zeta_at_zero": zeta0, "reachable": reach,
            "p_rest": p_rest, "w0_hat": w0(max(v_hat, tiny)),
            "combination": (p_rest / (v_hi + vc2), p_rest / (v_lo + vc2)),
            "combination_at_table": (PAPER["w0"][0] ** 2 * 0.91
                                     / (2 * float(rig.params["gas.polytropic_index"])
                                        * rig.area_a ** 2)),
            "fig6": {"estimate": float(g.estimates["cylinder.dead_volume_a"]),
                     "ci95": [float(c) for c in g.ci95_[1]], "status": g.status},
            "plant": _with_v0(rig, max(v_hat, 1e-7))}


def fig6_dead_volume_fit(record, setup: dict):
    """Grey-box fit of the valve size and chamber a's dead volume (m^3) to the Fig. 6
    record: a, the small chamber at the step's start (x = 20 mm), is the one whose dead
    volume the step could show at all. Returns ``fit(plant) -> GreyBoxResult``."""
    def fit(plant: Plant):
        return estimate(plant, [record], ["valve.sonic_conductance", "cylinder.dead_volume_a"],
                        signals=("x", "v"), x0="from_recording",
                        bounds={"cylinder.dead_volume_a": (1e-8, 1e-4)},
                        noise={"x": setup["noise_x"], "v": FIG6_V_STD}, max_iter=40,
                        progress=False)
    return fit


def hold_fig6(plant: Plant, v_target: float, step_velocity) -> Plant:
    """``plant`` with the sonic conductance that gives the 1 V step velocity ``v_target``
    (m/s; ``step_velocity(plant)[2]``): secant on log C, to 0.1 % (Fig. 6's velocity is
    known to 0.05 m/s)."""
    c0 = float(plant.params["valve.sonic_conductance"])
    pts = []
    c = c0
    for _ in range(8):
        v = step_velocity(plant.with_params(**{"valve.sonic_conductance": c}))[2]
        pts.append((np.log(c), v))
        if abs(v / v_target - 1.0) < 1e-3:
            break
        if len(pts) == 1:
            c = c * v_target / max(v, 1e-3)
        else:
            (l0, f0), (l1, f1) = pts[-2], pts[-1]
            c = float(np.exp(l1 + (v_target - f1) * (l1 - l0) / (f1 - f0))) if f1 != f0 else c
    return plant.with_params(**{"valve.sonic_conductance": c})


def with_friction(plant: Plant, fc: float) -> Plant:
    """``plant`` with Coulomb friction ``fc`` (N; static STATIC_RATIO x, Stribeck
    STRIBECK m/s), or without dry friction for fc = 0."""
    if fc <= 0.0:
        return plant.with_params(**{"friction.coulomb": None, "friction.static": None,
                                    "friction.stribeck_velocity": None}) \
            if "friction.coulomb" in plant.param_names else plant
    return plant.with_params(**{"friction.coulomb": fc, "friction.static": STATIC_RATIO * fc,
                                "friction.stribeck_velocity": STRIBECK})


def friction_grid(quick: bool, committed: Plant | None) -> tuple[float, ...]:
    """Coulomb friction grid, N: FC_FULL; quick mode checks 0 N and the committed
    plant file's value (warm start, as the valve size; 20 N without one)."""
    if not quick:
        return FC_FULL
    fc = float(committed.params.get("friction.coulomb", 0.0)) if committed else 20.0
    return (0.0, fc) if fc > 0 else (0.0, 20.0)


def friction_family(rig0: Plant, setup: dict, quick: bool, v_target: float, tools: dict,
                    at_zero: dict, grid: tuple[float, ...]) -> list[dict]:
    """For each Coulomb friction F_c of the grid: the valve re-held on Fig. 6, the DC
    gain with friction alone (no deadband), the deadband that gives Table I's DC gain
    with its 95 % interval, and at that point the re-identified dominant pole, the
    distance to Table I, the distance to Fig. 6 (``tools["fig6_distance"]``), their
    root sum of squares ("score": both are RMS residuals in standard deviations) and
    the P loop's steady-state error. ``at_zero`` is the deadband estimate without
    friction (reused); ``tools`` holds paper_000's step_velocity, estimate_deadband,
    experiment, staircase and fig6_distance."""
    rows = []
    for fc in grid:
        if fc == 0.0:
            db, rig_f = at_zero, rig0
        else:
            rig_f = hold_fig6(with_friction(rig0, fc), v_target, tools["step_velocity"])
            db = tools["estimate_deadband"](rig_f, setup, quick)
        alone = tools["experiment"](rig_f, setup, PAPER["n"][0])["model"]
        ex = tools["experiment"](db["plant"], setup, PAPER["n"][0])
        sse = tools["staircase"](db["plant"], setup, quick)[1]
        rows.append({"coulomb": fc, "static": STATIC_RATIO * fc, "deadband": db["deadband"],
                     "ci95": list(db["ci95"]), "bracketed": db.get("bracketed", True),
                     "dc_friction_alone": float(alone.b.sum() / (1.0 + alone.a.sum())),
                     "sonic_conductance": float(db["plant"].params["valve.sonic_conductance"]),
                     "pole": dominant(ex["model"].poles),
                     "distance": table1_distance(ex["model"]), "sse": float(np.mean(sse)),
                     "fig6": tools["fig6_distance"](db["plant"]),
                     "table1_rows_agree": sum(r_["agrees"] for r_ in arx_rows(ex["model"])
                                              + pole_rows(ex["model"])[:2]),
                     "plant": db["plant"], "db": db})
        r = rows[-1]
        r["score"] = float(np.hypot(r["distance"], r["fig6"]))
        print(f"    F_c = {fc:g} N: friction alone DC {r['dc_friction_alone']:.4f}; deadband "
              f"{r['deadband']:.4f} [{r['ci95'][0]:.4f}, {r['ci95'][1]:.4f}], |z|dom "
              f"{abs(r['pole']):.4f}, Table I distance {r['distance']:.2f}, Fig. 6 distance "
              f"{r['fig6']:.2f}, "
              f"error {r['sse'] * 1e3:.1f} mm")
    return rows


def calibrated_toml(rig: Plant, cal: dict) -> str:
    """The calibrated plant file, each value with where it comes from (paper section,
    table or figure, and the estimator's result with its interval)."""
    p = rig.params
    dv, db, fam = cal["dead_volume"], cal["deadband"], cal["friction"]
    best = cal["friction_choice"]
    fit = cal["result"]
    c_lo, c_hi = fit.ci95_[0]
    fc_rows = ", ".join(f"{r['coulomb']:g} N -> {r['deadband']:.3f}" for r in fam)
    fric = ""
    if best["coulomb"] > 0:
        fric = (f"\n[friction]                        # ASSUMED form: static = {STATIC_RATIO:g} x "
                f"Coulomb, Stribeck {STRIBECK:g} m/s\n"
                f"coulomb = {best['coulomb']:.1f}                   # N: Table I's DC gain fixes "
                "only the friction-deadband family;\n"
                "                                  # this is its point nearest Table I's "
                "coefficients and Fig. 6's curve (paper_000.py)\n"
                f"static = {best['static']:.1f}                    # N: ASSUMED ratio\n"
                f"stribeck_velocity = {STRIBECK:g}          # m/s: ASSUMED\n")
    lo_w, _, hi_w = dv["w0_band"]
    return f'''# Paper 000 rig (Situm, Novakovic, Petric): 15 mm rodless cylinder SMC CDY1S15H-500,
# Festo MPYE-5-1/8 5/3 proportional valve, 10 ms P position loop -- CALIBRATED from
# the paper's own measurements by designs/paper_000.py (a full run writes this file as
# DIR/situm_rodless.calibrated.toml; its report says how, with the intervals). Values
# quoted from Table II are marked so; the rest are estimated from the paper's numbers.
# It keeps the effects its calibration found (spool overlap, dry friction): the valve's
# small-signal gain at the centre is zero, so the linear-model tools and designs use
# situm_rodless_nominal.toml (Table II's Kv = 0.7 as a small-signal slope, no effects).
name = "situm-rodless-15mm-calibrated"

[gas]
temperature = 293.15              # K, not in the paper (20 degC)
polytropic_index = {float(p["gas.polytropic_index"]):g}            # kappa, Table II
atmospheric_pressure = 101325.0   # Pa

[supply]
pressure = {float(p["supply.pressure"]):.1f}               # Pa abs: Table II's 5e5 Pa read as {cal["convention"].upper()}; the paper does not
                                  # say which: the reading whose re-identified ARX lies closer to Table I

[valve]
sonic_conductance = {float(p["valve.sonic_conductance"]):.4e}   # m^3/(s Pa): Fig. 6's 1 V step (Kv = 0.7, eq. 5): grey-box fit {fit.values_[0]:.3e}
                                  # [95 %: {c_lo:.3e}, {c_hi:.3e}] without overlap and friction, re-sized so that the
                                  # 1 V step keeps its velocity ({cal["v_target"]:.3f} m/s) with them
critical_pressure_ratio = {float(p["valve.critical_pressure_ratio"]):g}     # not in the paper (MPYE-like)
deadband = {float(p["valve.deadband"]):.4f}                 # fraction of the span: Table I's closed-loop DC gain {db["dc_target"]:.3f}, 95 % [{db["ci95"][0]:.3f}, {db["ci95"][1]:.3f}];
                                  # with Coulomb friction F_c the DC gain needs more overlap ({fc_rows})
command_center = 5.0              # V, 0..10 V command (Sec. II)
command_span = 5.0                # V
command_min = 0.0                 # V
command_max = 10.0                # V

[cylinder]
bore = 0.015                      # m, Table II
rod_diameter = 0.0                # rodless
stroke = 0.5                      # m, Table II
dead_volume_a = {float(p["cylinder.dead_volume_a"]):.3e}         # m^3: Table II's w0 band [{lo_w:.2f}, {hi_w:.2f}] rad/s (zeta's digit) at the rest pressure
dead_volume_b = {float(p["cylinder.dead_volume_b"]):.3e}         # {dv["p_rest"] * 1e-5:.2f} bar abs: [{dv["ci"][0]:.2e}, {dv["ci"][1]:.2e}] m^3 (Fig. 6 alone cannot tell)

[load]
mass = 0.91                       # kg, Table II
viscous_friction = 65.0           # N s/m, k_f, Table II
{fric}
[controller]
kind = "p"
sample_time = 0.01                # s, T, Table II
kp = 10.0                         # V/m = K_m K_AD K_DA K_R = 20 * 204.8 * 2.44e-3 * 1 (Table II): K0 = kp Kv = 7 1/s
position_resolution = 2.44140625e-4  # m = 1 / (K_AD K_m): 12-bit A/D (Table II)
command_resolution = 2.44e-3      # V = K_DA: 12-bit D/A (Table II)
'''


def slow_mode(plant: Plant, state: np.ndarray, u: float) -> tuple[float, np.ndarray]:
    """Slowest stable mode of the exact Jacobian df/dx (CasADi; dry friction in its
    smooth, differentiable form) at ``state`` with the command ``u`` (V) held: its time
    constant (s) and its eigenvector scaled by the state scales (x 0.5 m, v 1 m/s,
    pressures 6e5 Pa) and normalised to a largest entry of 1."""
    import casadi as ca
    xs = ca.SX.sym("x", len(state))
    smooth = plant.with_friction("smooth")
    jac = ca.Function("slow_mode_jacobian", [xs], [ca.jacobian(smooth.f(xs, u, smooth.p0), xs)])
    w, vec = np.linalg.eig(np.array(jac(np.asarray(state, float))))
    i = int(np.argmin(np.where(w.real < 0, -w.real, np.inf)))
    scaled = np.abs(vec[:, i].real) / np.array([0.5, 1.0, 6e5, 6e5][:len(state)])
    return float(-1.0 / w[i].real), scaled / np.max(scaled)
