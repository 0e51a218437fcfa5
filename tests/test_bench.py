"""The benchmarks' JSON (workbench.bench): the common schema in quick mode, and the
baselines reaching the accuracy they are compared at. Timings are not asserted (the
machine is shared); the accuracy of every method is, against independent references
(scipy Radau at rtol 1e-9, the numpy RLS loop, the point-by-point loop)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench.bench import timing


def _check_stats(d: dict) -> None:
    assert d["median_s"] > 0
    for kind in ("wall_s", "cpu_s"):
        q = d["spread"][kind]
        assert q["min"] <= q["q25"] <= q["median"] <= q["q75"] <= q["max"]
    assert d["spread"]["wall_s"]["median"] == pytest.approx(d["median_s"])


def _check_schema(res: dict, name: str) -> None:
    json.dumps(res)                                    # plain data
    assert res["benchmark"] == name
    _check_stats(res)
    assert "error" in res or "cost" in res
    assert res["baselines"], "a benchmark needs at least one baseline"
    for row in res["baselines"].values():
        assert {"median_s", "error", "ratio", "description", "available"} <= set(row)
        if row["available"]:
            assert row["ratio"] == pytest.approx(row["median_s"] / res["median_s"])
        else:
            assert row["reason"] and row["ratio"] is None


def test_timing_helpers():
    calls = []
    res, stats = timing.interleaved({"a": lambda: calls.append("a") or 1,
                                     "b": lambda: calls.append("b") or 2}, repeats=3)
    assert res == {"a": 1, "b": 2}
    assert calls == ["a", "b"] * 4                     # warm-up, then round-robin
    assert stats["a"]["spread"]["repeats"] == 3
    row = timing.baseline({"median_s": 2.0}, 0.5, 1e-3, "x")
    assert row["ratio"] == 4.0 and row["available"]
    row = timing.baseline({"median_s": 2.0, "cpu_median_s": 0.3}, 0.5, 1e-3, "x", ours_cpu_s=0.1)
    assert row["cpu_ratio"] == pytest.approx(3.0) and "cpu_ratio" not in timing.baseline(
        {"median_s": 2.0}, 0.5, 1e-3, "x")
    assert timing.unavailable("x", "why")["ratio"] is None


def test_bench_rls_schema_and_baseline_accuracy():
    from workbench.bench import run
    res = run("rls", quick=True)
    _check_schema(res, "rls")
    # same arithmetic as the numpy loop: differences are rounding (1e-9 of O(1) estimates)
    assert res["error"] < 1e-9
    nb = res["baselines"]["numba_loop"]
    if nb["available"]:
        assert nb["error"] < 1e-9 and nb["std_rel_difference"] < 1e-6
    assert res["baselines"]["numpy_loop"]["error"] == 0.0


def test_bench_rls_without_numba(monkeypatch):
    from workbench.bench import baselines_rls, run
    monkeypatch.setattr(baselines_rls, "unavailable_reason", lambda: "numba is not installed")
    res = run("rls", quick=True)
    row = res["baselines"]["numba_loop"]
    assert not row["available"] and "numba" in row["reason"]


def test_bench_sweep_schema_and_agreement():
    from workbench.bench import run
    res = run("sweep", quick=True)
    _check_schema(res, "sweep")
    # the map and both loops compute the same spectral radius: 1e-9 is rounding in the
    # equilibrium solve and the eigenvalues
    assert res["error"] < 1e-9
    assert res["baselines"]["python_control_loop"]["error"] < 1e-9
    assert res["baselines"]["batched_numpy_casadi"]["error"] < 1e-9


def test_bench_simulate_case_schema_and_accuracy():
    # one short case with one rung per ladder (the full bench calibrates on long ladders)
    from workbench.bench import simulate
    plant, _ = simulate.cases(quick=True)["rig25_4_states"]
    res = simulate._case(plant, 1.0, True, cvodes_ladder=(1e-4,), rk4_ladder=(8,))
    json.dumps(res)
    _check_stats(res)
    bound = 1e-3 * plant.stroke
    assert res["accuracy_bound_m"] == bound
    assert res["within_bound"] and res["error"] < bound
    assert res["realtime_factor"] == pytest.approx(1.0 / res["median_s"])
    assert res["realtime_factor_cpu"] == pytest.approx(1.0 / res["cpu_median_s"])
    assert res["wall_over_cpu"] == pytest.approx(res["median_s"] / res["cpu_median_s"])
    assert res["steps"] >= 100 and res["native"] in (True, False)
    for name in ("cvodes_mapaccum", "rk4_compiled"):
        row = res["baselines"][name]
        assert row["available"] and row["within_bound"] and row["error"] <= bound
        assert row["ratio"] == pytest.approx(row["median_s"] / res["median_s"])
    assert np.isfinite(res["baselines"]["scipy_lsoda_per_period"]["error"])


def test_bench_mpc_lockstep_scores():
    # the lockstep loop and the scores on a short run of ours only (the full benchmark
    # builds IPOPT, do-mpc and OSQP baselines: minutes, not for the suite)
    from workbench import Plant
    from workbench.bench import mpc
    from workbench.controllers.mpc import NMPC
    plant = Plant.from_toml("designs/plants/rig25_mpye.toml")
    nmpc = NMPC.for_plant(plant, horizon=10, sample_time=0.01, disturbance_gain=0.0,
                          jit=False)
    ref = mpc.bench_reference(plant, 20.0)
    runs = mpc.lockstep(plant, {"rti": nmpc}, ref, 0.3, nmpc)
    sc = mpc._scores(runs["rti"], nmpc, 0.01)
    _check_stats(sc)
    assert len(runs["rti"]["wall"]) == 30 and sc["cpu_p99_ms"] > 0
    # the cost is a sum of squares of the tracking error (the reference starts where
    # the piston rests, then holds): finite and >= 0; IAE <= duration x largest error
    assert 0.0 <= sc["cost"] < np.inf
    assert sc["iae_m_s"] <= 0.3 * sc["max_error_m"] + 1e-12


def test_plain_rti_baseline_has_the_cost_weights():
    # The plain RTI's QP Hessian once lacked the cost weights (evaluated with the
    # parameters at 0: an LP OSQP could not solve). Its diagonal at node k's position
    # and velocity must be the weights (L / position_tolerance)^2 and
    # (1 m/s / velocity_tolerance)^2 (x terminal_factor at node N), computed here from
    # the settings; node 0 and the pressures carry no cost (the regularisation only).
    from workbench import Plant
    from workbench.bench.baselines_mpc import cost_hessian
    from workbench.controllers.mpc import NMPC
    plant = Plant.from_toml("designs/plants/rig25_mpye.toml")
    nmpc = NMPC.for_plant(plant, horizon=5, sample_time=0.01, disturbance_gain=0.0,
                          jit=False)
    pb = nmpc._problem
    d = np.asarray(cost_hessian(pb.ipopt._nlp(), pb.P, 1e-8).full()).diagonal()
    wx = (plant.stroke / nmpc.position_tolerance) ** 2
    wv = (1.0 / nmpc.velocity_tolerance) ** 2
    for k in range(1, 6):
        f = nmpc.terminal_factor if k == 5 else 1.0
        assert d[4 * k] == pytest.approx(f * wx + 1e-8, rel=1e-12)
        assert d[4 * k + 1] == pytest.approx(f * wv + 1e-8, rel=1e-12)
        assert d[4 * k + 2] == d[4 * k + 3] == pytest.approx(1e-8, rel=1e-12)
    assert d[0] == pytest.approx(1e-8, rel=1e-12)


def test_bench_mpc_targets_met_judges_each_configuration():
    # synthetic scores (no timing): a configuration meets a target only if its own
    # figure is on the right side of it; the plain RTI missing leaves the ratio unjudged
    from workbench.bench.mpc import TARGETS, targets_met

    def row(med, p99, cost):
        return {"median_s": med, "cpu_p99_ms": p99, "cost": cost}
    sc = {"sqp": row(1e-4, 0.3, 100.0), "rti": row(1e-4, 0.3, 102.0),
          "sqp2": row(1e-4, 0.3, 100.5), "adaptive": row(1e-4, 0.3, 100.05),
          "plain_rti_osqp": row(1.2e-3, 2.0, 100.1)}
    alone = {"rti": {"median_s": 0.9e-4, "cpu_p99_ms": 0.2, "ratio_plain_rti_osqp": 12.0},
             "sqp2": {"median_s": 2e-4, "cpu_p99_ms": 0.2, "ratio_plain_rti_osqp": 12.0},
             "adaptive": {"median_s": 0.9e-4, "cpu_p99_ms": 0.6, "ratio_plain_rti_osqp": 9.0}}
    out = targets_met(sc, alone, {"friction": {"ratio": 1.2}, "lines": {"ratio": 3.5}})
    assert out["rti"]["met"]["cost_vs_converged"] is False      # +2 % > 1 %
    assert out["rti"]["met"]["median_s"] and out["rti"]["met"]["ratio_plain_rti_osqp"]
    assert out["sqp2"]["met"]["median_s"] is False                # 0.2 ms > 0.15 ms
    assert out["adaptive"]["met"]["cpu_p99_ms"] is False and not out["adaptive"]["all"]
    assert out["adaptive"]["met"]["ratio_plain_rti_osqp"] is False   # 9x < 10x
    assert out["adaptive"]["ratio_plain_rti_osqp_lockstep"] == pytest.approx(12.0)
    assert out["adaptive"]["cost_vs_converged"] == pytest.approx(5e-4)
    assert out["variants"] == {"worst_ratio": 3.5, "met": False}
    assert TARGETS["ratio_plain_rti_osqp"] == 10.0 and TARGETS["median_s"] == 0.15e-3
    none = targets_met(sc, {k: {**v, "ratio_plain_rti_osqp": None} for k, v in alone.items()},
                       {})
    assert none["rti"]["met"]["ratio_plain_rti_osqp"] is None and not none["rti"]["all"]
