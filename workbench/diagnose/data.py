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

__all__ = ["Prepared", "prepare", "uniform", "recorded_supply", "MIN_DURATION",
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

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def has_pressures(self) -> bool:
        return self.p_a is not None and self.p_b is not None

    def measured(self, name: str) -> np.ndarray:
        return {"x": self.x, "p_a": self.p_a, "p_b": self.p_b}[name]

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
        prev = np.where(idx - self.ratio >= 0, idx - self.ratio, idx)
        return e[prev]


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
              has_p: bool) -> dict[str, Any]:
    """Smoothed signals, their derivatives and the noise floors (Prepared's fields).

    Position: cubic Savitzky-Golay over ``win_x`` samples (value, velocity m/s,
    acceleration m/s^2); pressures: quadratic over ``win_p`` (value, rate Pa/s).
    """
    out: dict[str, Any] = {
        "xs": smooth(x, win_x, 3), "v": derivative(x, dt, 3, win_x),
        "a": derivative(x, dt, 3, win_x, deriv=2), "noise": {"x": noise_floor(x), "u": 0.0},
        "p_a": None, "p_b": None, "pas": None, "pbs": None, "dpa": None, "dpb": None}
    if has_p:
        for name, short in (("p_a", "a"), ("p_b", "b")):
            p = np.asarray(rec[name], dtype=float)
            out[name], out[f"p{short}s"] = p, smooth(p, win_p, 2)
            out[f"dp{short}"] = derivative(p, dt, 2, win_p)
            out["noise"][name] = noise_floor(p)
    return out


#: Recorded columns held (zero-order) when resampling: the command and reference are
#: outputs held between updates; the measurements are interpolated.
HELD = ("u", "r")


def uniform(rec: Recording, dt: float) -> Recording:
    """``rec`` on a uniform grid of period ``dt`` (s) from its first sample: measured
    columns interpolated linearly, :data:`HELD` columns held from the last sample at or
    before each grid time."""
    t = np.asarray(rec.t, dtype=float)
    grid = t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt + 1e-9)) + 1)
    cols = {}
    for name in rec.columns:
        if name == "t":
            continue
        y = np.asarray(rec[name], dtype=float)
        if name in HELD:
            idx = np.clip(np.searchsorted(t, grid + 1e-12 * dt, side="right") - 1, 0, len(t) - 1)
            cols[name] = y[idx]
        else:
            cols[name] = np.interp(grid, t, y)
    meta = dict(getattr(rec, "metadata", {}) or {})
    meta["sample_time"] = repr(float(dt))
    return Recording.from_arrays(grid, source=rec.source, metadata=meta, **cols)


def recorded_supply(plant: Plant, rec: Recording) -> tuple[Plant, list[str]]:
    """The plant with the recorded supply pressure ``p_s`` (its median, Pa) when the
    recording has one and the plant has no supply droop, and notes: the value used, and
    a sag under flow (which the supply_droop candidate models) when p_s varies."""
    if "p_s" not in rec:
        return plant, []
    ps = np.asarray(rec["p_s"], dtype=float)
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
    if sag > 0.03 * med:
        notes.append(f"the recorded supply pressure varies by {sag / 1e5:.3g} bar "
                     f"({100 * sag / med:.0f} %): it sags under flow (see supply_droop)")
    return plant, notes


def prepare(plant: Plant, rec: Recording, mode: str = "auto") -> Prepared:
    """Check the recording against the plant and prepare the signals.

    Parameters
    ----------
    plant : the nominal plant.
    rec : the recording.
    mode : "auto", "closed" or "open" (replay mode).

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
        dt = float((t[-1] - t[0]) / (n - 1))     # the mean step: jitter averages out
        notes.append(f"the sample time varies (mean {dt * 1e3:.3g} ms, range "
                     f"{steps.min() * 1e3:.3g}..{steps.max() * 1e3:.3g} ms): the recording is "
                     f"resampled on a uniform {dt * 1e3:.3g} ms grid (measurements linearly "
                     "interpolated, the command and reference held as a logger's outputs are)")
        rec = uniform(rec, dt)
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
    has_p = "p_a" in rec and "p_b" in rec
    if not has_p:
        what = "neither p_a nor p_b" if ("p_a" not in rec and "p_b" not in rec) else \
            ("no p_b" if "p_a" in rec else "no p_a")
        notes.append(f"the recording has {what}: without both chamber pressures the flow "
                     "witnesses are not available, so the diagnosis is reduced to what the "
                     "position shows (dry friction, valve deadband and offset, mass and "
                     "viscous friction); leakage, lines, supply droop and heat transfer "
                     "cannot be told apart from position alone")
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
    sm = _smoothed(rec, x, dt, win_x, win_p, has_p)
    if has_r and controller is not None and mode != "open":
        closed = True
        agree = _controller_agreement(plant, controller, rec, x, phase, ratio)
        if agree < CONTROLLER_AGREEMENT and mode != "closed":
            closed = False
            notes.append(f"the plant file's [controller] does not reproduce the recorded command "
                         f"(fit of u {agree:.0f} %): it is probably not the loop that ran, so the "
                         "recording is replayed open loop on u, re-anchored")
    return Prepared(plant=plant, rec=rec, t=t, dt=dt, closed=closed,
                    controller=controller if closed else controller, ratio=ratio, phase=phase,
                    x=x, **sm, signals=("x",) + (("p_a", "p_b") if has_p else ()),
                    win_x=win_x, win_p=win_p, win_slow=odd_window(WINDOW_SLOW, dt, 9),
                    notes=notes)
