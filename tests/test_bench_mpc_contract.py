"""Issue 16's contract of ``workbench bench NAME --json``: {"median_s", "spread",
"cpu_p99_ms" (mpc), "realtime_factor" (simulate, from the median), "error" or "cost",
"baselines": {name: {"median_s", "error", "ratio"}}} (:func:`workbench.bench.timing.
contract_problems`).

The quick runs of rls, sweep and greybox are tested in tests/test_bench.py and
tests/test_bench_greybox.py; those of simulate, mpc and diagnose take minutes (IPOPT,
do-mpc, whole diagnoses), so here their JSON is assembled from stand-in measurements
(the measuring parts have tests of their own) and printed through the command line,
and the checker itself is tested on what it must reject.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench.bench import timing
from workbench.bench.timing import contract_problems


def _good() -> dict:
    ours = timing.summary([2.0, 1.0, 3.0], [1.0, 1.0, 2.0])
    return {"benchmark": "rls", **ours, "error": 1e-12,
            "baselines": {"loop": timing.baseline(timing.summary([4.0], [4.0]), 2.0, 0.0, "x"),
                          "gone": timing.unavailable("y", "not installed")}}


def test_contract_checker_rejects_what_the_issue_asks_for():
    assert contract_problems(_good()) == []
    for key in ("median_s", "spread", "baselines"):
        bad = _good()
        del bad[key]
        assert contract_problems(bad), key
    bad = _good()
    del bad["error"]
    assert contract_problems(bad) == ["neither error nor cost"]
    bad = _good()
    bad["baselines"]["loop"]["ratio"] = 3.0                  # 4 s / 2 s is 2
    assert contract_problems(bad) == ["baseline loop: ratio is not its median_s / ours"]
    bad = _good()
    del bad["baselines"]["loop"]["error"]
    assert contract_problems(bad) == ["baseline loop lacks error"]
    bad = _good()
    bad["spread"]["wall_s"]["median"] = 1.5                  # not the headline median
    assert contract_problems(bad) == ["spread.wall_s.median is not median_s"]
    assert contract_problems({**_good(), "benchmark": "mpc"}) == ["cpu_p99_ms missing"]
    sim = {**_good(), "benchmark": "simulate", "simulated_s": 24.0, "realtime_factor": 10.0}
    assert contract_problems(sim) == ["realtime_factor is not simulated_s / median_s"]
    assert contract_problems({**sim, "realtime_factor": 12.0}) == []


def _cli_json(name: str, capsys) -> dict:
    from workbench.cli import main
    assert main(["bench", name, "--quick", "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_bench_diagnose_json_has_the_contract(monkeypatch, capsys):
    from workbench.bench import diagnose

    def one(name, duration, tmp):                            # a diagnosis stand-in
        wall = {"single_effect": 9.0, "two_effects": 40.0}[name]
        effect = diagnose.CASES[name][0]
        named = sorted(effect.split("+")) if name == "single_effect" else ["leakage"]
        return {"wall_s": wall, "cpu_s": wall / 2, "target_s": 15.0, "concealed": effect,
                "named": named, "correct": named == sorted(effect.split("+")),
                "candidate_models": 3, "candidates": 3, "samples": 8001, "stages_s": {},
                "report_write_s": 0.1, "make_recording_s": 0.1, "fit_before": {},
                "fit_after": {}}
    monkeypatch.setattr(diagnose, "_one", one)
    res = _cli_json("diagnose", capsys)
    assert contract_problems(res) == []
    assert res["median_s"] == 9.0 and res["spread"]["repeats"] == 1
    assert res["error"] == 0.5                               # one case of two misnamed
    assert res["baselines"] == {} and "no plain baseline" in res["baselines_note"]


def test_bench_simulate_json_has_the_contract(monkeypatch, capsys):
    from workbench.bench import simulate

    def case(plant, duration, quick):                        # a measurement stand-in
        st = timing.summary([0.002, 0.004, 0.003], [0.002, 0.003, 0.003])
        return {"states": 4, "simulated_s": duration, **st,
                "realtime_factor": duration / st["median_s"],
                "realtime_factor_cpu": duration / st["cpu_median_s"],
                "wall_over_cpu": st["median_s"] / st["cpu_median_s"], "error": 1e-4,
                "error_pct_stroke": 0.02, "within_bound": True,
                "baselines": {"rk4_compiled": timing.baseline(
                    timing.summary([0.006], [0.006]), st["median_s"], 2e-4, "rk4")}}
    monkeypatch.setattr(simulate, "cases", lambda quick: {"rig25_4_states": (None, 4.0),
                                                          "rig25_lines_valve": (None, 2.0)})
    monkeypatch.setattr(simulate, "_case", case)
    res = _cli_json("simulate", capsys)
    assert contract_problems(res) == []
    assert res["realtime_factor"] == pytest.approx(4.0 / res["median_s"], rel=1e-12)
    assert res["baselines"]["rk4_compiled"]["ratio"] == pytest.approx(2.0)


def _scores(med: float, cost: float) -> dict:
    st = timing.summary([med, 1.2 * med, 0.9 * med], [med, med, med])
    return {**st, "cpu_p99_ms": 2e3 * med, "cost": cost, "iae_m_s": 0.03}


def test_bench_mpc_rows_have_the_contract():
    # the baselines' rows: each against ours of its class (RTI with RTI, converged with
    # converged), ratio and error (closed-loop cost relative to ours - 1) from the scores
    from workbench.bench import mpc
    sc = {"rti": _scores(2e-5, 101.0), "sqp": _scores(5e-5, 100.0),
          "plain_rti_osqp": _scores(4e-4, 101.5), "ipopt_gauss_newton": _scores(1e-2, 100.0),
          "do_mpc_recommended": _scores(3e-2, 100.2)}
    rows = mpc._baseline_rows(sc, {k: object() for k in sc},
                              {"do_mpc_defaults": "do-mpc is not installed"})
    head = {"benchmark": "mpc", **{k: sc["rti"][k] for k in ("median_s", "cpu_median_s",
                                                            "spread", "cpu_p99_ms", "cost")},
            "baselines": rows}
    assert contract_problems(head) == []
    assert rows["plain_rti_osqp"]["ratio"] == pytest.approx(20.0)
    assert rows["plain_rti_osqp"]["error"] == pytest.approx(101.5 / 101.0 - 1)
    assert rows["ipopt_gauss_newton"]["ratio"] == pytest.approx(200.0)    # vs sqp
    assert rows["do_mpc_defaults"]["ratio"] is None
    # ours with the limits between the nodes: judged on the targets like the others
    alone = {"adaptive": {"cost": 100.0},
             "adaptive_interior_limits": {"median_s": 4e-5, "cpu_p99_ms": 0.6,
                                          "cost": 100.3, "ratio_plain_rti_osqp": 11.0}}

    class _Pb:
        n_rows, m_int = 312, 1
    row = mpc._interior_row(alone, type("C", (), {"pb": _Pb()})())
    assert row["met"] == {"median_s": True, "cpu_p99_ms": False, "ratio_plain_rti_osqp": True}
    assert row["cost_vs_adaptive"] == pytest.approx(3e-3) and row["rows"] == 312
    assert np.isfinite(row["median_s"])
