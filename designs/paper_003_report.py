"""Report sections of designs/paper_003.py, and the labels and step sizes both share."""

from __future__ import annotations

from workbench import report as rp
from workbench.identify import plots
from workbench.identify import valve as vf

#: A tangent-model quantity is "poor" when it is off by more than this fraction: the
#: tank's time constant and gain then differ visibly on a step (paper Fig. 10).
TANGENT_TOL = 0.2
STEPS = (1.0, -1.0, 0.1, -0.1)
#: Steps to commands that are not among the blocked-port points (the check that the
#: pressure gain constraints do not just return their own measurements).
BETWEEN = (0.25, -0.25, 0.05, -0.05)
I_LAW, II_LAW = "I (n=5, m=10)", "II, two psi"
I_FLOW, II_FLOW = "I (n=5, m=10), flow points only", "II, two psi, flow points only"


#: Bands of |u - u_e| (V) over which the Cp and Gu errors along p_e(u) are summarised.
BANDS = ((0.0, 0.3), (0.3, 0.7), (0.7, 1.0), (1.0, 2.0))


def paper_count(fit) -> int:
    """Coefficients counted as paper 003 counts them: (n+1)(m+1) for I; for II one
    polynomial per function, Gamma with its forced constant: (n+1) + (m+1) + (l+1)."""
    if isinstance(fit, vf.PolynomialValveFit):
        return int(fit.coefficients.size)
    psi = len(fit.psi_in) * (1 if fit.psi_in == fit.psi_out else 2)
    return len(fit.phi) + psi + len(fit.gamma) + 1


#: Where the report measures the cause of a disagreeing row (by the row's result text).
EXPLAINED = {
    "largest flow error": "section 'Approximations and their accuracy' (the border of the "
                          "table: square-root nozzle law at supply and atmosphere; noise-free "
                          "fit measured)",
    "(15 coef.)": "section 'Approximations and their accuracy' (one psi cannot vanish at "
                  "supply and at atmosphere at once)",
    "tank error": "section 'Tank steps' (budget of each step: flow error over Cp, the border "
                  "near atmosphere, the noise-free fit)",
    "Cp, Gu": "section 'Pressure gain characteristic' (Cp, Gu errors by |u|: Gamma's single "
              "bend in the underlap)",
    "pressure gain:": "section 'Pressure gain characteristic' (where each law's largest "
                      "equilibrium error is)",
}


def _where_explained(rows) -> str:
    """One sentence per disagreeing row: where its measured cause is in the report."""
    parts = []
    for r in rows:
        if r["agrees"]:
            continue
        where = next((v for k, v in EXPLAINED.items() if k in r["result"]), None)
        parts.append(f"'{r['result']}': " + (where or "no measured explanation in this report"))
    return ("Disagreements and where their causes are measured: " + "; ".join(parts) + "."
            if parts else "Every row agrees.")


def _fmt(v):
    return v if isinstance(v, str) else (f"{v:.4g}" if isinstance(v, float) else str(v))


def _stage_section(stage, table, blocked):
    return rp.Section("The flow stage (assumptions where the paper is silent)", [
        rp.Paragraph("Paper 003 characterises one port of the 3/2 Servotronic globally (its "
                     "Fig. 3) but gives neither the supply pressure nor the conductances. The "
                     "workbench builds a flow stage of the same structure (Fig. 2: a supply "
                     "restriction A_S(u) and an exhaust restriction A_E(u), each an ISO 6358 "
                     "restriction with a rounded underlap) and calibrates the one number the "
                     "paper gives: the centred port rests at 5.1e5 Pa (section 5). Measurement "
                     "noise of 0.05 g/s is added to every point. The bench also reads the "
                     "blocked port's pressure at each command (q = 0 exactly; transducer noise "
                     "0.01 bar), the pressure gain characteristic of the paper's Fig. 3d, where "
                     "it lies more than 5 % of the range inside atmosphere and supply (beyond, "
                     "the port is saturated and p_e no longer depends on u). Both fits pass "
                     "through these points (q(p_e, u) = 0 imposed): near the centred spool the "
                     "restoring slope is small, so a flow reading's 0.05 g/s noise moves the "
                     "zero crossing by tenths of a bar, while the transducer fixes it to 0.01 bar."),
        rp.KeyValues([("flow stage", stage.summary()),
                      ("exhaust conductance (calibrated)", f"{stage.exhaust_conductance:.4g} m^3/(s Pa)"),
                      ("full inlet flow", f"{1e3 * stage.max_flow():.3g} g/s"),
                      ("table", f"{len(table)} points: 21 commands x 10 pressures (paper: 201)"),
                      ("blocked-port points", ", ".join(f"{u:+.2g} V: {p / 1e5:.3f} bar"
                                                        for u, p in blocked))]),
    ])


def _fit_section(table, fits, border):
    rows = [[lab, paper_count(f), f.quality.free, f.quality.r, f.quality.max_error_g_s,
             f.quality.rms_g_s] for lab, f in fits.items()]
    errors = {lab: f.flow(table.p, table.u) - table.q_m for lab, f in list(fits.items())[:3]}
    return rp.Section("Approximations and their accuracy", [
        rp.Table(["approximation", "coefficients (paper count)", "free", "R", "max error",
                  "RMS error"], rows, units=["", "-", "-", "-", "g/s", "g/s"],
                 caption="Accuracy on the measured table (paper: R = 0.99; I < 0.4 g/s, II < 0.5 g/s)"),
        rp.Paragraph("Reading paper 003's 15: its count (n+1) + (m+1) + (l+1) has one psi "
                     "polynomial, while its text and Fig. 5b give psi two branches, one for the "
                     "inlet (Gamma > 0) and one for the exhaust (Gamma < 0). Either the paper "
                     "counts the two-branch law once (it then has 21 coefficients by the same "
                     "count: row 'II, two psi'), or one psi serves both directions (15 "
                     "coefficients: row 'II, 15 coef.'). The table measures both: one psi "
                     f"reaches R = {fits['II, 15 coef. (one psi)'].quality.r:.3f} only, since "
                     "the inlet law vanishes at supply and the exhaust law at atmosphere; the "
                     "two-branch law meets the paper's R and error bound. The workbench takes "
                     "the first reading as the paper's approximation II."),
        rp.Paragraph(f"Approximation I's largest error, {border['max_error_g_s']:.2f} g/s, is at "
                     f"u = {border['at_u_V']:.3g} V, p = {border['at_p_Pa'] / 1e5:.2f} bar; "
                     "fitted to the same grid without noise it is "
                     f"{border['noise_free_max_error_g_s']:.2f} g/s at u = "
                     f"{border['noise_free_at_u_V']:.3g} V, p = "
                     f"{border['noise_free_at_p_Pa'] / 1e5:.2f} bar: a model error at the border "
                     "of the table (the open restriction's flow falls to zero at supply or "
                     "atmosphere as a square root, with an infinite slope no polynomial in p "
                     "follows), not noise. Paper 003 does not give its valve's flow scale; ours "
                     f"is {border['full_flow_g_s']:.2f} g/s full inlet flow (assumed "
                     f"conductance), so the error is {100 * border['max_error_g_s'] / border['full_flow_g_s']:.1f} "
                     "% of full flow, and the paper's 0.4 g/s bound is met or not by the "
                     "assumed size of the valve, not by the method."),
        rp.Figure(plots.valve_error_figure(table.u, table.p, errors),
                  "Flow errors over the table (paper Figs. 4b and 6b)"),
    ])


def _gain_section(gains, cmp_, bands):
    rows = [[lab, None if v is None else v / 1e5, bands[lab]["worst_u_V"],
             bands[lab]["worst_p_true_Pa"] / 1e5] for lab, v in cmp_.items()]
    brows = [[lab] + [100 * v if v is not None else None for pair in b["bands"] for v in pair]
             for lab, b in bands.items()]
    heads = [f"{c}, {a:g}-{b:g} V" for a, b in BANDS for c in ("Cp", "Gu")]
    ii, one = bands[II_LAW]["bands"], bands[I_LAW]["bands"]
    return rp.Section("Pressure gain characteristic", [
        rp.Table(["law", "max |p_e - p_e,true|", "at u", "true p_e there"], rows,
                 units=["", "bar", "V", "bar"],
                 caption="Equilibrium pressure error where the true equilibrium is inside the range"),
        rp.Figure(plots.pressure_gain_figure(list(gains.values()), u_range=(-1.5, 1.5)),
                  "q_m(p_e, u) = 0 with Cp and Gu along it (paper Figs. 3d, 4a, 6a, 8)"),
        rp.Table(["law", *heads], brows, units=["", *["%"] * len(heads)],
                 caption="Median relative error of Cp and Gu along the true p_e(u), by |u|"),
        rp.Paragraph("Where approximation II's tangent coefficients are off: its Gu error is "
                     f"largest for 0.3 <= |u| < 1 V (median {100 * ii[1][1]:.0f} % and "
                     f"{100 * ii[2][1]:.0f} %, against {100 * one[1][1]:.0f} % and "
                     f"{100 * one[2][1]:.0f} % for I), the underlap, where the real opening "
                     "bends from the centred leakage (both restrictions open d/2) to the "
                     "opening law. Gamma(s) = g1 s + g2 s|s| over s in [-1, 1] has one bend "
                     "for the whole command range and cannot bend within |s| < 0.1, and phi, "
                     "the same for every u, cannot let the leakage vanish as the spool opens; "
                     "approximation I, degree 10 in u, follows the bend. Paper 003's "
                     "'seems to be better' for II is a reading of its Fig. 8 on its own valve; "
                     "on this flow stage it is measured the other way. The same bend sets II's "
                     f"largest equilibrium error (at u = {bands[II_LAW]['worst_u_V']:+.2f} V, "
                     "between two blocked-port points)"
                     + (f", while I (n = m = 5) errs most at u = "
                        f"{bands['I (n=m=5)']['worst_u_V']:+.2f} V, p_e = "
                        f"{bands['I (n=m=5)']['worst_p_true_Pa'] / 1e5:.2f} bar, near atmosphere."
                        if "I (n=m=5)" in bands else ".")),
    ])


def _tank_section(tank, budget, clean):
    keep = ("true valve", I_LAW, II_LAW, I_FLOW)
    shown = vf.TankStepTests(volume=tank.volume, k=tank.k, temperature=tank.temperature,
                             u_e=tank.u_e, reference=tank.reference,
                             steps={k: v for k, v in tank.steps.items()
                                    if k[0] in keep and k[1] in STEPS})
    rows = [[b["law"], b["du_V"], b["max_error_percent"], b["max_error_of_p_e0_percent"],
             b["p_e_true_Pa"] / 1e5,
             b["flow_error_g_s"], b["cp_kg_s_Pa"] * 1e8, b["end_error_Pa"] / 1e5,
             None if b["gain_error_Pa"] is None else b["gain_error_Pa"] / 1e5,
             b["flow_error_over_cp_Pa"] / 1e5] for b in budget]
    return rp.Section("Tank steps and the downward-step errors", [
        rp.Paragraph("'max error' is |p - p_true| / p_true, the strict reading of paper 003's "
                     "'pressure error'; the paper does not say relative to what, so 'of 5.1 bar' "
                     "gives the same largest |p - p_true| relative to the starting equilibrium."),
        rp.Paragraph("The end error equals the error of the law's pressure gain characteristic "
                     "at the new command (columns 'end error' and 'p_e error'), as paper 003 "
                     "notes in section 5, and that is the flow error there divided by the "
                     "tank's restoring slope Cp (last column, first order). "
                     + _downward_text(budget, clean)),
        rp.Figure(plots.tank_steps_figure(shown), "Closed 1 l tank, k = 1.2, steps at u_e = 0 V "
                                                  "(paper Figs. 9 and 10); the 15-coefficient "
                                                  "and n = m = 5 fits are in the table only"),
        rp.Table(["law", "step", "max error", "of 5.1 bar", "true p_e", "flow error at p_e",
                  "true Cp at p_e", "end error", "p_e error", "flow error / Cp"], rows,
                 units=["", "V", "%", "%", "bar", "g/s", "1e-8 kg/(s Pa)", "bar", "bar", "bar"],
                 caption="Where the tank errors come from: the end error is the flow error at "
                         "the true end state divided by the restoring slope Cp there"),
    ])


def _seed_section(spread) -> "rp.Section":
    rows = [[r["seed"], r["small_percent"], r["between_percent"], r["large_percent"],
             r["tau_I_ratio"], r["tau_II_ratio"], r["max_error_I_g_s"], r["max_error_II_g_s"]]
            for r in spread]
    return rp.Section("Other noise draws", [
        rp.Table(["seed", "I, +-0.1 V", "I, between", "I, +-1 V", "tau I / true",
                  "tau II / true", "I max error", "II max error"], rows,
                 units=["-", "%", "%", "%", "-", "-", "g/s", "g/s"],
                 caption="The headline numbers on tables with other noise draws (seed 3 is the "
                         "report's)"),
        rp.Paragraph("The same grid, noise levels and blocked-port commands with other random "
                     "draws: whether a row agrees is a property of the method and the table's "
                     "design, not of one draw."),
    ])


def _downward_text(budget, clean: dict) -> str:
    """Why approximation I exceeds 2 % on a step, from the measured budget: on the flow
    points alone (the zero crossing), and through the blocked-port points (the border)."""
    parts = []
    for b in budget:
        if b["max_error_percent"] <= 2 or b["law"] not in (I_LAW, I_FLOW):
            continue
        if b["law"] == I_FLOW and b["worst_at_end"]:
            parts.append(
                f"Fitted to the flow points alone, after {b['du_V']:+g} V the error "
                f"({b['max_error_percent']:.1f} %) is the end error: Cp there is "
                f"{b['cp_kg_s_Pa']:.3g} kg/(s Pa), so 2 % of {b['p_e_true_Pa'] / 1e5:.2f} bar "
                f"needs a flow error below {b['needed_flow_error_g_s']:.3f} g/s at the zero "
                f"crossing; the fit's is {b['flow_error_g_s']:.3f} g/s, within the table's "
                "0.05 g/s measurement noise: flow readings alone cannot place the zero crossing "
                "to 2 %. Through the blocked-port points the same polynomial meets it.")
        elif b["law"] == I_LAW:
            parts.append(
                f"Through the blocked-port points, after {b['du_V']:+g} V the worst error "
                f"({b['max_error_percent']:.1f} %, "
                f"{b['max_error_of_p_e0_percent']:.1f} % of 5.1 bar) is "
                + (f"in the transient at {b['worst_t_s']:.1f} s and "
                   f"{b['worst_p_true_Pa'] / 1e5:.2f} bar" if not b["worst_at_end"] else
                   f"at the end, {b['p_e_true_Pa'] / 1e5:.2f} bar")
                + f", where the true flow is {b['flow_at_worst_g_s']:.3f} g/s and the fit's is "
                f"off by {b['flow_error_at_worst_g_s']:.3f} g/s: the polynomial's error near the "
                "border of the table (paper 003's 'border effect': the exhaust flow goes as "
                "sqrt(1 - ((p_atm/p - b)/(1 - b))^2), with an infinite slope as p -> p_atm, "
                "which no polynomial in p follows) acting on a small flow, divided by a small "
                f"pressure. Fitted without noise: {clean[b['du_V']]:.2f} % ("
                + ("a model error; the table's noise adds the rest)."
                   if clean[b["du_V"]] > 2 else
                   "within 2 %: the table's noise takes it over).") if b["du_V"] in clean else ")")
    return " ".join(parts) or "Approximation I stays within 2 % on every step."


def _tangent_section(rows, reasons):
    blocks = [rp.Table(["law", "p_e", "Cp", "Gu", "tau", "G", "against the true valve"], rows,
                       units=["", "bar", "1e-8 kg/(s Pa)", "g/(s V)", "s", "bar/V", ""],
                       caption="Tangent model p*/u* = G/(1 + tau s) at u_e = 0 V, 1 l tank (eq. 7-8)")]
    blocks += [rp.Paragraph(text) for text in reasons.values()] or [
        rp.Paragraph("Every approximation's tangent model is within 20 % of the true valve's.")]
    return rp.Section("Tangent models", blocks)
