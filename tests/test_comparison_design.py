"""The joint PD / FL / NMPC report runs end to end (quick mode) and says what it found.

One quick run (module fixture, ~15 s) serves every test. Its verdict is the quick-mode
verdict of ``designs/nonlinear_comparison.py`` (``QUICK_IAE_FACTOR``): the NMPC passes
the validation on both plants and its IAE on the full plant is at most 1/1.5 of the
PD's (measured 2.38). The headline numbers are recomputed here from the validation
trajectories the design writes as CSV, by the trapezoid rule, not by the code that
made them.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import run_design

#: one quick run, shared with test_designs.py and test_report_designs.py (conftest)
pytestmark = pytest.mark.design("nonlinear_comparison")

CONTROLLERS = ("PD", "FL", "NMPC")


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("nonlinear_comparison")
    rc, summary = run_design("nonlinear_comparison", out, "--no-jit", "--workers", "2")
    return rc, out, summary


def _trapezoid(y: np.ndarray, t: np.ndarray) -> float:
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))


def _trajectory(out: Path, name: str, where: str) -> pd.DataFrame:
    return pd.read_csv(out / f"validation_{name.lower()}_{where}.csv", comment="#")


def test_joint_report_compares_three_controllers_with_robustness(quick_run):
    rc, tmp_path, s = quick_run
    html = (tmp_path / "report.html").read_text()
    assert (tmp_path / "report.pdf").read_bytes().startswith(b"%PDF")
    for heading in ("Validation and comparison", "Robustness", "Paper 002 bounds, full plant",
                    "Controllers", "Provenance"):
        assert heading in html
    for quantity in ("IAE", "air drawn from the supply", "command activity",
                     "worst settling time", "worst overshoot", "worst steady-state error"):
        assert quantity in html
    assert rc == (0 if s["design_passed"] else 1)
    assert set(s["figures"]["full"]) == {"PD", "FL", "NMPC"}
    for key in ("default_full", "default_nominal", "paper002_full"):
        r = s["robustness"][key]
        assert r["seed"] == 2026 and len(r["draws"]) == 2
        assert set(r["controllers"]) == {"PD", "FL", "NMPC"}
        rows = list(csv.DictReader((tmp_path / f"robustness_{key}.csv").open()))
        assert len(rows) == 2
        # the CSV says the same as the JSON, draw by draw
        for i, row in enumerate(rows):
            for name in ("PD", "FL", "NMPC"):
                assert bool(int(row[f"{name}_passed"])) == r["controllers"][name]["passed"][i]
    # the same seed draws the same plants for every set with the same ranges
    assert s["robustness"]["default_full"]["draws"] == s["robustness"]["default_nominal"]["draws"]


def test_quick_verdict_is_judged_and_passes(quick_run):
    rc, out, s = quick_run
    assert s["quick"] is True and s["quick_iae_factor"] == 1.5
    val = s["validations"]
    nmpc_ok = val["full"]["NMPC"]["passed"] and val["nominal"]["NMPC"]["passed"]
    ratio = s["iae_ratio_pd_over_nmpc_full"]
    # the verdict follows its rule, and on this run the rule holds: a pass, rc 0
    assert s["design_passed"] == bool(nmpc_ok and ratio >= 1.5)
    assert s["design_passed"] is True and rc == 0
    assert "PASS" in (out / "report.html").read_text()


def test_headline_numbers_from_the_trajectories(quick_run):
    _, out, s = quick_run
    iae = {}
    for where in ("full", "nominal"):
        for name in CONTROLLERS:
            d = _trajectory(out, name, where)
            t = d["t"].to_numpy()
            e = np.abs(d["x"].to_numpy() - d["r"].to_numpy())
            iae[where, name] = _trapezoid(e, t)
            fig = s["figures"][where][name]
            # the CSV holds the run at full precision (repr floats): the same sums to
            # rounding, 1e-9 relative
            assert fig["iae"] == pytest.approx(iae[where, name], rel=1e-9)
            assert fig["air_kg"] == pytest.approx(_trapezoid(d["q_supply"].to_numpy(), t),
                                                  rel=1e-9)
            assert fig["max_error"] == pytest.approx(float(e.max()), rel=1e-9)
    ratio = iae["full", "PD"] / iae["full", "NMPC"]
    assert s["iae_ratio_pd_over_nmpc_full"] == pytest.approx(ratio, rel=1e-9)
    assert ratio >= 1.5                      # the quick verdict's factor (measured 2.38)
    assert s["iae_ratio_pd_over_fl_full"] == pytest.approx(iae["full", "PD"] / iae["full", "FL"],
                                                           rel=1e-9)
    # the NMPC's runs, checked against the plant file and the Specification's limits
    # (validate.Specification defaults: steady-state error 1 mm, chamber pressures
    # between atmosphere - 0.2 bar and supply + 0.2 bar; rig25_mpye.toml: 6 bar supply)
    for where in ("full", "nominal"):
        d = _trajectory(out, "NMPC", where)
        assert abs(d["x"].iloc[-1] - d["r"].iloc[-1]) < 1e-3
        p = np.concatenate([d["p_a"].to_numpy(), d["p_b"].to_numpy()])
        assert p.min() >= 101325.0 - 0.2e5 and p.max() <= 6e5 + 0.2e5
    # Monte Carlo: the NMPC passes every quick draw of every set (measured 2/2 each)
    for key, r in s["robustness"].items():
        assert all(r["controllers"]["NMPC"]["passed"]), key
