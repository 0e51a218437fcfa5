"""Comparison figures of a validated run, checked on trajectories with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from workbench import Plant, compare, validate
from workbench.errors import InputError
from workbench.physics.gas import RHO_ANR
from workbench.simulate import Trajectory, steps

PLANT = "designs/plants/situm_rodless_nominal.toml"
T = 0.01                      # control period of the synthetic runs, s


def _run(ref, x, u, q, dt=1e-3):
    """A hand-built trajectory on a 1 ms grid with the given x(t), u(t), q_supply(t)."""
    t = np.arange(0.0, ref.duration + 1e-12, dt)
    n = len(t)
    states = np.column_stack([x(t), np.zeros(n), np.full(n, 3e5), np.full(n, 3e5)])
    outputs = np.column_stack([x(t), q(t)])
    return Trajectory(time=t, states=states, inputs=u(t)[:, None], outputs=outputs,
                      state_names=("x", "v", "p_a", "p_b"), output_names=("x_out", "q_supply"),
                      reference=ref(t), info={"sample_time": T})


def _evaluate(ref, x, u, q):
    plant = Plant.from_toml(PLANT)
    return validate.evaluate(_run(ref, x, u, q), ref, validate.Specification(), plant)


def test_perfect_tracking_constant_flow_and_square_wave_command():
    ref = steps([0.2, 0.3], hold=2.0)                      # one 100 mm step at t = 2 s
    # x follows r exactly; u toggles 4 V <-> 6 V every 0.5 s (1 Hz square wave of
    # amplitude 1 V); q_supply is a constant 2 g/s.
    v = _evaluate(ref, lambda t: ref(t), lambda t: 5.0 + np.where(np.floor(t / 0.5) % 2, 1.0, -1.0),
                  lambda t: np.full_like(t, 2e-3))
    f = compare.run_figures(v)
    assert f["iae"] == pytest.approx(0.0, abs=1e-12)
    assert f["max_error"] == pytest.approx(0.0, abs=1e-12)
    # air: 2 g/s over the 4 s run (trapezoid of a constant is exact)
    assert f["air_kg"] == pytest.approx(2e-3 * 4.0, rel=1e-12)
    assert f["air_l_anr"] == pytest.approx(8e-3 / RHO_ANR * 1e3, rel=1e-12)
    # 8 toggles of 2 V in the 4 s run (at 0.5, 1.0, ..., 4.0 s, the last sample
    # included): 16 V / 4 s
    assert f["command_activity"] == pytest.approx(16.0 / 4.0, rel=1e-12)
    assert f["u_min"] == 4.0 and f["u_max"] == 6.0
    assert f["p_min"] == f["p_max"] == 3e5


def test_constant_offset_and_settled_window():
    ref = steps([0.2, 0.3], hold=2.0)
    # x lags the step by an exponential (tau 0.1 s) and keeps a 1 mm offset
    def x(t):
        return ref(t) - 0.1 * np.exp(-np.clip(t - 2.0, 0.0, None) / 0.1) * (t >= 2.0) - 1e-3
    v = _evaluate(ref, x, lambda t: np.full_like(t, 5.0), lambda t: np.zeros_like(t))
    f = compare.run_figures(v)
    # IAE = 1 mm x 4 s + the exponential's area 0.1 m x 0.1 s + half a 1 ms sample of
    # the 0.1 m jump (the trapezoid bridges the step at t = 2 s); the trapezoid's error
    # on the exponential is (dt/tau)^2/12 ~ 1e-5 of its area
    assert f["iae"] == pytest.approx(4e-3 + 0.01 + 0.5 * 1e-3 * 0.1, rel=1e-5)
    assert f["max_error"] == pytest.approx(0.1 + 1e-3, rel=1e-9)
    # 0.5 s after the step the exponential is exp(-5) x 0.1 m = 0.67 mm, plus the offset
    assert f["max_error_settled"] == pytest.approx(0.1 * math.exp(-5.0) + 1e-3, rel=1e-2)
    assert f["command_activity"] == 0.0
    # the offset, plus the exponential's tail where the steady-state window begins
    # (0.1 m x exp(-16) ~ 1e-8 m)
    assert f["steady_state_error"] == pytest.approx(1e-3, rel=1e-4)


def test_comparison_rows_ratio_and_bad_input():
    a = {k: 1.0 for k, *_ in compare.FIGURES}
    b = {k: 2.0 for k, *_ in compare.FIGURES}
    head, rows = compare.comparison_rows({"NMPC": a, "PD": b}, baseline="PD", keys=["iae", "air_kg"])
    assert head == ["quantity", "unit", "NMPC", "PD", "PD / NMPC"]
    assert rows[0][2:] == [1e3, 2e3, 2.0]                 # mm s display, ratio 2
    assert rows[1][2:] == [1e3, 2e3, 2.0]                 # g display
    with pytest.raises(InputError):
        compare.comparison_rows({"a": a}, baseline="b")
    with pytest.raises(InputError):
        compare.comparison_rows({"a": a}, keys=["nonsense"])
    with pytest.raises(InputError):
        compare.comparison_rows({})


def test_no_ratio_below_a_figures_resolution():
    a = {k: 1.0 for k, *_ in compare.FIGURES}
    b = dict(a, overshoot=1e-8)                       # numerically zero overshoot, %
    _, rows = compare.comparison_rows({"PD": a, "NMPC": b}, baseline="PD", keys=["overshoot", "iae"])
    assert rows[0][-1] is None                         # 1 / 1e-8 would say nothing
    assert rows[1][-1] == 1.0
