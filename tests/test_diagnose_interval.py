"""A fitted value's 95 % interval on a flat or rough cost (refit._evaluated_span).

The Gauss-Newton interval is the cost's curvature at the solution. A position-only
recording's friction cost is flat along a valley and rough across it: the interval came
out 25.6-26.2 N where values of 13-29 N fit within a few percent (session 12, h12p). Every
point the fit evaluated whose residual sum of squares lies within chi2(1, 0.95) = 3.84
residual variances of the lowest evaluated is a witness: its value of each parameter lies
in that parameter's profile-likelihood interval, so the interval must reach it.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from workbench.diagnose.candidates import Candidate, Free
from workbench.diagnose.refit import CHI2_95_1, _evaluated_span, _residual_variance

M = 200                 # residuals per replay; n_eff = M: no inflation, s2 = ssr / (M - k)


def _stand_in(points):
    """An objective stand-in whose cache holds one residual vector per (a, b) point, of
    the given residual sum of squares (same direction, scaled: only the sum matters)."""
    cand = Candidate("stand_in", "parameter_error",
                     (Free("a", -10.0, 10.0, 1.0, log=False), Free("b", -10.0, 10.0, 0.0, log=False)))
    e = np.random.default_rng(0).normal(size=M)
    cache = {np.array(z, dtype=float).tobytes(): e * np.sqrt(ssr / (e @ e)) for z, ssr in points}
    obj = SimpleNamespace(cand=cand, shpe=SimpleNamespace(n_eff=float(M)), _cache=cache,
                          lo=np.array([-10.0, -10.0]), hi=np.array([10.0, 10.0]))
    return obj, e


def test_the_interval_reaches_every_evaluated_point_inside_the_likelihood_region():
    """Best fit a = 1 (ssr = M, so s2 = M / (M - 2)); a = 3 costs 2 s2 more (inside:
    2 < 3.84), a = -2 costs 5 s2 more (outside), b = 4 costs 3.5 s2 more (inside). The
    Gauss-Newton interval (0.9, 1.1) for a widens to (0.9, 3.0), not to -2; b's (-0.1, 0.1)
    to (-0.1, 4.0). A chi-square of two degrees of freedom (5.99: the joint region, not the
    profile of one value) takes in a = -2 and goes red."""
    s2 = M / (M - 2)
    obj, e = _stand_in([((1.0, 0.0), M), ((3.0, 0.0), M + 2.0 * s2),
                        ((-2.0, 0.0), M + 5.0 * s2), ((1.0, 4.0), M + 3.5 * s2)])
    r = e * np.sqrt(M / (e @ e))
    assert _residual_variance(r, 2, M) == pytest.approx(s2, rel=1e-12)
    ci = _evaluated_span(obj, r, {"a": (0.9, 1.1), "b": (-0.1, 0.1)})
    assert ci["a"] == pytest.approx((0.9, 3.0), abs=1e-12)
    assert ci["b"] == pytest.approx((-0.1, 4.0), abs=1e-12)
    assert CHI2_95_1 == pytest.approx(3.841458820694124, rel=1e-12)   # scipy chi2.ppf(.95, 1)


def test_the_region_is_measured_from_the_lowest_point_evaluated_not_the_solution():
    """The least squares may end above a point the scan or the pattern search saw (a rough
    cost). With a point 1.5 s2 below the solution, a = 3 at 3 s2 above the solution is
    4.5 s2 above the lowest: outside. Measuring from the solution takes it in (red)."""
    s2 = M / (M - 2)
    obj, e = _stand_in([((1.0, 0.0), M), ((2.0, 0.0), M - 1.5 * s2), ((3.0, 0.0), M + 3.0 * s2)])
    r = e * np.sqrt(M / (e @ e))
    ci = _evaluated_span(obj, r, {"a": (0.9, 1.1), "b": (-0.1, 0.1)})
    assert ci["a"] == pytest.approx((0.9, 2.0), abs=1e-12)
    assert ci["b"] == pytest.approx((-0.1, 0.1), abs=1e-12)


def test_an_evaluated_point_beyond_a_bound_counts_at_the_bound():
    """The objective replays a point outside the bounds clipped to them (refit._Objective):
    its witness value is the clipped one."""
    s2 = M / (M - 2)
    obj, e = _stand_in([((1.0, 0.0), M), ((14.0, 0.0), M + 1.0 * s2)])
    r = e * np.sqrt(M / (e @ e))
    ci = _evaluated_span(obj, r, {"a": (0.9, 1.1), "b": (-0.1, 0.1)})
    assert ci["a"] == pytest.approx((0.9, 10.0), abs=1e-12)
