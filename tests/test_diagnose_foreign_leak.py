"""A leak is named only where it shows in the chamber equations (issue 12, session 11).

Found on test_diagnose.py's foreign dry-friction recording (tests/foreign_rig.py:
smooth Stribeck law 16.3/22.3 N, no leak) with the engine's friction events refined
(``predict.REFINE_STEPS``): the diagnosis named a leak of 4.9e-12 m^3/(s Pa) to
atmosphere and 8.4e-11 kg/(s Pa) across the piston beside the friction, removing 45 %
of what the friction left. By its size that leak is not negligible (it moves more than
the pressure noise in a horizon, :class:`~workbench.diagnose.leakfloor.LeakFloor`);
it absorbed what the Karnopp law leaves of the smooth law. The force-free witness
(:func:`~workbench.diagnose.leakfloor.chamber_evidence`: each chamber's equation
driven by the measured motion and command, the other chamber's pressure imposed) has
no force in it, so no friction misfit can pass for a leak there.

Recordings of the foreign rig, 6 s at 1 kHz (0.3 CPU s each); the witness integrates
each chamber once with and once without the leak (about 0.3 CPU s).
"""

from __future__ import annotations

import numpy as np
import pytest

import foreign_rig
from workbench.diagnose import synth
from workbench.diagnose.data import prepare
from workbench.diagnose.leakfloor import chamber_evidence, chamber_misfit
from workbench.plant import Plant

DURATION = 6.0
#: test_diagnose.py's foreign dry-friction case (synth.concealed_case("dry_friction", 3)).
FRICTION = {"coulomb": 16.33, "static": 22.26, "stribeck": 0.0135}
#: The leak named beside that friction (rounded from the diagnosis's JSON).
SPURIOUS = {"leakage.conductance_to_atmosphere": 4.9e-12, "leakage.cross_piston": 8.4e-11}
REAL = {"leakage.conductance_to_atmosphere": 2.5e-10}


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    root = tmp_path_factory.mktemp("foreign_leak")
    plant_file = synth.concealed_case("none", seed=0).write_nominal(root / "plant.toml")
    ref = synth.rich_reference(3, DURATION)
    plant = Plant.from_toml(plant_file)
    friction = foreign_rig.record(plant_file, ref, DURATION, seed=10, friction=FRICTION)
    leak = foreign_rig.record(plant_file, ref, DURATION, seed=10, overrides=REAL)
    return plant, prepare(plant, friction), prepare(plant, leak)


def test_a_leak_absorbing_a_friction_misfit_does_not_show_in_the_chambers(rig):
    """No leak on the rig: the force-free estimates are at the sensor noise (500 Pa,
    plus the foreign valve's laminar patch) without a leak, and the spurious leak makes
    them worse (measured on the 20 s recording: 0.67/0.59 -> 6.4/5.9 kPa)."""
    _, prep, _ = rig
    ev = chamber_evidence(prep, {}, SPURIOUS)
    assert not ev["shows"], ev
    assert ev["without_Pa"] < 2e3, ev          # 4x the pressure noise
    assert ev["with_Pa"] > 2.0 * ev["without_Pa"], ev


def test_a_real_leak_shows_in_the_chambers(rig):
    """A 2.5e-10 m^3/(s Pa) leak on the rig: without it the chamber equations miss the
    recorded pressures by far more than the noise (the leak drains ~1 bar/s at 5 bar
    on this chamber, order 100 kPa), with it they come to the noise level."""
    _, _, prep = rig
    ev = chamber_evidence(prep, {}, REAL)
    assert ev["shows"], ev
    assert ev["without_Pa"] > 30e3, ev
    assert ev["with_Pa"] < 2e3, ev             # 4x the pressure noise


def test_no_recorded_pressure_gives_no_judgement(rig, tmp_path):
    """A position-only recording: nothing to compare, the witness does not judge."""
    plant, prep, _ = rig
    from dataclasses import replace
    xonly = replace(prep, p_a=None, p_b=None, signals=("x",))
    assert chamber_misfit(xonly, plant) is None
    assert chamber_evidence(xonly, {}, SPURIOUS)["shows"]


def test_a_set_whose_leak_the_chambers_reject_gives_way_to_the_next():
    """Selection logic: the lowest-BIC set has a leak the witness rejects, so the next
    set that earns its place is chosen; without a witness the leak's set is."""
    from workbench.diagnose.sets import SetScore, _select
    n = 1000.0

    def score(names, cost, k):
        return SetScore(names, None, cost, k, n * np.log(cost) + k * np.log(n))
    scores = {(): score((), 100.0, 0), ("dry_friction",): score(("dry_friction",), 10.0, 3),
              ("leakage",): score(("leakage",), 90.0, 2),
              ("dry_friction", "leakage"): score(("dry_friction", "leakage"), 5.0, 5)}
    assert _select(dict(scores), 100.0, n=n).names == ("dry_friction", "leakage")
    for s in scores.values():
        s.earns, s.own, s.own_of_rest = True, {}, {}
    seen = []

    def witness(s):
        seen.append(s.names)
        return "leakage" not in s.names
    assert _select(scores, 100.0, n=n, witness=witness).names == ("dry_friction",)
    assert seen == [("dry_friction", "leakage"), ("dry_friction",)]
