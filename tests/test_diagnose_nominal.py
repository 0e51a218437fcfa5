"""Wrong nominal values alone (issue 12, point 2): supply pressure and valve conductance.

Recordings from the independent simulator :mod:`foreign_rig` (numpy/scipy: its own
valve law, lines and friction), 12 s at 1 kHz of the 25 mm rig in its PD loop, with
one nominal value of the plant file off and no missing effect. The diagnosis gets the
nominal plant file and the recording only and searches every candidate. It must
answer ``parameter_error`` with the right key and size, invent no effect, and not
"correct" the values that are right. (All four wrong at once, and with a real effect
on top: ``tests/test_diagnose_sets.py``.)
"""

from __future__ import annotations

from pathlib import Path

import pytest

import foreign_rig
from workbench.diagnose import synth

DURATION = 12.0
#: Relative tolerance on the corrected value: a quarter of the error concealed
#: (8-10 %), so the finding tells the error's size, not only its sign (measured: the
#: supply exact to 4 digits, the conductance -0.3 %).
REL = 0.02
#: A value the rig has right may be refitted, but must stay within this of nominal
#: (half the smallest error the issue asks to find, 5 %).
KEEP = 0.025


@pytest.fixture(scope="module")
def nominal(tmp_path_factory):
    root = tmp_path_factory.mktemp("nominal")
    case = synth.concealed_case("none", seed=0)
    return case.write_nominal(root / "plant.toml"), case.nominal


def _diagnose(plant_file, overrides, seed=5):
    from workbench.diagnose import diagnose
    rec = foreign_rig.record(plant_file, synth.rich_reference(seed, DURATION), DURATION,
                             seed=seed, overrides=overrides)
    return diagnose(plant_file, rec)


def _check(d, params, key, true):
    assert d.findings, d.summary()
    assert {f.effect for f in d.findings} == {"parameter_error"}, d.summary()
    corrected = {k: v for f in d.findings for k, v in f.parameters.items()}
    assert corrected.get(key) == pytest.approx(true, rel=REL), d.summary()
    for k, v in corrected.items():
        if k != key:
            assert v == pytest.approx(params[k], rel=KEEP), (k, d.summary())


@pytest.mark.parametrize("key, factor", [("supply.pressure", 0.92),
                                         ("valve.sonic_conductance", 1.10)],
                         ids=["supply-8%", "conductance+10%"])
def test_one_wrong_nominal_value_is_named(nominal, key, factor):
    """Supply -8 % alone, conductance +10 % alone: parameter_error names that key
    within REL, nothing else is invented, and the pressures fit within a few % of
    what the noise allows (the noise floor here is ~97 %; before the correction the
    supply case fits the pressures worse than a constant)."""
    plant_file, params = nominal
    true = params[key] * factor
    d = _diagnose(plant_file, {key: true})
    _check(d, params, key, true)
    assert min(d.fit_after["p_a"], d.fit_after["p_b"]) > 90.0, d.summary()
    assert d.fit_after["p_a"] > d.fit_before["p_a"] + 5.0, d.summary()
