"""The stepping library (workbench.integrate): orders, stiff stability, sensitivities, cache.

References are analytic solutions; nothing here is compared with the code under test.
"""

from __future__ import annotations

import math
import subprocess

import casadi as ca
import numpy as np
import pytest

from workbench import integrate
from workbench.integrate import jit

# ---------------------------------------------------------------- a problem with a known solution
# y0' = y0 (1 - y0)            logistic: y0 = 1 / (1 + (1/y0(0) - 1) e^-t)
# y1' = -y1 + cos(y2)          forced:   y1 = (y1(0) - 1/2) e^-t + (cos t + sin t) / 2
# y2' = 1                      time:     y2 = t
Y0 = np.array([0.2, 1.0, 0.0])


def rhs(y):
    return ca.vertcat(y[0] * (1 - y[0]), -y[1] + ca.cos(y[2]), 1.0)


def exact(t):
    return np.array([1.0 / (1.0 + (1.0 / Y0[0] - 1.0) * math.exp(-t)),
                     (Y0[1] - 0.5) * math.exp(-t) + 0.5 * (math.cos(t) + math.sin(t)), t])


def _stepper(kind, tab):
    """A step Function (y, h) -> y+ for one of the library's steppers."""
    y = ca.SX.sym("y", 3)
    if kind == "rk":
        return lambda h: ca.Function("s", [y], [integrate.explicit_rk(tab, rhs, y, h)])
    if kind == "ros":
        return lambda h: ca.Function("s", [y], [integrate.rosenbrock(tab, rhs, y, h)])
    if kind == "radau":          # full Newton (the grey-box stepper), h and p as inputs
        u, p = ca.SX.sym("u"), ca.SX.sym("p", 0)
        f = ca.Function("f", [y, u, p], [rhs(y)])
        step, _ = integrate.radau_step_functions(tab, f, 0, newton=10)
        return lambda h: (lambda yy: step(yy, 0.0, h, []))
    # the simplified-Newton Radau IIA of the compiled loop, stages carried over
    fun = (lambda h: integrate.step_function("radau", lambda yy, uu: rhs(yy), 3, h,
                                             newton_iterations=10))

    def make(h):
        st = fun(h)
        z = [np.zeros(9)]

        def one(yy):
            yn, z[0] = st(yy, 0.0, z[0])
            return yn
        return one
    return make


def _error(make, h, t_end=1.0):
    step = make(h)
    y = Y0.copy()
    for _ in range(int(round(t_end / h))):
        y = np.asarray(step(y)).ravel()
    return float(np.max(np.abs(y - exact(t_end))))


CASES = [("rk", integrate.RK4, (0.1, 0.05, 0.025)),
         ("ros", integrate.ROS2, (0.02, 0.01, 0.005)),
         ("ros", integrate.ROS4, (0.1, 0.05, 0.025)),
         ("ros", integrate.RODAS4, (0.1, 0.05, 0.025)),
         ("radau", integrate.RADAU_IIA_1, (0.02, 0.01, 0.005)),
         ("radau", integrate.RADAU_IIA_2, (0.1, 0.05, 0.025)),
         ("radau", integrate.RADAU_IIA_3, (0.2, 0.1, 0.05)),
         ("radau_simplified", integrate.RADAU_IIA_3, (0.2, 0.1, 0.05))]


@pytest.mark.parametrize("kind,tab,hs", CASES, ids=[f"{c[0]}-{c[1].name}" for c in CASES])
def test_observed_order(kind, tab, hs):
    # Errors at t = 1 against the analytic solution for three step sizes; the slope of
    # log(error) over log(h) is the observed order. Within 0.2 of the nominal order:
    # the step sizes are chosen in the asymptotic range, where the next error term
    # shifts the slope by less than that (and errors stay far above rounding, 1e-15).
    errs = [_error(_stepper(kind, tab), h) for h in hs]
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert slope == pytest.approx(tab.order, abs=0.2), (tab.name, errs)


STIFF = [("ros", integrate.ROS2), ("ros", integrate.ROS4), ("ros", integrate.RODAS4),
         ("radau", integrate.RADAU_IIA_1), ("radau", integrate.RADAU_IIA_2),
         ("radau", integrate.RADAU_IIA_3)]


@pytest.mark.parametrize("kind,tab", STIFF, ids=[f"{c[0]}-{c[1].name}" for c in STIFF])
def test_stiff_decay(kind, tab):
    # y' = lambda y with h lambda = -1e5 (far outside any explicit method's region):
    # an L-stable method has R(z) -> 0 as z -> -inf, here |R| = O(1/|z|) = 1e-5 or
    # smaller; 1e-3 leaves room for the constant. RK4's |R| grows like z^4 / 24.
    lam, h = -1e6, 0.1
    y = ca.SX.sym("y")
    if kind == "ros":
        step = ca.Function("s", [y], [integrate.rosenbrock(tab, lambda v: lam * v, y, h)])
        ratio = float(step(1.0))
    else:
        u, p = ca.SX.sym("u"), ca.SX.sym("p", 0)
        f = ca.Function("f", [y, u, p], [lam * y])
        st, _ = integrate.radau_step_functions(tab, f, 0, newton=2)
        ratio = float(st(1.0, 0.0, h, []))
    assert abs(ratio) < 1e-3
    rk = ca.Function("r", [y], [integrate.explicit_rk(integrate.RK4, lambda v: lam * v, y, h)])
    assert abs(float(rk(1.0))) > 1e10


def test_simplified_newton_radau_stiff():
    # The compiled loop's Radau (simplified Newton, J once per step) on a stiff linear
    # system with a slow and a fast mode (-1, -1e6), h = 0.1: the fast mode is damped
    # (L-stability, |R| < 1e-3 as above) and the slow one follows exp(-h) to order 5
    # (error ~ h^6 / 7200 ~ 1e-10; 1e-8 allows for the constant).
    A = np.array([[-1.0, 0.0], [0.0, -1e6]])
    st = integrate.step_function("radau", lambda y, u: ca.mtimes(ca.DM(A), y), 2, 0.1,
                                 newton_iterations=3)
    y, _ = st([1.0, 1.0], 0.0, np.zeros(6))
    y = np.asarray(y).ravel()
    assert abs(y[1]) < 1e-3
    assert y[0] == pytest.approx(math.exp(-0.1), abs=1e-8)


def test_radau_sensitivity_matches_central_differences():
    # dx+/d[x0, p] of a Radau IIA step (implicit function theorem on the converged stage
    # equations) against central differences of the step itself. Step 1e-6 (relative):
    # truncation O(1e-12) and rounding O(1e-16 / 1e-6 = 1e-10) both below the 1e-7 bound.
    x, u, p = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("p", 2)
    f = ca.Function("f", [x, u, p],
                    [ca.vertcat(x[1], -p[0] * ca.sin(x[0]) - p[1] * x[1] ** 3 + u)])
    E = np.array([[1.0, 0.0], [0.0, 1.0]])
    for tab in (integrate.RADAU_IIA_2, integrate.RADAU_IIA_3):
        step, sens = integrate.radau_step_functions(tab, f, 2, newton=12)
        x0, p0, h = np.array([0.7, -0.3]), np.array([9.81, 0.5]), 0.05
        xn, S = sens(x0, np.hstack([np.eye(2), np.zeros((2, 2))]), 0.2, h, p0, E)
        assert np.allclose(np.asarray(xn).ravel(), np.asarray(step(x0, 0.2, h, p0)).ravel(),
                           rtol=0, atol=1e-15)
        fd = np.empty((2, 4))
        for j in range(4):
            d = 1e-6 * max(1.0, abs(np.concatenate([x0, p0])[j]))
            xp, xm, pp, pm = x0.copy(), x0.copy(), p0.copy(), p0.copy()
            if j < 2:
                xp[j] += d
                xm[j] -= d
            else:
                pp[j - 2] += d
                pm[j - 2] -= d
            fd[:, j] = (np.asarray(step(xp, 0.2, h, pp)).ravel()
                        - np.asarray(step(xm, 0.2, h, pm)).ravel()) / (2 * d)
        assert np.allclose(np.asarray(S), fd, rtol=1e-7, atol=1e-9), tab.name


def test_rk4_exact_on_quartic():
    # y' = 4 t^3 (cubic in time): RK4's quadrature is Simpson's rule, exact for cubics,
    # so y(t) = t^4 is reproduced to rounding (1e-14 on values of order 1) with 3 steps.
    y = ca.SX.sym("y", 2)                 # (value, time)
    step = ca.Function("s", [y], [integrate.explicit_rk(
        integrate.RK4, lambda v: ca.vertcat(4 * v[1] ** 3, 1.0), y, 1.0 / 3.0)])
    v = np.array([0.0, 0.0])
    for _ in range(3):
        v = np.asarray(step(v)).ravel()
    assert v[0] == pytest.approx(1.0, abs=1e-14)
    with pytest.raises(ValueError, match="implicit"):
        integrate.explicit_rk(integrate.RADAU_IIA_2, lambda v: v, y, 0.1)


def test_jit_cache_hit(tmp_path, monkeypatch):
    # A second compile of the same Function finds the library by its source hash and
    # runs no compiler; the compiled Function gives the VM's numbers. Without a C
    # compiler the contract of that case is checked instead (never a skip).
    monkeypatch.setenv("WORKBENCH_CACHE", str(tmp_path))
    if not jit.have_compiler():
        _no_compiler_contract(tmp_path, monkeypatch)
        return
    x = ca.SX.sym("x", 2)
    fun = ca.Function("wb_test_cache", [x], [ca.vertcat(ca.sin(x[0]) * x[1], x[0] ** 3)])
    first = jit.compiled(fun)
    libs = sorted(tmp_path.glob("wb_test_cache_*.so"))
    assert len(libs) == 1
    stamp = libs[0].stat().st_mtime_ns
    # plain C source (the benchmark loop's C driver) goes through the same cache
    src = "double wb_twice(double x) { return 2.0 * x; }\n"
    so, cached = jit.shared_library("wb_test_src", src)
    assert not cached and so.parent == tmp_path

    def no_compiler(*args, **kwargs):
        raise AssertionError("the compiler ran on a cache hit")
    monkeypatch.setattr(subprocess, "run", no_compiler)
    second = jit.compiled(fun)
    assert sorted(tmp_path.glob("wb_test_cache_*.so")) == libs
    assert libs[0].stat().st_mtime_ns == stamp
    v = [0.3, -1.2]
    assert np.array_equal(np.asarray(first(v)), np.asarray(second(v)))
    assert np.allclose(np.asarray(second(v)), np.asarray(fun(v)), rtol=1e-15, atol=0)
    assert jit.shared_library("wb_test_src", src) == (so, True)


def _no_compiler_contract(cache, monkeypatch):
    """Without a C compiler: :func:`jit.compiled` returns the Function itself (the
    virtual machine evaluates it, same numbers), :func:`jit.shared_library` refuses a
    source it would have to build with a CompileError naming the compiler and writes
    nothing, and a library already in the cache under the documented key
    (``{name}_{sha256(source + flags + casadi version)[:20]}.so``, key computed here
    with hashlib) is found without any compiler run."""
    import hashlib
    x = ca.SX.sym("x", 2)
    fun = ca.Function("wb_test_nocc", [x], [ca.vertcat(ca.sin(x[0]) * x[1], x[0] ** 3)])
    assert jit.compiled(fun) is fun
    src = "double wb_twice(double x) { return 2.0 * x; }\n"
    # "no C compiler found", or "the C compiler failed" when $CC names a missing one
    with pytest.raises(jit.CompileError, match="C compiler"):
        jit.shared_library("wb_test_src", src)
    assert list(cache.glob("*")) == []
    key = hashlib.sha256(src.encode() + b"-O2" + ca.__version__.encode()).hexdigest()[:20]
    assert jit.source_digest(src.encode(), ("-O2",)) == key
    planted = cache / f"wb_test_src_{key}.so"
    planted.write_bytes(b"\x7fELF stand-in")
    # another flag set is another key: not a hit, and still no compiler to build it
    with pytest.raises(jit.CompileError, match="C compiler"):
        jit.shared_library("wb_test_src", src, (("-O3",),))
    assert list(cache.glob("*")) == [planted]

    def no_compiler(*args, **kwargs):
        raise AssertionError("a compiler ran on a cache hit")
    monkeypatch.setattr(subprocess, "run", no_compiler)
    assert jit.shared_library("wb_test_src", src) == (planted, True)


def test_jit_without_compiler(tmp_path, monkeypatch):
    # the no-compiler contract on every machine: no CC, no compiler on the PATH
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("WORKBENCH_CACHE", str(tmp_path))
    monkeypatch.setattr(jit, "c_compiler", lambda: None)
    assert not jit.have_compiler()
    _no_compiler_contract(tmp_path, monkeypatch)
