"""NMPC limits respected between the shooting nodes (issue 14, item 4).

A plan is judged by its continuous trajectory: the plan's commands (held over each
10 ms interval) applied to the prediction model and integrated by scipy's Radau at
rtol 1e-10 (independent of the NMPC's RK4), sampled 101 times per interval. With
limits at the nodes only, the nodes satisfy the speed and pressure limits while the
trajectory between them does not; with ``interior_limits`` (limits also at the RK4
substep ends, every 2.5 ms) it satisfies them up to what can happen between two
substep ends.

Rig: ``designs/plants/rig25_mpye.toml``; mode "sqp" (converged plans), ``jit=False``.
"""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from workbench import Plant
from workbench.controllers.mpc import NMPC

ROOT = Path(__file__).resolve().parents[1]
RIG25 = ROOT / "designs" / "plants" / "rig25_mpye.toml"
REST = {"v": 0.0, "p_a": 3.5e5, "p_b": 3.5e5}


@pytest.fixture(scope="module")
def rig25():
    return Plant.from_toml(RIG25)


def _continuous(nmpc, sol) -> np.ndarray:
    """(4, 101 N) states between and at the nodes: scipy Radau on the model's f."""
    m = nmpc._problem.model
    xs, us = ca.SX.sym("x", 4), ca.SX.sym("u")
    f = ca.Function("f", [xs, us], [m.f(xs, us, ca.DM(m.p0))])
    z, out = np.asarray(sol.states[0], dtype=float), []
    for u in sol.commands:
        r = solve_ivp(lambda t, y, u=u: np.asarray(f(y, u)).ravel(), (0.0, nmpc.sample_time), z,
                      method="Radau", rtol=1e-10, atol=[1e-12, 1e-10, 1e-3, 1e-3],
                      dense_output=True)
        out.append(r.sol(np.linspace(0.0, nmpc.sample_time, 101)))
        z = r.y[:, -1]
    return np.hstack(out)


def _plans(rig25, x0, r, **settings):
    """{interior_limits: (nodes (N+1, 4), continuous (4, .), problem)}."""
    out = {}
    for il in (False, True):
        n = NMPC.for_plant(rig25, mode="sqp", jit=False, max_iterations=50,
                           interior_limits=il, **settings)
        sol = n.solve(dict(REST, x=x0), r=r)
        assert sol.info.success
        out[il] = (np.asarray(sol.states), _continuous(n, sol), n._problem)
    return out


def test_speed_limit_holds_between_the_nodes(rig25):
    """A 0.3 m step from rest, speed limit 0.5 m/s. Measured: nodes 0.5000 m/s in both;
    continuous 0.68 m/s at the nodes only, 0.504 m/s with interior limits."""
    vmax = 0.5
    plans = _plans(rig25, 0.1, 0.4, max_speed=vmax)
    nodes, cont, _ = plans[False]
    assert np.abs(nodes[1:, 1]).max() <= vmax * (1 + 1e-6)    # the nodes keep it ...
    assert np.abs(cont[1]).max() > 1.2 * vmax                   # ... the trajectory does not
    nodes, cont, _ = plans[True]
    assert np.abs(nodes[1:, 1]).max() <= vmax * (1 + 1e-6)
    # between two substep ends (2.5 ms) the speed can still rise by its curvature
    # over half a substep: measured 0.8 %; 2 % allows for it and nothing more
    assert np.abs(cont[1]).max() <= 1.02 * vmax


def test_pressure_limit_holds_between_the_nodes(rig25):
    """A 0.19 m step towards the far end, speed limit 1 m/s: braking compresses
    chamber b. Limit supply - 40 kPa = 5.6 bar. Measured: continuous peak 5.80 bar
    with limits at the nodes only (nodes 5.60 bar), 5.608 bar with interior limits."""
    plans = _plans(rig25, 0.3, 0.49, max_speed=1.0)
    nodes, cont, pb = plans[False]
    p_hi = pb.hi[3] * pb.p_sup
    assert nodes[1:, 2:].max() <= p_hi + 1.0                   # Pa: the nodes keep it ...
    assert cont[2:].max() > p_hi + 1e4                          # ... the trajectory not
    nodes, cont, pb = plans[True]
    # between substep ends: measured +849 Pa; 2 kPa (a twentieth of the 40 kPa margin
    # that keeps the true peak within supply)
    assert cont[2:].max() <= p_hi + 2e3


def test_interior_rows_are_in_the_qp(rig25):
    """The condensed QP has the interior rows: 2 x N x soft limits x (1 + substeps - 1);
    mode ipopt has none (module text of the setting)."""
    on = NMPC.for_plant(rig25, jit=False, interior_limits=True)._problem
    off = NMPC.for_plant(rig25, jit=False)._problem                 # the default: off
    assert off.n_rows == 2 * off.N * len(off.soft)
    assert on.n_rows == off.n_rows * on.c.substeps
    one = NMPC.for_plant(rig25, jit=False, substeps=1, interior_limits=True)._problem
    assert one.Fi is None and one.n_rows == 2 * one.N * len(one.soft)
    ipopt = NMPC.for_plant(rig25, jit=False, mode="ipopt", interior_limits=True)._problem
    assert ipopt.Fi is None and ipopt.n_rows == off.n_rows
