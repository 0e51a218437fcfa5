"""SQP mode on a stuck piston (issue 14): the full Gauss-Newton steps fell into a
2-cycle there (qp.SQP_DAMPING's text); the steps that stop contracting are halved, in
the Python update and the compiled sample alike."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from workbench import Plant, simulate
from workbench.controllers.mpc import NMPC

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_mpc_friction import RIG, T  # noqa: E402


class _Recorder:
    """The controller, its memories kept (iterations per sample)."""

    def __init__(self, inner) -> None:
        self.inner, self.states = inner, []
        self.sample_time, self.needs = inner.sample_time, inner.needs

    def reset(self):
        return self.inner.reset()

    def update(self, state, r, y):
        new, u = self.inner.update(state, r, y)
        self.states.append(new)
        return new, u


def _run(compiled: bool):
    plant = Plant(Plant.from_toml(RIG).params.without_effect("line_dynamics"))
    nmpc = NMPC.for_plant(plant, effects=["dry_friction"], sample_time=T, horizon=40,
                          max_speed=2.0, disturbance_gain=0.1, mode="sqp", jit=True,
                          compiled_sample=compiled)
    if compiled and nmpc.compiled_reason is not None:
        pytest.skip(nmpc.compiled_reason)
    rec = _Recorder(nmpc)
    # 0.2-0.3 mm steps every 0.1 s: the piston sticks after each (friction 15/25 N)
    ref = simulate.steps([0.25, 0.2502, 0.2499], hold=0.1)
    run = simulate.closed_loop(plant, rec, ref, x0=0.25, t_end=0.24, progress=False)
    its = np.array([s.info.iterations for s in rec.states])
    return run, its, nmpc.max_iterations


@pytest.fixture(scope="module")
def python_run():
    return _run(False)


def test_sqp_converges_on_a_stuck_piston(python_run):
    _, its, cap = python_run
    assert len(its) >= 120
    # full steps: samples 51-53 and 101-104 ran into the 30-iteration cap (a 2-cycle:
    # the plan alternating between two, its step 0.0063 for ever); halved steps: only
    # sample 101 (it converges in 40 iterations; 1 of 201 over the whole 0.4 s)
    assert np.sum(its >= cap) <= 1, np.flatnonzero(its >= cap)
    assert np.all(its[51:54] < cap)


def test_compiled_sample_damps_as_the_python_update(python_run):
    run, its, _ = python_run
    fast, its_fast, _ = _run(True)
    assert np.array_equal(its, its_fast)
    ua, ub = (np.asarray(r["u"], dtype=float).ravel() for r in (run, fast))
    assert np.max(np.abs(ua - ub)) < 1e-6          # V: the same steps, other rounding
