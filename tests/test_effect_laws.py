"""Every effect law of :mod:`workbench.physics`, and its wiring in the plant, against hand values.

Each expected value below is computed in the test from a formula typed from
``/work/shared/spec/physics.md`` or a named textbook source, with plain ``math``;
nothing is taken from the code under test. Points are chosen so that a sign, a
swapped temperature or a dropped factor changes the result by far more than the
tolerance: flows in both directions, chambers at different temperatures (T_a != T_b),
velocities of both signs.

Tolerances: where the package evaluates the same formula in another arrangement,
the difference is roundoff of a few dozen operations, so ``REL = 1e-12`` (a wrong
factor, sign or variable shows as >= 1e-3). Stated otherwise where it differs.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from workbench import Plant
from workbench.physics import chamber, friction, line, piston, supply, valve

from conftest import DATA, write_plant

# Air and ISO 6358 reference conditions, typed from physics.md (not imported).
R = 287.0
GAMMA = 1.4
T0 = 293.15
RHO0 = 1.185
P_ATM = 101325.0
B_NOZZLE = (2.0 / (GAMMA + 1.0)) ** (GAMMA / (GAMMA - 1.0))   # 0.528, physics.md
MU_AIR = 1.81e-5   # Pa s, dynamic viscosity of air at 20 degC (handbook value)

#: Same formula, other arrangement: roundoff of a few dozen operations.
REL = 1e-12


def iso(c, b, p1, p2, t1=T0, t2=T0):
    """ISO 6358-1 mass flow (physics.md), positive from side 1 to side 2.

    Upstream is the side of higher pressure, with its own temperature. Valid for
    ratios below 0.995 (outside the package's laminar patch); every point of this
    file stays there.
    """
    if p1 < p2:
        return -iso(c, b, p2, p1, t2, t1)
    x = p2 / p1
    assert x < 0.995, "hand formula used inside the laminar patch"
    psi = 1.0 if x <= b else math.sqrt(1.0 - ((x - b) / (1.0 - b)) ** 2)
    return c * p1 * RHO0 * math.sqrt(T0 / t1) * psi


# ====================================================================== supply.py
@pytest.mark.parametrize("p, t", [(3.0e5, 293.15), (1.3e5, 330.0), (7.0e5, 280.0)])
def test_leak_to_atmosphere_carries_air_out_of_a_chamber_above_atmosphere(p, t):
    c = 1e-10
    q = supply.leak_to_atmosphere(p, P_ATM, c, t)
    # ISO 6358-1 from the chamber (upstream, at its temperature) to atmosphere.
    expected = iso(c, B_NOZZLE, p, P_ATM, t, t)
    assert expected > 0
    assert q == pytest.approx(expected, rel=REL)


def test_leak_below_atmosphere_draws_air_in():
    c, p = 1e-10, 0.6e5          # chamber evacuated below atmosphere
    q = supply.leak_to_atmosphere(p, P_ATM, c, 293.15)
    assert q < 0
    assert q == pytest.approx(iso(c, B_NOZZLE, p, P_ATM), rel=REL)
    # The leak uses the given critical ratio: with b = 0.8, 1.3 bar -> 1 atm is choked.
    q_b = supply.leak_to_atmosphere(1.3e5, P_ATM, c, 293.15, b=0.8)
    assert q_b == pytest.approx(c * 1.3e5 * RHO0, rel=REL)


@pytest.mark.parametrize("p_a, p_b", [(4e5, 2e5), (1.5e5, 5.5e5), (3e5, 3e5)])
def test_cross_piston_leak_flows_from_high_to_low(p_a, p_b):
    c = 1e-9   # kg/(s Pa), laminar gap
    q = supply.cross_piston_leak(p_a, p_b, c)
    # Laminar (Hagen-Poiseuille) gap: q = c (p_a - p_b), positive from a to b.
    assert q == pytest.approx(c * (p_a - p_b), rel=1e-15, abs=0.0)
    assert math.copysign(1.0, q) == math.copysign(1.0, p_a - p_b) or p_a == p_b


@pytest.mark.parametrize("p_s, q_out, k", [(5.5e5, 3e-3, 1.0), (6e5, 0.0, 1.0),
                                           (2e5, 1e-2, 1.4), (5.9e5, 1e-3, 1.2)])
def test_reservoir_rate(p_s, q_out, k):
    p_set, c_reg, vol, t = 6e5, 1e-7, 1e-3, 300.0
    # Ideal gas in a fixed volume: dp/dt = k R T / V (q_in - q_out), q_in the
    # regulator's ISO 6358 flow from the set pressure into the reservoir.
    q_in = iso(c_reg, B_NOZZLE, p_set, p_s, t, t) if p_s < p_set * 0.995 else 0.0
    expected = k * R * t / vol * (q_in - q_out)
    got = supply.reservoir_rate(p_s, p_set, c_reg, vol, q_out, t, k=k)
    assert got == pytest.approx(expected, rel=REL, abs=1e-9)
    if q_out == 0.0 and p_s == p_set:
        assert got == 0.0        # no flow, no droop
    if p_s < p_set * 0.995 and q_out == 0.0:
        assert got > 0           # the regulator refills a sagging reservoir


def test_reservoir_refills_towards_set_pressure():
    # Sign: below the set pressure with no draw it rises; above it (regulator back-flow) it falls.
    assert supply.reservoir_rate(5e5, 6e5, 1e-7, 1e-3, 0.0, T0) > 0
    assert supply.reservoir_rate(6.5e5, 6e5, 1e-7, 1e-3, 0.0, T0) < 0


# ====================================================================== chamber.py
def test_volumes():
    A_a, A_b, L, d_a, d_b = 4.9e-4, 4.1e-4, 0.5, 5e-6, 7e-6
    va, vb, dva, dvb = chamber.volumes(0.2, -0.3, A_a, A_b, L, d_a, d_b)
    assert (va, vb, dva, dvb) == pytest.approx(
        (d_a + A_a * 0.2, d_b + A_b * 0.3, A_a * -0.3, -A_b * -0.3), rel=1e-15)


@pytest.mark.parametrize("q, dv", [(2e-3, 0.0), (-1e-3, 5e-5), (0.0, -3e-5)])
def test_pressure_rate_polytropic(q, dv):
    p, vol, k, t = 3.3e5, 8e-5, 1.2, 310.0
    # Polytropic filling (physics.md): dp/dt = k/V (r T q - p dV/dt).
    expected = k / vol * (R * t * q - p * dv)
    assert chamber.pressure_rate(p, vol, dv, q, k, t) == pytest.approx(expected, rel=REL)
    # and its inverse returns the inflow
    dp = chamber.pressure_rate(p, vol, dv, q, k, t)
    assert chamber.inflow_for_pressure_rate(p, vol, dv, dp, k, t) == pytest.approx(
        q, rel=1e-10, abs=1e-15)
    # Sign: inflow into a fixed chamber raises its pressure; expansion lowers it.
    if dv == 0.0:
        assert math.copysign(1.0, expected) == math.copysign(1.0, q)


def test_chamber_mass_ideal_gas():
    # Ideal gas: m = p V / (r T).
    assert chamber.chamber_mass(4e5, 1e-4, 300.0) == pytest.approx(4e5 * 1e-4 / (R * 300.0),
                                                                   rel=1e-15)


def energy_balance(p, t, vol, dv, inflows, q_out, h, t_wall):
    """Open-system energy and mass balance of an ideal gas (any thermodynamics text,
    e.g. Cengel & Boles ch. 5), written in U and m, not in the package's form.

    U = c_v m T = p V / (gamma - 1); dU/dt = c_p sum(T_k q_k) - c_p T q_out - p dV/dt
    + h (T_w - T); dm/dt = sum q_k - q_out. Then p = (gamma-1) U/V and T = U/(c_v m).
    """
    cv, cp = R / (GAMMA - 1.0), GAMMA * R / (GAMMA - 1.0)
    m = p * vol / (R * t)
    du = (cp * sum(q * tk for q, tk in inflows) - cp * t * q_out - p * dv
          + h * (t_wall - t))
    dm = sum(q for q, _ in inflows) - q_out
    dp = ((GAMMA - 1.0) * du - p * dv) / vol
    dt = (du - cv * t * dm) / (cv * m)
    return dp, dt


@pytest.mark.parametrize("t, t_wall, inflows, q_out, dv", [
    (330.0, 293.15, [], 0.0, 0.0),                     # hot gas, closed: cools, p falls
    (270.0, 293.15, [], 0.0, 0.0),                     # cold gas, closed: warms, p rises
    (301.0, 293.15, [(2e-3, 293.15)], 0.0, 2e-5),      # filling while expanding
    (287.0, 293.15, [(1e-3, 310.0)], 1.5e-3, -3e-5),   # through-flow, compressed
])
def test_pressure_temperature_rates_energy_balance(t, t_wall, inflows, q_out, dv):
    p, vol, h = 3.4e5, 9e-5, 0.5
    q_in = sum(q for q, _ in inflows)
    tq = sum(q * tk for q, tk in inflows)
    dp, dt = chamber.pressure_temperature_rates(p, t, vol, dv, tq, q_in, q_out, h, t_wall)
    dp_ref, dt_ref = energy_balance(p, t, vol, dv, inflows, q_out, h, t_wall)
    # dT/dt is a difference of terms up to ~1e4 times larger (K/s of compression vs
    # the net): roundoff relative to the largest term, hence the absolute part.
    assert dp == pytest.approx(dp_ref, rel=REL)
    assert dt == pytest.approx(dt_ref, rel=1e-10, abs=1e-9)
    if not inflows and q_out == 0.0 and dv == 0.0:
        # Heat flows from hot to cold: the sign of the wall term is visible alone.
        assert math.copysign(1.0, dp) == math.copysign(1.0, t_wall - t)
        assert math.copysign(1.0, dt) == math.copysign(1.0, t_wall - t)
        # closed rigid chamber: dp/dt = (gamma - 1) h (T_w - T) / V exactly
        assert dp == pytest.approx((GAMMA - 1.0) * h * (t_wall - t) / vol, rel=REL)


# ====================================================================== valve.py
C_V, B_V = 6.25e-8, 0.23   # Festo MPYE-5-1/4 datasheet pair (physics.md)


def four_edge_hand(o, p_s, p_a, p_b, t_s, t_a, t_b, d=0.0, law="linear"):
    """The 5/3 valve of physics.md: edges S->A and B->E open with max(o, 0), A->E and
    S->B with max(-o, 0); each edge an ISO 6358 restriction whose upstream gas has
    its own side's temperature (exhaust at atmosphere: T0)."""
    if law == "linear":
        op, om = max(o, 0.0) + d, max(-o, 0.0) + d
    else:
        r = math.sqrt(o * o + d * d)
        op, om = (r + o) / 2, (r - o) / 2
    s_a = op * iso(C_V, B_V, p_s, p_a, t_s, t_a)
    a_e = om * iso(C_V, B_V, p_a, P_ATM, t_a, T0)
    s_b = om * iso(C_V, B_V, p_s, p_b, t_s, t_b)
    b_e = op * iso(C_V, B_V, p_b, P_ATM, t_b, T0)
    return s_a - a_e, s_b - b_e, s_a + s_b


# T_a != T_b != T_s everywhere: a swapped temperature changes a flow by >= 4 %.
_EDGE_POINTS = [
    # o,    p_s,   p_a,    p_b,    t_s,   t_a,   t_b,   d
    (0.6, 6e5, 3.0e5, 2.5e5, 293.15, 330.0, 270.0, 0.0),   # fill A, exhaust B (uses t_b)
    (-0.4, 6e5, 3.0e5, 2.5e5, 293.15, 330.0, 270.0, 0.0),  # exhaust A (uses t_a), fill B
    (1.0, 6e5, 1.5e5, 5.0e5, 305.0, 280.0, 340.0, 0.0),    # choked fill, B exhaust subsonic
    (0.3, 6e5, 6.4e5, 0.9e5, 300.0, 350.0, 260.0, 0.05),   # A above supply, B below atm
    (-0.2, 6e5, 2.0e5, 4.0e5, 293.15, 320.0, 275.0, 0.05), # all four edges pass flow
]


@pytest.mark.parametrize("o, p_s, p_a, p_b, t_s, t_a, t_b, d", _EDGE_POINTS)
def test_four_edge_flows_with_unequal_chamber_temperatures(o, p_s, p_a, p_b, t_s, t_a, t_b, d):
    got = valve.four_edge_flows(o, p_s, p_a, p_b, P_ATM, C_V, B_V, t_s, t_a, t_b, d)
    expected = four_edge_hand(o, p_s, p_a, p_b, t_s, t_a, t_b, d)
    assert got == pytest.approx(expected, rel=REL)


def test_four_edge_flow_directions():
    # Positive opening fills A and exhausts B (physics.md); negative the reverse.
    q_a, q_b, q_s = valve.four_edge_flows(0.5, 6e5, 3e5, 3e5, P_ATM, C_V, B_V,
                                          T0, 330.0, 270.0)
    assert q_a > 0 > q_b and q_s == pytest.approx(q_a, rel=1e-15)
    # The exhaust of B is B's own gas: colder gas is denser, so it leaves faster,
    # by sqrt(T_a/T_b) against the same valve with B at A's temperature.
    q_b_hot = valve.four_edge_flows(0.5, 6e5, 3e5, 3e5, P_ATM, C_V, B_V, T0, 330.0, 330.0)[1]
    assert q_b / q_b_hot == pytest.approx(math.sqrt(330.0 / 270.0), rel=REL)
    q_a, q_b, _ = valve.four_edge_flows(-0.5, 6e5, 3e5, 3e5, P_ATM, C_V, B_V,
                                        T0, 330.0, 270.0)
    assert q_b > 0 > q_a
    q_a_cold = valve.four_edge_flows(-0.5, 6e5, 3e5, 3e5, P_ATM, C_V, B_V, T0, 270.0, 270.0)[0]
    assert q_a / q_a_cold == pytest.approx(math.sqrt(270.0 / 330.0), rel=REL)
    # A chamber above supply pushes back into the supply line (reverse S->A edge).
    assert valve.four_edge_flows(0.5, 6e5, 6.5e5, 3e5, P_ATM, C_V, B_V)[0] < 0


@pytest.mark.parametrize("o", [-0.7, -0.02, 0.0, 0.01, 0.5])
def test_four_edge_flows_rounded_underlap(o):
    args = (6e5, 3.2e5, 2.7e5, 300.0, 325.0, 275.0)
    got = valve.four_edge_flows(o, args[0], args[1], args[2], P_ATM, C_V, B_V, *args[3:],
                                underlap=0.04, underlap_law="rounded")
    assert got == pytest.approx(four_edge_hand(o, *args, d=0.04, law="rounded"), rel=REL)


@pytest.mark.parametrize("u, offset, expected", [
    (7.5, 0.0, 0.5), (2.0, 0.0, -0.6), (12.0, 0.0, 1.0), (-3.0, 0.0, -1.0),
    (5.1, 0.1, 0.0), (7.6, 0.1, 0.5)])
def test_spool_position(u, offset, expected):
    # s = (u - center - offset)/span clipped to [-1, 1] (physics.md); center 5 V, span 5 V.
    assert valve.spool_position(u, 5.0, 5.0, offset) == pytest.approx(expected, abs=1e-15)


@pytest.mark.parametrize("s", [-1.0, -0.5, -0.05, -0.01, 0.0, 0.03, 0.2, 1.0])
def test_effective_opening_deadband(s):
    d = 0.05
    # physics.md: opening = sign(s) max(|s| - d, 0)/(1 - d).
    expected = math.copysign(max(abs(s) - d, 0.0) / (1.0 - d), s)
    assert valve.effective_opening(s, d) == pytest.approx(expected, abs=1e-15)
    assert valve.effective_opening(s, 0.0) == s


def test_spool_dynamics_hand_values():
    f_bw, zeta = 100.0, 0.7
    w = 2 * math.pi * f_bw
    for y, ydot, u in [(5.0, 0.0, 6.0), (6.0, 300.0, 6.0), (4.0, -250.0, 7.0)]:
        # Second-order lag: y'' = w^2 (u - y) - 2 zeta w y'.
        d1, d2 = valve.spool_dynamics(y, ydot, u, f_bw, zeta)
        assert d1 == ydot
        assert d2 == pytest.approx(w * w * (u - y) - 2 * zeta * w * ydot, rel=REL)


def test_spool_dynamics_poles_have_the_bandwidth_and_damping():
    """The linear system's poles: |lambda| = w = 2 pi f and -Re(lambda)/|lambda| = zeta
    (textbook second-order system), from the law's numeric Jacobian."""
    f_bw, zeta = 100.0, 0.7
    h = 1e-3
    cols = []
    for e in ((h, 0.0), (0.0, h)):
        plus = valve.spool_dynamics(e[0], e[1], 0.0, f_bw, zeta)
        minus = valve.spool_dynamics(-e[0], -e[1], 0.0, f_bw, zeta)
        cols.append([(a - b) / (2 * h) for a, b in zip(plus, minus)])
    lam = np.linalg.eigvals(np.array(cols).T)
    # The law is linear: central differences are exact up to roundoff (1e-9 relative).
    assert np.abs(lam) == pytest.approx([2 * math.pi * f_bw] * 2, rel=1e-9)
    assert -lam.real / np.abs(lam) == pytest.approx([zeta] * 2, rel=1e-9)


def test_affine_port_flows_hand_values():
    phi, psi_in, psi_out, g = (1e-5, -2e-6), (4e-3, 1e-4, -3e-5), (3e-3, 5e-4), (1.1, -0.2)

    def poly(c, x):
        return sum(ci * x ** i for i, ci in enumerate(c))

    def gam(s):
        return g[0] * s + g[1] * s * abs(s)

    p_a, p_b = 3.2e5, 2.1e5
    for o in (0.6, -0.35):
        q_a, q_b, q_s = valve.affine_port_flows(o, p_a, p_b, phi, psi_in, psi_out, g)
        # paper 003 eq. 5 at each port; port b sees Gamma(-o) = -Gamma(o).
        ga = gam(o)
        qa = poly(phi, 3.2) + (poly(psi_in, 3.2) if ga >= 0 else poly(psi_out, 3.2)) * ga
        qb = poly(phi, 2.1) + (poly(psi_in, 2.1) if -ga >= 0 else poly(psi_out, 2.1)) * -ga
        assert (q_a, q_b) == pytest.approx((qa, qb), rel=REL)
        assert q_s == pytest.approx(max(qa, 0.0) + max(qb, 0.0), rel=REL)
        assert (q_a > 0 > q_b) == (o > 0)
    # underlap leak: d Gamma(1) (psi_in(p) - psi_out(p)) added at each port
    d = 1e-3
    q_a, q_b, _ = valve.affine_port_flows(0.0, p_a, p_b, phi, psi_in, psi_out, g, underlap=d)
    assert q_a == pytest.approx(poly(phi, 3.2) + d * gam(1.0) * (poly(psi_in, 3.2)
                                                                - poly(psi_out, 3.2)), rel=REL)
    assert q_b == pytest.approx(poly(phi, 2.1) + d * gam(1.0) * (poly(psi_in, 2.1)
                                                                - poly(psi_out, 2.1)), rel=REL)


# ====================================================================== friction.py
FC, FS, VS, BETA = 20.0, 30.0, 0.01, 40.0


@pytest.mark.parametrize("v", [0.0, 0.005, -0.005, 0.01, -0.02, 0.03])
def test_stribeck_level(v):
    # Stribeck curve (Armstrong-Helouvry 1991; physics.md: F_c, F_s, v_s):
    # F = F_c + (F_s - F_c) exp(-(v/v_s)^2).
    expected = FC + (FS - FC) * math.exp(-(v / VS) ** 2)
    assert friction.stribeck_level(v, FC, FS, VS) == pytest.approx(expected, rel=REL)


def test_stribeck_level_landmarks():
    # v = 0: static level; v = v_s: F_c + (F_s - F_c)/e; v = 2 v_s: exp(-4) of the excess.
    assert friction.stribeck_level(0.0, FC, FS, VS) == FS
    assert friction.stribeck_level(VS, FC, FS, VS) == pytest.approx(FC + 10.0 / math.e, rel=REL)
    assert friction.stribeck_level(2 * VS, FC, FS, VS) == pytest.approx(
        FC + 10.0 * math.exp(-4.0), rel=REL)
    assert friction.stribeck_level(-2 * VS, FC, FS, VS) == pytest.approx(
        FC + 10.0 * math.exp(-4.0), rel=REL)


@pytest.mark.parametrize("v", [0.05, -0.002, 1e-4, 0.0])
def test_smooth_friction(v):
    vsm = 1e-3
    level = FC + (FS - FC) * math.exp(-(v / VS) ** 2)
    expected = level * math.tanh(v / vsm) + BETA * v
    got = friction.smooth_friction(v, FC, FS, VS, BETA, vsm)
    assert got == pytest.approx(expected, rel=REL, abs=1e-15)
    assert math.copysign(1.0, got) == math.copysign(1.0, v) or v == 0.0   # opposes motion


@pytest.mark.parametrize("v, force, expected_kind", [
    (0.0, 25.0, "stick"), (5e-5, -29.0, "stick"),          # below break-away: held
    (0.0, 45.0, "break"), (-5e-5, -50.0, "break"),         # above: breaks away
    (0.02, 10.0, "slip"), (-0.015, 60.0, "slip"), (0.3, -5.0, "slip")])
def test_stick_slip_acceleration(v, force, expected_kind):
    m, tau = 1.2, friction.STICK_TIME_CONSTANT
    # Karnopp (1985) stick-slip: inside |v| < v_stick the piston sticks unless the
    # drive exceeds static friction; outside, Stribeck + viscous opposes the motion.
    if expected_kind == "stick":
        expected = -v / tau
    elif expected_kind == "break":
        expected = (force - math.copysign(FS, force)) / m
    else:
        level = FC + (FS - FC) * math.exp(-(v / VS) ** 2)
        expected = (force - math.copysign(level, v) - BETA * v) / m
    got = friction.stick_slip_acceleration(v, force, m, BETA, FC, FS, VS)
    assert got == pytest.approx(expected, rel=REL, abs=1e-15)


# ====================================================================== line.py
def pressure_drop_hand(q, p, d, seg, t):
    """Darcy-Weisbach friction of a pipe segment: laminar Hagen-Poiseuille
    32 mu L v / d^2 plus turbulent Blasius f = 0.316 Re^-0.25 (White, Fluid Mechanics,
    eq. 6.55: dp = f L/d rho v|v|/2),
    v = q/(rho A), rho = p/(R T), Re = rho |v| d / mu. Opposes the flow."""
    area = math.pi * d * d / 4.0
    rho = p / (R * t)
    vel = q / (rho * area)
    lam = 32.0 * MU_AIR * seg * vel / d ** 2
    if vel == 0.0:
        return 0.0
    re = rho * abs(vel) * d / MU_AIR
    turb = 0.316 * re ** -0.25 * seg / d * rho * vel * abs(vel) / 2.0
    return lam + turb


@pytest.mark.parametrize("q", [2e-3, -5e-4, 1e-5, 0.0])
def test_pressure_drop(q):
    p, d, seg, t = 3e5, 0.004, 0.25, 293.15
    got = line.pressure_drop(q, p, d, seg, t)
    # The package smooths |v| as sqrt(v^2 + 1e-12): relative change 5e-13 / v^2 in the
    # Blasius term, 1e-11 at the smallest flow here (1e-5 kg/s: v = 0.22 m/s); the
    # rest is roundoff. Tolerance 1e-9.
    assert got == pytest.approx(pressure_drop_hand(q, p, d, seg, t), rel=1e-9, abs=1e-12)
    # Sign: friction opposes the flow.
    assert math.copysign(1.0, got) == math.copysign(1.0, q) or q == 0.0
    # Laminar limit: at tiny flows the drop is Hagen-Poiseuille's alone.
    q_small = 1e-9
    rho = p / (R * t)
    v_small = q_small / (rho * math.pi * d * d / 4)
    assert line.pressure_drop(q_small, p, d, seg, t) == pytest.approx(
        32 * MU_AIR * seg * v_small / d ** 2, rel=1e-3)


def test_line_rates_two_segments():
    n, length, d, t = 2, 1.0, 0.004, 293.15
    p_nodes, q_flows, q_in, p_end = [4.0e5, 3.6e5], [1.5e-3, -4e-4], 2e-3, 3.3e5
    dp, dq = line.line_rates(p_nodes, q_flows, q_in, p_end, length, d, t)
    area, seg = math.pi * d * d / 4, length / n
    vol = area * seg
    # Node: adiabatic (the wave travels at a = sqrt(gamma R T)), dp_j/dt = a^2/V (in - out).
    a2 = GAMMA * R * t
    exp_dp = [a2 / vol * (q_in - q_flows[0]), a2 / vol * (q_flows[0] - q_flows[1])]
    # Segment momentum: L/A dq/dt = p_j - p_{j+1} - friction drop (at the mean pressure).
    exp_dq = [area / seg * (p_nodes[0] - p_nodes[1]
                            - line.pressure_drop(q_flows[0], 3.8e5, d, seg, t)),
              area / seg * (p_nodes[1] - p_end
                            - line.pressure_drop(q_flows[1], 3.45e5, d, seg, t))]
    assert dp == pytest.approx(exp_dp, rel=REL)
    assert dq == pytest.approx(exp_dq, rel=REL)
    # ... and with the hand friction (independent of line.pressure_drop):
    hand = [area / seg * (p_nodes[0] - p_nodes[1]
                          - pressure_drop_hand(q_flows[0], 3.8e5, d, seg, t)),
            area / seg * (p_nodes[1] - p_end
                          - pressure_drop_hand(q_flows[1], 3.45e5, d, seg, t))]
    # (the hand friction agrees to 1e-9 of the drop, see test_pressure_drop)
    assert dq == pytest.approx(hand, rel=1e-9)


def test_line_friction_decelerates_a_flow_without_pressure_difference():
    # Equal pressures along the line: only friction acts, and it opposes each flow.
    dp, dq = line.line_rates([3e5, 3e5], [1e-3, -1e-3], 0.0, 3e5, 1.0, 0.004, T0)
    assert dq[0] < 0 < dq[1]


# ====================================================================== piston.py
def test_pneumatic_force_with_a_rod():
    A_a, A_b = math.pi / 4 * 0.025 ** 2, math.pi / 4 * (0.025 ** 2 - 0.01 ** 2)
    # Newton on the piston (physics.md): p_a A_a - p_b A_b - p_atm (A_a - A_b).
    for p_a, p_b in [(4e5, 3e5), (2e5, 5e5)]:
        expected = p_a * A_a - p_b * A_b - P_ATM * (A_a - A_b)
        assert piston.pneumatic_force(p_a, p_b, A_a, A_b, P_ATM) == pytest.approx(expected,
                                                                                  rel=REL)
    # both chambers at atmosphere: no force, rod or not
    assert piston.pneumatic_force(P_ATM, P_ATM, A_a, A_b, P_ATM) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("x, v", [(-1e-4, -0.2), (-1e-4, 5.0), (0.5 + 2e-4, 0.1),
                                  (0.5 + 2e-4, -5.0), (0.25, 1.0)])
def test_end_stop_force(x, v):
    L, m = 0.5, 1.2
    w = 2 * math.pi * piston.STOP_FREQUENCY
    k, c = m * w * w, 2 * piston.STOP_DAMPING * m * w
    # Spring-damper contact that only pushes back (unilateral, Hunt-Crossley-like).
    if x < 0:
        expected = max(-k * x - c * v, 0.0)
    elif x > L:
        expected = min(-k * (x - L) - c * v, 0.0)
    else:
        expected = 0.0
    got = piston.end_stop_force(x, v, L, m)
    assert got == pytest.approx(expected, rel=REL, abs=1e-12)
    if x < 0 and v < 0:
        assert got > 0        # pushes back into the stroke
    if x > L and v > 0:
        assert got < 0


# ====================================================================== the composed plant
_K, _T, _V_DEAD = 1.2, 293.15, 5e-6          # conftest.BASE
_AREA = math.pi / 4 * 0.025 ** 2


def _plant(tmp_path, effects, overrides=None, friction="stick"):
    return Plant.from_toml(write_plant(tmp_path / "p.toml", effects, overrides or {}),
                           friction=friction)


def _f(plant, values, u):
    x = np.array([values[n] for n in plant.state_names], dtype=float)
    return dict(zip(plant.state_names, np.asarray(plant.f(x, u, plant.p0)).ravel()))


def test_plant_leakage_rows(tmp_path):
    """At v = 0 with the valve closed, dp_a/dt = k R T / V_a (-q_leak_a - q_cross),
    dp_b/dt = k R T / V_b (-q_leak_b + q_cross) (polytropic chamber, physics.md)."""
    plant = _plant(tmp_path, ["leakage"])
    c_atm, c_x = 1e-10, 1e-9                 # conftest.EFFECT_KEYS["leakage"]
    x, p_a, p_b = 0.2, 4.0e5, 2.5e5
    d = _f(plant, {"x": x, "v": 0.0, "p_a": p_a, "p_b": p_b}, 5.0)
    v_a, v_b = _V_DEAD + _AREA * x, _V_DEAD + _AREA * (0.5 - x)
    leak_a, leak_b = iso(c_atm, B_NOZZLE, p_a, P_ATM), iso(c_atm, B_NOZZLE, p_b, P_ATM)
    cross = c_x * (p_a - p_b)
    assert d["p_a"] == pytest.approx(_K * R * _T / v_a * (-leak_a - cross), rel=REL)
    assert d["p_b"] == pytest.approx(_K * R * _T / v_b * (-leak_b + cross), rel=REL)
    assert d["p_a"] < 0                      # both leaks empty the high chamber


@pytest.mark.parametrize("p_a, p_b, t_a, t_b, u, v", [
    (2.2e5, 3.5e5, 310.0, 275.0, 7.0, 0.1),      # fill A, exhaust B, cross leak b -> a
    (4.1e5, 1.8e5, 270.0, 335.0, 2.5, -0.2),     # exhaust A, fill B, cross leak a -> b
])
def test_plant_heat_transfer_rows_with_open_valve_and_cross_leak(tmp_path, p_a, p_b, t_a, t_b,
                                                                 u, v):
    """Energy balance of each chamber (see :func:`energy_balance`): supply air enters at
    the gas temperature, an exhausting chamber loses its own gas, the cross leak carries
    the upstream chamber's gas (at that chamber's temperature) and the walls are at the
    gas temperature."""
    plant = _plant(tmp_path, ["heat_transfer", "leakage"])
    h, c_atm, c_x, x = 0.5, 1e-10, 1e-9, 0.2
    d = _f(plant, {"x": x, "v": v, "p_a": p_a, "p_b": p_b, "T_a": t_a, "T_b": t_b}, u)
    q_a, q_b, _ = four_edge_hand((u - 5.0) / 5.0, 6e5, p_a, p_b, _T, t_a, t_b)
    cross = c_x * (p_a - p_b)                # > 0: a -> b
    leak_a = iso(c_atm, B_NOZZLE, p_a, P_ATM, t_a, t_a)
    leak_b = iso(c_atm, B_NOZZLE, p_b, P_ATM, t_b, t_b)
    v_a, v_b = _V_DEAD + _AREA * x, _V_DEAD + _AREA * (0.5 - x)
    in_a = [(max(q_a, 0.0), _T), (max(-cross, 0.0), t_b)]
    in_b = [(max(q_b, 0.0), _T), (max(cross, 0.0), t_a)]
    out_a = max(-q_a, 0.0) + max(cross, 0.0) + leak_a
    out_b = max(-q_b, 0.0) + max(-cross, 0.0) + leak_b
    dp_a, dt_a = energy_balance(p_a, t_a, v_a, _AREA * v, in_a, out_a, h, _T)
    dp_b, dt_b = energy_balance(p_b, t_b, v_b, -_AREA * v, in_b, out_b, h, _T)
    assert (d["p_a"], d["p_b"]) == pytest.approx((dp_a, dp_b), rel=1e-11)
    # dT/dt: differences of large terms, roundoff relative to R T q / (c_v m) ~ 1e3 K/s
    assert (d["T_a"], d["T_b"]) == pytest.approx((dt_a, dt_b), rel=1e-9, abs=1e-7)


def test_plant_heat_transfer_closed_valve_wall_term(tmp_path):
    plant = _plant(tmp_path, ["heat_transfer"])
    h, x, p_a, p_b, t_a, t_b = 0.5, 0.3, 3e5, 3e5, 330.0, 260.0
    d = _f(plant, {"x": x, "v": 0.0, "p_a": p_a, "p_b": p_b, "T_a": t_a, "T_b": t_b}, 5.0)
    v_a, v_b = _V_DEAD + _AREA * x, _V_DEAD + _AREA * (0.5 - x)
    # closed rigid chamber: dp/dt = (gamma - 1) h (T_w - T)/V, dT/dt = T dp/dt / p
    assert d["p_a"] == pytest.approx((GAMMA - 1) * h * (_T - t_a) / v_a, rel=REL)
    assert d["p_b"] == pytest.approx((GAMMA - 1) * h * (_T - t_b) / v_b, rel=REL)
    assert d["T_a"] == pytest.approx(t_a * d["p_a"] / p_a, rel=REL)
    assert d["T_a"] < 0 < d["T_b"]           # hot A cools, cold B warms


def test_plant_supply_droop_row(tmp_path):
    plant = _plant(tmp_path, ["supply_droop"])
    vol, c_reg = 1e-3, 1e-7                  # conftest.EFFECT_KEYS["supply_droop"]
    x, p_a, p_b, p_s, u = 0.25, 2.0e5, 4.0e5, 5.2e5, 3.0
    d = _f(plant, {"x": x, "v": 0.0, "p_a": p_a, "p_b": p_b, "p_s": p_s}, u)
    o = (u - 5.0) / 5.0                      # fills B from the reservoir
    q_sup = -o * iso(C_V, B_V, p_s, p_b)
    q_reg = iso(c_reg, B_NOZZLE, 6e5, p_s)
    assert d["p_s"] == pytest.approx(_K * R * _T / vol * (q_reg - q_sup), rel=REL)
    # the chamber is fed from the reservoir's pressure, not the set pressure
    v_b = _V_DEAD + _AREA * (0.5 - x)
    assert d["p_b"] == pytest.approx(_K * R * _T / v_b * q_sup, rel=REL)
    # outputs: the reservoir pressure, the supply draw and the piston force (rodless)
    y = dict(zip(plant.output_names, plant.evaluate_h(
        [x, 0.0, p_a, p_b, p_s], u)))
    assert y["p_s"] == p_s
    assert y["q_supply"] == pytest.approx(q_sup, rel=REL)
    assert y["force"] == pytest.approx(_AREA * (p_a - p_b), rel=REL)


def test_plant_line_rows(tmp_path):
    plant = _plant(tmp_path, ["line_dynamics"], {"lines.segments": 2})
    length, diam = 1.0, 0.004
    x, p_a, p_b, u = 0.25, 2.5e5, 3.5e5, 6.0
    vals = {"x": x, "v": 0.0, "p_a": p_a, "p_b": p_b,
            "line_a_p0": 3.0e5, "line_a_p1": 2.7e5, "line_a_q0": 1e-3, "line_a_q1": 8e-4,
            "line_b_p0": 3.2e5, "line_b_p1": 3.4e5, "line_b_q0": -6e-4, "line_b_q1": -7e-4}
    d = _f(plant, vals, u)
    o = (u - 5.0) / 5.0
    q_va = o * iso(C_V, B_V, 6e5, vals["line_a_p0"])           # valve feeds node 0
    q_vb = -o * iso(C_V, B_V, vals["line_b_p0"], P_ATM)
    area, seg = math.pi * diam ** 2 / 4, length / 2
    a2v = GAMMA * R * _T / (area * seg)
    for side, q_v, p_end in (("a", q_va, p_a), ("b", q_vb, p_b)):
        p0_, p1_ = vals[f"line_{side}_p0"], vals[f"line_{side}_p1"]
        q0, q1 = vals[f"line_{side}_q0"], vals[f"line_{side}_q1"]
        assert d[f"line_{side}_p0"] == pytest.approx(a2v * (q_v - q0), rel=REL)
        assert d[f"line_{side}_p1"] == pytest.approx(a2v * (q0 - q1), rel=REL)
        # friction from the hand Darcy-Weisbach form (1e-9 of the drop, see
        # test_pressure_drop)
        assert d[f"line_{side}_q0"] == pytest.approx(
            area / seg * (p0_ - p1_ - pressure_drop_hand(q0, (p0_ + p1_) / 2, diam, seg, _T)),
            rel=1e-9)
        assert d[f"line_{side}_q1"] == pytest.approx(
            area / seg * (p1_ - p_end - pressure_drop_hand(q1, (p1_ + p_end) / 2, diam, seg,
                                                           _T)), rel=1e-9)
    # The chambers are fed by the last segment, not by the valve.
    v_a, v_b = _V_DEAD + _AREA * x, _V_DEAD + _AREA * (0.5 - x)
    assert d["p_a"] == pytest.approx(_K * R * _T / v_a * vals["line_a_q1"], rel=REL)
    assert d["p_b"] == pytest.approx(_K * R * _T / v_b * vals["line_b_q1"], rel=REL)


def test_plant_valve_dynamics_deadband_offset_rows(tmp_path):
    plant = _plant(tmp_path, ["valve_dynamics", "valve_deadband", "valve_offset"])
    f_bw, zeta, dead, off = 100.0, 0.7, 0.05, 0.1
    w = 2 * math.pi * f_bw
    x, p_a, p_b, spool, rate, u = 0.3, 2.5e5, 3.0e5, 7.1, -120.0, 4.0
    d = _f(plant, {"x": x, "v": 0.0, "p_a": p_a, "p_b": p_b, "spool": spool,
                   "spool_rate": rate}, u)
    assert d["spool"] == rate
    assert d["spool_rate"] == pytest.approx(w * w * (u - spool) - 2 * zeta * w * rate, rel=REL)
    # The valve opens with the spool (not the command), after offset and deadband.
    s = (spool - 5.0 - off) / 5.0
    o = (abs(s) - dead) / (1 - dead)
    v_a, v_b = _V_DEAD + _AREA * x, _V_DEAD + _AREA * (0.5 - x)
    assert d["p_a"] == pytest.approx(_K * R * _T / v_a * o * iso(C_V, B_V, 6e5, p_a), rel=REL)
    assert d["p_b"] == pytest.approx(-_K * R * _T / v_b * o * iso(C_V, B_V, p_b, P_ATM),
                                     rel=REL)


@pytest.mark.parametrize("form", ["stick", "smooth"])
def test_plant_dry_friction_and_piston_rows(tmp_path, form):
    plant = _plant(tmp_path, ["dry_friction"], {"cylinder.rod_diameter": 0.01,
                                                 "load.external_force": 15.0}, friction=form)
    A_b = math.pi / 4 * (0.025 ** 2 - 0.01 ** 2)
    m = 1.2
    for v in (0.004, -0.03):
        vals = {"x": 0.2, "v": v, "p_a": 3.0e5, "p_b": 3.2e5}
        d = _f(plant, vals, 5.0)
        drive = 3.0e5 * _AREA - 3.2e5 * A_b - P_ATM * (_AREA - A_b) - 15.0
        level = FC + (FS - FC) * math.exp(-(v / VS) ** 2)
        f_dry = level * (math.copysign(1.0, v) if form == "stick" else math.tanh(v / 1e-3))
        assert d["v"] == pytest.approx((drive - f_dry - BETA * v) / m, rel=REL)
        assert d["x"] == v


def test_plant_end_stop_row(tmp_path):
    plant = _plant(tmp_path, [])
    x, v = -2e-4, -0.05
    d = _f(plant, {"x": x, "v": v, "p_a": 3e5, "p_b": 3e5}, 5.0)
    w = 2 * math.pi * piston.STOP_FREQUENCY
    stop = -1.2 * w * w * x - 2 * piston.STOP_DAMPING * 1.2 * w * v
    assert d["v"] == pytest.approx((stop - BETA * v) / 1.2, rel=REL)


def test_plant_input_affine_rows():
    """Paper 003's law at both ports (port b mirrored) feeding the polytropic chambers,
    with a leakage phi and a degree-2 Gamma so that every coefficient shows."""
    plant = Plant.from_toml(DATA / "input_affine.toml").with_params(
        **{"valve.affine_phi": [1e-5, -2e-6], "valve.affine_gamma": [1.1, -0.2]})
    prm = plant.params
    phi, g = (1e-5, -2e-6), (1.1, -0.2)
    psi_in, psi_out = prm["valve.affine_psi_in"], prm["valve.affine_psi_out"]

    def poly(c, x):
        return sum(ci * x ** i for i, ci in enumerate(c))

    x, v, p_a, p_b = 0.3, 0.05, 3.2e5, 2.4e5
    for u in (6.5, 3.0):
        o = (u - 5.0) / 5.0
        gam = g[0] * o + g[1] * o * abs(o)
        q_a = poly(phi, 3.2) + poly(psi_in if gam >= 0 else psi_out, 3.2) * gam
        q_b = poly(phi, 2.4) + poly(psi_in if -gam >= 0 else psi_out, 2.4) * -gam
        assert (q_a > 0 > q_b) == (u > 5.0)
        d = _f(plant, {"x": x, "v": v, "p_a": p_a, "p_b": p_b}, u)
        v_a, v_b = _V_DEAD + _AREA * x, _V_DEAD + _AREA * (0.5 - x)
        # polytropic chambers (physics.md): dp/dt = k/V (r T q - p dV/dt)
        assert d["p_a"] == pytest.approx(_K / v_a * (R * _T * q_a - p_a * _AREA * v), rel=REL)
        assert d["p_b"] == pytest.approx(_K / v_b * (R * _T * q_b + p_b * _AREA * v), rel=REL)


def test_speed_of_sound_is_adiabatic():
    """a = sqrt(gamma R T) (adiabatic; Newton's isothermal sqrt(R T) is 16 % low): at
    20 degC in air, 343.2 m/s, the textbook value (e.g. White, Fluid Mechanics, table
    A.2), and it scales with sqrt(T). Written out with math: rounding only, 1e-12."""
    from workbench.physics import gas
    a = math.sqrt(1.4 * 287.0 * 293.15)
    assert a == pytest.approx(343.2, abs=0.1)
    assert gas.speed_of_sound(293.15, 1.4, 287.0) == pytest.approx(a, rel=1e-12)
    assert gas.speed_of_sound(4 * 293.15, 1.4, 287.0) == pytest.approx(2 * a, rel=1e-12)
