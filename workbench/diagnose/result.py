"""What a diagnosis returns: :class:`Finding` and :class:`Diagnosis` (formats.md section 4),
their serialisation (``to_dict``, ``details``), terminal summary and result set on disk."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..params import PlantParams, atomic_write_text
from .data import Prepared
from .explain import Ranked

__all__ = ["Finding", "Diagnosis", "OUTPUT_FILES"]


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
    hunting: list[list[float]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """The diagnosis result of formats.md section 4 (exactly those keys), and for
        several recordings diagnosed together ``recordings``: per recording its file,
        and its fit before and after per signal it recorded (%, rounded as the others).
        ``fit_before`` / ``fit_after`` are then over the joined recordings, each signal
        where it was recorded."""
        out = {"plant": self.plant_file, "recording": self.recording_file,
               "fit_before": {k: _round(v) for k, v in self.fit_before.items()},
               "fit_after": {k: _round(v) for k, v in self.fit_after.items()},
               "findings": [f.to_dict() for f in self.findings]}
        if len(self.recordings) > 1:
            out["recordings"] = [
                {"recording": r["recording"],
                 "fit_before": {k: _round(v) for k, v in r["fit_before"].items()},
                 "fit_after": {k: _round(v) for k, v in r["fit_after"].items()}}
                for r in self.recordings]
        return out

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
            "sets": self.sets, "recordings": self.recordings, "hunting_s": self.hunting,
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
        names = {"json": OUTPUT_FILES[0], "plant": OUTPUT_FILES[1],
                 "details": OUTPUT_FILES[2]}
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


#: The files :meth:`Diagnosis.write` puts in its folder (the report's last two).
OUTPUT_FILES = ("diagnosis.json", "plant.augmented.toml", "details.json", "report.html",
                "report.pdf")


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
