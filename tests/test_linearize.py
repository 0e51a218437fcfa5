"""Equilibria, exact tangent models and paper 000's linear position model."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from workbench import Plant, linearize
from workbench.physics import gas

PLANTS = Path(__file__).resolve().parents[1] / "designs" / "plants"


@pytest.fixture(scope="module")
def situm():
    return Plant.from_toml(PLANTS / "situm_rodless_nominal.toml")


def test_paper000_formulas_reproduce_table_ii():
    # physics.md: the formulas give w0 = 32.97 rad/s and zeta = 1.08 from Table II
    # (A = 1.767e-4 m^2, L = 0.5 m, p = 5e5 Pa, M = 0.91 kg, k_f = 65 N s/m, kappa 1.4).
    # Tolerances: the paper prints 4 significant digits for w0 and 3 for zeta.
    w0 = linearize.paper000_w0(1.767e-4, 0.91, 5e5, 0.5, kappa=1.4)
    zeta = linearize.paper000_zeta(1.767e-4, 0.91, 5e5, 0.5, 65.0, kappa=1.4)
    assert w0 == pytest.approx(32.97, abs=0.01)
    assert zeta == pytest.approx(1.08, abs=0.005)
    # the quoted Hurwitz limit 72.5 1/s uses the rounded zeta = 1.1 of Table II
    assert 2 * 1.1 * w0 == pytest.approx(72.5, abs=0.1)


def test_exact_linearisation_of_the_rig_side_by_side(situm):
    """The exact tangent model at mid-stroke is of paper 000's form; its w0 and zeta differ.

    Why they differ: the paper puts the supply pressure and kappa = 1.4 into the
    stiffness and ignores dead volume; the nonlinear model rests at the valve's centre
    balance pressure p_e (< supply), with polytropic index k and dead volumes. The
    analytic stiffness of the model, w0^2 = k p_e A^2 (1/V_a + 1/V_b) / M, and
    zeta = beta / (2 M w0), computed here independently, must match the fit exactly.
    """
    op = linearize.operating_point(situm, 0.25)
    lin = linearize.tangent(situm, op)
    red = linearize.reduced_position_model(lin)
    prm = situm.params
    A = situm.area_a
    va = prm["cylinder.dead_volume_a"] + A * 0.25
    vb = prm["cylinder.dead_volume_b"] + A * 0.25
    k = prm["gas.polytropic_index"]
    w0_model = math.sqrt(k * op.p_a * A * A * (1 / va + 1 / vb) / prm["load.mass"])
    zeta_model = prm["load.viscous_friction"] / (2 * prm["load.mass"] * w0_model)
    # fit of an exactly third-order response: agreement to solver precision (1e-8)
    assert red.w0 == pytest.approx(w0_model, rel=1e-8)
    assert red.zeta == pytest.approx(zeta_model, rel=1e-8)
    assert red.fit_error < 1e-8
    # the paper's formula value is higher because p_e < p_supply
    w0_paper = linearize.paper000_w0(A, prm["load.mass"], prm["supply.pressure"], 0.5)
    assert op.p_a < prm["supply.pressure"]
    assert red.w0 < w0_paper
    # Kv: the plant file's valve was sized so that Kv ~ 0.7 m/(V s) (Table II), 2 %
    assert red.kv == pytest.approx(0.7, rel=0.02)


def test_centre_balance_pressure_balances_edge_flows():
    p_e = linearize.centre_balance_pressure(6e5, gas.P_ATM, 0.3)
    q_in = gas.iso6358_flow(1e-8, 0.3, 6e5, p_e)
    q_out = gas.iso6358_flow(1e-8, 0.3, p_e, gas.P_ATM)
    assert q_in == pytest.approx(q_out, rel=1e-9)
    assert gas.P_ATM < p_e < 6e5


def test_operating_point_is_an_equilibrium(situm):
    op = linearize.operating_point(situm, 0.1)
    xdot = situm.evaluate_f(op.state, op.u)
    # exactly zero up to roundoff: the valve is centred and the pressures balanced
    assert np.all(np.abs(xdot) < 1e-6 * np.array([1, 1, 1e5, 1e5]))
    assert op.u == pytest.approx(situm.params["valve.command_center"], abs=1e-9)


def test_rod_cylinder_equilibrium_balances_force():
    plant = Plant.from_toml(PLANTS / "rig25_mpye.toml").with_params(
        **{"cylinder.rod_diameter": 0.010})
    op = linearize.operating_point(plant, 0.2)
    f_net = op.p_a * plant.area_a - op.p_b * plant.area_b - gas.P_ATM * (plant.area_a - plant.area_b)
    # 1e-6 N: the force balance is one of the solved equations (scaled residual 1e-12)
    assert abs(f_net) < 1e-6
    assert op.p_b > op.p_a


def test_tangent_matches_python_control_export(situm):
    lin = linearize.tangent(situm, x=0.25)
    sys = lin.to_control(outputs=["x"])
    assert sys.nstates == 4 and sys.output_labels == ["x"]
    w = np.array([1.0, 10.0, 100.0])
    h_ctrl = np.array([complex(sys(1j * wi)[0, 0]) if np.ndim(sys(1j * wi)) else complex(sys(1j * wi))
                       for wi in w])
    assert np.allclose(h_ctrl, lin.frequency_response(w), rtol=1e-10)


def test_deadband_gives_zero_small_signal_gain(situm):
    plant = situm.with_params(**{"valve.deadband": 0.05})
    lin = linearize.tangent(plant, x=0.25)
    assert np.allclose(lin.B, 0.0)
    with pytest.raises(Exception, match="no small-signal effect"):
        linearize.reduced_position_model(lin)


def test_valve_gain_at_the_centre_matches_central_differences():
    """At the equilibrium the command sits exactly on the valve centre, where the
    openings have a kink. CasADi's derivative there must equal the central difference
    (the mean of the one-sided gains) -- a regression test for a derivative that came
    out 0.75x through an fmin/fmax tie in the deadband clip."""
    from workbench import Plant, linearize
    plant = Plant.from_toml("designs/plants/rig25_mpye.toml")
    op = linearize.operating_point(plant, 0.25)
    lin = linearize.tangent(plant, op)
    h = 1e-6                                       # V; the flow is smooth on each side
    fp = np.asarray(plant.f(op.state, op.u + h, op.params)).ravel()
    fm = np.asarray(plant.f(op.state, op.u - h, op.params)).ravel()
    fd = (fp - fm) / (2 * h)
    # piecewise-smooth: the central difference is exact up to O(h) curvature terms
    np.testing.assert_allclose(lin.B[:, 0], fd, rtol=1e-5, atol=1e-9 * np.abs(fd).max())


def test_supply_droop_equilibrium_has_physical_pressures():
    """A closed-centre valve leaves the chamber pressure level undetermined in the real
    model; the refinement must stay at the pinned (centre balance) level instead of
    drifting. Regression: a supply-droop plant came out at 80 bar in a 6 bar supply."""
    from workbench import Plant, linearize
    plant = Plant.from_toml("designs/plants/rig25_mpye.toml").with_params(
        **{"supply.reservoir_volume": 7e-4, "supply.regulator_conductance": 4.6e-9})
    op = linearize.operating_point(plant, 0.2)
    p_atm, p_s = plant.params["gas.atmospheric_pressure"], plant.params["supply.pressure"]
    assert p_atm < op.p_a < p_s and p_atm < op.p_b < p_s
    # no flow at rest, so the reservoir sits at the regulator's set pressure
    assert dict(zip(op.state_names, op.state))["p_s"] == pytest.approx(p_s, rel=1e-9)
