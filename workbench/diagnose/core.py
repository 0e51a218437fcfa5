"""The diagnosis: replay, locate, explain, model and refit -- :func:`diagnose`.

Method
------
1. **Replay** the recording on the nominal plant (:func:`replay`): closed loop on ``r``
   with the plant file's controller (CVODES, as ``workbench simulate``) when the
   recording has ``r`` and the controller reproduces the recorded command, else open
   loop on ``u`` re-anchored on the measured state every 0.5 s. The fit per signal is
   ``fit_before``.
2. **Locate** (:mod:`.locate`, :mod:`.witness`): short-horizon predictions (0.2 s,
   open loop on the recorded command from the measured state, :mod:`.predict`) give a
   per-sample error that does not drift; its intervals above the noise and its share
   in each operating regime (at rest, moving, reversals, near the valve centre, high
   flow, fast pressure transients, accelerating) say where the mismatch lives. The
   flow witnesses (mass flow each chamber received by the chamber equation, minus the
   valve law at the recorded command and pressures) and the force witness are shown
   in the report.
3. **Explain** (:mod:`.candidates`, :mod:`.refit`, :mod:`.explain`): every effect of
   formats.md section 2 and every nominal value that may be wrong is added to the
   plant and refitted on the short-horizon predictions (signature scan on a grid,
   then bounded least squares; all candidates in parallel processes; the four most
   promising refitted fully). Evidence: share of the mismatch removed, information
   criterion (dBIC with an effective number of observations), no loss on the
   re-anchored closed-loop replay, consistency with the regimes where the effect acts.
   The best significant candidate is the first finding; further ones are added
   greedily while they stay significant on top; nothing significant: no finding.
4. **Model and refit**: each finding's values are polished by the grey-box estimator
   (:mod:`.polish`) on the windows where it removes most of the mismatch; the
   augmented plant is replayed like the nominal one (``fit_after``) and written as
   ``plant.augmented.toml``.

Examples
--------
>>> from workbench.diagnose import diagnose
>>> d = diagnose("plant.toml", "recording.csv")          # doctest: +SKIP
>>> d.findings[0].effect, d.fit_before, d.fit_after       # doctest: +SKIP
('valve_offset', {'x': 52.2, ...}, {'x': 99.9, ...})
>>> d.write("out/")                                      # doctest: +SKIP
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import WorkbenchError
from ..params import PlantParams, atomic_write_text
from ..plant import Plant
from ..recording import Recording, fit
from .candidates import Candidate, candidates as make_candidates
from .data import Prepared, prepare
from .explain import Ranked, rank, refit_all
from .locate import concentration, consistency, intervals, regimes, smooth_error
from .predict import horizons, segments
from .refit import CandidateModel
from .witness import Witness, observer_inputs

__all__ = ["Finding", "Diagnosis", "diagnose", "replay"]

#: s: anchor spacing of the open-loop replay reported when there is no closed loop.
OPEN_ANCHOR = 0.5
#: Further findings looked for after the first.
MAX_EXTRA = 2
#: Least-squares iterations of the screening refit of every candidate.
SCREEN_NFEV = 3
#: Candidates refitted fully after the screening.
FULL_REFITS = 4


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
        """The finding as in formats.md section 4 (one entry of ``findings``)."""
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
            "timings_s": self.timings,
        }

    def summary(self) -> str:
        """A few lines for the terminal."""
        def fits(d):
            return ", ".join(f"{k} {v:.1f} %" for k, v in d.items())
        lines = [f"diagnosis of {self.recording_file} on {self.plant_file} ({self.mode})",
                 f"  fit before: {fits(self.fit_before)}"]
        if not self.findings:
            lines.append("  no finding: the nominal model explains the recording within its "
                         "noise (no candidate is significant)")
        for i, f in enumerate(self.findings, 1):
            par = ", ".join(f"{k} = {v:.4g}" for k, v in f.parameters.items())
            lines.append(f"  {i}. {f.effect} (confidence {f.confidence:.2f}): {par}")
            lines.append(f"     {f.evidence}")
        lines.append(f"  fit after:  {fits(self.fit_after)}")
        for n in self.notes:
            lines.append(f"  note: {n}")
        return "\n".join(lines)

    def write(self, out_dir: str | os.PathLike, report: bool = True) -> dict[str, Path]:
        """Write diagnosis.json, plant.augmented.toml, details.json and report.html/.pdf."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {"json": out / "diagnosis.json", "plant": out / "plant.augmented.toml",
                 "details": out / "details.json"}
        atomic_write_text(paths["json"], json.dumps(self.to_dict(), indent=2) + "\n")
        self.augmented.to_toml(paths["plant"])
        atomic_write_text(paths["details"], json.dumps(_jsonable(self.details()), indent=1) + "\n")
        if report:
            from .report import write_report
            html, pdf = write_report(self, out)
            paths["html"], paths["pdf"] = html, pdf
        return paths


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
def replay(plant: Plant, prep: Prepared) -> dict[str, np.ndarray]:
    """The recording replayed on ``plant``: closed loop on r (CVODES, as ``workbench
    simulate``) when the diagnosis runs closed loop, else open loop on u re-anchored every
    :data:`OPEN_ANCHOR` s. Returns x, p_a, p_b, u on the recording's samples."""
    from .. import simulate
    rec = prep.rec
    t = prep.t
    if prep.closed:
        x0 = float(np.clip(rec["x"][0], 0.0, plant.stroke))
        kw = {}
        if prep.has_pressures:
            kw = {"p_a": float(prep.pas[0]), "p_b": float(prep.pbs[0])}
        z0 = plant.initial_state(x0, u0=float(rec["u"][0]), **kw)
        ref = simulate.Reference(times=t, values=np.asarray(rec["r"], dtype=float), hold=True)
        try:
            run = simulate.closed_loop(plant, prep.controller, ref, x0=z0, output_times=t,
                                       progress=False)
            return {k: np.asarray(run[k], dtype=float) for k in ("x", "p_a", "p_b", "u")}
        except WorkbenchError:
            pass                 # fall back on the engine (re-anchored) below
    model = CandidateModel(prep, plant.params, None)
    pred = segments(prep, OPEN_ANCHOR if not prep.closed else 2.0)
    Y = model.run(pred, {})
    return {k: pred.full(Y, i) for i, k in enumerate(("x", "p_a", "p_b", "u"))}


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


# ---------------------------------------------------------------------- evidence texts
def _fmt_where(conc: Mapping[str, Mapping[str, float]], name: str) -> str:
    best = sorted(conc.items(), key=lambda kv: -kv[1]["ratio"])
    top = [(k, v) for k, v in best if v["time_share"] > 0.01 and v["ratio"] >= 1.3][:2]
    parts = [f"{k} ({v['ratio']:.1f}x its share of time)" for k, v in top]
    return ("mostly " + " and ".join(parts)) if parts else "throughout the recording"


def _evidence(r: Ranked, cand: Candidate, conc: Mapping[str, Mapping[str, float]],
              prep: Prepared) -> str:
    v = r.result.values
    pv = r.result.plant_values
    name = r.name
    where = _fmt_where(conc, name)
    gain = f"adding it removes {100 * r.gain:.0f} % of the short-horizon prediction error"
    if name == "dry_friction":
        what = (f"the piston sticks and the pressures build up to a break-away force of "
                f"{pv['friction.static']:.3g} N before it moves, then slides against "
                f"{pv['friction.coulomb']:.3g} N")
    elif name == "valve_deadband":
        what = (f"commands within {100 * v['valve.deadband']:.2g} % of the span around the "
                f"centre move no air (pressures flat, piston stopped short of r)")
    elif name == "valve_offset":
        closed_at = prep.plant.params["valve.command_center"] + v["valve.null_offset"]
        what = (f"the valve is closed at u = {closed_at:.3g} V, not at the nominal centre "
                f"(steady error and drifting pressures at rest)")
    elif name == "valve_dynamics":
        what = (f"the pressures answer command steps with a lag "
                f"({v['valve.bandwidth']:.3g} Hz, damping {v['valve.damping']:.2g})")
    elif name == "line_dynamics":
        what = (f"pressure transients are delayed and damped as by {v['lines.length']:.3g} m "
                f"lines of {1e3 * v['lines.diameter']:.2g} mm")
    elif name == "leakage":
        what = (f"the chamber pressures decay while the valve is closed "
                f"(leak conductance {v['leakage.conductance_to_atmosphere']:.3g} m^3/(s Pa) "
                f"to atmosphere, {v['leakage.cross_piston']:.3g} kg/(s Pa) across the piston)")
    elif name == "supply_droop":
        what = (f"the pressures rise more slowly at large openings, as from a "
                f"{1e3 * v['supply.reservoir_volume']:.3g} l reservoir behind a regulator")
    elif name == "heat_transfer":
        what = (f"pressures overshoot in fast transients and relax afterwards, as gas "
                f"heated by compression cools through the walls "
                f"({v['gas.heat_transfer_coefficient']:.3g} W/K)")
    else:
        key = name.split(":", 1)[1]
        nominal = prep.plant.params[key]
        new = pv[key]
        what = f"{key} fits as {new:.4g} instead of the nominal {nominal:.4g}"
    return f"Mismatch {where}: {what}; {gain}."


def _confidence(r: Ranked, runner_up: Ranked | None) -> float:
    """BIC weight against the runner-up and "nothing", tempered by the share explained."""
    if runner_up is None or not np.isfinite(runner_up.dbic):
        w = 1.0 / (1.0 + math.exp(-0.5 * r.dbic)) if r.dbic < 60 else 1.0
    else:
        d = r.dbic - runner_up.dbic
        w = 1.0 / (1.0 + math.exp(-0.5 * d)) if abs(d) < 60 else (1.0 if d > 0 else 0.0)
        w = min(w, 1.0 / (1.0 + math.exp(-0.5 * r.dbic)) if r.dbic < 60 else 1.0)
    w *= 0.6 + 0.4 * min(max(r.gain, 0.0), 1.0)
    if r.consistency is not None and r.consistency < 0.5:
        w *= 0.85
    return float(min(max(w, 0.0), 0.99))


# ---------------------------------------------------------------------- the diagnosis
def diagnose(plant: str | os.PathLike | Plant, recording: str | os.PathLike | Recording,
             effects: Sequence[str] | None = None, workers: int | None = None,
             mode: str = "auto", verbose: bool = False, jit: bool = True,
             max_nfev: int = 10, budget_s: float | None = None,
             polish_values: bool = True) -> Diagnosis:
    """Diagnose the mismatch between a nominal plant and a recording.

    Parameters
    ----------
    plant : plant file (formats.md sections 1-2) or Plant.
    recording : recording file (section 3) or Recording.
    effects : candidate effects to test (names of section 2 and/or ``parameter_error``);
        default all.
    workers : processes for the candidate refits (default the CPU count).
    mode : replay "auto" (closed loop when r and a matching controller exist), "closed"
        or "open".
    verbose : print progress (to stderr).
    max_nfev : least-squares iterations per candidate.
    budget_s : stop looking for further findings after this wall time (s).
    polish_values : refine each finding's values with the grey-box estimator
        (:mod:`.polish`) on the windows where it removes most of the mismatch.

    Returns
    -------
    Diagnosis

    Raises
    ------
    InputError
        Unusable input (see :func:`.data.prepare`).
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}

    def tick(name: str, t0: float) -> float:
        now = time.perf_counter()
        timings[name] = round(now - t0, 3)
        if verbose:
            import sys
            print(f"  [{now - t_start:6.1f} s] {name}", file=sys.stderr, flush=True)
        return now

    plant_file = str(plant) if not isinstance(plant, Plant) else plant.params.source
    if not isinstance(plant, Plant):
        plant = Plant.from_toml(plant)
    rec_file = str(recording) if not isinstance(recording, Recording) else recording.source
    if not isinstance(recording, Recording):
        from ..recording import load_recording
        recording = load_recording(recording)
    if plant.friction != "stick":
        plant = plant.with_friction("stick")
    t0 = time.perf_counter()
    prep = prepare(plant, recording, mode)
    notes = list(prep.notes)
    params = plant.params
    t0 = tick("prepare", t0)

    # 1. replay on the nominal plant
    sim0 = replay(plant, prep)
    fit_before = _fits(prep, sim0)
    mode_txt = ("closed loop on r with the plant file's controller" if prep.closed else
                f"open loop on u, re-anchored on the measured state every {OPEN_ANCHOR:g} s")
    t0 = tick("nominal replay", t0)

    # 2. comparable predictions, witnesses, regimes
    shpe = horizons(prep)
    seg = segments(prep) if prep.closed else None
    if not prep.has_pressures and prep.closed:
        shpe = segments(prep, 1.0)      # open-loop horizons drift without pressures
        seg = None
    base = CandidateModel(prep, params, None, jit=jit)
    Y0 = base.run(shpe, {})
    cost0 = shpe.cost(Y0)
    err0 = shpe.error_by_sample(Y0)
    seg0 = seg.cost(base.run(seg, {})) if seg is not None else None
    wit = Witness.build(prep)
    masks = regimes(prep, wit.v_rest)
    witness0: dict[str, np.ndarray] = {}
    if prep.has_pressures:
        witness0 = wit.in_units(wit.residuals(_observer_rates(prep, params, jit)))
    conc0 = concentration(err0, masks)
    e_s = smooth_error(err0, prep.dt)
    floor = float(np.nanmedian(e_s[e_s > 0])) if np.any(e_s > 0) else 0.0
    located = intervals(e_s, prep.t, max(5.0 * floor, 3.0 * len(prep.signals)))
    t0 = tick("witnesses and regimes", t0)

    # 3. explain: refit every candidate
    cands = make_candidates(params, effects, prep.has_pressures)
    # every candidate: signature scan and a short refit; the most promising: a full refit
    results = refit_all(prep, params, cands, shpe, seg, workers=workers, max_nfev=SCREEN_NFEV,
                        jit=jit)

    def _cons(rs, err_ref):
        return {r.name: consistency(err_ref - r.err, masks, r.name) if r.err is not None
                else None for r in rs}

    ranking = rank(results, cost0, seg0, shpe.n_eff, _cons(results, err0))
    t0 = tick("candidates screened", t0)
    top = [r for r in ranking if np.isfinite(r.dbic) and r.dbic > 0][:FULL_REFITS]
    if top:
        by = {c.name: c for c in cands}
        again = refit_all(prep, params, [by[r.name] for r in top], shpe, seg, workers=workers,
                          max_nfev=max_nfev, jit=jit,
                          starts={r.name: r.result.values for r in top})
        merged = {r.name: r for r in results}
        for r_old, r_new in zip(top, again):
            if r_new.error is None and r_new.cost <= r_old.result.cost:
                r_new.grid = r_old.result.grid
                r_new.nfev += r_old.result.nfev
                r_new.wall_s += r_old.result.wall_s
                merged[r_new.name] = r_new
        results = [merged[c.name] for c in cands]
        ranking = rank(results, cost0, seg0, shpe.n_eff, _cons(results, err0))
        t0 = tick("best candidates refitted", t0)

    # 4. choose findings (greedy), model and refit
    by_name = {c.name: c for c in cands}
    chosen: list[Ranked] = []
    if ranking and ranking[0].significant:
        chosen.append(ranking[0])
    added: dict[str, Any] = dict(chosen[0].result.plant_values) if chosen else {}
    cost_cur = chosen[0].result.cost if chosen else cost0
    seg_cur = chosen[0].result.seg_cost if chosen else seg0
    err_cur = chosen[0].result.err if chosen else err0
    for _ in range(MAX_EXTRA):
        if not chosen or (budget_s is not None and time.perf_counter() - t_start > budget_s):
            break
        if (cost0 - cost_cur) / cost0 > 0.97:
            break                      # nothing left worth a further effect
        used = {c.result.effect for c in chosen if c.result.effect != "parameter_error"}
        used_names = {c.name for c in chosen}
        others = [r for r in ranking if r.significant and r.name not in used_names
                  and r.result.effect not in used
                  and not (r.result.effect == "parameter_error"
                           and any(k in added for k in r.result.plant_values))][:3]
        if not others:
            break
        more = refit_all(prep, params, [by_name[r.name] for r in others], shpe, seg,
                         workers=workers, max_nfev=max_nfev, jit=jit, base=added,
                         starts={r.name: r.result.values for r in others})
        ranked2 = rank(more, cost_cur, seg_cur, shpe.n_eff,
                       {r.name: consistency(err_cur - r.err, masks, r.name)
                        if r.err is not None else None for r in more})
        if not ranked2 or not ranked2[0].significant:
            break
        chosen.append(ranked2[0])
        added.update(ranked2[0].result.plant_values)
        cost_cur, seg_cur, err_cur = (ranked2[0].result.cost, ranked2[0].result.seg_cost,
                                      ranked2[0].result.err)
    if chosen:
        t0 = tick("further findings", t0)

    # 5. polish each finding's values with the grey-box estimator (a local refinement
    # on the windows where it removes most of the mismatch; the refit's values stand
    # when it fails or jumps)
    polished: dict[str, Any] = {}
    if polish_values:
        from .polish import polish as _polish
        base_pv = params
        for i, r in enumerate(chosen):
            gain_i = (err0 if i == 0 else chosen[i - 1].result.err) - r.result.err
            pol = _polish(prep, base_pv, by_name[r.name], r.result.values, gain_i)
            if pol is not None:
                cand = by_name[r.name]
                r.result.values = pol.values
                r.result.plant_values = cand.plant_values(pol.values)
                r.result.std = {**r.result.std, **pol.std}
                r.result.ci95 = {**r.result.ci95, **pol.ci95}
                polished[r.name] = {"windows_s": pol.windows, "status": pol.status,
                                    "wall_s": round(pol.wall_s, 2)}
            base_pv = base_pv.replace(**r.result.plant_values)
        if chosen:
            t0 = tick("grey-box polish", t0)

    findings: list[Finding] = []
    aug = params
    sim_after = sim0
    fit_after = dict(fit_before)
    for i, r in enumerate(chosen):
        aug = aug.replace(**r.result.plant_values)
        sim_after = replay(Plant(aug), prep)
        fa = _fits(prep, sim_after)
        gain_i = (err0 if i == 0 else chosen[i - 1].result.err) - r.result.err
        g_s = smooth_error(gain_i, prep.dt)
        where = intervals(g_s, prep.t, 0.2 * float(np.nanmax(g_s)) if np.nanmax(g_s) > 0 else 1.0)
        runner = next((o for o in ranking if o is not r and o.name != r.name), None) if i == 0 \
            else None
        conc_i = concentration(gain_i, masks)
        cand = by_name[r.name]
        findings.append(Finding(
            effect=r.result.effect, confidence=_confidence(r, runner),
            parameters=cand.reported(r.result.values), where=where,
            evidence=_evidence(r, cand, conc_i, prep), fit_after=fa, name=r.name,
            plant_values=dict(r.result.plant_values), std=dict(r.result.std),
            ci95=dict(r.result.ci95)))
        fit_after = fa
    witness_after: dict[str, np.ndarray] = {}
    if findings and prep.has_pressures:
        fr = None
        p_obs = aug
        if aug.has_effect("dry_friction"):
            fr = {k: aug[f"friction.{k}"] for k in ("coulomb", "static", "stribeck_velocity")}
            p_obs = aug.without_effect("dry_friction")
        witness_after = wit.in_units(wit.residuals(_observer_rates(prep, p_obs, jit), fr))
    if findings:
        t0 = tick("augmented replay", t0)
    if not findings:
        best = ranking[0] if ranking else None
        if best is not None:
            notes.append(f"no candidate is significant; the best, {best.name}, would remove "
                         f"{100 * best.gain:.0f} % of the short-horizon prediction error "
                         f"({best.reason})")
    timings["total"] = round(time.perf_counter() - t_start, 3)
    return Diagnosis(
        plant_file=plant_file, recording_file=rec_file, fit_before=fit_before,
        fit_after=fit_after, findings=findings, ranking=ranking, located=located,
        regime_share=conc0, notes=notes, mode=mode_txt, nominal=params, augmented=aug,
        prep=prep, replay_nominal=sim0, replay_augmented=sim_after if findings else {},
        witness=witness0, witness_after=witness_after, err_nominal=err0,
        err_after=err_cur if findings else None, cost_nominal=cost0,
        cost_after=cost_cur if findings else cost0, timings=timings, polished=polished)
