"""Recursive least squares with forgetting (workbench.identify.rls), paper 002.

References are independent of the code under test: batch least squares
(``numpy.linalg.lstsq``) on regressors built here by an explicit loop, the known true
parameters of simulated systems, the textbook steady-state lag of a forgetting-factor
estimator behind a ramp, Monte-Carlo spread over seeds.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.signal import lfilter

from workbench.errors import InputError
from workbench.identify.rls import choose_forgetting, rls

# --------------------------------------------------------------------------------------
# Test systems (2nd-order ARX as in paper 002, orders (2, 2, 1))
#   y(k) + a1 y(k-1) + a2 y(k-2) = b1 u(k-1) + b2 u(k-2) + e(k)
# --------------------------------------------------------------------------------------
TRUE = np.array([-1.5, 0.7, 1.0, 0.5])       # poles 0.75 +- 0.37j, |z| = 0.84
N_TV = 3000                                  # samples of the time-varying record
JUMP = 1000                                  # a1: -1.5 -> -1.3 at this sample
DRIFT = 2000                                 # b1: ramps 1.0 -> 1.5 from here to the end
SIGMA = 0.1                                  # equation-noise std (y std is about 5)


def prbs(n: int, rng: np.random.Generator, hold: int = 2) -> np.ndarray:
    """Random binary +-1 signal held ``hold`` samples (PRBS-like excitation)."""
    return np.repeat(rng.choice([-1.0, 1.0], n // hold + 1), hold)[:n]


def tv_truth() -> np.ndarray:
    """True [a1, a2, b1, b2] at every sample: a1 jumps, b1 drifts, a2 and b2 constant."""
    k = np.arange(N_TV)
    a1 = np.where(k < JUMP, -1.5, -1.3)                   # |z| stays 0.84 (a2 fixed)
    b1 = np.where(k < DRIFT, 1.0, 1.0 + 0.5 * (k - DRIFT) / (N_TV - 1 - DRIFT))
    return np.column_stack([a1, np.full(N_TV, 0.7), b1, np.full(N_TV, 0.5)])


def simulate_tv(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    th = tv_truth()
    u = prbs(N_TV, rng)
    e = SIGMA * rng.standard_normal(N_TV)
    y = np.zeros(N_TV)
    for k in range(2, N_TV):
        y[k] = (-th[k, 0] * y[k - 1] - th[k, 1] * y[k - 2]
                + th[k, 2] * u[k - 1] + th[k, 3] * u[k - 2] + e[k])
    return y, u


def simulate_ti(n: int, seed: int, sigma: float = SIGMA) -> tuple[np.ndarray, np.ndarray]:
    """Time-invariant system TRUE (scipy lfilter, independent of the code under test)."""
    rng = np.random.default_rng(seed)
    u = prbs(n, rng)
    a = [1.0, TRUE[0], TRUE[1]]
    y = lfilter([0.0, TRUE[2], TRUE[3]], a, u) + lfilter([1.0], a, sigma * rng.standard_normal(n))
    return y, u


@pytest.fixture(scope="module")
def tv_records():
    return [simulate_tv(seed) for seed in range(12)]


# --------------------------------------------------------------------------------------
# lambda = 1 is batch least squares
# --------------------------------------------------------------------------------------
def test_lambda_one_equals_batch_least_squares():
    y, u = simulate_ti(800, seed=7)
    # regressors written out here: phi(k) = [-y(k-1), -y(k-2), u(k-1), u(k-2)], k >= 2
    phi = np.array([[-y[k - 1], -y[k - 2], u[k - 1], u[k - 2]] for k in range(2, y.size)])
    target = y[2:]
    ls, rss, *_ = np.linalg.lstsq(phi, target, rcond=None)
    p0 = 1e6
    res = rls(y, u, (2, 2, 1), forgetting=1.0, p0=p0)
    # With lambda = 1 RLS minimises sum e^2 + |theta - theta0|^2 / p0 (theta0 = 0): the
    # prior moves the answer away from least squares by (Phi'Phi)^-1 theta / p0, i.e.
    # relatively by at most 1 / (p0 * smallest eigenvalue of Phi'Phi). Check that bound
    # is below 1e-6 here, then the 1e-6 relative agreement it implies.
    gram = phi.T @ phi
    bound = 1.0 / (p0 * np.linalg.eigvalsh(gram).min())
    assert bound < 1e-6
    rel = np.abs(res.theta[-1] - ls) / np.abs(ls)
    assert np.all(rel < 1e-6), rel
    # The regularised normal equations are what RLS solves exactly: agreement to
    # rounding (1e-9 relative; the recursion runs 800 rank-one updates).
    reg = np.linalg.solve(gram + np.eye(4) / p0, phi.T @ target)
    assert np.allclose(res.theta[-1], reg, rtol=1e-9, atol=0)
    # Standard deviations: textbook least squares s^2 (Phi'Phi)^-1 with s^2 = RSS/(N-n);
    # equal up to the same prior effect (1e-5 relative covers it with margin).
    s2 = float(rss[0]) / (target.size - 4)
    std_ls = np.sqrt(s2 * np.diag(np.linalg.inv(gram)))
    np.testing.assert_allclose(res.std[-1], std_ls, rtol=1e-5)
    np.testing.assert_allclose(res.covariance, s2 * np.linalg.inv(gram), rtol=1e-5, atol=0)


# --------------------------------------------------------------------------------------
# Tracking: a jump and a drift; lambda = 0.99 vs 0.9 (paper 002's trade-off)
# --------------------------------------------------------------------------------------
def _tracking_numbers(records, lam):
    th = tv_truth()
    tracks, noise = [], []
    for y, u in records:
        res = rls(y, u, (2, 2, 1), forgetting=lam)
        assert res.start_index == 2
        tracks.append(res.theta)
        # noise: std of each estimate over a constant stretch (600 samples after the
        # jump, before the drift: samples 1600..1999)
        noise.append(res.theta[1600 - 2:DRIFT - 2].std(axis=0))
    mean = np.mean(tracks, axis=0)            # mean over seeds: the lag without the noise
    k = np.arange(2, N_TV)
    # lag: samples after the jump until the mean a1 estimate stays within 10 % of the
    # jump size (0.2) of the new value
    err = np.abs(mean[:, 0] - th[2:, 0])
    late = np.flatnonzero((k >= JUMP) & (k < DRIFT) & (err > 0.1 * 0.2))
    lag = int(k[late].max() - JUMP + 1) if late.size else 0
    # drift: mean lag of b1 behind its ramp over the last 300 samples, in samples
    slope = 0.5 / (N_TV - 1 - DRIFT)
    drift_lag = float(np.mean(th[-300:, 2] - mean[-300:, 2]) / slope)
    return lag, np.mean(noise, axis=0), drift_lag, mean


def test_tracks_jump_and_drift_lambda_trade_off(tv_records, record_property):
    lag99, noise99, drift99, mean99 = _tracking_numbers(tv_records, 0.99)
    lag90, noise90, drift90, mean90 = _tracking_numbers(tv_records, 0.9)
    numbers = {"lag_samples": {"0.99": lag99, "0.9": lag90},
               "noise_std_a1_a2_b1_b2": {"0.99": noise99.round(5).tolist(),
                                         "0.9": noise90.round(5).tolist()},
               "drift_lag_samples": {"0.99": round(drift99, 1), "0.9": round(drift90, 1)}}
    print("RLS trade-off (12 seeds):", json.dumps(numbers))
    record_property("rls_trade_off", json.dumps(numbers))
    # the paper's trade-off: 0.9 follows the jump faster ...
    assert lag90 < lag99
    # ... but every estimate is noisier on a constant stretch. Theory for stationary
    # regressors: std ratio sqrt((1-0.9)/(1+0.9) / ((1-0.99)/(1+0.99))) = 3.2.
    assert np.all(noise90 > noise99)
    assert np.all(noise90 / noise99 > 2.0)
    # Both track: the jump is followed within 10 % in well under the 1000 samples
    # before the drift (memory 1/(1-lambda) = 10 and 100 samples; 10 % is reached after
    # about ln(0.1)/ln(lambda) = 22 and 229 samples for well-excited regressors).
    assert lag90 < 100 and lag99 < 600
    th = tv_truth()
    for mean in (mean99, mean90):
        # before the jump and after it has been followed: within 0.02 of a1 (10 % of jump)
        assert np.all(np.abs(mean[800 - 2:JUMP - 2, 0] - th[800:JUMP, 0]) < 0.02)
        assert np.all(np.abs(mean[1800 - 2:DRIFT - 2, 0] - th[1800:DRIFT, 0]) < 0.02)
    # The drift is followed with the textbook lag of a forgetting-factor estimator behind
    # a ramp, lambda / (1 - lambda) samples (9 and 99). The measured lag is a mean
    # offset of size lag * slope (slope 5e-4 per sample) read through the estimation
    # noise: for 0.9 the noise (0.027 per seed, ~30 independent values in 300 samples,
    # 12 seeds) is ~3 samples of lag at 1 std, so +-10 samples; for 0.99 the noise is
    # ~2 samples, and +-25 % also covers the finite ramp (steady lag after ~3/(1-lambda)).
    assert abs(drift90 - 9) < 10
    assert abs(drift99 - 99) < 0.25 * 99


def test_standard_deviations_match_monte_carlo_spread():
    # Constant parameters, lambda = 0.98: the reported std of the final estimate against
    # the spread of that estimate over 150 seeds. The sample std of 150 values is known
    # to about 1/sqrt(2*149) = 6 %, so 20 % is a 3-sigma tolerance; sigma^2 P alone
    # (without the sandwich) would be sqrt(1 + lambda) = 1.41 times too wide.
    finals, stds = [], []
    for seed in range(150):
        y, u = simulate_ti(1000, seed=100 + seed)
        res = rls(y, u, (2, 2, 1), forgetting=0.98)
        finals.append(res.theta[-1])
        stds.append(res.std[-1])
    spread = np.std(finals, axis=0, ddof=1)
    reported = np.sqrt(np.mean(np.square(stds), axis=0))
    ratio = reported / spread
    assert np.all((ratio > 0.8) & (ratio < 1.2)), ratio


# --------------------------------------------------------------------------------------
# Choosing lambda by prediction error
# --------------------------------------------------------------------------------------
def test_choose_forgetting_time_varying_vs_invariant(tv_records):
    y, u = tv_records[0]
    tv = choose_forgetting(y, u, (2, 2, 1))
    assert tv.forgetting < 1.0
    assert tv.forgetting <= 0.99
    assert tv.result.forgetting == tv.forgetting
    table = tv.to_pandas()
    assert list(table["forgetting"]) == [0.9, 0.95, 0.98, 0.99, 0.995, 0.999, 1.0]
    assert table.loc[table["chosen"], "mse"].iloc[0] == table["mse"].min()
    # time-invariant: forgetting only adds estimation noise, so ~1 wins
    # (candidates 0.999 and 1 differ by a noise term of about (1-lambda)/2 * n = 0.2 %)
    y, u = simulate_ti(3000, seed=11)
    ti = choose_forgetting(y, u, (2, 2, 1))
    assert ti.forgetting >= 0.999, ti.to_pandas()


# --------------------------------------------------------------------------------------
# The compiled loop against the plain numpy loop
# --------------------------------------------------------------------------------------
def _assert_same_tracks(fast, slow):
    # same arithmetic, different evaluation order (the C loop multiplies the Joseph form
    # out, CasADi and numpy evaluate (I - K phi') P~ (I - K phi')' + K K'): rounding only
    # (1e-9 on estimates of order 1 and errors of order 0.1; 1e-9 relative on the stds)
    np.testing.assert_allclose(fast.theta, slow.theta, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.errors, slow.errors, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.std, slow.std, rtol=1e-9, atol=0)
    np.testing.assert_allclose(fast.noise_variance, slow.noise_variance, rtol=1e-9, atol=0)
    np.testing.assert_allclose(fast.effective_forgetting, slow.effective_forgetting,
                               rtol=1e-12)
    np.testing.assert_allclose(fast.covariance, slow.covariance, rtol=1e-8, atol=0)
    np.testing.assert_array_equal(fast.time, slow.time)


def test_compiled_loops_equal_numpy_loop(monkeypatch):
    # 2100 samples: two full chunks of CasADi's compiled loop plus a padded partial one;
    # the C loop in chunks of 500 (four calls and a partial one, the state carried
    # between them); a stretch without input excitation makes the trace bound act
    # (lambda_k > lambda).
    from workbench.identify.rls import ckernel
    monkeypatch.setattr(ckernel, "CHUNK", 500)
    rng = np.random.default_rng(5)
    y, u = simulate_ti(2100, seed=5)
    u = u.copy()
    u[900:1300] = 0.0
    y = lfilter([0.0, TRUE[2], TRUE[3]], [1.0, TRUE[0], TRUE[1]], u) \
        + 0.1 * rng.standard_normal(u.size)
    for lam in (0.9, 0.99):
        kw = dict(forgetting=lam, sample_time=0.01)
        slow = rls(y, u, (2, 2, 1), method="numpy", **kw)
        assert slow.method == "numpy"
        if ckernel.c_kernel(4) is not None:
            fast = rls(y, u, (2, 2, 1), **kw)
            assert fast.method == "c"
            _assert_same_tracks(fast, slow)
        cas = rls(y, u, (2, 2, 1), method="casadi", **kw)
        assert cas.method in ("compiled", "casadi")
        _assert_same_tracks(cas, slow)
        if lam == 0.9:
            assert slow.bound_active_fraction > 0.0


@pytest.mark.parametrize("orders", [(1, 0, 0), (0, 2, 0), (3, 1, 2), (2, 3, 0), (1, 2, 4)])
def test_c_loop_regressors_for_other_orders(orders):
    # The C loop forms the regressors itself from y and u; the numpy loop runs on
    # regressors(): both orders conventions (na = 0, nb = 0, nk = 0, nk > na) must agree.
    from workbench.identify.rls import ckernel
    if ckernel.c_kernel(orders[0] + orders[1]) is None:
        pytest.skip("no C compiler")
    rng = np.random.default_rng(9)
    u = prbs(700, rng)
    y = lfilter([0.0, 0.3, 0.2], [1.0, -0.9], u) + 0.05 * rng.standard_normal(700)
    uu = None if orders[1] == 0 else u
    fast = rls(y, uu, orders, forgetting=0.98, method="c")
    slow = rls(y, uu, orders, forgetting=0.98, method="numpy")
    assert fast.start_index == slow.start_index == max(orders[0], orders[2] + orders[1] - 1)
    _assert_same_tracks(fast, slow)


def test_trace_bound_prevents_wind_up():
    # Input switched off for 8000 samples with lambda = 0.9: without a bound, P grows
    # by 1/0.9 per sample in the unexcited b directions and overflows after about
    # ln(1e308)/ln(1/0.9) = 6700 samples; with the bound the estimates stay finite and
    # recover once the input returns.
    rng = np.random.default_rng(3)
    n = 10_000
    u = prbs(n, rng)
    u[1000:9000] = 0.0
    y = lfilter([0.0, TRUE[2], TRUE[3]], [1.0, TRUE[0], TRUE[1]], u) \
        + lfilter([1.0], [1.0, TRUE[0], TRUE[1]], SIGMA * rng.standard_normal(n))
    bounded = rls(y, u, (2, 2, 1), forgetting=0.9)
    assert np.all(np.isfinite(bounded.theta))
    assert bounded.bound_active_fraction > 0.5
    # last 500 samples: back within 0.2 of the truth (noise std at lambda = 0.9 ~ 0.03)
    assert np.all(np.abs(bounded.theta[-500:] - TRUE) < 0.2)
    unbounded = rls(y, u, (2, 2, 1), forgetting=0.9, p_max=np.inf)
    assert not np.all(np.isfinite(unbounded.theta))


# --------------------------------------------------------------------------------------
# Result object
# --------------------------------------------------------------------------------------
def test_result_is_frozen_and_exports():
    y, u = simulate_ti(300, seed=2)
    res = rls(y, u, (2, 2, 1), forgetting=0.99, sample_time=0.01)
    assert res.names == ("a1", "a2", "b1", "b2")
    assert res.theta.shape == (298, 4) and res.std.shape == (298, 4)
    assert res.time[0] == pytest.approx(0.02) and res.time[-1] == pytest.approx(2.99)
    with pytest.raises(ValueError):
        res.theta[0, 0] = 1.0
    with pytest.raises(AttributeError):
        res.forgetting = 0.5
    df = res.to_pandas()
    assert list(df.columns[:5]) == ["time", "a1", "a2", "b1", "b2"]
    d = res.to_dict()
    json.dumps(d)                                            # JSON-ready
    assert d["a"] == pytest.approx(res.theta[-1, :2].tolist())
    assert set(d) >= {"final", "final_std", "forgetting", "prediction_mse", "orders"}


def test_orders_follow_matlab_convention():
    # y(k) = 0.6 y(k-1) + 2 u(k-3) (na=1, nb=1, nk=3), no noise: exact after a few samples
    rng = np.random.default_rng(0)
    u = prbs(400, rng)
    y = np.zeros(400)
    for k in range(3, 400):
        y[k] = 0.6 * y[k - 1] + 2.0 * u[k - 3]
    res = rls(y, u, (1, 1, 3), forgetting=1.0)
    assert res.start_index == 3
    # exact but for the prior P(0) = 1e4 I, which pulls towards 0 by about
    # theta / (p0 * sum phi^2) = 2 / (1e4 * 400) = 5e-7: tolerance 1e-5
    np.testing.assert_allclose(res.theta[-1], [-0.6, 2.0], atol=1e-5)
    # a wrong delay cannot fit: nk = 2 leaves a clearly different model
    wrong = rls(y, u, (1, 1, 2), forgetting=1.0)
    assert np.max(np.abs(wrong.theta[-1] - [-0.6, 2.0])) > 0.1


def test_auto_prior_is_unit_invariant():
    # Output in m (1e-3 of the dimensionless y) and input in V around 0: with
    # p0="auto" the recursion is the same up to the change of units, so a_i are equal
    # and b_i scale by 1e-3 (to rounding, 1e-9 relative). With a fixed p0 = 1e4 and
    # lambda = 1 the small signals make the prior strong and pull the estimates to 0.
    y, u = simulate_ti(600, seed=4, sigma=0.01)
    ref = rls(y, u, (2, 2, 1), forgetting=1.0, p0="auto")
    small = rls(1e-3 * y, u, (2, 2, 1), forgetting=1.0, p0="auto")
    np.testing.assert_allclose(small.theta[-1], ref.theta[-1] * [1, 1, 1e-3, 1e-3], rtol=1e-9)
    np.testing.assert_allclose(small.std[-1], ref.std[-1] * [1, 1, 1e-3, 1e-3], rtol=1e-9)
    np.testing.assert_allclose(ref.theta[-1], TRUE, atol=0.01)     # std ~ 1e-3
    fixed = rls(1e-3 * y, u, (2, 2, 1), forgetting=1.0, p0=1e4)
    assert np.max(np.abs(fixed.theta[-1, :2] - TRUE[:2])) > 0.02


# --------------------------------------------------------------------------------------
# Bad data
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("case, words", [
    ("short", ["too short", "at least"]),
    ("nan", ["NaN", "sample 17"]),
    ("inf", ["inf", "sample 4"]),
    ("lambda0", ["(0, 1]"]),
    ("lambda_big", ["(0, 1]"]),
    ("lambda_neg", ["(0, 1]"]),
    ("constant", ["constant", "excite"]),
    ("lengths", ["samples"]),
    ("orders", ["orders"]),
    ("negative_order", [">= 0"]),
])
def test_bad_data_raises_input_error(case, words):
    y, u = simulate_ti(200, seed=1)
    args = dict(y=y, u=u, orders=(2, 2, 1), forgetting=0.99)
    if case == "short":
        args.update(y=y[:8], u=u[:8])
    elif case == "nan":
        y = y.copy(); y[17] = np.nan; args["y"] = y
    elif case == "inf":
        u = u.copy(); u[4] = np.inf; args["u"] = u
    elif case == "lambda0":
        args["forgetting"] = 0.0
    elif case == "lambda_big":
        args["forgetting"] = 1.01
    elif case == "lambda_neg":
        args["forgetting"] = -0.5
    elif case == "constant":
        args["u"] = np.full_like(u, 5.0)
    elif case == "lengths":
        args["u"] = u[:-3]
    elif case == "orders":
        args["orders"] = (2, 2)
    elif case == "negative_order":
        args["orders"] = (2, -1, 1)
    with pytest.raises(InputError) as exc:
        rls(**args)
    for w in words:
        assert w in str(exc.value), str(exc.value)


def test_choose_forgetting_rejects_bad_candidates():
    y, u = simulate_ti(300, seed=1)
    with pytest.raises(InputError, match=r"\(0, 1\]"):
        choose_forgetting(y, u, (2, 2, 1), candidates=(0.9, 1.2))
    with pytest.raises(InputError, match="no candidate"):
        choose_forgetting(y, u, (2, 2, 1), candidates=())


# --------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------
def _write_recording(path, n=600, seed=4):
    from workbench.recording import Recording
    y, u = simulate_ti(n, seed=seed, sigma=0.01)
    # a valve command around 5 V and a position in m; still the ARX TRUE in deviations
    t = np.arange(n) * 0.01
    Recording.from_arrays(t, u=5.0 + u, x=0.25 + 1e-3 * y,
                          metadata={"sample_time": 0.01}).to_csv(path)
    return t


@pytest.mark.parametrize("orders, header", [
    (("2", "2", "1"), "t,a1,a2,b1,b2"),
    (("3", "1", "2"), "t,a1,a2,a3,b1"),
])
def test_cli_writes_estimates_with_exact_columns(tmp_path, capsys, orders, header):
    from workbench.__main__ import main
    rec = tmp_path / "rec.csv"
    t = _write_recording(rec)
    out = tmp_path / "out"
    code = main(["identify", "rls", str(rec), "--input", "u", "--output", "x",
                 "--orders", *orders, "--forgetting", "0.99", "--out", str(out), "--no-plot"])
    assert code == 0, capsys.readouterr().err
    lines = (out / "estimates.csv").read_text().splitlines()
    assert lines[0] == header
    k0 = max(int(orders[0]), int(orders[2]) + int(orders[1]) - 1)
    assert len(lines) == 1 + t.size - k0
    first = [float(v) for v in lines[1].split(",")]
    assert first[0] == pytest.approx(t[k0])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["forgetting"] == 0.99
    assert (out / "report.md").read_text().startswith("# Recursive least squares")


def test_cli_auto_forgetting_and_plot(tmp_path, capsys):
    from workbench.__main__ import main
    rec = tmp_path / "rec.csv"
    _write_recording(rec)
    out = tmp_path / "auto"
    code = main(["identify", "rls", str(rec), "--orders", "2", "2", "1",
                 "--forgetting", "auto", "--out", str(out), "--json"])
    assert code == 0, capsys.readouterr().err
    summary = json.loads(capsys.readouterr().out)
    table = summary["forgetting_choice"]["table"]
    assert [row["forgetting"] for row in table] == [0.9, 0.95, 0.98, 0.99, 0.995, 0.999, 1.0]
    assert summary["forgetting"] == min(table, key=lambda r: r["mse"])["forgetting"]
    assert (out / "rls.png").stat().st_size > 10_000


@pytest.mark.parametrize("extra, words", [
    (["--forgetting", "fast"], ["--forgetting", "auto"]),
    (["--forgetting", "1.5"], ["(0, 1]"]),
    (["--input", "r"], ["no column 'r'"]),
])
def test_cli_bad_arguments_exit_2(tmp_path, capsys, extra, words):
    from workbench.__main__ import main
    rec = tmp_path / "rec.csv"
    _write_recording(rec, n=200)
    args = ["identify", "rls", str(rec), "--out", str(tmp_path / "o"), "--no-plot"]
    assert main(args + extra) == 2
    err = capsys.readouterr().err
    for w in words:
        assert w in err, err


def test_cli_detrend_removes_operating_point_offsets(tmp_path, capsys):
    # The recording is the ARX TRUE in deviations around u = 5 V, x = 0.25 m (x in m is
    # 1e-3 y, so b is 1e-3 TRUE[2:] m/V). ARX has no constant term: --detrend mean
    # removes the offsets. Noise std 1e-5 m on 600 samples: estimates within 0.05
    # (a, -) and 5e-5 m/V (b), many standard deviations but far below the offset bias.
    from workbench.__main__ import main
    rec = tmp_path / "rec.csv"
    _write_recording(rec)
    out = tmp_path / "dt"
    assert main(["identify", "rls", str(rec), "--orders", "2", "2", "1", "--forgetting", "1",
                 "--detrend", "mean", "--out", str(out), "--no-plot", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["detrend"] == "mean"
    np.testing.assert_allclose(summary["a"], TRUE[:2], atol=0.05)
    np.testing.assert_allclose(summary["b"], 1e-3 * TRUE[2:], atol=5e-5)


def _weighted_ls_reference(y, u, lam, p0, p_max):
    """RLS with forgetting written as batch weighted least squares (Ljung, System
    Identification, 11.2): after sample N the estimate minimises
    sum_k w_k e_k^2 + w_0 theta' P0^-1 theta (theta0 = 0), w_k the product of the
    forgetting factors applied after sample k, i.e. R_N theta = f_N with
    R_N = l_N R_{N-1} + phi phi', f_N = l_N f_{N-1} + phi y, R_0 = P0^-1. The factor
    is the documented trace bound l_N = min(1, max(lam, trace(R_{N-1}^-1) / p_max)).
    The noise variance is the minimised cost over the effective degrees of freedom
    sum w_k - trace(P M), M = sum w_k^2 phi phi', and the covariance is the
    weighted-LS sandwich s^2 P M P. Regressors built here,
    phi(k) = [-y(k-1), -y(k-2), u(k-1), u(k-2)] for orders (2, 2, 1)."""
    phi = np.array([[-y[k - 1], -y[k - 2], u[k - 1], u[k - 2]] for k in range(2, y.size)])
    target = y[2:]
    R, f = np.diag(1.0 / p0), np.zeros(4)
    M, ne = np.zeros((4, 4)), 0.0
    errors, lks = np.empty(target.size), np.empty(target.size)
    for k, (ph, yk) in enumerate(zip(phi, target)):
        errors[k] = yk - ph @ np.linalg.solve(R, f)          # a priori: theta(k-1)
        lk = lks[k] = min(1.0, max(lam, np.trace(np.linalg.inv(R)) / p_max))
        R, f = lk * R + np.outer(ph, ph), lk * f + ph * yk
        M, ne = lk ** 2 * M + np.outer(ph, ph), lk * ne + 1.0
    theta = np.linalg.solve(R, f)
    w = np.append(np.cumprod(lks[::-1])[::-1][1:], 1.0)      # w_k = prod_{j > k} l_j
    w_prior = np.prod(lks)
    cost = np.sum(w * (target - phi @ theta) ** 2) + w_prior * np.sum(theta ** 2 / p0)
    P = np.linalg.inv(R)
    s2 = cost / (ne - np.trace(P @ M))
    return dict(theta=theta, errors=errors, s2=s2, cov=s2 * P @ M @ P,
                bound_fraction=float(np.mean(lks > lam)))


def test_cli_summary_every_value(tmp_path, capsys):
    """Every number of summary.json (lambda = 0.98, --detrend mean, p0 auto) against
    the batch weighted least squares above. Tolerances: the recursion and the batch
    solve differ by rounding accumulated over 598 rank-one updates, 1e-7 relative on
    the estimates and 1e-6 on variances and errors (the a priori errors of the first
    samples are O(1), later ones O(1e-5): 1e-6 relative on their mean square)."""
    from workbench.__main__ import main
    from workbench.recording import load_recording
    rec_path = tmp_path / "rec.csv"
    _write_recording(rec_path)
    out = tmp_path / "o"
    assert main(["identify", "rls", str(rec_path), "--orders", "2", "2", "1",
                 "--forgetting", "0.98", "--detrend", "mean", "--out", str(out),
                 "--no-plot", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    s = json.loads((out / "summary.json").read_text())
    assert s == printed
    rec = load_recording(rec_path)
    y, u = rec["x"] - np.mean(rec["x"]), rec["u"] - np.mean(rec["u"])
    phi = np.array([[-y[k - 1], -y[k - 2], u[k - 1], u[k - 2]] for k in range(2, y.size)])
    p0 = 1e4 / np.mean(phi ** 2, axis=0)                    # documented "auto" prior
    ref = _weighted_ls_reference(y, u, 0.98, p0, np.sum(p0) / 0.98)
    n = y.size - 2
    assert (s["input"], s["output"], s["detrend"]) == ("u", "x", "mean")
    assert s["orders"] == {"na": 2, "nb": 2, "nk": 1} and s["names"] == ["a1", "a2", "b1", "b2"]
    assert s["units"] == {"output": "m", "input": "V"}
    assert s["forgetting"] == 0.98 and s["sample_time"] == 0.01
    assert s["estimates"] == n and s["start_index"] == 2
    np.testing.assert_allclose(s["p0"], p0, rtol=1e-12)
    assert s["p_max"] == pytest.approx(np.sum(p0) / 0.98, rel=1e-12)   # trace P0 / lambda
    # the bound acts where trace P is near trace P0 (the first samples)
    assert 0.0 < ref["bound_fraction"] < 0.1
    assert s["bound_active_fraction"] == pytest.approx(ref["bound_fraction"], rel=1e-12)
    np.testing.assert_allclose(s["a"] + s["b"], ref["theta"], rtol=1e-7)
    np.testing.assert_allclose([s["final"][k] for k in s["names"]], ref["theta"], rtol=1e-7)
    std = np.sqrt(np.diag(ref["cov"]))
    np.testing.assert_allclose(s["std_a"] + s["std_b"], std, rtol=1e-6)
    np.testing.assert_allclose([s["final_std"][k] for k in s["names"]], std, rtol=1e-6)
    assert s["noise_variance"] == pytest.approx(ref["s2"], rel=1e-6)
    burn = max(10 * 4, n // 10)                     # documented default burn-in
    assert s["prediction_mse_burn_in"] == burn
    mse = float(np.mean(ref["errors"][burn:] ** 2))
    assert s["prediction_mse"] == pytest.approx(mse, rel=1e-6)
    assert s["prediction_rmse"] == pytest.approx(np.sqrt(mse), rel=1e-6)
    assert s["forgetting_choice"] is None
    assert s["files"] == {"estimates": str(out / "estimates.csv"),
                          "report": str(out / "report.md"), "summary": str(out / "summary.json")}
    assert s["recording"] == str(rec_path) and s["method"] in ("c", "compiled", "casadi", "numpy")


def test_cli_forgetting_choice_values(tmp_path, capsys):
    """--forgetting auto: each candidate's mean squared a priori error after the
    burn-in from the batch weighted least squares above (1e-6 relative, as in
    test_cli_summary_every_value), rmse = sqrt(mse), the burn-in by its documented
    default, the choice = smallest mse (ties to the larger lambda)."""
    from workbench.__main__ import main
    from workbench.recording import load_recording
    rec_path = tmp_path / "rec.csv"
    _write_recording(rec_path, n=300)
    assert main(["identify", "rls", str(rec_path), "--orders", "2", "2", "1",
                 "--forgetting", "auto", "--out", str(tmp_path / "o"), "--no-plot",
                 "--json"]) == 0
    ch = json.loads(capsys.readouterr().out)["forgetting_choice"]
    rec = load_recording(rec_path)
    y, u = rec["x"], rec["u"]
    phi = np.array([[-y[k - 1], -y[k - 2], u[k - 1], u[k - 2]] for k in range(2, y.size)])
    p0 = 1e4 / np.mean(phi ** 2, axis=0)
    n = y.size - 2
    burn = max(10 * 4, n // 10)
    assert ch["burn_in"] == burn
    want = {}
    for row in ch["table"]:
        lam = row["forgetting"]
        e = _weighted_ls_reference(y, u, lam, p0, np.sum(p0) / lam)["errors"][burn:]
        want[lam] = float(np.mean(e ** 2))
        assert row["mse"] == pytest.approx(want[lam], rel=1e-6), lam
        assert row["rmse"] == pytest.approx(np.sqrt(want[lam]), rel=1e-6), lam
    assert ch["forgetting"] == min(want, key=lambda lam: (want[lam], -lam))
