"""Core numerics against values written out by hand (issue 17, blind mutation round 2).

Each test kills one or more mutants of the ``core`` group of ``tests/mutation.py``
that survived the modules' own tests; the reference values are hand formulas
(source named) or a direct re-computation in the test, never the code's output.
Runs in a few seconds (one 0.2 s closed loop, one short open-loop hold).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from workbench import Plant, controllers, linearize, signals, simulate
from workbench import replay as rp
from workbench.controllers.pd import PID, clip_and_quantise, pid_law
from workbench.equilibrium import initial_state, operating_point
from workbench.integrate import tableaux
from workbench.metrics import _first_crossing, trapezoid
from workbench.recording import Recording
from workbench.references import steps
from workbench.stability.kernel import _closed_loop
from workbench.validate import _run_metrics

from conftest import PLANTS

#: Float round-off only (the quantities are a few operations on O(1) numbers).
EXACT = 1e-12


@pytest.fixture(scope="module")
def plant() -> Plant:
    return Plant.from_toml(PLANTS / "rig25_mpye.toml")


# ------------------------------------------------------------------ PID (controllers/pd.py)
def test_pid_law_terms_by_hand():
    """u = u_c + kp e + kd (e - e_prev) / T + ki (I + e T) (the pid_law docstring)."""
    kp, kd, ki, T, uc = 20.0, 0.5, 3.0, 0.01, 5.0
    e, e_prev, integ = 0.02, 0.015, 0.1
    u, i_next = pid_law(e, e_prev, integ, kp, kd, ki, T, uc, -1e9, 1e9)
    assert i_next == pytest.approx(integ + e * T, abs=EXACT)
    assert u == pytest.approx(uc + kp * e + kd * (e - e_prev) / T + ki * (integ + e * T),
                              abs=EXACT)


def test_pid_transfer_function_matches_the_difference_equation():
    """PID.to_control() evaluated at z equals kp + kd (1 - 1/z)/T + ki T / (1 - 1/z)."""
    pid = PID(kp=20.0, sample_time=0.01, kd=0.5, ki=3.0)
    tf = pid.to_control()
    for z in (0.3 + 0.4j, 1.7, -0.8 + 0.1j):
        zi = 1.0 / z
        want = pid.kp + pid.kd * (1 - zi) / pid.sample_time + pid.ki * pid.sample_time / (1 - zi)
        num, den = np.asarray(tf.num[0][0]), np.asarray(tf.den[0][0])
        got = np.polyval(num, z) / np.polyval(den, z)
        assert abs(got - want) <= 1e-10 * abs(want)


def test_dac_quantisation_rounds_to_nearest():
    """A 10 mV DAC turns 3.337 V into 3.34 V (nearest step), not 3.33 V."""
    assert float(clip_and_quantise(3.337, 0.0, 10.0, 0.01)) == pytest.approx(3.34, abs=EXACT)
    assert float(clip_and_quantise(12.0, 0.0, 10.0, 0.01)) == pytest.approx(10.0, abs=EXACT)


# ------------------------------------------------------------------ metrics.py
def test_first_crossing_and_trapezoid_by_hand():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    y = np.array([0.0, 0.2, 0.6, 1.0])
    # level 0.5 lies between y = 0.2 (t = 1) and 0.6 (t = 2): t = 1 + 0.3/0.4 = 1.75 s
    assert _first_crossing(t, y, 0.5) == pytest.approx(1.75, abs=EXACT)
    # trapezoid: (0 + 0.2)/2 + (0.2 + 0.6)/2 + (0.6 + 1.0)/2 = 1.3
    assert trapezoid(y, t) == pytest.approx(1.3, abs=EXACT)


# ------------------------------------------------------------------ references.py
def test_steps_hold_and_jump_instants():
    """Levels 0.1, 0.3 held 1 s each: the jump instant takes the new level and the
    reference ends on the last level."""
    ref = steps([0.1, 0.3], hold=1.0)
    assert float(ref(0.5)) == 0.1
    assert float(ref(1.0)) == 0.3
    assert float(ref(ref.duration)) == 0.3
    assert ref.duration == 2.0


# ------------------------------------------------------------------ linearize.py
def test_position_model_response_and_transfer_function():
    """Kv / (s (s^2/w0^2 + 2 zeta s/w0 + 1)) at s = j w, both ways."""
    m = linearize.PositionModel(kv=0.05, w0=40.0, zeta=0.3, fit_error=0.0)
    w = np.array([5.0, 40.0, 120.0])
    s = 1j * w
    want = 0.05 / (s * (s ** 2 / 1600.0 + 0.6 * s / 40.0 + 1.0))
    np.testing.assert_allclose(m.response(w), want, rtol=1e-12)
    tf = m.transfer_function()
    num, den = np.asarray(tf.num[0][0]), np.asarray(tf.den[0][0])
    np.testing.assert_allclose(np.polyval(num, s) / np.polyval(den, s), want, rtol=1e-12)


def test_kv_from_flow_by_hand():
    """Kv = R T (dq/du) / (p A): 287.058 * 293.15 * 1e-4 / (3e5 * 5e-4) (ideal gas)."""
    from workbench.physics import gas
    kv = linearize.paper000_kv_from_flow(1e-4, 5e-4, 3e5)
    assert kv == pytest.approx(gas.R_AIR * gas.T_REF * 1e-4 / (3e5 * 5e-4), rel=EXACT)


def test_tank_tangent_on_a_linear_valve():
    """q = g u - c (p - p0): p_e = p0 + g u/c, Cp = c, Gu = g, tau = V/(k R T c), G = g/c
    (paper 003's tank: V/(k R T) dp/dt = q)."""
    from workbench.physics import gas
    g, c, p0, vol, k = 2e-4, 1e-8, 2e5, 1e-3, 1.2

    def flow(p, u):
        return g * u - c * (p - p0)

    tt = linearize.tank_tangent(flow, vol, u_e=1.0, k=k)
    assert tt.p_e == pytest.approx(p0 + g / c, rel=1e-9)   # brentq xtol 1e-10 Pa
    assert tt.cp == pytest.approx(c, rel=EXACT)
    assert tt.gu == pytest.approx(g, rel=EXACT)
    assert tt.tau == pytest.approx(vol / (k * gas.R_AIR * gas.T_REF * c), rel=EXACT)
    assert tt.gain == pytest.approx(g / c, rel=EXACT)


# ------------------------------------------------------------------ equilibrium.py
def test_operating_point_is_a_rest_point_of_the_ode(make_plant):
    """At the operating point every derivative but dx/dt (= v = 0) vanishes: f is
    evaluated here with the point's own command u (the value written to JSON). Leaks
    and a 60 N load put the command off the valve's rest (about 23 mV here: the
    leaks must be fed unequally), so a wrongly unscaled command shows."""
    plant = make_plant(["leakage"], {"load.external_force": 60.0})
    op = operating_point(plant, 0.3 * plant.stroke)
    assert abs(op.u - plant.inputs[0].rest) > 0.01
    xdot = np.asarray(plant.f(op.state, op.u, op.params)).ravel()
    scales = plant.state_scales()
    # the solver stops at a scaled residual of 1e-9 per 10 ms; 1e-4 of a scale per
    # second is far below what a command off by a factor of the 5 V span gives
    assert np.max(np.abs(xdot) / scales) < 1e-4


def test_initial_state_takes_the_given_velocity_and_pressures(plant):
    s = initial_state(plant, 0.1, p_a=3e5, p_b=2e5, v0=0.05, u0=5.0)
    assert s[plant.state_index("v")] == 0.05
    assert s[plant.state_index("p_a")] == 3e5
    assert s[plant.state_index("p_b")] == 2e5
    assert s[plant.state_index("x")] == 0.1


# ------------------------------------------------------------------ simulate.py
class _Spy:
    """A constant-command controller that records the position it is shown."""

    sample_time = 0.01

    def __init__(self, u):
        self.u, self.seen = u, []

    def reset(self):
        return None

    def update(self, state, r, y):
        self.seen.append(y["x"])
        return state, self.u


def test_closed_loop_measures_the_position_through_the_adc(plant):
    """The controller sees round(x / q) q of the true x at each sample (ADC, q = 1 mm)."""
    q = 1e-3
    spy = _Spy(plant.params["valve.command_center"] + 0.6)
    traj = simulate.closed_loop(plant, spy, steps([0.1], hold=0.2), t_end=0.2, x0=0.1,
                                position_resolution=q, progress=False)
    seen = np.array(spy.seen)
    x_true = traj["x"][:len(seen)]
    assert np.ptp(x_true) > 5 * q                   # it moves over several steps
    np.testing.assert_allclose(seen, np.round(x_true / q) * q, atol=1e-12)


def test_hold_equals_interval_by_interval(plant):
    """hold() over 3 intervals (blocks 2 + 1) equals three successive 1-interval holds."""
    sim = simulate.Simulator(plant)
    x0 = plant.initial_state(0.1)
    u = plant.params["valve.command_center"] + 1.0
    block = sim.hold(x0, u, [0.01, 0.01, 0.01])
    state, seq = x0, []
    for _ in range(3):
        state = sim.hold(state, u, [0.01])[-1]
        seq.append(state)
    # both are CVODES at rtol 1e-7 over the same intervals: agree to ~1e-6 relative
    np.testing.assert_allclose(block, np.array(seq), rtol=1e-5,
                               atol=1e-9 * np.max(np.abs(seq)))


# ------------------------------------------------------------------ signals.py
def test_ljung_box_by_hand():
    """Q = N (N + 2) sum_{k=1..M} r_k^2 / (N - k), p = chi2.sf(Q, M) (Ljung & Box 1978)."""
    rng = np.random.default_rng(7)
    e = rng.standard_normal(200)
    e[1:] += 0.3 * e[:-1]
    m = 6
    ec = e - e.mean()
    r = np.array([ec[k:] @ ec[:len(e) - k] for k in range(m + 1)]) / (ec @ ec)
    n = len(e)
    q = n * (n + 2) * sum(r[k] ** 2 / (n - k) for k in range(1, m + 1))
    got_q, got_p = signals.ljung_box(e, m)
    assert got_q == pytest.approx(q, rel=1e-12)
    assert got_p == pytest.approx(stats.chi2.sf(q, m), rel=1e-10)


# ------------------------------------------------------------------ replay.py
def test_replay_starts_from_the_recorded_state_and_time_zero(plant):
    """Replay of a recording whose clock starts at 5 s: time from 0 s, and the first
    state takes both recorded chamber pressures."""
    t = np.arange(201) * 1e-3
    run = simulate.closed_loop(plant, controllers.from_plant(plant), steps([0.2], hold=0.2),
                               t_end=0.2, x0=0.15, output_times=t, progress=False)
    rec = Recording.from_arrays(t + 5.0, u=run["u"], r=run.reference, x=run["x"],
                                p_a=run["p_a"] + 1e4, p_b=run["p_b"] - 1e4)
    x0 = rp.initial_state(plant, rec)
    assert x0[plant.state_index("p_a")] == pytest.approx(rec["p_a"][0], abs=EXACT)
    assert x0[plant.state_index("p_b")] == pytest.approx(rec["p_b"][0], abs=EXACT)
    out = rp.run(plant, rec, rp.ClosedLoop(), x0=run.states[0])
    np.testing.assert_allclose(out.time, t, atol=1e-12)
    assert np.max(np.abs(out["x"] - run["x"])) < 1e-6    # same loop, CVODES rtol 1e-7


# ------------------------------------------------------------------ validate.py
def test_saturation_share_is_zero_order_hold():
    """u at its limit on [0, 1) s and inside on [1, 3] s: saturated 1/3 of the time."""
    t = np.array([0.0, 1.0, 3.0])
    u = np.array([10.0, 5.0, 5.0])
    p = np.full(3, 2e5)
    m = _run_metrics(t, np.zeros(3), u, p, p, steps([0.0], hold=3.0), (), (0.0, 10.0))
    assert m.saturation_fraction == pytest.approx(1.0 / 3.0, abs=EXACT)


# ------------------------------------------------------------------ integrate/tableaux.py
@pytest.mark.parametrize("tab", [tableaux.RK4, *tableaux.RADAU_IIA.values()],
                         ids=lambda t: t.name)
def test_butcher_nodes_are_row_sums(tab):
    """c_i = sum_j a_ij (Butcher's simplifying condition; Radau IIA(3) nodes
    (4 -+ sqrt 6)/10, 1 from Hairer & Wanner II, Table IV.5.6)."""
    np.testing.assert_allclose(tab.A.sum(axis=1), tab.c, atol=1e-14)
    np.testing.assert_allclose(sum(tab.b), 1.0, atol=1e-14)


# ------------------------------------------------------------------ stability/kernel.py
def test_closed_loop_matrix_with_integral_by_hand():
    """One-state plant x+ = a x + b u, u = kp e + ki (I + e T), I+ = I + e T, e = r - x:
    Acl = [[a - b (kp + ki T), b ki], [-T, 1]], Br = [b (kp + ki T), T]."""
    a, b, kp, ki, T = 0.9, 0.2, 3.0, 40.0, 0.01
    one = np.ones(1)
    acl, br = _closed_loop(np.full((1, 1, 1), a), np.full((1, 1), b), kp * one, 0 * one,
                           ki * one, T * one, 1.0, 1.0, 0)
    want = np.array([[a - b * (kp + ki * T), b * ki], [-T, 1.0]])
    np.testing.assert_allclose(acl[0], want, atol=1e-14)
    np.testing.assert_allclose(br[0], [b * (kp + ki * T), T], atol=1e-14)

