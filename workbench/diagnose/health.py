"""Is a replay usable, and what does it leave unexplained?

Two questions the diagnosis must answer before it may say anything:

* :func:`check_replay` -- did the replay of the recording on a plant work at all?
  A replay with non-finite values, a piston far beyond its end stops (which the plant's
  stiff stops make impossible for a working replay) or a fit worse than the recording's
  own mean (fit < 0 %, formats.md section 4) is not a model that "explains the
  recording"; :func:`core.diagnose` turns such a replay into a finding's motivation or,
  when no candidate explains it, into :class:`DiagnosisError` with the cause -- never
  into "no finding".
* :func:`unexplained` -- the **noise floor** of each signal: the fit a perfect model
  would reach on this recording, ``100 (1 - sigma / std(y))`` with ``sigma`` the
  sensor noise estimated from the recording itself (:func:`workbench.signals.noise_floor`),
  compared with the fit reached, and the operating regime where the remaining error
  concentrates (:mod:`.locate`), in a sentence.

Examples
--------
>>> import numpy as np
>>> floor_fit(np.sin(np.linspace(0, 6, 600)), 0.01)      # % a perfect model reaches
98.6
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from ..errors import WorkbenchError
from ..signals import fit
from .candidates import LINE_SEGMENTS
from .data import Prepared

__all__ = ["DiagnosisError", "ReplayCheck", "check_replay", "floor_fit", "unexplained", "verdict",
           "hunting", "gauge_hint", "STROKE_MARGIN", "UNEXPLAINED_RATIO", "HUNT_STICK",
           "GAUGE_BAND"]

#: Share of the stroke beyond an end stop that no working replay reaches (the stops'
#: contact at 300 Hz lets a 1 m/s piston in by well under 1 mm).
STROKE_MARGIN = 0.05
#: A signal is "still unexplained" when its replay error is more than this many times
#: the error a perfect model would leave (the noise): a model error of the size of the
#: noise doubles the error energy only at a ratio of sqrt(2); 3 is well clear of it.
UNEXPLAINED_RATIO = 3.0
#: s: window of :func:`rest_noise` (the position loop's and chambers' slowest time
#: constants at rest are longer; a sensor's coloured noise of up to ~30 ms correlation
#: time shows its full spread in it).
REST_WINDOW = 0.2
#: Fewest windows at rest for :func:`rest_noise` to be used.
REST_WINDOWS_MIN = 5
#: The spread at rest replaces the sample-to-sample noise in the noise floor when it is
#: this many times larger (their statistical errors, a few % each, are far below it).
COLOURED_FACTOR = 1.5


#: The nominal replay's pressures above the recorded ones by atmospheric pressure within
#: this relative band, on every recorded chamber, suggest gauge readings (a wrong nominal
#: value shifts the two chambers by different amounts, and rarely by exactly 1 atm).
GAUGE_BAND = 0.25


#: s: shortest stick phase before a slip of a hunt (a few velocity-smoothing windows,
#: so that the zero crossing of an underdamped settling, which passes through rest in a
#: few samples, is not a stick phase).
HUNT_STICK = 0.1


class DiagnosisError(WorkbenchError):
    """The diagnosis cannot give an answer it can stand behind (the replay failed, or
    fits the recording worse than a constant and no candidate explains why)."""


@dataclass
class ReplayCheck:
    """What is wrong with one replay (empty lists: nothing).

    Attributes
    ----------
    failures : the replay itself broke (non-finite values, piston beyond the stops).
    worse : signals fitted worse than the recording's mean, ``"x -128 %"``.
    fits : fit per signal, % (NaN where undefined).
    """

    failures: list[str] = field(default_factory=list)
    worse: list[str] = field(default_factory=list)
    fits: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """Neither a failure nor a signal worse than a constant."""
        return not self.failures and not self.worse

    def cause(self) -> str:
        """Everything wrong, in one sentence (empty when :attr:`ok`)."""
        parts = list(self.failures)
        if self.worse:
            parts.append("it fits " + ", ".join(self.worse)
                         + " (worse than the recording's own mean, a constant)")
        return "; ".join(parts)


def _spans(t: np.ndarray, mask: np.ndarray) -> str:
    """``mask``'s first and last time, e.g. ``"6.44-8.00 s"``."""
    idx = np.flatnonzero(mask)
    return f"{t[idx[0]]:.2f}-{t[idx[-1]]:.2f} s"


def check_replay(t: np.ndarray, measured: Mapping[str, np.ndarray],
                 sim: Mapping[str, np.ndarray], stroke: float,
                 signals: Sequence[str]) -> ReplayCheck:
    """Check the replay ``sim`` of the recording (arrays on its samples).

    Parameters
    ----------
    t : s. measured : recorded signals by name. sim : replayed signals by name.
    stroke : m. signals : the signals compared (x, and p_a, p_b when recorded).

    Returns
    -------
    ReplayCheck
    """
    chk = ReplayCheck()
    for s in signals:
        y = np.asarray(sim[s], dtype=float)
        bad = ~np.isfinite(y)
        if bad.any():
            chk.failures.append(f"the replayed {s} is not finite at {int(bad.sum())} samples "
                                f"({_spans(t, bad)})")
            chk.fits[s] = float("nan")
            continue
        meas = np.asarray(measured[s], dtype=float)
        rec = np.isfinite(meas)          # NaN: not recorded there (several recordings)
        chk.fits[s] = fit(meas[rec], y[rec]) if rec.sum() > 2 else float("nan")
        if np.isfinite(chk.fits[s]) and chk.fits[s] < 0.0:
            chk.worse.append(f"{s} at {chk.fits[s]:.3g} %")
    x = np.asarray(sim["x"], dtype=float)
    out = np.isfinite(x) & ((x < -STROKE_MARGIN * stroke) | (x > (1 + STROKE_MARGIN) * stroke))
    if out.any():
        worst = float(np.max(np.abs(np.clip(x[out], -np.inf, 0.0))
                             + np.clip(x[out] - stroke, 0.0, np.inf)))
        chk.failures.append(f"the replayed piston leaves the stroke [0, {stroke:g}] m by up "
                            f"to {worst:.3g} m ({_spans(t, out)})")
    return chk


def rest_noise(y: np.ndarray, rest: np.ndarray, window: int) -> float:
    """Noise spread of ``y`` at rest, slow (coloured) parts included: the median, over
    windows of ``window`` samples inside the stretches at rest, of the standard
    deviation about a quadratic fitted in each (what a leak or the gas settling after
    a stop does within :data:`REST_WINDOW` is a quadratic to well within the noise).
    The sample-to-sample estimate (:func:`workbench.signals.noise_floor`) sees only the
    white part: an AR(1) noise of pole 0.95 is 3.2 x larger than it says; this one
    sees what varies within the window (72 % of that noise's spread at 0.2 s and
    1 kHz: its slowest part goes into the quadratic), so it is a lower bound of the
    coloured noise too. 0.0 when fewer than :data:`REST_WINDOWS_MIN` windows fit."""
    y = np.asarray(y, dtype=float)
    rest = np.asarray(rest, dtype=bool)
    if window < 8:
        return 0.0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], rest.astype(int), [0]])))
    tt = np.linspace(-1.0, 1.0, window)
    V = np.vander(tt, 3)
    P = V @ np.linalg.pinv(V)
    spreads = []
    for a, b in zip(edges[::2], edges[1::2]):
        for i in range(a, b - window + 1, window):
            seg = y[i:i + window]
            r = seg - P @ seg
            spreads.append(float(np.sqrt(np.sum(r * r) / (window - 3))))
    if len(spreads) < REST_WINDOWS_MIN:
        return 0.0
    return float(np.median(spreads))


def floor_fit(y: np.ndarray, sigma: float) -> float:
    """The fit (%) a model without any error reaches on ``y`` measured with noise
    ``sigma``: ``100 (1 - sigma / std(y))``, rounded to 0.1 %."""
    sd = float(np.std(np.asarray(y, dtype=float)))
    if sd <= 0.0:
        return float("nan")
    return round(100.0 * (1.0 - sigma / sd), 1)


def unexplained(measured: Mapping[str, np.ndarray], sim: Mapping[str, np.ndarray],
                noise: Mapping[str, float], masks: Mapping[str, np.ndarray],
                signals: Sequence[str], label: str = "the augmented model",
                hunt: np.ndarray | None = None, hunt_text: str = ""
                ) -> tuple[dict[str, dict[str, float]], list[str]]:
    """Per signal: fit reached, noise-floor fit, error / noise ratio overall and per
    operating regime; and the plain statements for the signals still unexplained
    (error above :data:`UNEXPLAINED_RATIO` times the noise).

    ``hunt`` (mask of the stick-slip hunting stretches, :func:`hunting`; ``hunt_text``
    their times): each row also gets the ratio there (``"stick-slip hunting"``), the
    share of the error energy there (``hunting_share``) and the fit outside them
    (``fit_outside_hunting``), and the statement says both.

    Returns
    -------
    table : signal -> {"fit", "floor", "ratio", and one ratio per regime}.
    statements : sentences, e.g. ``"p_a fit 74.0 %, the noise floor allows 95.1 %:
        the remaining mismatch is largest at velocity reversal (9.1 x the noise)"``.
    """
    table: dict[str, dict[str, float]] = {}
    said: list[str] = []
    for s in signals:
        y = np.asarray(measured[s], dtype=float)
        e = y - np.asarray(sim[s], dtype=float)
        ok = np.isfinite(e)
        sig = max(float(noise.get(s, 0.0)), 1e-300)
        if ok.sum() < 3:
            continue
        row = {"fit": fit(y[ok], y[ok] - e[ok]), "floor": floor_fit(y[ok], sig),
               "ratio": float(np.sqrt(np.mean(e[ok] ** 2)) / sig)}
        worst, worst_r = "", 0.0
        for name, m in masks.items():
            mm = m & ok
            if mm.sum() < 10:
                continue
            r = float(np.sqrt(np.mean(e[mm] ** 2)) / sig)
            row[name] = r
            if r > worst_r:
                worst, worst_r = name, r
        hunted = _hunting_row(y, e, ok, sig, hunt, row)
        table[s] = row
        if row["ratio"] > UNEXPLAINED_RATIO:
            if hunted and row["hunting_share"] > 0.5:
                where = (f": {100 * row['hunting_share']:.0f} % of the remaining mismatch is in "
                         f"stick-slip hunting ({hunt_text}; {row['stick-slip hunting']:.1f} x the "
                         "noise there): the loop hunts against stiction around a held "
                         "reference, and a free-running replay cannot reproduce the phase of "
                         "that limit cycle")
            else:
                where = (f": the remaining mismatch is largest {_at(worst)} ({worst_r:.1f} x "
                         f"the noise)") if worst else ""
            if hunted:
                where += (f"; outside the hunting stretches {label} fits "
                          f"{row['fit_outside_hunting']:.1f} %")
            said.append(f"{s}: {label} fits {row['fit']:.1f} %, the noise floor allows "
                        f"{row['floor']:.1f} % (error {row['ratio']:.1f} x the noise){where}")
    return table, said


def _hunting_row(y: np.ndarray, e: np.ndarray, ok: np.ndarray, sig: float,
                 hunt: np.ndarray | None, row: dict[str, float]) -> bool:
    """Add the hunting stretches' entries to ``row`` (see :func:`unexplained`); False
    when there are none worth a number (fewer than 10 samples in or outside)."""
    if hunt is None:
        return False
    inside, outside = hunt & ok, ~hunt & ok
    if inside.sum() < 10 or outside.sum() < 10:
        return False
    row["stick-slip hunting"] = float(np.sqrt(np.mean(e[inside] ** 2)) / sig)
    row["hunting_share"] = float(np.sum(e[inside] ** 2) / max(np.sum(e[ok] ** 2), 1e-300))
    row["fit_outside_hunting"] = fit(y[outside], y[outside] - e[outside])
    return True


def _at(regime: str) -> str:
    """'at rest' stays, others get 'at' / 'when': words for the statement."""
    if regime.startswith("at ") or regime.startswith("near "):
        return regime
    if regime in ("moving", "accelerating"):
        return f"while {regime}"
    return f"at {regime}s" if regime == "velocity reversal" else f"in {regime}s"


def _slips(x: np.ndarray, moving: np.ndarray, least: float) -> list[tuple[int, int]]:
    """(start, end) of each slip: a run of moving samples that moves the piston by
    more than ``least``."""
    d = np.diff(np.concatenate(([0], moving.astype(int), [0])))
    return [(int(a), int(b)) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1))
            if abs(float(x[b - 1] - x[a])) > least]


def hunting(prep: Prepared, v_rest: float) -> list[tuple[int, int]]:
    """Stick-slip hunting stretches of a closed-loop recording (sample ranges).

    Where the reference is held, a loop that hunts against stiction stops off the
    reference, builds up force while the piston sticks, breaks away and stops again
    (beyond or short of the reference). A hold hunts when, after its first slip (the
    approach), the piston slips again from a stick phase (still, within the slip
    threshold, for at least :data:`HUNT_STICK` before the slip); a slip moves the piston by more than ten position-noise levels
    and 0.1 % of the stroke (quantisation and noise do not slip). The stretch runs from
    the stick phase before its first such slip to the end of the hold -- the moment a
    stuck piston breaks away is decided by a small force margin, so a free-running
    replay, whose break-aways fall elsewhere, loses the phase of the hunt from there
    -- and from the start of the hold when the hold before it ended hunting (the
    replay enters it off phase). Open loop (no reference): none.

    Parameters
    ----------
    prep : the prepared recording. v_rest : m/s, speed below which the piston is at rest.
    """
    if not prep.closed or "r" not in prep.rec:
        return []
    r = np.asarray(prep.rec["r"], dtype=float)
    x = prep.xs
    cuts = np.flatnonzero(np.abs(np.diff(r)) > 1e-9 * max(prep.plant.stroke, 1e-9)) + 1
    edges = np.unique(np.concatenate(([0], cuts, list(prep.starts or []), [len(r)]))).astype(int)
    least = max(10.0 * prep.noise["x"], 1e-3 * prep.plant.stroke)
    stick = max(int(round(HUNT_STICK / prep.dt)), 2)
    moving = np.abs(prep.v) >= v_rest
    out: list[tuple[int, int]] = []
    for a, b in zip(edges[:-1], edges[1:]):
        xh = x[a:b]
        slips = _slips(xh, moving[a:b], least)
        # from a stick phase: the piston still (within the slip threshold; its velocity
        # estimate may flicker above v_rest in the noise) for `stick` samples before it
        again = [i for i in range(1, len(slips))
                 if slips[i][0] - slips[i - 1][1] >= stick
                 and np.ptp(xh[slips[i][0] - stick:slips[i][0]]) < least]
        if not again:
            continue
        start = a if out and out[-1][1] == a and a not in (prep.starts or []) \
            else a + slips[again[0] - 1][1]
        if out and out[-1][1] == start:
            out[-1] = (out[-1][0], int(b))
        else:
            out.append((int(start), int(b)))
    return out


def gauge_hint(prep: Prepared, sim0: Mapping[str, np.ndarray]) -> str:
    """A sentence when the recorded pressures look like gauge readings, else "".

    Gauge pressures within the absolute range (a loop whose chambers never vent) pass
    the recording's checks; the nominal replay then runs about one atmosphere above
    every recorded chamber pressure (the median offset, robust to the transients a
    missing effect leaves). A leak to atmosphere or a lower supply can shift both
    chambers by as much: the level alone cannot tell them apart, so the sentence
    names both readings and the diagnosis goes on.
    """
    p_atm = float(prep.plant.params["gas.atmospheric_pressure"])
    offsets = {}
    for s in prep.pressures:
        y = np.asarray(sim0.get(s, ()), dtype=float)
        if y.shape != prep.measured(s).shape or not np.isfinite(y).all():
            return ""
        rec = prep.mask(s)
        offsets[s] = float(np.median(y[rec] - prep.measured(s)[rec]))
    if not offsets or any(abs(d / p_atm - 1.0) > GAUGE_BAND for d in offsets.values()):
        return ""
    said = ", ".join(f"{s} by {d / 1e5:.2f} bar" for s, d in offsets.items())
    units = ", ".join(f"{s}=Pa_g" for s in offsets)
    return (f"the recorded pressures lie below the nominal replay's by about atmospheric "
            f"pressure ({said}; {p_atm / 1e5:.3f} bar): if the logger writes gauge "
            f"pressures, declare them ('# units: {units}', or bar_g / kPa_g) and diagnose "
            "again; if they are absolute, something lowers both chambers (a leak to "
            "atmosphere, a lower supply)")


def _check(prep: Prepared, sim: Mapping[str, np.ndarray]) -> ReplayCheck:
    """:func:`check_replay` of a replay of the prepared recording."""
    return check_replay(prep.t, {s: prep.measured(s) for s in prep.signals}, sim,
                        prep.plant.stroke, prep.signals)


#: What the model form of a finding cannot reach, said when a signal stays unexplained
#: with that finding (the limit, not a missing effect).
MODEL_FORM = {
    "line_dynamics": (
        f"the line model is the workbench's lumped chain of {LINE_SEGMENTS} segments, "
        "each segment's volume at its valve end: it cannot reproduce a distributed "
        "line's wave shape, and its fitted length and diameter are the chain's, not the "
        "tube's (by a linear analysis of this layout, up to 15 % shorter than a "
        "distributed line)"),
    "dry_friction": (
        "the friction law is Karnopp stick-slip with a Stribeck curve: it has no "
        "pre-sliding displacement and no frictional lag (LuGre-type behaviour at "
        "velocity reversals and at break-away is beyond it)"),
}


def verdict(prep: Prepared, sim0: Mapping[str, np.ndarray], findings: Sequence[str],
            sim_after: Mapping[str, np.ndarray], masks: Mapping[str, np.ndarray],
            no_finding: Sequence[str] = (), hunt: Sequence[tuple[int, int]] = ()
            ) -> tuple[dict[str, dict[str, float]], list[str], list[str]]:
    """Never a silent all-clear.

    Parameters
    ----------
    prep : the prepared recording. sim0 : its replay on the nominal plant.
    findings : effect names found (in order). sim_after : the replay with them ({} if none).
    masks : operating regimes (:func:`.locate.regimes`).
    no_finding : why no candidate was significant (a note), when there is no finding.
    hunt : stick-slip hunting stretches (sample ranges, :func:`hunting`): the remaining
        error is also given outside them.

    Returns
    -------
    remaining : :func:`unexplained`'s table for the final model (nominal or augmented).
    statements : the signals still unexplained, in words.
    notes : the recording's notes and what this check adds.

    Raises
    ------
    DiagnosisError
        The nominal replay failed or fits a signal worse than a constant and there is no
        finding; or the augmented replay fails (non-finite, piston beyond the stops).
    """
    notes = list(prep.notes)
    check0 = _check(prep, sim0)
    gauge = gauge_hint(prep, sim0)
    if gauge:
        notes.append(gauge)
    if not findings:
        if not check0.ok:
            raise DiagnosisError(
                "the nominal plant does not reproduce the recording and no candidate "
                f"explains why: {check0.cause()}. " + (f"{gauge[0].upper()}{gauge[1:]}. "
                                                       if gauge else "")
                + "".join(f"{n}. " for n in no_finding)
                + "Check the plant file (units, supply, valve size, stroke, controller) "
                  "and the recording's columns against formats.md sections 1-3.")
        notes += list(no_finding)
        sim, label = sim0, "the nominal model"
    else:
        check1 = _check(prep, sim_after)
        if check1.failures:
            raise DiagnosisError(
                "the plant augmented by " + ", ".join(findings)
                + f" cannot be replayed on the recording: {check1.cause()}")
        if not check0.ok and check1.ok:
            notes.append(f"the nominal replay failed ({check0.cause()}); the findings "
                         "explain it")
        elif not check0.ok:
            notes.append(f"the nominal replay failed ({check0.cause()})")
        if check1.worse:
            notes.append(f"even with the findings the replay {check1.cause()}")
        sim, label = sim_after, "the augmented model"
    mask, text = None, ""
    if hunt:
        mask = np.zeros(prep.n, dtype=bool)
        for a, b in hunt:
            mask[a:b] = True
        text = ", ".join(f"{prep.t[a]:.1f}-{prep.t[b - 1]:.1f} s" for a, b in hunt)
    noise = dict(prep.noise)
    rest = masks.get("at rest")
    if rest is not None:
        for s in prep.signals:
            slow = rest_noise(prep.measured(s), rest & prep.mask(s),
                              int(round(REST_WINDOW / prep.dt)))
            unit = "m" if s == "x" else "Pa"
            if slow > COLOURED_FACTOR * noise.get(s, 0.0):
                notes.append(
                    f"the noise of {s} is coloured: at rest it spreads {slow:.3g} {unit} "
                    f"({slow / max(noise[s], 1e-300):.1f} x its sample-to-sample level "
                    f"{noise[s]:.3g} {unit}); the noise floor below uses the spread at rest")
                noise[s] = slow
    remaining, still = unexplained({s: prep.measured(s) for s in prep.signals}, sim,
                                   noise, masks, prep.signals, label, mask, text)
    if still:
        still += [f"model-form limit of {f}: {MODEL_FORM[f]}" for f in dict.fromkeys(findings)
                  if f in MODEL_FORM]
    return remaining, still, notes
