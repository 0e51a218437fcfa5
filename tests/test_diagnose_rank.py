"""The diagnosis's evidence and ranking on hand-built candidate results (issue 17).

No simulation: every :class:`~workbench.diagnose.refit.FitResult` here is written by
hand with a chosen cost, so the evidence of :mod:`workbench.diagnose.explain` has a
known answer, computed in the test from the formulas of that module's docstring
(which is the specification):

* gain ``(J0 - J) / J0`` (share of the nominal cost removed), per fitted value
  ``gain / k``;
* ``dBIC = n ln(J0 / J) - k ln(n)`` (Schwarz's criterion for a Gaussian likelihood
  with the cost as the residual sum of squares; more fitted values must cost);
* significant when ``dBIC >= 10`` and ``gain >= 25 %`` and the re-anchored
  closed-loop cost does not rise by more than 25 %;
* order: significant ones first, then by dBIC, best first;
* BIC weights ``exp(dBIC_i / 2) / (1 + sum_j exp(dBIC_j / 2))`` (the 1 is the
  nominal model, "nothing to add", whose dBIC is 0: Schwarz weights, Burnham &
  Anderson 2002, ch. 6);
* the greedy choice of findings (:func:`~workbench.diagnose.explain.choose`) with a
  stand-in for the refits that returns hand-written results.

The confidence of a finding (:func:`workbench.diagnose.evidence.confidence`) is the
two-model BIC weight ``exp(a/2) / (exp(a/2) + exp(b/2))`` against the runner-up and
against "nothing", times ``0.6 + 0.4 gain``, times 0.85 when less than half of the
gain lies where the effect should act.

Tolerances: 1e-12 relative on closed-form numbers (a handful of floating-point
operations; the planted bugs change them by factors).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.diagnose import explain
from workbench.diagnose.candidates import Free
from workbench.diagnose.evidence import confidence, evidence_text, where_text
from workbench.diagnose.explain import (Chosen, Ranked, Refits, choose, promising, rank,
                                        refit_fully, screen)
from workbench.diagnose.refit import FitResult, _at_bound

REL = 1e-12

#: The thresholds of explain.py (smallest dBIC, smallest gain, largest closed-loop
#: loss), written out here so that a changed threshold is seen.
DBIC_MIN, GAIN_MIN, SEG_WORSE = 10.0, 0.25, -0.25


def fit(name: str, cost: float, k: int = 2, effect: str | None = None,
        seg_cost: float | None = None, at_bound=(), error: str | None = None,
        plant_values: dict | None = None, values: dict | None = None,
        err: np.ndarray | None = None, nfev: int = 0) -> FitResult:
    """A hand-written refit result."""
    return FitResult(name=name, effect=effect or name, k=k, values=dict(values or {}), std={},
                     ci95={}, cost=cost, signal_costs={}, seg_cost=seg_cost, grid=[], fits={},
                     plant_values=dict(plant_values or {}), at_bound=list(at_bound), error=error,
                     err=err, nfev=nfev)


def dbic(j0: float, j: float, k: int, n: float) -> float:
    """Schwarz's criterion difference, written out (module docstring of explain)."""
    return n * (math.log(j0) - math.log(j)) - k * math.log(n)


def by_name(ranked):
    return {r.name: r for r in ranked}


def test_thresholds_are_the_documented_ones():
    assert (explain.DBIC_MIN, explain.GAIN_MIN, explain.SEG_WORSE) == (DBIC_MIN, GAIN_MIN,
                                                                      SEG_WORSE)


# ------------------------------------------------------------------ gain and dBIC
def test_gain_and_dbic_exact():
    """J0 = 400, n = 200: J = 100 with k = 2 removes 3/4 of the cost (not 3, which is
    (J0 - J) / J); dBIC = 200 ln 4 - 2 ln 200 = 266.662 (not + 2 ln 200)."""
    j0, n = 400.0, 200.0
    out = by_name(rank([fit("a", 100.0, k=2), fit("b", 300.0, k=1)], j0, None, n))
    a, b = out["a"], out["b"]
    assert a.gain == pytest.approx(0.75, rel=REL)
    assert a.gain_per_value == pytest.approx(0.375, rel=REL)
    assert a.dbic == pytest.approx(200 * math.log(4.0) - 2 * math.log(200.0), rel=REL)
    assert a.dbic == pytest.approx(266.6623, abs=1e-4)
    assert b.gain == pytest.approx(0.25, rel=REL)
    assert b.gain_per_value == pytest.approx(0.25, rel=REL)
    assert b.dbic == pytest.approx(dbic(j0, 300.0, 1, n), rel=REL)
    assert a.seg_gain is None and a.consistency is None


def test_more_fitted_values_cost_exactly_ln_n_each():
    """Same cost, k = 1 against k = 4: dBIC lower by 3 ln(n) for the larger model,
    which therefore ranks second."""
    n = 150.0
    ranked = rank([fit("big", 50.0, k=4), fit("small", 50.0, k=1)], 100.0, None, n)
    assert [r.name for r in ranked] == ["small", "big"]
    assert ranked[0].dbic - ranked[1].dbic == pytest.approx(3 * math.log(n), rel=1e-9)
    assert ranked[0].gain == ranked[1].gain == pytest.approx(0.5, rel=REL)


def test_closed_loop_gain_exact():
    """seg_gain = (S0 - S) / S0: S0 = 8, S = 6 gives 0.25; S = 12 gives -0.5."""
    out = by_name(rank([fit("a", 100.0, seg_cost=6.0), fit("b", 100.0, seg_cost=12.0),
                        fit("c", 100.0, seg_cost=None)], 400.0, 8.0, 200.0))
    assert out["a"].seg_gain == pytest.approx(0.25, rel=REL)
    assert out["b"].seg_gain == pytest.approx(-0.5, rel=REL)
    assert out["c"].seg_gain is None
    # no closed-loop check without a nominal closed-loop cost
    assert rank([fit("a", 100.0, seg_cost=6.0)], 400.0, None, 200.0)[0].seg_gain is None


# ------------------------------------------------------------------ vetoes
def test_large_gain_without_enough_evidence_is_not_significant():
    """n = 10, k = 3, J0/J = 2: gain 50 % but dBIC = 10 ln 2 - 3 ln 10 = 0.02 < 10
    (with the penalty's sign flipped it would be 13.8 and pass)."""
    r = rank([fit("a", 50.0, k=3)], 100.0, None, 10.0)[0]
    assert r.dbic == pytest.approx(10 * math.log(2.0) - 3 * math.log(10.0), rel=1e-9)
    assert 0.0 < r.dbic < DBIC_MIN
    assert r.gain == pytest.approx(0.5, rel=REL)
    assert not r.significant
    assert "dBIC" in r.reason and "gain" not in r.reason


def test_small_gain_with_large_dbic_is_not_significant():
    """n = 1000, J0/J = 1.25: dBIC = 1000 ln 1.25 - 2 ln 1000 = 209 but the gain is
    20 % < 25 % (as (J0 - J) / J it would be exactly 25 % and pass)."""
    r = rank([fit("a", 80.0, k=2)], 100.0, None, 1000.0)[0]
    assert r.dbic == pytest.approx(dbic(100.0, 80.0, 2, 1000.0), rel=REL)
    assert r.dbic > DBIC_MIN
    assert r.gain == pytest.approx(0.2, rel=REL)
    assert not r.significant
    assert r.reason == "gain 20 % < 25 %"


def test_closed_loop_worse_vetoes_a_good_predictor():
    """gain 75 %, dBIC 267, but the closed-loop cost rises by 30 % (> 25 %): not
    significant; by 20 %: significant."""
    out = by_name(rank([fit("worse", 100.0, seg_cost=13.0), fit("ok", 100.0, seg_cost=12.0)],
                       400.0, 10.0, 200.0))
    assert out["worse"].seg_gain == pytest.approx(-0.3, rel=1e-12)
    assert not out["worse"].significant
    assert "closed loop worse (-30 %)" in out["worse"].reason
    assert out["ok"].significant and out["ok"].reason == ""


def test_thresholds_are_inclusive_on_the_passing_side():
    """Just above both thresholds: significant; just below either: not. J0 = 100,
    n = 400, k = 1: J = 75 gives gain 25 % exactly (passes), J = 75.1 gives 24.9 %."""
    n = 400.0
    out = by_name(rank([fit("at", 75.0, k=1), fit("below", 75.1, k=1)], 100.0, None, n))
    assert out["at"].gain == pytest.approx(0.25, rel=REL) and out["at"].significant
    assert not out["below"].significant
    # dBIC around 10: n ln(J0/J) = 10 + ln n (k = 1) at J = J0 exp(-(10 + ln n) / n)
    j_edge = 100.0 * math.exp(-(DBIC_MIN + math.log(n)) / n)
    hi = by_name(rank([fit("hi", j_edge * 0.999, k=1)], 100.0, None, n))["hi"]
    lo = by_name(rank([fit("lo", j_edge * 1.001, k=1)], 100.0, None, n))["lo"]
    assert hi.dbic == pytest.approx(DBIC_MIN + n * -math.log(0.999), rel=1e-9)
    assert lo.dbic < DBIC_MIN < hi.dbic
    # gain here is only ~3.5 %: the gain veto holds both; the dBIC reason only lo
    assert "dBIC" in lo.reason and "dBIC" not in hi.reason


def test_failed_refit_ranks_last_with_no_weight():
    ranked = rank([fit("bad", math.inf, error="RuntimeError: boom"), fit("nan", math.nan),
                   fit("a", 300.0, k=1)], 400.0, None, 200.0)
    assert ranked[0].name == "a"
    for r in ranked[1:]:
        assert r.dbic == -math.inf and not r.significant and r.weight == 0.0
        assert r.gain == 0.0 and r.gain_per_value == 0.0
    assert by_name(ranked)["bad"].reason == "RuntimeError: boom"
    assert by_name(ranked)["nan"].reason == "refit failed"


def test_at_range_edge_is_reported_when_the_gain_is_partial():
    """A value at its bound is said in the reason (short key) below 90 % gain."""
    out = by_name(rank([fit("a", 100.0, at_bound=["friction.coulomb", "friction.static"]),
                        fit("b", 30.0, at_bound=["friction.coulomb"])], 400.0, None, 200.0))
    assert out["a"].reason == "at range edge: coulomb, static"
    assert out["a"].gain == pytest.approx(0.75, rel=REL)
    assert out["b"].gain == pytest.approx(0.925, rel=REL)
    assert "range edge" not in out["b"].reason


def test_at_bound_detection():
    """Within 0.1 % of the (optimiser-coordinate) range from a bound; a linear lower
    bound of 0 (no offset) does not count."""
    lin0 = Free("valve.null_offset", 0.0, 1.0, 0.1, log=False)
    lin = Free("valve.null_offset", -1.0, 1.0, 0.1, log=False)
    lg = Free("lines.length", 0.1, 10.0, 1.0)                  # z in [ln 0.1, ln 10]
    span = math.log(100.0)
    lo = np.array([0.0, -1.0, math.log(0.1)])
    hi = np.array([1.0, 1.0, math.log(10.0)])
    z = np.array([0.0, -1.0 + 0.5e-3 * 2.0, math.log(10.0) - 0.5e-3 * span])
    assert _at_bound([lin0, lin, lg], z, lo, hi) == ["valve.null_offset", "lines.length"]
    z = np.array([0.5, -1.0 + 2e-3 * 2.0, math.log(10.0) - 2e-3 * span])
    assert _at_bound([lin0, lin, lg], z, lo, hi) == []
    z = np.array([1.0 - 1e-4, 0.0, math.log(0.1)])
    assert _at_bound([lin0, lin, lg], z, lo, hi) == ["valve.null_offset", "lines.length"]


# ------------------------------------------------------------------ order and weights
def test_order_significant_first_then_by_dbic():
    """Hand-computed dBIC (J0 = 400, n = 200): c (k = 1, J = 80) 315.6 > a (k = 2,
    J = 100) 266.7 > d (k = 1, J = 200) 133.3; e removes 20 % only (dBIC 39.3, not
    significant); f makes things worse (dBIC < 0). Given in scrambled order."""
    res = [fit("a", 100.0, k=2), fit("d", 200.0, k=1), fit("e", 320.0, k=1),
           fit("c", 80.0, k=1), fit("f", 500.0, k=1)]
    ranked = rank(res, 400.0, None, 200.0)
    assert [r.name for r in ranked] == ["c", "a", "d", "e", "f"]
    assert [r.significant for r in ranked] == [True, True, True, False, False]
    want = {"c": dbic(400, 80, 1, 200), "a": dbic(400, 100, 2, 200),
            "d": dbic(400, 200, 1, 200), "e": dbic(400, 320, 1, 200),
            "f": dbic(400, 500, 1, 200)}
    for r in ranked:
        assert r.dbic == pytest.approx(want[r.name], rel=REL)
    assert want["c"] > want["a"] > want["d"] > want["e"] > 0 > want["f"]


def test_insignificant_with_larger_dbic_ranks_after_significant():
    """n = 1000: e (k = 1, J0/J = 1.25) has dBIC 1000 ln 1.25 - ln 1000 = 216 but
    gains 20 %; d (k = 40, J0/J = 1/0.7) has dBIC 1000 ln(1/0.7) - 40 ln 1000 = 80 and
    gains 30 %: d is significant and ranks first, e second."""
    n = 1000.0
    ranked = rank([fit("e", 80.0, k=1), fit("d", 70.0, k=40)], 100.0, None, n)
    e_dbic, d_dbic = dbic(100, 80, 1, n), dbic(100, 70, 40, n)
    assert e_dbic > d_dbic > DBIC_MIN
    assert [r.name for r in ranked] == ["d", "e"]
    assert ranked[0].significant and not ranked[1].significant
    assert [r.dbic for r in ranked] == pytest.approx([d_dbic, e_dbic], rel=REL)


def test_bic_weights_exact():
    """Weights exp(dBIC_i / 2) / (1 + sum_j exp(dBIC_j / 2)); the nominal model
    (dBIC 0) takes the rest. Small dBICs (n = 20) so that no weight is 0 or 1."""
    n = 20.0
    res = [fit("a", 60.0, k=1), fit("b", 70.0, k=1), fit("c", 90.0, k=2),
           fit("x", math.inf, error="failed")]
    ranked = rank(res, 100.0, None, n)
    d = {r: dbic(100.0, j, k, n) for r, j, k in (("a", 60.0, 1), ("b", 70.0, 1), ("c", 90.0, 2))}
    z = 1.0 + sum(math.exp(v / 2) for v in d.values())
    out = by_name(ranked)
    for name, v in d.items():
        assert out[name].weight == pytest.approx(math.exp(v / 2) / z, rel=1e-9)
    assert out["x"].weight == 0.0
    nothing = 1.0 - sum(r.weight for r in ranked)
    assert nothing == pytest.approx(1.0 / z, rel=1e-9)
    assert 0.01 < nothing < 0.99 and 0.01 < out["a"].weight < 0.99


def test_bic_weights_do_not_overflow():
    """dBIC of thousands: the best takes all the weight (no overflow)."""
    ranked = rank([fit("a", 1.0, k=1), fit("b", 2.0, k=1)], 1e3, None, 2000.0)
    assert ranked[0].name == "a"
    assert ranked[0].weight == pytest.approx(1.0, rel=1e-12)
    assert ranked[1].weight == pytest.approx(0.0, abs=1e-12)


def test_zero_nominal_cost_gives_no_gain():
    r = rank([fit("a", 1.0)], 0.0, None, 100.0)[0]
    assert r.gain == 0.0 and not r.significant


# ------------------------------------------------------------------ Refits.rank, choose
def _refits(masks, n_eff, results=None, calls=None):
    """A :class:`Refits` whose refits return hand-written results: ``results[(name,
    frozenset(base))]``; every call is recorded in ``calls``."""

    @dataclass(frozen=True)
    class Stub(Refits):
        table: dict = field(default_factory=dict)
        log: list = field(default_factory=list)

        def __call__(self, cands, max_nfev, base=None, starts=None):
            key = frozenset((base or {}).items())
            self.log.append(([c.name for c in cands], max_nfev, dict(base or {}),
                             dict(starts or {})))
            return [self.table[(c.name, key)] for c in cands]

    return Stub(prep=None, params=None, shpe=SimpleNamespace(n_eff=n_eff), seg=None,
                masks=masks, workers=1, jit=False, table=results or {},
                log=calls if calls is not None else [])


def test_refits_rank_against_a_finding_and_consistency():
    """Against a finding of cost 100 (not the nominal 400): J = 50 gains 50 %.
    Consistency of leakage (expected "at rest", 4 of 10 samples): gain per sample
    1 on the 4 rest samples, 0.5 on the 6 others: (4 / 7) / 0.4 = 1.4286."""
    masks = {"at rest": np.arange(10) < 4, "moving": np.arange(10) >= 4}
    refits = _refits(masks, 200.0)
    against = Chosen([], {}, 100.0, None, np.full(10, 2.0))
    err = np.where(np.arange(10) < 4, 1.0, 1.5)
    r = refits.rank([fit("leakage", 50.0, k=2, err=err)], against)[0]
    assert r.gain == pytest.approx(0.5, rel=REL)
    assert r.dbic == pytest.approx(dbic(100.0, 50.0, 2, 200.0), rel=REL)
    assert r.consistency == pytest.approx((4 / 7) / 0.4, rel=1e-9)
    # a candidate without an expected regime, or without a per-sample error: None
    out = by_name(refits.rank([fit("nonsense", 50.0, err=err), fit("leakage", 50.0)], against))
    assert out["nonsense"].consistency is None and out["leakage"].consistency is None


def _cands(*names):
    return [SimpleNamespace(name=n) for n in names]


def test_choose_nothing_significant_names_nothing():
    refits = _refits({}, 200.0)
    nothing = Chosen.nothing(400.0, None, np.zeros(3))
    ranking = rank([fit("a", 390.0), fit("b", 395.0)], 400.0, None, 200.0)
    chosen = choose(refits, _cands("a", "b"), ranking, 8, nothing, lambda: False)
    assert chosen.ranked == [] and chosen.added == {} and chosen.cost == 400.0
    assert refits.log == []


def test_choose_adds_a_second_effect_only_if_significant_on_top():
    """a (gain 75 %) is named. On top of it, b costs 90: 10 % of what is left (100),
    not significant although it would be 77.5 % of the nominal 400; c costs 40 on top:
    60 % of 100, dBIC 200 ln 2.5 - 2 ln 200: added. d has a's effect: never tried.
    Then b on top of a and c: 39 of 40 left, not added."""
    n = 200.0
    base_a = frozenset({"leakage.k": 1.0}.items())
    table = {("b", base_a): fit("b", 90.0, plant_values={"supply.v": 2.0}),
             ("c", base_a): fit("c", 40.0, plant_values={"gas.h": 3.0}, seg_cost=5.0,
                                err=np.ones(3)),
             # on top of a and c, b gains 2.5 % of what is left: not added
             ("b", base_a | {("gas.h", 3.0)}): fit("b", 39.0)}
    refits = _refits({}, n, table)
    nothing = Chosen.nothing(400.0, None, np.zeros(3))
    first = [fit("a", 100.0, effect="leakage", plant_values={"leakage.k": 1.0},
                 err=np.full(3, 2.0)),
             fit("b", 150.0, values={"supply.v": 1.5}), fit("c", 200.0),
             fit("d", 120.0, effect="leakage", k=3)]
    ranking = rank(first, 400.0, None, n)
    assert [r.name for r in ranking][:2] == ["a", "d"]
    chosen = choose(refits, _cands("a", "b", "c", "d"), ranking, 8, nothing, lambda: False)
    assert [r.name for r in chosen.ranked] == ["a", "c"]
    assert chosen.added == {"leakage.k": 1.0, "gas.h": 3.0}
    assert chosen.cost == 40.0 and chosen.seg_cost == 5.0 and np.all(chosen.err == 1.0)
    c = chosen.ranked[1]
    assert c.gain == pytest.approx(0.6, rel=REL)
    assert c.dbic == pytest.approx(dbic(100.0, 40.0, 2, n), rel=REL)
    names, nfev, base, starts = refits.log[0]
    assert names == ["b", "c"] and nfev == 8 and base == {"leakage.k": 1.0}
    assert starts["b"] == {"supply.v": 1.5}
    assert [x[0] for x in refits.log] == [["b", "c"], ["b"]]


def test_choose_stops_when_little_is_left_or_out_of_time():
    """The first finding removes 97.5 % (> 97 %) of the nominal cost: no further refit;
    with 75 % removed but out of time: none either."""
    nothing = Chosen.nothing(400.0, None, np.zeros(3))
    for first_cost, out_of_time in ((10.0, False), (100.0, True)):
        refits = _refits({}, 200.0)
        ranking = rank([fit("a", first_cost, effect="leakage"), fit("b", 150.0)], 400.0,
                       None, 200.0)
        chosen = choose(refits, _cands("a", "b"), ranking, 8, nothing, lambda: out_of_time)
        assert [r.name for r in chosen.ranked] == ["a"] and refits.log == []


def test_choose_at_most_max_extra_more():
    """Every further candidate stays significant: 1 + MAX_EXTRA (= 2) findings."""
    assert explain.MAX_EXTRA == 2
    n = 200.0
    names = ["a", "b", "c", "d"]
    first = [fit(x, 100.0 + 10 * i, effect=x, plant_values={f"{x}.v": 1.0})
             for i, x in enumerate(names)]
    table = {}
    base = {"a.v": 1.0}
    cost = 100.0
    for step in (("b", "c", "d"), ("c", "d")):
        cost /= 3.0                                     # gain 2/3, significant
        for j, x in enumerate(step):
            table[(x, frozenset(base.items()))] = fit(x, cost * (1 + 0.1 * j), effect=x,
                                                      plant_values={f"{x}.v": 1.0})
        base = {**base, f"{step[0]}.v": 1.0}
    refits = _refits({}, n, table)
    chosen = choose(refits, _cands(*names), rank(first, 400.0, None, n), 8,
                    Chosen.nothing(400.0, None, np.zeros(3)), lambda: False)
    assert [r.name for r in chosen.ranked] == ["a", "b", "c"]
    assert len(refits.log) == 2


def test_promising_screen_and_refit_fully():
    """promising: at most FULL_REFITS (= 4) of positive finite dBIC, in rank order.
    screen: SCREEN_NFEV (= 3) iterations, ranked against the nominal cost. refit_fully:
    a full refit replaces the screening one only if it costs no more (nfev added)."""
    assert (explain.FULL_REFITS, explain.SCREEN_NFEV) == (4, 3)
    n = 200.0
    costs = {"a": 100.0, "b": 150.0, "c": 200.0, "d": 250.0, "e": 300.0, "f": 500.0}
    table = {(x, frozenset()): fit(x, j, nfev=7) for x, j in costs.items()}
    refits = _refits({}, n, table)
    nothing = Chosen.nothing(400.0, None, np.zeros(3))
    cands = _cands(*costs)
    ranking = screen(refits, cands, nothing)
    assert refits.log[-1][1] == 3
    assert [r.name for r in ranking] == ["a", "b", "c", "d", "e", "f"]
    top = promising(ranking)
    assert [r.name for r in top] == ["a", "b", "c", "d"]
    few = rank([fit("f", 500.0), fit("x", math.inf, error="x"), fit("e", 300.0)], 400.0, None,
               n)
    assert [r.name for r in promising(few)] == ["e"]
    # full refits: a worse (120 > 100: the screening one is kept), b better (60),
    # c failed (kept), d equal (the full one is taken)
    table.update({("a", frozenset()): fit("a", 120.0, nfev=5),
                  ("b", frozenset()): fit("b", 60.0, nfev=5),
                  ("c", frozenset()): fit("c", 10.0, error="failed"),
                  ("d", frozenset()): fit("d", 250.0, nfev=5)})
    again = by_name(refit_fully(refits, cands, ranking, top, 12, nothing))
    assert refits.log[-1][1] == 12
    assert again["a"].result.cost == 100.0 and again["a"].result.nfev == 7
    assert again["b"].result.cost == 60.0 and again["b"].result.nfev == 12
    assert again["c"].result.cost == 200.0 and again["c"].result.error is None
    assert again["d"].result.nfev == 12           # equal cost: the full refit is kept
    assert again["b"].gain == pytest.approx(0.85, rel=REL)
    assert list(again) == ["b", "a", "c", "d", "e", "f"]


# ------------------------------------------------------------------ confidence
def _ranked(dbic_: float, gain: float = 0.5, cons: float | None = None,
            name: str = "leakage") -> Ranked:
    return Ranked(fit(name, 1.0), gain, gain, dbic_, None, cons, True)


def w2(a: float, b: float) -> float:
    """BIC weight of model a against model b (dBIC against the same reference)."""
    return math.exp(a / 2) / (math.exp(a / 2) + math.exp(b / 2))


def test_confidence_exact():
    # alone: against "nothing" (dBIC 0) only
    assert confidence(_ranked(6.0, 0.5), None) == pytest.approx(w2(6.0, 0.0) * 0.8, rel=1e-12)
    assert confidence(_ranked(6.0, 0.5), None) == pytest.approx(0.76206, abs=1e-5)
    # the runner-up is closer than "nothing": its weight decides
    assert confidence(_ranked(6.0, 0.5), _ranked(4.0)) == \
        pytest.approx(w2(6.0, 4.0) * 0.8, rel=1e-12)
    # the runner-up is further than "nothing": "nothing" decides
    assert confidence(_ranked(6.0, 0.5), _ranked(-8.0)) == \
        pytest.approx(w2(6.0, 0.0) * 0.8, rel=1e-12)
    # a failed runner-up counts as none
    assert confidence(_ranked(6.0, 0.5), _ranked(-math.inf)) == \
        pytest.approx(w2(6.0, 0.0) * 0.8, rel=1e-12)
    # the share explained: gain 1 -> x1, gain 0.25 -> x0.7, negative -> x0.6
    assert confidence(_ranked(5.0, 0.25), None) == pytest.approx(w2(5.0, 0.0) * 0.7, rel=1e-12)
    assert confidence(_ranked(5.0, -0.3), None) == pytest.approx(w2(5.0, 0.0) * 0.6, rel=1e-12)
    # gain where the effect does not act: x0.85 below 0.5, not at 0.5
    assert confidence(_ranked(5.0, 0.5, cons=0.4), None) == \
        pytest.approx(w2(5.0, 0.0) * 0.8 * 0.85, rel=1e-12)
    assert confidence(_ranked(5.0, 0.5, cons=0.5), None) == \
        pytest.approx(w2(5.0, 0.0) * 0.8, rel=1e-12)


def test_confidence_bounds():
    """Overwhelming evidence is capped at 0.99; a runner-up far ahead gives 0."""
    assert confidence(_ranked(500.0, 1.0), None) == 0.99
    assert confidence(_ranked(500.0, 1.0), _ranked(100.0)) == 0.99
    assert confidence(_ranked(100.0, 1.0), _ranked(500.0)) == 0.0
    assert confidence(_ranked(-40.0, 1.0), None) == pytest.approx(w2(-40.0, 0.0), rel=1e-9)


# ------------------------------------------------------------------ evidence text
def test_where_text():
    """At most the two regimes with the largest ratio >= 1.3 and > 1 % of the time."""
    conc = {"at rest": {"ratio": 2.5, "time_share": 0.3},
            "moving": {"ratio": 0.4, "time_share": 0.7},
            "high flow": {"ratio": 3.0, "time_share": 0.005},
            "near valve centre": {"ratio": 1.5, "time_share": 0.1},
            "velocity reversal": {"ratio": 1.4, "time_share": 0.1},
            "accelerating": {"ratio": 1.29, "time_share": 0.1}}
    assert where_text(conc) == ("mostly at rest (2.5x its share of time) and near valve "
                                "centre (1.5x its share of time)")
    conc = {"at rest": {"ratio": 1.29, "time_share": 0.3},
            "high flow": {"ratio": 9.0, "time_share": 0.01}}
    assert where_text(conc) == "throughout the recording"
    conc["at rest"]["ratio"] = 1.3
    assert where_text(conc) == "mostly at rest (1.3x its share of time)"


def _evidence(name: str, gain: float, values=None, plant_values=None) -> str:
    r = Ranked(fit(name, 1.0, values=values, plant_values=plant_values), gain, gain, 50.0,
               None, None, True)
    prep = SimpleNamespace(plant=SimpleNamespace(params={"valve.command_center": 5.0,
                                                         "load.mass": 1.2}))
    conc = {"at rest": {"ratio": 2.0, "time_share": 0.5}}
    return evidence_text(r, SimpleNamespace(name=name), conc, prep)


def test_evidence_text_states_the_fitted_values_and_the_gain():
    t = _evidence("valve_offset", 0.746, values={"valve.null_offset": 0.12})
    assert t == ("Mismatch mostly at rest (2.0x its share of time): the valve is closed at "
                 "u = 5.12 V, not at the nominal centre (steady error and drifting pressures "
                 "at rest); adding it removes 75 % of the short-horizon prediction error.")
    t = _evidence("dry_friction", 0.5, plant_values={"friction.static": 30.0,
                                                     "friction.coulomb": 20.0})
    assert "break-away force of 30 N" in t and "slides against 20 N" in t
    assert t.endswith("removes 50 % of the short-horizon prediction error.")
    t = _evidence("supply_droop", 0.4, values={"supply.reservoir_volume": 2e-3})
    assert "from a 2 l reservoir" in t
    t = _evidence("line_dynamics", 0.4, values={"lines.length": 1.5, "lines.diameter": 4e-3})
    assert "1.5 m lines of 4 mm" in t
    t = _evidence("valve_deadband", 0.4, values={"valve.deadband": 0.05})
    assert "within 5 % of the span" in t
    t = _evidence("parameter_error:load.mass", 0.3, plant_values={"load.mass": 1.5})
    assert "load.mass fits as 1.5 instead of the nominal 1.2" in t
    t = _evidence("heat_transfer", 0.3, values={"gas.heat_transfer_coefficient": 0.45})
    assert "(0.45 W/K)" in t


# ---------------------------------------------------------------------- refit uncertainty
def test_uncertainty_is_the_gauss_newton_covariance_written_out():
    """refit._uncertainty on a hand-made linear problem: residuals r of m = 40 samples,
    Jacobian J (2 free values) known, so cov = (J'J)^-1 r'r / (m - 2) inflated by
    m / n_eff when the residuals are correlated (n_eff = 10 effective samples: x4),
    never deflated (n_eff > m: x1). A log-scaled value v has std v sigma_z and the
    interval v exp(+-1.96 sigma_z); a linear one with scale s: s sigma_z and
    v +- 1.96 s sigma_z (delta method, written out here with numpy)."""
    from workbench.diagnose.refit import _uncertainty

    rng = np.random.default_rng(5)
    m = 40
    J = np.column_stack([np.ones(m), np.linspace(-1.0, 1.0, m)])
    r = rng.standard_normal(m)
    free = [Free("leakage.k", 1e-12, 1e-6, 1e-9, log=True),
            Free("load.mass", 0.1, 10.0, 1.0, log=False, scale=2.0)]
    vals = {"leakage.k": 3e-9, "load.mass": 1.7}
    cov_z = np.linalg.inv(J.T @ J) * (r @ r) / (m - 2)
    for n_eff, infl in ((10.0, 4.0), (400.0, 1.0)):
        std, ci, _ = _uncertainty(free, vals, J, r, n_eff)
        sz = np.sqrt(np.diag(cov_z) * infl)
        assert std["leakage.k"] == pytest.approx(3e-9 * sz[0], rel=1e-10)
        assert ci["leakage.k"] == pytest.approx(
            (3e-9 * math.exp(-1.96 * sz[0]), 3e-9 * math.exp(1.96 * sz[0])), rel=1e-10)
        assert std["load.mass"] == pytest.approx(2.0 * sz[1], rel=1e-10)
        assert ci["load.mass"] == pytest.approx(
            (1.7 - 1.96 * 2.0 * sz[1], 1.7 + 1.96 * 2.0 * sz[1]), rel=1e-10)


def test_fd_jacobian_steps_back_at_an_upper_bound():
    """refit._secant_jacobian: forward differences of a quadratic, with the step turned
    back where it would leave the upper bound. For f(z) = (z0^2, 3 z1) the forward
    difference is 2 z0 + h (exactly, up to rounding) and the backward one 2 z0 - h."""
    from workbench.diagnose.refit import _secant_jacobian as _fd_jacobian

    def fun(z):
        return np.array([z[0] ** 2, 3.0 * z[1]])

    z = np.array([1.0, 2.0])
    steps = np.array([1e-3, 1e-3])
    r0 = fun(z)
    J = _fd_jacobian(fun, z, r0, steps, (np.array([-5.0, -5.0]), np.array([5.0, 5.0])))
    assert J[0, 0] == pytest.approx(2.0 + 1e-3, rel=1e-9) and J[1, 1] == pytest.approx(3.0)
    J = _fd_jacobian(fun, z, r0, steps, (np.array([-5.0, -5.0]), np.array([1.0005, 5.0])))
    assert J[0, 0] == pytest.approx(2.0 - 1e-3, rel=1e-9)     # z0 + h leaves [.., 1.0005]
    assert J[0, 1] == 0.0 and J[1, 0] == 0.0


def test_further_findings_are_drawn_from_significant_candidates_only():
    """explain._others: what may be refitted on top of a finding are the significant
    candidates (dBIC and gain over their thresholds) of other effects, at most three,
    in ranking order. Here three non-significant candidates rank before two
    significant ones: only the significant ones are offered."""
    n = 200.0
    chosen = Chosen.nothing(400.0, None, np.zeros(3))
    chosen.add(rank([fit("a", 100.0, effect="leakage")], 400.0, None, n)[0])
    ranking = rank([fit("a", 100.0, effect="leakage"),
                    fit("p", 399.0), fit("q", 398.5), fit("r", 398.0),     # gain < 1 %
                    fit("s", 150.0), fit("t", 160.0)], 400.0, None, n)
    offered = [x.name for x in explain._others(ranking, chosen)]
    assert offered == ["s", "t"]
