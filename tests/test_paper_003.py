"""designs/paper_003.py in quick mode: paper 003's numbers, the summary contract.

The flow stage's equilibrium and tangent model are recomputed here from the summary's
parameters with an independent implementation of the ISO 6358 law (plain ``math``,
physics.md) and central differences, not with the code under test.
"""

from __future__ import annotations

import json
import math

import pytest
from scipy import optimize

from conftest import run_design

#: one quick run, shared with tests/test_report_designs.py (same worker: conftest)
pytestmark = pytest.mark.design("paper_003")

R_AIR, RHO0, T0 = 287.0, 1.185, 293.15
KEYS = {"result", "paper", "workbench", "unit", "source", "agrees"}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper_003")
    rc, summary = run_design("paper_003", out)
    return rc, summary, out


def iso(c, b, p1, p2):
    """ISO 6358 flow (kg/s) from p1 to p2 >= 0 direction only (p1 >= p2), physics.md."""
    x = p2 / p1
    psi = 1.0 if x <= b else math.sqrt(max(0.0, 1.0 - ((x - b) / (1.0 - b)) ** 2))
    return c * p1 * RHO0 * psi


def flow(st, p, u):
    """The 3/2 flow stage from its parameters: rounded underlap, two restrictions."""
    o = min(1.0, max(-1.0, (u - st["command_center"]) / st["command_span"]))
    r = math.hypot(o, st["underlap"])
    b = st["critical_pressure_ratio"]
    return (0.5 * (r + o) * iso(st["inlet_conductance"], b, st["supply_pressure"], p)
            - 0.5 * (r - o) * iso(st["exhaust_conductance"], b, p, st["atmospheric_pressure"]))


def test_summary_contract_and_files(run):
    rc, summary, out = run
    assert rc == 0
    for name in ("report.html", "report.pdf", "valve_table.csv", "pressure_gain.csv",
                 "summary.json"):
        assert (out / name).stat().st_size > 0, name
    rows = summary["paper_results"]
    assert len(rows) >= 10
    for r in rows:
        assert set(r) == KEYS, r
        assert isinstance(r["agrees"], bool)
        assert "sect." in r["source"] or "Fig." in r["source"], r["source"]
    json.dumps(summary, allow_nan=False)          # strict JSON: no NaN or inf anywhere


def test_flow_stage_rests_at_the_papers_pressure(run):
    """Paper 003, sect. 5: the centred port's equilibrium is 5.1e5 Pa (Brent to 1e-6 Pa)."""
    st = run[1]["flow_stage"]
    pe = optimize.brentq(lambda p: flow(st, p, 0.0), st["atmospheric_pressure"] + 1.0,
                         st["supply_pressure"] - 1.0, xtol=1e-6)
    assert pe == pytest.approx(5.1e5, abs=1e-3)
    row = next(r for r in run[1]["paper_results"] if r["result"].startswith("equilibrium"))
    assert row["workbench"] == pytest.approx(5.1, abs=1e-6) and row["agrees"]


def test_true_tangent_model_by_central_differences(run):
    """tau = V / (k r T Cp), G = Gu / Cp (eq. 8) of the true valve; central differences
    with 10 Pa and 1e-4 V steps have relative truncation errors below 1e-6 on these smooth
    curves, so 1e-4 checks the exact (CasADi) values."""
    summary = run[1]
    st = summary["flow_stage"]
    tk = summary["tank_steps"]
    true = next(r for r in tk["runs"] if r["law"] == "true valve")
    pe = true["p_e_Pa"]
    cp = -(flow(st, pe + 10, 0.0) - flow(st, pe - 10, 0.0)) / 20
    gu = (flow(st, pe, 1e-4) - flow(st, pe, -1e-4)) / 2e-4
    tau = tk["volume_m3"] / (tk["k"] * R_AIR * tk["temperature_K"] * cp)
    assert tk["volume_m3"] == 1e-3 and tk["k"] == 1.2          # paper 003, sect. 5
    assert true["tau_s"] == pytest.approx(tau, rel=1e-4)
    assert true["G_Pa_V"] == pytest.approx(gu / cp, rel=1e-4)


def test_headline_accuracy_against_the_paper(run):
    """Paper 003: approximation I (66 coefficients) R = 0.99, errors < 0.4 g/s; II R = 0.99,
    errors < 0.5 g/s. R is quoted to two digits, so R >= 0.99 is the claim. Our table
    carries 0.05 g/s noise (its largest of 210 draws is about 0.15 g/s), so the largest
    error is allowed the paper's bound plus that 0.15 g/s for approximation I."""
    fits = run[1]["fits"]
    one, two = fits["I (n=5, m=10)"], fits["II, two psi"]
    assert one["paper_count"] == 66 and one["R"] >= 0.99
    assert one["max_error_g_s"] <= 0.4 + 0.15
    assert two["R"] >= 0.99 and two["max_error_g_s"] <= 0.5
    assert fits["II, 15 coef. (one psi)"]["paper_count"] == 15


def test_tangent_models_and_their_reasons(run):
    """Through the blocked-port points, approximations I and II (two psi) have the true
    valve's tau and G within 20 % (the report's 'poor' line: a step response visibly
    different, paper Fig. 10; measured 2 % and 5 %). On the flow points alone II's tau
    is off by more than 1.5x (issue 13's finding: 15.1 s against 7.63 s), and the report
    gives the measured reason."""
    summary = run[1]
    runs = {r["law"]: r for r in summary["tank_steps"]["runs"] if r["du_V"] == 1.0}
    true = runs["true valve"]
    for law in ("I (n=5, m=10)", "II, two psi"):
        assert runs[law]["tau_s"] == pytest.approx(true["tau_s"], rel=0.2), law
        assert runs[law]["G_Pa_V"] == pytest.approx(true["G_Pa_V"], rel=0.2), law
    assert runs["II, two psi, flow points only"]["tau_s"] > 1.5 * true["tau_s"]
    assert "phi'(p_e)" in summary["tangent_reasons"]["II, two psi, flow points only"]


def test_tank_errors_of_approximation_I(run):
    """Paper 003, sect. 5: approximation I's tank pressure error is below 2 %. Through the
    blocked-port points this holds after +-0.1 V and after steps to commands with no
    blocked-port point (+-0.05, +-0.25 V: the constraints do not merely return their own
    measurements); the +-1 V row disagrees and the report explains it from the budget."""
    rows = {r["result"]: r for r in run[1]["paper_results"]}
    small = rows["approximation I tank error, +-0.1 V steps (Fig. 10)"]
    between = rows["approximation I tank error, steps between the measured commands"]
    assert small["workbench"] <= 2.0 and small["agrees"]
    assert between["workbench"] <= 2.0 and between["agrees"]
    large = rows["approximation I tank error, +-1 V steps (Fig. 9)"]
    assert large["agrees"] == (large["workbench"] <= 2.0)


def test_end_error_is_the_pressure_gain_error(run):
    """The tank's end error is the error of the law's pressure gain characteristic at the
    new command (paper 003, sect. 5): for laws whose tank has settled (tau within 1.5x of
    the true one, so >= 4 time constants: at most 2 % of the step left), they agree within
    2 % of the step plus 1 % of the error."""
    summary = run[1]
    tau = {r["law"]: r["tau_s"] for r in summary["tank_steps"]["runs"] if r["du_V"] == 1.0}
    p0 = {(r["law"], r["du_V"]): (r["p0_Pa"], r["p_end_Pa"])
          for r in summary["tank_steps"]["runs"]}
    checked = 0
    for b in summary["end_error_budget"]:
        if b["gain_error_Pa"] is None or tau[b["law"]] > 1.5 * tau["true valve"]:
            continue
        start, end = p0[("true valve", b["du_V"])]
        tol = 0.02 * abs(end - start) + 0.01 * abs(b["end_error_Pa"])
        assert b["end_error_Pa"] == pytest.approx(b["gain_error_Pa"], abs=tol), b
        checked += 1
    assert checked >= 8


def test_written_table_refits_to_the_same_approximation(run, capsys):
    """valve_table.csv and pressure_gain.csv (shortest round-trip floats) refitted by the
    CLI give the report's approximation I: same R and largest error to rounding (1e-12),
    and the law passes through the blocked-port points."""
    from workbench.__main__ import main
    summary, out = run[1], run[2]
    assert main(["identify", "valve", str(out / "valve_table.csv"), "--approx", "I",
                 "--coefficients", "66", "--no-tank", "--json",
                 "--pressure-gain", str(out / "pressure_gain.csv")]) == 0
    got = json.loads(capsys.readouterr().out)["approximation_I"]
    want = summary["fits"]["I (n=5, m=10)"]
    assert got["degrees"] == {"n_pressure": 5, "m_command": 10}
    assert got["R"] == pytest.approx(want["R"], abs=1e-12)
    assert got["max_error_g_s"] == pytest.approx(want["max_error_g_s"], abs=1e-9)
    assert len(got["pressure_gain_points"]) >= 3
