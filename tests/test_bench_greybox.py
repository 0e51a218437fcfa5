"""``workbench bench greybox`` and its plain baseline (workbench.bench.baselines_greybox).

The baseline (scipy least_squares on CVODES single-shooting replays) must reach the
accuracy it is compared at: the maximum-likelihood estimate of the four parameters,
which the workbench's estimator (multiple shooting, Radau steps, IPOPT: a different
method on the same data) computes independently, with its standard deviations.
Timings are not asserted (the machine is shared).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench.bench import baselines_greybox, greybox
from workbench.errors import InputError
from workbench.recording import Recording

NAMES = list(greybox.TRUTH)


@pytest.fixture(scope="module")
def short_case():
    """A 2 s recording of the bench's rig, ours and the baseline's fit of it."""
    from workbench.identify.grey_box import estimate
    _, start, rec = greybox.problem(2.0)
    ours = estimate(start, [rec], NAMES)
    base = baselines_greybox.fit(start, rec, NAMES, greybox.NOISE)
    return start, rec, ours, base


def test_least_squares_baseline_reaches_the_maximum_likelihood_estimate(short_case):
    _, _, ours, base = short_case
    assert base["status"] > 0, base["message"]
    for name, std in zip(NAMES, ours.std_):
        est, ref = base["estimates"][name], ours.estimates[name]
        # both minimise the same noise-weighted output error from the same data: they
        # differ by integration error and stopping only. 0.25 std is the bench's
        # "same accuracy" (it adds 3 % to the rms error); measured 0.001-0.03 std.
        assert abs(est - ref) <= greybox.SAME_ACCURACY_STD * std, name
        # and the estimate is a statistically sound one: within 4 std of the truth
        assert abs(est - greybox.TRUTH[name]) <= 4.0 * std, name
    # the fitted initial state is the rig's (0.25 m, at rest, 3.5 bar both sides) to
    # within a few sensor-noise levels (10 um, 200 Pa)
    x0 = np.asarray(base["x0"])
    assert abs(x0[0] - 0.25) < 3e-5 and abs(x0[1]) < 1e-3
    assert np.all(np.abs(x0[2:] - 3.5e5) < 600.0)
    # the residuals are at the noise level: cost ~ 0.5 * number of residuals
    n = 3 * 2001
    assert 0.4 * n < base["cost"] < 0.6 * n


def test_jacobian_by_sensitivities_reaches_the_same_estimates(short_case):
    start, rec, ours, base = short_case
    sens = baselines_greybox.fit(start, rec, NAMES, greybox.NOISE, jacobian="sensitivities")
    assert sens["njev"] > 0
    for name, std in zip(NAMES, ours.std_):
        # the same minimum up to the stopping tolerance: 0.05 std
        assert abs(sens["estimates"][name] - base["estimates"][name]) <= 0.05 * std, name


def test_baseline_rejects_bad_input(short_case):
    start, rec, _, _ = short_case
    with pytest.raises(InputError, match="noise"):
        baselines_greybox.fit(start, rec, NAMES, {"x": 1e-5, "p_a": 200.0})
    with pytest.raises(InputError, match="names"):
        baselines_greybox.fit(start, rec, ["load.no_such"], greybox.NOISE)
    with pytest.raises(InputError, match="jacobian"):
        baselines_greybox.fit(start, rec, NAMES, greybox.NOISE, jacobian="exact")
    t = rec.t.copy()
    t[5:] += 1e-4                                     # one uneven step
    cols = {c: rec[c] for c in ("u", "x", "p_a", "p_b")}
    uneven = Recording.from_arrays(t, **cols)
    with pytest.raises(InputError, match="uniform"):
        baselines_greybox.fit(start, uneven, NAMES, greybox.NOISE)


def test_bench_greybox_reports_the_baseline_at_the_same_accuracy():
    res = greybox.bench(quick=True)
    json.dumps(res)                                   # plain data
    row = res["baselines"]["least_squares"]
    assert row["available"] and row["same_accuracy"]
    assert row["ratio"] == pytest.approx(row["median_s"] / res["median_s"])
    assert row["cpu_ratio"] == pytest.approx(row["cpu_median_s"] / res["cpu_median_s"])
    assert max(row["distance_from_ours_std"].values()) <= greybox.SAME_ACCURACY_STD
    assert row["error"] == pytest.approx(max(abs(v) for v in row["relative_error"].values()))
