"""Comparable replays: short-horizon predictions and re-anchored closed-loop segments.

Two ways of asking "does the model reproduce the recording?" that stay comparable
where a long open-loop replay would drift away:

* :func:`horizons` -- *short-horizon predictions*: every ``horizon`` seconds the model
  is put on the measured state and run open loop on the recorded command; its
  position and pressures are compared with the measurement until the next anchor.
  This is the refit objective: it uses only what the rig did (the applied command),
  it is smooth in the parameters, and a correct model reaches the noise level.
* :func:`segments` -- the recording's closed loop (reference, plant-file controller)
  re-anchored every ``length`` seconds (at controller instants, at rest where
  possible), i.e. the replay of ``workbench simulate`` with its drift cut off.

Both are :class:`Predictor` objects: engine inputs for the selected samples plus
the weighting of the residuals (measurement noise of each signal).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..recording import fit
from ..signals import dilate
from .data import Prepared
from .engine import INPUT_ROWS, EngineInputs

__all__ = ["Predictor", "horizons", "segments", "default_step", "HORIZON", "SEGMENT",
           "friction_events", "settle_refinement", "EVENT_REACH"]

#: s: short-horizon prediction length (about ten time constants of the chambers,
#: a few of the position loop).
HORIZON = 0.2
#: s: closed-loop segment length.
SEGMENT = 2.0


@dataclass
class Predictor:
    """Engine inputs on selected samples and how to weigh the residuals.

    Attributes
    ----------
    kind : "horizons" or "segments".
    index : (M,) recording samples simulated, in order.
    inputs : engine inputs for those samples.
    starts : (W,) positions in ``index`` where the model is re-anchored.
    signals : compared signals. sigma : their noise (weights 1/sigma).
    decimate : residual vector keeps every n-th simulated sample.
    step : recording samples per simulated sample (the engine's step is step * dt).
    """

    kind: str
    prep: Prepared
    index: np.ndarray
    inputs: EngineInputs
    starts: np.ndarray
    signals: tuple[str, ...]
    sigma: dict[str, float]
    decimate: int = 4
    step: int = 1

    @property
    def windows(self) -> int:
        return int(len(self.starts))

    @property
    def n_eff(self) -> float:
        """Effective number of independent observations (for the information criteria):
        a few (3) per :data:`HORIZON` of window and signal recorded there, since the
        residuals within a window are correlated; a window counts its length in whole
        horizons (at least one). So a closed-loop segment (position only, 1 s, also as a
        part of joined recordings) counts five: the loop decorrelates its residuals within
        a horizon or so (measured on a position-only foreign recording: 49 independent
        residuals per 1 s segment by their autocorrelation). Counted as one horizon's 3,
        8 s of a 200 Hz position-only recording of 18/26 N of friction fell short of the
        information criterion (dBIC 9) while the friction removed 51 %."""
        ends = np.append(self.starts[1:], len(self.index))
        seconds = (ends - self.starts) * self.step * self.prep.dt
        weight = np.maximum(np.round(seconds / HORIZON), 1.0)   # horizons: 1 each
        counts = [len(self.prep.signals_at(int(i))) for i in self.index[self.starts]] \
            if self.prep.recorded else [len(self.signals)] * self.windows
        return float(max(3 * float(np.dot(weight, counts)), 10))

    def measured(self, s: str) -> np.ndarray:
        return self.prep.measured(s)[self.index]

    def _ok(self, s: str) -> np.ndarray:
        """Simulated samples where signal ``s`` was recorded (all but where a joined
        recording lacks it, :meth:`.data.Prepared.mask`)."""
        return self.prep.mask(s)[self.index]

    def residuals(self, Y: np.ndarray) -> np.ndarray:
        """Weighted residual vector (measurement - model) / noise, decimated; 0 where the
        signal was not recorded."""
        out = []
        for s in self.signals:
            row = ("x", "p_a", "p_b").index(s)
            r = np.where(self._ok(s), (self.measured(s) - Y[row]) / self.sigma[s], 0.0)
            out.append(r[::self.decimate])
        r = np.concatenate(out)
        return np.where(np.isfinite(r), r, 1e6)

    def residual_jacobian(self, Y: np.ndarray, dY: np.ndarray) -> np.ndarray:
        """Jacobian of :meth:`residuals` from the engine's sensitivities ``dY`` (rows x,
        p_a, p_b; shape (3, k, samples)): (residuals, k); zero where a residual is not
        finite (it is then the constant 1e6)."""
        out = []
        for s in self.signals:
            row = ("x", "p_a", "p_b").index(s)
            r = (self.measured(s) - Y[row])[::self.decimate]
            d = -dY[row][:, ::self.decimate].T / self.sigma[s]
            ok = np.isfinite(r)[:, None] & np.isfinite(d) & self._ok(s)[::self.decimate, None]
            out.append(np.where(ok, d, 0.0))
        return np.concatenate(out)

    def cost(self, Y: np.ndarray) -> float:
        """Mean squared weighted residual, summed over signals (1 per signal = noise level)."""
        return float(sum(self.signal_costs(Y).values()))

    def signal_costs(self, Y: np.ndarray) -> dict[str, float]:
        """Mean squared weighted residual of each signal over the samples where it was
        recorded (1e12 when the model's output is not finite there)."""
        out = {}
        for s in self.signals:
            row = ("x", "p_a", "p_b").index(s)
            ok = self._ok(s)
            r = (self.measured(s)[ok] - Y[row][ok]) / self.sigma[s]
            out[s] = (0.0 if not len(r) else float(np.mean(r * r)) if np.all(np.isfinite(r))
                      else 1e12)
        return out

    def fits(self, Y: np.ndarray) -> dict[str, float]:
        """NRMSE fit (%) of each signal over the simulated samples where it was recorded."""
        out = {}
        for s in self.signals:
            row = ("x", "p_a", "p_b").index(s)
            ok = self._ok(s)
            y = Y[row][ok]
            out[s] = (float("nan") if len(y) < 3 else fit(self.measured(s)[ok], y)
                      if np.all(np.isfinite(y)) else float("-inf"))
        return out

    def full(self, Y: np.ndarray, row: int) -> np.ndarray:
        """A model output on the recording's samples (NaN where not simulated)."""
        return self._spread(np.asarray(Y[row], dtype=float))

    def _spread(self, values: np.ndarray) -> np.ndarray:
        """Values at the simulated samples held over their steps, NaN elsewhere."""
        out = np.full(self.prep.n, np.nan)
        for j in range(self.step):
            idx = self.index + j
            ok = idx < self.prep.n
            out[idx[ok]] = values[ok]
        return out

    def error_by_sample(self, Y: np.ndarray) -> np.ndarray:
        """Squared weighted residual per recording sample, summed over signals (NaN outside)."""
        e = np.zeros(len(self.index))
        for s in self.signals:
            row = ("x", "p_a", "p_b").index(s)
            e += np.where(self._ok(s), ((self.measured(s) - Y[row]) / self.sigma[s]) ** 2, 0.0)
        return self._spread(e)


def _base_inputs(prep: Prepared, index: np.ndarray, step: int = 1) -> np.ndarray:
    row = {k: i for i, k in enumerate(INPUT_ROWS)}
    d = np.zeros((len(INPUT_ROWS), len(index)))
    u = np.asarray(prep.rec["u"], dtype=float)
    if step > 1:          # the command held over each simulated step: its mean
        u = np.convolve(u, np.ones(step) / step, mode="full")[step - 1:][:len(u)]
        u[-step:] = np.asarray(prep.rec["u"])[-step:]
    d[row["u_rec"]] = u[index]
    d[row["x_m"]] = prep.xs[index]
    d[row["v_m"]] = prep.v[index]
    if prep.pressures:        # one recorded: the other is estimated (Prepared.smoothed)
        d[row["p_a_m"]] = prep.pas[index]
        d[row["p_b_m"]] = prep.pbs[index]
    if "r" in prep.rec:
        d[row["r"]] = np.asarray(prep.rec["r"])[index]
    if prep.supply is not None:          # the recorded supply pressure, sample by sample
        d[row["use_p_s"]], d[row["p_s_m"]] = 1.0, prep.supply[index]
    inst = prep.control_instants()
    if step > 1:          # a controller instant anywhere within the step
        inst = np.convolve(inst.astype(float), np.ones(step), mode="full")[step - 1:]
        inst = inst[:len(prep.t)] > 0
    d[row["control_instant"]] = inst[index]
    d[row["e_prev_m"]] = prep.e_prev()[index]
    return d


def _sigma(prep: Prepared) -> dict[str, float]:
    sig = {"x": max(prep.noise["x"], 1e-6 * prep.plant.stroke)}
    for side in prep.pressures:
        sig[side] = max(prep.noise[side], 10.0)
    return sig


def default_step(prep: Prepared) -> int:
    """Recording samples per engine step: about 2 ms (the chambers' fastest time
    constants are several ms), dividing the controller period."""
    step = max(int(round(0.002 / prep.dt)), 1)
    while step > 1 and prep.closed and prep.ratio % step:
        step -= 1
    return step


#: s: longest stretch of recording the short-horizon predictions cover (longer
#: recordings: the busiest half of the windows plus evenly spread quiet ones).
MAX_PREDICTED = 60.0


def horizons(prep: Prepared, horizon: float = HORIZON, coverage: float | None = None,
             decimate: int = 2, step: int | None = None) -> Predictor:
    """Short-horizon open-loop predictions from the measured state every ``horizon`` s.

    ``coverage`` < 1 keeps that share of the windows: half of them the busiest (a
    window where nothing happens tells little about most effects), half spread
    evenly over the rest (leaks and heat exchange show at rest). Default: all windows
    up to :data:`MAX_PREDICTED` seconds of recording.
    """
    n = prep.n
    step = default_step(prep) if step is None else step
    h = max(int(round(horizon / prep.dt)), 5)
    h -= h % step
    first = prep.win_x + (-(prep.win_x - prep.phase)) % step if prep.closed else prep.win_x
    starts = np.arange(first, n - h, h)
    if coverage is None:
        coverage = min(1.0, MAX_PREDICTED / max(len(starts) * h * prep.dt, 1e-9))
    if coverage < 1.0 and len(starts) > 8:
        act = np.array([np.ptp(prep.xs[s:s + h]) / max(np.ptp(prep.xs), 1e-9)
                        + np.std(np.diff(np.asarray(prep.rec["u"])[s:s + h])) for s in starts])
        keep = max(int(round(coverage * len(starts))), 8)
        order = np.argsort(-act)
        busy = order[:keep // 2]
        rest = np.sort(order[keep // 2:])
        spread = rest[np.linspace(0, len(rest) - 1, keep - len(busy)).astype(int)]
        starts = starts[np.unique(np.concatenate([busy, spread]))]
    # hidden states: from rest at the first window, then carried over (when windows
    # are contiguous) or reset to rest (after a gap)
    gap = np.concatenate(([True], np.diff(starts) > h))
    if len(prep.pressures) == 1:
        starts, ends = _quiet_starts(prep, starts, h, step, gap)
    else:
        ends = starts + h
    pieces = [np.arange(a, b, step) for a, b in zip(starts, ends)]
    index = np.concatenate(pieces)
    d = _base_inputs(prep, index, step)
    row = {k: i for i, k in enumerate(INPUT_ROWS)}
    pos = np.concatenate(([0], np.cumsum([len(q) for q in pieces])[:-1]))
    d[row["anchor"], pos] = 1.0
    if prep.pressures:
        d[row["anchor_p"], pos] = 1.0
    d[row["anchor_hidden"], pos[gap]] = 1.0
    d[row["closed_loop"]] = 0.0
    return Predictor("horizons", prep, index, EngineInputs(d), pos, prep.signals, _sigma(prep),
                     decimate, step)


def _quiet_starts(prep: Prepared, starts: np.ndarray, h: int, step: int, gap: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Window starts moved (by whole steps, at most a quarter window) to where the
    piston accelerates least, and the windows' ends (the next start when contiguous).

    With one chamber pressure recorded, each window starts from the other one's
    force-balance estimate (:func:`.data.other_side`), whose error is that of the
    smoothed acceleration times m / A: measured on the foreign rig, 1.5 kPa rms overall
    but 4.4 kPa in the 10 % of samples that accelerate most, where a wrong start
    pressure sets off a transient that a spurious spool lag (valve_dynamics at 38 Hz)
    absorbed. Where the piston accelerates least the estimate rests on the pressures
    and the load, not on the acceleration.
    """
    n = prep.n
    a = np.abs(prep.a)
    reach = (h // 4) // step
    moved = starts.copy()
    for i, s0 in enumerate(starts):
        cand = s0 + step * np.arange(-reach, reach + 1)
        cand = cand[(cand >= starts[0]) & (cand + h <= n)]
        if i > 0 and not gap[i]:
            cand = cand[cand > moved[i - 1]]
        if len(cand):
            moved[i] = int(cand[np.argmin(a[cand])])
    ends = moved + h
    contiguous = np.concatenate((~gap[1:], [False]))
    ends[contiguous] = moved[1:][contiguous[:-1]]
    return moved, np.minimum(ends, n)


def segments(prep: Prepared, length: float = SEGMENT, decimate: int = 2,
             step: int | None = None) -> Predictor:
    """The closed loop re-anchored every ``length`` s (open loop on u without controller)."""
    n = prep.n
    step = default_step(prep) if step is None else step
    seg = max(int(round(length / prep.dt)), 10)
    if prep.closed:
        seg -= seg % prep.ratio
    seg -= seg % step
    nominal = np.arange(prep.phase if prep.closed else 0, n - 1, seg)
    rest = np.abs(prep.v) < 3e-3
    inst = prep.control_instants() if prep.closed else np.ones(n, dtype=bool)
    if not prep.closed:
        inst &= (np.arange(n) % step) == 0
    starts = []
    for s in nominal:
        lo, hi = max(s - seg // 4, 0), min(s + seg // 4, n - 2)
        cand = np.flatnonzero(rest[lo:hi] & inst[lo:hi]) + lo
        starts.append(int(cand[np.argmin(np.abs(cand - s))]) if len(cand) else int(s))
    starts = np.unique(np.array(starts))
    if starts[0] != nominal[0]:
        starts = np.concatenate(([nominal[0]], starts))
    index = np.arange(starts[0], n, step)
    d = _base_inputs(prep, index, step)
    row = {k: i for i, k in enumerate(INPUT_ROWS)}
    pos = (starts - starts[0]) // step
    d[row["anchor"], pos] = 1.0
    if prep.pressures:
        d[row["anchor_p"], pos] = 1.0
    d[row["anchor_hidden"], pos] = 1.0
    d[row["closed_loop"]] = 1.0 if prep.closed else 0.0
    return Predictor("segments", prep, index, EngineInputs(d), pos, prep.signals, _sigma(prep),
                     decimate, step)


#: Whether the diagnosis refines the engine's steps (:func:`settle_refinement`) in its
#: predictors. Off: measured on the single-effect bench case (24 s, concealed dry
#: friction, loaded 2-core machine, CPU time), the settled refinement took 64 CPU s
#: against 25 (more refined steps, and 42 candidate models against 27) and named a
#: spurious valve_offset beside the friction; on the 8 s valve-offset case of
#: tests/test_diagnose.py it added a negligible leak as a second finding. Both are the
#: replay's remaining error where it is not refined (the 2 ms step in fast smooth motion:
#: 67 um rms over 0.2 s windows on a noise-free recording of the exact model, 6 um at
#: four sub-steps), which the extra effects absorb once the friction events are exact.
#: The mechanism stays (a decision once per predictor keeps the cost smooth). Those
#: figures were ROS2's; the engine steps plants without lines or a spool lag with ROS4
#: now (:data:`.engine.TABLEAU`), whose floor outside the events is 5.4 um: on a
#: noise-free 4 s stick-slip recording (Coulomb 20 N, static 28 N, v_s 12 mm/s) the
#: exact model's replay misses x by 22.7 um rms unrefined, 7.3 um with the events
#: refined (4.5 % of the samples), 5.5 um with every sample refined; with the sensor
#: noise of synth (20 um, 12 bits) 48 / 42 / 42 um. Switched on with ROS4 (loaded
#: machine): the single-effect bench case named dry friction alone, 27 candidate
#: models, 25.1 CPU s against 23.3 off; but tests/test_diagnose.py's foreign dry-friction
#: case (tanh-smoothed law) named a negligible leak (4.9e-12 kg/(s Pa)) beside the
#: friction. So still off.
REFINE_STEPS = False

#: Engine steps on each side of a friction event of the recording (or of a step the
#: nominal replay flags) that are refined: the replay of a model that is not yet
#: fitted meets the event a few ms off the measured instant (2 steps: 4 ms at 1 kHz).
EVENT_REACH = 2


def friction_events(prep: Prepared, index: np.ndarray, reach: int = EVENT_REACH
                    ) -> np.ndarray:
    """Simulated samples (positions in ``index``) at a friction event of the recording:
    where the measured (smoothed) velocity reverses, or passes between rest and motion
    (a stop, a break-away), widened by ``reach`` engine steps on each side.

    These are where a stick-slip replay's one-step method loses its order (the friction
    law switches inside the step, the Stribeck curve's negative damping right after a
    break-away). They come from the recording only, never from a model's parameters.
    Rest: |v| below three times the velocity estimate's noise (at least 1 mm/s, as
    :class:`.witness.Witness`)."""
    from scipy.signal import savgol_coeffs
    sig_v = prep.noise["x"] * float(np.linalg.norm(
        savgol_coeffs(prep.win_x, 3, deriv=1, delta=prep.dt)))
    v_rest = max(3.0 * sig_v, 1e-3)
    v = np.asarray(prep.v, dtype=float)[index]
    moving = np.abs(v) >= v_rest
    sign = np.sign(v) * moving
    ev = np.zeros(len(index), dtype=bool)
    ev[1:] |= moving[1:] != moving[:-1]                    # stop or break-away
    # a reversal: the last moving sample's direction differs from this one's
    last = np.maximum.accumulate(np.where(moving, np.arange(len(v)), -1))
    prev = np.concatenate(([-1], last[:-1]))
    flip = moving & (prev >= 0) & (sign != sign[np.maximum(prev, 0)])
    ev |= flip
    return dilate(ev, reach)


def settle_refinement(pred: Predictor, run, reach: int = EVENT_REACH) -> np.ndarray:
    """Decide once which samples of ``pred`` the engine refines, and return the outputs
    of ``run`` (a replay, ``Y = run(pred)``) with that decision.

    Refined: the recording's friction events (:func:`friction_events`) and the steps
    that ``run``'s own replay flags as inexact (the engine's ``inexact`` row: a local
    error estimate above tolerance, e.g. at a valve opening), each widened by ``reach``
    steps. ``run`` is the nominal model's replay, so the decision does not depend on
    any candidate's parameters: every candidate is then replayed with the same steps
    throughout its fit, and the cost is a smooth function of its values (a decision
    taken per replay makes the cost jump wherever a step switches between one and
    :data:`.engine.REFINE` sub-steps). At a fitted model, which follows the measurement,
    the events and valve openings are those of the recording, so they are refined.
    """
    ev = friction_events(pred.prep, pred.index, reach)
    pred.inputs = pred.inputs.with_rows(refine=ev.astype(float))
    Y = run(pred)
    flags = np.nan_to_num(np.asarray(Y[-1], dtype=float)) > 0.5
    mask = ev | dilate(flags, reach)
    if np.array_equal(mask, ev):
        return Y
    pred.inputs = pred.inputs.with_rows(refine=mask.astype(float))
    return run(pred)
