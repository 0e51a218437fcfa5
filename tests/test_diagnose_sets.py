"""Several effects at once and wrong nominal values (issue 12, points 1 and 2).

Recordings from the independent simulator :mod:`foreign_rig` (numpy/scipy: its own
valve, lines in 5 pi-segments, smooth friction law), 12 s (20 s for the pair) at 1 kHz of the 25 mm rig in
its PD loop; the diagnosis gets only the nominal plant file and the recording and
searches all candidates (no ``effects`` restriction). Bounds: fitted values within
30 % of the concealed ones (the issue's bound for a single effect, kept for pairs).

Nominal errors (point 2): mass +8 %, viscous friction -7 %, valve conductance +6 %,
supply pressure -5 % at once -- within the issue's 5-10 %.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import foreign_rig
from workbench.diagnose import synth

DURATION = 12.0
NOMINAL_ERRORS = {"load.mass": 1.2 * 1.08, "load.viscous_friction": 40.0 * 0.93,
                  "valve.sonic_conductance": 6.25e-8 * 1.06, "supply.pressure": 6.0e5 * 0.95}


@pytest.fixture(scope="module")
def plant_file(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("sets")
    return synth.concealed_case("none", seed=0).write_nominal(root / "plant.toml")


def _diagnose(plant_file, seed=5, duration=DURATION, **kw):
    from workbench.diagnose import diagnose
    rec = foreign_rig.record(plant_file, synth.rich_reference(seed, duration), duration,
                             seed=seed, **kw)
    return diagnose(plant_file, rec)


def _by_effect(d):
    return {f.effect: f for f in d.findings}


def test_two_effects_at_once_are_both_named(plant_file):
    """Deadband 0.05 and a leak of 2.5e-10 m^3/(s Pa) to atmosphere: both are findings,
    each value within 30 %, each with its own share, and the pressures fit better than
    with the deadband alone would leave them (the joint set beat the single). 20 s: in
    12 s the loop rests too little for the leak to show beside the deadband."""
    d = _diagnose(plant_file, duration=20.0, overrides={"valve.deadband": 0.05,
                                         "leakage.conductance_to_atmosphere": 2.5e-10})
    found = _by_effect(d)
    assert set(found) == {"valve_deadband", "leakage"}, d.summary()
    assert found["valve_deadband"].parameters["deadband"] == pytest.approx(0.05, rel=0.3)
    assert found["leakage"].parameters["conductance_to_atmosphere"] == \
        pytest.approx(2.5e-10, rel=0.3)
    best = next(s for s in d.sets["sets"] if s["set"] == sorted(d.sets["chosen"]))
    assert all(v > 0 for v in best["own_share"].values())
    single = next(s for s in d.sets["sets"] if s["set"] == ["valve_deadband"])
    assert best["cost"] < single["cost"]
    assert d.sets["candidate_models"] > len(d.ranking)     # pairs were refitted too


def test_nominal_errors_alone_are_parameter_errors_not_new_physics(plant_file):
    """Mass, viscous friction, valve conductance and supply 5-8 % off, no effect: every
    finding is a parameter_error (or none), and a mass correction found is within 10 %
    of the rig's mass (the largest error, seen while accelerating)."""
    d = _diagnose(plant_file, overrides=NOMINAL_ERRORS)
    assert {f.effect for f in d.findings} <= {"parameter_error"}, d.summary()
    for f in d.findings:
        if "load.mass" in f.parameters:
            assert f.parameters["load.mass"] == pytest.approx(NOMINAL_ERRORS["load.mass"],
                                                              rel=0.1)


def test_nominal_errors_plus_an_effect_still_name_the_effect(plant_file):
    """The same nominal errors and a valve deadband of 0.06: the deadband is named
    (within 30 %) and no other effect is invented."""
    d = _diagnose(plant_file, overrides={**NOMINAL_ERRORS, "valve.deadband": 0.06})
    found = _by_effect(d)
    assert "valve_deadband" in found, d.summary()
    assert found["valve_deadband"].parameters["deadband"] == pytest.approx(0.06, rel=0.3)
    assert set(found) <= {"valve_deadband", "parameter_error"}, d.summary()


def test_position_only_foreign_recording_names_friction(plant_file):
    """Position only (no pressures), and another friction law than the workbench's: the
    foreign rig's LuGre bristle model (Coulomb 22 N, static 31 N; pre-sliding and
    frictional lag the Karnopp law lacks). Dry friction is named with its Coulomb level
    within 30 % (measured -14 %), and the model-form limit shows as a remaining mismatch
    well above the noise."""
    d = _diagnose(plant_file, seed=21, pressures=False,
                  friction={"coulomb": 22.0, "static": 31.0, "stribeck": 0.012, "law": "lugre"})
    assert d.prep.signals == ("x",)
    found = _by_effect(d)
    assert "dry_friction" in found, d.summary()
    assert found["dry_friction"].parameters["coulomb"] == pytest.approx(22.0, rel=0.3)
    assert d.unexplained and d.unexplained[0].startswith("x:")
