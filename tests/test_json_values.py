"""Values of the JSON outputs (issue 17): every key of ``check --json``, ``linearize --json``
and ``simulate``'s fit.json against an independent computation written here.

Sources: physics.md (ISO 6358 datasheet form, rho0 = 1.185 kg/m^3 at 293.15 K, 1 bar: the
ANR convention of ``workbench.units``; paper 000 w0/zeta formulas), formats.md section 4
(fit = 100 (1 - ||y - y_m|| / ||y - mean y||)); central differences of ``plant.evaluate_f``.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from workbench import Plant
from workbench.__main__ import main

from conftest import central_jacobian, write_plant

ROOT = Path(__file__).resolve().parents[1]
SITUM = ROOT / "designs" / "plants" / "situm_rodless_nominal.toml"
RIG25 = ROOT / "designs" / "plants" / "rig25_mpye.toml"
REC = ROOT / "tests" / "data" / "recordings" / "step_small.csv"
RHO_ANR = 1.185          # kg/m^3 at 20 degC, 1 bar (physics.md, ISO 6358 datasheet form)


def _read_csv(path):
    """Columns of a formats.md CSV by name, skipping '#' lines (plain Python, no workbench)."""
    lines = [ln for ln in Path(path).read_text().splitlines() if ln and not ln.startswith("#")]
    names = lines[0].split(",")
    rows = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    return {n: rows[:, i] for i, n in enumerate(names)}


def _run_json(capsys, argv):
    capsys.readouterr()
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("path, kind", [(SITUM, "p"), (RIG25, "pd"), ("rod", "p")],
                         ids=["situm", "rig25", "situm_with_rod"])
def test_check_json_values(capsys, tmp_path, path, kind):
    """Every key of ``check --json`` by hand from the TOML (read with tomllib, not the plant).

    Both shipped plants are rodless (A_a = A_b, equal dead volumes), so a third case gives
    the Situm rig an 8 mm rod and unequal dead volumes: an A/B mix-up must show.
    """
    import tomllib
    if path == "rod":
        path = tmp_path / "rod.toml"
        path.write_text(SITUM.read_text()
                        .replace("rod_diameter = 0.0 ", "rod_diameter = 0.008 ")
                        .replace("dead_volume_b = 2.0e-6", "dead_volume_b = 3.5e-6"))
        assert "0.008" in path.read_text() and "3.5e-6" in path.read_text()
    toml = tomllib.loads(path.read_text())
    cyl, gas = toml["cylinder"], toml.get("gas", {})
    bore, stroke = cyl["bore"], cyl["stroke"]
    rod = cyl.get("rod_diameter", 0.0)
    p_s, p_atm = toml["supply"]["pressure"], gas.get("atmospheric_pressure", 101325.0)
    temp = gas.get("temperature", 293.15)
    d = _run_json(capsys, ["check", str(path), "--json"])
    a_a = math.pi / 4 * bore ** 2
    a_b = math.pi / 4 * (bore ** 2 - rod ** 2)
    # 1e-12 relative: the same closed forms, only rounding differs
    assert d["area_a_m2"] == pytest.approx(a_a, rel=1e-12)
    assert d["area_b_m2"] == pytest.approx(a_b, rel=1e-12)
    assert d["stroke_m"] == pytest.approx(stroke, rel=1e-12)
    assert d["volume_a_max_m3"] == pytest.approx(a_a * stroke + cyl["dead_volume_a"], rel=1e-12)
    assert d["volume_b_max_m3"] == pytest.approx(a_b * stroke + cyl["dead_volume_b"], rel=1e-12)
    assert d["max_force_extend_N"] == pytest.approx((p_s - p_atm) * a_a, rel=1e-12)
    assert d["max_force_retract_N"] == pytest.approx((p_s - p_atm) * a_b, rel=1e-12)
    # ISO 6358, choked at full opening (p_atm / p_s < b): q = C p_s rho0 sqrt(T0 / T)
    valve = toml["valve"]
    assert p_atm / p_s < valve["critical_pressure_ratio"]
    q = valve["sonic_conductance"] * p_s * RHO_ANR * math.sqrt(293.15 / temp)
    assert d["valve_flow_full_opening_kg_s"] == pytest.approx(q, rel=1e-12)
    # l/min ANR: volume at rho0 = 1.185 kg/m^3, 1000 l/m^3, 60 s/min
    assert d["valve_flow_full_opening_l_min_anr"] == pytest.approx(q / RHO_ANR * 1e3 * 60, rel=1e-12)
    assert d["valve_law"] == "iso6358"
    assert d["effects"] == []
    assert d["states"] == ["x", "v", "p_a", "p_b"]
    # parameters of a plant without effects, counted by hand (formats.md): gas 3 (T, k,
    # p_atm), supply 1, valve 4 (C, b, command centre and span; min/max are limits, not
    # parameters), cylinder 5, load 3 (mass, k_f, external force, default 0)
    assert d["parameters"] == 3 + 1 + 4 + 5 + 3
    assert d["controller"] == toml["controller"] and d["controller"]["kind"] == kind
    assert d["name"] == toml["name"]


@pytest.fixture(scope="module", params=[SITUM, RIG25], ids=["situm", "rig25"])
def lin_json(request):
    """``linearize PLANT --x 0.25 --json`` (mid stroke) once per plant for the module."""
    import contextlib
    import io
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["linearize", str(request.param), "--x", "0.25", "--json"]) == 0
    return request.param, json.loads(buf.getvalue())


def test_linearize_equilibrium_and_matrices(lin_json):
    """Equilibrium solves f = 0; A, B by central differences of f; C, D of h; eigenvalues."""
    path, d = lin_json
    plant = Plant.from_toml(path)
    eq = d["equilibrium"]
    x_e = np.array([eq["state"][n] for n in d["states"]])
    u_e = eq["u"]
    assert eq["x"] == x_e[0] == 0.25 and x_e[1] == 0.0
    assert d["plant"] == str(path) and d["inputs"] == ["u"]
    assert d["states"] == ["x", "v", "p_a", "p_b"]
    assert d["outputs"] == ["x", "v", "p_a", "p_b", "p_s", "q_supply", "force"]
    assert eq["p_a"] == x_e[2] and eq["p_b"] == x_e[3]
    # force balance of a symmetric rodless cylinder at rest: p_a A = p_b A
    assert eq["p_a"] == pytest.approx(eq["p_b"], rel=1e-9)
    f_e = plant.evaluate_f(x_e, u_e)
    # scaled residual ~ machine precision; the reported one is that small too
    assert np.max(np.abs(f_e / plant.state_scales())) < 1e-9
    assert 0.0 <= eq["residual"] < 1e-9
    # central differences: relative steps 1e-6 of each state's scale, error O(h^2) ~ 1e-10
    sc = plant.state_scales()
    hu = 1e-6 * 10.0
    a_fd, b_fd = central_jacobian(plant.evaluate_f, x_e, u_e, sc, hu)
    a, b = np.array(d["A"]), np.array(d["B"])[:, 0]
    # tolerance: 1e-6 of each row's largest entry (FD truncation + rounding ~1e-8)
    for i in range(4):
        tol = 1e-6 * max(np.max(np.abs(a_fd[i])), np.abs(b_fd[i]), 1e-12)
        np.testing.assert_allclose(a[i], a_fd[i], atol=tol, rtol=0)
        np.testing.assert_allclose(b[i], b_fd[i], atol=tol, rtol=0)
    c_fd, d_fd = central_jacobian(plant.evaluate_h, x_e, u_e, sc, hu)
    c, dd = np.array(d["C"]), np.array(d["D"])[:, 0]
    for i in range(7):
        tol = 1e-6 * max(np.max(np.abs(c_fd[i])), np.abs(d_fd[i]), 1e-12)
        np.testing.assert_allclose(c[i], c_fd[i], atol=tol, rtol=0)
        np.testing.assert_allclose(dd[i], d_fd[i], atol=tol, rtol=0)
    # eigenvalues of the FD matrix (numpy), matched as sorted sets; 1e-5 rad/s absolute
    ev = np.sort_complex(np.array([complex(e["re"], e["im"]) for e in d["eigenvalues"]]))
    np.testing.assert_allclose(ev, np.sort_complex(np.linalg.eigvals(a_fd)), atol=1e-4)


def test_linearize_reduced_model_paper_formulas(lin_json):
    """Kv, w0, zeta by the paper 000 formulas (physics.md) at the equilibrium pressure."""
    import tomllib
    path, d = lin_json
    toml = tomllib.loads(path.read_text())
    p = d["equilibrium"]["p_a"]
    area = math.pi / 4 * toml["cylinder"]["bore"] ** 2
    kappa, m, kf = toml["gas"]["polytropic_index"], toml["load"]["mass"], toml["load"]["viscous_friction"]
    # Vc = both chambers at x = 0.25 (the paper's A L with the dead volumes)
    vc = 2 * (area * 0.25 + toml["cylinder"]["dead_volume_a"])
    w0 = math.sqrt(4 * kappa * p * area ** 2 / (m * vc))
    zeta = kf / 2 * math.sqrt(vc / (4 * kappa * p * area ** 2 * m))
    red = d["reduced_model"]
    # exact reduction of a symmetric plant at mid stroke: only rounding differs
    assert red["w0"] == pytest.approx(w0, rel=1e-9)
    assert red["zeta"] == pytest.approx(zeta, rel=1e-9)
    # Kv: steady velocity per volt, from p_a' = 0 (B_pa u = -A_pa,v v), FD-checked above
    a, b = np.array(d["A"]), np.array(d["B"])
    assert red["Kv"] == pytest.approx(b[2, 0] / -a[2, 1], rel=1e-9)
    if path == SITUM:      # Table II, the TOML comment's design target
        assert red["Kv"] == pytest.approx(0.70, abs=0.005)
    assert 0 <= red["fit_error"] < 1e-9
    lo, hi = red["band_rad_s"]
    assert lo < w0 < hi
    assert d["notes"] == []


def test_simulate_fit_json_is_nrmse(tmp_path):
    """fit.json = 100 (1 - ||y - y_m|| / ||y - mean y||) (formats.md 4), from the CSVs."""
    out = tmp_path / "sim"
    assert main(["simulate", str(SITUM), str(REC), "--out", str(out), "--quiet"]) == 0
    fits = json.loads((out / "fit.json").read_text())
    rec, sim = _read_csv(REC), _read_csv(out / "simulation.csv")
    assert set(fits) == {"x", "p_a", "p_b"}
    np.testing.assert_allclose(sim["t"], rec["t"], atol=1e-9)
    for k, v in fits.items():
        y, ym = rec[k], sim[k]
        ref = 100 * (1 - np.linalg.norm(y - ym) / np.linalg.norm(y - y.mean()))
        # 1e-6 %: the CSV rounds the simulated signals to its printed digits
        assert v == pytest.approx(ref, abs=1e-4)


def _fd_tangent(plant, x_e, u_e):
    """A, B of ``plant.evaluate_f`` by central differences (steps 1e-6 of each scale)."""
    sc = plant.state_scales()
    a = np.zeros((len(x_e), len(x_e)))
    for j in range(len(x_e)):
        e = np.zeros(len(x_e))
        e[j] = 1e-6 * sc[j]
        a[:, j] = (plant.evaluate_f(x_e + e, u_e) - plant.evaluate_f(x_e - e, u_e)) / (2 * e[j])
    b = (plant.evaluate_f(x_e, u_e + 1e-5) - plant.evaluate_f(x_e, u_e - 1e-5)) / 2e-5
    return a, b[:, None]


def test_map_json_rho_against_python_control(tmp_path, capsys):
    """map.json axes, rho[y][x] at every point = max |z| of python-control's c2d (ZOH) of the
    FD tangent x/u, minimal realisation, closed by the discrete P law u = kp (r - x)."""
    import control
    from scipy import signal
    from workbench.equilibrium import operating_point
    out = tmp_path / "map"
    import time
    t0 = time.perf_counter()
    d = _run_json(capsys, ["map", str(SITUM), "--x-axis", "kp=5:20:3", "--y-axis",
                           "load.mass=0.5:1.5:2", "--out", str(out), "--json", "--no-plot",
                           "--workers", "1", "--quiet"])
    d_wall = time.perf_counter() - t0
    m = json.loads((out / "map.json").read_text())
    assert m["x"]["name"] == "kp" and m["y"]["name"] == "load.mass"
    np.testing.assert_allclose(m["x"]["values"], [5.0, 12.5, 20.0], rtol=1e-12)
    np.testing.assert_allclose(m["y"]["values"], [0.5, 1.5], rtol=1e-12)
    assert m["position_m"] == 0.25 and m["controller"]["sample_time"] == 0.01
    assert d["stable_fraction"] == m["stable_fraction"]
    assert m["fallbacks"] == d["fallbacks"] == 0          # no point needed the slow path
    # throughput: the 6 points over the reported wall time (rounding only)
    assert m["points_per_s"] == pytest.approx(6 / m["elapsed_s"], rel=1e-9)
    # timing: a positive float, no longer than the whole command measured in the test
    assert isinstance(m["elapsed_s"], float) and 0.0 < m["elapsed_s"] <= d_wall
    assert {Path(v).name for v in d["files"].values()} == {"map.csv", "map.json", "map.png"}
    assert (out / "map.csv").exists() and Path(d["files"]["json"]) == out / "map.json"
    rho = np.array(m["rho"])
    assert rho.shape == (2, 3)                  # rows: y (mass), columns: x (kp)
    base = Plant.from_toml(SITUM)
    for iy, mass in enumerate(m["y"]["values"]):
        plant = base.with_params(**{"load.mass": mass})
        op = operating_point(plant, 0.25)
        a, b = _fd_tangent(plant, np.asarray(op.state, float), op.u)
        num, den = signal.ss2tf(a, b, np.array([[1.0, 0, 0, 0]]), np.zeros((1, 1)))
        # the pressure-sum mode (s = 0) cancels: minimal x/u of order 3 (no slycot needed)
        g = control.tf(num[0], den).minreal(tol=1e-6)
        assert len(g.den[0][0]) == 4
        gz = control.c2d(g, 0.01, method="zoh")
        for ix, kp in enumerate(m["x"]["values"]):
            cl = control.feedback(kp * gz, 1)
            ref = np.max(np.abs(control.poles(cl)))
            # 1e-5: FD Jacobian (~1e-8 relative) through the closed-loop pole map
            assert rho[iy, ix] == pytest.approx(ref, abs=1e-5), (mass, kp)
    stable = (rho < 1).mean()
    assert m["stable_fraction"] == pytest.approx(stable)
    # the one hidden mode (pressure sum, |z| = 1 for a leak-free closed centre) is named
    assert any("hidden" in n for n in m["notes"])


def test_map_json_pid_against_python_control(tmp_path, capsys):
    """A PID map (kd axis, fixed kp, ki, 1 sample of delay): rho against python-control with
    the discrete law of ``controllers.pd.pid_law`` written out as a transfer function,
    C(z) = kp + kd (z - 1) / (T z) + ki T z / (z - 1), and the delay 1/z."""
    import control
    from scipy import signal
    from workbench.equilibrium import operating_point
    out = tmp_path / "pidmap"
    kp, ki, t_s = 8.0, 4.0, 0.01
    _run_json(capsys, ["map", str(SITUM), "--x-axis", "kd=0:0.08:3", "--y-axis",
                       "position=0.15:0.35:2", "--kp", str(kp), "--ki", str(ki), "--delay", "1",
                       "--out", str(out), "--json", "--no-plot", "--workers", "1", "--quiet"])
    m = json.loads((out / "map.json").read_text())
    assert m["x"]["name"] == "kd" and m["y"]["name"] == "position"
    assert m["delay_samples"] == 1
    assert m["controller"]["kp"] == kp and m["controller"]["ki"] == ki
    rho = np.array(m["rho"])
    plant = Plant.from_toml(SITUM)
    z = control.tf([1, 0], [1], t_s)
    for iy, pos in enumerate(m["y"]["values"]):
        op = operating_point(plant, pos)
        a, b = _fd_tangent(plant, np.asarray(op.state, float), op.u)
        num, den = signal.ss2tf(a, b, np.array([[1.0, 0, 0, 0]]), np.zeros((1, 1)))
        gz = control.c2d(control.tf(num[0], den).minreal(tol=1e-6), t_s, method="zoh")
        for ix, kd in enumerate(m["x"]["values"]):
            c = kp + kd * (z - 1) / (t_s * z) + ki * t_s * z / (z - 1)
            cl = control.feedback(c * gz / z, 1)
            ref = np.max(np.abs(control.poles(cl)))
            # 1e-5: FD Jacobian through the pole map (the integrator pole is not cancelled)
            assert rho[iy, ix] == pytest.approx(ref, abs=1e-5), (pos, kd)


def test_linearize_residual_recomputed_from_f(capsys, tmp_path):
    """``equilibrium.residual`` of ``linearize --json`` (issue 17), recomputed: the largest
    |f_i(x_e, u_e)| / (100 s_i) over every state but the position (equilibrium.py:
    RATE_PER_SCALE = 100 1/s, s_i = Plant.state_scales()), f evaluated here at the state
    and command the JSON prints. A plant with every effect that adds states (25 states)
    and an external load, so that the solver's residual is not exactly zero (measured
    5e-14 .. 2e-13): the two agree to 3e-8 relative (the printed state is the solver's to
    the last digit); 1e-4 allows for rounding of the largest row."""
    path = write_plant(tmp_path / "all.toml", ["leakage", "line_dynamics", "supply_droop",
                                               "heat_transfer", "valve_dynamics", "valve_offset"],
                       {"load.external_force": 15.0})
    d = _run_json(capsys, ["linearize", str(path), "--x", "0.1", "--json"])
    eq = d["equilibrium"]
    plant = Plant.from_toml(path)
    assert d["states"] == list(plant.state_names) and len(d["states"]) == 25
    x_e = np.array([eq["state"][n] for n in d["states"]])
    assert x_e[0] == 0.1 and x_e[1] == 0.0
    f = plant.evaluate_f(x_e, eq["u"])
    assert f[0] == 0.0                                    # dx/dt = v = 0: not a row
    rows = np.abs(f[1:]) / (100.0 * plant.state_scales()[1:])
    assert isinstance(eq["residual"], float)
    assert 0.0 < eq["residual"] < 1e-9
    # abs=0: pytest.approx would otherwise accept anything within 1e-12 of these 1e-13s
    assert eq["residual"] == pytest.approx(float(np.max(rows)), rel=1e-4, abs=0.0)
