"""Stability maps: every point checked against an independent python-control chain."""

from __future__ import annotations

import warnings

import control
import numpy as np
import pytest
import scipy.linalg

from workbench import Plant, linearize
from workbench.controllers import PID
from workbench.errors import InputError
from workbench.stability import maps

SITUM = "designs/plants/situm_rodless_nominal.toml"
RIG25 = "designs/plants/rig25_mpye.toml"


@pytest.fixture(scope="module")
def situm():
    return Plant.from_toml(SITUM)


def reference_rho(plant: Plant, x: float, kp: float, T: float, kd: float = 0.0,
                  delay: int = 0, **changes) -> float:
    """Largest closed-loop pole of the position loop, the slow independent way:
    operating_point + tangent per point, minimal SISO realisation u -> x,
    python-control c2d (ZOH), the controller's own transfer function, feedback."""
    p = plant.with_params(**changes) if changes else plant
    lin = linearize.tangent(p, linearize.operating_point(p, x))
    sys = control.ss(lin.A, lin.B, lin.output("x")[0], lin.output("x")[1])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = control.minreal(control.ss2tf(sys), tol=1e-6, verbose=False)
        gd = control.c2d(g, T, "zoh")
        c = PID(kp=kp, kd=kd, sample_time=T).to_control()
        if delay:
            c = c * control.tf([1], [1] + [0] * delay, T)
        cl = control.feedback(c * gd, 1)
    return float(np.max(np.abs(control.poles(cl))))


def test_expm_batched_matches_scipy():
    rng = np.random.default_rng(1)
    # norms from 1e-3 to ~1e3: no scaling, a few and many squarings
    M = rng.standard_normal((60, 6, 6)) * np.geomspace(1e-3, 3e2, 60)[:, None, None]
    E = maps.expm_batched(M)
    for k in range(len(M)):
        ref = scipy.linalg.expm(M[k])
        # Pade-13 with scaling and squaring: backward error ~ unit roundoff, so the
        # relative error grows with the condition of expm; 1e-9 leaves room for the
        # large-norm cases while catching any wrong coefficient (errors ~1e-2)
        assert np.allclose(E[k], ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())


def test_map_points_match_python_control(situm):
    kp = maps.Axis("kp", [3.0, 20.0, 60.0])
    mass = maps.Axis("load.mass", [0.6, 0.91, 3.0])
    m = maps.stability_map(situm, kp, mass, position=0.25, workers=1, progress=False)
    assert m.rho.shape == (3, 3)
    for iy, mv in enumerate(mass.values):
        for ix, k in enumerate(kp.values):
            ref = reference_rho(situm, 0.25, k, 0.01, **{"load.mass": mv})
            # two exact computations of the same eigenvalues; minreal/c2d rounding ~1e-9
            assert m.rho[iy, ix] == pytest.approx(ref, rel=1e-7, abs=1e-9)


def test_position_supply_delay_and_pd_points(situm):
    pos = maps.Axis("position", [0.05, 0.25, 0.45])
    ps = maps.Axis("supply.pressure", [3e5, 7e5])
    ctrl = PID(kp=15.0, kd=0.2, sample_time=0.01)
    m = maps.stability_map(situm, pos, ps, controller=ctrl, delay_samples=1, workers=1,
                           progress=False)
    for iy, pv in enumerate(ps.values):
        for ix, xv in enumerate(pos.values):
            ref = reference_rho(situm, xv, 15.0, 0.01, kd=0.2, delay=1,
                                **{"supply.pressure": pv})
            assert m.rho[iy, ix] == pytest.approx(ref, rel=1e-7, abs=1e-9)


def test_sample_time_and_k0_axes(situm):
    m = maps.stability_map(situm, maps.Axis("k0", [5.0, 40.0]),
                           maps.Axis("sample_time", [0.005, 0.02]), workers=1, progress=False)
    kv = linearize.reduced_position_model(linearize.tangent(situm, x=0.25)).kv
    # kp = k0 / Kv per point; Kv from the map is lim s G(s) at s = 1e-4 rad/s
    assert m.kp[0, 0] == pytest.approx(5.0 / kv, rel=1e-4)
    assert m.rho[1, 1] == pytest.approx(reference_rho(situm, 0.25, 40.0 / kv, 0.02), rel=1e-4)


def test_stability_boundary_matches_sampled_limit_of_third_order_model(situm):
    """For the four-state drive the minimal model u -> x is exactly
    Kv/(s (s^2/w0^2 + 2 zeta s/w0 + 1)); the map's boundary in K0 must sit at the
    exact sampled-data limit of that model, found here by bisection on python-control
    poles (independent of the map)."""
    lin = linearize.tangent(situm, x=0.25)
    red = linearize.reduced_position_model(lin)
    gd = control.c2d(red.transfer_function(), 0.01, "zoh")
    lo, hi = 1.0, 500.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        stable = np.max(np.abs(control.poles(control.feedback(mid / red.kv * gd, 1)))) < 1
        lo, hi = (mid, hi) if stable else (lo, mid)
    limit = lo
    k0 = maps.Axis("k0", np.linspace(0.9 * limit, 1.1 * limit, 201))
    m = maps.stability_map(situm, k0, maps.Axis("load.mass", [0.90, 0.91]), workers=1,
                           progress=False)
    row = m.rho[1]
    crossing = k0.values[np.argmax(row >= 1.0)]
    # grid step is 0.1 % of the limit; the reduced-model fit is exact to ~1e-6 here
    assert crossing == pytest.approx(limit, rel=2e-3)
    assert np.all(row[k0.values < 0.995 * limit] < 1) and np.all(row[k0.values > 1.005 * limit] > 1)
    b = m.boundary
    assert b is not None
    # dominant pair of the tangent model = the reduced model (exactly third order)
    assert b["w0"][1, 0] == pytest.approx(red.w0, rel=1e-4)
    assert b["zeta"][1, 0] == pytest.approx(red.zeta, rel=1e-4)


def test_hidden_pressure_sum_mode_is_not_counted(situm):
    """Closed centre, no leakage: the pressure-sum mode sits at z = 1 for every gain.
    It is neither driven by r nor seen in x, so a small stable gain still gives
    |z|max < 1, and the map says it hid a mode."""
    m = maps.stability_map(situm, maps.Axis("kp", [1.0, 2.0]), maps.Axis("load.mass", [0.9, 1.0]),
                           workers=1, progress=False)
    assert np.all(m.rho < 1)
    assert np.all(m.hidden_modes == 1)
    assert any("hidden" in n for n in m.notes)


def test_leaking_valve_falls_back_to_robust_equilibrium():
    leaky = Plant.from_toml(RIG25).with_params(**{"leakage.conductance_to_atmosphere": 1e-10,
                                                 "leakage.cross_piston": 1e-9})
    m = maps.stability_map(leaky, maps.Axis("kp", [5.0, 30.0]),
                           maps.Axis("supply.pressure", [4e5, 6e5]), workers=1, progress=False,
                           controller=PID(kp=1.0, sample_time=0.01))   # P only (plant has PD)
    assert m.fallbacks == 2                      # one equilibrium per supply pressure
    assert m.rho[1, 1] == pytest.approx(
        reference_rho(leaky, 0.25, 30.0, 0.01, **{"supply.pressure": 6e5}), rel=1e-6)


def test_worker_processes_and_dask_give_the_same_map(situm):
    # dask[distributed] is a dependency of the package (pyproject): imported, not skipped
    from distributed import Client, LocalCluster
    kp = maps.Axis.linspace("kp", 2, 80, 12)
    mass = maps.Axis.linspace("load.mass", 0.5, 4, 10)
    serial = maps.stability_map(situm, kp, mass, workers=1, block_size=25, progress=False)
    forked = maps.stability_map(situm, kp, mass, workers=2, block_size=25, progress=False)
    np.testing.assert_array_equal(serial.rho, forked.rho)
    # in-process workers keep the test quick; the code path (scatter, submit,
    # as_completed, results by key) is the one a remote cluster takes
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        viadask = maps.stability_map(situm, kp, mass, scheduler=client, block_size=25,
                                     progress=False)
        by_address = maps.stability_map(situm, kp, mass, scheduler=cluster.scheduler_address,
                                        block_size=40, progress=False)
    np.testing.assert_array_equal(serial.rho, viadask.rho)
    np.testing.assert_array_equal(serial.rho, by_address.rho)


def test_bad_axes_are_rejected(situm):
    with pytest.raises(InputError, match="did you mean 'load.mass'"):
        maps.stability_map(situm, maps.Axis("kp", [1, 2]), maps.Axis("load.mas", [1, 2]))
    with pytest.raises(InputError, match="same gain"):
        maps.stability_map(situm, maps.Axis("kp", [1, 2]), maps.Axis("k0", [1, 2]))
    with pytest.raises(InputError, match="within the stroke"):
        maps.stability_map(situm, maps.Axis("kp", [1, 2]), maps.Axis("position", [0.1, 0.6]))
    with pytest.raises(InputError, match="strictly increasing"):
        maps.Axis("kp", [2, 1])
    with pytest.raises(InputError, match="NAME=START:STOP"):
        maps.parse_axis("kp=1")
    ax = maps.parse_axis("mass=0.5:5:10:log")
    assert ax.name == "load.mass" and len(ax) == 10 and ax.values[-1] == pytest.approx(5)


def test_unreachable_scheduler_is_a_clear_error(situm, monkeypatch):
    from workbench.errors import WorkbenchError
    monkeypatch.setattr(maps, "DASK_CONNECT_TIMEOUT", "1s")
    with pytest.raises(WorkbenchError, match="cannot reach the Dask scheduler"):
        maps.stability_map(situm, maps.Axis("kp", [1, 2]), maps.Axis("load.mass", [1, 2]),
                           scheduler="tcp://127.0.0.1:1", progress=False)
