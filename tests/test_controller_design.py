"""Smooth trajectories, deadband inverse, axis limits and controllers.design (issue 14)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from workbench import Plant, simulate
from workbench.controllers.compensation import Compensated, DeadbandInverse, hold_limit_cycle
from workbench.controllers.design import axis_limits, design
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
