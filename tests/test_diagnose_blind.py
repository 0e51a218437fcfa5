"""Blind check: a rig simulated by other code than the workbench's.

The recording comes from a small independent simulator written here with numpy and
scipy (``solve_ivp``, LSODA, one call per 1 ms sample): its own ISO 6358 four-edge
valve with a linear (laminar) patch near equal pressures, the polytropic chambers,
and a *different friction law*: a smooth Stribeck curve times tanh(v / 2 mm/s) plus
viscous friction, where the workbench uses Karnopp stick-slip. The diagnosis must
still name dry friction and find the Coulomb level within 30 %.
"""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from workbench.diagnose import synth
from workbench.recording import Recording

R_AIR, T0, RHO0 = 287.0, 293.15, 1.185


def _iso_flow(C, b, p1, p2):
    up, dw = (p1, p2) if p1 >= p2 else (p2, p1)
    x = dw / up
    if x <= b:
        psi = 1.0
    elif 1.0 - x < 2e-3:                  # laminar: linear in the pressure difference
        z0 = (1.0 - 2e-3 - b) / (1.0 - b)
        psi = math.sqrt(1.0 - z0 * z0) * (1.0 - x) / 2e-3
    else:
        z = (x - b) / (1.0 - b)
        psi = math.sqrt(max(1.0 - z * z, 0.0))
    q = C * up * RHO0 * psi
    return q if p1 >= p2 else -q


def foreign_rig(plant_file, reference, duration, seed, coulomb, static, stribeck, v_eps=2e-3):
    """Closed-loop PD run of the rig, logged at 1 kHz (noise + 12-bit quantisation)."""
    P = tomllib.loads(open(plant_file, encoding="utf-8").read())
    g, s, va, c = P["gas"], P["supply"], P["valve"], P["cylinder"]
    ld, ct = P["load"], P["controller"]
    k, patm, ps = g["polytropic_index"], g["atmospheric_pressure"], s["pressure"]
    C, b, uc, span = va["sonic_conductance"], va["critical_pressure_ratio"], va["command_center"], \
        va["command_span"]
    A = math.pi / 4 * c["bore"] ** 2
    L, Va0, Vb0 = c["stroke"], c["dead_volume_a"], c["dead_volume_b"]
    m, beta = ld["mass"], ld["viscous_friction"]
    wn = 2 * math.pi * 200.0

    def f(t, z, u):
        x, v, pa, pb = z
        sp = min(max((u - uc) / span, -1.0), 1.0)
        op, om = max(sp, 0.0), max(-sp, 0.0)
        qa = op * _iso_flow(C, b, ps, pa) - om * _iso_flow(C, b, pa, patm)
        qb = om * _iso_flow(C, b, ps, pb) - op * _iso_flow(C, b, pb, patm)
        va_, vb_ = Va0 + A * x, Vb0 + A * (L - x)
        ff = (coulomb + (static - coulomb) * math.exp(-(v / stribeck) ** 2)) * math.tanh(v / v_eps)
        force = (pa - pb) * A - ff - beta * v
        if x < 0:
            force += -m * wn * wn * x - 1.4 * m * wn * v
        if x > L:
            force += -m * wn * wn * (x - L) - 1.4 * m * wn * v
        return [v, force / m, k / va_ * (R_AIR * T0 * qa - pa * A * v),
                k / vb_ * (R_AIR * T0 * qb + pb * A * v)]

    from scipy.integrate import solve_ivp
    dt, Ts = 1e-3, ct["sample_time"]
    rng = np.random.default_rng(seed)
    n = int(round(duration / dt)) + 1
    t = np.arange(n) * dt
    z = np.array([float(reference(0.0)), 0.0, 4.4e5, 4.4e5])
    lsb_x, lsb_p = L / 4096, 1e6 / 4096
    nx = rng.normal(0, 20e-6, n)
    X, PA, PB, U = (np.empty(n) for _ in range(4))
    ratio = int(round(Ts / dt))
    e_prev, u = None, uc
    for i in range(n):
        X[i] = round((z[0] + nx[i]) / lsb_x) * lsb_x
        PA[i], PB[i] = z[2], z[3]
        if i % ratio == 0:
            e = float(reference(t[i])) - X[i]
            e_prev = e if e_prev is None else e_prev
            u = min(max(uc + ct["kp"] * e + ct["kd"] * (e - e_prev) / Ts, va["command_min"]),
                    va["command_max"])
            e_prev = e
        U[i] = u
        if i + 1 < n:
            z = solve_ivp(f, (0.0, dt), z, method="LSODA", args=(u,), rtol=1e-7,
                          atol=[1e-9, 1e-7, 1e-2, 1e-2]).y[:, -1]
    PA = np.round((PA + rng.normal(0, 500.0, n)) / lsb_p) * lsb_p
    PB = np.round((PB + rng.normal(0, 500.0, n)) / lsb_p) * lsb_p
    return Recording.from_arrays(t, u=U, x=X, p_a=PA, p_b=PB, r=reference(t),
                                 metadata={"sample_time": dt, "source": "foreign simulator"})


def test_foreign_friction_law_is_diagnosed(tmp_path):
    from workbench.diagnose import diagnose
    plant_file = synth.concealed_case("none", seed=0).write_nominal(tmp_path / "plant.toml")
    coulomb, static = 22.0, 31.0
    rec = foreign_rig(plant_file, synth.rich_reference(21, 20.0), 20.0, seed=21,
                      coulomb=coulomb, static=static, stribeck=0.012)
    d = diagnose(plant_file, rec)
    res = d.to_dict()
    assert res["findings"], d.summary()
    f = res["findings"][0]
    assert f["effect"] == "dry_friction", d.summary()
    assert f["parameters"]["coulomb"] == pytest.approx(coulomb, rel=0.3)
    assert np.mean(list(res["fit_after"].values())) > np.mean(list(res["fit_before"].values()))
