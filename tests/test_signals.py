"""The signal toolbox: noise floor, derivatives, fit, whiteness, and one noise number.

Reference values are analytic (a polynomial's derivative, the known standard deviation of
added white noise, the measurement error computed from the noise-free signal) or
distributional (the Ljung-Box false-alarm rate on white noise), never from the code.
"""

import math

import numpy as np
import pytest

from conftest import PLANTS
from workbench import signals as S
from workbench.errors import InputError
from workbench.recording import Recording

N = 20000
DT = 1e-3
#: Relative standard deviation of noise_floor on N samples: about 1.3 / sqrt(N)
#: (MAD efficiency 37 %, neighbouring residuals correlated), 0.9 % for N = 20000.
REL_SD = 1.3 / math.sqrt(N)
#: Tolerance of a single seeded estimate: 4 standard deviations.
TOL = 4 * REL_SD


def _t(n: int = N) -> np.ndarray:
    return np.arange(n) * DT


def _smooth(t):
    return 0.05 * np.sin(2 * math.pi * 1.0 * t) + 0.02 * np.sin(2 * math.pi * 3.3 * t)


def _steps(t, rng, every: int = 1000):
    y = np.zeros(t.size)
    for k in range(0, t.size, every):
        y[k:] = rng.uniform(-0.05, 0.05)
    return y


@pytest.mark.parametrize("sigma", [1e-5, 1e-3])
def test_noise_floor_on_smooth_signal(sigma):
    rng = np.random.default_rng(1)
    t = _t()
    y = _smooth(t) + sigma * rng.standard_normal(t.size)
    assert S.noise_floor(y) == pytest.approx(sigma, rel=TOL)


def test_noise_floor_on_steps():
    # a step every 1000 samples spoils 6 of 1000 residuals: a bias of about +0.6 %
    # (measured 1 % at one step in 400) on top of the statistical error
    rng = np.random.default_rng(2)
    t = _t()
    sigma = 1e-3
    y = _steps(t, rng) + sigma * rng.standard_normal(t.size)
    assert S.noise_floor(y) == pytest.approx(sigma, rel=TOL + 0.01)


@pytest.mark.parametrize("ratio", [0.05, 0.2, 1.0, 3.0])
def test_noise_floor_on_quantised_signal(ratio):
    # the noise a fit sees is the whole measurement error: noise plus quantisation,
    # computed here from the noise-free signal. Below one step (ratio < 1) the robust
    # spread sees mostly flat runs and the floor q/sqrt(12) takes over (exact for a
    # uniform error); the quantisation error is then not Gaussian: 20 % allowed
    # (measured 0.82 to 1.02 of the true error over sigma/q = 0.05..3).
    rng = np.random.default_rng(3)
    t = _t()
    q = 1e-3
    clean = 0.01 * np.sin(2 * math.pi * t) + 0.0031
    yq = np.round((clean + ratio * q * rng.standard_normal(t.size)) / q) * q
    err = float(np.std(yq - clean))
    assert S.quantisation_step(yq) == pytest.approx(q, rel=1e-9)
    assert S.noise_floor(yq) == pytest.approx(err, rel=0.2 if ratio < 1 else 0.05)
    assert S.noise_floor(yq) >= q / math.sqrt(12) * (1 - 1e-9)


def test_quantisation_is_found_on_an_offset_grid_only():
    rng = np.random.default_rng(4)
    t = _t(5000)
    q = 10.0                                    # Pa, gauge sensor + 101325 Pa offset
    p = np.round((2e5 + 3e4 * np.sin(2 * math.pi * t) + 3.0 * rng.standard_normal(t.size))
                 / q) * q + 101325.0
    assert S.quantisation_step(p) == pytest.approx(q, rel=1e-9)
    # a noise-free smooth signal is not on a grid: no floor, only the smoother's
    # leakage (4th derivative * h^4, about 1e-12 here)
    assert S.quantisation_step(np.sin(t)) == 0.0
    assert S.noise_floor(np.sin(_t())) < 1e-8


def test_derivative_of_a_polynomial_is_exact():
    t = np.arange(1001) * DT
    c = [2.0, 3.0, -4.0, 5.0]                   # 2 + 3 t - 4 t^2 + 5 t^3
    y = np.polyval(c[::-1], t)
    d1 = np.polyval(np.polyder(c[::-1]), t)
    d2 = np.polyval(np.polyder(c[::-1], 2), t)
    # rounding of y (~1e-15) amplified by the filter gains / dt (1e3) and / dt^2 (1e6),
    # times the window's coefficient sums: ~1e-10 and ~1e-6; also at the ends
    np.testing.assert_allclose(S.derivative(y, DT, order=3, window=11), d1, rtol=0, atol=1e-8)
    np.testing.assert_allclose(S.derivative(y, DT, order=3, window=11, deriv=2), d2,
                               rtol=0, atol=1e-4)
    with pytest.raises(InputError, match="odd"):
        S.derivative(y, DT, window=10)


def test_fit_of_identical_signals_is_100_and_of_the_mean_0():
    y = np.sin(_t(100))
    assert S.fit(y, y) == 100.0
    assert S.fit(y, np.full_like(y, y.mean())) == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(InputError, match="shapes"):
        S.fit(y, y[:-1])
    from workbench.recording import fit as recording_fit
    assert recording_fit is S.fit                # re-exported, one definition


def test_ljung_box_false_alarm_rate_on_white_noise():
    # 400 white series: rejections at the 1 % level are Binomial(400, 0.01), mean 4,
    # sd 2; at 5 %: mean 20, sd 4.4. Bounds at about 3 sd.
    rng = np.random.default_rng(5)
    p = np.array([S.ljung_box(rng.standard_normal(500), 20)[1] for _ in range(400)])
    assert np.sum(p < S.WHITENESS_LEVEL) <= 10
    assert 7 <= np.sum(p < 0.05) <= 33
    # and it sees colour: an AR(1) with pole 0.5 over 2000 samples has r(1) = 0.5, so
    # Q > N r(1)^2 = 500, far beyond chi2(20) (p = 1e-6 at Q = 67)
    e = rng.standard_normal(2000)
    for k in range(1, e.size):
        e[k] += 0.5 * e[k - 1]
    assert S.ljung_box(e, 20)[1] < 1e-6


def test_correlations_of_white_noise_stay_in_the_99_percent_band():
    rng = np.random.default_rng(6)
    e, u = rng.standard_normal(5000), rng.standard_normal(5000)
    r = S.autocorrelation(e, 25)
    assert r[0] == 1.0
    # 25 lags of a 1 % band: about 0.25 outside; 3 would be a 1e-3 event
    assert S.fraction_outside(r[1:], e.size) <= 2 / 25
    lags, c = S.cross_correlation(e, u, 25)
    assert list(lags) == list(range(-25, 26))
    assert S.fraction_outside(c, e.size) <= 3 / 51
    stat, p, dof = S.independence_test(e, u, 25)
    assert dof == 26 and p > S.WHITENESS_LEVEL
    assert S.correlation_band(e.size) == pytest.approx(2.5758 / math.sqrt(5000), rel=1e-4)


def test_whiteness_agrees_with_arx_validation():
    # the ARX residual check (identify.arx.validate) computes the same statistics
    from workbench.identify import arx
    rng = np.random.default_rng(7)
    u = np.sign(rng.standard_normal(800))
    y = np.zeros(800)
    for k in range(2, 800):
        y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + 0.5 * u[k - 1] + 0.1 * rng.standard_normal()
    model = arx.fit_arx(y, u, (2, 2, 1))
    v = arx.validate(model, y, u)
    e, uu = v.residuals, u[model.max_lag:]
    np.testing.assert_allclose(S.autocorrelation(e, 25), v.autocorrelation, rtol=1e-12)
    np.testing.assert_allclose(S.cross_correlation(e, uu, 25)[1], v.cross_correlation,
                               rtol=1e-12, atol=1e-15)
    assert S.ljung_box(e, 25) == pytest.approx((v.whiteness_statistic, v.whiteness_p_value),
                                               rel=1e-12)
    assert S.independence_test(e, uu, 25)[:2] == pytest.approx(
        (v.independence_statistic, v.independence_p_value), rel=1e-12)


def test_same_noise_number_in_diagnosis_and_grey_box():
    from workbench import Plant
    from workbench.diagnose.data import prepare
    from workbench.identify.grey_box import _prepare
    plant = Plant.from_toml(PLANTS / "rig25_mpye.toml")
    rng = np.random.default_rng(8)
    t = np.arange(3000) * DT
    qx = 0.5 / 4096                             # 12-bit position sensor
    x = np.round((0.25 + 0.05 * np.sin(2 * math.pi * t) + 2e-5 * rng.standard_normal(t.size))
                 / qx) * qx
    p_a = 3e5 + 2e4 * np.sin(2 * math.pi * t) + 300.0 * rng.standard_normal(t.size)
    p_b = 3e5 - 2e4 * np.sin(2 * math.pi * t) + 300.0 * rng.standard_normal(t.size)
    rec = Recording.from_arrays(t, u=5.0 + np.sin(2 * math.pi * t), x=x, p_a=p_a, p_b=p_b)
    prep = prepare(plant, rec, mode="open")
    data = _prepare(plant, [rec], ("x", "p_a", "p_b"), None)[0]
    for s in ("x", "p_a", "p_b"):
        assert prep.noise[s] == data.noise[s] == S.noise_floor(rec[s])
    assert prep.noise["p_a"] == pytest.approx(300.0, rel=0.05)   # 3000 samples: 2.4 % sd
