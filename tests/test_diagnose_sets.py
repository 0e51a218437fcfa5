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


#: Relative tolerance on a corrected nominal value: a quarter of the smallest error
#: concealed (5 %), so a named correction tells the error's size, not only its sign
#: (measured: all four within 0.3 %).
NOMINAL_REL = 0.0125


def _corrected(d):
    """Every nominal value the findings correct (dotted key -> value)."""
    return {k: v for f in d.findings if f.effect == "parameter_error"
            for k, v in f.parameters.items()}


def test_nominal_errors_alone_are_parameter_errors_not_new_physics(plant_file):
    """Mass, viscous friction, valve conductance and supply 5-8 % off, no effect: every
    finding is a parameter_error, each of the four values within NOMINAL_REL of the
    rig's, and the pressures then fit well (before: negative, the supply sets the
    pressure levels). Conductance +6 % and supply -5 % leave the valve's flow C p_s
    within 1 % of nominal: neither is found alone, only jointly."""
    d = _diagnose(plant_file, overrides=NOMINAL_ERRORS)
    assert d.findings and {f.effect for f in d.findings} == {"parameter_error"}, d.summary()
    found = _corrected(d)
    for key, true in NOMINAL_ERRORS.items():
        assert found.get(key) == pytest.approx(true, rel=NOMINAL_REL), (key, d.summary())
    assert min(d.fit_before["p_a"], d.fit_before["p_b"]) < 0
    assert min(d.fit_after["p_a"], d.fit_after["p_b"]) > 90.0, d.summary()


def test_nominal_errors_plus_an_effect_still_name_the_effect(plant_file):
    """The same nominal errors and a valve deadband of 0.06: the deadband is named
    (within 30 %), no other effect is invented, and the four nominal values are still
    corrected, each within NOMINAL_REL (the joint refit also starts from the plant
    file's values: alone, the nominal values drift far to mimic the deadband)."""
    d = _diagnose(plant_file, overrides={**NOMINAL_ERRORS, "valve.deadband": 0.06})
    found = _by_effect(d)
    assert "valve_deadband" in found, d.summary()
    assert found["valve_deadband"].parameters["deadband"] == pytest.approx(0.06, rel=0.3)
    assert set(found) <= {"valve_deadband", "parameter_error"}, d.summary()
    corrected = _corrected(d)
    for key, true in NOMINAL_ERRORS.items():
        assert corrected.get(key) == pytest.approx(true, rel=NOMINAL_REL), (key, d.summary())


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


# ---------------------------------------------------------------------- alternatives
class _FakeRefits:
    """Joint refits with prescribed costs (noise units) by set of member names: the
    set search's logic on its own, without a recording."""

    def __init__(self, costs, masks, n_eff):
        from types import SimpleNamespace
        self.costs, self.masks = costs, masks
        self.shpe = SimpleNamespace(n_eff=n_eff)

    def result(self, cand, corr=None):
        import numpy as np
        from workbench.diagnose.refit import FitResult
        cost = self.costs[frozenset(cand.name.split("+"))]
        # effects at their start values, nominal values corrected by +20 %
        vals = {f.key: f.start * (1.2 if "parameter_error" in cand.effect else 1.0)
                for f in cand.free}
        return FitResult(name=cand.name, effect=cand.effect, k=cand.k, values=vals,
                         std={}, ci95={}, cost=cost, signal_costs={}, seg_cost=None, grid=[],
                         fits={}, plant_values=cand.plant_values(vals),
                         err=np.full(len(next(iter(self.masks.values()))), cost),
                         corr=corr or {})

    def __call__(self, cands, max_nfev, base=None, starts=None):
        return [self.result(c) for c in cands]


def test_sets_the_data_cannot_tell_apart_are_both_reported_with_what_separates_them():
    """Coulomb friction (3 values) and a higher viscous friction (1 value) explain the
    recording about as well: BICs 4 apart (< DBIC_MIN = 10) and together no better than
    either. The chosen set is the lower-BIC one; the other is reported as an
    alternative, with the regimes that would separate them and the share of this
    recording spent in each (computed here from the masks, independently)."""
    import math
    import numpy as np
    from workbench.diagnose.candidates import candidates
    from workbench.diagnose.explain import DBIC_MIN, Chosen, rank
    from workbench.diagnose.sets import search
    params = synth.concealed_case("none", seed=0).nominal
    cands = candidates(params, ["dry_friction", "parameter_error:load.viscous_friction"])
    fr, visc = (next(c for c in cands if c.name == n)
                for n in ("dry_friction", "parameter_error:load.viscous_friction"))
    n, n_samples = 400.0, 1000
    j0, j_fr = 100.0, 10.0
    # viscous: 4 BIC units worse than friction although it has 2 values fewer
    j_visc = math.exp(math.log(j_fr) + (4.0 + 2 * math.log(n)) / n)
    i = np.arange(n_samples)
    masks = {"at rest": i < 300, "velocity reversal": (i >= 300) & (i < 350),
             "moving": i >= 300}
    fake = _FakeRefits({frozenset([fr.name]): j_fr, frozenset([visc.name]): j_visc,
                        frozenset([fr.name, visc.name]): j_fr * 0.999}, masks, n)
    nothing = Chosen.nothing(j0, None, np.full(n_samples, j0))
    ranking = rank([fake.result(fr), fake.result(visc)], j0, None, n, {})
    chosen, info = search(fake, cands, ranking, 5, nothing)
    assert [r.name for r in chosen.ranked] == ["dry_friction"]
    assert info["alternatives"] == [[visc.name]]
    (alt,) = info["alternatives_tell_apart"]
    assert alt["dbic"] == pytest.approx(4.0, abs=1e-6) and alt["dbic"] < DBIC_MIN
    text = alt["tells_apart"]
    assert "dry_friction shows at rest / velocity reversal (35 % of this recording)" in text
    assert f"{visc.name} shows moving (70 % of this recording)" in text


def test_trade_off_of_two_members_names_the_separating_regimes():
    """A chosen pair whose values correlate beyond TRADE_OFF (a leak and a larger valve
    conductance both raise the pressures' drift) is reported as a trade-off with the
    regimes each member shows in and their share of the recording; below TRADE_OFF it
    is not."""
    import numpy as np
    from workbench.diagnose.candidates import candidates
    from workbench.diagnose.sets import TRADE_OFF, SetScore, combine, trade_offs
    params = synth.concealed_case("none", seed=0).nominal
    cands = candidates(params, ["leakage", "parameter_error:valve.sonic_conductance"])
    by = {c.name: c for c in cands}
    pair = combine(cands)
    i = np.arange(100)
    masks = {"at rest": i < 40, "high flow": i >= 90, "moving": i >= 40}
    fake = _FakeRefits({frozenset(pair.name.split("+")): 5.0}, masks, 100.0)
    leak_key = by["leakage"].free[0].key
    for corr, expect in ((-0.93, 1), (TRADE_OFF - 0.05, 0)):
        res = fake.result(pair, corr={(leak_key, "valve.sonic_conductance"): corr})
        best = SetScore(tuple(sorted(by)), res, 5.0, res.k, 0.0)
        out = trade_offs(best, by, masks)
        assert len(out) == expect
    (t,) = trade_offs(SetScore(tuple(sorted(by)), fake.result(
        pair, corr={(leak_key, "valve.sonic_conductance"): -0.93}), 5.0, pair.k, 0.0), by, masks)
    assert t["members"] == ["leakage", "parameter_error:valve.sonic_conductance"]
    assert "leakage shows at rest (40 % of this recording)" in t["tells_apart"]
    assert "valve.sonic_conductance shows high flow / moving (60 % of this recording)" \
        in t["tells_apart"]


def test_a_correction_below_min_correction_is_not_a_finding():
    """A nominal-value correction earns nothing when no value moves by MIN_CORRECTION
    (relative to the nominal, or to the scale for a nominal of 0); one value moved by
    more is enough. Effects are never judged by this rule."""
    from workbench.diagnose.candidates import JOINT_NOMINAL, candidates
    from workbench.diagnose.sets import MIN_CORRECTION, _negligible
    params = synth.concealed_case("none", seed=0).nominal
    by = {c.name: c for c in candidates(params)}
    joint = by[JOINT_NOMINAL]
    fake = _FakeRefits({frozenset([JOINT_NOMINAL]): 1.0}, {"at rest": [True]}, 10.0)
    res = fake.result(joint)
    nominal = {f.key: params[f.key] for f in joint.free}
    res.values = {k: v * (1 + 0.9 * MIN_CORRECTION) for k, v in nominal.items()}
    assert _negligible(joint, res)
    res.values = {**res.values, "supply.pressure": nominal["supply.pressure"]
                  * (1 - 1.1 * MIN_CORRECTION)}
    assert not _negligible(joint, res)
    assert not _negligible(by["valve_offset"], fake.result(joint))
