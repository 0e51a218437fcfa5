"""P and PD position loops for the 15 mm rodless rig of paper 000, end to end.

Reproduces paper 000 (Situm et al.) on the workbench:

1. the linear model from the paper's formulas beside the exact linearisation of the
   nonlinear rig model at mid-stroke;
2. the gain limits side by side: continuous Hurwitz (72.5 1/s), PCT (62.3), exact
   sampled-data (~54) and with one sample of computation delay (~36), K0 = 7;
3. a stability map (loop gain x moving mass) of the exact sampled-data loop with the
   classical boundaries over it;
4. the paper's P loop (kp = 10 V/m, K0 = 7) and a PD loop with its zero on the slower
   process pole, both validated in closed loop on the full nonlinear plant;
5. the closed-loop ARX model of Table I beside the PCT model (poles and step responses).

Writes ``reports/situm_p_pd/report.html`` and ``report.pdf`` (same content), plus
``summary.json``, ``map.csv`` and the validation trajectories as CSV. A design that
fails to run still leaves a report saying at which step and why.

Usage: python designs/situm_p_pd.py [--quick] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from workbench.output import write_json
from workbench import Plant, controllers, linearize, plots
from workbench import report as rp
from workbench import stability, validate
from workbench.params import atomic_write_text
from workbench.stability import maps

HERE = Path(__file__).resolve().parent
PLANT = HERE / "plants" / "situm_rodless_nominal.toml"
ROOT = HERE.parent
TITLE = "P and PD position loops, 15 mm rodless rig (paper 000)"

#: Table II of paper 000 (physics.md).
TABLE_II = {"w0": 32.97, "zeta": 1.1, "T": 0.01, "K0": 7.0, "Kv": 0.7}
#: Limits quoted by paper 000 / physics.md, 1/s ("about" for the last two).
PAPER_LIMITS = {"continuous": 72.5, "pct": 62.3, "sampled": 54.0, "sampled_delay": 36.0}
#: Table I: closed-loop ARX [4 1 1] identified on the rig (signs restored, physics.md).
ARX_A = [1.0, -2.4478, 2.1352, -0.7742, 0.0995]
ARX_B = [0.0, 0.0, 0.0125]
#: PD gain search: start value, then kp times PD_BACKOFF per failed validation.
PD_TRIES = 6
PD_BACKOFF = 0.8
#: Design position (mid-stroke), m.
X_DESIGN = 0.25


def pd_design(w0: float, zeta: float, kv: float, T: float) -> tuple[float, float, float]:
    """PD of paper 000: zero on the slower real process pole, gain for a damping of
    1/sqrt(2) of what remains, K0/(s (tau_f s + 1)) with the sampler's T/2 lumped into
    tau_f (PCT). Returns (kp V/m, kd V s/m, K0 1/s)."""
    root = np.sqrt(zeta ** 2 - 1.0)
    tau_fast = 1.0 / (w0 * (zeta + root))
    k0 = 1.0 / (2.0 * (tau_fast + T / 2.0))
    kp = k0 / kv
    pd = controllers.pd_zero_on_slow_pole(w0, zeta, kp, T)
    return kp, pd.kd, k0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="smoke mode: coarse map, short validation profile")
    ap.add_argument("--out", default=str(ROOT / "reports" / "situm_p_pd"),
                    help="output folder (default reports/situm_p_pd)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    t_start = time.perf_counter()
    return rp.run_design(TITLE, out, PLANT, lambda done: _design(args, out, done, t_start))




def _design(args, out: Path, done: list, t_start: float) -> int:
    quick = args.quick
    with rp.step("load plant"):
        plant = Plant.from_toml(PLANT)
        summ = plant.to_dict()
        prm = plant.params
        done.append(rp.Section("Plant", [
            rp.Paragraph("Rodless cylinder with a 5/3 proportional valve and a 10 ms position "
                         "loop (paper 000, Table II). Valve size and dead volumes are not in the "
                         "paper; they are estimates (see the plant file)."),
            rp.KeyValues([
                ("plant file", str(PLANT.relative_to(ROOT))),
                ("bore / stroke", f"{prm['cylinder.bore'] * 1e3:g} mm / {prm['cylinder.stroke'] * 1e3:g} mm"),
                ("piston area", summ["area_a_m2"] * 1e4, "cm^2"),
                ("moving mass M", prm["load.mass"], "kg"),
                ("viscous friction k_f", prm["load.viscous_friction"], "N s/m"),
                ("supply pressure", prm["supply.pressure"] * 1e-5, "bar abs"),
                ("polytropic index", prm["gas.polytropic_index"], "-"),
                ("valve flow, one edge fully open", summ["valve_flow_full_opening_l_min_anr"], "l/min ANR"),
                ("effects", ", ".join(summ["effects"]) or "none (nominal model)"),
                ("controller in the file", f"{prm['controller.kind']}, kp = {prm['controller.kp']:g} V/m, "
                                           f"T = {prm['controller.sample_time'] * 1e3:g} ms"),
            ]),
        ]))

    with rp.step("exact linearisation"):
        op = linearize.operating_point(plant, X_DESIGN)
        lin = linearize.tangent(plant, op)
        red = linearize.reduced_position_model(lin)
        A = prm["cylinder.bore"] ** 2 * np.pi / 4
        w0_f = linearize.paper000_w0(A, prm["load.mass"], prm["supply.pressure"],
                                     prm["cylinder.stroke"], prm["gas.polytropic_index"])
        z_f = linearize.paper000_zeta(A, prm["load.mass"], prm["supply.pressure"],
                                      prm["cylinder.stroke"], prm["load.viscous_friction"],
                                      prm["gas.polytropic_index"])
        ev = lin.eigenvalues
        done.append(rp.Section("Linear model", [
            rp.Paragraph("x(s)/u(s) = Kv / (s (s^2/w0^2 + 2 zeta s/w0 + 1)). Left: paper 000's "
                         "formulas with Table II (chamber pressure = supply pressure, no dead "
                         "volume). Right: the exact tangent model of the nonlinear rig model at "
                         f"x = {X_DESIGN * 1e3:g} mm from CasADi, with Kv, w0, zeta fitted to its "
                         "frequency response (exact here: the minimal model is third order)."),
            rp.Table(["quantity", "unit", "paper 000 formula", "Table II", "exact linearisation"],
                     [["w0", "rad/s", w0_f, TABLE_II["w0"], red.w0],
                      ["zeta", "-", z_f, TABLE_II["zeta"], red.zeta],
                      ["Kv", "m/(V s)", None, TABLE_II["Kv"], red.kv],
                      ["T0 = 1/w0", "ms", 1e3 / w0_f, 30.0, 1e3 / red.w0],
                      ["chamber pressure at rest", "bar abs", prm["supply.pressure"] * 1e-5, 5.0,
                       op.p_a * 1e-5]],
                     caption="Linear position model: formulas vs exact linearisation"),
            rp.Paragraph(
                f"They differ because the model rests at the valve's centre balance pressure "
                f"({op.p_a * 1e-5:.2f} bar, where the closed-centre valve holds both chambers) rather "
                f"than at the 5 bar supply the formula assumes, and because the dead volumes add "
                f"to the chamber volume: a softer air spring, so a lower w0 and, with the same "
                f"k_f, a higher zeta. Tangent-model eigenvalues (1/s): "
                + ", ".join(f"{e.real:.2f}" + (f"{e.imag:+.2f}j" if abs(e.imag) > 1e-9 else "")
                            for e in ev)
                + ". One zero eigenvalue is the position integrator; the other is the pressure "
                  "level of a closed-centre valve without leakage, which the command cannot move "
                  "and the position does not see."),
        ]))

    with rp.step("gain limits"):
        T = prm["controller.sample_time"]
        kp_p = prm["controller.kp"]
        lim_paper = stability.gain_limits(TABLE_II["w0"], TABLE_II["zeta"], TABLE_II["T"],
                                          k0=TABLE_II["K0"])
        lim_rig = stability.limits_from_plant(plant, X_DESIGN)
        names = [("continuous", "continuous Hurwitz 2 zeta w0"),
                 ("pct", "PCT 2 zeta / Ts"),
                 ("sampled", "exact sampled-data (ZOH)"),
                 ("sampled_delay", "sampled-data + 1 sample delay")]
        rows = []
        for key, label in names:
            lp, lr = getattr(lim_paper, key), getattr(lim_rig, key)
            rows.append([label, PAPER_LIMITS[key], lp, lr, lr / red.kv, lim_rig.k0 / lr])
        margins = [["gain margin at K0", "-", lim_paper.gain_margin, lim_rig.gain_margin],
                   ["phase margin at K0", "deg", lim_paper.phase_margin_deg,
                    lim_rig.phase_margin_deg]]     # own table: not 1/s like the limits
        checks = [abs(lim_paper.continuous - 72.5) < 0.1, abs(lim_paper.pct - 62.3) < 0.1,
                  abs(lim_paper.sampled - 54) < 1.0, abs(lim_paper.sampled_delay - 36) < 1.0]
        done.append(rp.Section("Gain limits", [
            rp.Paragraph(f"Loop gain K0 = kp Kv: paper K0 = {TABLE_II['K0']:g} 1/s; rig model "
                         f"K0 = {kp_p:g} V/m x {red.kv:.4f} m/(V s) = {lim_rig.k0:.3f} 1/s. "
                         f"PCT lumps the sampler and hold into a lag T/2: Ts = T/2 + 1/w0 = "
                         f"{lim_paper.pct_time_constant * 1e3:.1f} ms (Table II). The exact limits "
                         "come from the ZOH-discretised loop (where a closed-loop pole reaches "
                         "the unit circle)."),
            rp.Table(["limit", "paper 000", "workbench, Table II model", "workbench, rig model",
                      "as kp on the rig", "K0 / limit"],
                     rows, units=["", "1/s", "1/s", "1/s", "V/m", "-"],
                     caption="Gain limits of the sampled P position loop, side by side"),
            rp.Table(["margin", "unit", "workbench, Table II model", "workbench, rig model"],
                     margins, caption="Stability margins of the sampled P loop at its K0"),
            rp.Status("PASS" if all(checks) else "FAIL",
                      "Table II limits reproduced (72.5, 62.3, ~54, ~36 1/s)" if all(checks)
                      else "Table II limits NOT reproduced"),
        ]))

    with rp.step("controllers"):
        kp_pd0, kd_pd0, k0_pd0 = pd_design(red.w0, red.zeta, red.kv, T)
        u_c, u_lo, u_hi = (prm["valve.command_center"], prm["valve.command_min"],
                           prm["valve.command_max"])
        p_ctrl = controllers.PID(kp=kp_p, sample_time=T, u_center=u_c, u_min=u_lo, u_max=u_hi)
        tau_slow = controllers.slow_time_constant(red.w0, red.zeta)

    with rp.step("closed-loop validation"):
        spec = validate.Specification()
        ref = validate.validation_profile(plant, hold=1.5 if quick else 2.5)
        v_p = validate.validate(plant, p_ctrl, spec=spec, reference=ref, label="P (paper 000)",
                                progress=None)
        # PD gain: start from the damping-based value; while the nonlinear validation
        # fails, lower kp by 20 % (kd follows: the zero stays on the slower pole)
        tries = []
        for i in range(PD_TRIES):
            kp_i = kp_pd0 * PD_BACKOFF ** i
            ctrl_i = controllers.PID(kp=kp_i, kd=kp_i * tau_slow, sample_time=T, u_center=u_c,
                                     u_min=u_lo, u_max=u_hi)
            v_i = validate.validate(plant, ctrl_i, spec=spec, reference=ref, label="PD",
                                    progress=None)
            tries.append((ctrl_i, v_i))
            print(f"    PD kp = {kp_i:.2f} V/m: {'pass' if v_i.passed else 'fail: ' + ', '.join(c.name for c in v_i.failed)}")
            if v_i.passed:
                break
        pd_ctrl, v_pd = tries[-1]
        kp_pd, kd_pd, k0_pd = pd_ctrl.kp, pd_ctrl.kd, pd_ctrl.kp * red.kv
        mass_axis = maps.Axis("load.mass", [prm["load.mass"], prm["load.mass"] * 1.001])
        rho_p = maps.stability_map(plant, maps.Axis("kp", [kp_p, kp_p * 1.001]), mass_axis,
                                   position=X_DESIGN, controller=p_ctrl, workers=1,
                                   progress=False).rho[0, 0]
        rho_pd = maps.stability_map(plant, maps.Axis("kp", [kp_pd, kp_pd * 1.001]), mass_axis,
                                    position=X_DESIGN, controller=pd_ctrl, workers=1,
                                    progress=False).rho[0, 0]
        tf_pd = pd_ctrl.to_control()
        tf_lines = [ln.strip() for ln in str(tf_pd).strip().splitlines() if ln.strip()]
        done.append(rp.Section("Controllers", [
            rp.Paragraph(f"P: the paper's gain, kp = {kp_p:g} V/m. PD: its zero cancels the "
                         f"slower real process pole, tau_slow = {tau_slow * 1e3:.1f} ms "
                         f"(zeta = {red.zeta:.3f} > 1 gives two real poles), so kd = kp tau_slow. "
                         f"What remains is K0/(s (tau_f s + 1)); its gain starts at a damping of "
                         f"0.71 with the sampler's T/2 lumped into tau_f (K0 = {k0_pd0:.2f} 1/s) "
                         f"and is lowered by {100 * (1 - PD_BACKOFF):.0f} % while the closed-loop "
                         "validation on the nonlinear plant fails (Table below). Both controllers "
                         "run in the sampled-data simulation and export to python-control "
                         f"(PD, e -> u: ({tf_lines[-3]}) / ({tf_lines[-1]}), dt = {T:g} s)."),
            rp.Table(["controller", "kp", "kd", "K0 = kp Kv", "|z|max, exact sampled loop",
                      "validation"],
                     [["P (paper 000)", kp_p, 0.0, kp_p * red.kv, rho_p, v_p.passed]]
                     + [[f"PD try {i + 1}", c.kp, c.kd, c.kp * red.kv,
                         None if (c, v) != tries[-1] else rho_pd, v.passed]
                        for i, (c, v) in enumerate(tries)],
                     units=["", "V/m", "V s/m", "1/s", "-", ""],
                     caption="The designs at mid-stroke; the last PD try is the design"),
        ]))
        v_p.trajectory.to_csv(out / "validation_p.csv")
        v_pd.trajectory.to_csv(out / "validation_pd.csv")
        rows = []
        for (item, val, lim, unit, verdict), (_, val2, _, _, verdict2) in zip(v_p.table(), v_pd.table()):
            rows.append([item, lim, unit, val, verdict == "pass", val2, verdict2 == "pass"])
        done.append(rp.Section("Closed-loop validation on the nonlinear plant", [
            rp.Paragraph("Both loops run on the full nonlinear model of the rig (sampled at T, "
                         "command clipped to the valve range) for steps both ways, large and small, "
                         "ramps and holds. Each item is judged on its worst segment. "
                         f"Specification: overshoot <= {spec.max_overshoot:g} %, settling to "
                         f"{spec.settling_band * 100:g} % (at least {spec.band_floor * 1e3:g} mm) "
                         f"within {spec.max_settling_time:g} s, steady-state error <= "
                         f"{spec.max_steady_state_error * 1e3:g} mm, ramp error <= "
                         f"{spec.max_ramp_error * 1e3:g} mm, command saturated <= "
                         f"{spec.max_saturation * 100:g} % of the time, chamber pressures within "
                         "atmosphere and supply."),
            rp.Table(["item", "limit", "unit", "P", "P verdict", "PD", "PD verdict"], rows,
                     caption="Validation checks: P (paper 000) and PD"),
            rp.Figure(plots.compare_figure([v_p, v_pd], ["P (paper 000)", "PD"],
                                           title="P vs PD on the nonlinear rig model"),
                      "Reference and position, command and chamber pressures: P and PD"),
            rp.Figure(plots.validation_figure(v_pd, title="PD loop on the nonlinear rig model"),
                      "PD loop: reference and position with the settling band, command with "
                      "its limits, chamber pressures with supply and atmosphere"),
        ]))

    with rp.step("stability map"):
        n = 40 if quick else 100
        smap = maps.stability_map(plant, maps.Axis.linspace("k0", 1.0, 90.0, n),
                                  maps.Axis.linspace("load.mass", 0.3, 5.0, n),
                                  position=X_DESIGN, controller=p_ctrl, progress=None)
        smap.to_csv(out / "map.csv")
        mass_row = int(np.argmin(np.abs(smap.y.values - prm["load.mass"])))
        cross = smap.x.values[np.argmax(smap.rho[mass_row] >= 1.0)] \
            if np.any(smap.rho[mass_row] >= 1.0) else float("nan")
        n_pd = 30 if quick else 80
        smap_pd = maps.stability_map(plant, maps.Axis.linspace("kp", 5.0, 150.0, n_pd),
                                     maps.Axis.linspace("kd", 0.0, 6.0, n_pd),
                                     position=X_DESIGN, controller=pd_ctrl, progress=None)
        fig_pd = plots.stability_map_figure(smap_pd, title="PD loop: stability over kp and kd "
                                            f"(M = {prm['load.mass']:g} kg, T = {T * 1e3:g} ms)")
        fig_pd.axes[0].plot([kp_pd], [kd_pd], "k*", ms=14, label="PD design")
        fig_pd.axes[0].plot([kp_p], [0.0], "ko", ms=8, label="P (paper)")
        fig_pd.axes[0].legend(loc="upper left", fontsize=8)
        done.append(rp.Section("Stability maps", [
            rp.Paragraph(f"Each point is the exact sampled-data loop: equilibrium, exact tangent "
                         f"model, ZOH at T, controller, eigenvalues ({smap.rho.size} points in "
                         f"{smap.elapsed_s:.1f} s). Colour: largest closed-loop pole magnitude; "
                         f"black: |z| = 1. Dashed and dotted: the PCT and continuous limits from "
                         f"w0, zeta of each point. At M = {smap.y.values[mass_row]:.2f} kg the map "
                         f"crosses |z| = 1 at K0 = {cross:.1f} 1/s (grid step "
                         f"{smap.x.values[1] - smap.x.values[0]:.2f}); the exact limit of the "
                         f"reduced model is {lim_rig.sampled:.2f} 1/s. The classical limits are "
                         "optimistic everywhere: more so for heavy loads."),
            rp.Figure(plots.stability_map_figure(smap, title="P loop: stability over loop gain "
                                                 f"and moving mass (T = {T * 1e3:g} ms)"),
                      "Stability map of the P loop at mid-stroke: loop gain K0 against moving mass"),
            rp.Figure(fig_pd, "Stability map of the PD loop at mid-stroke over kp and kd"),
            *[rp.Paragraph("Note: " + nt) for nt in smap.notes],
        ]))

    with rp.step("ARX (Table I) vs PCT"):
        arx_poles = np.roots(ARX_A)
        pct_poles = stability.pct_closed_loop_poles(TABLE_II["w0"], TABLE_II["zeta"], T, TABLE_II["K0"])
        zoh_poles = stability.closed_loop_poles(TABLE_II["w0"], TABLE_II["zeta"], T, TABLE_II["K0"])
        rig_poles = stability.closed_loop_poles(red.w0, red.zeta, T, lim_rig.k0)

        def fmt_poles(p):
            p = sorted(p, key=lambda z: (-abs(z), z.imag))
            return ", ".join(f"{z.real:.3f}" + (f" {'+' if z.imag >= 0 else '-'} {abs(z.imag):.3f}j"
                                                if abs(z.imag) > 1e-6 else "") for z in p)
        rows = [["ARX [4 1 1], Table I (rig)", fmt_poles(arx_poles), max(abs(arx_poles)),
                 sum(ARX_B) / sum(ARX_A)],
                ["PCT model, K0 = 7 (z = exp(sT))", fmt_poles(pct_poles), max(abs(pct_poles)), 1.0],
                ["ZOH model, Table II, K0 = 7", fmt_poles(zoh_poles), max(abs(zoh_poles)), 1.0],
                [f"ZOH model, rig linearisation, K0 = {lim_rig.k0:.2f}", fmt_poles(rig_poles),
                 max(abs(rig_poles)), 1.0]]
        n_steps = 150
        k = np.arange(n_steps)
        y_arx = _arx_step(ARX_A, ARX_B, n_steps)
        sims = {"ARX, Table I (rig)": y_arx}
        import control
        w0, z, K0 = TABLE_II["w0"], TABLE_II["zeta"], TABLE_II["K0"]
        Ts = T / 2 + 1 / w0
        pct = control.tf([K0], [Ts ** 2, 2 * z * Ts, 1.0, K0])
        sims["PCT model"] = control.step_response(pct, k * T).outputs
        g = control.c2d(control.tf([K0], [1 / w0 ** 2, 2 * z / w0, 1, 0]), T, "zoh")
        sims["ZOH model, Table II"] = control.step_response(control.feedback(g, 1), k * T).outputs
        fig = plots.pole_step_figure({"ARX, Table I (rig)": arx_poles, "PCT model": pct_poles,
                                      "ZOH model, Table II": zoh_poles}, k * T, sims)
        done.append(rp.Section("Table I ARX model vs PCT model", [
            rp.Paragraph("Table I is a closed-loop ARX model identified on the rig with the P "
                         "controller (K0 = 7). Its dominant poles are faster than those of the PCT "
                         "and ZOH models: the rig responds about twice as fast as the linear model "
                         "predicts. Paper 000 blames static friction, supply pressure variation, "
                         "valve deadband and leakage, none of which the linear model has. "
                         "designs/paper_000.py calibrates the rig model from the paper's "
                         "measurements and re-identifies Table I on it."),
            rp.Table(["model", "closed-loop poles", "|z|max", "DC gain"], rows, units=["", "", "-", "-"],
                     caption="Closed-loop poles at T = 10 ms"),
            rp.Figure(fig, "Closed-loop poles in the z-plane and unit-step responses of the ARX, "
                           "PCT and ZOH models"),
        ]))

    # ---- verdict and report
    with rp.step("write report"):
        design_ok = v_pd.passed and all(checks) and rho_pd < 1
        failed = [c.name for c in v_pd.failed]
        msg = (f"PD design meets its specification on the nonlinear plant (K0 = {k0_pd:.1f} 1/s, "
               f"{k0_pd / lim_rig.k0:.1f}x the paper's P loop); paper 000 limits reproduced"
               if design_ok else
               "PD design does not meet: " + (", ".join(failed) or "see the limits") )
        p_note = ("The paper's P loop fails: " + ", ".join(c.name for c in v_p.failed)
                  if not v_p.passed else "The paper's P loop passes as well.")
        summary_section = rp.Section("Summary", [
            rp.KeyValues([
                ("design verdict", "PASS" if design_ok else "FAIL"),
                ("PD gains", f"kp = {kp_pd:.2f} V/m, kd = {kd_pd:.3f} V s/m"),
                ("P gain (paper)", f"kp = {kp_p:g} V/m, K0 = {lim_rig.k0:.2f} 1/s"),
                ("limits, Table II model", f"{lim_paper.continuous:.1f} / {lim_paper.pct:.1f} / "
                                           f"{lim_paper.sampled:.1f} / {lim_paper.sampled_delay:.1f} 1/s "
                                           "(continuous / PCT / sampled / + delay)"),
                ("P loop", p_note),
                ("run time", f"{time.perf_counter() - t_start:.1f} s"
                             + (" (quick mode)" if quick else "")),
            ]),
        ])
        doc = rp.Report(TITLE, subtitle="Classical design chain: linear model, gain limits, "
                                        "stability maps, nonlinear validation",
                        status=rp.Status("PASS" if design_ok else "FAIL", msg),
                        sections=[summary_section, *done],
                        provenance=rp.provenance(plant_file=PLANT, command_line=" ".join(sys.argv)))
        html, pdf = rp.write(doc, out)
        summary = {"design_passed": bool(design_ok), "k0_p": lim_rig.k0, "kp_pd": kp_pd,
                   "kd_pd": kd_pd, "k0_pd": k0_pd,
                   "limits_table_ii": lim_paper.to_dict(), "limits_rig": lim_rig.to_dict(),
                   "rho_p": float(rho_p), "rho_pd": float(rho_pd),
                   "map_crossing_k0": float(cross),
                   "validation_p": v_p.to_dict(), "validation_pd": v_pd.to_dict(),
                   "arx_poles": [[float(z.real), float(z.imag)] for z in arx_poles],
                   "pct_poles": [[float(z.real), float(z.imag)] for z in pct_poles]}
        write_json(out / "summary.json", summary, indent=1, default=rp.json_default)
    print(f"design {'PASS' if design_ok else 'FAIL'}: {msg}")
    print(f"  report: {html}\n          {pdf}")
    return 0 if design_ok else 1


def _arx_step(a, b, n):
    """Unit-step response of B(q)/A(q) (coefficients in powers of q^-1)."""
    y = np.zeros(n)
    for k in range(n):
        acc = sum(b[j] for j in range(len(b)) if k - j >= 0)
        acc -= sum(a[j] * y[k - j] for j in range(1, len(a)) if k - j >= 0)
        y[k] = acc
    return y


if __name__ == "__main__":
    sys.exit(main())
