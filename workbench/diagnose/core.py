"""The diagnosis: replay, locate, explain, model and refit -- :func:`diagnose`.

Method
------
1. **Replay** the recording on the nominal plant (:func:`replay`): closed loop on ``r``
   with the plant file's controller (CVODES, as ``workbench simulate``) when the
   recording has ``r`` and the controller reproduces the recorded command, else open
   loop on ``u`` re-anchored on the measured state every 0.5 s. The fit per signal is
   ``fit_before``. Rig recordings: one chamber pressure is fitted and anchored, the
   other estimated by the force balance (:func:`.data.other_side`; the predictions
   then start where the piston accelerates least, where that estimate is good, and the
   witness and the polish use the recorded side); a recorded ``p_s``
   that sags is the supply sample by sample (the replay then runs on the engine);
   several recordings are joined (:func:`.data.prepare_many`), replayed one by one,
   with their fits reported per recording.
2. **Locate** (:mod:`.locate`, :mod:`.witness`): short-horizon predictions (0.2 s,
   open loop on the recorded command from the measured state, :mod:`.predict`) give a
   per-sample error that does not drift; its intervals above the noise and its share
   in each operating regime (at rest, moving, reversals, near the valve centre, high
   flow, fast pressure transients, accelerating) say where the mismatch lives. The
   flow witnesses (mass flow each recorded chamber received by the chamber equation,
   minus the valve law at the recorded command, pressures and supply) and the force
   witness are shown in the report.
3. **Explain** (:mod:`.candidates`, :mod:`.refit`, :mod:`.explain`, :mod:`.sets`):
   every effect of formats.md section 2 and every nominal value that may be wrong is
   added to the plant and refitted on the short-horizon predictions (signature scan
   on a grid, then bounded least squares; all candidates in parallel processes; the
   four most promising refitted fully). Evidence: share of the mismatch removed,
   information criterion (dBIC with an effective number of observations), no loss on
   the re-anchored closed-loop replay, consistency with the regimes where the effect
   acts. Then *sets*: every pair of the most promising candidates and triples around
   the best pair are refitted jointly, and the set with the lowest BIC in which every
   member earns its place (:mod:`.sets`) gives the findings; nothing significant: no
   finding -- unless the nominal replay failed or fits worse than a constant, which
   is then an error with its cause (:mod:`.health`), never an all-clear.
4. **Model and refit**: each finding's values are polished by the grey-box estimator
   (:mod:`.polish`) on the windows where it removes most of the mismatch; the
   augmented plant is replayed like the nominal one (``fit_after``) and written as
   ``plant.augmented.toml``. What it still leaves is compared with the noise floor
   per signal and regime (:func:`.health.verdict`); where the recorded loop hunts
   against stiction (:func:`.health.hunting`), whose phase no free-running replay
   reproduces, the share of the mismatch there and the fit outside are said.

Examples
--------
Skipped here: a diagnosis takes 5-10 s (tests/test_diagnose*.py run it):

>>> from workbench.diagnose import diagnose
>>> d = diagnose("plant.toml", "recording.csv")          # doctest: +SKIP
>>> d.findings[0].effect, d.fit_before, d.fit_after       # doctest: +SKIP
('valve_offset', {'x': 52.2, ...}, {'x': 99.9, ...})
>>> d.write("out/")                                      # doctest: +SKIP
"""

from __future__ import annotations

import math
import os
import sys
import time
from typing import Any, Mapping, Sequence

import numpy as np

from ..params import PlantParams
from ..plant import Plant
from ..recording import Recording
from .blas import single_thread
from .candidates import Candidate, candidates as make_candidates
from .data import Prepared, prepare_many, recorded_supply
from .evidence import confidence, evidence_text
from .explain import Chosen, Ranked, Refits, promising, refit_fully, screen
from .health import DiagnosisError, hunting, verdict
from .locate import concentration, intervals, smooth_error
from .nominal import Nominal, nominal
from .replays import OPEN_ANCHOR, EngineOpenLoop, fits as _fits, observer_rates, replay
from .result import Diagnosis, Finding
from .sets import MIN_CORRECTION, search
from .witness import Witness

__all__ = ["Finding", "Diagnosis", "diagnose", "replay", "EngineOpenLoop", "DiagnosisError"]


# ---------------------------------------------------------------------- the diagnosis
def diagnose(plant: str | os.PathLike | Plant,
             recording: str | os.PathLike | Recording | Sequence[str | os.PathLike | Recording],
             effects: Sequence[str] | None = None, workers: int | None = None,
             mode: str = "auto", verbose: bool = False, jit: bool = True,
             max_nfev: int = 10, budget_s: float | None = None,
             polish_values: bool = True) -> Diagnosis:
    """Diagnose the mismatch between a nominal plant and a recording.

    Parameters
    ----------
    plant : plant file (formats.md sections 1-2) or Plant.
    recording : recording file (section 3) or Recording, or a list of them: several
        experiments on the same rig, diagnosed together (one set of findings for all,
        the fit per recording in ``Diagnosis.recordings``; :func:`.data.prepare_many`).
        Each is checked against the plant first (:meth:`Recording.check`: units, stroke,
        command range), as :func:`workbench.replay.replay` does.
    effects : candidate effects to test (names of section 2 and/or ``parameter_error``);
        default all.
    workers : processes for the candidate refits (default the CPU count).
    mode : replay "auto" (closed loop when r and a matching controller exist), "closed"
        or "open".
    verbose : print progress (to stderr).
    max_nfev : least-squares iterations per candidate.
    budget_s : after this wall time (s), no triples are refitted (pairs still are).
    polish_values : refine each finding's values with the grey-box estimator
        (:mod:`.polish`) on the windows where it removes most of the mismatch.

    Returns
    -------
    Diagnosis

    Raises
    ------
    InputError
        Unusable input (see :meth:`Recording.check`, :func:`.data.prepare` and
        :func:`.data.prepare_many`).
    DiagnosisError
        The nominal replay fails (non-finite, piston beyond the stops) or fits a signal
        worse than a constant and no candidate explains it, or the augmented replay
        fails (:func:`.health.verdict`): never reported as "no finding".
    """
    with single_thread():       # the refits' parallelism is their worker processes
        return _diagnose(plant, recording, effects, workers, mode, verbose, jit, max_nfev,
                         budget_s, polish_values)


def _diagnose(plant, recording, effects, workers, mode, verbose, jit, max_nfev, budget_s,
              polish_values) -> Diagnosis:
    """:func:`diagnose` (its arguments in its order)."""
    clock = _Clock(verbose)
    plant, plant_file, recs, rec_file = _load(plant, recording)
    clock.restart()
    plant, supply_notes = recorded_supply(plant, recs)
    prep = prepare_many(plant, recs, mode)
    prep.notes[:0] = supply_notes
    params = plant.params
    clock.tick("prepare")
    # 1. replay on the nominal plant
    sim0 = replay(plant, prep)
    fit_before = _fits(prep, sim0)
    clock.tick("nominal replay")
    # 2. comparable predictions, witnesses, regimes
    nom = nominal(prep, params, jit)
    clock.tick("witnesses and regimes")
    # 3. explain: every candidate screened, the most promising refitted fully
    cands = make_candidates(params, effects, bool(prep.pressures))
    if prep.supply is not None:        # the recorded p_s is the supply: nothing to fit
        cands = [c for c in cands if c.effect != "supply_droop"
                 and c.name != "parameter_error:supply.pressure"]
    refits = Refits(prep, params, nom.shpe, nom.seg, nom.masks, workers, jit)
    nothing = Chosen.nothing(nom.cost, nom.seg_cost, nom.err)
    ranking = screen(refits, cands, nothing)
    clock.tick("candidates screened")
    top = promising(ranking)
    if top:
        ranking = refit_fully(refits, cands, ranking, top, max_nfev, nothing)
        clock.tick("best candidates refitted")
    # 4. choose findings (greedy) and polish their values
    by_name = {c.name: c for c in cands}
    chosen, sets_info = search(refits, cands, ranking, max_nfev, nothing,
                               lambda: budget_s is not None and clock.elapsed() > budget_s)
    clock.tick(f"sets of explanations ({sets_info['candidate_models']} candidate models)")
    # a chosen candidate refitted by the set search (from a pair's values) is reported
    # with that fit: the ranking (details.json) lists the values the findings carry
    refitted = {r.name: r for r in chosen.ranked}
    ranking = [refitted.get(r.name, r) for r in ranking]
    polished: dict[str, Any] = {}
    if polish_values and chosen.ranked:
        polished = _polish_findings(prep, params, chosen.ranked, by_name, nom.err)
        clock.tick("grey-box polish")
    # 5. model and refit: the augmented plant replayed like the nominal one
    kept = _without_negligible(prep, params, chosen.ranked, by_name, nom, max_nfev, jit)
    found, replay_note = _replay_check(prep, params, kept, ranking, by_name, nom, max_nfev, jit)
    findings, aug, sim_after = found
    witness_after: dict[str, np.ndarray] = {}
    if findings and prep.pressures:
        witness_after = _witness_after(prep, nom.wit, aug, jit)
    if findings:
        clock.tick("augmented replay")
    hunt = hunting(prep, nom.wit.v_rest)
    remaining, still, notes = verdict(prep, sim0, [f.effect for f in findings], sim_after,
                                      nom.masks, _no_finding_note(ranking), hunt)
    if replay_note:
        notes.append(replay_note)
    return Diagnosis(
        hunting=[[round(float(prep.t[a]), 4), round(float(prep.t[b - 1]), 4)] for a, b in hunt],
        recordings=_per_recording(prep, sim0, sim_after if findings else sim0),
        plant_file=plant_file, recording_file=rec_file, fit_before=fit_before,
        fit_after=findings[-1].fit_after if findings else dict(fit_before), findings=findings,
        ranking=ranking, located=nom.located, regime_share=nom.share,
        notes=notes, remaining=remaining, unexplained=still, sets=sets_info,
        mode=_mode_text(prep), nominal=params, augmented=aug, prep=prep, replay_nominal=sim0,
        replay_augmented=sim_after, witness=nom.witness, witness_after=witness_after,
        err_nominal=nom.err, err_after=chosen.err if findings else None, cost_nominal=nom.cost,
        cost_after=chosen.cost, timings=clock.total(), polished=polished)


class _Clock:
    """Wall time of each step of the diagnosis (``Diagnosis.timings``, s), printed to
    stderr as it goes when ``verbose``."""

    def __init__(self, verbose: bool) -> None:
        self.verbose = verbose
        self.start = time.perf_counter()
        self.last = self.start
        self.timings: dict[str, float] = {}

    def restart(self) -> None:
        """The next step is timed from now."""
        self.last = time.perf_counter()

    def tick(self, name: str) -> None:
        """Record the step ``name`` as ending now."""
        now = time.perf_counter()
        self.timings[name] = round(now - self.last, 3)
        if self.verbose:
            print(f"  [{now - self.start:6.1f} s] {name}", file=sys.stderr, flush=True)
        self.last = now

    def elapsed(self) -> float:
        """s since the diagnosis started."""
        return time.perf_counter() - self.start

    def total(self) -> dict[str, float]:
        """The step timings with the total wall time added."""
        self.timings["total"] = round(self.elapsed(), 3)
        return self.timings


def _load(plant, recording) -> tuple[Plant, str, list[Recording], str]:
    """The plant (stick-slip friction) and the recordings, loaded when given as files and
    checked against the plant (:meth:`Recording.check`: what a file loader checks, and
    mm, ms, the stroke and the command range), and the file names the result reports."""
    from ..errors import InputError
    from ..recording import load_recording
    plant_file = str(plant) if not isinstance(plant, Plant) else plant.params.source
    if not isinstance(plant, Plant):
        plant = Plant.from_toml(plant)
    many = isinstance(recording, (list, tuple))
    items = list(recording) if many else [recording]
    if not items:
        raise InputError("no recording given: a diagnosis needs at least one")
    recs = [r if isinstance(r, Recording) else load_recording(r) for r in items]
    names = [r.source if isinstance(r, Recording) else str(r) for r in items]
    for r in recs:
        r.check(plant)
    if plant.friction != "stick":
        plant = plant.with_friction("stick")
    return plant, plant_file, recs, " + ".join(str(n) for n in names)


def _per_recording(prep: Prepared, sim0: Mapping[str, np.ndarray],
                   sim1: Mapping[str, np.ndarray]) -> list[dict[str, Any]]:
    """Fit (%) per signal before and after, per recording (one entry for one recording)."""
    parts = prep.parts or [prep]
    cuts = list(prep.starts or [0]) + [prep.n]
    out = []
    for part, a, b in zip(parts, cuts[:-1], cuts[1:]):
        def sl(sim):
            return {k: np.asarray(v)[a:b] for k, v in sim.items()}
        out.append({"recording": str(part.rec.source), "start_s": round(float(a * prep.dt), 6),
                    "duration_s": round(float((b - a) * prep.dt), 6),
                    "fit_before": _fits(part, sl(sim0)), "fit_after": _fits(part, sl(sim1))})
    return out


def _mode_text(prep: Prepared) -> str:
    """How the recording was replayed, in words."""
    if prep.closed:
        return "closed loop on r with the plant file's controller"
    return f"open loop on u, re-anchored on the measured state every {OPEN_ANCHOR:g} s"


def _gain(chosen: Sequence[Ranked], i: int, err0: np.ndarray) -> np.ndarray:
    """Per-sample short-horizon error that finding ``i`` removes on top of the earlier ones."""
    return (err0 if i == 0 else chosen[i - 1].result.err) - chosen[i].result.err


def _polish_findings(prep: Prepared, params: PlantParams, chosen: Sequence[Ranked],
                     by_name: Mapping[str, Candidate], err0: np.ndarray) -> dict[str, Any]:
    """Each finding's values refined by the grey-box estimator on the windows where it
    removes most of the mismatch (in place; the refit's values stand when the polish
    fails or jumps). Returns what was polished, for ``details.json``.

    Each member is polished with every other finding in the plant at its values, not
    only the earlier ones: the set was fitted jointly, and values that trade off
    across members (a supply pressure and a droop's regulator) polished without the
    partner take its share (the supply lowered for the droop's pressure drop, then the
    droop added on top: the drop twice). The polish refines on two short windows; the
    replay of the whole recording is its check: when the polished values fit it worse
    (mean fit over the signals), the refit's values stand (``polished["reverted"]``).
    """
    from .polish import polish
    polished: dict[str, Any] = {}
    refit = _snapshot(chosen)
    for i, r in enumerate(chosen):
        cand = by_name[r.name]
        base = params.replace(**{k: v for j, o in enumerate(chosen) if j != i
                                 for k, v in o.result.plant_values.items()})
        pol = polish(prep, base, cand, r.result.values, _gain(chosen, i, err0))
        if pol is not None:
            r.result.values = pol.values
            r.result.plant_values = cand.plant_values(pol.values)
            r.result.std = {**r.result.std, **pol.std}
            r.result.ci95 = {**r.result.ci95, **pol.ci95}
            polished[r.name] = {"windows_s": pol.windows, "status": pol.status,
                                "wall_s": round(pol.wall_s, 2)}
    if polished:
        after = _mean_fit(prep, params, [r.result.plant_values for r in chosen])
        before = _mean_fit(prep, params, [pv for _, pv, _, _ in refit])
        if not after >= before:
            _restore(chosen, refit)
            polished = {"reverted": {"polished": polished, "mean_fit_polished": after,
                                     "mean_fit_refit": before}}
    return polished


def _mean_fit(prep: Prepared, params: PlantParams, plant_values: Sequence[Mapping[str, Any]]
              ) -> float:
    """Mean fit (%) over the signals of the whole recording's replay with ``plant_values``
    added to ``params`` (-inf when the replay fails)."""
    aug = params
    for pv in plant_values:
        aug = aug.replace(**pv)
    try:
        fits = _fits(prep, replay(Plant(aug), prep))
    except Exception as exc:  # noqa: BLE001 - a failed replay loses the comparison
        from ..output import reraise_interrupt
        reraise_interrupt(exc)
        return -math.inf
    return _mean(fits)


def _mean(fits: Mapping[str, float]) -> float:
    """Mean of the finite fits (%), -inf without any."""
    vals = [v for v in fits.values() if math.isfinite(v)]
    return float(np.mean(vals)) if vals else -math.inf


def _assign(kept: Sequence[Ranked], members: Sequence[Candidate], res: Any) -> list[tuple]:
    """Each finding of ``kept`` takes its values from the joint fit ``res``; returns the
    values it had (for :func:`_restore`)."""
    old = _snapshot(kept)
    for r, m in zip(kept, members):
        keys = [f.key for f in m.free]
        r.result.values = {k: res.values[k] for k in keys}
        r.result.plant_values = m.plant_values(r.result.values)
        r.result.std = {k: v for k, v in res.std.items() if k in keys}
        r.result.ci95 = {k: v for k, v in res.ci95.items() if k in keys}
    return old


def _snapshot(kept: Sequence[Ranked]) -> list[tuple]:
    """Each finding's values, plant values, std and ci95 (for :func:`_restore`)."""
    return [(r.result.values, r.result.plant_values, r.result.std, r.result.ci95)
            for r in kept]


def _restore(kept: Sequence[Ranked], old: Sequence[tuple]) -> None:
    """The values :func:`_assign` replaced, back."""
    for r, (vals, pv, std, ci) in zip(kept, old):
        r.result.values, r.result.plant_values = vals, pv
        r.result.std, r.result.ci95 = std, ci


def _without_negligible(prep: Prepared, params: PlantParams, chosen: Sequence[Ranked],
                        by_name: Mapping[str, Candidate], nom: Nominal, max_nfev: int,
                        jit: bool) -> list[Ranked]:
    """The chosen findings without the negligible corrections (:func:`_at_nominal`);
    when one is left out, the others are refitted jointly without it (short horizons,
    from their values): they were fitted beside it, and keep what it took (session 11's
    blind sweep: offset + 30 Hz spool lag, the correction polished to < 3 % and left
    out, the pressures fit 83.6/81.8 % with the rest's values where the set fitted
    96.3/96.0 %)."""
    kept = [r for r in chosen if not _at_nominal(r, params)]
    if not kept or len(kept) == len(chosen):
        return kept
    from .refit import refit_set
    members = [by_name[r.name] for r in kept]
    res = refit_set(prep, params, members,
                    {k: v for r in kept for k, v in r.result.values.items()},
                    nom.shpe, max_nfev, jit)
    if res is not None and res.error is None and np.isfinite(res.cost):
        _assign(kept, members, res)
    return kept


def _replay_check(prep: Prepared, params: PlantParams, kept: Sequence[Ranked],
                  ranking: Sequence[Ranked], by_name: Mapping[str, Candidate], nom: Nominal,
                  max_nfev: int, jit: bool) -> tuple[tuple, str | None]:
    """:func:`_findings`, checked on the whole recording's replay: when the plant with
    every finding fits it worse (mean over signals) than with only the first of them,
    the set's values -- fitted on 0.2 s horizons -- are refitted jointly on the long
    re-anchored replay (:func:`.refit.refit_set`) and kept when the whole
    replay then fits better. What still fits worse is said (a note), never reported
    as the set's improvement. Returns (findings, augmented params, replay) and the note.
    """
    from .refit import refit_set
    found = _findings(prep, params, kept, ranking, by_name, nom)
    means = [_mean(f.fit_after) for f in found[0]]
    if len(means) < 2 or means[-1] >= max(means[:-1]):
        return found, None
    members = [by_name[r.name] for r in kept]
    res = None
    if nom.seg is not None:
        res = refit_set(prep, params, members,
                        {k: v for r in kept for k, v in r.result.values.items()},
                        nom.seg, max_nfev, jit)
    if res is not None and res.error is None:
        old = _assign(kept, members, res)
        again = _findings(prep, params, kept, ranking, by_name, nom)
        if _mean(again[0][-1].fit_after) > means[-1]:
            found, means = again, [_mean(f.fit_after) for f in again[0]]
        else:
            _restore(kept, old)
    if means[-1] >= max(means[:-1]):
        return found, None
    i = int(np.argmax(means[:-1]))
    text = ", ".join(f"{k} {found[0][i].fit_after[k]:.1f} -> {v:.1f} %"
                     for k, v in found[0][-1].fit_after.items())
    return found, (f"the replay with every finding fits worse than with the first {i + 1} "
                   f"({text}): the later findings' values were fitted on 0.2 s horizons "
                   "and trade off with the earlier ones there; the whole replay does not "
                   "support them as fitted")


def _findings(prep: Prepared, params: PlantParams, chosen: Sequence[Ranked],
              ranking: Sequence[Ranked], by_name: Mapping[str, Candidate], nom: Nominal
              ) -> tuple[list[Finding], PlantParams, dict[str, np.ndarray]]:
    """The findings, each with the fit of the plant augmented by it and the earlier
    ones; the augmented parameters and the last augmented replay ({} without findings)."""
    findings: list[Finding] = []
    aug = params
    sim_after: dict[str, np.ndarray] = {}
    for i, r in enumerate(chosen):
        aug = aug.replace(**r.result.plant_values)
        sim_after = replay(Plant(aug), prep)
        runner = next((o for o in ranking if o is not r and o.name != r.name), None) \
            if i == 0 else None
        findings.append(_finding(prep, r, by_name[r.name], _gain(chosen, i, nom.err), runner,
                                 _fits(prep, sim_after), nom.masks))
    return findings, aug, sim_after


def _finding(prep: Prepared, r: Ranked, cand: Candidate, gain: np.ndarray,
             runner: Ranked | None, fit_after: dict[str, float],
             masks: Mapping[str, np.ndarray]) -> Finding:
    """One finding: where it removes the mismatch, its confidence and evidence text."""
    g_s = smooth_error(gain, prep.dt)
    where = intervals(g_s, prep.t, 0.2 * float(np.nanmax(g_s)) if np.nanmax(g_s) > 0 else 1.0)
    return Finding(
        effect=r.result.effect, confidence=confidence(r, runner),
        parameters=cand.reported(r.result.values), where=where,
        evidence=evidence_text(r, cand, concentration(gain, masks), prep), fit_after=fit_after,
        name=r.name, plant_values=dict(r.result.plant_values), std=dict(r.result.std),
        ci95=dict(r.result.ci95))


def _witness_after(prep: Prepared, wit: Witness, aug: PlantParams, jit: bool
                   ) -> dict[str, np.ndarray]:
    """Flow and force witnesses of the augmented plant (dry friction, if found, is taken
    out of the observer and handed to the witness, which applies it along the data)."""
    fr = None
    p_obs = aug
    if aug.has_effect("dry_friction"):
        fr = {k: aug[f"friction.{k}"] for k in ("coulomb", "static", "stribeck_velocity")}
        p_obs = aug.without_effect("dry_friction")
    return wit.in_units(wit.residuals(observer_rates(prep, p_obs, jit), fr))


def _at_nominal(r: Ranked, params: PlantParams) -> bool:
    """A nominal-value correction whose (polished) values change no nominal value by
    :data:`.sets.MIN_CORRECTION`: not a finding, by the rule the set search applies to
    the fitted values (the grey-box polish is the more accurate estimate; measured: on a
    2 kHz recording of a 32 mm foreign rig with a 30 Hz spool lag and the plant file
    exact, the set's correction was polished to within 2.8 % -- mass -0.3 %, viscous
    friction +2.8 % -- and was still named, with a 0.5 % rule)."""
    return r.result.effect == "parameter_error" and all(
        k in params and abs(float(v) - float(params[k])) < MIN_CORRECTION * abs(float(params[k]))
        for k, v in r.result.plant_values.items())


def _no_finding_note(ranking: Sequence[Ranked]) -> list[str]:
    """Why nothing was found: the best candidate and what it lacked."""
    if not ranking:
        return []
    best = ranking[0]
    return [f"no candidate is significant; the best, {best.name}, would remove "
            f"{100 * best.gain:.0f} % of the short-horizon prediction error ({best.reason})"]
