"""The stability map's batched kernel (workbench.stability.kernel): the pieces made
faster in session 8, each against an independent computation written here or in
scipy/numpy (never the code under test)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from workbench import Plant
from workbench.stability import kernel, maps

SITUM = "designs/plants/situm_rodless_nominal.toml"


@pytest.mark.parametrize("degree", [3, 5, 7, 9, 13])
def test_expm_every_pade_degree_matches_scipy(degree):
    # a stack whose largest 1-norm lies just below theta_m picks degree m (13: above
    # theta_9, and a few matrices far above theta_13 so that squarings happen too)
    rng = np.random.default_rng(degree)
    M = rng.standard_normal((20, 5, 5))
    theta = kernel._PADE[degree][0]
    norms = np.abs(M).sum(axis=-2).max(axis=-1)
    target = np.linspace(0.2, 0.99, 20) * theta
    if degree == 13:
        target[-5:] = theta * np.array([2.0, 7.0, 30.0, 100.0, 400.0])
    M *= (target / norms)[:, None, None]
    E = kernel.expm_batched(M)
    for k in range(len(M)):
        ref = scipy.linalg.expm(M[k])
        # backward error ~ unit roundoff for each degree within its theta: 1e-13
        # relative to the largest entry (the squared cases lose up to ~1e-13 by their
        # condition; measured 2e-13 at 400 theta_13 with atol 1e-12 below)
        np.testing.assert_allclose(E[k], ref, rtol=1e-11, atol=1e-12 * np.abs(ref).max())


def test_expm_degree_follows_the_largest_norm():
    # the degree chosen is the lowest whose theta bounds the stack's largest norm
    calls = []
    orig = kernel._pade_uv

    def spy(A, m):
        calls.append(m)
        return orig(A, m)

    M = np.zeros((3, 4, 4))
    for top, want in ((0.01, 3), (0.2, 5), (0.9, 7), (2.0, 9), (5.0, 13), (50.0, 13)):
        M[0] = np.diag([top, 0, 0, 0])
        calls.clear()
        kernel._pade_uv = spy
        try:
            E = kernel.expm_batched(M)
        finally:
            kernel._pade_uv = orig
        assert calls == [want]
        assert E[0, 0, 0] == pytest.approx(math.exp(top), rel=1e-14)


def _dominant_loop(lam, score):
    """The per-point rule, written as a plain loop (the session-7 implementation)."""
    w0 = np.full(len(lam), np.nan)
    zeta = np.full(len(lam), np.nan)
    for k in range(len(lam)):
        order = np.argsort(-score[k], kind="stable")
        first = order[0]
        if score[k, first] <= 0:
            continue
        l1 = lam[k, first]
        if abs(l1.imag) > 1e-9 * abs(l1):
            l2 = np.conj(l1)
        else:
            reals = [j for j in order[1:] if score[k, j] > 0
                     and abs(lam[k, j].imag) <= 1e-9 * abs(lam[k, j])]
            if not reals:
                continue
            l2 = lam[k, reals[0]]
        w2 = (l1 * l2).real
        if w2 <= 0:
            continue
        w0[k] = math.sqrt(w2)
        zeta[k] = -(l1 + l2).real / (2 * w0[k])
    return w0, zeta


def test_dominant_pair_equals_the_per_point_rule():
    rng = np.random.default_rng(3)
    lam = np.linalg.eigvals(rng.standard_normal((3000, 5, 5)))
    score = rng.standard_normal((3000, 5))
    score[rng.random((3000, 5)) < 0.3] = -1.0           # integrators / hidden modes
    w0, zeta = kernel._dominant_pair(lam, score)
    r0, rz = _dominant_loop(lam, score)
    assert 0.2 < np.mean(np.isnan(r0)) < 0.8                # both kinds of points occur
    np.testing.assert_array_equal(np.isnan(w0), np.isnan(r0))
    # sqrt of the same w0^2: rounding only
    np.testing.assert_allclose(w0, r0, rtol=1e-15, equal_nan=True)
    np.testing.assert_allclose(zeta, rz, rtol=1e-14, atol=1e-15, equal_nan=True)


def test_unique_rows_matches_numpy_unique():
    rng = np.random.default_rng(4)
    key = np.column_stack([rng.integers(0, 5, 500).astype(float), np.full(500, 2.5),
                           rng.integers(0, 3, 500) * 0.1])
    first, inv = kernel._unique_rows(key)
    np.testing.assert_array_equal(key[first][inv], key)          # every row mapped back
    ref = np.unique(key, axis=0)
    assert len(first) == len(ref)
    # first occurrences: no earlier row equals row first[g]
    for g, i in enumerate(first):
        assert not np.any(np.all(key[:i] == key[i], axis=1)), g
    f1, i1 = kernel._unique_rows(np.full((7, 3), 1.0))           # nothing varies
    assert f1.tolist() == [0] and i1.tolist() == [0] * 7


def test_mapped_call_without_function_buffer_gives_the_same_numbers():
    import casadi as ca
    x, p = ca.SX.sym("x"), ca.SX.sym("p", 2)
    fun = ca.Function("f", [x, p], [ca.vertcat(x * p[0], p[1] ** 2, x),
                                    ca.densify(ca.jacobian(ca.vertcat(x * p[0], p[1]), p))])
    xs = np.linspace(0, 1, 9)[:, None]
    ps = np.column_stack([np.arange(9.0), -np.arange(9.0)])
    a = kernel._mapped_call(fun, [xs, ps])

    class NoBuffer:                          # a CasADi without FunctionBuffer
        def __init__(self, f):
            self.f = f

        def __getattr__(self, name):
            if name == "buffer":
                raise AttributeError(name)
            return getattr(self.f, name)

        def __call__(self, *args):
            return self.f(*args)

    orig = kernel._mapped
    kernel._mapped = lambda f, N: NoBuffer(orig(f, N))
    try:
        b = kernel._mapped_call(fun, [xs, ps])
    finally:
        kernel._mapped = orig
    for u, v in zip(a, b):
        np.testing.assert_array_equal(u, v)
    # independent: the first output is [x p0, p1^2, x]; the Jacobian, column-major
    np.testing.assert_array_equal(a[0], np.column_stack([xs[:, 0] * ps[:, 0], ps[:, 1] ** 2,
                                                         xs[:, 0]]))
    np.testing.assert_array_equal(a[1][:, :2], np.column_stack([xs[:, 0], np.zeros(9)]))


@pytest.mark.slow
def test_compiled_map_equals_the_virtual_machine(monkeypatch):
    # The C of the equilibrium-and-tangent function (flags, fmax/fmin inlined) gives
    # the virtual machine's numbers: rounding only (1e-12 on |z| ~ 1). Compiling takes
    # ~5-10 s once (then the JIT cache).
    plant = Plant.from_toml(SITUM)
    x = maps.Axis.linspace("position", 0.05, 0.45, 7)
    y = maps.Axis.linspace("supply.pressure", 3e5, 7e5, 6)
    vm = maps.stability_map(plant, x, y, workers=1, compile_c=False)
    monkeypatch.setattr(maps, "_COMPILE_ABOVE", 0)
    c = maps.stability_map(plant, x, y, workers=1, compile_c=True)
    np.testing.assert_allclose(c.rho, vm.rho, rtol=0, atol=1e-12)
    np.testing.assert_allclose(c.kv, vm.kv, rtol=1e-10)
    np.testing.assert_array_equal(c.hidden_modes, vm.hidden_modes)
