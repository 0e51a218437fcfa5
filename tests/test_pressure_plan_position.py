"""The position design by pressure-trajectory inversion runs end to end in smoke mode,
and its plans and closed-loop figures obey the physics they rest on."""

from __future__ import annotations

import json
import runpy
from pathlib import Path

import numpy as np
import pytest

from workbench import Plant
from workbench.controllers.force import DriveModel, motion_force, pressure_plan
from workbench.controllers.inversion import ValveInversion

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "designs" / "pressure_plan_position.py"


#: one quick run, shared with test_designs.py and test_report_designs.py (conftest)
pytestmark = pytest.mark.design("pressure_plan_position")


@pytest.fixture(scope="module")
def design():
    return runpy.run_path(str(DESIGN), run_name="design")


@pytest.fixture(scope="module")
def quick_report(design, tmp_path_factory):
    from conftest import run_design          # one quick run per session (test_designs too)
    out = tmp_path_factory.mktemp("pressure_plan_position")
    rc, summary = run_design("pressure_plan_position", out)
    return rc, out, summary


@pytest.fixture(scope="module")
def sv_plan(design):
    rig = Plant.from_toml(ROOT / "designs" / "plants" / "rig25_mpye.toml")
    model = DriveModel.from_plant(rig, valve=ValveInversion.from_plant(rig, law="input_affine"))
    ref = design["MinJerkTrajectory"](design["QUICK_WAYPOINTS"])
    t = np.arange(0.0, ref.duration + 1e-9, 1e-3)
    x = ref(t)
    force, v, a = motion_force(model, t, x)
    return model, ref, t, force, v, a, pressure_plan(model, t, force, x=x, v=v, rule="single_valve")


def test_report_written_and_passes(quick_report):
    rc, out, s = quick_report
    html = (out / "report.html").read_text()
    assert (out / "report.pdf").read_bytes().startswith(b"%PDF")
    for heading in ("Pressure-trajectory inversion", "Position control in closed loop", "Provenance"):
        assert heading in html
    assert html.count("data:image/png;base64,") >= 3
    assert rc == (0 if s["design_passed"] else 1)
    assert s["design_passed"] and not s["errors"]
    assert set(s["plans"]) == {"mean", "min_air", "single_valve"}
    assert len(s["metrics"]) == 6


def test_minimum_jerk_reference_is_consistent(sv_plan):
    _, ref, t, _, v, a, _ = sv_plan
    # the analytic derivatives match the sampled trajectory (1 ms central differences)
    assert np.max(np.abs(v - ref.velocity(t))) < 1e-3 * np.max(np.abs(v))
    inner = slice(5, -5)
    assert np.max(np.abs(a[inner] - ref.acceleration(t)[inner])) < 0.05 * np.max(np.abs(a))
    # a 250 mm quintic in 0.6 s peaks at 1.875 D / T = 0.78 m/s
    assert np.max(np.abs(ref.velocity(t))) == pytest.approx(1.875 * 0.25 / 0.6, rel=1e-3)
    for tt, xx in zip(ref.t, ref.x):
        assert float(ref(tt)) == pytest.approx(xx, abs=1e-12)


def test_single_valve_plan_is_one_valve_and_gives_the_force(sv_plan):
    model, _, t, force, v, a, plan = sv_plan
    assert plan.feasible
    # one 5/3 valve: both ports get the same command
    assert np.max(np.abs(plan.command_a - plan.command_b)) < 1e-9
    # the pressures produce the force the motion needs, F = m a + beta v + F_ext
    f_plan = model.force(plan.p_a, plan.p_b)
    assert np.allclose(f_plan, force, rtol=1e-6, atol=1e-6 * np.max(np.abs(force)))
    assert np.allclose(force, model.mass * a + model.viscous * v + model.external_force)
    # pressures between atmosphere and supply
    assert plan.p_a.min() > model.p_atm and plan.p_b.max() < model.p_s


def test_air_and_tracking_sane(quick_report):
    _, _, s = quick_report
    plans = s["plans"]
    # minimum air draws least; the mean level keeps the most stiffness of the two-valve rules
    assert plans["min_air"]["air_mass"] < plans["mean"]["air_mass"]
    assert plans["min_air"]["air_mass"] < plans["single_valve"]["air_mass"]
    assert plans["min_air"]["stiffness_min"] < plans["mean"]["stiffness_min"]
    assert plans["single_valve"]["command_mismatch"] < 1e-9
    m = s["metrics"]
    exact = "exact-model plant, "
    both, fb = m[exact + "feedforward + feedback"], m[exact + "feedback only"]
    # the inversion is worth having: far less error with the feedforward than without
    assert both["max_error"] < fb["max_error"] / 10
    assert both["rms_error"] < fb["rms_error"] / 10
    assert both["max_error"] <= s["bound"] == pytest.approx(0.02 * 0.25)
    # on the rig's ISO valve the feedback removes what the feedforward alone leaves
    rig = "rig (ISO valve), "
    assert m[rig + "feedforward + feedback"]["max_error"] < m[rig + "feedforward only"]["max_error"]
    assert m[rig + "feedforward + feedback"]["max_error"] < m[rig + "feedback only"]["max_error"]
