"""What a diagnosis works from: the recording checked, smoothed, differentiated, its noise.

:func:`prepare` turns a plant and a recording into :class:`Prepared`: the replay mode
(closed loop when the recording has ``r`` and the plant file a controller that
reproduces the recorded ``u``; otherwise open loop, re-anchored), the controller's
sample instants, Savitzky-Golay smoothed signals and their derivatives (velocity and
acceleration from the position, pressure rates), and the sensor noise of each
signal. Problems with the input become :class:`~workbench.errors.InputError` when
nothing can be done (too short, no motion), and *notes* when a reduced diagnosis is
still possible (no pressures, no controller, a controller that does not match).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from ..plant import Plant
from ..recording import Recording
from ..replay import CONTROLLER_AGREEMENT  # % below which the replay is open loop
from ..replay import controller_agreement as _controller_agreement
from ..replay import controller_phase as _controller_phase
from ..signals import derivative, fit, noise_floor, odd_window, savgol, smooth
from .recorded import mixed_note, start_pressures, unrecorded_pressure, with_all_signals

__all__ = ["Prepared", "prepare", "prepare_many", "other_side", "uniform", "logger_period",
           "recorded_supply", "MIN_DURATION",
           "SHORT_DURATION", "savgol"]

#: s: shorter recordings are refused (a few closed-loop time constants at least).
MIN_DURATION = 2.0
#: s: shorter recordings are diagnosed with a warning (few events to learn from).
SHORT_DURATION = 8.0
#: s: Savitzky-Golay window for velocity and acceleration from the position.
WINDOW_X = 0.031
#: s: Savitzky-Golay window for the pressure rates.
WINDOW_P = 0.011
#: s: long Savitzky-Golay window for the slow pressure rates (leaks, heat exchange).
WINDOW_SLOW = 0.101


# The smoothing, derivatives and noise floor are those of workbench.signals, shared with
# the grey-box fit (savgol is re-exported here for the diagnosis modules).
_noise_std = noise_floor


@dataclass
class Prepared:
    """A recording made ready for the diagnosis (arrays on the recording's samples).

    Attributes
    ----------
    plant : the nominal Plant. rec : the Recording. t : s from the first sample.
    dt : sample time, s. closed : closed-loop replay. controller : PID or None.
    ratio : samples per controller period. phase : index of the first controller instant.
    x, p_a, p_b : measured (p_* None without pressures).
    xs, v, a : smoothed position (m), velocity (m/s), acceleration (m/s^2).
    pas, pbs, dpa, dpb : smoothed pressures (Pa) and their rates (Pa/s).
    noise : sensor noise per signal (same unit), :func:`workbench.signals.noise_floor`.
    signals : the measured outputs fitted (x, and p_a, p_b when recorded).
    notes : what was reduced or assumed, in words for the report.
    supply : recorded supply pressure (Pa, smoothed), used sample by sample, when it
        varies (:func:`supply_profile`); else None (the plant's constant).
    parts, starts : several recordings joined (:func:`prepare_many`): each prepared
        alone, and the sample where each starts.
    recorded : per signal, a boolean mask of the samples where it was recorded, when
        recordings with different signals are joined (a signal of ``signals`` that one
        of them lacks: NaN in :meth:`measured` there); empty when every signal is
        recorded throughout (:meth:`mask`).
    """

    plant: Plant
    rec: Recording
    t: np.ndarray
    dt: float
    closed: bool
    controller: Any
    ratio: int
    phase: int
    x: np.ndarray
    p_a: np.ndarray | None
    p_b: np.ndarray | None
    xs: np.ndarray
    v: np.ndarray
    a: np.ndarray
    pas: np.ndarray | None
    pbs: np.ndarray | None
    dpa: np.ndarray | None
    dpb: np.ndarray | None
    noise: dict[str, float]
    signals: tuple[str, ...]
    win_x: int
    win_p: int
    win_slow: int
    notes: list[str] = field(default_factory=list)
    supply: np.ndarray | None = None
    parts: list["Prepared"] = field(default_factory=list, repr=False)
    starts: list[int] = field(default_factory=list)
    recorded: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    start: dict[str, float] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def has_pressures(self) -> bool:
        """Both chamber pressures recorded (flow witnesses, pressure regimes, polish)."""
        return self.p_a is not None and self.p_b is not None

    @property
    def pressures(self) -> tuple[str, ...]:
        """The chamber pressures recorded: ("p_a", "p_b"), one of them, or ()."""
        return tuple(s for s in ("p_a", "p_b") if getattr(self, s) is not None)

    def smoothed(self, side: str) -> np.ndarray:
        """The smoothed pressure ``side`` ("p_a" or "p_b"), Pa; with only one recorded,
        the other is its estimate by the piston's force balance (:func:`other_side`)."""
        return {"p_a": self.pas, "p_b": self.pbs}[side]

    def first_pressures(self) -> dict[str, float]:
        """Both smoothed pressures at the first sample (Pa) when any is recorded (the
        other one estimated, :func:`other_side`), by name; without pressures, the
        valve's null pressures of the plant without its leaks
        (:func:`.recorded.start_pressures`), if it has leaks, else {}."""
        return {s: float(self.smoothed(s)[0]) for s in ("p_a", "p_b")} if self.pressures \
            else dict(self.start)

    def measured(self, name: str) -> np.ndarray:
        """The recorded signal ``name`` (x m, p_a/p_b Pa); NaN where it was not recorded
        (several recordings with different signals, :meth:`mask`)."""
        return {"x": self.x, "p_a": self.p_a, "p_b": self.p_b}[name]

    def filled(self, name: str) -> np.ndarray:
        """:meth:`measured` with the smoothed estimate where it was not recorded (for
        filters that need every sample; compare only where :meth:`mask` is True)."""
        y = self.measured(name)
        return y if name not in self.recorded else np.where(
            self.recorded[name], y, self.xs if name == "x" else self.smoothed(name))

    def mask(self, name: str) -> np.ndarray:
        """Boolean mask of the samples where signal ``name`` was recorded (all of them
        but where a recording joined with others lacks it, :func:`prepare_many`)."""
        m = self.recorded.get(name)
        return np.ones(self.n, dtype=bool) if m is None else m

    def pressure_anchor(self) -> np.ndarray:
        """Samples where at least one chamber pressure was recorded: there the
        predictions may re-anchor both (the other one estimated, :func:`other_side`);
        elsewhere the model's pressures run on, as for a position-only recording."""
        m = np.zeros(self.n, dtype=bool)
        for s in self.pressures:
            m |= self.mask(s)
        return m

    def signals_at(self, i: int) -> tuple[str, ...]:
        """The signals recorded at sample ``i``."""
        return tuple(s for s in self.signals if self.mask(s)[i])

    def smooth_x(self, y: np.ndarray) -> np.ndarray:
        """The smoothing applied to the acceleration (for model rates of v)."""
        return savgol(y, self.win_x, 3, dt=self.dt)

    def smooth_p(self, y: np.ndarray) -> np.ndarray:
        """The smoothing applied to the pressure rates (for model rates of p)."""
        return savgol(y, self.win_p, 2, dt=self.dt)

    def smooth_slow(self, y: np.ndarray, deriv: int = 0) -> np.ndarray:
        """The long-window smoothing (slow pressure rates)."""
        return savgol(y, self.win_slow, 2, deriv=deriv, dt=self.dt)

    def control_instants(self) -> np.ndarray:
        """Boolean mask of the samples at which the controller updated."""
        m = np.zeros(self.n, dtype=bool)
        m[self.phase::self.ratio] = True
        return m

    def e_prev(self) -> np.ndarray:
        """At each sample, r - x at the previous controller instant (controller memory)."""
        if "r" not in self.rec:
            return np.zeros(self.n)
        e = np.asarray(self.rec["r"]) - self.x
        idx = np.arange(self.n)
        first = np.asarray(self.starts or [0])[np.searchsorted(self.starts or [0], idx,
                                                                side="right") - 1]
        prev = np.where(idx - self.ratio >= first, idx - self.ratio, idx)
        return e[prev]        # within one recording (several: :func:`prepare_many`)


def _plant_controller(plant: Plant, rec: Recording, dt: float,
                      notes: list[str]) -> tuple[Any, int, int]:
    """The plant file's controller (None without one, or when its period is not a
    multiple of the sample time ``dt``, s), samples per period, phase of its updates."""
    if not plant.params.has_controller:
        return None, 1, 0
    from ..controllers import from_plant
    controller = from_plant(plant)
    ratio = int(round(controller.sample_time / dt))
    if ratio < 1 or abs(ratio * dt - controller.sample_time) > 0.02 * dt:
        notes.append(f"the controller period ({controller.sample_time:g} s) is not a "
                     f"multiple of the sample time ({dt:g} s): open-loop replay")
        return None, 1, 0
    phase, _share = _controller_phase(np.asarray(rec["u"]), ratio)
    return controller, ratio, phase


def _smoothed(rec: Recording, x: np.ndarray, dt: float, win_x: int, win_p: int,
              sides: tuple[str, ...], starts: list[int] | None = None) -> dict[str, Any]:
    """Smoothed signals, their derivatives and the noise floors (Prepared's fields).

    Position: cubic Savitzky-Golay over ``win_x`` samples (value, velocity m/s,
    acceleration m/s^2); pressures ``sides``: quadratic over ``win_p`` (value, rate
    Pa/s). Several recordings joined (``starts``: first sample of each): each is
    smoothed on its own (no filter window across a junction), the noise is the median
    of theirs.
    """
    cuts = list(starts or [0]) + [len(x)]

    def piecewise(fun, y):
        return np.concatenate([fun(y[a:b]) for a, b in zip(cuts[:-1], cuts[1:])])

    def noise(y):
        return float(np.median([noise_floor(y[a:b]) for a, b in zip(cuts[:-1], cuts[1:])]))

    out: dict[str, Any] = {
        "xs": piecewise(lambda y: smooth(y, win_x, 3), x),
        "v": piecewise(lambda y: derivative(y, dt, 3, win_x), x),
        "a": piecewise(lambda y: derivative(y, dt, 3, win_x, deriv=2), x),
        "noise": {"x": noise(x), "u": 0.0},
        "p_a": None, "p_b": None, "pas": None, "pbs": None, "dpa": None, "dpb": None}
    for name in sides:
        short = name[-1]
        p = np.asarray(rec[name], dtype=float)
        out[name], out[f"p{short}s"] = p, piecewise(lambda y: smooth(y, win_p, 2), p)
        out[f"dp{short}"] = piecewise(lambda y: derivative(y, dt, 2, win_p), p)
        out["noise"][name] = noise(p)
    return out


def other_side(plant: Plant, side: str, p: np.ndarray, x: np.ndarray, v: np.ndarray,
               a: np.ndarray) -> np.ndarray:
    """The chamber pressure that is not recorded (Pa), from the recorded one ``p`` (Pa,
    chamber ``side``) and the piston's force balance along the smoothed position ``x``
    (m), velocity ``v`` (m/s) and acceleration ``a`` (m/s^2):
    p_a A_a - p_b A_b - p_atm (A_a - A_b) = m a + beta v + F_ext - F_stop (+ the plant
    file's dry friction, if it has one, in its smooth form). Dry friction the plant
    file lacks is not known here and biases the estimate by up to F_s / A. Clipped to
    [0.5 p_atm, 1.1 p_supply]."""
    from ..physics import friction, piston
    pr = plant.params
    m, beta = pr["load.mass"], pr["load.viscous_friction"]
    need = m * a + beta * v + pr["load.external_force"] - np.asarray(
        [float(piston.end_stop_force(xi, vi, plant.stroke, m)) for xi, vi in zip(x, v)]
        if np.any((x < 0) | (x > plant.stroke)) else np.zeros(len(x)))
    if pr.has_effect("dry_friction"):
        need = need + friction.smooth_friction(v, pr["friction.coulomb"], pr["friction.static"],
                                               pr["friction.stribeck_velocity"], 0.0)
    aa, ab, p_atm = plant.area_a, plant.area_b, pr["gas.atmospheric_pressure"]
    if side == "p_a":
        est = (p * aa - p_atm * (aa - ab) - need) / ab
    else:
        est = (need + p * ab + p_atm * (aa - ab)) / aa
    return np.clip(est, 0.5 * p_atm, 1.1 * pr["supply.pressure"])


#: Recorded columns held (zero-order) when resampling: the command and reference are
#: outputs held between updates; the measurements are interpolated.
HELD = ("u", "r")


#: Share of the command's changes that must fit one regular clock of the controller's
#: period for :func:`command_switches` to place them on it.
CLOCK_SHARE = 0.9


def command_switches(t: np.ndarray, u: np.ndarray, period: float
                     ) -> tuple[np.ndarray, np.ndarray] | None:
    """When the command changed, if a controller of ``period`` (s) updated it on its
    own regular clock while the logger sampled it with jitter.

    A change between samples j-1 and j happened at some instant in (t_{j-1}, t_j]; on
    a regular clock k period + phi every such bracket holds one instant. The phase that
    the most brackets admit is kept (scanned over 400 values, the middle of the best
    run), provided :data:`CLOCK_SHARE` of them do; each change is then put at its clock
    instant. Returns (instants, index of the sample showing the new value) or None.
    """
    j = np.flatnonzero(np.diff(u) != 0) + 1
    if len(j) < 10 or not (period > 0):
        return None
    lo, hi = t[j - 1], t[j]
    phi = np.arange(400) * (period / 400)
    inst = phi[:, None] + period * (np.floor((lo[None, :] - phi[:, None]) / period) + 1.0)
    ok = inst <= hi[None, :]
    count = ok.sum(axis=1)
    best = np.flatnonzero(count == count.max())
    if count.max() < CLOCK_SHARE * len(j):
        return None
    runs = np.split(best, np.flatnonzero(np.diff(best) > 1) + 1)
    run = max(runs, key=len)
    k = int(run[len(run) // 2])
    return np.where(ok[k], inst[k], hi), j


def logger_period(steps: np.ndarray) -> float:
    """The logger's nominal sample period (s) from its time steps (s): the duration over
    the number of periods it spans, each step counted as the whole number of median
    steps nearest to it. With jitter alone that is the mean step (jitter averages out);
    a dropped sample is a step of two periods, counted as two (the mean step would be
    too long by the share of samples dropped, and the controller's clock would no
    longer fit the grid).

    >>> round(logger_period(np.array([1e-3, 1e-3, 2e-3, 1e-3])) * 1e3, 9)
    1.0
    """
    med = float(np.median(steps))
    periods = np.maximum(np.rint(steps / med), 1.0)
    return float(np.sum(steps) / np.sum(periods))


def uniform(rec: Recording, dt: float, period: float | None = None) -> Recording:
    """``rec`` on a uniform grid of period ``dt`` (s) from its first sample: measured
    columns interpolated linearly, :data:`HELD` columns held from the last sample at or
    before each grid time. With the controller's ``period`` (s), the command's changes
    are first put on that controller's clock (:func:`command_switches`): a jittered
    logger that sampled just before an update would otherwise delay it by a sample."""
    t = np.asarray(rec.t, dtype=float)
    grid = t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt + 1e-9)) + 1)
    cols = {}
    for name in rec.columns:
        if name == "t":
            continue
        y = np.asarray(rec[name], dtype=float)
        sw = command_switches(t, y, period) if name == "u" and period else None
        if sw is not None:
            when, j = sw
            order = np.argsort(when, kind="stable")
            k = np.searchsorted(when[order], grid + 1e-12 * dt, side="right")
            cols[name] = np.where(k > 0, y[j[order][np.maximum(k - 1, 0)]], y[0])
        elif name in HELD:
            idx = np.clip(np.searchsorted(t, grid + 1e-12 * dt, side="right") - 1, 0, len(t) - 1)
            cols[name] = y[idx]
        else:
            cols[name] = np.interp(grid, t, y)
    meta = dict(getattr(rec, "metadata", {}) or {})
    meta["sample_time"] = repr(float(dt))
    return Recording.from_arrays(grid, source=rec.source, metadata=meta, **cols)


#: Relative 1..99 % spread of a recorded p_s above which it is used sample by sample
#: (below: its median as a constant; 3 % of 6 bar = 0.18 bar, several times a
#: pressure sensor's noise, and about what moves a 25 mm piston's force by 9 N).
SAG = 0.03


def supply_profile(plant: Plant, rec: Recording, win: int) -> np.ndarray | None:
    """The recorded supply pressure (Pa) smoothed over ``win`` samples, when the
    recording has ``p_s``, it varies by more than :data:`SAG` and the plant file does
    not model the supply as a reservoir (supply_droop); else None."""
    if "p_s" not in rec or plant.params.has_effect("supply_droop"):
        return None
    ps = np.asarray(rec["p_s"], dtype=float)
    med = float(np.median(ps))
    if float(np.percentile(ps, 99) - np.percentile(ps, 1)) <= SAG * med:
        return None
    return smooth(ps, win, 2)


def recorded_supply(plant: Plant, rec: Recording | list[Recording]
                    ) -> tuple[Plant, list[str]]:
    """The plant with the recorded supply pressure ``p_s`` (its median, Pa) when the
    recording (or any of several) has one and the plant has no supply droop, and notes:
    the value used, and a sag under flow (which the supply_droop candidate models) when
    p_s varies."""
    recs = [r for r in (rec if isinstance(rec, (list, tuple)) else [rec]) if "p_s" in r]
    if not recs:
        return plant, []
    ps = np.concatenate([np.asarray(r["p_s"], dtype=float) for r in recs])
    med = float(np.median(ps))
    nominal = float(plant.params["supply.pressure"])
    notes = []
    if plant.params.has_effect("supply_droop"):
        return plant, [f"recorded supply pressure p_s (median {med / 1e5:.3g} bar) shown, not "
                       "used: the plant file models the supply as a reservoir"]
    if abs(med - nominal) > 0.005 * nominal:
        plant = Plant(plant.params.replace(**{"supply.pressure": med}), friction=plant.friction)
        notes.append(f"the recorded supply pressure p_s (median {med / 1e5:.4g} bar) is used "
                     f"instead of the plant file's {nominal / 1e5:.4g} bar")
    sag = float(np.percentile(ps, 99) - np.percentile(ps, 1))
    if sag > SAG * med:
        notes.append(f"the recorded supply pressure varies by {sag / 1e5:.3g} bar "
                     f"({100 * sag / med:.0f} %): it sags under flow, so the replays take "
                     "it sample by sample (the supply_droop and supply-pressure candidates "
                     "are not needed and left out)")
    return plant, notes


def _pressure_notes(sides: tuple[str, ...]) -> list[str]:
    """What a recording without one or both chamber pressures allows, in words."""
    out: list[str] = []
    if not sides:
        out.append("the recording has no chamber pressures (neither p_a nor p_b): the "
                   "diagnosis is reduced to what the position shows (dry friction, valve "
                   "deadband, offset and dynamics, lines, mass and viscous friction); "
                   "leakage, supply droop and heat transfer cannot be told apart from "
                   "position alone")
    elif len(sides) == 1:
        other = "p_b" if sides == ("p_a",) else "p_a"
        out.append(f"the recording has {sides[0]} but no {other}: the predictions are "
                   f"re-anchored on the measured {sides[0]} and on {other} estimated (see "
                   f"the next note); the fit compares x and "
                   f"{sides[0]}; the flow witness is formed for chamber {sides[0][-1]} "
                   "only, and the grey-box polish compares x and " f"{sides[0]}")
    return out


def _unrecorded(plant: Plant, sides: tuple[str, ...], sm: dict[str, Any], u: np.ndarray,
                dt: float, starts: list[int] | None, notes: list[str]) -> dict[str, float]:
    """The chamber pressures not recorded: with one side, the other's smoothed estimate
    into ``sm`` (:func:`.recorded.unrecorded_pressure`); with none, the start pressures
    returned (:func:`.recorded.start_pressures`); how, appended to ``notes``."""
    how, start = "", {}
    if len(sides) == 1:
        other = "p_b" if sides == ("p_a",) else "p_a"
        rec_s = sm[f"p{sides[0][-1]}s"]
        sm[f"p{other[-1]}s"], how = unrecorded_pressure(
            plant, sides[0], rec_s, other_side(plant, sides[0], rec_s, sm["xs"], sm["v"], sm["a"]),
            sm["xs"], sm["v"], u, dt, starts)
    elif not sides:
        start, how = start_pressures(plant, float(sm["xs"][0]))
    notes += [how] if how else []
    return start


def prepare(plant: Plant, rec: Recording, mode: str = "auto",
            starts: list[int] | None = None) -> Prepared:
    """Check the recording against the plant and prepare the signals.

    Parameters
    ----------
    plant : the nominal plant.
    rec : the recording.
    mode : "auto", "closed" or "open" (replay mode).
    starts : first sample of each recording when ``rec`` joins several
        (:func:`prepare_many`); each is smoothed on its own.

    Raises
    ------
    InputError
        Too short, no motion at all, a sample time the controller period is not a
        multiple of, or a closed-loop replay asked for without ``r`` or controller.
    """
    notes: list[str] = []
    t = np.asarray(rec.t, dtype=float) - float(rec.t[0])
    n = len(t)
    src = rec.source
    if rec.duration < MIN_DURATION or n < 50:
        raise InputError(f"the recording is too short for a diagnosis: {rec.duration:.3g} s, "
                         f"{n} samples; at least {MIN_DURATION:g} s (and 50 samples) with the "
                         "piston moving are needed, better 20 s or more with steps both ways",
                         source=src)
    steps = np.diff(t)
    dt = float(np.median(steps))
    if not np.all(steps > 0):
        raise InputError("the time column t must increase strictly from sample to sample",
                         source=src, location="column 't'")
    if np.max(np.abs(steps - dt)) > 0.05 * dt:
        dt = logger_period(steps)
        notes.append(f"the sample time varies (period {dt * 1e3:.3g} ms, range "
                     f"{steps.min() * 1e3:.3g}..{steps.max() * 1e3:.3g} ms): the recording is "
                     f"resampled on a uniform {dt * 1e3:.3g} ms grid (measurements linearly "
                     "interpolated, the command and reference held as a logger's outputs are; the "
                     "command's updates on the controller's clock when they fit one)")
        period = (plant.params["controller.sample_time"] if plant.params.has_controller
                  else None)
        rec = uniform(rec, dt, period)
        t = np.asarray(rec.t, dtype=float) - float(rec.t[0])
        n = len(t)
    if rec.duration < SHORT_DURATION:
        notes.append(f"short recording ({rec.duration:.3g} s): few events to learn from, "
                     "so weak effects may go unnoticed")
    x = np.asarray(rec["x"], dtype=float)
    if np.ptp(x) < 1e-3 * plant.stroke:
        raise InputError(f"the piston hardly moves in this recording (position range "
                         f"{np.ptp(x) * 1e3:.3g} mm): nothing to diagnose", source=src,
                         location="column 'x'")
    sides = tuple(s for s in ("p_a", "p_b") if s in rec)
    notes += _pressure_notes(sides)
    has_r = "r" in rec
    has_ctrl = plant.params.has_controller
    controller, ratio, phase = _plant_controller(plant, rec, dt, notes)
    closed = False
    if mode == "closed":
        if not has_r:
            raise InputError("closed-loop replay needs an 'r' column", source=src)
        if controller is None:
            raise InputError("closed-loop replay needs a [controller] section (with a period "
                             "that is a multiple of the sample time)", source=plant.params.source)
    if has_r and not has_ctrl:
        notes.append("the recording has a reference r but the plant file has no [controller]: "
                     "the recording is replayed open loop on its command u, re-anchored on the "
                     "measured state every few tenths of a second (add the [controller] that "
                     "ran for a closed-loop replay)")
    elif has_ctrl and not has_r and controller is not None:
        notes.append("the plant file has a [controller] but the recording has no reference r: "
                     "open-loop replay on the recorded command u, re-anchored")
    win_x, win_p = odd_window(WINDOW_X, dt), odd_window(WINDOW_P, dt)
    sm = _smoothed(rec, x, dt, win_x, win_p, sides, starts)
    start = _unrecorded(plant, sides, sm, np.asarray(rec["u"], dtype=float), dt, starts, notes)
    if has_r and controller is not None and mode != "open":
        closed = True
        agree = _controller_agreement(plant, controller, rec, x, phase, ratio)
        if agree < CONTROLLER_AGREEMENT and mode != "closed":
            closed = False
            notes.append(f"the plant file's [controller] does not reproduce the recorded command "
                         f"(fit of u {agree:.0f} %): it is probably not the loop that ran, so the "
                         "recording is replayed open loop on u, re-anchored")
    return Prepared(plant=plant, rec=rec, t=t, dt=dt, closed=closed, start=start,
                    controller=controller if closed else controller, ratio=ratio, phase=phase,
                    x=x, **sm, signals=("x",) + sides,
                    win_x=win_x, win_p=win_p, win_slow=odd_window(WINDOW_SLOW, dt, 9),
                    notes=notes, starts=list(starts or []),
                    supply=supply_profile(plant, rec, win_p))


def _piece(rec: Recording, a: int, b: int) -> Recording:
    """Samples ``a:b`` of ``rec`` (time from its first kept sample)."""
    t = np.asarray(rec.t, dtype=float)[a:b]
    return Recording.from_arrays(t - t[0], source=rec.source,
                                 metadata=dict(getattr(rec, "metadata", {}) or {}),
                                 **{c: np.asarray(rec[c])[a:b] for c in rec.columns if c != "t"})


def prepare_many(plant: Plant, recs: list[Recording], mode: str = "auto") -> Prepared:
    """Several recordings of the same rig prepared as one (one model explains them all).

    The recordings are put end to end on one time axis (each starts one sample time
    after the previous one ends; those with another sample time are resampled on the
    first one's, :func:`uniform`), each smoothed on its own, in one replay mode (closed
    loop only if every one is). In closed loop each is cut to whole controller periods
    from a controller update, so the joined recording's updates keep one phase. The
    result's ``parts`` are the recordings prepared alone (the replays and the fit per
    recording use them) and ``starts`` their first samples in the joined one: the
    predictions are re-anchored there (:func:`workbench.diagnose.core.diagnose`).

    Recordings with different measured signals (one with x, p_a, p_b, one with x only,
    one with p_a only) are joined on the signals they share and each other signal is
    kept where it was recorded (:func:`.recorded.with_all_signals`): it counts only there.

    Raises
    ------
    InputError
        No recording.
    """
    if not recs:
        raise InputError("no recording given: a diagnosis needs at least one")
    if len(recs) == 1:
        return prepare(plant, recs[0], mode)
    parts = [prepare(plant, r, mode) for r in recs]
    closed, some_closed = all(p.closed for p in parts), any(p.closed for p in parts)
    mode = "closed" if closed else "open"
    dt = parts[0].dt
    recs = [p.rec if abs(p.dt - dt) <= 1e-3 * dt else uniform(p.rec, dt) for p in parts]
    parts = [prepare(plant, r, mode) for r in recs]
    ratio = parts[0].ratio if closed else 1
    pieces = []
    for p in parts:
        a = p.phase if closed else 0
        pieces.append(_piece(p.rec, a, a + (p.n - a) // ratio * ratio))
    parts = [prepare(plant, r, mode) for r in pieces]
    cols = [c for c in pieces[0].columns if c != "t" and all(c in r for r in pieces)]
    starts = [int(s) for s in np.cumsum([0] + [len(r.t) for r in pieces[:-1]])]
    t = dt * np.arange(sum(len(r.t) for r in pieces))
    joined = Recording.from_arrays(
        t, source=" + ".join(str(r.source) for r in pieces),
        metadata={"sample_time": repr(dt)},
        **{c: np.concatenate([np.asarray(r[c], dtype=float) for r in pieces]) for c in cols})
    prep = prepare(plant, joined, mode, starts)
    mixed = len({p.signals for p in parts}) > 1
    if mixed:
        prep = with_all_signals(prep, parts, starts)
    prep.parts = parts
    notes = [f"{len(parts)} recordings diagnosed together (one model for all; fit per "
             "recording in details.json): " + ", ".join(
                 f"{p.rec.source} from {dt * s:.3g} s" for p, s in zip(parts, starts))]
    if some_closed and not closed:
        notes.append("not every recording can be replayed in closed loop: all are replayed "
                     "open loop on u, re-anchored")
    if mixed:
        notes.append(mixed_note(parts))
    for p in parts:       # (a part's "short recording" is not the joined one's)
        notes += [(f"{p.rec.source}: {n}" if mixed and n.startswith("the recording has")
                   else n) for n in p.notes
                  if n not in notes and not n.startswith("short record")
                  and not (mixed and n.startswith("the recording has no chamber"))]
    prep.notes = notes + [n for n in prep.notes if n not in notes
                          and not (mixed and n.startswith("the recording has"))]
    return prep
