"""Smooth trajectories, deadband inverse, axis limits and controllers.design (issue 14)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from workbench import Plant, simulate
from workbench.controllers.compensation import Compensated, DeadbandInverse, hold_limit_cycle
from workbench.controllers.design import VelocityPID, axis_limits, design
from workbench.controllers.sensors import RigSensors
from workbench.errors import InputError
from workbench.references import smooth, steps, validation_profile

PLANTS = Path(__file__).resolve().parents[1] / "designs" / "plants"


@pytest.fixture(scope="module")
def rig():
    return Plant.from_toml(PLANTS / "rig25_mpye.toml")


def test_smoothed_step_is_a_min_jerk_move_within_the_limits():
    D, vmax, amax, jmax = 0.1, 1.0, 20.0, 1000.0
    tr = smooth(steps([0.2, 0.2 + D], hold=1.0), vmax, amax, jmax)
    # the shortest min-jerk duration: the peaks 1.875 D/T, 5.7735 D/T^2, 60 D/T^3
    tf = max(1.875 * D / vmax, math.sqrt(5.7735 * D / amax), (60 * D / jmax) ** (1 / 3))
    t = np.arange(0.0, 2.0, 1e-4)
    r, v, a, j = tr.derivatives(t)
    assert np.max(np.abs(v)) <= vmax * (1 + 1e-3)
    assert np.max(np.abs(a)) <= amax * (1 + 1e-3)
    assert np.max(np.abs(j)) <= jmax * (1 + 1e-6)
    # starts at the jump (causal), reaches the level after tf, untouched elsewhere
    assert np.all(r[t < 1.0] == 0.2) and np.allclose(r[t >= 1.0 + tf + 1e-3], 0.2 + D)
    s = (1.05 - 1.0) / tf
    assert float(tr(1.05)) == pytest.approx(0.2 + D * (10 * s**3 - 15 * s**4 + 6 * s**5), abs=1e-7)
    # derivatives agree with central differences of the position, which is tabulated
    # every 0.5 ms and interpolated linearly: chord slopes differ by up to a_max h / 2
    dv = np.gradient(r, t)
    assert np.max(np.abs(dv - v)[10:-10]) < amax * 5e-4 / 2 * 1.01


def test_smoothed_profile_keeps_ramps_and_the_sine():
    ref = validation_profile(0.5, sine=True)
    tr = smooth(ref, 1.0, 20.0, 2000.0)
    (_, a, b), = ref.sections
    t = np.linspace(a, b, 6001)
    # corners blended over 10 ms, zero phase: on the sine the error is A w^2 tau^2/56
    assert np.max(np.abs(tr(t) - ref(t))) < 2e-6
    # mid-ramp (far from corners) position and speed are the ramp's
    r, v, _, _ = tr.derivatives(12.0)
    assert float(r) == pytest.approx(float(ref(12.0)), abs=1e-9) and float(v) == pytest.approx(0.1)
    with pytest.raises(InputError):
        smooth(ref, 0.0, 1.0, 1.0)


def test_deadband_inverse_undoes_the_overlap():
    inv = DeadbandInverse(center=5.0, span=5.0, deadband=0.1, offset=0.2, u_min=0.0, u_max=10.0)
    # physics.md: opening = max(|s| - d, 0) / (1 - d), s about the shifted centre
    for s_want in (-0.8, -0.3, -0.05, 0.02, 0.5, 0.9):      # 1.0 + offset clips
        u = inv(5.0 + 5.0 * s_want)
        s = (u - 5.2) / 5.0
        opening = math.copysign(max(abs(s) - 0.1, 0.0) / 0.9, s)
        if abs(s_want) >= inv.width * 0.1:
            assert opening == pytest.approx(s_want, abs=1e-3)   # 1e-6 of span off the null
    assert inv(5.0) == pytest.approx(5.2, abs=1e-5)            # closed: the true null
    with pytest.raises(InputError):
        DeadbandInverse(center=5.0, span=5.0, deadband=1.5)


def test_axis_limits_from_valve_flow_and_pressures(rig):
    lim = axis_limits(rig, margin=1.0)
    A = math.pi / 4 * 0.025 ** 2
    q = 6.25e-8 * 6e5 * 1.185                 # choked flow, kg/s (T = T0)
    assert lim.speed == pytest.approx(q * 287 * 293.15 / (3.506625e5 * A), rel=1e-9)
    assert lim.acceleration == pytest.approx((6e5 - 101325) * A / 1.2, rel=1e-9)
    assert lim.jerk == pytest.approx(1.2 * 287 * 293.15 * q * A / (A * 0.25 + 5e-6) / 1.2, rel=1e-9)
    assert axis_limits(rig).speed == pytest.approx(0.3 * lim.speed)


@pytest.mark.parametrize("kind", ["pid", "fl", "nmpc"])
def test_designed_controllers_need_no_velocity(rig, kind):
    plant = rig.with_params(**{"friction.coulomb": 10.0, "friction.static": 15.0,
                               "friction.stribeck_velocity": 0.01, "valve.deadband": 0.02})
    ctrl = design(plant, kind, jit=False)     # CasADi's VM: no compile in a fresh CI
    assert ctrl.needs == ("x", "p_a", "p_b")
    assert isinstance(ctrl.inner, Compensated) and ctrl.inner.lock_band > 0
    # dry friction in the plant file: the precision hold, its band one quantum wide
    assert ctrl.inner.hold is not None and ctrl.inner.hold.quantum == 2 * ctrl.inner.lock_band
    ref = steps([0.25, 0.28], hold=1.5)
    run = simulate.closed_loop(plant, RigSensors(ctrl, stroke=plant.stroke), ref, x0=0.25)
    # a 30 mm step reached within 2 mm (every law, 10 ms, friction and deadband)
    assert abs(run["x"][-1] - 0.28) < 2e-3


def test_hold_evidence_counts_command_activity():
    t = np.arange(0.0, 2.0, 0.01)
    x = 0.25 + 1e-5 * np.sin(20 * t)
    u = np.where(np.arange(len(t)) % 2 == 0, 5.0, 5.1)
    ev = hold_limit_cycle(t, x, u, 1.0, 2.0, 1e-4)
    assert ev["command_changes"] == 99 and ev["peak_to_peak"] == pytest.approx(2e-5, rel=1e-2)


def test_design_rejects_unknown_kind(rig):
    with pytest.raises(InputError, match="kind"):
        design(rig, "lqr")


def _sine_reference(c=0.25, periods=2):
    from workbench import references
    pts = ([(0, c - 0.06), (0.5, c - 0.06)] + references.sine_points(0.5, c, 0.06, 0.5, periods)[1:]
           + [(0.5 + 2 * periods + 0.5, c - 0.06)])
    p = references.profile(pts)
    return references.Reference(p.times, p.values, sections=(("sine", 0.5, 0.5 + 2 * periods),))


def _sine_error(run, ref, a, b):
    sel = (run.time > a) & (run.time < b)
    return float(np.max(np.abs(run["x"] - ref(run.time))[sel]))


def test_fl_with_preview_tracks_the_sine_without_the_reference_model_lag(rig):
    # nominal 25 mm rig, 10 ms: the 60 mm 0.5 Hz sine. Through the reference model
    # H = 1/(1 + s/20)^3 the error is A |1 - H(j pi)| = 27 mm (analytic; the loop adds
    # a little lag of its own: 10 %); fed forward it is the loop's own error
    from dataclasses import replace
    from workbench.controllers.feedback_linearizing import feedback_linearizing
    ref = _sine_reference()
    lim = axis_limits(rig)
    fl = feedback_linearizing(rig, bandwidth=20.0, sample_time=0.01, integral=False)
    lagging = _sine_error(simulate.closed_loop(rig, fl, ref, x0=0.19), ref, 0.5, 4.5)
    fed = replace(fl, preview=smooth(ref, lim.speed, lim.acceleration, lim.jerk))
    tracked = _sine_error(simulate.closed_loop(rig, fed, ref, x0=0.19), ref, 0.5, 4.5)
    H = 1.0 / (1.0 + 1j * math.pi / 20.0) ** 3
    assert lagging == pytest.approx(0.06 * abs(1.0 - H), rel=0.1)
    assert tracked < 1e-3 and tracked < lagging / 20


def test_nmpc_with_preview_beats_rate_extrapolation_on_the_sine(rig):
    from workbench.controllers.mpc import NMPC
    ref = _sine_reference(periods=1)
    online = NMPC.for_plant(rig, sample_time=0.01, jit=False)
    ahead = online.with_settings(preview=ref)
    e_online = _sine_error(simulate.closed_loop(rig, online, ref, x0=0.19), ref, 0.5, 2.5)
    e_ahead = _sine_error(simulate.closed_loop(rig, ahead, ref, x0=0.19), ref, 0.5, 2.5)
    assert e_ahead < 0.5 * e_online, (e_ahead, e_online)


def test_workbench_design_writes_the_whole_result_set(tmp_path):
    import json
    from workbench.cli import main
    out = tmp_path / "pid"
    plant = PLANTS / "rig25_mpye.toml"
    rc = main(["design", str(plant), "--kind", "pid", "--out", str(out), "--quick",
               "--pressure-noise", "0"])
    assert rc == 0
    assert {p.name for p in out.iterdir()} == {"report.html", "report.pdf", "design.json",
                                               "validation.csv"}
    d = json.loads((out / "design.json").read_text())
    assert d["needs"] == ["x", "p_a", "p_b"] and d["validation"]["spec"]["name"] == "precision"
    assert any(c["name"] == "sine tracking error" for c in d["validation"]["checks"])
    # a file where the folder should be: refused before any work, nothing written
    bad = tmp_path / "file"
    bad.write_text("x")
    assert main(["design", str(plant), "--out", str(bad), "--quick"]) == 2
    assert bad.read_text() == "x"


# ------------------------------------------------------------------ friction feedforward
def test_friction_model_from_the_plant_file():
    from workbench.controllers.compensation import FrictionModel
    rig = Plant.from_toml(PLANTS / "rigs" / "precision_rig25.toml")
    fm = FrictionModel.from_plant(rig)
    prm = rig.params
    assert (fm.coulomb, fm.static, fm.stribeck_velocity) == (
        prm["friction.coulomb"], prm["friction.static"], prm["friction.stribeck_velocity"])
    # far beyond the Stribeck velocity the law is Coulomb's, odd in v
    assert fm(0.2) == pytest.approx(prm["friction.coulomb"], rel=1e-9)
    assert fm(-0.2) == pytest.approx(-prm["friction.coulomb"], rel=1e-9)
    assert FrictionModel.from_plant(Plant.from_toml(PLANTS / "rig25_mpye.toml")) is None
    with pytest.raises(InputError, match="stribeck_velocity"):
        FrictionModel(10.0, 15.0, 0.0)


def test_fl_friction_feedforward_at_a_reversal_decays_with_the_handover_lag(rig):
    # the part of the model friction the feedback has not taken over: zero while the
    # reference's velocity is steady; at a reversal the full jump F(-v) - F(v) = -2 F_c
    # (exp(-(v/v_s)^2) = e^-100 at 0.1 m/s), then decaying by exp(-T/lag) per sample
    # (the discrete first-order lag, exact)
    from dataclasses import replace
    from workbench.controllers.compensation import FrictionModel
    from workbench.controllers.feedback_linearizing import feedback_linearizing
    T, lag = 0.002, 0.04
    fl = replace(feedback_linearizing(rig, bandwidth=25.0, sample_time=T, check=False,
                                      integral=False),
                 friction=FrictionModel(10.0, 15.0, 0.01), friction_lag=lag)
    f_lag, fed, got = None, None, []
    for v_r in [0.1] * 5 + [-0.1] * 4:
        ff, f_lag, fed = fl._friction_feedforward(f_lag, v_r, fed)
        got.append(ff)
    want = [0.0] * 5 + [-20.0 * math.exp(-k * T / lag) for k in range(4)]
    assert np.allclose(got, want, rtol=0, atol=1e-9)
    # a reference coming to rest keeps the last direction's friction: no feedforward
    ff, f_lag, fed = fl._friction_feedforward(f_lag, 0.0, fed)
    assert fed == pytest.approx(-10.0, rel=1e-9)
    with pytest.raises(InputError, match="friction_lag"):
        replace(fl, friction_lag=-1.0)


def _precision_sine():
    """The precision rig's plant file and one period of its 60 mm 0.5 Hz sine, held
    0.3 s before and 0.5 s after (the sine starts from rest, the piston stuck)."""
    from workbench import references
    plant = Plant.from_toml(PLANTS / "rigs" / "precision_rig25.toml")
    c = 0.25
    pts = [(0.0, c - 0.06), (0.3, c - 0.06)] + references.sine_points(0.3, c, 0.06, 0.5, 1)[1:]
    pts += [(2.8, c - 0.06)]
    p = references.profile(pts)
    return plant, references.Reference(p.times, p.values, sections=(("sine", 0.3, 2.3),))


def _sine_with_and_without_friction(kind: str, monkeypatch) -> tuple[float, float]:
    """Worst error (m) on :func:`_precision_sine` of the ``kind`` design with its
    friction terms, and with the plant file's friction hidden from the design."""
    from workbench.controllers import compensation
    from workbench.controllers.evaluation import evaluate_design
    plant, ref = _precision_sine()
    fed = evaluate_design(plant, kind, reference=ref, jit=False).validation.metrics.sine_error_max
    monkeypatch.setattr(compensation.FrictionModel, "from_plant", classmethod(lambda cls, pl: None))
    bare = evaluate_design(plant, kind, reference=ref, jit=False).validation.metrics.sine_error_max
    return fed, bare


def test_fl_friction_feedforward_reduces_the_sine_error_on_the_precision_rig(monkeypatch):
    # the precision rig (Karnopp 15/25 N, 2 % overlap, 1 m lines, 2 ms, 12-bit x, noisy
    # p, no v): without the feedforward the piston sticks 150-200 ms at each start and
    # reversal of the 60 mm 0.5 Hz sine (FL's force builds at its error bandwidth).
    # Measured worst error with / without (seed 0 unless said): this sine alone
    # 10.2 / 13.3 mm; test profile of test_precision_positioning 11.3 / 13.7 (seed 1:
    # 9.9 / 13.8); precision profile 9.1 / 13.3 (seed 1: 13.4 / 13.2, no gain). So
    # not a cure: required here a gain beyond 15 % on this case, not a fixed figure.
    # With the break-away (feedback_linearizing.breakaway, branch h14h): this sine
    # 3.3 / 13.3 mm, the precision profile's 3.8-4.0 mm (seeds 0-1); required now at
    # most half (the margin for other seeds). Session 10 (h14l: 40 rad/s, the lines'
    # delay in the bandwidth rule: 1.82 mm; with the break-away probe: 1.45 mm)
    fed, bare = _sine_with_and_without_friction("fl", monkeypatch)
    assert fed < 0.5 * bare, (fed, bare)
    # and below the 3.3 mm of session 9 with a margin for other machines' noise
    assert fed < 2.5e-3, fed


def test_report_says_how_each_law_uses_the_friction_model():
    from workbench.controllers.evaluation import _friction_text
    plant = Plant.from_toml(PLANTS / "rigs" / "precision_rig25.toml")
    said = {k: _friction_text(design(plant, k, jit=False).inner.inner) for k in ("pid", "fl", "nmpc")}
    assert said["fl"].startswith("plant file's friction (Coulomb 15 N, static 25 N)")
    assert said["nmpc"] == "in the prediction model (smooth form)"
    assert said["pid"].startswith("plant file's friction (Coulomb 15 N, static 25 N): its rate")


def test_pid_integral_only_on_a_still_reference_near_its_target_and_clamped():
    # the 11 mm steady-state error of issue 14's PID: its integral wound up over a
    # 250 mm step (-0.2 V) and held the piston short with the valve in the deadband
    from workbench.controllers.design import VelocityPID
    pid = VelocityPID(kp=4.0, kd=0.1, ki=10.0, sample_time=0.002, u_center=5.0, u_min=0.0,
                      u_max=10.0, integral_band=6e-5, integral_zone=0.025, integral_limit=0.1)
    st = pid.reset()
    for k in range(50):                              # a moving reference: no integration
        st, _ = pid.update(st, 0.25 - 0.005 * k, {"x": 0.25, "v": 0.0})
    assert st[0] == 0.0
    for _ in range(50):                              # still, 30 mm off: beyond the zone
        st, _ = pid.update(st, 0.28, {"x": 0.25, "v": 0.0})
    assert st[0] == 0.0
    for _ in range(6):                # still (after its first sample), 10 mm off: e T each
        st, u = pid.update(st, 0.26, {"x": 0.25, "v": 0.0})
    assert st[0] == pytest.approx(5 * 0.01 * 0.002, rel=1e-12)
    assert u == pytest.approx(5.0 + 4.0 * 0.01 + 10.0 * st[0], abs=1e-12)
    for _ in range(5000):                            # clamped at integral_limit / ki
        st, u = pid.update(st, 0.26, {"x": 0.25, "v": 0.0})
    assert 10.0 * st[0] == pytest.approx(0.1, rel=1e-12)


def test_the_hold_takes_over_where_the_pid_cannot_move_a_stuck_piston():
    # the deadband inverse's straight piece leaves a residual overlap of width x d of
    # the span (0.1 x 2 % x 5 V = 10 mV): a P law with kp V/m opens the valve only
    # beyond 10 mV / kp; the hold must reach at least that far (on the precision rig
    # the PID stuck 2.1-2.5 mm off, beyond a 2 mm hold range)
    plant = Plant.from_toml(PLANTS / "rigs" / "precision_rig25.toml")
    pid = design(plant, "pid", jit=False)
    zone = 0.1 * 0.02 * 5.0 / pid.inner.inner.kp
    assert zone > 2e-3 and pid.inner.hold.range == pytest.approx(2 * zone, rel=1e-12)
    # FL: the break-away jump 2 (F_s - F_c) / k on the closed chambers' gas spring at
    # mid-stroke, k = n p_m (A^2 / V_a + A^2 / V_b), each volume half the stroke's,
    # its dead volume and its 1 m line of 4 mm bore (hand numbers, precision rig)
    A = math.pi / 4 * 0.025 ** 2
    V = A * 0.25 + 5e-6 + math.pi / 4 * 0.004 ** 2 * 1.0
    k = 1.2 * 0.5 * (6e5 + 101325.0) * 2 * A * A / V
    assert design(plant, "fl", jit=False).inner.hold.range == pytest.approx(2 * 10.0 / k, rel=1e-12)


# ------------------------------------------------------------------ lines and break-away
def test_line_flow_is_the_steady_flow_of_the_line_model():
    # independent: the same friction law (laminar + Blasius) integrated along the
    # line by scipy's adaptive RK45 at tight tolerance, the flow by brentq; the
    # function under test marches 200 fixed pieces and bisects (agreement within
    # the march's discretisation, 0.1 %)
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq
    from workbench.controllers.design import line_flow
    from workbench.physics.line import pressure_drop
    L, d, T, p_in, p_out = 1.0, 0.004, 293.15, 6e5, 3.5e5

    def end(q):
        sol = solve_ivp(lambda s, p: [-float(pressure_drop(q, p[0], d, 1.0, T))], (0, L),
                        [p_in], rtol=1e-10, atol=1e-6)
        return sol.y[0, -1] - p_out

    want = brentq(end, 1e-4, 0.02, xtol=1e-12)
    assert line_flow(L, d, p_in, p_out, T) == pytest.approx(want, rel=1e-3)
    # a longer line passes less; a line passes nothing without a pressure drop
    assert line_flow(10.0, d, p_in, p_out, T) < 0.5 * want
    with pytest.raises(InputError, match="p_in > p_out"):
        line_flow(L, d, p_out, p_in, T)


def test_axis_limits_with_lines_are_limited_by_the_line_flow():
    from workbench.controllers.design import line_flow
    plant = Plant.from_toml(PLANTS / "rigs" / "precision_rig25.toml")
    lim = axis_limits(plant, margin=1.0)
    q = line_flow(1.0, 0.004, 6e5, 0.5 * (6e5 + 101325.0), 293.15)
    A = math.pi / 4 * 0.025 ** 2
    assert q < 0.3 * 6.25e-8 * 6e5 * 1.185        # the line, not the valve, limits
    assert lim.speed == pytest.approx(q * 287 * 293.15 / (3.506625e5 * A), rel=1e-9)


def test_breakaway_state_enters_stuck_and_leaves_on_a_measured_move():
    from workbench.controllers.feedback_linearizing import breakaway
    vs = 0.01
    # moving piston, or a reference slower than v_s: none
    assert breakaway(None, 0.1, 0.05, 0.2, vs) is None
    assert breakaway(None, 0.005, 0.0, 0.2, vs) is None
    brk = breakaway(None, -0.1, 0.002, 0.2, vs)
    assert brk == (-1.0, 0.2)
    # held while the position has not moved, whatever the (noisy) speed estimate says
    assert breakaway(brk, -0.1, -0.03, 0.2, vs) == brk
    assert breakaway(brk, -0.1, 0.0, 0.2 + 1.2e-4, vs) == brk     # moved the wrong way
    assert breakaway(brk, -0.1, 0.0, 0.2 - 1.2e-4, vs) is None    # broke away
    assert breakaway(brk, 0.1, 0.0, 0.2, vs) is None              # direction changed


def test_pid_break_away_and_friction_rate_cut_the_sine_error_on_the_precision_rig(monkeypatch):
    # the precision rig's 60 mm 0.5 Hz sine (12-bit x, noisy p, no v): without the
    # friction terms the PID's piston sticks at the start and each reversal while its
    # proportional term builds the force at 4 mV per mm (9.8 mm worst on the
    # precision profile, seed 0). Measured on this sine, seed 0: with / without
    # 3.2 / 10.6 mm; required: at most half (a margin for other seeds: the
    # precision profile's seeds 0-4 gave 3.3-3.4 mm with them). Session 10 (h14l:
    # the sliding law fed while the reference slows, the break-away force handed
    # back to the sliding level): 1.87 mm with them
    fed, bare = _sine_with_and_without_friction("pid", monkeypatch)
    assert fed < 0.5 * bare, (fed, bare)
    # and below the 3.2 mm of session 9 (sliding law into the reversal, break-away
    # force handed back: 1.87 mm)
    assert fed < 2.5e-3, fed


def test_fl_breaks_away_on_a_rig_with_more_friction_than_its_plant_file():
    # designed from the precision rig's file (static friction 25 N), run on a rig with
    # 1.5 x the friction (37.5 / 22.5 N) and 10 % more mass. Stuck at the sine's start
    # and reversals, a break-away that drove the force to the file's F_s stopped
    # there: precision profile --quick, seed 0, sine worst 16.7 mm, ramp 19.5 mm; with
    # the force taken beyond F_s until the piston moves 3.5 / 7.1 mm. Measured on this
    # sine: 3.2 / 3.3 mm (seeds 0 / 1); the limit 5 mm pins that class (the nominal
    # rig's own error on it is 3.3 mm), far below the 15-17 mm without. Session 10
    # (40 rad/s, break-away probe 0.3): 1.72 / 1.72 mm
    from workbench.controllers.evaluation import evaluate_design
    plant, ref = _precision_sine()
    rig = plant.with_params(**{"friction.coulomb": 22.5, "friction.static": 37.5,
                               "load.mass": 1.32})
    ev = evaluate_design(plant, "fl", reference=ref, jit=False, rig=rig)
    assert ev.validation.metrics.sine_error_max < 5e-3


def test_report_table_has_one_number_format_per_unit():
    # the precision report's validation table printed 23.1500 s, 0.9202 s and 2.358 %
    # (5 significant digits); now mm, s and bar with 3 decimals, % with 2
    from types import SimpleNamespace
    from workbench.controllers.evaluation import _check_rows
    from workbench.validate import Check
    checks = [Check("simulation", 23.15, 23.15, "s", True, bound="min"),
              Check("settling time", 0.92022, 1.5, "s", True),
              Check("overshoot", 2.35806, 2.0, "%", False),
              Check("steady-state error", 3.2353e-4, 1.220703125e-4, "m", False),
              Check("min chamber pressure", 311920.0, 81325.0, "Pa", True, bound="min"),
              Check("settling time", math.inf, 1.5, "s", False)]
    rows = _check_rows(SimpleNamespace(checks=checks))
    assert [r[1] for r in rows] == [">= 23.150", "<= 1.500", "<= 2.00", "<= 0.122", ">= 0.813",
                                    "<= 1.500"]
    assert [r[3] for r in rows] == ["23.150", "0.920", "2.36", "0.324", "3.119", "inf"]
    assert [r[2] for r in rows] == ["s", "s", "%", "mm", "bar abs", "s"]
    assert [r[4] for r in rows] == [True, True, False, False, True, False]


def test_friction_slope_is_the_derivative_of_the_law():
    # central differences at tight step (the truncation error h^2 F'''/6 is ~1e-9
    # relative at h = 1e-5 v_e) against the exact slope, across the tanh, the
    # Stribeck hump and the sliding range
    from workbench.controllers.compensation import FrictionModel
    fr = FrictionModel(15.0, 25.0, 0.012)
    v = np.array([-0.05, -0.012, -2e-3, -1e-4, 0.0, 3e-4, 1.2e-3, 0.006, 0.02, 0.3])
    h = 1e-5 * 0.1 * fr.stribeck_velocity
    fd = (fr(v + h) - fr(v - h)) / (2 * h)
    assert np.allclose(fr.slope(v), fd, rtol=1e-6, atol=1e-6)
    assert fr.slope(0.0) == pytest.approx(25.0 / (0.1 * 0.012), rel=1e-12)  # F_s / v_e


def test_fl_default_bandwidth_spends_the_sampling_phase_on_the_hold_and_the_lines():
    # lambda (T/2 + L/c) <= pi/20, c the adiabatic speed of sound (1 m at 20 degC:
    # 2.9 ms), at most 0.8 of the sampling bound pi/(10 T): precision rig (2 ms, 1 m
    # lines) 40.1 rad/s (25 before: limit cycles in its holds, 3.3-3.6 mm on the
    # sine); rig25 (10 ms, no lines) keeps the sampling rule's 25 rad/s
    import sys
    from workbench.controllers.design import design as _design  # noqa: F401
    D = sys.modules["workbench.controllers.design"]
    precision = Plant.from_toml(PLANTS / "rigs" / "precision_rig25.toml")
    c = math.sqrt(1.4 * 287.0 * 293.15)
    assert D.line_delay(precision) == pytest.approx(1.0 / c, rel=1e-3)
    want = (math.pi / 20) / (0.001 + 1.0 / c)
    assert design(precision, "fl", jit=False).inner.inner.bandwidth == pytest.approx(want, rel=1e-3)
    rig25 = Plant.from_toml(PLANTS / "rig25_mpye.toml")
    assert D.line_delay(rig25) == 0.0
    assert design(rig25, "fl", jit=False).inner.inner.bandwidth == pytest.approx(
        0.8 * math.pi / 10 / 0.01, rel=1e-9)
    # the observer's slowest pole bounds it too (a third of it)
    assert D._fl_bandwidth(0.002, 0.0, 90.0) == pytest.approx(30.0, rel=1e-12)


def test_friction_fed_at_a_slowing_reference_has_no_stribeck_excess():
    # speeding up (or steady) the plant file's law; slowing towards rest its sliding
    # part: F_c tanh(v / v_e) (v_e = v_s / 10), the Stribeck excess F_s - F_c left to
    # the break-away. At 5 mm/s: 15 + 10 exp(-0.25) = 22.79 N vs 15 tanh(5) = 14.998 N
    from workbench.controllers.compensation import FrictionModel
    from workbench.controllers.feedback_linearizing import fed_friction
    fr = FrictionModel(15.0, 25.0, 0.01)
    v = 0.005
    assert float(fed_friction(fr, v, 1.0)(v)) == pytest.approx(
        (15.0 + 10.0 * math.exp(-0.25)) * math.tanh(5.0), rel=1e-9)
    assert float(fed_friction(fr, v, 0.0)(v)) == pytest.approx(float(fr(v)), rel=1e-12)
    assert float(fed_friction(fr, v, -1.0)(v)) == pytest.approx(15.0 * math.tanh(5.0), rel=1e-9)
    assert float(fed_friction(fr, -v, 1.0)(-v)) == pytest.approx(-15.0 * math.tanh(5.0), rel=1e-9)
    # the rate term slows at the sliding law's slope: F_c (1 - tanh^2) / v_e
    assert float(fed_friction(fr, v, -1.0).slope(v)) == pytest.approx(
        15.0 * (1 - math.tanh(5.0) ** 2) / 0.001, rel=1e-9)


def test_pid_hands_the_break_away_force_back_to_the_sliding_friction():
    # a stuck piston (break-away state) whose measured position moves a quantum has
    # broken away: the force built to F_s is driven back to the sliding need
    # F_c + m r2 + beta r1 with the same time constant, until it gets there
    from workbench.controllers.compensation import FrictionModel
    pid = VelocityPID(kp=1.0, kd=0.0, ki=0.0, sample_time=0.002, u_center=5.0, u_min=0.0,
                      u_max=10.0, friction=FrictionModel(15.0, 25.0, 0.01), force_rate=5000.0,
                      mass=1.2, viscous=40.0, force_time=0.025)
    q = 1.220703125e-4

    def y(x_m, force, v=0.0):
        # the observer's force m a + beta v + d: a = 0, d = force - beta v
        return {"x": x_m, "x_measured": x_m, "v": v, "a": 0.0, "d": force - 40.0 * v}

    r1, r2 = 0.05, 0.5
    u, brk = pid._friction(None, 0.2, r1, r2, y(0.2, 10.0), 0.0)
    assert brk == (1.0, 0.2)
    want_s = 25.0 + 1.2 * r2 + 40.0 * r1
    rate = float(FrictionModel(15.0, 25.0, 0.01).slope(r1)) * r2 / 5000.0
    assert u == pytest.approx(rate + (want_s - 10.0) / (5000.0 * 0.025), rel=1e-9)
    # moved a quantum forwards: released, the force (26 N) driven to the sliding need
    u, rel = pid._friction(brk, 0.2, r1, r2, y(0.2 + q, 26.0, 0.02), 0.1)
    want_c = 15.0 + 1.2 * r2 + 40.0 * r1
    assert rel[0] == 1.0 and rel[1] is None
    assert u == pytest.approx(rate + (want_c - 26.0) / (5000.0 * 0.025), rel=1e-9)
    # once the force is at the sliding need (or after 3 time constants) it hands over
    u, done = pid._friction(rel, 0.2, r1, r2, y(0.2 + 2 * q, want_c - 0.1, 0.05), 0.102)
    assert done is None and u == pytest.approx(rate, rel=1e-9)
    u, done = pid._friction(rel, 0.2, r1, r2, y(0.2 + 2 * q, 30.0, 0.05), 0.1 + 0.076)
    assert done is None


def test_pid_feeds_the_sliding_friction_into_a_reversal_not_into_a_stop():
    # slowing at 1 m/s^2 from 5 mm/s: the preview's velocity 2 x 5 ms ahead has turned
    # (a reversal: the sliding law, F_c (1 - tanh^2(v/v_e)) / v_e of slope) or is zero
    # (a stop: the plant file's law with its Stribeck rise, which this weak loop
    # needs to arrive)
    from workbench.controllers.compensation import FrictionModel

    class Preview:
        def __init__(self, stops):
            self.stops = stops

        def derivatives(self, t):
            v = 0.005 - t
            return 0.0, (max(v, 0.0) if self.stops else v), -1.0, 0.0

    fr = FrictionModel(15.0, 25.0, 0.01)
    y = {"x": 0.2, "x_measured": 0.2, "v": 0.02, "a": 0.0, "d": 15.0}
    got = {}
    for stops in (False, True):
        pid = VelocityPID(kp=1.0, kd=0.0, ki=0.0, sample_time=0.002, u_center=5.0, u_min=0.0,
                          u_max=10.0, friction=fr, force_rate=5000.0, mass=1.2, viscous=40.0,
                          force_time=0.025, preview=Preview(stops))
        got[stops] = pid._friction(None, 0.2, 0.005, -1.0, y, 0.0)[0]
    sliding = 15.0 * (1 - math.tanh(5.0) ** 2) / 0.001
    assert got[False] == pytest.approx(sliding * -1.0 / 5000.0, rel=1e-9)
    assert got[True] == pytest.approx(float(fr.slope(0.005)) * -1.0 / 5000.0, rel=1e-9)


def test_fl_breakaway_probe_keeps_the_force_overshoot_to_a_share_of_the_stribeck_excess():
    # probe = 0.3 / (k2 tau): k2 = 3 lambda, tau = sqrt(2 q m / (F_s - F_c)) + L / c
    # (a quantum of travel under the jump's acceleration, then the lines' delay);
    # precision rig: 1.2 kg, 25 / 15 N, q = 0.5 m / 4096, 1 m lines
    from dataclasses import replace
    from workbench.controllers.design import breakaway_probe
    plant = Plant.from_toml(PLANTS / "rigs" / "precision_rig25.toml")
    q = 0.5 / 4096
    lam = 40.0
    tau = math.sqrt(2 * q * 1.2 / 10.0) + 1.0 / math.sqrt(1.4 * 287.0 * 293.15)
    assert breakaway_probe(plant, lam, q) == pytest.approx(0.3 / (3 * lam * tau), rel=1e-3)
    fl = design(plant, "fl", jit=False).inner.inner
    assert fl.probe == pytest.approx(breakaway_probe(plant, fl.bandwidth, q), rel=1e-12)
    # no Stribeck excess (F_s = F_c): the force target leads by nothing to scale
    flat = plant.with_params(**{"friction.static": 15.0})
    assert breakaway_probe(flat, lam, q) == 1.0
    with pytest.raises(InputError, match="probe"):
        replace(fl, probe=0.0)


def test_fl_release_adds_the_force_rate_to_the_sliding_need_after_a_break_away():
    # release samples = the lines' round trip 2 L / c in samples: 1 m at 20 degC,
    # c = sqrt(1.4 R T) = 343 m/s, 5.83 ms over 2 ms -> 3; without lines one sample
    from dataclasses import replace
    from workbench.controllers.design import release_samples
    plant = Plant.from_toml(PLANTS / "rigs" / "precision_rig25.toml")
    c = math.sqrt(1.4 * 287.0 * 293.15)
    assert release_samples(plant, 0.002) == math.ceil(2.0 / c / 0.002) == 3
    assert release_samples(Plant.from_toml(PLANTS / "rig25_mpye.toml"), 0.002) == 1
    fl = design(plant, "fl", jit=False).inner.inner
    assert fl.release == 3
    with pytest.raises(InputError, match="release"):
        replace(fl, release=-1)
    # a stuck piston the reference moves on (+x), then a quantum of travel: the
    # sample that sees it adds (F_need - F) / (3 T) of force rate to the law's
    # command; F_need = F_c + m (a_r + (k1 e1 + k0 e0) / k2) + beta v, computed here
    m = fl.model
    T = fl.sample_time
    q = 0.5 / 4096
    p_a, p_b = 4.6e5, 4.0e5                       # 29.5 N: past the 25 N static friction
    x0 = 0.25
    y_stuck = {"x": x0, "v": 0.0, "p_a": p_a, "p_b": p_b, "d": 25.0, "x_measured": x0}
    from workbench import references
    p = references.profile([(0.0, x0), (0.01, x0), (0.2, x0 + 0.01)])
    traj = references.smooth(references.Reference(p.times, p.values), 0.2, 5.0, 500.0)
    with_release, without = replace(fl, preview=traj), replace(fl, preview=traj, release=0)
    t_move = next(t for t in np.arange(0.0, 0.2, T) if traj.derivatives(t)[1] > 0.011)
    y_moved = dict(y_stuck, x=x0 + q, v=0.03, x_measured=x0 + q)
    out = []
    for law in (with_release, without):
        state = (None, 0.0, 0.0, None, t_move, None)    # reset(), at t_move
        state, _ = law.update(state, x0, y_stuck)          # break-away state entered
        assert state[5][2] is not None and state[5][2][0] == 1.0
        state, u = law.update(state, x0, y_moved)          # moved: broke away
        out.append((state, u))
    (st_r, u_r), (st_0, u_0) = out
    assert st_r[5][2][1] is None and st_0[5][2] is None      # release under way / none
    tt = t_move + T
    r, r1, r2, _ = (float(v) for v in traj.derivatives(tt))
    g = fl.gains
    acc = r2 + (g["k1"] * (r1 - 0.03) + g["k0"] * (r - (x0 + q))) / g["k2"]
    need = 15.0 + 1.2 * acc + 40.0 * 0.03
    F = (p_a - p_b) * float(plant.area_a)
    rate = (need - F) / (3 * T)
    assert rate < -1e3                                   # the excess comes down
    dG = (float(m.gamma_for_force_rate(rate, x0 + q, 0.03, p_a, p_b))
          - float(m.gamma_for_force_rate(0.0, x0 + q, 0.03, p_a, p_b)))
    assert st_r[5][2][3] == pytest.approx(rate, rel=1e-9)
    # the same law otherwise: u without release is the valve's command for some G0,
    # with release the command for G0 + dG (G0 found by bisection on the valve law)
    from scipy.optimize import brentq
    g0 = brentq(lambda g: float(m.valve.command_for_gamma(g, "a")[0]) - u_0, -0.99, 0.99,
                xtol=1e-12)
    assert dG < -0.02
    assert u_r == pytest.approx(float(m.valve.command_for_gamma(g0 + dG, "a")[0]), abs=1e-6)


def test_pid_can_drive_a_stuck_piston_in_the_lines_round_trip_and_release_after():
    # the stuck piston's drive to F_s in the lines' round trip (3 samples of 2 ms),
    # below 1/w0; the release over the same 3 samples (options, off in design)
    from dataclasses import replace
    plant = Plant.from_toml(PLANTS / "rigs" / "precision_rig25.toml")
    base = design(plant, "pid", jit=False).inner.inner
    assert base.release == 0 and base.breakaway_time == 0.0      # off in design
    pid = replace(base, release=3, breakaway_time=0.006)
    assert pid.force_time > 0.006
    c = pid.force_rate
    # stuck, moving on (+x): (F_s + m r2 + beta r1 - F) / (c tau_b), tau_b = 6 ms
    x0, q = 0.25, 0.5 / 4096
    y = {"x": x0, "v": 0.0, "a": 0.0, "d": 20.0, "x_measured": x0}
    r1, r2 = 0.03, 0.5
    slope_term = float(pid.friction.slope(r1)) * r2 / c
    u, brk = pid._friction((1.0, x0), x0, r1, r2, y, 1.0)
    assert brk == (1.0, x0)
    assert u - slope_term == pytest.approx((25.0 + 1.2 * r2 + 40.0 * r1 - 20.0) / (c * 0.006),
                                           rel=1e-9)
    # the sample that sees a quantum of travel: force 27 N; the release adds
    # (F_c + m r2 + beta r1 - F) / (c 3 T) on top of the hand-back's (.. - F) / (c / w0)
    y_moved = dict(y, x=x0 + q, x_measured=x0 + q, v=0.02, d=27.0 - 40.0 * 0.02)
    want = 15.0 + 1.2 * r2 + 40.0 * r1
    u_r, rel = pid._friction((1.0, x0), x0, r1, r2, y_moved, 1.0)
    u_0, _ = replace(pid, release=0)._friction((1.0, x0), x0, r1, r2, y_moved, 1.0)
    assert rel[1] is None and rel[0] == 1.0
    assert u_r - u_0 == pytest.approx((want - 27.0) / (c * 0.006), rel=1e-9)
    assert u_0 - slope_term == pytest.approx((want - 27.0) / (c * pid.force_time), rel=1e-9)
    # the release lasts 3 samples: still on at 1.004 s, off at 1.006 s
    u_on, _ = pid._friction(rel, x0, r1, r2, y_moved, 1.004)
    u_off, _ = pid._friction(rel, x0, r1, r2, y_moved, 1.006)
    assert u_on - u_off == pytest.approx((want - 27.0) / (c * 0.006), rel=1e-9)
