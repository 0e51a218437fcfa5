"""Design scripts run end to end in smoke mode (coarse map, short profile).

Each design runs once (module fixtures) and its outcome is asserted: its verdict and
its headline numbers against paper 000 / physics.md or a hand computation here.
"""

from __future__ import annotations

import json
import math
import runpy
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import optimize, signal

from conftest import (RHO_ANR_KG_M3, close_value as _close, check_figures,
                      check_validation, design_console, run_design, trapezoid as _trap)

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def situm_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("situm_p_pd")
    rc, _ = run_design("situm_p_pd", out)
    return rc, out


@pytest.mark.design("situm_p_pd")
def test_situm_design_writes_both_reports(situm_report):
    rc, out = situm_report
    html = (out / "report.html").read_text()
    pdf = (out / "report.pdf").read_bytes()
    assert pdf.startswith(b"%PDF") and len(pdf) > 50_000          # figures embedded
    for heading in ("Linear model", "Gain limits", "Stability maps",
                    "Closed-loop validation on the nonlinear plant", "Table I ARX model vs PCT model",
                    "Provenance"):
        assert heading in html
    assert "http://" not in html.replace("http://www.w3.org", "")   # self-contained
    assert html.count("data:image/png;base64,") >= 5
    summary = json.loads((out / "summary.json").read_text())
    assert rc == (0 if summary["design_passed"] else 1)
    # the quick run's verdict (PD passes the validation on the nonlinear plant, the
    # paper-000 limits are reproduced, the sampled loop is stable): a pass
    assert summary["design_passed"] is True and rc == 0


@pytest.mark.design("situm_p_pd")
def test_situm_design_reproduces_paper_000(situm_report):
    _, out = situm_report
    s = json.loads((out / "summary.json").read_text())
    lim = s["limits_table_ii"]
    # physics.md: 72.5 and 62.3 are quoted to 3 digits; "about 54" and "about 36"
    assert lim["continuous"] == pytest.approx(72.5, abs=0.05)
    assert lim["pct"] == pytest.approx(62.3, abs=0.05)
    assert lim["sampled"] == pytest.approx(54, abs=0.5)
    assert lim["sampled_delay"] == pytest.approx(36, abs=0.5)
    assert s["k0_p"] == pytest.approx(7.0, abs=0.05)                # Table II: K0 = 7.0
    # Table I ARX poles, physics.md: 0.861 +- 0.109j, 0.363 +- 0.019j (3 digits)
    key = lambda z: (round(z.real, 2), z.imag)                      # noqa: E731
    arx = sorted((complex(*p) for p in s["arx_poles"]), key=key)
    expected = sorted([0.861 + 0.109j, 0.861 - 0.109j, 0.363 + 0.019j, 0.363 - 0.019j], key=key)
    assert np.allclose(arx, expected, atol=1.5e-3)
    pct = [complex(*p) for p in s["pct_poles"]]
    assert any(abs(z - (0.928 + 0.076j)) < 1.5e-3 for z in pct)
    assert any(abs(z - 0.619) < 1.5e-3 for z in pct)
    # the map's |z| = 1 crossing at the rig's mass sits on the exact limit of the rig
    # model within one grid step of the quick map (90/39 = 2.3 1/s)
    assert abs(s["map_crossing_k0"] - s["limits_rig"]["sampled"]) < 2.4
    # the PD loop is faster than the paper's P loop and stable
    assert s["k0_pd"] > s["k0_p"] and s["rho_pd"] < 1


def test_failed_design_still_writes_a_report(tmp_path, monkeypatch):
    mod = runpy.run_path(str(ROOT / "designs" / "situm_p_pd.py"), run_name="design")
    main = mod["main"]
    g = main.__globals__

    def broken(*a, **k):
        raise RuntimeError("valve table missing")
    monkeypatch.setitem(g, "pd_design", broken)
    rc = main(["--quick", "--out", str(tmp_path)])
    assert rc == 1
    html = (tmp_path / "report.html").read_text()
    assert "valve table missing" in html and "controllers" in html
    assert (tmp_path / "report.pdf").read_bytes().startswith(b"%PDF")


# --------------------------------------------------------------- situm_rodless_sim
# Paper 000 rig (designs/plants/situm_rodless_nominal.toml), recomputed by hand here.
SITUM = dict(ps=5e5, patm=101325.0, b=0.30, C=6.23e-9, T=293.15, bore=0.015, L=0.5,
             Vd=2e-6, M=0.91, kf=65.0, kappa=1.4, span=5.0, kp=10.0)
RHO0, R_AIR = 1.185, 287.0                 # physics.md: ISO 6358 rho0 at T0; air


def _iso6358_psi(x: float, b: float) -> float:
    """ISO 6358 flow function (physics.md, datasheet form)."""
    return 1.0 if x <= b else math.sqrt(1.0 - ((x - b) / (1.0 - b)) ** 2)


@pytest.fixture(scope="module")
def rodless_sim(tmp_path_factory):
    out = tmp_path_factory.mktemp("situm_rodless_sim")
    rc, summary = run_design("situm_rodless_sim", out)
    return rc, out, summary


@pytest.mark.design("situm_rodless_sim")
def test_rodless_sim_linear_numbers_against_hand_formulas(rodless_sim):
    rc, out, s = rodless_sim
    assert rc == 0 and (out / "trajectory.png").stat().st_size > 0
    c = SITUM
    A = math.pi / 4 * c["bore"] ** 2
    # paper 000's formulas (physics.md), p = supply, Vc = A L, no dead volume
    w0_p = math.sqrt(4 * c["kappa"] * c["ps"] * A ** 2 / (c["M"] * A * c["L"]))
    zeta_p = c["kf"] / 2 * math.sqrt(A * c["L"] / (4 * c["kappa"] * c["ps"] * A ** 2 * c["M"]))
    assert s["paper000_formulas"]["w0"] == pytest.approx(w0_p, rel=1e-9)
    assert s["paper000_formulas"]["zeta"] == pytest.approx(zeta_p, rel=1e-9)
    # ... and physics.md's own check of them: 32.97 rad/s and 1.08 (quoted digits)
    assert w0_p == pytest.approx(32.97, abs=0.01) and zeta_p == pytest.approx(1.08, abs=0.005)
    # Centred closed-centre valve: equal openings to supply and exhaust pass equal
    # flow, ps psi(p/ps) = p psi(patm/p) (ISO 6358, equal upstream temperatures).
    pe = optimize.brentq(lambda p: c["ps"] * _iso6358_psi(p / c["ps"], c["b"])
                         - p * _iso6358_psi(c["patm"] / p, c["b"]),
                         1.01 * c["patm"], 0.999 * c["ps"], xtol=1e-8)
    op = s["operating_point"]
    # the workbench pins this with a 1e-4 underlap: equal to the zero-leak limit to
    # ~1e-6 relative (equilibrium.PIN_UNDERLAP)
    assert op["u"] == pytest.approx(5.0, abs=1e-6)
    assert op["p_a"] == pytest.approx(pe, rel=1e-6) and op["p_b"] == pytest.approx(pe, rel=1e-6)
    # Tangent model at mid-stroke: polytropic chamber stiffness with the dead volume,
    # w0^2 = kappa A^2 (p_a/V_a + p_b/V_b) / M; a closed centre has no pressure-flow
    # coefficient, so the damping is the viscous friction's alone, zeta = kf / (2 M w0);
    # Kv = flow gain / (rho_e A), flow gain = C rho0 ps psi(pe/ps) / span.
    V = A * c["L"] / 2 + c["Vd"]
    w0 = math.sqrt(c["kappa"] * A ** 2 * 2 * pe / V / c["M"])
    zeta = c["kf"] / (2 * c["M"] * w0)
    kv = RHO0 * c["C"] * c["ps"] * _iso6358_psi(pe / c["ps"], c["b"]) / c["span"] \
        / (pe / (R_AIR * c["T"]) * A)
    lin = s["exact_linearisation"]
    # same formulas to rounding (measured 1e-15); 1e-6 leaves room for the pinning
    assert lin["w0"] == pytest.approx(w0, rel=1e-6)
    assert lin["zeta"] == pytest.approx(zeta, rel=1e-6)
    assert lin["Kv"] == pytest.approx(kv, rel=1e-6)
    assert s["loop_gain_k0"] == pytest.approx(c["kp"] * kv, rel=1e-6)
    assert s["loop_gain_k0"] == pytest.approx(7.0, abs=0.05)        # Table II: K0 = 7.0


@pytest.mark.design("situm_rodless_sim")
def test_rodless_sim_closed_loop_against_the_sampled_linear_loop(rodless_sim):
    _, out, s = rodless_sim
    d = pd.read_csv(out / "trajectory.csv", comment="#")
    sim = s["simulation"]
    assert sim["duration_s"] == pytest.approx(1.2) and d["t"].iloc[-1] == pytest.approx(1.2)
    # the 50 mm step at 0.3 s: the largest error is the step itself (x cannot jump)
    assert sim["max_abs_error_m"] == pytest.approx(0.05, abs=1e-9)
    # pressures of a passive valve stay between atmosphere and supply
    lo, hi = sim["pressure_range_pa"]
    assert SITUM["patm"] < lo < hi < SITUM["ps"]
    # The same P loop (kp = 10 V/m, ZOH at 10 ms) on the hand-made tangent model
    # Kv w0^2 / (s (s^2 + 2 zeta w0 s + w0^2)), discretised by scipy.
    lin = s["exact_linearisation"]
    w0, zeta, kv = lin["w0"], lin["zeta"], lin["Kv"]
    sysd = signal.StateSpace(*signal.tf2ss([kv * w0 ** 2], [1, 2 * zeta * w0, w0 ** 2, 0])
                             ).to_discrete(0.01, method="zoh")
    z, x_lin = np.zeros((3, 1)), []
    for k in range(121):
        y = 0.25 + (sysd.C @ z).item()
        x_lin.append(y)
        r = 0.30 if k >= 30 else 0.25
        z = sysd.A @ z + sysd.B * (SITUM["kp"] * (r - y))
    x_nl = np.interp(np.arange(121) * 0.01, d["t"], d["x"])
    # a 50 mm step moves the chambers off the tangent point: measured 2.9 mm largest
    # difference and 0.09 mm at the end; bounds 5 mm (10 % of the step) and 0.3 mm
    assert np.max(np.abs(x_nl - np.array(x_lin))) < 5e-3
    assert sim["final_error_m"] == pytest.approx(x_nl[-1] - 0.30, abs=1e-9)
    assert abs(sim["final_error_m"] - (x_lin[-1] - 0.30)) < 3e-4
    assert abs(sim["final_error_m"]) < 1e-3       # Specification: 1 mm steady-state error


# --------------------------------------------------------------- diagnose_concealed
#: The quick run's three cases (seed 2026), the effect the diagnosis must name for
#: each (formats.md section 2; a wrong mass is a parameter_error on load.mass).
CONCEALED_QUICK = {"dry_friction": "dry_friction", "mass_error": "parameter_error",
                   "none": None}


@pytest.fixture(scope="module")
def concealed(tmp_path_factory):
    out = tmp_path_factory.mktemp("diagnose_concealed")
    rc, summary = run_design("diagnose_concealed", out)
    return rc, out, summary


@pytest.mark.design("diagnose_concealed")
def test_concealed_quick_names_each_effect_and_nothing_else(concealed):
    rc, out, s = concealed
    cases = s["cases"]
    assert [c["concealed"] for c in cases] == list(CONCEALED_QUICK)
    for c in cases:
        findings = c["result"]["findings"]
        want = CONCEALED_QUICK[c["concealed"]]
        # the named effect, and nothing extra
        assert [f["effect"] for f in findings] == ([want] if want else []), c["concealed"]
        before, after = c["result"]["fit_before"], c["result"]["fit_after"]
        if want:
            # the fit improves on every signal once the effect is added
            assert all(after[k] > before[k] for k in ("x", "p_a", "p_b")), (before, after)
        else:
            assert after == before and before["x"] > 99.0    # the nominal model fits
    assert s["correct"] == s["total"] == 3
    assert s["passed"] is True and rc == 0
    assert "PASS" in (out / "report.html").read_text()


def test_sets_table_counts_hits_misses_and_spurious_per_effect():
    """diagnose_concealed's per-effect table over the sets: a pair whose partner is
    named counts for both effects, not as a confusion; a named effect that was not
    concealed is spurious; 'none' is not an effect. Counts written out by hand."""
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "designs"))
    import diagnose_concealed as dc
    rows = [
        {"case": 0, "label": "a + b", "concealed": ["dry_friction", "leakage"],
         "named": ["dry_friction", "leakage"], "correct": True, "wall_s": 1.0},
        {"case": 1, "label": "a + c", "concealed": ["dry_friction", "valve_offset"],
         "named": ["valve_offset", "line_dynamics"], "correct": False, "wall_s": 1.0},
        {"case": 2, "label": "nominal", "concealed": [], "named": ["none"],
         "correct": True, "wall_s": 1.0},
    ]
    section, all_ok, text = dc.sets_section(rows)
    table = section.blocks[2]
    got = {r[0]: tuple(r[1:]) for r in table.rows}
    # effect: (concealed in, named there, missed, missed but said, named without being
    # concealed)
    assert got == {"dry_friction": (2, 1, 1, 0, 0), "leakage": (1, 1, 0, 0, 0),
                   "valve_offset": (1, 1, 0, 0, 0), "line_dynamics": (0, 0, 0, 0, 1)}
    assert text == "2/3 sets named exactly" and all_ok is False


@pytest.mark.design("diagnose_concealed")
def test_concealed_quick_fitted_values(concealed):
    _, _, s = concealed
    by_kind = {c["concealed"]: c for c in s["cases"]}
    # 8 s recordings with sensor noise and 12-bit quantisation. Measured: Coulomb
    # -0.5 %, static -1.6 %, mass +0.002 %; bounds 5 %, 10 % and 1 % (the design's
    # own check is 30 %). The Stribeck velocity is not identifiable from these
    # recordings (measured +115 %) and is not checked.
    fr = by_kind["dry_friction"]
    par, true = fr["result"]["findings"][0]["parameters"], fr["values"]
    assert par["coulomb"] == pytest.approx(true["friction.coulomb"], rel=0.05)
    assert par["static"] == pytest.approx(true["friction.static"], rel=0.10)
    ms = by_kind["mass_error"]
    par, true = ms["result"]["findings"][0]["parameters"], ms["values"]
    assert par["load.mass"] == pytest.approx(true["load.mass"], rel=0.01)
    assert abs(true["load.mass"] / 1.2 - 1) > 0.1     # the concealed mass is a real error


# =============================================================== every summary key (issue 17)
# The validation and figure checks (conftest.check_validation, check_figures) recompute
# each value from the CSV the design writes of the same run; the rest by hand or
# python-control.

def _csv(path):
    return pd.read_csv(path, comment="#")


@pytest.mark.design("situm_p_pd")
def test_situm_design_every_validation_key(situm_report):
    """situm_p_pd's validation blocks from its CSVs; the gains and loop gains by hand."""
    _, out = situm_report
    s = json.loads((out / "summary.json").read_text(), parse_constant=float)
    for key, csv_name in (("validation_p", "validation_p.csv"), ("validation_pd", "validation_pd.csv")):
        check_validation(s[key], _csv(out / csv_name), p_s=5e5)
    # P loop: K0 = kp Kv with the plant's kp = 10 V/m (TOML) and Kv of the exact model
    assert s["k0_p"] == pytest.approx(10.0 * s["limits_rig"]["kv"], rel=1e-12)
    assert s["k0_pd"] == pytest.approx(s["kp_pd"] * s["limits_rig"]["kv"], rel=1e-9)
    assert s["kd_pd"] > 0 and s["design_passed"] is s["validation_pd"]["passed"]


def _load(out):
    return json.loads((out / "summary.json").read_text(), parse_constant=float)


def _rig_pd_rho(kp, kd, T=0.01):
    """|z|max of the rig's (rig25_mpye.toml) sampled PD loop at mid stroke, by
    python-control: the central-difference tangent x/u at the equilibrium (minimal,
    order 3), c2d with a ZOH at T, the discrete PD kp + kd (z - 1) / (T z)
    (controllers.pd.pid_law), unity feedback."""
    import control
    from workbench import Plant
    from workbench.equilibrium import operating_point
    from conftest import central_jacobian
    rig = Plant.from_toml(ROOT / "designs" / "plants" / "rig25_mpye.toml")
    op = operating_point(rig, 0.25)
    a, b = central_jacobian(rig.evaluate_f, np.asarray(op.state, float), op.u,
                            np.array([0.5, 1.0, 1e5, 1e5]), 1e-5)
    num, den = signal.ss2tf(a, b[:, None], np.array([[1.0, 0, 0, 0]]), np.zeros((1, 1)))
    gz = control.c2d(control.tf(num[0], den).minreal(tol=1e-6), T, "zoh")
    z = control.tf([1, 0], [1], T)
    loop = (kp + kd * (z - 1) / (T * z)) * gz
    return float(np.max(np.abs(control.poles(control.feedback(loop, 1)))))


#: The nominal values of rig25_mpye.toml the Monte Carlo draws are spread around.
RIG25_NOMINAL = {"gas.polytropic_index": 1.2, "valve.sonic_conductance": 6.25e-8,
                 "load.mass": 1.2, "supply.pressure": 6e5}


def _draws_within_their_ranges(r):
    """Each Monte Carlo draw inside its uncertainty's range (workbench.robustness modes:
    'value' low..high, 'factor' nominal x low..high, 'offset' nominal + low..high)."""
    for u in r["uncertainty"]:
        k, lo, hi, mode = u["key"], u["low"], u["high"], u["mode"]
        nom = RIG25_NOMINAL[k]
        bounds = {"value": (lo, hi), "factor": (nom * lo, nom * hi),
                  "offset": (nom + lo, nom + hi)}.get(mode)
        for d in r["draws"]:
            if bounds is not None:
                assert bounds[0] <= d[k] <= bounds[1], (k, mode, d[k])
            assert d[k] > 0, k


@pytest.fixture(scope="module")
def fl_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("fl_position")
    rc, _ = run_design("fl_position", out)
    return rc, out, _load(out)


@pytest.mark.design("fl_position")
def test_fl_design_every_key(fl_run):
    """fl_position: validations and figures from its CSVs, gains from the bandwidth,
    feasibility from its definitions, the must-show table's own arithmetic."""
    rc, out, s = fl_run
    assert s["quick"] is True and rc == (0 if s["design_passed"] else 1)
    names = {"FL nominal": "fl_nominal", "PD nominal": "pd_nominal", "FL full": "fl_full",
             "PD full": "pd_full"}
    assert set(s["validations"]) == set(s["metrics"]) == set(names)
    for name, stem in names.items():
        df = _csv(out / f"validation_{stem}.csv")
        v = check_validation(s["validations"][name], df)
        # no q_supply column: the air is bounded by the fully open valve's choked flow
        # for the whole run, C p_s rho0 T (rig25_mpye.toml: C = 6.25e-8, 6 bar)
        check_figures(s["metrics"][name], v, df,
                      air_bound=6.25e-8 * 6e5 * RHO_ANR_KG_M3 * (df["t"].iloc[-1]))
    assert s["fl_full_passed"] is s["validations"]["FL full"]["passed"]
    # gains of the error dynamics (s + w)^4 with all four poles at -w (damping 1):
    # binomial coefficients 4 w, 6 w^2, 4 w^3, w^4
    w = s["bandwidth"]
    assert s["damping"] == 1.0 and s["feasibility"]["bandwidth"] == w
    g = s["gains"]
    for k, ref in (("k2", 4 * w), ("k1", 6 * w ** 2), ("k0", 4 * w ** 3), ("ki", w ** 4)):
        assert g[k] == pytest.approx(ref, rel=1e-12), k
    f = s["feasibility"]
    # the sampling limit pi / (10 T) (the refusal message states it)
    assert f["sampling_limit"] == pytest.approx(math.pi / (10 * f["sample_time"]), rel=1e-12)
    assert f["sample_time"] == 0.01 and w < f["sampling_limit"]
    # feasible: every need within the margin of what is available, and no reason given
    assert f["reasons"] == [] and f["max_bandwidth"] is None and f["margin"] == 0.8
    for need, avail in (("gamma_needed", "gamma_available"), ("flow_needed", "flow_available"),
                        ("force_needed", "force_available")):
        assert 0.0 < f[need] <= f["margin"] * f[avail], need
    assert f["gamma_available"] == 1.0            # a fully open valve
    # the largest pneumatic force either way: one chamber at supply, the other at
    # atmosphere, (p_s - p_atm) A (rodless 25 mm bore, rig25_mpye.toml)
    area = math.pi / 4 * 0.025 ** 2
    assert f["force_available"] == pytest.approx((6e5 - 101325.0) * area, rel=1e-9)
    # closed centre: no flow at zero opening, so the flow is proportional to the opening
    # term G and flow_needed / flow_available = gamma_needed / gamma_available
    assert f["flow_needed"] / f["flow_available"] == pytest.approx(
        f["gamma_needed"] / f["gamma_available"], rel=1e-9)
    assert f["pressures"][0] == f["pressures"][1]             # rodless, at mid stroke
    # flow available: the fully open valve, choked flow bound C p_s rho0 (ISO 6358)
    assert f["flow_available"] <= 6.25e-8 * 6e5 * RHO_ANR_KG_M3
    assert 0.0 <= f["when"] <= s["validations"]["FL nominal"]["metrics"]["duration"]
    # refused designs: each named, with the reason the FL design gives
    assert len(s["refused"]) == 2
    for label, why, msg in s["refused"]:
        assert "feedback linearisation refused" in msg and label and why
    assert "sampling limit" in s["refused"][0][2]
    # must-show: fraction = max error / |step| per step, the worst of them, below 2 %
    ms = s["must_show"]
    for st in ms["steps"]:
        assert st["fraction"] == pytest.approx(st["max_error"] / abs(st["size"]), rel=1e-12)
    assert ms["worst_fraction"] == max(st["fraction"] for st in ms["steps"])
    assert ms["bound"] == 0.02 and ms["worst_fraction"] < ms["bound"]
    # PD: the stable sampled loop (|z| < 1) the design compares against; formats.md's
    # example PD (20, 1) is not (rho > 1), which is why the design retunes it. Both
    # spectral radii from python-control (see _rig_pd_rho); measured agreement 4e-12
    assert s["pd"]["rho"] < 1.0 < s["rho_file_pd"]
    assert s["pd"]["rho"] == pytest.approx(_rig_pd_rho(s["pd"]["kp"], s["pd"]["kd"]), rel=1e-7)
    assert s["rho_file_pd"] == pytest.approx(_rig_pd_rho(20.0, 1.0), rel=1e-7)
    # the quick verdict's rule (the validations of short holds are not judged): the
    # must-show bound and both refusals given
    refusals = all("refused" in r[2] for r in s["refused"])
    assert s["design_passed"] is bool(ms["worst_fraction"] < ms["bound"] and refusals)


@pytest.fixture(scope="module")
def nmpc_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("nmpc_position")
    rc, _ = run_design("nmpc_position", out, "--no-jit")
    return rc, out, _load(out)


@pytest.mark.design("nmpc_position")
def test_nmpc_design_every_key(nmpc_run):
    """nmpc_position: validations and figures from its CSVs (with q_supply), the IAE
    ratio, the constraint table from the same runs, the solve-time statistics' order."""
    rc, out, s = nmpc_run
    assert s["quick"] is True and rc == (0 if s["design_passed"] else 1)
    for key, stem in (("nmpc", "nmpc"), ("pd", "pd")):
        df = _csv(out / f"validation_{stem}.csv")
        v = check_validation(s[f"validation_{stem}"], df)
        check_figures(s[key], v, df)
    assert s["validation_pd"]["label"] == f"PD kp={s['pd_gains']['kp']:g} kd={s['pd_gains']['kd']:g}"
    assert s["iae_ratio_pd_over_nmpc"] == pytest.approx(s["pd"]["iae"] / s["nmpc"]["iae"], rel=1e-12)
    # the constraint table: the validation run's ranges in V, bar and mm from the CSV
    df = _csv(out / "validation_nmpc.csv")
    p = np.concatenate([df["p_a"], df["p_b"]])
    rows = {(c["run"], c["quantity"].split(" (")[0]): c for c in s["constraints"]}
    val = {q: c for (run, q), c in rows.items() if run == "validation"}
    assert val["command"]["min"] == pytest.approx(df["u"].min(), rel=1e-12)
    assert val["command"]["max"] == pytest.approx(df["u"].max(), rel=1e-12)
    assert val["chamber pressures"]["min"] == pytest.approx(p.min() / 1e5, rel=1e-12)
    assert val["chamber pressures"]["max"] == pytest.approx(p.max() / 1e5, rel=1e-12)
    assert val["position"]["min"] == pytest.approx(df["x"].min() * 1e3, rel=1e-12)
    assert val["position"]["max"] == pytest.approx(df["x"].max() * 1e3, rel=1e-12)
    # ok = inside the plant's limits: command 0..10 V, pressures between atmosphere and
    # supply (1.013..6 bar), position within the 500 mm stroke (rig25_mpye.toml)
    limits = {"command": (0.0, 10.0), "chamber pressures": (1.01325 - 1e-9, 6.0 + 1e-9),
              "position": (0.0, 500.0)}
    for (run, q), c in rows.items():
        lo, hi = limits[q]
        assert c["ok"] is bool(lo <= c["min"] <= c["max"] <= hi), (run, q)
    assert {run for run, _ in rows} == {"validation", "limit steps"}
    assert s["constraints_held"] is all(c["ok"] for c in s["constraints"])
    st = s["solve_time"]
    assert 0.0 < st["median_ms"] <= st["p99_ms"] <= st["max_ms"]
    # one solve per control sample of the 11.35 s profile at 10 ms, both ends included
    assert st["samples"] == round(s["validation_nmpc"]["metrics"]["duration"] / 0.01) + 1
    assert st["qp_failures"] == 0 and st["restarts"] >= 0 and isinstance(st["restarts"], int)
    assert s["design_passed"] is bool(s["constraints_held"] and s["validation_nmpc"]["passed"]
                                      and s["nmpc"]["iae"] < s["pd"]["iae"])


@pytest.fixture(scope="module")
def comparison_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("nonlinear_comparison")
    # the arguments of tests/test_comparison_design.py: the same (shared) run
    rc, _ = run_design("nonlinear_comparison", out, "--no-jit", "--workers", "2")
    return rc, out, _load(out)


@pytest.mark.design("nonlinear_comparison")
def test_comparison_design_every_validation_and_figure(comparison_run):
    """nonlinear_comparison: all six validations and figures from the CSVs (the robustness
    tables and verdict are checked in tests/test_comparison_design.py)."""
    _, out, s = comparison_run
    for where in ("nominal", "full"):
        for name in ("PD", "FL", "NMPC"):
            df = _csv(out / f"validation_{name.lower()}_{where}.csv")
            v = check_validation(s["validations"][where][name], df)
            check_figures(s["figures"][where][name], v, df)
    # the NMPC with the lines model on the rig: a second run of the same profile; its
    # figures obey the same identities (no CSV is written for it)
    f = s["nmpc_lines_model_on_rig"]
    assert f["air_l_anr"] == pytest.approx(f["air_kg"] / RHO_ANR_KG_M3 * 1e3, rel=1e-12)
    assert f["max_error_settled"] <= f["max_error"] and f["ramp_error"] <= f["max_error"]
    assert f["overshoot_abs"] <= f["max_error"] and f["passed"] is (f["failed"] == [])
    assert 0.0 <= f["u_min"] <= f["u_max"] <= 10.0 and 0 < f["x_min"] < f["x_max"] < 0.5
    assert s["pd"] == {"kp": 8.0, "kd": 0.1}
    for key, r in s["robustness"].items():
        _draws_within_their_ranges(r)
        for name, c in r["controllers"].items():
            assert c["pass_rate"] == pytest.approx(np.mean(c["passed"]), rel=1e-12), (key, name)
            assert len(c["scores"]) == len(c["failed_checks"]) == len(r["draws"])
            assert all(p is (not f_) for p, f_ in zip(c["passed"], c["failed_checks"]))


@pytest.mark.design("situm_p_pd")
def test_situm_design_limits_and_loops_against_python_control(situm_report):
    """Every key of situm_p_pd's two limit tables and the closed loops' spectral radii,
    from python-control: the loop 1 / (s (s^2/w0^2 + 2 zeta s/w0 + 1)) discretised with
    a ZOH (c2d), its gain margin (the sampled limit), with one sample of delay 1/z, the
    phase crossover (the oscillation's frequency, rad/s) and the phase margin at K0;
    PCT's Ts = T/2 + 1/w0 (paper 000). Agreement measured 1e-10; 1e-7 relative."""
    import warnings
    import control
    _, out = situm_report
    s = _load(out)
    for key in ("limits_table_ii", "limits_rig"):
        lim = s[key]
        w0, zeta, T, k0 = lim["w0"], lim["zeta"], lim["sample_time"], lim["k0"]
        gz = control.c2d(control.tf([1.0], [1 / w0 ** 2, 2 * zeta / w0, 1, 0]), T, "zoh")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)     # python-control's method note
            gm, _, wcg, _ = control.margin(gz)
            gmd, _, wcgd, _ = control.margin(gz * control.tf([1], [1, 0], T))
            gm_k0, pm_k0, _, _ = control.margin(k0 * gz)
        ref = {"sampled": gm, "sampled_delay": gmd, "sampled_frequency_rad_s": wcg,
               "sampled_delay_frequency_rad_s": wcgd, "gain_margin": gm_k0,
               "phase_margin_deg": pm_k0, "continuous": 2 * zeta * w0,
               "pct_time_constant_s": T / 2 + 1 / w0, "pct": 2 * zeta / (T / 2 + 1 / w0)}
        for k, v in ref.items():
            assert lim[k] == pytest.approx(v, rel=1e-7), (key, k)
        assert lim["gain_margin"] == pytest.approx(lim["sampled"] / k0, rel=1e-9)
        assert T == 0.01
    tab, rig = s["limits_table_ii"], s["limits_rig"]
    # Table II's model (physics.md: w0 = 32.97 rad/s, zeta = 1.1, K0 = 7.0); the rig's
    # from the exact linearisation (test_rodless_sim_... checks w0, zeta, Kv by hand)
    assert (tab["w0"], tab["zeta"], tab["k0"]) == (32.97, 1.1, 7.0)
    assert tab["kv"] is None and tab["kp"] is None
    assert rig["kp"] == 10.0 and rig["k0"] == pytest.approx(rig["kp"] * rig["kv"], rel=1e-12)
    for k, v in rig["kp_limits"].items():
        assert v == pytest.approx(rig[k] / rig["kv"], rel=1e-12), k
    # closed loops on the rig's reduced model kv / (s (...)) with the ZOH: P (kp = 10)
    # and the discrete PD u = kp e + kd (e_k - e_k-1) / T (controllers.pd.pid_law)
    gz = control.c2d(control.tf([rig["kv"]], [1 / rig["w0"] ** 2, 2 * rig["zeta"] / rig["w0"],
                                              1, 0]), 0.01, "zoh")
    z = control.tf([1, 0], [1], 0.01)
    rho = lambda loop: float(np.max(np.abs(control.poles(control.feedback(loop, 1)))))  # noqa
    assert s["rho_p"] == pytest.approx(rho(10.0 * gz), rel=1e-9)
    assert s["rho_pd"] == pytest.approx(rho((s["kp_pd"] + s["kd_pd"] * (z - 1) / (0.01 * z)) * gz),
                                        rel=1e-9)


@pytest.mark.design("situm_rodless_sim")
def test_rodless_sim_remaining_keys(rodless_sim):
    """situm_rodless_sim: the plant, the operating point's position, the reduced model's
    fit and band, the pressure range from the CSV, the wall time."""
    _, out, s = rodless_sim
    d = pd.read_csv(out / "trajectory.csv", comment="#")
    assert s["plant"] == "designs/plants/situm_rodless_nominal.toml"
    assert s["operating_point"]["x"] == 0.25
    lin = s["exact_linearisation"]
    assert 0.0 <= lin["fit_error"] < 1e-9          # an exact reduction (symmetric, mid stroke)
    lo, hi = lin["band_rad_s"]
    assert lo < lin["w0"] < hi
    p = np.concatenate([d["p_a"], d["p_b"]])
    assert s["simulation"]["pressure_range_pa"] == pytest.approx([p.min(), p.max()], rel=1e-12)
    e = np.abs(d["r"] - d["x"])
    assert s["simulation"]["max_abs_error_m"] == pytest.approx(e.max(), rel=1e-9)
    assert s["simulation"]["final_error_m"] == pytest.approx(d["x"].iloc[-1] - d["r"].iloc[-1],
                                                             abs=1e-12)
    wall = s["simulation"]["wall_s"]
    assert isinstance(wall, float) and 0.0 < wall < 60.0


@pytest.mark.design("diagnose_concealed")
def test_concealed_every_case_key(concealed):
    """diagnose_concealed: per case the seed (seed * 1000 + case), the drawn values
    (drawn again here from the seed), the score (named, correct, extra findings, relative
    errors of the fitted values, the 30 % check, the fit gains) from the diagnosis's own
    JSON, and the timings: every step of each diagnosis (details.json) adds up to no more
    than its total, which is within the case's wall time, and the cases within the run's."""
    from workbench.diagnose import synth
    _, out, s = concealed
    assert s["quick"] is True and s["total"] == len(s["cases"])
    assert s["correct"] == sum(c["correct"] for c in s["cases"])
    expected = {"dry_friction": "dry_friction", "mass_error": "parameter_error", "none": "none"}
    short = {"friction.coulomb": "coulomb", "friction.static": "static",
             "friction.stribeck_velocity": "stribeck_velocity", "load.mass": "load.mass"}
    for i, c in enumerate(s["cases"]):
        assert c["case"] == i and c["seed"] == 2026 * 1000 + i and c["redrawn"] == []
        assert c["values"] == pytest.approx(dict(synth.concealed_case(c["concealed"],
                                                                      seed=c["seed"]).values))
        res = c["result"]
        names = [f["effect"] for f in res["findings"]]
        assert c["expected"] == expected[c["concealed"]]
        assert c["named"] == (names[0] if names else "none")
        assert c["correct"] is (c["named"] == c["expected"])
        assert c["extra_findings"] == names[1:]
        par = res["findings"][0]["parameters"] if names else {}
        assert set(c["relative_errors"]) == set(c["values"])
        for k, rel in c["relative_errors"].items():
            # the JSON's fitted values are printed to 6 digits: 1e-5 relative
            assert rel == pytest.approx(par[short[k]] / c["values"][k] - 1.0, abs=1e-5), k
        checked = synth.CHECKED_KEYS.get(c["concealed"], ())
        assert c["checked_ok"] is all(abs(c["relative_errors"][k]) <= 0.3 for k in checked)
        for sig, g in c["fit_gain"].items():
            assert g == pytest.approx(res["fit_after"][sig] - res["fit_before"][sig], abs=1e-9)
        # timings: the steps of the diagnosis add up to its total (each rounded to 1 ms)
        t = json.loads((out / "cases" / f"{i:02d}" / "diagnosis" / "details.json")
                       .read_text())["timings_s"]
        parts = [v for k, v in t.items() if k != "total"]
        assert all(isinstance(v, float) and v >= 0.0 for v in t.values())
        assert sum(parts) <= t["total"] + 5e-4 * len(parts)
        assert 0.0 < t["total"] < c["wall_s"]          # the subprocess ran the diagnosis
        assert 0.0 < c["record_s"]
    assert s["wall_s"] >= sum(c["wall_s"] + c["record_s"] for c in s["cases"])


@pytest.fixture(scope="module")
def force_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("force_tracking")
    rc, _ = run_design("force_tracking", out)       # shared with tests/test_inversion.py
    return rc, out, _load(out)


@pytest.mark.design("force_tracking")
def test_force_tracking_every_metric_from_its_csvs(force_run):
    """force_tracking: each run's figures from its CSV (e = force - force_ref; RMS, max,
    IAE by the trapezoid rule, air = integral of q_supply, command total variation, the
    largest position drift, pressure range, duration), the bounds from the reference's
    span (1 % and 0.2 %), the Monte Carlo tables' arithmetic, the verdict's rule."""
    rc, out, s = force_run
    assert s["quick"] is True and rc == (0 if s["design_passed"] else 1)
    files = {"nominal affine plant": "run_nominal_affine_plant.csv",
             "rig (four-edge valve)": "run_rig__four_edge_valve.csv"}
    assert set(s["metrics"]) == set(files) == set(s["plan_deviation"])
    for name, fname in files.items():
        d = _csv(out / fname)
        t = d["t"].to_numpy()
        e = (d["force"] - d["force_ref"]).to_numpy()
        m = s["metrics"][name]
        _close(m["rms_error"], np.sqrt(np.mean(e ** 2)), "rms")
        _close(m["max_error"], np.abs(e).max(), "max")
        _close(m["iae"], _trap(np.abs(e), t), "iae")
        _close(m["air_kg"], _trap(d["q_supply"].to_numpy(), t), "air")
        _close(m["command_tv"], np.abs(np.diff(d["u"])).sum(), "tv")
        _close(m["x_drift"], np.abs(d["x"] - d["x"].iloc[0]).max(), "drift")
        p = np.concatenate([d["p_a"], d["p_b"]])
        _close(m["p_min"], p.min(), "p_min")
        _close(m["p_max"], p.max(), "p_max")
        _close(m["duration"], t[-1], "duration")
        span = float(np.ptp(d["force_ref"]))
        _close(s["span"], span, "span")
        # the plan deviation is a pressure difference: within the supply's range
        assert 0.0 < s["plan_deviation"][name] < 6e5
    assert s["bounds"]["max"] == pytest.approx(0.01 * s["span"], rel=1e-12)
    assert s["bounds"]["rms"] == pytest.approx(0.002 * s["span"], rel=1e-12)
    nom = s["metrics"]["nominal affine plant"]
    assert s["design_passed"] is bool(nom["max_error"] <= s["bounds"]["max"]
                                      and nom["rms_error"] <= s["bounds"]["rms"])
    # plans: ranges ordered, levels inside the pressure range, feasible, air positive
    for rule, pl in s["plans"].items():
        assert pl["p_min"] <= pl["level_min"] <= pl["level_max"] <= pl["p_max"] <= 6e5, rule
        assert pl["q_max"] > 0 and pl["air_mass"] > 0 and pl["feasible"] is True
        assert pl["saturated_fraction"] == 0.0 and pl["command_mismatch"] >= 0.0
    assert s["plans"]["single_valve"]["command_mismatch"] < 1e-9    # its defining rule
    rb = s["robustness"]
    # the Monte Carlo judge's bounds: 1 %, 5 % and 2 % of the span (the design's text)
    assert rb["spec"] == pytest.approx({"hold error": 0.01 * s["span"],
                                        "peak error": 0.05 * s["span"],
                                        "RMS error": 0.02 * s["span"]}, rel=1e-12)
    assert rb["hold_settle"] > 0 and isinstance(rb["run_time"], float) and rb["run_time"] > 0
    # the tracker on the locked rig is the rig run above: the same RMS error
    assert rb["nominal"]["tracker (FF + FB) | locked rig"]["rms_error"] == pytest.approx(
        s["metrics"]["rig (four-edge valve)"]["rms_error"], rel=1e-12)
    for key, r in rb["nominal"].items():
        assert r["passed"] is (r["failed"] == []), key
        assert ("RMS error" in r["failed"]) is (r["rms_error"] > rb["spec"]["RMS error"]), key
    for plant, res in rb["results"].items():
        assert res["seed"] == 2026 and len(res["draws"]) == 2
        _draws_within_their_ranges(res)
        for name, c in res["controllers"].items():
            assert c["pass_rate"] == pytest.approx(np.mean(c["passed"]), rel=1e-12)
            assert all(p is (f == []) for p, f in zip(c["passed"], c["failed_checks"]))
            # score = the run's RMS error; a failed "RMS error" check means it is above
            for sc, f in zip(c["scores"], c["failed_checks"]):
                assert ("RMS error" in f) is (sc > rb["spec"]["RMS error"]), (plant, name)


@pytest.fixture(scope="module")
def plan_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("pressure_plan_position")
    rc, _ = run_design("pressure_plan_position", out)   # shared with its own test file
    return rc, out, _load(out)


@pytest.mark.design("pressure_plan_position")
def test_pressure_plan_position_every_metric_from_its_csvs(plan_run):
    """pressure_plan_position: each run's figures from its CSV (e = x - x_ref; moves are
    the waypoint intervals where the position changes, holds the rest; the last 0.2 s
    for the end figure), the waypoints against the CSV's reference, the move and bound
    (2 % of the largest move), the plan deviations within the plans' pressure range."""
    rc, out, s = plan_run
    assert s["quick"] is True and rc == (0 if s["design_passed"] else 1)
    wp = s["waypoints"]
    moves = [(a[0], b[0]) for a, b in zip(wp, wp[1:]) if a[1] != b[1]]
    s_move = max(abs(b[1] - a[1]) for a, b in zip(wp, wp[1:]))
    assert s["move"] == pytest.approx(s_move, rel=1e-12)
    assert s["bound"] == pytest.approx(0.02 * s["move"], rel=1e-12)
    assert s["gains"] == {"kp": 5.0, "kd": 0.1} and s["sample_time"] == 0.01
    # force peak of the minimum-jerk moves, m a + beta v (rig25: m = 1.2 kg, beta = 40
    # N s/m, rodless: no net atmospheric force), x = x0 + D (10 s^3 - 15 s^4 + 6 s^5),
    # s = (t - t0) / tau, on a fine grid; the design samples at 1 ms, which can only
    # lower the peak, by ~1e-5 (measured): 1e-4
    peak = 0.0
    for (t0, x0), (t1, x1) in zip(wp, wp[1:]):
        if x1 == x0:
            continue
        dx, tau, u_ = x1 - x0, t1 - t0, np.linspace(0.0, 1.0, 200001)
        force = (1.2 * dx / tau ** 2 * (60 * u_ - 180 * u_ ** 2 + 120 * u_ ** 3)
                 + 40.0 * dx / tau * (30 * u_ ** 2 - 60 * u_ ** 3 + 30 * u_ ** 4))
        peak = max(peak, float(np.abs(force).max()))
    assert peak * (1 - 1e-4) <= s["force_peak"] <= peak * (1 + 1e-9)
    assert len(s["metrics"]) == 6
    plan_lo = min(p["p_min"] for p in s["plans"].values())
    plan_hi = max(p["p_max"] for p in s["plans"].values())
    for name, m in s["metrics"].items():
        slug = "".join(ch if ch.isalnum() else "_" for ch in name).strip("_")
        d = _csv(out / f"run_{slug}.csv")
        t, x, ref, u = (d[c].to_numpy() for c in ("t", "x", "x_ref", "u"))
        for tw, xw in wp:                      # the reference passes the waypoints
            k = int(np.argmin(np.abs(t - tw)))
            if abs(t[k] - tw) < 1e-9:
                assert ref[k] == pytest.approx(xw, abs=1e-12)
        e = x - ref
        mv = np.zeros(len(t), dtype=bool)
        for a, b in moves:
            mv |= (t >= a) & (t <= b)
        for key, sel in (("", np.ones(len(t), bool)), ("_moves", mv), ("_holds", ~mv)):
            _close(m[f"max_error{key}"], np.abs(e[sel]).max(), name + key)
            _close(m[f"rms_error{key}"], np.sqrt(np.mean(e[sel] ** 2)), name + key)
        _close(m["final_error"], abs(e[-1]), "final")
        _close(m["max_error_end"], np.abs(e[t >= t[-1] - 0.2]).max(), "end")
        _close(m["u_min"], u.min(), "u_min")
        _close(m["u_max"], u.max(), "u_max")
        _close(m["command_tv"], np.abs(np.diff(u)).sum(), "tv", rel=1e-6)
        p = np.concatenate([d["p_a"], d["p_b"]])
        _close(m["p_min"], p.min(), "p_min")
        _close(m["p_max"], p.max(), "p_max")
        # max |p_a - plan|: the plan lies within the plans' range
        dev_bound = max(d["p_a"].max() - plan_lo, plan_hi - d["p_a"].min())
        assert 0.0 <= m["plan_deviation_pa"] <= dev_bound, name
    key = "exact-model plant, feedforward + feedback"
    nom = s["metrics"][key]
    # on the exact model the feedforward is the motion: errors far inside the bound
    assert nom["max_error"] <= s["bound"] and nom["max_error_end"] <= 0.1 * s["bound"]
    for rule, pl in s["plans"].items():
        assert pl["p_min"] <= pl["level_min"] <= pl["level_max"] <= pl["p_max"], rule
        assert 0 < pl["stiffness_min"] <= pl["stiffness_max"] and pl["problems"] == []
        # the plan's force equation is met to rounding (N)
        assert 0.0 <= pl["force_residual"] < 1e-9 and pl["feasible"] is True
        assert pl["q_max"] > 0 and pl["air_mass"] > 0 and pl["saturated_fraction"] == 0.0


@pytest.mark.design("pressure_plan_position")
def test_design_progress_goes_to_stderr_step_by_step(tmp_path):
    # issue 15: long steps in the designs were silent (the force-tracking Monte Carlo
    # for 126 s). Every step announces itself on stderr with the time of day, a step
    # over 2 s says when it is done, results stay on stdout; the suite's one quick run
    # of the design, its console as run_design kept it
    import re
    rc, _ = run_design("pressure_plan_position", tmp_path / "out")
    out, err = design_console("pressure_plan_position")
    assert rc == 0
    steps = re.findall(r"^\[\d\d:\d\d:\d\d\] (.+) \.\.\.$", err, flags=re.M)
    assert steps == ["plants", "pressure plans", "closed loop", "write report"]
    done = re.findall(r"^\[\d\d:\d\d:\d\d\] (.+): done in (\d+\.\d) s$", err, flags=re.M)
    assert all(name in steps and float(s) > 2.0 for name, s in done)
    assert "..." not in out and "feedforward + feedback" in out   # results on stdout
