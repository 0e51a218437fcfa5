"""The NMPC near a stuck piston: the predicted dry friction's width, and a plan
iteration that does not amplify rounding (issue 14).

On the precision rig (designs/plants/rigs/precision_rig25.toml: static friction 25 N,
1.2 kg, 2 ms loop, 4 RK4 substeps of 0.5 ms) the smooth friction law's default width
of 1 mm/s has the slope k = F_s / v_e = 2.5e4 N s/m at rest, k h / m = 10.4: far
outside RK4's stability interval (2.785), so one interval multiplied a velocity
difference at rest by ~1e10 and two closed loops whose measurements differ by 1e-9 m
parted by volts within one sample. The width is now half the Stribeck velocity, and
the substeps are raised until one RK4 step resolves the decay at rest, k h / m <= 1
(mpc.model.friction_velocity: at most 8 substeps, 5.25 mm/s here).
"""

from __future__ import annotations

import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

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


def _jacobian_at_rest(pb) -> np.ndarray:
    """A = d f / d z of the scaled continuous model at the rest point of
    :func:`_velocity_gain` (equal pressures, valve closed: an equilibrium)."""
    z, w, d, fz, _ = _scaled_rhs(pb.model, pb.sx, pb.u_c, pb.u_s, pb.friction_width)
    jac = ca.Function("a", [z, w, d], [ca.jacobian(fz, z)])
    z0 = [0.25 / pb.L, 0.0, 3.5e5 / pb.p_sup, 3.5e5 / pb.p_sup]
    return np.array(jac(z0, 0.0, 0.0))


def _rk4_factor(M: np.ndarray) -> np.ndarray:
    """RK4's step matrix for x' = A x: I + M + M^2/2 + M^3/6 + M^4/24, M = h A."""
    eye = np.eye(len(M))
    return eye + M @ (eye + M @ (eye / 2 + M @ (eye / 6 + M / 24)))


def test_predicted_friction_is_integrated_stably_at_rest(plant):
    prm = plant.params
    m, beta, fs = prm["load.mass"], prm["load.viscous_friction"], prm["friction.static"]
    nmpc = _nmpc(plant)
    pb = nmpc._problem
    v_e, n = pb.friction_width, pb.substeps
    k = fs / v_e + beta
    # half the Stribeck velocity (10 mm/s) needs k h / m <= 1 with 9 substeps, more
    # than MAX_SUBSTEPS: the width is widened to what 8 resolve, k h / m = 1
    assert n == MAX_SUBSTEPS == 8
    assert v_e > 0.5 * prm["friction.stribeck_velocity"]
    assert k * (T / n) / m == pytest.approx(1.0, rel=1e-12)
    # a wider width needs fewer substeps: the fewest from 4 on with k h / m <= 1
    wide = _nmpc(plant, friction_width=0.008)._problem            # 6 substeps
    kw = fs / 0.008 + beta
    assert wide.friction_width == 0.008 and 4 < wide.substeps < MAX_SUBSTEPS
    assert kw * (T / wide.substeps) / m <= 1.0 < kw * (T / (wide.substeps - 1)) / m
    # at an equilibrium the interval map's Jacobian is RK4's step matrix of the
    # linearisation to the n-th power, exactly
    A = _jacobian_at_rest(pb)
    step = _rk4_factor(A * T / n)
    gain = _velocity_gain(pb.F, pb)
    assert gain == pytest.approx(np.linalg.matrix_power(step, n)[1, 1], rel=1e-9)
    # every mode of a step decays as the exact flow's exp(h lambda) does, within RK4's
    # error at h lambda >= -1: R(-1) e - 1 = 1.9 % (the fastest mode is the friction's,
    # h lambda = -1.0001 here; 1e-4 of slack for it)
    lam = np.sort_complex(np.linalg.eigvals(A) * T / n)
    mu = np.sort_complex(np.linalg.eigvals(step))
    assert lam.real.min() >= -1.0 - 1e-3
    assert np.max(np.abs(mu / np.exp(lam) - 1.0)) <= 0.375 * math.e - 1.0 + 1e-4
    # the cause: the physics' 1 mm/s with the default 4 substeps, k h / m = 10.4:
    # one interval blows a velocity difference at rest up by ~1e10
    F, _ = interval_maps(pb.model, pb.sx, pb.u_c, pb.u_s, T, 4, "pade", 1e-3)
    assert abs(_velocity_gain(F, pb)) > 1e6


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
    # a quantum, commands within a 12-bit DAC step (10 V / 4096). Measured 2.2e-8 m,
    # 1.2e-4 V; with 1 mm/s and 4 substeps: 0.88 mm and 4.4 V
    assert np.max(np.abs(x0 - x1)) <= 0.01 * q
    assert np.max(np.abs(u0 - u1)) <= 10.0 / 4096
