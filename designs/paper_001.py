"""Paper 001 (Iliev, Hristov) end to end: 1 m against 10 m lines, PID positioning.

Paper 001 simulates and measures an electropneumatic positioning drive with lines of
1 m and 10 m between the proportional valve and the cylinder, under a PID loop with
setpoint steps, and finds the longer lines delay and attenuate the chamber pressures
and make 'the time of the transition process' 0.4 s longer. The stored text of the
paper gives the model's form, the valve's Cv and X_T, the two lengths and the 0.4 s,
but no drive size, tube bore, step size or gains (the figures' values are not in it).
designs/plants/papers/iliev_lines_1m.toml says where each value comes from. This script:

1. derives the valve's ISO 6358 conductance from the paper's eq. (2) (Cv = 0.274,
   X_T = 1), read as the ISA/IEC 60534 gas law it is (:func:`valve_from_cv`);
2. reproduces the paper's experiment as set up: 'two experiments under identical
   conditions', i.e. one PID tuned on the 1 m drive and run unchanged with 10 m
   lines, on uniform setpoint steps; the transition time is the settling time into
   +-5 % of the step (the classical definition);
3. estimates the tube bore the paper does not give from its 0.4 s (a grid of bores,
   interpolated; interval from the 0.4 s's one significant digit, 0.35 .. 0.45 s) and
   checks the paper's other results on that setup: pressure delay and attenuation
   (valve step, open loop, lumped-segment lines of :mod:`workbench.physics.line`,
   beside eq. (4)'s own attenuation factor), the PID validated on both lines
   (:func:`workbench.validate.validate`), and how the step size moves the 0.4 s.

The report's first table is the paper's results beside the workbench's;
``DIR/summary.json`` holds the same rows in ``paper_results``.

Usage: python designs/paper_001.py [--quick] [--out DIR]
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from workbench import Plant, controllers, linearize, references, simulate, stability
from workbench import report as rp
from workbench import validate
from workbench.controllers.pd import pid_law
from workbench.physics.gas import R_AIR, RHO_ANR, T_REF
from workbench.physics.line import AIR_VISCOSITY

if str(Path(__file__).resolve().parent) not in sys.path:    # the sibling report module
    sys.path.insert(0, str(Path(__file__).resolve().parent))

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PLANT = HERE / "plants" / "papers" / "iliev_lines_1m.toml"
TITLE = "Paper 001 reproduced: 1 m against 10 m pneumatic lines, PID positioning"

#: Values quoted from paper 001: (value, unit, where).
PAPER = {
    "lengths": ((1.0, 10.0), "m", "Sec. 'Experimental study': two experiments, 1 m and 10 m"),
    "dt": (0.4, "s", "Sec. 'Modelling and simulation', after Fig. 9: 'the time of the "
                     "transition process differs by 0.4 s'"),
    "effects": ("time delay and amplitude decay", "", "Sec. 'Modelling and simulation', after "
                                                      "Fig. 9"),
    "cv": (0.274, "-", "eq. (2) and the line after it: Cv = 0.274"),
    "x_t": (1.0, "-", "the line after eq. (2): X_T = 1"),
}
#: Speed of sound of eq. (4)'s a_s, m/s (physics.md; the paper gives no number).
A_SOUND = 343.0
#: The ISA/IEC 60534 gas law Q = N Cv p1 Y sqrt(x / (G T1)), Q in standard ft^3/h,
#: p1 in psia, T1 in degR: N = 1360 (air, G = 1). In SI (Q m^3/s at 60 degF and
#: 14.696 psia, p1 Pa, T1 K): N = 1360 x 0.0283168 / 3600 / 6894.757 / sqrt(1.8).
ISA_N_SI = 1360.0 * 0.0283168 / 3600.0 / 6894.757 / math.sqrt(1.8)
#: Air density at the law's standard conditions (60 degF = 288.71 K, 14.696 psia), kg/m^3.
RHO_STD = 101325.0 / (R_AIR * 288.706)
#: Pressure delay: time for chamber a to rise 100 Pa after the valve step (0.1 % of the
#: 1e5 Pa swing: the front's arrival, above the solver's noise). The narrow line's front
#: rises over a few ms: at 2 mm bore the 10 m minus 1 m delay reads 25.1 / 26.1 / 27.2 /
#: 30.3 ms at 30 / 100 / 300 / 1000 Pa (40 segments; 23.5 .. 30.1 ms with 20).
DELAY_THRESHOLD = 100.0
#: Segments per line: about 0.25 m each (quick: 0.5 m on the 10 m line). Measured on the
#: quick staircase: transient shift 0.0510 s (20) against 0.0513 s (40 segments) with the
#: 4 mm bore, 0.4137 s against 0.4140 s with 2 mm; the delay differs by 1 ms.
SEGMENTS = {1.0: 8, 10.0: 40}
SEGMENTS_QUICK = {1.0: 8, 10.0: 20}
#: The transition time: settling into +- TRANSIENT_BAND of the step (the classical
#: 'time of the transition process' uses 5 %); 2 % and the half-way time are reported too.
TRANSIENT_BAND = 0.05
#: The paper's 0.4 s has one significant digit: it stands for 0.35 .. 0.45 s.
DT_INTERVAL = (0.35, 0.45)
#: Setpoint steps of the experiment, m (the paper: uniform steps 'within the working
#: stroke', no size; 100 mm = a fifth of the assumed stroke) and the hold, s (long
#: enough for the 10 m drive to settle at the narrowest bore of the grid).
STEP, HOLD = 0.1, 2.5
#: Tube bores of the fit, m (2 .. 6 mm: polyurethane tubes of about 3 .. 8 mm outside
#: diameter; 4 mm was the a-priori guess).
BORES = [0.0016, 0.0018, 0.0019, 0.002, 0.0021, 0.0023, 0.0025, 0.003, 0.004, 0.006]
BORES_QUICK = [0.0018, 0.002, 0.0023, 0.003, 0.004]
#: Other setpoint step sizes at the fitted bore, m (the paper gives none).
STEPS = [0.05, 0.1, 0.2, 0.4]
STEPS_QUICK = [0.4]
#: Tube bores of the per-step-size fits (full mode only), m.
#: The grid is walked up from the narrowest bore and left once the difference is below
#: 0.3 s (the quick grid: it falls with the bore below 3 mm; measured with 50 mm steps
#: it rises again from -0.09 s at 3 mm to +0.015 s at 4 mm, far below 0.35 s).
BORES_STEPFIT = [0.0012, 0.0014, 0.0016, 0.0018, 0.002, 0.0023, 0.0026, 0.003, 0.0035, 0.004,
                 0.005, 0.006]
#: Assumed drive values changed one at a time for the bore fit (full mode), and its grid.
ASSUMPTION_CASES = {"cylinder bore 32 mm": {"cylinder.bore": 0.032},
                    "moving mass 5 kg": {"load.mass": 5.0},
                    "supply 6 bar abs": {"supply.pressure": 6e5},
                    "viscous friction 100 N s/m": {"load.viscous_friction": 100.0}}
BORES_ASSUMPTIONS = [0.0012, 0.0014, 0.0016, 0.0018, 0.002, 0.0023, 0.0026, 0.003, 0.0035]
#: PID design rules (see design_pid) and the back-off per failed validation.
GAIN_MARGIN = 3.0
#: Ti = (specified settling time) / TI_SETTLING: an offset decays as exp(-t/Ti), to
#: e^-4 = 1.8 % (inside the 2 % band) within it. Measured (quick): Ti = 10/K0 = 1.55 s
#: leaves 1.6 mm of a 3 mm offset at the hold ends.
TI_SETTLING = 4.0
#: Integral separation band = BAND_FLOORS x the spec's 1 mm band floor: it removes rest
#: errors that fail the 1 mm spec (null offsets up to kp x 2 mm = 0.02 V) while the error
#: area collected on a >= 100 mm step stays small. Measured (quick, Ti = 0.375 s): 2 mm
#: and 3 mm pass on both lines (hold-end errors 0.41, 0.65 mm); no band fails.
BAND_FLOORS = 2.0
#: Valve null offset of the demonstration, in band floors: the zero-flow command is
#: NULL_OFFSET x kp x (1 mm) above the controller's centre (ASSUMED), so a PD loop rests
#: 1.5 mm short (fails the 1 mm spec) and the error lies inside the integral's 2 mm band.
NULL_OFFSET = 1.5
BACKOFF, TRIES = 0.8, 5
#: Transport delay: +- 5 ms (the lumped line's wave front is smeared over a few
#: segments of 1 .. 1.5 ms transit each).
DELAY_TOL = 5e-3


def valve_from_cv(cv: float, x_t: float) -> tuple[float, float, float]:
    """ISO 6358 (C m^3/(s Pa), b, largest shape difference) of eq. (2)'s valve.

    Eq. (2) is the ISA/IEC 60534 gas law Q = N Cv p1 Y sqrt(x/T1) times the standard
    density, with x = 1 - p2/p1; its expansion factor is Y = 1 - x/(3 X_T) (as printed,
    1 - x/X_T, the flow would vanish at x = X_T instead of choking there). Choked flow
    at x = X_T with Y = 2/3 matched to ISO 6358's C p1 rho0 sqrt(T0/T1) at T1 = T0
    gives C; b is the least-squares ISO ellipse through the law's flow shape
    (1 - x/(3 X_T)) sqrt(x / X_T) / (2/3) on x in [0, 1].
    """
    from scipy.optimize import minimize_scalar
    c = ISA_N_SI * cv * (2.0 / 3.0) * math.sqrt(x_t / T_REF) * RHO_STD / RHO_ANR
    x = np.linspace(0.0, 1.0, 2001)
    xs = np.minimum(x, x_t)
    isa = (1.0 - xs / (3.0 * x_t)) * np.sqrt(xs / x_t) / (2.0 / 3.0)

    def iso(b):
        r = 1.0 - x
        return np.where(r <= b, 1.0, np.sqrt(np.clip(1.0 - ((r - b) / (1.0 - b)) ** 2, 0.0, None)))
    b = float(minimize_scalar(lambda b: float(np.sum((iso(b) - isa) ** 2)), bounds=(0.0, 0.9),
                              method="bounded", options={"xatol": 1e-6}).x)
    return c, b, float(np.abs(iso(b) - isa).max())


def plants(quick: bool, diameter: float | None = None,
           changes: dict | None = None) -> dict[float, Plant]:
    """The drive with 1 m and 10 m lines (optionally another tube bore, m, and other
    plant parameters ``changes``)."""
    base = Plant.from_toml(PLANT)
    if changes:
        base = base.with_params(**changes)
    seg = SEGMENTS_QUICK if quick else SEGMENTS
    out = {}
    for L in PAPER["lengths"][0]:
        ch = {"lines.length": L, "lines.segments": seg[L]}
        if diameter is not None:
            ch["lines.diameter"] = diameter
        out[L] = base.with_params(**ch)
    return out


def line_step(plant: Plant) -> dict:
    """Valve step 5 -> 8 V at t = 10 ms, piston at rest at mid-stroke, 0.1 ms samples.

    Returns t (s), p_a, p_b (Pa), the mass flows into chamber a and out of chamber b
    at the line ends (kg/s), the delay (s) until p_a has risen DELAY_THRESHOLD, the
    peak rate of rise of p_a (Pa/s) and the peak flow into chamber a (kg/s): eq. (4)
    attenuates the mass flow.
    """
    t = np.arange(0.0, 0.12 + 1e-12, 1e-4)
    u = np.where(t >= 0.01, 8.0, 5.0)
    tr = simulate.open_loop(plant, t, u, x0=0.25, progress=False)
    p_a, p_b = np.asarray(tr["p_a"]), np.asarray(tr["p_b"])
    k = int(np.argmax(p_a - p_a[0] > DELAY_THRESHOLD))
    rate = np.gradient(p_a, t)
    last = plant.segments - 1                     # the segment that ends in the chamber
    q_a = np.asarray(tr[f"line_a_q{last}"])       # kg/s into chamber a
    q_b = -np.asarray(tr[f"line_b_q{last}"])      # kg/s out of chamber b
    return {"t": t, "p_a": p_a, "p_b": p_b, "q_a": q_a, "q_b": q_b,
            "delay": float(t[k] - 0.01), "peak_rate": float(rate.max()),
            "peak_flow": float(q_a.max()), "x": np.asarray(tr["x"]), "p_rest": float(p_a[0])}


def eq4_attenuation(diameter: float, extra_length: float, pressure: float) -> float:
    """Eq. (4)'s factor exp(-R_r L / (2 rho a_s)) for ``extra_length`` m more line:
    R_r = 32 mu / d^2 (Hagen-Poiseuille resistance per unit length of the velocity,
    Pa s/m^2), rho = p / (R T) at ``pressure`` Pa and T_REF, a_s = A_SOUND."""
    r_r = 32.0 * AIR_VISCOSITY / diameter ** 2
    rho = pressure / (R_AIR * T_REF)
    return float(math.exp(-r_r * extra_length / (2.0 * rho * A_SOUND)))


@dataclass(frozen=True)
class BandedPID:
    """:func:`workbench.controllers.pd.pid_law` (integral held while saturated) with the
    integral also held while |e| > integral_band (m): integral separation. A no-load
    integrating drive rests at the valve's null, so the integral must end each step
    where it began and the error area it collects comes back as overshoot; collected
    only inside the band, that area is small. Not a PID subclass on purpose: code that
    re-runs a PID's gains (compiled loop, diagnosis) must refuse it, not drop the band.
    """

    kp: float
    sample_time: float
    kd: float = 0.0
    ki: float = 0.0
    u_center: float = 0.0
    u_min: float = float("-inf")
    u_max: float = float("inf")
    integral_band: float = float("inf")

    kind = "pid"

    def reset(self):
        return (None, 0.0)

    def update(self, state, r: float, y: dict) -> tuple[tuple, float]:
        e_prev, held = state
        e = r - y["x"]
        u, integ = pid_law(e, e if e_prev is None else e_prev, held, self.kp, self.kd,
                           self.ki, self.sample_time, self.u_center, self.u_min, self.u_max)
        if abs(e) > self.integral_band:
            u, integ = u - self.ki * (integ - held), held
        return (e, integ), u


def design_pid(plant1: Plant, spec: validate.Specification) -> tuple:
    """(PID, the same without integral, design figures) from the 1 m drive's exact
    tangent model at mid-stroke (the paper tunes once and swaps the lines: 'identical
    conditions'): K0 = (exact sampled-data P limit) / GAIN_MARGIN, kp = K0 / Kv;
    Td = 1/w0 (derivative zero at the air spring's natural frequency, phase lead at the
    lightly damped mode); Ti = spec.max_settling_time / TI_SETTLING; integral band
    BAND_FLOORS x spec.band_floor (:class:`BandedPID`)."""
    red = linearize.reduced_position_model(linearize.tangent(plant1, x=0.25))
    T = float(plant1.params["controller.sample_time"])
    lim = stability.limits_from_plant(plant1, 0.25, sample_time=T, k0=1.0)
    k0 = lim.sampled / GAIN_MARGIN
    kp = k0 / red.kv
    prm = plant1.params
    pd = controllers.PID(kp=kp, kd=kp / red.w0, sample_time=T,
                         u_center=prm["valve.command_center"], u_min=prm["valve.command_min"],
                         u_max=prm["valve.command_max"])
    ti = spec.max_settling_time / TI_SETTLING
    pid = BandedPID(kp=kp, kd=kp / red.w0, ki=kp / ti, sample_time=T,
                    u_center=pd.u_center, u_min=pd.u_min, u_max=pd.u_max,
                    integral_band=BAND_FLOORS * spec.band_floor)
    return pid, pd, {"kv": red.kv, "w0": red.w0, "zeta": red.zeta, "k0": k0, "ti": ti,
                     "limit": lim.sampled, "fit_error": red.fit_error}


def staircase(quick: bool, step: float = STEP) -> references.Reference:
    """The paper's input: uniform setpoint steps up the stroke and back (quick: three
    steps, full: five), from 0.1 m."""
    n_up = 2 if quick else 3
    levels = [0.1 + i * step for i in range(n_up + 1)]
    levels += levels[-2:-2 - (1 if quick else 2):-1]
    return references.steps(levels, hold=HOLD)


def single_step(step: float) -> references.Reference:
    """One setpoint step of ``step`` m up from 50 mm and back, held 4 s (a 400 mm step
    through the narrow 10 m line takes longer than the staircase's hold)."""
    return references.steps([0.05, 0.05 + step, 0.05], hold=4.0)


def scaled(pid: controllers.PID, f: float) -> controllers.PID:
    """The PID with every gain times f (same zero and integral time)."""
    return replace(pid, kp=pid.kp * f, kd=pid.kd * f, ki=pid.ki * f)


def validate_both(pls: dict, pid0, ref, spec) -> tuple[controllers.PID, dict, list]:
    """Validate on both drives; lower all gains by BACKOFF while either fails."""
    tries = []
    for i in range(TRIES):
        pid = scaled(pid0, BACKOFF ** i)
        vals = {L: validate.validate(pl, pid, spec=spec, reference=ref, progress=False,
                                     label=f"PID, {L:g} m lines") for L, pl in pls.items()}
        tries.append((pid, {L: v.passed for L, v in vals.items()}))
        print(f"    kp = {pid.kp:.2f} V/m: " + ", ".join(
            f"{L:g} m {'pass' if v.passed else 'fail: ' + ', '.join(c.name for c in v.failed)}"
            for L, v in vals.items()))
        if all(v.passed for v in vals.values()):
            break
    return pid, vals, tries


def integral_comparison(plant10: Plant, pid, pd, ref, spec) -> dict:
    """What the integral is for, measured on the 10 m drive: the PID, the PD (ki = 0),
    and the PID without its separation band, on the nominal valve; the PD and the PID
    on a valve whose zero-flow command is :func:`null_offset` V above the controller's
    centre.
    Returns {name: Validation}."""
    off = plant10.with_params(**{"valve.command_center":
                                 float(plant10.params["valve.command_center"])
                                 + null_offset(pd, spec)})
    runs = {"PID": (plant10, pid), "PD (ki = 0)": (plant10, pd),
            "PID without band": (plant10, replace(pid, integral_band=float("inf"))),
            "PD, valve null offset": (off, pd), "PID, valve null offset": (off, pid)}
    out = {}
    for name, (pl, c) in runs.items():
        out[name] = validate.validate(pl, c, spec=spec, reference=ref, progress=False, label=name)
        print(f"    {name}: " + ("pass" if out[name].passed else
                                 "fail: " + ", ".join(x.name for x in out[name].failed)))
    return out


def null_offset(pd, spec) -> float:
    """The demonstration's valve null offset, V: NULL_OFFSET band floors times kp."""
    return NULL_OFFSET * spec.band_floor * pd.kp


def step_times(v) -> tuple[np.ndarray, np.ndarray]:
    """Per setpoint step of a validation: time (s) until the position has covered half
    the step, and the settling time (s) into the validation's band."""
    t, x = v.trajectory.time, np.asarray(v.trajectory["x"])
    half, settle = [], []
    for s in v.segments:
        if s.segment.kind != "step":
            continue
        sel = t >= s.segment.start
        frac = (x[sel] - s.segment.r_start) / (s.segment.r_end - s.segment.r_start)
        half.append(float(t[sel][np.argmax(frac >= 0.5)] - s.segment.start)
                    if np.any(frac >= 0.5) else np.inf)
        settle.append(s.settling_time)
    return np.array(half), np.array(settle)



def settle_times(v, band: float) -> np.ndarray:
    """Per setpoint step of a validation: the time (s) after the step from which the
    position stays within +- band x |step| of the new setpoint until the hold ends
    (inf if it is outside at the hold's end)."""
    t, x = v.trajectory.time, np.asarray(v.trajectory["x"])
    out = []
    for s in v.segments:
        if s.segment.kind != "step":
            continue
        sel = (t >= s.segment.start) & (t < s.segment.end)
        tt, xx = t[sel], x[sel]
        outside = np.abs(xx - s.segment.r_end) > band * abs(s.segment.r_end - s.segment.r_start)
        if outside[-1]:
            out.append(np.inf)
        else:
            last = np.flatnonzero(outside)
            out.append(float(tt[last[-1] + 1] - s.segment.start) if last.size else 0.0)
    return np.array(out)


def transient_difference(vals: dict) -> dict:
    """10 m minus 1 m, mean over the setpoint steps, s: ``dt`` the transition time
    (settling into +- TRANSIENT_BAND of the step: the paper's quantity), ``dt2`` the
    same into 2 %, ``shift`` the half-way time (a 'signal delay' reading)."""
    h1, _ = step_times(vals[1.0])
    h10, _ = step_times(vals[10.0])
    s1, s10 = settle_times(vals[1.0], TRANSIENT_BAND), settle_times(vals[10.0], TRANSIENT_BAND)
    t1, t10 = settle_times(vals[1.0], 0.02), settle_times(vals[10.0], 0.02)
    return {"dt": float(np.mean(s10 - s1)), "dt2": float(np.mean(t10 - t1)),
            "shift": float(np.mean(h10 - h1)), "half_1m": h1, "half_10m": h10,
            "settle_1m": s1, "settle_10m": s10}


def experiment(pls: dict, ref, spec, backoff: bool = False) -> dict:
    """The paper's experiment on one setup: the PID designed on the 1 m drive, run on
    both, validated on both (``backoff``: lower its gains by BACKOFF while either
    fails). Returns pid, pd, design info, validations, transient differences."""
    pid0, pd0, info = design_pid(pls[1.0], spec)
    if backoff:
        pid, vals, tries = validate_both(pls, pid0, ref, spec)
    else:
        pid, tries = pid0, []
        vals = {L: validate.validate(pl, pid, spec=spec, reference=ref, progress=False,
                                     label=f"PID, {L:g} m lines") for L, pl in pls.items()}
    pd = scaled(pd0, pid.kp / pid0.kp)
    return {"pid": pid, "pd": pd, "info": info, "vals": vals, "tries": tries,
            "td": transient_difference(vals)}


def _crossing(d: np.ndarray, y: np.ndarray, target: float) -> float | None:
    """Bore (m) where y (falling with d, inf allowed) crosses ``target``: linear
    interpolation between the grid points that bracket it; None if none do."""
    for i in range(len(d) - 1):
        if y[i] >= target > y[i + 1] and np.isfinite(y[i]):
            return float(d[i] + (y[i] - target) / (y[i] - y[i + 1]) * (d[i + 1] - d[i]))
    return None


def fit_bore(quick: bool, ref, spec, bores=None, lines: bool = True,
             changes: dict | None = None) -> dict:
    """The paper's experiment on ``ref`` over a grid of tube bores (m; default BORES);
    the bore whose transition-time difference is the paper's 0.4 s (and the interval
    for 0.35 .. 0.45 s), by linear interpolation on the grid. ``lines``: also the valve
    step's delay and attenuation per bore; ``changes``: other assumed plant values.
    Returns grid rows and d, lo, hi (m or None)."""
    rows = []
    for d in bores if bores is not None else (BORES_QUICK if quick else BORES):
        pls = plants(quick, diameter=d, changes=changes)
        ex = experiment(pls, ref, spec)
        rows.append({"diameter": d, "dt": ex["td"]["dt"], "dt2": ex["td"]["dt2"],
                     "shift": ex["td"]["shift"], "kp": ex["pid"].kp,
                     "passed": all(v.passed for v in ex["vals"].values())})
        if lines:
            st = {L: line_step(pl) for L, pl in pls.items()}
            rows[-1].update(delay=st[10.0]["delay"] - st[1.0]["delay"],
                            flow_ratio=st[10.0]["peak_flow"] / st[1.0]["peak_flow"],
                            eq4=eq4_attenuation(d, 9.0, st[10.0]["p_rest"]),
                            p_rest=st[10.0]["p_rest"])
        print(f"    tube bore {d * 1e3:.2f} mm: transition time 10 m - 1 m "
              f"{rows[-1]['dt']:.3f} s, half-way shift {rows[-1]['shift']:.3f} s", flush=True)
        if not lines and rows[-1]["dt"] < DT_INTERVAL[0] - 0.05:
            break                       # past the interval: wider tubes only settle sooner
    dd = np.array([r["diameter"] for r in rows])
    y = np.array([r["dt"] for r in rows])
    other = {f"d_{k}": _crossing(dd, np.array([r[k] for r in rows]), PAPER["dt"][0])
             for k in ("dt2", "shift")}        # the same 0.4 s read as 2 % settling / half-way
    return {"grid": rows, "d": _crossing(dd, y, PAPER["dt"][0]),
            "lo": _crossing(dd, y, DT_INTERVAL[1]), "hi": _crossing(dd, y, DT_INTERVAL[0]),
            **other}


def step_sensitivity(quick: bool, diameter: float, spec) -> list[dict]:
    """The experiment at the fitted bore on single setpoint steps of other sizes and
    (full mode) the bore that gives the paper's 0.4 s with each step size."""
    rows = []
    pls = plants(quick, diameter=diameter)
    for s in (STEPS_QUICK if quick else STEPS):
        ex = experiment(pls, single_step(s), spec)
        rows.append({"step": s, "dt": ex["td"]["dt"], "dt2": ex["td"]["dt2"],
                     "shift": ex["td"]["shift"],
                     "passed": all(v.passed for v in ex["vals"].values())})
        print(f"    steps of {s * 1e3:g} mm: transition time 10 m - 1 m {rows[-1]['dt']:.3f} s")
        if not quick:
            f = fit_bore(quick, single_step(s), spec, bores=BORES_STEPFIT, lines=False)
            rows[-1].update(fit_d=f["d"], fit_lo=f["lo"], fit_hi=f["hi"])
    return rows


def assumption_sensitivity(quick: bool, ref, spec) -> list[dict]:
    """Full mode: the bore fit again with one assumed drive value changed at a time
    (ASSUMPTION_CASES): how far the estimate rests on the assumptions."""
    rows = []
    for name, ch in ({} if quick else ASSUMPTION_CASES).items():
        print(f"    {name}:")
        f = fit_bore(quick, ref, spec, bores=BORES_ASSUMPTIONS, lines=False, changes=ch)
        rows.append({"case": name, "changes": ch, "d": f["d"], "lo": f["lo"], "hi": f["hi"],
                     "dt": [g["dt"] for g in f["grid"]]})
    return rows


def main(argv=None) -> int:
    args, out = rp.design_arguments(__doc__.splitlines()[0], ROOT / "reports" / "paper_001",
                                    "coarser 10 m line, three steps, fewer bores and step sizes",
                                    argv)
    t_start = time.perf_counter()
    return rp.run_design(TITLE, out, PLANT, lambda done: _design(args, out, done, t_start))


def _design(args, out: Path, done: list, t_start: float) -> int:
    import paper_001_report as rep
    quick = args.quick
    spec = validate.Specification()
    ref = staircase(quick)
    with rp.step("valve from the paper's Cv"):
        valve = valve_from_cv(PAPER["cv"][0], PAPER["x_t"][0])
    with rp.step("tube bore from the paper's 0.4 s"):
        fit = fit_bore(quick, ref, spec)
    d = fit["d"] if fit["d"] is not None else float(Plant.from_toml(PLANT).params["lines.diameter"])
    pls = plants(quick, diameter=d)
    done.append(rep.config_section(pls, valve, fit))
    with rp.step("line delay and attenuation"):
        steps = {L: line_step(pl) for L, pl in pls.items()}
        done.append(rep.lines_section(steps, d))
    with rp.step("the experiment at the fitted bore: PID design and validation"):
        ex = experiment(pls, ref, spec, backoff=True)
        for L, v in ex["vals"].items():
            v.trajectory.to_csv(out / f"validation_{L:g}m.csv")
        compare = integral_comparison(pls[10.0], ex["pid"], ex["pd"], ref, spec)
        done.append(rep.pid_section(ex, compare))
    with rp.step("position transients, step sizes and assumptions"):
        sizes = step_sensitivity(quick, d, spec)
        fit["assumptions"] = assumption_sensitivity(quick, ref, spec)
        done.append(rep.transient_section(ex["td"], fit, sizes, d))
    with rp.step("write report"):
        results = rep.results(steps, ex, fit, d)
        done.insert(0, rep.results_section(results))
        done.append(rep.disagreement_section(results, steps, ex["td"], fit, sizes))
        return rep.finish(out, results, steps, ex, fit, sizes, valve, compare, done, t_start,
                          quick)


if __name__ == "__main__":
    sys.exit(main())
