"""The NMPC near a stuck piston: the predicted dry friction's width, and a plan
iteration that does not amplify rounding (issue 14).

On the precision rig (designs/plants/rigs/precision_rig25.toml: static friction 25 N,
1.2 kg, 2 ms loop, 4 RK4 substeps of 0.5 ms) the smooth friction law's default width
of 1 mm/s has the slope k = F_s / v_e = 2.5e4 N s/m at rest, k h / m = 10.4: far
outside RK4's stability interval (2.785), so one interval multiplied a velocity
difference at rest by ~1e10 and two closed loops whose measurements differ by 1e-9 m
parted by volts within one sample. The width is now half the Stribeck velocity, and
the substeps are raised until one RK4 step resolves the decay at rest, k h / m <= 1
(mpc.model.friction_velocity: 5 mm/s and 9 substeps here).
"""

from __future__ import annotations

import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy.linalg import expm

from workbench import Plant, simulate
from workbench.controllers.mpc import NMPC
from workbench.controllers.mpc.model import MAX_SUBSTEPS, _scaled_rhs, interval_maps
from workbench.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
RIG = ROOT / "designs" / "plants" / "rigs" / "precision_rig25.toml"
T = 0.002


@pytest.fixture(scope="module")
def plant():
    # the rig without its lines: the NMPC then measures the plant's four states
    rig = Plant.from_toml(RIG)
    return Plant(rig.params.without_effect("line_dynamics"))


def _nmpc(plant, **kw):
    kw = dict(dict(sample_time=T, horizon=40, max_speed=2.0, disturbance_gain=0.1,
                   jit=False), **kw)
    return NMPC.for_plant(plant, effects=["dry_friction"], **kw)


def _velocity_gain(F, pb) -> float:
    """d v_{k+1} / d v_k of an interval map F, at rest mid-stroke."""
    z = ca.SX.sym("z", 4)
    jac = ca.Function("j", [z], [ca.jacobian(F(z, 0.0, 0.0), z)])
    z0 = [0.25 / pb.L, 0.0, 3.5e5 / pb.p_sup, 3.5e5 / pb.p_sup]
    return float(np.array(jac(z0))[1, 1])


def _exact_gain(pb, v_e) -> float:
    """expm(A T)[v, v] of the scaled continuous model at the rest point of
    :func:`_velocity_gain` (scipy's matrix exponential)."""
    z, w, d, fz, _ = _scaled_rhs(pb.model, pb.sx, pb.u_c, pb.u_s, v_e)
    jac = ca.Function("a", [z, w, d], [ca.jacobian(fz, z)])
    z0 = [0.25 / pb.L, 0.0, 3.5e5 / pb.p_sup, 3.5e5 / pb.p_sup]
    return float(expm(np.array(jac(z0, 0.0, 0.0)) * T)[1, 1])


def test_predicted_friction_is_integrated_stably_at_rest(plant):
    prm = plant.params
    m, beta, fs = prm["load.mass"], prm["load.viscous_friction"], prm["friction.static"]
    nmpc = _nmpc(plant)
    pb = nmpc._problem
    v_e, n = pb.friction_width, pb.substeps
    # half the Stribeck velocity (10 mm/s), the substeps raised from 4 until one RK4
    # step resolves the decay at rest: k h / m <= 1, k = F_s / v_e + beta
    assert v_e == pytest.approx(0.5 * prm["friction.stribeck_velocity"], rel=1e-12)
    k = fs / v_e + beta
    assert k * (T / n) / m <= 1.0 < k * (T / (n - 1)) / m
    # at rest with equal pressures and the valve closed (an equilibrium) the exact
    # interval's sensitivity is expm(A T) of the continuous Jacobian A. RK4's factor
    # per step R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24 exceeds exp(z) by at most
    # R(-1) e - 1 = 1.9 % for -1 <= z < 0: (R(-1) e)^n - 1 = 19 % over n = 9 steps
    exact = _exact_gain(pb, v_e)
    rk4 = 1 - 1 + 1 / 2 - 1 / 6 + 1 / 24
    assert 0.0 < _velocity_gain(pb.F, pb) / exact - 1.0 <= (rk4 * math.e) ** n - 1.0
    # the cause: the physics' 1 mm/s with the default 4 substeps, k h / m = 10.4:
    # one interval blows a velocity difference at rest up by ~1e10
    F, _ = interval_maps(pb.model, pb.sx, pb.u_c, pb.u_s, T, 4, "pade", 1e-3)
    assert abs(_velocity_gain(F, pb)) > 1e6
    # a width too sharp for MAX_SUBSTEPS is widened to what they resolve
    wide = _nmpc(plant, friction_width=1e-4)._problem
    assert wide.substeps == MAX_SUBSTEPS
    assert (fs / wide.friction_width + beta) * (T / MAX_SUBSTEPS) / m == pytest.approx(1.0)


def test_friction_width_is_checked(plant):
    with pytest.raises(InputError, match="friction_width"):
        _nmpc(plant, friction_width=0.0)
    with pytest.raises(InputError, match="friction_width"):
        _nmpc(plant, friction_width=float("nan"))


class _Offset:
    """The controller with the measured position offset by ``dx`` (m)."""

    def __init__(self, inner, dx: float) -> None:
        self.inner, self.dx = inner, dx
        self.sample_time, self.needs = inner.sample_time, inner.needs

    def reset(self):
        return self.inner.reset()

    def update(self, state, r, y):
        return self.inner.update(state, r, dict(y, x=float(y["x"]) + self.dx))


def test_one_nanometre_in_the_measurement_stays_small_near_a_stuck_piston(plant):
    # sub-millimetre steps from rest (the piston stuck most of the time), then a
    # 0.5 mm step that breaks it away
    nmpc = _nmpc(plant)
    ref = simulate.steps([0.25, 0.2502, 0.2499, 0.2505], hold=0.1)
    runs = [simulate.closed_loop(plant, _Offset(nmpc, dx), ref, x0=0.25, progress=False)
            for dx in (0.0, 1e-9)]
    (u0, u1), (x0, x1) = ([np.asarray(r[k], dtype=float).ravel() for r in runs]
                          for k in ("u", "x"))
    v0, v1 = (np.abs(np.asarray(r["v"], dtype=float).ravel()) for r in runs)
    q = float(plant.params["controller.position_resolution"])
    stuck = np.cumprod((v0 < 1e-9) & (v1 < 1e-9)).astype(bool)   # until the first slip
    assert 0.5 < stuck.mean() < 1.0
    # while stuck the plant is the same in both runs, so the difference is the
    # controller's alone: at most a position loop's gain times 1e-9 m, the gain
    # bounded by the whole command span (10 V) for one quantum (0.122 mm), 8.2e-5 V.
    # Measured 1.1e-6 V; with the physics' 1 mm/s and 4 substeps the
    # commands parted by volts from the first sample on
    assert np.max(np.abs(u0 - u1)[stuck]) <= 10.0 / q * 1e-9
    # through the break-away (a time shift of a stick-slip event, amplified by the
    # plant itself) the runs stay indistinguishable on a rig: positions within 1 % of
    # a quantum, commands within a 12-bit DAC step (10 V / 4096). Measured 1.1e-7 m,
    # 2.0e-4 V; with 1 mm/s and 4 substeps: 0.88 mm and 4.4 V
    assert np.max(np.abs(x0 - x1)) <= 0.01 * q
    assert np.max(np.abs(u0 - u1)) <= 10.0 / 4096
