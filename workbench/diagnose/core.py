"""The diagnosis: replay, locate, explain, model and refit -- :func:`diagnose`.

Method
------
1. **Replay** the recording on the nominal plant (:func:`replay`): closed loop on ``r``
   with the plant file's controller (CVODES, as ``workbench simulate``) when the
   recording has ``r`` and the controller reproduces the recorded command, else open
   loop on ``u`` re-anchored on the measured state every 0.5 s. The fit per signal is
   ``fit_before``. Rig recordings: one chamber pressure is fitted and anchored, the
   other estimated by the force balance (:func:`.data.other_side`); a recorded ``p_s``
   that sags is the supply sample by sample (the replay then runs on the engine);
   several recordings are joined (:func:`.data.prepare_many`), replayed one by one,
   with their fits reported per recording.
2. **Locate** (:mod:`.locate`, :mod:`.witness`): short-horizon predictions (0.2 s,
   open loop on the recorded command from the measured state, :mod:`.predict`) give a
   per-sample error that does not drift; its intervals above the noise and its share
   in each operating regime (at rest, moving, reversals, near the valve centre, high
   flow, fast pressure transients, accelerating) say where the mismatch lives. The
   flow witnesses (mass flow each chamber received by the chamber equation, minus the
   valve law at the recorded command and pressures) and the force witness are shown
   in the report.
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
   ``plant.augmented.toml``.

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

import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..params import PlantParams, atomic_write_text
from ..plant import Plant
from ..recording import Recording, fit
from .candidates import Candidate, candidates as make_candidates
from .data import Prepared, prepare_many, recorded_supply
from .evidence import confidence, evidence_text
from .explain import Chosen, Ranked, Refits, promising, refit_fully, screen
from .sets import search
from .health import DiagnosisError, verdict
from .locate import concentration, intervals, regimes, smooth_error
from .predict import Predictor, horizons, segments
from .refit import CandidateModel
from .witness import Witness, observer_inputs

__all__ = ["Finding", "Diagnosis", "diagnose", "replay", "EngineOpenLoop", "DiagnosisError"]

#: s: anchor spacing of the open-loop replay reported when there is no closed loop.
OPEN_ANCHOR = 0.5


@dataclass(frozen=True)
class Finding:
    """One explanation found (formats.md section 4, plus what the report shows).

    Attributes
    ----------
    effect : effect name of formats.md section 2 (or ``parameter_error``).
    confidence : 0..1.
    parameters : effect keys without section (dotted keys for ``parameter_error``).
    where : time intervals (s) in which the mismatch this finding removes shows.
    evidence : one or two sentences a rig engineer can check on the plot.
    fit_after : fit (%) per signal with this and the earlier findings added.
    name : candidate name. plant_values : dotted keys added to the plant file.
    std, ci95 : uncertainty of the fitted values (candidate keys).
    """

    effect: str
    confidence: float
    parameters: dict[str, float]
    where: list[list[float]]
    evidence: str
    fit_after: dict[str, float]
    name: str = ""
    plant_values: dict[str, Any] = field(default_factory=dict)
    std: dict[str, float] = field(default_factory=dict)
    ci95: dict[str, tuple[float, float]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """This finding as in the diagnosis JSON (formats.md section 4)."""
        return {"effect": self.effect, "confidence": round(float(self.confidence), 3),
                "parameters": {k: _num(v) for k, v in self.parameters.items()},
                "where": [[float(a), float(b)] for a, b in self.where],
                "evidence": self.evidence,
                "fit_after": {k: _round(v) for k, v in self.fit_after.items()}}


def _num(v: float) -> float:
    return float(f"{float(v):.6g}")


def _round(v: float) -> float | None:
    return None if not np.isfinite(v) else round(float(v), 2)


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`; :meth:`to_dict` is formats.md section 4 exactly."""

    plant_file: str
    recording_file: str
    fit_before: dict[str, float]
    fit_after: dict[str, float]
    findings: list[Finding]
    ranking: list[Ranked]
    located: list[list[float]]
    regime_share: dict[str, dict[str, float]]
    notes: list[str]
    mode: str
    nominal: PlantParams
    augmented: PlantParams
    prep: Prepared = field(repr=False)
    replay_nominal: dict[str, np.ndarray] = field(repr=False, default_factory=dict)
    replay_augmented: dict[str, np.ndarray] = field(repr=False, default_factory=dict)
    witness: dict[str, np.ndarray] = field(repr=False, default_factory=dict)
    witness_after: dict[str, np.ndarray] = field(repr=False, default_factory=dict)
    err_nominal: np.ndarray | None = field(repr=False, default=None)
    err_after: np.ndarray | None = field(repr=False, default=None)
    cost_nominal: float = float("nan")
    cost_after: float = float("nan")
    timings: dict[str, float] = field(default_factory=dict)
    polished: dict[str, Any] = field(default_factory=dict)
    remaining: dict[str, dict[str, float]] = field(default_factory=dict)
    unexplained: list[str] = field(default_factory=list)
    sets: dict[str, Any] = field(default_factory=dict)
    recordings: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """The diagnosis result of formats.md section 4 (exactly those keys)."""
        return {"plant": self.plant_file, "recording": self.recording_file,
                "fit_before": {k: _round(v) for k, v in self.fit_before.items()},
                "fit_after": {k: _round(v) for k, v in self.fit_after.items()},
                "findings": [f.to_dict() for f in self.findings]}

    def details(self) -> dict[str, Any]:
        """Everything else (ranking, regimes, notes, timings) for ``details.json``."""
        return {
            "mode": self.mode, "notes": list(self.notes), "located": self.located,
            "regimes": self.regime_share,
            "short_horizon_cost": {"nominal": self.cost_nominal, "after": self.cost_after},
            "candidates": [{
                "candidate": r.name, "effect": r.result.effect, "significant": r.significant,
                "gain": r.gain, "gain_per_value": r.gain_per_value, "dbic": r.dbic,
                "closed_loop_gain": r.seg_gain, "consistency": r.consistency,
                "weight": r.weight, "values": r.result.values, "std": r.result.std,
                "ci95": {k: list(v) for k, v in r.result.ci95.items()},
                "cost": r.result.cost, "fits": r.result.fits, "reason": r.reason,
                "error": r.result.error, "wall_s": r.result.wall_s, "evaluations": r.result.nfev}
                for r in self.ranking],
            "grey_box_polish": self.polished,
            "remaining_vs_noise": self.remaining, "unexplained": list(self.unexplained),
            "sets": self.sets, "recordings": self.recordings,
            "timings_s": self.timings,
        }

    def summary(self) -> str:
        """A few lines for the terminal."""
        def fits(d):
            return ", ".join(f"{k} {v:.1f} %" for k, v in d.items())
        lines = [f"diagnosis of {self.recording_file} on {self.plant_file} ({self.mode})",
                 f"  fit before: {fits(self.fit_before)}"]
        if not self.findings and not self.unexplained:
            lines.append("  no finding: the nominal model explains the recording within its "
                         "noise (no candidate is significant)")
        elif not self.findings:
            lines.append("  no finding: no candidate is significant, but the nominal model "
                         "does not explain the recording (below)")
        for i, f in enumerate(self.findings, 1):
            par = ", ".join(f"{k} = {v:.4g}" for k, v in f.parameters.items())
            lines.append(f"  {i}. {f.effect} (confidence {f.confidence:.2f}): {par}")
            lines.append(f"     {f.evidence}")
        lines.append(f"  fit after:  {fits(self.fit_after)}")
        for r in self.recordings if len(self.recordings) > 1 else ():
            lines.append(f"    {r['recording']}: before {fits(r['fit_before'])}; "
                         f"after {fits(r['fit_after'])}")
        if self.sets:
            lines.append(f"  {self.sets.get('candidate_models', 0)} candidate models evaluated "
                         "(single effects, pairs and triples)")
        for sg in self.sets.get("suggested", []) if self.sets else ():
            lines.append(f"  also significant, not named: {sg['text']}")
        for n in self.unexplained:
            lines.append(f"  still unexplained: {n}")
        for n in self.notes:
            lines.append(f"  note: {n}")
        return "\n".join(lines)

    def write(self, out_dir: str | os.PathLike, report: bool = True,
              inputs: Sequence[str | os.PathLike | None] = ()) -> dict[str, Path]:
        """Write diagnosis.json, plant.augmented.toml, details.json and report.html/.pdf
        (with its figures) as one result set (:func:`workbench.output.result_set`): all
        of them, or -- on any failure -- nothing new in ``out_dir``. ``inputs`` (default
        the plant and recording files) are never overwritten."""
        from ..output import result_set
        out = Path(out_dir)
        names = {"json": "diagnosis.json", "plant": "plant.augmented.toml",
                 "details": "details.json"}
        ins = list(inputs) or [self.plant_file, *self.recording_file.split(" + ")]
        with result_set(out, inputs=[i for i in ins if i]) as stage:
            atomic_write_text(stage / names["json"], json.dumps(self.to_dict(), indent=2) + "\n")
            self.augmented.to_toml(stage / names["plant"])
            atomic_write_text(stage / names["details"],
                              json.dumps(_jsonable(self.details()), indent=1) + "\n")
            if report:
                from .report import write_report
                html, pdf = write_report(self, stage)
                names["html"], names["pdf"] = Path(html).name, Path(pdf).name
        return {k: out / v for k, v in names.items()}


def _jsonable(v):
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return None if not np.isfinite(v) else float(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v


# ---------------------------------------------------------------------- replay
@dataclass(frozen=True, eq=False)
class EngineOpenLoop:
    """Replay strategy (:class:`workbench.replay.Strategy`) that the diagnosis provides:
    open loop on u on its fixed-step engine (:mod:`.engine`, ROS2 with stick-slip),
    re-anchored on the measured (smoothed) state every ``anchor_every`` s.

    It stays here because its numbers are those of the engine, not of CVODES; ``x0``
    and ``params`` are not used (the anchors come from ``prep``, the parameters from
    the plant). Returns x, p_a, p_b, u on the recording's samples.
    """

    prep: Prepared
    anchor_every: float = OPEN_ANCHOR

    def __call__(self, plant: Plant, recording: Recording, x0=None, params=None,
                 progress=False) -> dict[str, np.ndarray]:
        model = CandidateModel(self.prep, plant.params, None)
        pred = segments(self.prep, self.anchor_every)
        Y = model.run(pred, {})
        return {k: pred.full(Y, i) for i, k in enumerate(("x", "p_a", "p_b", "u"))}


def replay(plant: Plant, prep: Prepared) -> dict[str, np.ndarray]:
    """The recording replayed on ``plant`` (:mod:`workbench.replay`): closed loop on r
    (CVODES, :class:`~workbench.replay.ClosedLoop` with the diagnosis' controller, from
    the first position, smoothed pressures and recorded u) when the diagnosis runs closed
    loop, falling back on the engine re-anchored every 2 s when CVODES fails; else
    open loop on u on the engine re-anchored every :data:`OPEN_ANCHOR` s
    (:class:`EngineOpenLoop`). Returns x, p_a, p_b, u on the recording's samples."""
    from .. import replay as rp
    if prep.parts:             # several recordings: each replayed on its own
        runs = [replay(plant, part) for part in prep.parts]
        return {k: np.concatenate([r[k] for r in runs]) for k in ("x", "p_a", "p_b", "u")}
    if not prep.closed:
        return EngineOpenLoop(prep, OPEN_ANCHOR)(plant, prep.rec)
    if prep.supply is not None:   # p_s sample by sample: the engine's closed loop, unbroken
        return EngineOpenLoop(prep, 2.0 * prep.t[-1] + 1.0)(plant, prep.rec)
    x0 = rp.initial_state(plant, prep.rec, u0=float(prep.rec["u"][0]),
                          recorded_pressures=False, **prep.first_pressures())
    strategy = rp.Fallback(rp.ClosedLoop(prep.controller), EngineOpenLoop(prep, 2.0))
    run = rp.run(plant, prep.rec, strategy, x0=x0)
    return {k: np.asarray(run[k], dtype=float) for k in ("x", "p_a", "p_b", "u")}


def _observer_rates(prep: Prepared, params: PlantParams, jit: bool) -> np.ndarray:
    """Model rates (dv, dp_a, dp_b) along the measurement, one observer pass at 1 step/sample."""
    from .engine import Engine
    plant = Plant(params)
    from .refit import substeps_for
    eng = Engine(plant, prep.dt, None, jit=jit, rates=True, substeps=substeps_for(prep.dt))
    z0 = plant.initial_state(float(np.clip(prep.xs[0], 0.0, plant.stroke)),
                             p_a=float(prep.pas[0]), p_b=float(prep.pbs[0]),
                             u0=float(prep.rec["u"][0]))
    return eng.run(z0, observer_inputs(prep), plant.p0)[4:7]


def _fits(prep: Prepared, sim: Mapping[str, np.ndarray]) -> dict[str, float]:
    out = {}
    for s in prep.signals:
        y = np.asarray(sim[s])
        ok = np.isfinite(y)
        out[s] = fit(prep.measured(s)[ok], y[ok]) if ok.sum() > 2 else float("nan")
    return out


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
    nom = _nominal(prep, params, jit)
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
    polished: dict[str, Any] = {}
    if polish_values and chosen.ranked:
        polished = _polish_findings(prep, params, chosen.ranked, by_name, nom.err)
        clock.tick("grey-box polish")
    # 5. model and refit: the augmented plant replayed like the nominal one
    kept = [r for r in chosen.ranked if not _at_nominal(r, params)]
    findings, aug, sim_after = _findings(prep, params, kept, ranking, by_name, nom)
    witness_after: dict[str, np.ndarray] = {}
    if findings and prep.has_pressures:
        witness_after = _witness_after(prep, nom.wit, aug, jit)
    if findings:
        clock.tick("augmented replay")
    remaining, still, notes = verdict(prep, sim0, [f.effect for f in findings], sim_after,
                                      nom.masks, _no_finding_note(ranking))
    return Diagnosis(
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


@dataclass
class _Nominal:
    """The nominal plant against the recording: the predictors, the short-horizon cost
    and per-sample error, the closed-loop segment cost, the witnesses, the operating
    regimes and where the mismatch lives."""

    shpe: Predictor
    seg: Predictor | None
    cost: float
    seg_cost: float | None
    err: np.ndarray
    wit: Witness
    masks: dict[str, np.ndarray]
    witness: dict[str, np.ndarray]
    share: dict[str, dict[str, float]]
    located: list[list[float]]


def _predictors(prep: Prepared) -> tuple[Predictor, Predictor | None]:
    """The refit objective (short-horizon predictions) and its closed-loop check
    (re-anchored segments, closed loop only), re-anchored where a recording starts."""
    if prep.closed and not prep.pressures:
        return _at_starts(segments(prep, 1.0), prep), None   # horizons drift without p
    seg = _at_starts(segments(prep), prep) if prep.closed else None
    return _at_starts(horizons(prep), prep), seg


def _at_starts(pred: Predictor, prep: Prepared) -> Predictor:
    """``pred`` re-anchored (state, pressures, hidden states, controller memory) at the
    first simulated sample of each joined recording after the first (several recordings:
    no prediction runs from one into the next)."""
    from .engine import INPUT_ROWS
    if len(prep.starts) < 2:
        return pred
    d = pred.inputs.data.copy()
    pos = np.searchsorted(pred.index, np.asarray(prep.starts[1:]))
    pos = pos[pos < len(pred.index)]
    for name in ("anchor", "anchor_hidden") + (("anchor_p",) if prep.pressures else ()):
        d[INPUT_ROWS.index(name), pos] = 1.0
    pred.inputs = type(pred.inputs)(d)
    pred.starts = np.unique(np.concatenate([pred.starts, pos]))
    return pred


def _nominal(prep: Prepared, params: PlantParams, jit: bool) -> _Nominal:
    """Step 2: the nominal model's predictions, witnesses and regimes."""
    shpe, seg = _predictors(prep)
    base = CandidateModel(prep, params, None, jit=jit)
    Y0 = base.run(shpe, {})
    err = shpe.error_by_sample(Y0)
    seg_cost = seg.cost(base.run(seg, {})) if seg is not None else None
    wit = Witness.build(prep)
    masks = regimes(prep, wit.v_rest)
    witness: dict[str, np.ndarray] = {}
    if prep.has_pressures:
        witness = wit.in_units(wit.residuals(_observer_rates(prep, params, jit)))
    e_s = smooth_error(err, prep.dt)
    floor = float(np.nanmedian(e_s[e_s > 0])) if np.any(e_s > 0) else 0.0
    located = intervals(e_s, prep.t, max(5.0 * floor, 3.0 * len(prep.signals)))
    return _Nominal(shpe=shpe, seg=seg, cost=shpe.cost(Y0), seg_cost=seg_cost, err=err,
                    wit=wit, masks=masks, witness=witness, share=concentration(err, masks),
                    located=located)


def _gain(chosen: Sequence[Ranked], i: int, err0: np.ndarray) -> np.ndarray:
    """Per-sample short-horizon error that finding ``i`` removes on top of the earlier ones."""
    return (err0 if i == 0 else chosen[i - 1].result.err) - chosen[i].result.err


def _polish_findings(prep: Prepared, params: PlantParams, chosen: Sequence[Ranked],
                     by_name: Mapping[str, Candidate], err0: np.ndarray) -> dict[str, Any]:
    """Each finding's values refined by the grey-box estimator on the windows where it
    removes most of the mismatch (in place; the refit's values stand when the polish
    fails or jumps). Returns what was polished, for ``details.json``."""
    from .polish import polish
    polished: dict[str, Any] = {}
    base = params
    for i, r in enumerate(chosen):
        cand = by_name[r.name]
        pol = polish(prep, base, cand, r.result.values, _gain(chosen, i, err0))
        if pol is not None:
            r.result.values = pol.values
            r.result.plant_values = cand.plant_values(pol.values)
            r.result.std = {**r.result.std, **pol.std}
            r.result.ci95 = {**r.result.ci95, **pol.ci95}
            polished[r.name] = {"windows_s": pol.windows, "status": pol.status,
                                "wall_s": round(pol.wall_s, 2)}
        base = base.replace(**r.result.plant_values)
    return polished


def _findings(prep: Prepared, params: PlantParams, chosen: Sequence[Ranked],
              ranking: Sequence[Ranked], by_name: Mapping[str, Candidate], nom: _Nominal
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
    return wit.in_units(wit.residuals(_observer_rates(prep, p_obs, jit), fr))


def _at_nominal(r: Ranked, params: PlantParams) -> bool:
    """A nominal-value correction whose (polished) values are the nominal ones within
    0.5 %: not a finding (a set may carry it along; it changes nothing)."""
    return r.result.effect == "parameter_error" and all(
        k in params and abs(float(v) - float(params[k])) <= 5e-3 * abs(float(params[k]))
        for k, v in r.result.plant_values.items())


def _no_finding_note(ranking: Sequence[Ranked]) -> list[str]:
    """Why nothing was found: the best candidate and what it lacked."""
    if not ranking:
        return []
    best = ranking[0]
    return [f"no candidate is significant; the best, {best.name}, would remove "
            f"{100 * best.gain:.0f} % of the short-horizon prediction error ({best.reason})"]
