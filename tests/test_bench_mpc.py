"""``workbench bench mpc``'s plain RTI baseline and its phase report (no timing here:
the benchmark itself takes minutes)."""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from workbench import Plant
from workbench.controllers.mpc import NMPC

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def plain():
    pytest.importorskip("osqp")
    from workbench.bench.baselines_mpc import PlainRTI
    plant = Plant.from_toml(ROOT / "designs" / "plants" / "rig25_mpye.toml")
    nmpc = NMPC.for_plant(plant, horizon=5, sample_time=0.01, disturbance_gain=0.0,
                          jit=False)
    return PlainRTI(nmpc)


def test_plain_rti_linearises_the_nlp(plain):
    # The plain RTI's constraints and their Jacobian come from one mapped call of the
    # interval map with sensitivities. Checked against independent evaluations at a
    # random point: g against the NLP's own g (IpoptSolver._nlp: its RK4 map F), the
    # Jacobian's blocks against pb.Fj evaluated interval by interval, its soft rows
    # against the NLP's (linear in w: its exact Jacobian). Same arithmetic: 1e-12.
    pb, N, nx = plain.pb, plain.N, plain.pb.nx
    rng = np.random.default_rng(3)
    X = np.tile([0.3, 0.05, 0.5, 0.5], N + 1) + 0.02 * rng.standard_normal(nx * (N + 1))
    w = np.concatenate([X, 0.3 * rng.standard_normal(N), np.abs(rng.standard_normal(pb.ns))])
    p = np.concatenate([X[:nx] + 0.01, np.full(N + 1, 0.3), np.zeros(N + 1), [0.1, 0.0], pb.P])
    _, g, J = plain.lin(w, p)
    nlp = plain.nlp
    g_nlp = ca.Function("g", [nlp["x"], nlp["p"]], [nlp["g"]])(w, p)
    assert np.allclose(np.asarray(g), np.asarray(g_nlp), rtol=0, atol=1e-12)
    J = np.asarray(ca.densify(J))
    n0 = nx * (N + 1)
    Xm = X.reshape(N + 1, nx).T
    for k in range(N):
        _, A, B = (np.asarray(v) for v in pb.Fj(Xm[:, k], w[n0 + k], 0.0))
        rows = slice(nx * (k + 1), nx * (k + 2))
        assert np.allclose(J[rows, nx * k:nx * (k + 1)], A, rtol=0, atol=1e-12)
        assert np.allclose(J[rows, nx * (k + 1):nx * (k + 2)], -np.eye(nx), atol=0)
        assert np.allclose(J[rows, n0 + k], B.ravel(), rtol=0, atol=1e-12)
    J_soft = ca.Function("j", [nlp["x"], nlp["p"]], [ca.jacobian(nlp["g"][n0:], nlp["x"])])
    assert np.allclose(J[n0:], np.asarray(ca.densify(J_soft(w, p))), rtol=0, atol=1e-12)
    assert np.allclose(J[:nx, :nx], np.eye(nx), atol=0)


def test_phase_medians_split_the_compiled_sample():
    # per sample (lin, condense, QP, post, whole in C) s -> medians in us; prep is the
    # linearisation and the condensing of each sample, then their median
    from workbench.bench.mpc import phase_medians
    run = {"phases": [(1e-6, 2e-6, 3e-6, 4e-6, 11e-6), (3e-6, 4e-6, 5e-6, 6e-6, 19e-6),
                      (2e-6, 9e-6, 4e-6, 5e-6, 21e-6)],
           "wall": [12e-6, 20e-6, 22e-6]}
    ph = phase_medians(run)
    assert ph["lin"] == pytest.approx(2.0) and ph["condense"] == pytest.approx(4.0)
    assert ph["prep"] == pytest.approx(7.0)              # medians of 3, 7, 11
    assert ph["qp"] == pytest.approx(4.0) and ph["post"] == pytest.approx(5.0)
    assert ph["sample_in_c"] == pytest.approx(19.0) and ph["update"] == pytest.approx(20.0)
