"""The diagnosis engine's replay of a plant with a spool lag (issue 12).

The spool lag (``valve_dynamics``: y'' = w^2 (u - y) - 2 zeta w y') is linear and driven
by the command alone, held over each step; the engine steps it exactly
(:func:`workbench.integrate.exact.lag2_step`) and integrates the rest of the plant with
the valve following that exact motion (:func:`workbench.diagnose.engine._split_spool`),
with the steps sized for the spool candidate's bound of 400 Hz
(:func:`workbench.diagnose.engine.stiff_substeps`). Until session 11 a spool plant was
stepped by ROS2 at one step per 2 ms sample, which damps a fast spool to its
quasi-static limit but misses the position by 0.15-0.6 mm in a window at a full valve
opening; ROS4 with the spool as an ordinary state kept a 200-400 Hz spool's mode weakly
damped in a wrong phase (h omega 3-5), and the fits ran to a spurious 222 Hz lag.

References: the exact step against scipy's DOP853 at 1e-12; the replays against CVODES
(:func:`workbench.simulate.closed_loop`) from the true full state.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from workbench import controllers, simulate
from workbench.diagnose import synth
from workbench.diagnose.engine import INPUT_ROWS, Engine, EngineInputs, stiff_substeps
from workbench.integrate.exact import lag2_step

R = {n: i for i, n in enumerate(INPUT_ROWS)}
H = 0.002         # s: the refits' engine step at 1 kHz


@pytest.mark.parametrize("bandwidth,damping", [(400.0, 0.8), (30.0, 0.25), (50.0, 1.0),
                                               (200.0, 3.0), (2.0, 0.2)])
def test_lag_step_is_exact(bandwidth, damping):
    """Under-, critically and over-damped, h omega from 0.025 to 5: end value, rate and
    mean over the step against scipy's DOP853 at 1e-12 (measured <= 6e-13 relative)."""
    w = 2.0 * math.pi * bandwidth

    def rhs(t, x):
        return [x[1], w * w * (1.0 - x[0]) - 2.0 * damping * w * x[1], x[0]]
    ref = solve_ivp(rhs, (0.0, H), [0.3, -50.0, 0.0], method="DOP853", rtol=1e-12,
                    atol=1e-12).y[:, -1]
    y1, r1, mean = (float(v) for v in lag2_step(0.3, -50.0, 1.0, bandwidth, damping, H))
    assert y1 == pytest.approx(ref[0], abs=1e-10)
    assert r1 == pytest.approx(ref[1], abs=1e-9 * max(1.0, abs(ref[1])))
    assert mean == pytest.approx(ref[2] / H, abs=1e-10)


@pytest.fixture(scope="module")
def spool_runs():
    """1.2 s of the 25 mm rig with a 0.15 V valve offset and a spool lag, closed loop on a
    step at 0.5 s (the valve opens fully), simulated by CVODES (all states kept)."""
    out = {}
    for bw, zeta in ((30.0, 0.3), (400.0, 0.8)):
        plant = synth.concealed_case("none", seed=3, values={
            "valve.null_offset": 0.15, "valve.bandwidth": bw, "valve.damping": zeta}).plant
        t = np.arange(1201) * 1e-3
        run = simulate.closed_loop(plant, controllers.from_plant(plant),
                                   lambda tt: np.where(np.asarray(tt) < 0.5, 0.15, 0.3),
                                   t_end=t[-1], x0=plant.initial_state(0.15),
                                   output_times=t, progress=False)
        out[bw] = plant, np.asarray(run.states), np.asarray(run["u"])
    return out


@pytest.mark.parametrize("bw", [30.0, 400.0])
def test_spool_replay_matches_cvodes(spool_runs, bw):
    """The window from 0.46 s from the true state, open loop on the recorded command: at
    the steps the engine sizes itself (2 per 2 ms sample: 400 Hz x 2 pi x 1 ms = 2.5) the
    position is within 10 um rms of CVODES at either bandwidth (measured 1.3 / 3.5 um;
    the same window without a spool: 2.0 um; ROS2 at one step, the method until session
    11: 150-590 um), a 12-bit position sensor over 0.5 m has 35 um rms of quantisation
    alone; the pressure within 50 Pa (measured 2 / 10 Pa, ROS2 1-1.7 kPa)."""
    plant, S, u = spool_runs[bw]
    assert plant.params.has_effect("valve_dynamics")
    assert stiff_substeps(plant, H) == 2
    k0, n = 460, 100
    d = np.zeros((len(INPUT_ROWS), n))
    d[R["u_rec"]] = u[k0:k0 + 2 * n:2]
    eng = Engine(plant, H, None, jit=False, chunk=n)
    y = eng.run(S[k0], EngineInputs(d), plant.p0)
    ref = S[k0:k0 + 2 * n:2]
    assert np.sqrt(np.mean((y[0] - ref[:, plant.state_index("x")]) ** 2)) < 10e-6
    assert np.sqrt(np.mean((y[1] - ref[:, plant.state_index("p_a")]) ** 2)) < 50.0
