"""designs/paper_001.py --quick: 1 m against 10 m lines, the paper's numbers (issue 13).

The script runs once per module (about 22 s of CPU). Paper values are typed in here
from the paper: lines of 1 m and 10 m, transition times differing by 0.4 s, the
valve's Cv = 0.274 and X_T = 1 of eq. (2).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from conftest import run_design

#: one quick run, shared with tests/test_report_designs.py (same worker: conftest)
pytestmark = pytest.mark.design("paper_001")

ROOT = Path(__file__).resolve().parents[1]
PAPER_DT = 0.4              # s, paper 001 after Fig. 9
PAPER_CV, PAPER_XT = 0.274, 1.0     # eq. (2)
A_SOUND = 343.0             # m/s, eq. (4)'s a_s as physics.md restates it
CONTRACT = {"result", "paper", "workbench", "unit", "source", "agrees"}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper_001")
    rc, summary = run_design("paper_001", out)
    assert rc == 0 and summary is not None
    return out, summary


def _rows(summary) -> dict:
    return {r["result"]: r for r in summary["paper_results"]}


def test_summary_contract(run):
    _, s = run
    assert len(s["paper_results"]) >= 4
    for r in s["paper_results"]:
        assert CONTRACT <= set(r), r
        assert isinstance(r["agrees"], bool)
        assert r["source"] and r["result"]
    assert _rows(s)["transition time difference, 10 m minus 1 m"]["paper"] == PAPER_DT


def test_pressure_delay_is_the_transport_delay(run):
    """At the fitted bore, 9 m more line delays the chamber pressure by 9 m / a =
    26.2 ms (eq. 4). The lumped line with 0.5 m segments (quick mode) smears the front
    over a few segment transits of 1.5 ms: 5 ms."""
    s = run[1]
    d = s["delays_s"]
    assert d["10"] - d["1"] == pytest.approx(9.0 / A_SOUND, abs=5e-3)
    assert d["1"] == pytest.approx(1.0 / A_SOUND, abs=2e-3)     # one 1 m line, 8 segments
    # attenuation (eq. 4 attenuates the mass flow): the longer line flattens the flow
    # and the pressure front; 0.8 leaves room above the measured 0.20 and 0.15
    assert s["peak_flow_kg_s"]["10"] < 0.8 * s["peak_flow_kg_s"]["1"]
    assert s["peak_rate_pa_s"]["10"] < 0.8 * s["peak_rate_pa_s"]["1"]
    assert _rows(s)["amplitude decay with the longer line"]["workbench"] == pytest.approx(
        s["peak_flow_kg_s"]["10"] / s["peak_flow_kg_s"]["1"], rel=1e-12)


def _half_way(path: Path) -> np.ndarray:
    """Time (s) from each reference step until x has covered half of it, read from a
    validation CSV (computed here, not by the script)."""
    lines = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]
    cols = lines[0].split(",")
    d = np.array([[float(c) for c in ln.split(",")] for ln in lines[1:]])
    t, x, r = d[:, cols.index("t")], d[:, cols.index("x")], d[:, cols.index("r")]
    jumps = np.flatnonzero(np.abs(np.diff(r)) > 1e-9) + 1
    out = []
    for j in jumps:
        r0, r1 = r[j - 1], r[j]
        k = j + np.argmax((x[j:] - r0) / (r1 - r0) >= 0.5)
        out.append(t[k] - t[j])
    return np.array(out)


def _settling(path: Path, band: float) -> np.ndarray:
    """Per reference step in a validation CSV: time (s) from which |x - r| stays within
    band x |step| until the next step (computed here, not by the script)."""
    lines = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]
    cols = lines[0].split(",")
    d = np.array([[float(c) for c in ln.split(",")] for ln in lines[1:]])
    t, x, r = d[:, cols.index("t")], d[:, cols.index("x")], d[:, cols.index("r")]
    jumps = list(np.flatnonzero(np.abs(np.diff(r)) > 1e-9) + 1) + [len(t)]
    out = []
    for j, k in zip(jumps[:-1], jumps[1:]):
        outside = np.abs(x[j:k] - r[j]) > band * abs(r[j] - r[j - 1])
        assert not outside[-1]                      # settled before the next step
        last = np.flatnonzero(outside)
        out.append(t[j + last[-1] + 1] - t[j] if last.size else 0.0)
    return np.array(out)


def test_transition_time_recomputed_from_the_runs(run):
    """The paper's quantity, the settling time into +-5 % of each step, 10 m minus 1 m,
    recomputed from the written runs: it agrees with the summary to the CSV's 1 ms
    step (plus the step instant's sample: 3 ms), and the half-way time comes later too."""
    out, s = run
    dt = float(np.mean(_settling(out / "validation_10m.csv", 0.05)
                       - _settling(out / "validation_1m.csv", 0.05)))
    assert dt == pytest.approx(s["transients_s"]["dt"], abs=3e-3)
    shift = float(np.mean(_half_way(out / "validation_10m.csv")
                          - _half_way(out / "validation_1m.csv")))
    assert shift == pytest.approx(s["transients_s"]["shift"], abs=3e-3)
    assert shift > 0.02                       # later, by more than two control samples
    assert _rows(s)["position transient later with 10 m lines"]["agrees"]


def test_bore_fitted_to_the_papers_0_4_s(run):
    """The tube bore is estimated from the paper's 0.4 s. At the fitted bore the run's
    own transition-time difference must land in 0.35 .. 0.45 s (the 0.4's one digit;
    the fit interpolates the grid, so this is a real check of the interpolation); the
    interval brackets the fit; the plant file's bore lies inside it; the a-priori 4 mm
    bore does not give the 0.4 s (below 0.2 s: the disagreement the fit resolves)."""
    s = run[1]
    fit = s["tube_bore_fit"]
    assert fit["lo"] < fit["d"] < fit["hi"]
    assert 0.35 <= s["transients_s"]["dt"] <= 0.45
    text = (ROOT / "designs" / "plants" / "papers" / "iliev_lines_1m.toml").read_text()
    file_bore = tomllib.loads(text)["lines"]["diameter"]
    assert fit["lo"] <= file_bore <= fit["hi"]
    grid = {round(g["diameter"] * 1e4): g for g in fit["grid"]}
    assert grid[40]["dt"] < 0.2
    dts = [g["dt"] for g in fit["grid"]]      # narrower tube, slower 10 m drive
    assert all(a > b for a, b in zip(dts, dts[1:]))
    row = _rows(s)["transition time difference, 10 m minus 1 m"]
    assert row["workbench"] == pytest.approx(s["transients_s"]["dt"], rel=1e-12)
    assert row["agrees"]


def test_eq4_attenuation_factor_recomputed(run):
    """Eq. (4)'s exp(-R_r 9 m / (2 rho a_s)) recomputed here for each bore of the grid:
    R_r = 32 mu / d^2 (Hagen-Poiseuille, mu = 1.81e-5 Pa s), rho = p / (R T) at the
    run's rest pressure, a_s = 343 m/s; 1e-4 (R = 287.05 here, 287.0 in the workbench:
    2e-4 of an exponent below 1). The
    factor falls with the bore and the measured peak-flow ratio lies below it (the
    lumped line also stores and holds back flow)."""
    s = run[1]
    for g in s["tube_bore_fit"]["grid"]:
        rho = g["p_rest"] / (287.05 * 293.15)
        expected = np.exp(-32 * 1.81e-5 / g["diameter"] ** 2 * 9.0 / (2 * rho * A_SOUND))
        assert g["eq4"] == pytest.approx(expected, rel=1e-4)
        assert g["flow_ratio"] < g["eq4"]
    fac = [g["eq4"] for g in s["tube_bore_fit"]["grid"]]
    assert all(0 < f < 1 for f in fac) and all(a < b for a, b in zip(fac, fac[1:]))


def test_step_size_moves_the_transition_time(run):
    """The other size the paper does not give: at the fitted bore, a single 400 mm step
    up and back settles much later on the 10 m line than the staircase's 100 mm steps
    (measured 2.0 s against 0.4 s; 2x leaves room)."""
    s = run[1]
    big = next(b for b in s["step_sizes"] if b["step"] == 0.4)
    assert big["dt"] > 2 * s["transients_s"]["dt"]


def test_valve_derived_from_the_papers_cv():
    """Eq. (2)'s Cv = 0.274, X_T = 1 as the ISA gas law (1360 scfh, psia, degR),
    converted here independently: choked at x = X_T with Y = 2/3, the standard cubic
    foot at 60 degF and 14.696 psia, mass matched to ISO 6358's C p1 rho0 with rho0 =
    1.185 kg/m^3 (physics.md) at 293.15 K. 5e-4: R = 287.05 here against the
    workbench's 287.0, and the plant file carries 4 digits."""
    import runpy
    scfh = 0.0283168466 / 3600.0                      # m^3/s per standard ft^3/h
    psia = 6894.757                                   # Pa
    t_r = 293.15 * 9.0 / 5.0                          # degR
    q_std = 1360.0 * PAPER_CV * (1.0 / psia) * (2.0 / 3.0) * np.sqrt(PAPER_XT / t_r) * scfh
    rho_std = 101325.0 / (287.05 * (60.0 + 459.67) * 5.0 / 9.0)
    c_expected = q_std * rho_std / 1.185              # m^3/(s Pa), per Pa of p1
    data = tomllib.loads(
        (ROOT / "designs" / "plants" / "papers" / "iliev_lines_1m.toml").read_text())
    assert data["valve"]["sonic_conductance"] == pytest.approx(c_expected, rel=5e-4)
    mod = runpy.run_path(str(ROOT / "designs" / "paper_001.py"), run_name="valve")
    c, b, dev = mod["valve_from_cv"](PAPER_CV, PAPER_XT)
    assert c == pytest.approx(c_expected, rel=5e-4)
    # b: the ISO ellipse through the law's shape; the law at x = 0.5 (p2/p1 = 0.5) is
    # (1 - 1/6) sqrt(0.5) / (2/3) = 0.884 of choked; the ellipse there within 1 %
    r = 0.5
    iso = np.sqrt(1 - ((r - b) / (1 - b)) ** 2)
    assert iso == pytest.approx((1 - 0.5 / 3) * np.sqrt(0.5) / (2 / 3), abs=0.01)
    assert dev < 0.01 and data["valve"]["critical_pressure_ratio"] == pytest.approx(b, abs=5e-4)


def test_pid_designed_and_validated_on_both(run):
    s = run[1]
    pid = s["pid"]
    assert pid["kp"] > 0 and pid["kd"] > 0 and pid["ki"] > 0
    assert pid["sample_time"] == 0.01
    # K0 = kp Kv a third of the exact sampled-data limit (or lower after back-offs)
    assert pid["kp"] * s["design"]["kv"] <= s["design"]["limit"] / 3.0 * (1 + 1e-9)
    # Ti = (specified settling time 1.5 s) / 4, ki = kp / Ti; band 2 x the 1 mm floor
    assert pid["ki"] == pytest.approx(pid["kp"] / (1.5 / 4.0), rel=1e-9)
    assert pid["integral_band"] == pytest.approx(2e-3)
    for L in ("1", "10"):
        assert s["validation"][L]["passed"] is True
    assert _rows(s)["PID positioning works with both line lengths"]["agrees"]


def test_integral_removes_a_valve_null_offset(run):
    """With the valve's zero-flow command u0 V above the controller's centre, a PD
    loop must rest where kp e = u0 (the valve closed, no load): e = u0 / kp, computed
    here; 0.25 mm covers the 12-bit sensor's 0.12 mm quantum and the hold end's
    residual motion. The PID (integral) removes it and passes; the same PID without its
    separation band fails (the integral's error area returns as overshoot)."""
    s = run[1]
    cmp_ = s["integral_comparison"]
    e_pd = float(cmp_["PD, valve null offset"]["steady_state_error_mm"]) * 1e-3
    assert e_pd == pytest.approx(s["pid"]["null_offset_v"] / s["pid"]["kp"], abs=2.5e-4)
    assert e_pd > 1e-3                        # the offset fails the 1 mm spec
    assert not cmp_["PD, valve null offset"]["passed"]
    assert "steady-state error" in cmp_["PD, valve null offset"]["failed"]
    assert cmp_["PID, valve null offset"]["passed"]
    assert float(cmp_["PID, valve null offset"]["steady_state_error_mm"]) < 1.0
    assert cmp_["PID"]["passed"] and cmp_["PD (ki = 0)"]["passed"]
    assert not cmp_["PID without band"]["passed"]


def test_plant_file_marks_assumptions():
    text = (ROOT / "designs" / "plants" / "papers" / "iliev_lines_1m.toml").read_text()
    data = tomllib.loads(text)
    assert data["lines"]["length"] == 1.0
    marks = {"bore =": "ASSUMED", "mass =": "ASSUMED", "pressure = 7": "ASSUMED",
             "diameter =": "ESTIMATED", "sonic_conductance =": "DERIVED",
             "critical_pressure_ratio =": "DERIVED"}
    for key, mark in marks.items():
        line = next(ln for ln in text.splitlines() if ln.strip().startswith(key))
        assert mark in line, line


def test_report_first_table_is_the_papers(run):
    out, _ = run
    html = (out / "report.html").read_text()
    first = html[html.index("<table"):html.index("</table>")]
    for head in ("paper", "workbench", "how obtained", "agrees?"):
        assert head in first
    assert (out / "report.pdf").stat().st_size > 10_000


def test_bad_out_is_refused_before_any_work(tmp_path, capsys):
    import runpy
    afile = tmp_path / "a_file"
    afile.write_text("not a folder")
    mod = runpy.run_path(str(Path(__file__).resolve().parents[1] / "designs" / "paper_001.py"),
                         run_name="design")
    with pytest.raises(SystemExit) as exc:
        mod["main"](["--quick", "--out", str(afile)])
    assert exc.value.code == 2
    assert "not a folder" in capsys.readouterr().err
