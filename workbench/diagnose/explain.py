"""Explain a mismatch: refit every candidate (in parallel) and rank them by evidence.

Evidence for a candidate with k fitted values, from its refit (:mod:`.refit`):

* **gain**: the share of the nominal short-horizon prediction cost it removes,
  ``(J0 - J) / J0``, and the gain per fitted value;
* **information criterion**: ``dBIC = n ln(J0 / J) - k ln(n)`` with ``n`` the
  effective number of independent observations (a few per prediction window and
  signal, since residuals within a window are correlated) -- a gain that a few
  free values could produce from the noise alone does not count;
* **closed-loop check**: the re-anchored closed-loop replay must not get worse
  (a model that predicts the next 0.2 s better but runs the loop worse is fitting
  the noise or another effect);
* **signature consistency**: the share of the gain found in the operating regimes
  where the effect acts (:mod:`.locate`), against the share of time spent there.

A candidate is *significant* when its dBIC exceeds :data:`DBIC_MIN` and it removes
at least :data:`GAIN_MIN` of the mismatch: :func:`screen` (every candidate, a short
refit), :func:`refit_fully` (the :func:`promising` ones). A fitted value at the edge
of its range is *not* a veto but reported ("at range edge": the range may be too
small, or the model form cannot reach the data): secondary shape values (Stribeck
velocity, static excess, cross-piston leak) legitimately sit at a bound when the
recording does not identify them, and a veto would discard real effects; the
evidence that matters (dBIC, share removed, closed loop) is judged all the same.
The findings are chosen among *sets* of candidates refitted jointly (:mod:`.sets`);
:func:`choose` is the former greedy choice (the best significant candidate, then
others added one by one while significant on top), kept for comparison.
"""

from __future__ import annotations

import math
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..output import stop_workers
from ..params import PlantParams
from .candidates import Candidate
from .data import Prepared
from .locate import consistency
from .predict import Predictor
from .refit import FitResult, fit_candidate

__all__ = ["Ranked", "refit_all", "rank", "Refits", "Chosen", "screen", "promising",
           "refit_fully", "choose", "DBIC_MIN", "GAIN_MIN", "COST_ORDER", "SCREEN_NFEV",
           "FULL_REFITS", "MAX_EXTRA"]

#: Smallest information-criterion improvement that counts as evidence.
DBIC_MIN = 10.0
#: Smallest share of the mismatch an explanation must remove.
GAIN_MIN = 0.25
#: A candidate that makes the re-anchored closed-loop replay worse by more than this
#: share is not accepted, however well it predicts the next 0.2 s.
SEG_WORSE = -0.25
#: Rough cost of refitting each candidate (for scheduling the slow ones first).
COST_ORDER = {"line_dynamics": 6.0, "dry_friction": 4.0, "leakage": 3.0, "supply_droop": 3.0,
              "valve_dynamics": 3.0, "heat_transfer": 2.0, "parameter_error:nominal values": 3.0}
#: Least-squares iterations of the screening refit of every candidate.
SCREEN_NFEV = 3
#: Candidates refitted fully after the screening.
FULL_REFITS = 4
#: Further findings looked for after the first.
MAX_EXTRA = 2

_JOB: dict[str, Any] = {}


def _work(i: int) -> FitResult:
    j = _JOB
    cand = j["cands"][i]
    try:
        return fit_candidate(j["prep"], j["params"], cand, j["shpe"], j["seg"],
                             max_nfev=j["max_nfev"], jit=j["jit"], base=j["base"],
                             start=j["starts"].get(cand.name))
    except Exception as exc:  # noqa: BLE001 - one failing candidate must not stop the rest
        from ..output import reraise_interrupt
        reraise_interrupt(exc)          # a Ctrl-C polled by CasADi is a stop, not a failed fit
        return FitResult(name=cand.name, effect=cand.effect, k=cand.k, values={}, std={}, ci95={},
                         cost=float("inf"), signal_costs={}, seg_cost=None, grid=[], fits={},
                         plant_values={}, error=f"{type(exc).__name__}: {exc}")


def refit_all(prep: Prepared, params: PlantParams, cands: Sequence[Candidate], shpe: Predictor,
              seg: Predictor | None, workers: int | None = None, max_nfev: int = 8,
              jit: bool = True, base: Mapping[str, float] | None = None,
              starts: Mapping[str, Mapping[str, float]] | None = None) -> list[FitResult]:
    """Refit each candidate; in ``workers`` processes (default: the CPU count, at most 2
    per candidate pair) when the platform can fork, else one after the other."""
    global _JOB
    order = sorted(range(len(cands)), key=lambda i: -COST_ORDER.get(cands[i].name, 1.0))
    _JOB = {"prep": prep, "params": params, "cands": list(cands), "shpe": shpe, "seg": seg,
            "max_nfev": max_nfev, "jit": jit, "base": dict(base or {}),
            "starts": dict(starts or {})}
    if workers is None:
        workers = min(os.cpu_count() or 1, len(cands))
    results: dict[int, FitResult] = {}
    can_fork = "fork" in multiprocessing.get_all_start_methods()
    try:
        if workers > 1 and can_fork and len(cands) > 1:
            ctx = multiprocessing.get_context("fork")
            ex = ProcessPoolExecutor(max_workers=workers, mp_context=ctx)
            try:
                futs = {i: ex.submit(_work, i) for i in order}
                for i, f in futs.items():
                    results[i] = f.result()
            except BaseException:
                stop_workers(ex)      # a signal (or an error): no waiting for the refits
                raise
            ex.shutdown(wait=True)
        else:
            for i in order:
                results[i] = _work(i)
    finally:
        _JOB = {}
    return [results[i] for i in range(len(cands))]


@dataclass
class Ranked:
    """A refit candidate with its evidence (see the module docstring)."""

    result: FitResult
    gain: float
    gain_per_value: float
    dbic: float
    seg_gain: float | None
    consistency: float | None
    significant: bool
    weight: float = 0.0
    reason: str = ""

    @property
    def name(self) -> str:
        return self.result.name


def rank(results: Sequence[FitResult], cost0: float, seg0: float | None, n_eff: float,
         consistency: Mapping[str, float] | None = None) -> list[Ranked]:
    """Evidence for every candidate, best first; ``weight`` is the BIC weight of each
    candidate against the others and against "nothing to add" (the nominal model)."""
    consistency = consistency or {}
    out = []
    for r in results:
        if r.error or not np.isfinite(r.cost):
            out.append(Ranked(r, 0.0, 0.0, -math.inf, None, None, False,
                              reason=r.error or "refit failed"))
            continue
        gain = (cost0 - r.cost) / cost0 if cost0 > 0 else 0.0
        dbic = n_eff * math.log(max(cost0, 1e-300) / max(r.cost, 1e-300)) - r.k * math.log(n_eff)
        seg_gain = None
        if seg0 is not None and r.seg_cost is not None and seg0 > 0:
            seg_gain = (seg0 - r.seg_cost) / seg0
        reasons = []
        sig = True
        if dbic < DBIC_MIN:
            sig = False
            reasons.append(f"dBIC {dbic:.0f} < {DBIC_MIN:g}")
        if gain < GAIN_MIN:
            sig = False
            reasons.append(f"gain {100 * gain:.0f} % < {100 * GAIN_MIN:.0f} %")
        if seg_gain is not None and seg_gain < SEG_WORSE:
            sig = False
            reasons.append(f"closed loop worse ({100 * seg_gain:.0f} %)")
        if r.at_bound and gain < 0.9:
            reasons.append("at range edge: " + ", ".join(k.split(".", 1)[-1] for k in r.at_bound))
        out.append(Ranked(r, gain, gain / max(r.k, 1), dbic, seg_gain,
                          consistency.get(r.name), sig, reason="; ".join(reasons)))
    finite = [o.dbic for o in out if np.isfinite(o.dbic)]
    ref = max(finite + [0.0])
    z = sum(math.exp(0.5 * (o.dbic - ref)) for o in out if np.isfinite(o.dbic)) \
        + math.exp(0.5 * (0.0 - ref))
    for o in out:
        o.weight = math.exp(0.5 * (o.dbic - ref)) / z if np.isfinite(o.dbic) else 0.0
    out.sort(key=lambda o: (-o.significant, -o.dbic if np.isfinite(o.dbic) else math.inf))
    return out


# ---------------------------------------------------------------------- choosing findings
@dataclass(frozen=True)
class Refits:
    """Refits of candidates on one recording: the data, the nominal plant, the
    predictors (objective ``shpe``, closed-loop check ``seg``), the operating-regime
    masks and the worker processes are fixed."""

    prep: Prepared
    params: PlantParams
    shpe: Predictor
    seg: Predictor | None
    masks: Mapping[str, np.ndarray]
    workers: int | None
    jit: bool

    def __call__(self, cands: Sequence[Candidate], max_nfev: int,
                 base: Mapping[str, Any] | None = None,
                 starts: Mapping[str, Mapping[str, float]] | None = None) -> list[FitResult]:
        """:func:`refit_all` of ``cands`` on top of ``base`` (dotted plant keys)."""
        return refit_all(self.prep, self.params, cands, self.shpe, self.seg,
                         workers=self.workers, max_nfev=max_nfev, jit=self.jit, base=base,
                         starts=starts)

    def rank(self, results: Sequence[FitResult], against: "Chosen") -> list[Ranked]:
        """:func:`rank` of ``results`` against the model with ``against`` added."""
        cons = {r.name: consistency(against.err - r.err, self.masks, r.name)
                if r.err is not None else None for r in results}
        return rank(results, against.cost, against.seg_cost, self.shpe.n_eff, cons)


@dataclass
class Chosen:
    """Findings chosen so far (in order), the plant keys they add, and the
    short-horizon cost (noise units), re-anchored closed-loop cost and per-sample
    error left with them added."""

    ranked: list[Ranked]
    added: dict[str, Any]
    cost: float
    seg_cost: float | None
    err: np.ndarray

    @classmethod
    def nothing(cls, cost: float, seg_cost: float | None, err: np.ndarray) -> "Chosen":
        """No finding: the nominal model's costs and error."""
        return cls([], {}, cost, seg_cost, err)

    def add(self, r: Ranked) -> None:
        """Add a finding; what is left is its refit's."""
        self.ranked.append(r)
        self.added.update(r.result.plant_values)
        self.cost, self.seg_cost, self.err = r.result.cost, r.result.seg_cost, r.result.err


def screen(refits: Refits, cands: Sequence[Candidate], nothing: Chosen) -> list[Ranked]:
    """Every candidate: signature scan and a short refit (:data:`SCREEN_NFEV`
    iterations), ranked against the nominal model."""
    return refits.rank(refits(cands, SCREEN_NFEV), nothing)


def promising(ranking: Sequence[Ranked]) -> list[Ranked]:
    """The (at most :data:`FULL_REFITS`) best screened candidates with a positive dBIC."""
    return [r for r in ranking if np.isfinite(r.dbic) and r.dbic > 0][:FULL_REFITS]


def refit_fully(refits: Refits, cands: Sequence[Candidate], ranking: Sequence[Ranked],
                top: Sequence[Ranked], max_nfev: int, nothing: Chosen) -> list[Ranked]:
    """The ``top`` candidates refitted fully from their screening values; a full refit
    replaces the screening one when it succeeds and costs no more. All ranked again."""
    by = {c.name: c for c in cands}
    again = refits([by[r.name] for r in top], max_nfev,
                   starts={r.name: r.result.values for r in top})
    merged = {r.name: r.result for r in ranking}
    for r_old, r_new in zip(top, again):
        if r_new.error is None and r_new.cost <= r_old.result.cost:
            r_new.grid = r_old.result.grid
            r_new.nfev += r_old.result.nfev
            r_new.wall_s += r_old.result.wall_s
            merged[r_new.name] = r_new
    return refits.rank([merged[c.name] for c in cands], nothing)


def choose(refits: Refits, cands: Sequence[Candidate], ranking: Sequence[Ranked],
           max_nfev: int, nothing: Chosen, out_of_time: Callable[[], bool]) -> Chosen:
    """The best significant candidate, then up to :data:`MAX_EXTRA` further ones, each
    refitted on top of those found, while they stay significant there; no further
    one when ``out_of_time()`` or when less than 3 % of the nominal mismatch is left."""
    by_name = {c.name: c for c in cands}
    chosen = Chosen.nothing(nothing.cost, nothing.seg_cost, nothing.err)
    if not ranking or not ranking[0].significant:
        return chosen
    chosen.add(ranking[0])
    for _ in range(MAX_EXTRA):
        if out_of_time():
            break
        if (nothing.cost - chosen.cost) / nothing.cost > 0.97:
            break                      # nothing left worth a further effect
        others = _others(ranking, chosen)
        if not others:
            break
        more = refits([by_name[r.name] for r in others], max_nfev, base=chosen.added,
                      starts={r.name: r.result.values for r in others})
        ranked = refits.rank(more, chosen)
        if not ranked or not ranked[0].significant:
            break
        chosen.add(ranked[0])
    return chosen


def _others(ranking: Sequence[Ranked], chosen: Chosen) -> list[Ranked]:
    """Up to three significant candidates that could add to ``chosen``: another effect,
    or a nominal value that no finding has changed yet."""
    used = {c.result.effect for c in chosen.ranked if c.result.effect != "parameter_error"}
    used_names = {c.name for c in chosen.ranked}
    return [r for r in ranking if r.significant and r.name not in used_names
            and r.result.effect not in used
            and not (r.result.effect == "parameter_error"
                     and any(k in chosen.added for k in r.result.plant_values))][:3]
