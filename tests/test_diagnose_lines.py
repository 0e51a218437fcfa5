"""Valve-chamber lines on recordings of another simulator (issue 12, rig recordings).

The foreign rig (:mod:`foreign_rig`, numpy/scipy) has two line models of its own,
neither the workbench's chain of segments with each segment's volume at its valve end:
five pi sections with laminar + Blasius friction (``"pi5"``), and one lumped pi
section with laminar friction only (``"lumped"``: half the tube's volume at each end,
the whole inertance and resistance between). Lines of 2.5 m x 4 mm on the 25 mm rig of
synth in its PD loop, 12 s at 1 kHz.

Bounds: fitted values within 30 % (the issue's bound); measured values in each test.
Candidates are restricted to what is concealed and what competes with it most (a
spool lag) to keep the suite short; the full search of the same cases is in the issue
note (friction + lines: both named, 34 candidate models; position only: lines named).
"""

from __future__ import annotations

import pytest

import foreign_rig
from workbench.diagnose import diagnose, synth

LINES = {"lines.length": 2.5, "lines.diameter": 4e-3}
DURATION = 12.0


@pytest.fixture(scope="module")
def plant_file(tmp_path_factory):
    root = tmp_path_factory.mktemp("lines")
    return synth.concealed_case("none", seed=0).write_nominal(root / "plant.toml")


def _record(plant_file, **kw):
    return foreign_rig.record(plant_file, synth.rich_reference(5, DURATION), DURATION,
                              seed=5, **kw)


def test_lines_of_another_line_model_are_named(plant_file):
    """The lumped one-section line (a single lightly damped inertance-capacitance
    resonance, laminar damping only): named as line_dynamics. The workbench's chain
    cannot make that one sharp resonance, so a lightly damped spool lag is named beside
    it (measured: valve_dynamics 32.6 Hz, damping 0.25; lines 1.22 m, 4.9 mm; the chain
    alone fits 1.90 m, 5.3 mm): the values are the chain's equivalent of a cruder model,
    not asserted; what is asserted is that the lines are named, that the pressure fits
    rise (37 -> 64 %, 40 -> 56 % measured) and that the remaining mismatch is stated with
    the line model's form as the limit. (On the realistic five-section line the length
    is found within 3 %: the next tests.)"""
    d = diagnose(plant_file, _record(plant_file, overrides=LINES, line_model="lumped"),
                 effects=("line_dynamics", "valve_dynamics"))
    found = {f.effect: f for f in d.findings}
    assert "line_dynamics" in found, d.summary()
    assert d.fit_after["p_a"] > d.fit_before["p_a"] + 15.0
    assert d.fit_after["p_b"] > d.fit_before["p_b"] + 10.0
    assert any(s.startswith("model-form limit of line_dynamics") for s in d.unexplained)


def test_lumped_lines_beside_a_valve_offset_are_named_not_a_lag(plant_file):
    """Two effects at once on the foreign lumped line: a 0.15 V valve offset beside it,
    both named, the offset within 10 % and the line length within the issue's 30 %.
    Measured (session 12, h12o; 3-segment candidate lines stepped by ROS2): offset
    0.150 V, lines 1.87 m, 5.29 mm. With the same 3 segments stepped by ROS4 (session
    12 reported it as 6 segments; its script's segment count did not take) the offset +
    spool lag pair predicted the position about as well as offset + lines (422.7 against
    420.9 noise units) but p_a 35.5 / p_b 10.8 against 10.0 / 3.3: the pressure rule of
    sets._pressures_better is what keeps the lines there (lines 2.30 m, 5.02 mm); that
    step was measured, not adopted (engine.LINE_TABLEAU)."""
    d = diagnose(plant_file, _record(plant_file, overrides={**LINES, "valve.null_offset": 0.15},
                                     line_model="lumped"),
                 effects=("line_dynamics", "valve_dynamics", "valve_offset"))
    found = {f.effect: f for f in d.findings}
    assert set(found) == {"line_dynamics", "valve_offset"}, d.summary()
    assert found["valve_offset"].parameters["null_offset"] == pytest.approx(0.15, rel=0.1)
    assert found["line_dynamics"].parameters["length"] == pytest.approx(2.5, rel=0.3)


def test_friction_and_long_lines_are_both_named(plant_file):
    """Dry friction (Coulomb 20 N, static 28 N, smooth law) and 2.5 m lines (5 pi
    sections): both named. Once only the friction was: the lines alone remove 26 % of
    the short-horizon mismatch while friction is unmodelled (the significance bar is
    25 %), so a greedy search that adds effects one by one could drop them; the joint
    refit of the pair does not. Measured in the full search (34 candidate models):
    Coulomb 20.9 N, static 29.1 N, length 2.51 m, diameter 3.98 mm; here the two alone
    (singles and the pair refitted)."""
    d = diagnose(plant_file, _record(plant_file, overrides=LINES,
                                     friction={"coulomb": 20.0, "static": 28.0,
                                               "stribeck": 0.01}),
                 effects=("dry_friction", "line_dynamics"))
    found = {f.effect: f for f in d.findings}
    assert {"dry_friction", "line_dynamics"} <= set(found), d.summary()
    assert found["dry_friction"].parameters["coulomb"] == pytest.approx(20.0, rel=0.3)
    assert found["line_dynamics"].parameters["length"] == pytest.approx(2.5, rel=0.3)
    assert found["line_dynamics"].parameters["diameter"] == pytest.approx(4e-3, rel=0.3)


def test_position_only_recording_with_lines_names_the_lines(plant_file):
    """No pressures: 2.5 m lines slow the position response, which a spool lag could
    also mimic. Before, line_dynamics was no candidate without pressures and a 9 Hz
    valve_dynamics was named (with viscous friction x 1.9); now the lines are named
    (measured 2.47 m, 3.94 mm here; 2.63 m, 3.98 mm in the full search) and the position
    fits within a few times its noise. A fast spool lag may ride along (measured 142 Hz,
    damping 0.48: the chain's form made up for, see the model-form statement)."""
    d = diagnose(plant_file, _record(plant_file, overrides=LINES, pressures=False),
                 effects=("line_dynamics", "valve_dynamics"))
    assert d.prep.signals == ("x",)
    found = {f.effect: f for f in d.findings}
    assert "line_dynamics" in found, d.summary()
    assert found["line_dynamics"].parameters["length"] == pytest.approx(2.5, rel=0.3)
    assert d.fit_after["x"] > 99.0
