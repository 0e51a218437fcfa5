"""Every law of workbench.physics gives the same value on every backend.

Each public function of ``workbench.physics`` (enumerated from the modules'
``__all__``, so a new function without a case here fails
:func:`test_every_public_function_has_a_case`) is evaluated on a set of points
that visits each of its branches (choked / subsonic / laminar patch / reverse
flow, stick / break-away / slip, inside / outside the deadband, at and through
the end stops ...):

* point by point with Python floats (the reference),
* once with numpy arrays (element-wise, must return numpy, never CasADi DM),
* through a ``casadi.Function`` of SX symbols and one of MX symbols, every
  numeric argument (also the parameters) symbolic, as the plant builds them.

Tolerance: 1e-12 relative (plus 1e-12 of the largest magnitude, for values that
cross zero). The formulas are the same on every backend, so only the elementary
functions can differ: numpy's SIMD exp/pow/tanh and the C library's differ by a
few ulp (~1e-16), and the worst amplification in these laws is the cancellation
1 - x^((gamma-1)/gamma) of the nozzle law near x = 1 (factor ~1e3 on the test
points). A wrong branch or formula differs by far more than 1e-12.
"""

from __future__ import annotations

import inspect
import math

import casadi as ca
import numpy as np
import pytest

from workbench import physics
from workbench.physics import ops

RTOL = 1e-12   # see the module docstring

A = np.array


def _iso_pairs():
    """(p1, p2) pairs, Pa: choked, subsonic, laminar patch, equal, reverse of each."""
    fwd = [(6e5, 1e5),                 # choked (ratio 0.17 < b)
           (6e5, 4.5e5),               # subsonic
           (6e5, 6e5 * (1 - 2e-3)),    # laminar patch (ratio within the margin of 1)
           (3e5, 3e5),                 # equal pressures: zero flow
           (2e5, 2e5 * (1 - 6e-3))]    # just outside the patch
    rev = [(b, a) for a, b in fwd]      # the same, flowing backwards
    p1, p2 = zip(*(fwd + rev))
    return A(p1), A(p2)


P1, P2 = _iso_pairs()
N_ISO = len(P1)
T1 = np.linspace(280.0, 320.0, N_ISO)
T2 = np.linspace(300.0, 270.0, N_ISO)
RATIO = A([0.05, 0.23, 0.4, 0.528, 0.6, 0.9, 0.996, 0.9999, 1.0])   # iso/nozzle branches
OPEN = A([-1.0, -0.6, -0.02, 0.0, 0.01, 0.3, 1.0])                  # signed openings
V = A([-0.3, -0.02, -5e-5, 0.0, 2e-5, 0.004, 0.25])                  # m/s, band is 1e-4
PHI, PSI_IN, PSI_OUT = [1e-4, -2e-5], [0.02, -0.002, -1e-4], [1e-3, 3e-3]
GAMMA_COEF = [1.0, 0.2, 0.05]


def _case(*args, **kwargs):
    return (args, kwargs)


#: "module.function" -> list of (args, static kwargs). ndarray args vary per point,
#: float args are shared (symbolic in SX/MX), lists recurse.
CASES = {
    "gas.smooth_sqrt": [_case(A([-1.0, -0.004, -1e-3, 0.0, 2e-3, 5e-3, 0.3, 2.0]), 0.005)],
    "gas.speed_of_sound": [_case(A([250.0, 293.15, 350.0]))],
    "gas.nozzle_cm": [_case(RATIO, gamma=1.4), _case(RATIO, gamma=1.3)],
    "gas.nozzle_flow": [_case(2e-6, P1, P2, T1, T2, 0.8)],
    "gas.iso6358_psi": [_case(RATIO, 0.23, 0.005), _case(RATIO, 0.45)],
    "gas.iso6358_flow": [_case(6.25e-8, 0.23, P1, P2, T1, T2)],
    "valve.spool_position": [_case(A([-1.0, 0.0, 2.5, 5.1, 7.0, 10.2, 12.0]), 5.0, 5.0, 0.1)],
    "valve.effective_opening": [_case(OPEN, 0.05), _case(OPEN, 0.0)],   # in/out of the band
    "valve.edge_openings": [_case(OPEN, 0.0), _case(OPEN, 0.03)],
    "valve.rounded_edge_openings": [_case(OPEN, 0.0), _case(OPEN, 0.05)],
    "valve.underlap_openings": [_case(OPEN, 0.04, law="linear"),
                                _case(OPEN, 0.04, law="rounded")],
    "valve.four_edge_flows": [
        _case(OPEN, 6e5, np.linspace(1.2e5, 5.9e5, 7), np.linspace(5.99e5, 1.02e5, 7),
              1.01325e5, 6e-8, 0.3, 293.0, np.linspace(280.0, 320.0, 7), 300.0, 0.0),
        _case(OPEN, 6e5, np.linspace(1.2e5, 5.9e5, 7), np.linspace(5.99e5, 1.02e5, 7),
              1.01325e5, 6e-8, 0.3, 293.0, 290.0, 300.0, 0.02, underlap_law="rounded")],
    "valve.spool_dynamics": [_case(A([0.0, 4.0, 9.0]), A([-50.0, 0.0, 30.0]),
                                   A([5.0, 2.0, 10.0]), 80.0, 0.7)],
    "valve.polyval": [_case([1.0, -2.0, 0.5], A([-2.0, 0.0, 0.7, 6.0]))],
    "valve.gamma_odd": [_case(OPEN, GAMMA_COEF)],
    "valve.affine_flow": [_case(A([1.2e5, 3e5, 4e5, 5.5e5]), A([-0.7, 0.0, 0.2, 1.0]),
                                PHI, PSI_IN, PSI_OUT)],
    "valve.affine_port_flows": [
        _case(OPEN, np.linspace(1.1e5, 5.8e5, 7), np.linspace(5.5e5, 1.3e5, 7),
              PHI, PSI_IN, PSI_OUT, GAMMA_COEF, 1e5, 0.0),
        _case(OPEN, np.linspace(1.1e5, 5.8e5, 7), 3e5, PHI, PSI_IN, PSI_OUT, GAMMA_COEF,
              1e5, 1e-3)],
    "chamber.volumes": [_case(A([-0.01, 0.0, 0.2, 0.5, 0.51]), A([-0.2, 0.0, 0.1, 0.3, 0.0]),
                              3e-4, 2.5e-4, 0.5, 1e-5, 1.2e-5)],
    "chamber.pressure_rate": [_case(A([1.2e5, 3e5, 5e5]), A([1e-4, 5e-5, 2e-4]),
                                    A([2e-5, 0.0, -3e-5]), A([1e-3, 0.0, -2e-3]), 1.3, 293.0)],
    "chamber.inflow_for_pressure_rate": [_case(A([1.2e5, 3e5, 5e5]), A([1e-4, 5e-5, 2e-4]),
                                               A([2e-5, 0.0, -3e-5]), A([4e6, 0.0, -1e6]),
                                               1.3, 293.0)],
    "chamber.pressure_temperature_rates": [
        _case(A([1.2e5, 3e5, 5e5]), A([280.0, 300.0, 330.0]), A([1e-4, 5e-5, 2e-4]),
              A([2e-5, 0.0, -3e-5]), A([0.3, 0.0, 0.1]), A([1e-3, 0.0, 3e-4]),
              A([0.0, 2e-4, 1e-4]), 0.5, 293.0)],
    "chamber.chamber_mass": [_case(A([1e5, 3e5, 6e5]), A([1e-5, 1e-4, 2e-4]), 293.0)],
    "friction.stribeck_level": [_case(V, 20.0, 30.0, 0.01)],
    "friction.smooth_friction": [_case(V, 20.0, 30.0, 0.01, 50.0, 1e-3)],
    "friction.stick_slip_acceleration": [
        # stick (|F| <= Fs in the band), break-away (|F| > Fs in the band), slip both ways
        _case(A([0.0, 5e-5, -5e-5, 0.0, 5e-5, -3e-5, 0.02, -0.3, 0.5, 0.0]),
              A([10.0, -25.0, 29.0, 45.0, -80.0, 31.0, 100.0, -5.0, 0.0, -30.0]),
              2.0, 50.0, 20.0, 30.0, 0.01)],
    "piston.pneumatic_force": [_case(A([1e5, 3e5, 6e5]), A([6e5, 3e5, 1e5]), 3e-4,
                                     2.5e-4, 1.01325e5)],
    "piston.end_stop_force": [
        # inside, at each stop, through each stop moving in and out; the last two
        # leave a stop faster than the contact pushes (clipped: a stop never pulls)
        _case(A([0.2, 0.0, 0.5, -1e-3, -1e-3, -1e-4, 0.501, 0.501, 0.5001, -1e-4, 0.5001]),
              A([0.1, -0.1, 0.1, -0.2, 0.3, 0.05, 0.2, -0.4, -0.01, 0.3, -0.3]), 0.5, 2.0)],
    "supply.reservoir_rate": [_case(A([5.0e5, 5.9e5, 6.0e5, 6.1e5]), 6e5, 1e-7, 1e-3,
                                    A([2e-3, 1e-3, 0.0, 0.0]), 293.0)],
    "supply.leak_to_atmosphere": [_case(A([0.9e5, 1.01325e5, 1.02e5, 3e5, 6e5]),
                                        1.01325e5, 1e-10, 293.0)],
    "supply.cross_piston_leak": [_case(A([1e5, 3e5, 6e5]), A([6e5, 3e5, 1e5]), 1e-9)],
    "line.pressure_drop": [_case(A([-0.01, -1e-6, 0.0, 1e-6, 0.01]),
                                 A([2e5, 3e5, 4e5, 5e5, 6e5]), 4e-3, 0.2, 293.0)],
    "line.line_rates": [_case([A([4e5, 2e5]), A([3.9e5, 2.1e5]), A([3.8e5, 2.2e5])],
                              [A([1e-3, -1e-3]), A([2e-3, 0.0]), A([1.5e-3, -2e-4])],
                              A([3e-3, -1e-3]), A([3.7e5, 2.3e5]), 1.5, 4e-3, 293.0)],
}

#: Public functions that are not laws evaluated on signals, and why.
EXEMPT = {
    "line.default_segments": "an integer segment count chosen from the line length when "
                             "the model is built (math.ceil), not a law on signals",
    "valve.fit_affine_to_four_edge": "a least-squares fit on a numpy grid returning an "
                                     "AffineValveFit; its reference law four_edge_flows "
                                     "is covered here",
}


def _public_functions() -> list[str]:
    names = []
    for mod_name in physics.__all__:
        if mod_name == "ops":                   # tested against math/numpy below
            continue
        mod = getattr(physics, mod_name)
        for name in mod.__all__:
            if inspect.isfunction(getattr(mod, name)):
                names.append(f"{mod_name}.{name}")
    return names


def _function(path: str):
    mod, name = path.split(".")
    return getattr(getattr(physics, mod), name)


# ---------------------------------------------------------------------- evaluation
def _points(args) -> int:
    sizes = {a.size for a in _leaves(args) if isinstance(a, np.ndarray)}
    assert len(sizes) == 1, "every varying argument of a case needs the same length"
    return sizes.pop()


def _leaves(tree):
    if isinstance(tree, (list, tuple)):
        return [x for t in tree for x in _leaves(t)]
    return [tree]


def _map(tree, fun):
    if isinstance(tree, (list, tuple)):
        return [_map(t, fun) for t in tree]
    return fun(tree)


def _on_floats(fn, args, kwargs, n):
    rows = []
    for i in range(n):
        out = _leaves(fn(*_map(args, lambda a: float(a[i]) if isinstance(a, np.ndarray)
                               else a), **kwargs))
        for leaf in out:
            assert isinstance(leaf, float), f"float inputs gave {type(leaf).__name__}"
        rows.append(out)
    return np.array(rows).T                       # (outputs, points)


def _on_numpy(fn, args, kwargs, n):
    out = _leaves(fn(*args, **kwargs))
    for leaf in out:
        assert isinstance(leaf, (np.ndarray, float)), \
            f"numpy inputs gave {type(leaf).__name__} (expected numpy, not CasADi)"
    return np.array([np.broadcast_to(np.asarray(leaf, dtype=float), (n,)) for leaf in out])


def _on_casadi(fn, args, kwargs, n, sym):
    symbols, values = [], []

    def make(a):
        s = sym.sym(f"a{len(symbols)}")
        symbols.append(s)
        values.append(np.broadcast_to(np.asarray(a, dtype=float), (n,)).reshape(1, -1))
        return s
    out = _leaves(fn(*_map(args, make), **kwargs))
    out = [leaf if isinstance(leaf, sym) else sym(leaf) for leaf in out]
    f = ca.Function("law", symbols, out).map(n)
    res = f(*values)
    res = res if isinstance(res, tuple) else (res,)
    return np.array([np.asarray(r, dtype=float).ravel() for r in res])


def _close(got, ref, what):
    """|got - ref| <= RTOL (|ref| + max |ref| of that output) at every point."""
    tol = RTOL * (np.abs(ref) + np.max(np.abs(ref), axis=1, keepdims=True))
    excess = np.abs(got - ref) - tol
    assert got.shape == ref.shape, f"{what}: shape {got.shape} != {ref.shape}"
    assert np.all(excess <= 0), (f"{what}: differs from the float value by up to "
                                 f"{np.max(np.abs(got - ref) / np.maximum(tol, 1e-300)):.3g}"
                                 " times the tolerance")


# ---------------------------------------------------------------------- the tests
def test_every_public_function_has_a_case():
    public = set(_public_functions())
    missing = sorted(public - set(CASES) - set(EXEMPT))
    assert not missing, f"physics functions without a backend case: {missing}"
    stale = sorted((set(CASES) | set(EXEMPT)) - public)
    assert not stale, f"cases for functions that are not public: {stale}"


@pytest.mark.parametrize("path", sorted(CASES))
def test_same_value_on_every_backend(path):
    fn = _function(path)
    for args, kwargs in CASES[path]:
        n = _points(args)
        ref = _on_floats(fn, args, kwargs, n)
        assert np.all(np.isfinite(ref)), f"{path}: non-finite reference"
        _close(_on_numpy(fn, args, kwargs, n), ref, f"{path} numpy")
        _close(_on_casadi(fn, args, kwargs, n, ca.SX), ref, f"{path} SX")
        _close(_on_casadi(fn, args, kwargs, n, ca.MX), ref, f"{path} MX")


def test_cases_visit_the_branches():
    """The points above do reach the branches the module docstring names."""
    from workbench.physics import friction, gas, piston, valve
    ratio = np.minimum(P1, P2) / np.maximum(P1, P2)
    assert np.any(ratio < 0.23) and np.any((ratio > 0.23) & (ratio < 1 - 0.005))
    assert np.any((ratio > 1 - 0.005) & (ratio < 1)) and np.any(ratio == 1)
    q = gas.iso6358_flow(6.25e-8, 0.23, P1, P2)
    assert np.any(q > 0) and np.any(q < 0) and np.any(q == 0)
    v, f = CASES["friction.stick_slip_acceleration"][0][0][:2]
    a = friction.stick_slip_acceleration(v, f, 2.0, 50.0, 20.0, 30.0, 0.01)
    stick, held = np.abs(v) < friction.STICK_VELOCITY, np.abs(f) <= 30.0
    assert np.any(stick & held) and np.any(stick & ~held) and np.any(~stick)
    np.testing.assert_array_equal(a[stick & held], -v[stick & held] / friction.STICK_TIME_CONSTANT)
    o = valve.effective_opening(OPEN, 0.05)
    assert np.any(o == 0.0) and np.any(o != 0.0)       # inside and outside the deadband
    x, vv = CASES["piston.end_stop_force"][0][0][:2]
    force = piston.end_stop_force(x, vv, 0.5, 2.0)
    assert np.any(force > 0) and np.any(force < 0)
    assert np.any((x < 0) & (force == 0)) and np.any((x > 0.5) & (force == 0))


# ---------------------------------------------------------------------- ops itself
SPECIAL = [-2.5, -1.0, -0.0, 0.0, 1e-300, 0.3, 1.0, 2.5, 700.0, 800.0, math.nan]


def _math_ref(name, x):
    """Reference with CasADi's conventions, written with :mod:`math` only."""
    if math.isnan(x):
        return math.nan
    if name == "sqrt":
        return math.sqrt(x) if x >= 0 else math.nan
    if name == "exp":
        return math.exp(x) if x < 709.0 else math.inf
    if name == "log":
        return math.log(x) if x > 0 else (-math.inf if x == 0 else math.nan)
    if name == "tanh":
        return math.tanh(x)
    if name == "fabs":
        return math.fabs(x)
    return 0.0 if x == 0 else math.copysign(1.0, x)


@pytest.mark.parametrize("name", ["sqrt", "exp", "log", "tanh", "fabs", "sign"])
def test_ops_unary_against_math_numpy_and_casadi(name):
    op = getattr(ops, name)
    ref = np.array([_math_ref(name, x) for x in SPECIAL])
    got = np.array([op(x) for x in SPECIAL])
    assert all(type(op(x)) is float for x in SPECIAL)
    # math and the scalar backend call the same C library: exactly equal
    np.testing.assert_array_equal(got, ref)
    arr = np.array(SPECIAL)
    with np.errstate(all="ignore"):
        npy = op(arr)
        np_ref = {"fabs": np.abs}.get(name, getattr(np, name, None))(arr)
    assert isinstance(npy, np.ndarray)
    np.testing.assert_array_equal(npy, np_ref)          # it is the numpy ufunc
    # numpy's SIMD and the C library may differ by an ulp or two
    np.testing.assert_allclose(npy, ref, rtol=1e-15)
    x = ca.SX.sym("x")
    f = ca.Function("f", [x], [op(x)])
    sx = np.array([float(f(v)) for v in SPECIAL])
    np.testing.assert_allclose(sx, ref, rtol=1e-15)     # casadi calls std:: maths
    assert isinstance(op(ca.DM(0.3)), ca.DM) and isinstance(op(ca.MX.sym("y")), ca.MX)


def test_ops_fmin_fmax_clip_follow_c99():
    nan = math.nan
    for a, b in [(1.0, 2.0), (2.0, 1.0), (-0.5, -0.5), (nan, 3.0), (3.0, nan)]:
        assert ops.fmin(a, b) == np.fmin(a, b) == float(ca.fmin(a, b))
        assert ops.fmax(a, b) == np.fmax(a, b) == float(ca.fmax(a, b))
        assert type(ops.fmin(a, b)) is float
    xs = np.array([-3.0, 0.0, 0.5, 1.0, 7.0])
    np.testing.assert_array_equal(ops.clip(xs, 0.0, 1.0), np.clip(xs, 0.0, 1.0))
    assert [ops.clip(float(x), 0.0, 1.0) for x in xs] == list(np.clip(xs, 0.0, 1.0))
    x = ca.SX.sym("x")
    f = ca.Function("f", [x], [ops.clip(x, 0.0, 1.0)])
    np.testing.assert_array_equal(np.asarray(f(xs.reshape(1, -1))).ravel(), np.clip(xs, 0, 1))


def test_ops_where_and_backend_choice():
    assert ops.backend(1.0, 2) == "float" and ops.backend(np.float64(1.0)) == "float"
    assert ops.backend(1.0, np.zeros(2)) == "numpy"
    assert ops.backend(np.zeros(2), ca.DM(1.0)) == "casadi"
    assert ops.backend(ca.SX.sym("a")) == "casadi" and ops.is_symbolic(ca.MX.sym("b"))
    assert not ops.is_symbolic(ca.DM(1.0), np.zeros(2), 1.0)
    assert ops.where(True, 1.0, math.nan) == 1.0 and math.isnan(ops.where(False, 1.0, math.nan))
    c = np.array([True, False, True])
    np.testing.assert_array_equal(ops.where(c, np.array([1.0, 2.0, math.nan]), 5.0),
                                  [1.0, 5.0, math.nan])
    x = ca.SX.sym("x")
    # a NaN/inf in the branch not taken does not leak (casadi's if_else multiplies it out)
    f = ca.Function("f", [x], [ops.where(x > 0, 1.0 / x, 7.0)])
    assert float(f(0.0)) == 7.0 and float(f(4.0)) == 0.25
    assert ops.if_else is ops.where and ops.PI == ca.pi == math.pi


def test_ops_quiet_silences_the_branch_not_taken():
    import warnings
    p = np.array([0.0, 2e5])
    with warnings.catch_warnings():
        warnings.simplefilter("error")            # any RuntimeWarning fails the test
        with ops.quiet():
            r = np.array([1e5, 1e5]) / p
        q = physics.gas.iso6358_flow(1e-8, 0.3, p, 1e5)   # p = 0: 1e5/0 in the branch not taken
    assert np.isinf(r[0]) and q[0] < 0 < q[1]


def test_every_ops_name_is_tested():
    tested = {"backend", "is_symbolic", "fmin", "fmax", "clip", "sqrt", "exp", "log", "tanh",
              "fabs", "sign", "where", "if_else", "quiet", "PI"}
    assert set(ops.__all__) == tested
