"""Simulated ARX output (workbench.identify.rls.simulate) against scipy.signal.lfilter.

A held parameter vector is a linear time-invariant filter: the simulation from the
filter's own first samples (only those are passed as the recording) must equal
lfilter(B, A, u); integrated, its cumulative sum; in a loop
u = -kp y + d, the closed-loop filter B / (A + kp B) driven by d. Differences are
rounding only (1e-12 relative to outputs of order 1).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from workbench.errors import InputError
from workbench.identify.rls import a_priori_track, rls, simulate_tarx

A = [1.0, -1.5, 0.7]          # y(k) - 1.5 y(k-1) + 0.7 y(k-2) = u(k-1) + 0.5 u(k-2)
B = [0.0, 1.0, 0.5]
THETA = np.array([-1.5, 0.7, 1.0, 0.5])


@pytest.fixture(scope="module")
def u():
    return np.random.default_rng(3).choice([-1.0, 1.0], 300)


def test_open_loop_is_the_filter(u):
    y = signal.lfilter(B, A, u)
    ys, us = simulate_tarx(THETA, (2, 2, 1), np.where(np.arange(len(u)) < 2, y, 0.0), u,
                           start=2)
    assert np.max(np.abs(ys - y)) < 1e-12 * np.max(np.abs(y))
    assert np.array_equal(us, u)


def test_integrated_output_is_the_cumulative_sum(u):
    v = signal.lfilter(B, A, u)
    rec = np.where(np.arange(len(u)) < 3, np.cumsum(v), 0.0)
    ys, _ = simulate_tarx(THETA, (2, 2, 1), rec, u, start=3, integrate=True)
    assert np.max(np.abs(ys - np.cumsum(v))) < 1e-10 * np.max(np.abs(np.cumsum(v)))


def test_loop_is_the_closed_loop_filter(u):
    kp = 0.3
    y = signal.lfilter(B, np.array(A) + kp * np.array(B), u)
    first = np.arange(len(u)) < 2
    ys, us = simulate_tarx(THETA, (2, 2, 1), np.where(first, y, 0.0),
                           np.where(first, -kp * y + u, 0.0), start=2,
                           feedback=lambda k, yk: -kp * yk + u[k])
    assert np.max(np.abs(ys - y)) < 1e-12 * np.max(np.abs(y))
    assert np.allclose(us[2:], -kp * y[2:] + u[2:], rtol=0, atol=1e-12)


def test_time_varying_track_uses_the_previous_estimate(u):
    """a_priori_track puts theta(k-1) at sample k: with it the one-step prediction
    phi(k)' theta(k-1) is the recording minus RLS's a priori error, to rounding (after
    the first estimate; before it the prior was in force, which the track replaces by
    the first estimate)."""
    y = signal.lfilter(B, A, u) + np.random.default_rng(4).normal(0, 0.01, len(u))
    res = rls(y, u, (2, 2, 1), 0.98)
    track = a_priori_track(res, len(y))
    k = np.arange(res.start_index + 1, len(y))
    pred = (-track[k, 0] * y[k - 1] - track[k, 1] * y[k - 2] + track[k, 2] * u[k - 1]
            + track[k, 3] * u[k - 2])
    assert np.max(np.abs(y[k] - pred - res.errors[1:])) < 1e-9


def test_refusals(u):
    with pytest.raises(InputError, match="start"):
        simulate_tarx(THETA, (2, 2, 1), np.zeros_like(u), u, start=1)
    with pytest.raises(InputError, match="theta"):
        simulate_tarx(THETA[:3], (2, 2, 1), np.zeros_like(u), u, start=2)
    with pytest.raises(InputError, match="nk >= 1"):
        simulate_tarx(THETA, (2, 2, 0), np.zeros_like(u), u, start=2, feedback=lambda k, y: 0.0)
