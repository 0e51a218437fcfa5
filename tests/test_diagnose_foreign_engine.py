"""The diagnosis engine's step where stick-slip rigs are hardest to replay.

The refits replay the recording with one 2 ms ROS2 step per engine sample
(:mod:`workbench.diagnose.engine`). Two places made that step wrong by far more than a
position sensor's noise (20 um), found on recordings of rigs with stick-slip
(tests/foreign_rig.py) and of the synthetic rig:

* a valve opening on the chambers: the pressures change at 1e7 Pa/s from one sample
  to the next, the piston's jerk is 8e3 m/s^3, and ROS2's local error C3 h^3 J^2 f
  (C3 = 1.37) is 50-90 um at h = 2 ms -- one step moved the piston backwards;
* the Stribeck range of the friction curve (|v| of a few mm/s after a break-away),
  whose negative damping (480 1/s) the step leaves out of its W matrix.

The engine now redoes such a step with :data:`~workbench.diagnose.engine.REFINE`
sub-steps. Each test compares one engine sample with scipy's Radau at rtol 1e-11 on
the same right-hand side (``Plant.f``): the reference is an independent integration,
not the engine at finer steps.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from workbench.diagnose import synth
from workbench.diagnose.engine import (INPUT_ROWS, LOCAL_TOL, Engine, EngineInputs,
                                       _error_too_large)
from workbench.plant import Plant

H = 0.002          # s: the refits' engine step at 1 kHz (predict.default_step)


def _one_sample(plant: Plant, z0: np.ndarray, u: float) -> np.ndarray:
    """x, p_a, p_b after one engine sample of H from z0 (open loop, no anchor after)."""
    R = {n: i for i, n in enumerate(INPUT_ROWS)}
    d = np.zeros((len(INPUT_ROWS), 2))
    d[R["u_rec"]] = u
    y = Engine(plant, H, None, jit=False, chunk=2).run(z0, EngineInputs(d), plant.p0)
    return y[:3, 1]


def _reference(plant: Plant, z0: np.ndarray, u: float) -> np.ndarray:
    zs = ca.MX.sym("z", len(z0))
    f = ca.Function("f", [zs], [plant.f(zs, u, plant.p0)])
    sol = solve_ivp(lambda t, z: np.asarray(f(z)).ravel(), (0.0, H), z0, method="Radau",
                    rtol=1e-11, atol=1e-12)
    ix, ia, ib = (plant.state_index(n) for n in ("x", "p_a", "p_b"))
    return sol.y[[ix, ia, ib], -1]


def test_a_valve_opening_step_is_refined():
    """The state of the 2 s synthetic recording (leakage case, seed 3) at 0.910 s, where
    the command jumps from 5.003 to 6.756 V: one 2 ms ROS2 step moved the piston
    -36 um where the converged solution moves +16.5 um (error 52 um; 16 um at two
    sub-steps, 1.1 um at eight: local error ~h^3). Now within 2 um of Radau: the
    step is redone with 8 sub-steps (error ~52/64 um) because its error estimate,
    86 um, exceeds the 5 um tolerance (1e-5 of the 0.5 m stroke)."""
    plant = Plant(synth.nominal_params())
    z0 = np.array([0.188700793, 3.24325434e-03, 3.82432553e+05, 3.82247587e+05])
    u = 6.756
    ref = _reference(plant, z0, u)
    assert ref[0] - z0[0] == pytest.approx(16.5e-6, abs=1e-6)      # the piston moves on
    got = _one_sample(plant, z0, u)
    assert abs(got[0] - ref[0]) < 2e-6
    assert np.all(np.abs(got[1:] - ref[1:]) < 20.0)                 # Pa


def test_error_estimate_is_the_leading_term():
    """On a linear system z' = J z, ROS2's local error (exact minus step) is
    C3 h^3 J^2 f + O(h^4), C3 from its stability function. A spring-mass at 10 rad/s
    (h omega = 0.02): the next term, (1/24 - c4) h^4 J^3 f with c4 = -5.58, is 8 % of
    the leading one there (it is 33 % at the pneumatic spring's 40 rad/s, so the
    estimate is an order of magnitude, not a bound)."""
    from workbench.diagnose.engine import ROS2_C3
    from workbench.integrate import ROS2, rosenbrock
    w2 = 100.0
    J = np.array([[0.0, 1.0], [-w2, -1.0]])
    z0 = np.array([0.0, 1.0])
    zs = ca.SX.sym("z", 2)
    step = ca.Function("s", [zs], [rosenbrock(ROS2, lambda z: ca.mtimes(ca.DM(J), z), zs, H)])
    from scipy.linalg import expm
    err = np.asarray(step(z0)).ravel() - expm(J * H) @ z0
    est = ROS2_C3 * H ** 3 * (J @ J @ (J @ z0))
    assert est[0] == pytest.approx(-err[0], rel=0.12)


def test_a_stribeck_range_step_is_refined():
    """A break-away on the friction rig (Coulomb 20 N, static 28 N, v_s 12 mm/s, 1.2 kg):
    from v = -10.7 mm/s the Stribeck curve's falling slope accelerates the piston at a
    rate of 410 1/s that the step's W leaves out. One plain 2 ms step ended 67 um from the
    converged solution; now within 3 um of Radau (no velocity reversal in this step,
    so the right-hand side is smooth and Radau's reference exact)."""
    P = synth.nominal_params().replace(**{"friction.coulomb": 20.0, "friction.static": 28.0,
                                          "friction.stribeck_velocity": 0.012})
    plant = Plant(P)
    z0 = np.array([0.303514477, -1.06907789e-02, 3.99001096e+05, 4.87880117e+05])
    u = 2.815
    ref = _reference(plant, z0, u)
    got = _one_sample(plant, z0, u)
    assert abs(got[0] - ref[0]) < 3e-6
    assert np.all(np.abs(got[1:] - ref[1:]) < 50.0)


def test_quiet_steps_are_not_refined():
    """The estimate does not fire where nothing happens: a piston at rest with the
    valve at its centre (pressures balanced), and a steady slide at 0.1 m/s."""
    plant = Plant(synth.nominal_params())
    zs = ca.SX.sym("z", 4)
    fz = plant.f(zs, 5.0, plant.p0)
    flag = ca.Function("flag", [zs], [_error_too_large(plant, ca.jacobian(fz, zs), fz, H)])
    assert float(flag([0.25, 0.0, 4.0e5, 4.0e5])) == 0.0
    assert LOCAL_TOL[0] * plant.stroke == pytest.approx(5e-6)
