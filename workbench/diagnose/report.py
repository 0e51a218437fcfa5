"""The diagnosis report (HTML + PDF through :mod:`workbench.report`). Renders, never computes."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from .. import report as rp
from ..params import EFFECTS
from .explain import DBIC_MIN

__all__ = ["write_report", "build_report"]


def _ci_text(ci) -> str:
    if not ci:
        return "n/a"
    lo, hi = ci
    return f"{rp.fmt(lo)} .. {rp.fmt(hi)}"


def build_report(d) -> rp.Report:
    """The :class:`workbench.report.Report` of a :class:`~.core.Diagnosis`."""
    sections = [_summary_section(d), _findings_section(d), _remaining_section(d),
                _replay_section(d),
                _signatures_section(d), _candidates_section(d)]
    title = "Mismatch diagnosis"
    recs = " + ".join(Path(r).name for r in d.recording_file.split(" + "))
    return rp.Report(title, subtitle=f"{recs} on {Path(d.plant_file).name}",
                     status=_status(d), sections=sections,
                     provenance=rp.provenance(plant_file=d.plant_file if Path(d.plant_file).exists()
                                              else None,
                                              command_line=" ".join(sys.argv),
                                              extra=[("recording", d.recording_file)]))


def _status(d) -> rp.Status:
    """The report's verdict: what was found and how the fit changed, or no finding."""
    if not d.findings and d.unexplained:
        return rp.Status("FAIL", "no candidate is significant, but the nominal model does not "
                                 "explain the recording within its noise (see 'What remains')")
    if not d.findings:
        return rp.Status("NOTE", "no significant mismatch: the nominal model explains the "
                                 "recording within its noise (no finding)")
    names = ", ".join(f.effect + (" (" + ", ".join(f.parameters) + ")"
                                  if f.effect == "parameter_error" else "")
                      for f in d.findings)
    return rp.Status("PASS", f"found {names}; fit "
                     + ", ".join(f"{k} {d.fit_before[k]:.1f} -> {d.fit_after[k]:.1f} %"
                                 for k in d.fit_before))


def _summary_section(d) -> rp.Section:
    """The recording and replay in numbers, the fit before and after each finding, notes."""
    prep = d.prep
    kv = [("plant file", d.plant_file), ("recording", d.recording_file),
          ("samples", int(prep.n)), ("duration", float(prep.rec.duration), "s"),
          ("sample time", float(prep.dt) * 1e3, "ms"), ("replay", d.mode),
          ("signals compared", ", ".join(prep.signals)
           + (" (each where recorded: see the fit per recording)" if prep.recorded else "")),
          ("position noise", prep.noise["x"] * 1e6, "um")]
    for side in prep.pressures:
        kv.append((f"pressure noise {side}", prep.noise[side], "Pa"))
    kv.append(("diagnosis wall time", d.timings.get("total", float("nan")), "s"))
    blocks = [rp.KeyValues(kv)]
    fit_rows = [[s, d.fit_before[s]] + [f.fit_after.get(s) for f in d.findings]
                for s in d.fit_before]
    cols = ["signal", "nominal"] + [f"+ {f.effect}" for f in d.findings]
    blocks.append(rp.Table(cols, fit_rows, units=[""] + ["%"] * (len(cols) - 1),
                           caption="Fit (100 (1 - ||y - y_model|| / ||y - mean y||)) of the "
                                   "replay, per signal, before and after each finding"))
    if len(d.recordings) > 1:
        sig = list(d.fit_before)

        def per(fits):
            return [fits.get(s, "not recorded") for s in sig]
        blocks.append(rp.Table(
            ["recording", "from", "duration"] + [f"{s} before" for s in sig]
            + [f"{s} after" for s in sig],
            [[Path(r["recording"]).name, r["start_s"], r["duration_s"]]
             + per(r["fit_before"]) + per(r["fit_after"]) for r in d.recordings],
            units=["", "s", "s"] + ["%"] * (2 * len(sig)),
            caption="Several recordings diagnosed together (one model for all): the fit of "
                    "each, before and after the findings ('from': where it starts on the "
                    "joined time axis of the figures)"))
    for n in d.notes:
        blocks.append(rp.Status("NOTE", n))
    return rp.Section("Summary", blocks)


def _findings_section(d) -> rp.Section:
    """The findings table, then per finding its evidence and fitted values."""
    if not d.findings:
        return rp.Section("Findings", [rp.Paragraph(
            "No candidate removes a significant share of the mismatch: findings are empty and "
            "plant.augmented.toml equals the nominal plant.")])
    rows = []
    for i, f in enumerate(d.findings, 1):
        rows.append([i, f.effect, round(float(f.confidence), 2),
                     ", ".join(f"{k} = {rp.fmt(v)}" for k, v in f.parameters.items()),
                     "; ".join(f"{a:.2f}-{b:.2f} s" for a, b in f.where[:6])
                     + (" ..." if len(f.where) > 6 else "")])
    fb = [rp.Table(["#", "effect", "confidence", "parameters (SI)", "where"], rows,
                   caption="Findings, most important first")]
    fb += _set_blocks(d)
    for i, f in enumerate(d.findings, 1):
        fb += _finding_blocks(i, f, d.polished.get(f.name))
    return rp.Section("Findings", fb)


def _set_blocks(d) -> list:
    """The chosen set: each member's own share, what the set leaves, the trade-offs."""
    info = d.sets or {}
    best = next((s for s in info.get("sets", []) if s["set"] == sorted(info.get("chosen", []))),
                None)
    if not best:
        return []
    out = [rp.Paragraph(
        f"Chosen among {info.get('candidate_models', 0)} candidate models (single effects, "
        "pairs and triples refitted jointly) as the set with the lowest BIC in which every "
        "member earns its place. Own share: the part of the nominal short-horizon mismatch "
        "only that member removes (the set without it, refitted, leaves that much more); "
        f"the set leaves {rp.fmt(100 * best['cost'] / max(d.cost_nominal, 1e-300))} % of it.")]
    rest = best.get("own_share_of_rest", {})
    rows = [[m, round(100 * float(v), 2), round(100 * float(rest.get(m, float("nan"))), 1)]
            for m, v in best["own_share"].items()]
    out.append(rp.Table(["member", "own share of the nominal mismatch",
                         "of what the others leave"], rows, units=["", "%", "%"],
                        caption="Each finding's own share: what only it removes"))
    for alt in info.get("alternatives", []):
        out.append(rp.Status("NOTE", "an alternative explains the recording about as well "
                                     f"(BIC within {DBIC_MIN:g}): {' + '.join(alt)}; the data cannot "
                                     "tell it from the chosen set"))
    for sg in info.get("suggested", []):
        out.append(rp.Status("NOTE", "also significant, not named: " + sg["text"]))
    for t in info.get("trade_offs", []):
        out.append(rp.Status("NOTE", f"{t['values'][0]} and {t['values'][1]} trade off "
                                     f"(correlation {t['correlation']:+.2f}): {t['tells_apart']}"))
    return out


def _remaining_section(d) -> rp.Section:
    """The final model's replay error against the noise floor, per signal and regime."""
    if not d.remaining:
        return rp.Section("What remains", [rp.Paragraph("No replay to compare.")])
    regimes = [k for k in next(iter(d.remaining.values()))
               if k not in ("fit", "floor", "ratio", "hunting_share", "fit_outside_hunting")]
    def one(v):                         # one decimal in every column ("3.0", not "3")
        return "n/a" if v is None or not np.isfinite(v) else f"{v:.1f}"
    rows = [[s, one(r["fit"]), one(r["floor"]), one(r["ratio"])]
            + [one(r.get(g)) for g in regimes] for s, r in d.remaining.items()]
    blocks = [rp.Table(["signal", "fit", "noise floor", "error / noise"] + regimes, rows,
                       units=["", "%", "%", "-"] + ["-"] * len(regimes),
                       caption="The replay of the final model against the noise floor (the fit "
                               "a perfect model reaches, from the recording's own noise), and "
                               "its error in noise units per operating regime")]
    hunted = [(s, r) for s, r in d.remaining.items() if "fit_outside_hunting" in r]
    if hunted:
        spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in d.hunting)
        blocks.append(rp.Table(
            ["signal", "fit", "fit outside hunting", "mismatch in hunting"],
            [[s, one(r["fit"]), one(r["fit_outside_hunting"]), one(100 * r["hunting_share"])]
             for s, r in hunted], units=["", "%", "%", "%"],
            caption=f"Stick-slip hunting ({spans}): the loop hunts against stiction around a "
                    "held reference; a free-running replay cannot reproduce the phase of "
                    "that limit cycle, so the fit is also given without those stretches"))
    for n in d.unexplained:
        blocks.append(rp.Status("NOTE", "still unexplained: " + n))
    if not d.unexplained:
        blocks.append(rp.Paragraph("Every signal is replayed within a few times its noise."))
    return rp.Section("What remains", blocks)


def _finding_blocks(i: int, f, pol: dict | None) -> list:
    """Heading, evidence, how the values were polished, and the fitted-values table."""
    fb = [rp.Heading(f"{i}. {f.effect}"), rp.Paragraph(f.evidence)]
    if pol:
        spans = "; ".join(f"{a:.2f}-{b:.2f} s" for a, b in pol["windows_s"])
        fb.append(rp.Paragraph(
            f"Values refined by the grey-box estimator (multiple shooting, IPOPT) on "
            f"the windows {spans}, where this finding removes most of the mismatch "
            f"({pol['status']}, {pol['wall_s']:.1f} s); intervals from its covariance."))
    prow = []
    for k, v in f.plant_values.items():
        if k == "lines.segments":
            continue
        unit = next((kk.unit for e in EFFECTS.values() for kk in e if kk.path == k), "")
        std = f.std.get(k)
        prow.append([k, float(v), unit, None if std is None else float(std),
                     _ci_text(f.ci95.get(k))])
    fb.append(rp.Table(["plant key", "fitted", "unit", "std", "95 % interval"], prow,
                       caption=f"Fitted values of finding {i} (plant.augmented.toml)"))
    return fb


def _replay_section(d) -> rp.Section:
    """Recording, nominal and augmented replays, with the located intervals."""
    from . import figures
    prep = d.prep
    meas = {s: prep.measured(s) for s in prep.signals}
    meas["u"] = np.asarray(prep.rec["u"])
    spans = d.findings[0].where if d.findings else []
    ref = np.asarray(prep.rec["r"]) if "r" in prep.rec else None
    fig = figures.replay_figure(prep.t, meas, d.replay_nominal, d.replay_augmented, d.located,
                                spans, reference=ref,
                                title="recording vs nominal vs augmented model")
    return rp.Section("Recording and models", [
        rp.Paragraph(f"Replay: {d.mode}. Grey: intervals where the nominal model's short-horizon "
                     "predictions miss the recording; orange: where the first finding removes "
                     "the mismatch."),
        rp.Figure(fig, caption="Recording, nominal model and augmented model")])


def _signatures_section(d) -> rp.Section:
    """Witnesses and prediction error, nominal vs augmented; the mismatch per regime."""
    from . import figures
    sb = [rp.Paragraph(
        "Flow witnesses: mass flow each chamber received (chamber equation with the measured "
        "pressure, position and velocity) minus what the valve law gives at the recorded "
        "command and pressures. Force witness: what the piston's equation of motion leaves "
        "unexplained (m a - forces). Prediction error: squared residual of the short-horizon "
        "predictions in units of the measurement noise.")]
    if d.err_nominal is not None:
        fig = figures.signature_figure(d.prep.t, d.witness, d.witness_after, d.err_nominal,
                                       d.err_after, d.located, title="residual signatures")
        sb.append(rp.Figure(fig, caption="Residual signatures, nominal vs augmented"))
    fig = figures.regime_figure(d.regime_share, title="where the nominal mismatch lives")
    sb.append(rp.Figure(fig, caption="Share of the nominal mismatch per operating regime",
                        width=0.8))
    sb.append(rp.Table(["regime", "share of mismatch", "share of time", "ratio"],
                       [[k, 100 * v["error_share"], 100 * v["time_share"], v["ratio"]]
                        for k, v in d.regime_share.items()], units=["", "%", "%", "-"],
                       caption="Operating regimes of the mismatch"))
    if d.located:
        sb.append(rp.Paragraph("Located intervals: " + "; ".join(
            f"{a:.2f}-{b:.2f} s" for a, b in d.located)))
    return rp.Section("Residual signatures and location", sb)


def _clean(v):
    """``v`` rounded to 6 decimals (a BIC weight of exp(-700) is 0, and denormal floats
    cannot be formatted)."""
    return None if v is None else round(float(v), 6)


def _candidates_section(d) -> rp.Section:
    """Every candidate's evidence (table and bar chart), best first."""
    from . import figures
    rows = []
    for r in d.ranking:
        vals = ", ".join(f"{k.split('.', 1)[-1]} = {rp.fmt(v, digits=3)}"
                         for k, v in r.result.values.items())
        rows.append([r.name.replace("parameter_error:", "parameter_error: "),
                     "yes" if r.significant else "no", _clean(100 * r.gain),
                     r.dbic if np.isfinite(r.dbic) else None,
                     None if r.seg_gain is None else _clean(100 * r.seg_gain),
                     _clean(r.consistency), _clean(r.weight), vals,
                     r.reason or r.result.error or ""])
    cb = [rp.Paragraph(
        "Every candidate is added to the nominal plant and refitted on short-horizon "
        "predictions. gain: share of the prediction error it removes; dBIC: information "
        "criterion gain (penalises each fitted value); closed-loop: change of the re-anchored "
        "closed-loop replay error; consistency: share of its gain in the regimes where the "
        "effect acts, relative to time spent there; weight: BIC weight among all candidates "
        "and 'nothing to add'."),
        rp.Table(["candidate", "significant", "gain", "dBIC", "closed-loop", "consistency",
                  "weight", "fitted", "note"], rows,
                 units=["", "", "%", "-", "%", "-", "-", "", ""],
                 caption="Candidates ranked by evidence", digits=3)]
    fig = figures.ranking_figure([r.name for r in d.ranking], [r.gain for r in d.ranking],
                                 [r.significant for r in d.ranking],
                                 title="candidate ranking")
    cb.append(rp.Figure(fig, caption="Share of the mismatch removed by each candidate", width=0.8))
    return rp.Section("Candidates", cb)


def write_report(d, out_dir) -> tuple[Path, Path]:
    """Write ``report.html`` and ``report.pdf`` into ``out_dir``."""
    return rp.write(build_report(d), out_dir)
