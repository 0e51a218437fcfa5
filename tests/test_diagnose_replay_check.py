"""A set whose values make the whole replay worse is refitted on the long replay
(issue 12, session 12).

Session 11's blind sweep: valve offset + supply droop with the plant file 6-8 % off
(tests/foreign_rig.py): all three named, but the pressures fit 41.5/31.4 % after them
where the right structure gives 90 %+. The set search fits on 0.2 s horizons, where
the supply pressure and the droop's regulator trade off (both set the pressure a
transient reaches); the level the loop settles to over seconds separates them.
:func:`workbench.diagnose.core._replay_check` replays the plant with each prefix of
the findings; when every finding together fits worse than fewer of them, the set is
refitted jointly on the re-anchored closed-loop segments
(:func:`workbench.diagnose.refit.refit_set`), and what still fits worse is said.

Recording: the independent simulator, 8 s at 1 kHz, supply 5.64 bar (the file says 6)
behind a 0.6 l reservoir and a 5e-9 m^3/(s Pa) regulator. The set handed over has the
structure right and the values traded off: the supply 5.3 bar (too low) with the
rig's own droop on top, the drop counted twice (measured: supply alone p 31.8/23.2 %,
with the droop -1.3/-13.9 %; the rig's values 96.9/96.6 %).
"""

from __future__ import annotations

import numpy as np
import pytest

from workbench.diagnose import refit as refit_mod
from workbench.diagnose.core import _findings, _mean, _replay_check
from workbench.diagnose.nominal import nominal

from test_diagnose_polish_joint import _ranked, supply_case

TRUE = {"supply.pressure": 5.64e5, "supply.reservoir_volume": 6e-4,
        "supply.regulator_conductance": 5e-9}
TRADED = {"supply.pressure": 5.3e5}
#: Relative tolerance on the refitted values: a quarter of the supply's trade-off
#: (6 %), so the refit tells the supply from the droop, not only the sign (measured:
#: supply +0.02 %, reservoir -0.8 %, regulator -0.2 %).
REL = 0.015


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    plant, prep, by = supply_case(tmp_path_factory.mktemp("replay_check"), TRUE, 8.0)
    return plant, prep, nominal(prep, plant.params, True), by


def _kept(by, n, supply):
    droop = {k: TRUE[k] for k in ("supply.reservoir_volume", "supply.regulator_conductance")}
    return [_ranked(by["parameter_error:supply.pressure"], supply, n),
            _ranked(by["supply_droop"], droop, n)]


def test_traded_off_values_are_refitted_on_the_long_replay(case):
    plant, prep, nom, by = case
    right = _findings(prep, plant.params, _kept(by, prep.n, {k: TRUE[k] for k in TRADED}),
                      [], by, nom)[0]
    traded = _findings(prep, plant.params, _kept(by, prep.n, TRADED), [], by, nom)[0]
    # the case is what it claims: the droop added to the traded supply lowers the fit
    assert _mean(traded[-1].fit_after) < _mean(traded[0].fit_after)
    assert _mean(right[-1].fit_after) > 90.0
    kept = _kept(by, prep.n, TRADED)
    (found, aug, _), note = _replay_check(prep, plant.params, kept, [], by, nom, 10, True)
    assert note is None
    for key, true in TRUE.items():
        assert aug[key] == pytest.approx(true, rel=REL), key
    # the set reaches what the right structure reaches, each pressure within 1 % fit
    for s in ("p_a", "p_b"):
        assert found[-1].fit_after[s] > right[-1].fit_after[s] - 1.0, found[-1].fit_after


def test_a_fall_the_long_refit_cannot_mend_is_said(case, monkeypatch):
    """Without the long refit (no segment predictor: a position-only recording; here
    forced) the fall is a note naming each signal's fit with fewer findings and with
    all, and the values are left as they were."""
    plant, prep, nom, by = case
    monkeypatch.setattr(refit_mod, "refit_set", lambda *a, **k: None)
    kept = _kept(by, prep.n, TRADED)
    (found, aug, _), note = _replay_check(prep, plant.params, kept, [], by, nom, 10, True)
    assert aug["supply.pressure"] == TRADED["supply.pressure"]
    assert note is not None and "fits worse than with the first 1" in note, note
    assert f"p_a {found[0].fit_after['p_a']:.1f} -> {found[-1].fit_after['p_a']:.1f} %" in note
    assert np.isfinite(found[-1].fit_after["p_a"])
