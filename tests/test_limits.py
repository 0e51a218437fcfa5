"""Gain limits of the sampled P position loop, PD zero placement, ``workbench limits``.

References come from paper 000 (Table II, physics.md), from closed-form results
(Hurwitz conditions, first- and second-order loops solved by hand) or from an
independent computation in this file (numpy roots of the characteristic polynomial,
python-control's own ZOH discretisation, bisection on closed-loop poles), never from
the code under test.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import control
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from workbench import InputError, Plant, WorkbenchError, controllers, linearize, stability
from workbench.__main__ import main

ROOT = Path(__file__).resolve().parents[1]
SITUM = ROOT / "designs" / "plants" / "situm_rodless_nominal.toml"

# Table II of paper 000
W0, ZETA, T, K0 = 32.97, 1.1, 0.01, 7.0

#: hypothesis: modest example counts keep the file fast; no example database in the tree
FAST = settings(max_examples=40, deadline=None, database=None)


# ---------------------------------------------------------------------- independent helpers
def _ref_discrete_loop(w0, zeta, T, delay=False):
    """ZOH loop by python-control's c2d (not the workbench's matrix exponential)."""
    g = control.c2d(control.tf([1.0], [1.0 / w0 ** 2, 2.0 * zeta / w0, 1.0, 0.0]), T, "zoh")
    num = np.asarray(g.num[0][0], dtype=float)
    den = np.asarray(g.den[0][0], dtype=float)
    if delay:
        den = np.append(den, 0.0)
    return num, den


def _max_pole_modulus(num, den, k):
    char = den.copy()
    char[den.size - num.size:] += k * num
    return np.max(np.abs(np.roots(char)))


def _bisect_limit(num, den, rtol=1e-10):
    """Smallest unstable gain by doubling then bisection on the closed-loop poles."""
    lo, hi = 0.0, 1.0
    while _max_pole_modulus(num, den, hi) < 1.0:
        lo, hi = hi, 2.0 * hi
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        if _max_pole_modulus(num, den, mid) < 1.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


# ---------------------------------------------------------------------- Table II numbers
def test_table_ii_limits():
    lim = stability.gain_limits(W0, ZETA, T, k0=K0)
    # closed forms evaluated here: only rounding separates them (1e-12)
    assert lim.continuous == pytest.approx(2 * ZETA * W0, rel=1e-12)
    assert lim.pct == pytest.approx(2 * ZETA / (T / 2 + 1 / W0), rel=1e-12)
    # physics.md / paper 000 quote 72.5 and 62.3 (one decimal): half a unit in that digit
    assert abs(lim.continuous - 72.5) <= 0.05
    assert abs(lim.pct - 62.3) <= 0.05
    # 72.53, 62.27, 53.84, 36.15: checked independently by bisection on python-control
    # poles and given to two decimals, so half a unit of the second decimal
    assert abs(lim.continuous - 72.53) <= 0.005
    assert abs(lim.pct - 62.27) <= 0.005
    assert abs(lim.sampled - 53.84) <= 0.005
    assert abs(lim.sampled_delay - 36.15) <= 0.005
    # the paper's "about 54" and "about 36"
    assert round(lim.sampled) == 54 and round(lim.sampled_delay) == 36
    assert lim.pct_time_constant == pytest.approx(0.0353, abs=5e-5)  # paper: Ts = 35.3 ms


def test_table_ii_margins_agree_with_direct_evaluation():
    lim = stability.gain_limits(W0, ZETA, T, k0=K0)
    num, den = _ref_discrete_loop(W0, ZETA, T)
    # gain margin of a P loop = (gain at which a pole reaches |z| = 1) / k0; the
    # bisection reference is converged to 1e-10, python-control's frd margin is
    # refined to ~1e-9: 1e-7 covers both
    assert lim.gain_margin == pytest.approx(_bisect_limit(num, den) / K0, rel=1e-7)

    # phase margin: find |L(e^{jwT})| = 1 on python-control's loop and read the phase
    def loop(w):
        z = np.exp(1j * w * T)
        return K0 * np.polyval(num, z) / np.polyval(den, z)
    from scipy.optimize import brentq
    wc = brentq(lambda w: abs(loop(w)) - 1.0, 0.1, math.pi / T * 0.999, xtol=1e-13)
    pm = 180.0 + math.degrees(np.angle(loop(wc)))
    # both refine the same crossover to ~1e-9 rad/s; 1e-6 deg is far above that
    assert lim.phase_margin_deg == pytest.approx(pm, abs=1e-6)


def test_pct_closed_loop_poles_match_paper():
    z = stability.pct_closed_loop_poles(W0, ZETA, T, K0)
    cplx = z[np.abs(z.imag) > 1e-9]
    real = z[np.abs(z.imag) <= 1e-9]
    assert len(cplx) == 2 and len(real) == 1
    # paper 000 prints 3 digits (0.928 +- 0.076j, 0.619): half a unit in the last digit
    assert abs(cplx[0].real - 0.928) <= 5e-4
    assert abs(abs(cplx[0].imag) - 0.076) <= 5e-4
    assert abs(real[0].real - 0.619) <= 5e-4


def test_discrete_closed_loop_poles_are_roots_of_the_characteristic_polynomial():
    num, den = _ref_discrete_loop(W0, ZETA, T)
    ref = np.roots(np.polyadd(den, K0 * num))
    got = stability.closed_loop_poles(W0, ZETA, T, K0)
    # two discretisations (expm vs python-control) of the same ZOH: ~1e-12 apart
    assert np.sort_complex(got) == pytest.approx(np.sort_complex(ref), abs=1e-9)
    got_d = stability.closed_loop_poles(W0, ZETA, T, K0, delay=True)
    assert len(got_d) == 4 and np.max(np.abs(got_d)) < 1.0


# ---------------------------------------------------------------------- Hurwitz / PCT (property)
@FAST
@given(w0=st.floats(1.0, 500.0), zeta=st.floats(0.05, 5.0))
def test_continuous_limit_separates_stable_from_unstable(w0, zeta):
    lim = stability.continuous_limit(w0, zeta)

    def max_real(k):
        return np.max(np.roots([1.0 / w0 ** 2, 2.0 * zeta / w0, 1.0, k]).real)
    # 2 % either side: the crossing pole pair moves off the imaginary axis by a
    # fraction of w0 that numpy's roots resolves many orders of magnitude better
    assert max_real(0.98 * lim) < 0.0
    assert max_real(1.02 * lim) > 0.0


@FAST
@given(w0=st.floats(1.0, 500.0), zeta=st.floats(0.05, 5.0), T=st.floats(1e-4, 0.1))
def test_pct_limit_separates_stable_from_unstable(w0, zeta, T):
    lim = stability.pct_limit(w0, zeta, T)
    ts = T / 2 + 1 / w0                              # physics.md, written out here

    def max_real(k):
        return np.max(np.roots([ts ** 2, 2.0 * zeta * ts, 1.0, k]).real)
    assert max_real(0.98 * lim) < 0.0               # 2 %: as above
    assert max_real(1.02 * lim) > 0.0


# ---------------------------------------------------------------------- exact sampled limit
@FAST
@given(w0=st.floats(2.0, 300.0), zeta=st.floats(0.05, 4.0), w0T=st.floats(0.01, 3.0),
       delay=st.booleans())
def test_sampled_limit_matches_bisection_on_poles(w0, zeta, w0T, delay):
    T = w0T / w0
    got = stability.sampled_gain_limit(*stability.zoh_position_loop(w0, zeta, T, delay))
    ref = _bisect_limit(*_ref_discrete_loop(w0, zeta, T, delay))
    # the reference is bisected to 1e-10, but numpy's roots of a polynomial whose
    # poles cluster near z = 1 (small w0 T) carry errors up to ~1e-8 at the crossing;
    # 1e-6 relative leaves margin above both
    assert got == pytest.approx(ref, rel=1e-6)


def test_sampled_limit_first_and_second_order_by_hand():
    # 1/(z - 0.5): pole 0.5 - K reaches -1 at K = 1.5 (crossing at theta = pi)
    assert stability.sampled_gain_limit([1.0], [1.0, -0.5]) == pytest.approx(1.5, rel=1e-12)
    # -1/(z - 0.5): pole 0.5 + K reaches +1 at K = 0.5 (crossing at theta = 0)
    assert stability.sampled_gain_limit([-1.0], [1.0, -0.5]) == pytest.approx(0.5, rel=1e-12)
    # z/(z - 0.5): pole 0.5/(1 + K) never leaves the unit disc
    assert stability.sampled_gain_limit([1.0, 0.0], [1.0, -0.5]) == math.inf
    # 1/(z (z - 1)): z^2 - z + K, complex pair of modulus sqrt(K): K = 1 at theta = pi/3
    cross = stability.unit_circle_crossings([1.0], [1.0, -1.0, 0.0])
    assert cross[0][1] == pytest.approx(1.0, rel=1e-12)
    assert cross[0][0] == pytest.approx(math.pi / 3, abs=1e-12)


def test_sampled_limit_rejects_loops_without_an_upper_limit():
    with pytest.raises(WorkbenchError, match="unstable already at small"):
        stability.sampled_gain_limit([1.0], [1.0, -2.0])          # open-loop pole at z = 2
    with pytest.raises(WorkbenchError, match="cannot move"):
        # (z - 2) cancels: hidden unstable mode
        stability.sampled_gain_limit(np.polymul([1.0, -2.0], [1.0]),
                                     np.polymul([1.0, -2.0], [1.0, -0.5]))


def test_sampled_limit_accepts_python_control_systems():
    num, den = _ref_discrete_loop(W0, ZETA, T)
    ref = _bisect_limit(num, den)
    tf = control.tf(num, den, T)
    assert stability.sampled_gain_limit(tf) == pytest.approx(ref, rel=1e-7)
    assert stability.sampled_gain_limit(control.tf2ss(tf)) == pytest.approx(ref, rel=1e-7)
    with pytest.raises(InputError, match="discrete"):
        stability.sampled_gain_limit(control.tf([1.0], [1.0, 1.0, 0.0]))
    with pytest.raises(InputError, match="SISO"):
        stability.sampled_gain_limit(control.ss(np.eye(2) * 0.5, np.eye(2), np.eye(2),
                                                np.zeros((2, 2)), T))


def test_sampled_limit_of_full_tangent_model_matches_reduced_model():
    """Two routes: the 4-state exact tangent model discretised by python-control (with
    its marginal pressure-level mode that feedback cannot move), and the fitted
    third-order model. For the basic drive the fit is exact, so they must agree."""
    plant = Plant.from_toml(SITUM)
    lin = linearize.tangent(plant, x=0.25)
    full = control.c2d(lin.to_control(outputs=["x"]), T, "zoh")
    red = linearize.reduced_position_model(lin)
    kp_full = stability.sampled_gain_limit(full)                    # V/m
    kp_red = stability.gain_limits(red.w0, red.zeta, T, kv=red.kv).kp_limit("sampled")
    # the ss -> tf conversion of a model with a double pole at z = 1 loses ~sqrt(eps)
    # in the cancelled pair; 1e-6 relative is well above that
    assert kp_full == pytest.approx(kp_red, rel=1e-6)


# ---------------------------------------------------------------------- input errors
@pytest.mark.parametrize("kwargs, word", [
    ({"w0": 0.0}, "w0"), ({"w0": -3.0}, "w0"), ({"w0": math.nan}, "w0"),
    ({"zeta": 0.0}, "zeta"), ({"zeta": math.inf}, "zeta"),
    ({"sample_time": 0.0}, "sample_time"), ({"sample_time": "fast"}, "sample_time"),
    ({"k0": -7.0}, "k0"), ({"k0": math.nan}, "k0"),
])
def test_gain_limits_rejects_bad_input(kwargs, word):
    args = {"w0": W0, "zeta": ZETA, "sample_time": T, "k0": K0, **kwargs}
    with pytest.raises(InputError, match=word):
        stability.gain_limits(**args)


def test_result_is_immutable_and_to_dict_has_the_keys():
    lim = stability.gain_limits(W0, ZETA, T, k0=K0)
    with pytest.raises(AttributeError):
        lim.sampled = 1.0
    d = lim.to_dict()
    assert {"k0", "continuous", "pct", "sampled", "sampled_delay", "gain_margin",
            "phase_margin_deg"} <= set(d)
    no_k0 = stability.gain_limits(W0, ZETA, T)
    assert no_k0.k0 is None and no_k0.gain_margin is None and no_k0.phase_margin_deg is None


# ---------------------------------------------------------------------- plant route
def test_limits_from_plant_situm():
    plant = Plant.from_toml(SITUM)
    lim = stability.limits_from_plant(plant, 0.25)
    # the plant file's valve was sized for Kv ~ 0.7 m/(V s) (Table II); 2 % covers
    # the file's rounding of the sonic conductance
    assert lim.kv == pytest.approx(0.70, rel=0.02)
    assert lim.k0 == pytest.approx(10.0 * lim.kv, rel=1e-12)     # kp = 10 V/m in the file
    assert lim.sample_time == 0.01
    # w0, zeta from the exact linearisation: the continuous limit is the Hurwitz
    # bound 2 zeta w0 of the tangent model's own quadratic factor (its two real
    # poles p1, p2: s^2 - (p1 + p2) s + p1 p2  ->  2 zeta w0 = -(p1 + p2))
    ev = np.linalg.eigvals(linearize.tangent(plant, x=0.25).A)
    nonzero = ev[np.abs(ev) > 1e-6]
    assert lim.continuous == pytest.approx(-np.sum(nonzero).real, rel=1e-9)


def test_limits_from_plant_without_controller(make_plant_file):
    plant = Plant.from_toml(make_plant_file())                   # no [controller]
    with pytest.raises(InputError, match="sample time"):
        stability.limits_from_plant(plant, 0.25)
    lim = stability.limits_from_plant(plant, 0.25, sample_time=0.01)
    assert lim.k0 is None and lim.gain_margin is None and lim.kv > 0
    lim2 = stability.limits_from_plant(plant, 0.25, sample_time=0.01, kp=5.0)
    assert lim2.k0 == pytest.approx(5.0 * lim2.kv, rel=1e-12)
    with pytest.raises(InputError, match="not both"):
        stability.limits_from_plant(plant, 0.25, sample_time=0.01, kp=5.0, k0=3.0)


# ---------------------------------------------------------------------- PD zero placement
@pytest.mark.parametrize("w0, zeta", [(W0, ZETA), (10.0, 1.01), (200.0, 3.0), (5.0, 20.0)])
def test_pd_zero_cancels_the_slow_pole(w0, zeta):
    kp, kv = 10.0, 0.7
    pd = controllers.pd_zero_on_slow_pole(w0, zeta, kp, T)
    assert pd.kp == kp and pd.ki == 0.0 and pd.kind == "pd"
    poles = np.roots([1.0 / w0 ** 2, 2.0 * zeta / w0, 1.0])      # both real for zeta > 1
    slow, fast = sorted(poles.real, key=abs)
    # zero of kp + kd s at -kp/kd is the slow pole (rounding only: 1e-9)
    assert -pd.kp / pd.kd == pytest.approx(slow, rel=1e-9)
    # the product C(s) P(s) loses the slow pole: it equals kp Kv / (s (1 - s/fast))
    num = np.polymul([pd.kd, pd.kp], [kv])
    den = np.polymul([1.0 / w0 ** 2, 2.0 * zeta / w0, 1.0], [1.0, 0.0])
    s = 1j * np.logspace(-1, 3, 25) * w0
    product = np.polyval(num, s) / np.polyval(den, s)
    reduced = kp * kv / (s * (1.0 - s / fast))
    assert product == pytest.approx(reduced, rel=1e-9)
    assert np.min(np.abs(np.roots(num) - slow)) <= 1e-9 * abs(slow)


@pytest.mark.parametrize("zeta", [1.0, 0.7, 0.0, math.nan])
def test_pd_placement_needs_two_real_poles(zeta):
    with pytest.raises(InputError, match="real poles"):
        controllers.pd_zero_on_slow_pole(W0, zeta, 10.0, T)


def test_pd_placement_rejects_bad_gain():
    with pytest.raises(InputError, match="kp"):
        controllers.pd_zero_on_slow_pole(W0, ZETA, -1.0, T)


def test_pd_placement_from_plant_uses_the_exact_slow_pole():
    plant = Plant.from_toml(SITUM)
    pd = controllers.pd_zero_on_slow_pole_at(plant, 0.25)
    ev = np.linalg.eigvals(linearize.tangent(plant, x=0.25).A).real
    slow = max(e for e in ev if e < -1e-6)                      # slowest stable pole
    # the reduced fit reproduces the tangent model to ~1e-15 here; 1e-8 is generous
    assert pd.kd / pd.kp == pytest.approx(-1.0 / slow, rel=1e-8)
    assert pd.kp == 10.0 and pd.u_center == 5.0 and (pd.u_min, pd.u_max) == (0.0, 10.0)


# ---------------------------------------------------------------------- CLI
LIMIT_KEYS = {"k0", "continuous", "pct", "sampled", "sampled_delay", "gain_margin",
              "phase_margin_deg"}


def test_cli_model_json(capsys):
    assert main(["limits", "--w0", "32.97", "--zeta", "1.1", "--sample-time", "0.01",
                 "--k0", "7.0", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)          # valid JSON (no NaN/Infinity)
    assert LIMIT_KEYS <= set(out)
    assert out["k0"] == 7.0
    # same references and tolerances as test_table_ii_limits
    assert abs(out["continuous"] - 72.53) <= 0.005
    assert abs(out["pct"] - 62.27) <= 0.005
    assert abs(out["sampled"] - 53.84) <= 0.005
    assert abs(out["sampled_delay"] - 36.15) <= 0.005
    assert abs(out["gain_margin"] - 53.84 / 7.0) <= 0.005 / 7.0 + 1e-9
    assert 0.0 < out["phase_margin_deg"] < 90.0


def test_cli_plant_json(capsys):
    assert main(["limits", str(SITUM), "--x", "0.25", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert LIMIT_KEYS <= set(out)
    # Kv ~ 0.70 by the plant file's design (2 %); K0 = kp Kv with kp = 10 V/m
    assert out["kv"] == pytest.approx(0.70, rel=0.02)
    assert out["k0"] == pytest.approx(10.0 * out["kv"], rel=1e-12)
    assert out["gain_margin"] == pytest.approx(out["sampled"] / out["k0"], rel=1e-7)
    assert out["continuous"] > out["sampled"] > out["sampled_delay"] > 0


def test_cli_table(capsys):
    assert main(["limits", str(SITUM), "--x", "0.25"]) == 0
    out = capsys.readouterr().out
    for word in ("continuous", "PCT", "sampled data", "1 sample delay", "kp (V/m)",
                 "K0/limit", "margins"):
        assert word in out


def test_cli_writes_null_for_missing_gain(capsys):
    assert main(["limits", "--w0", "30", "--zeta", "1.1", "--sample-time", "0.01",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["k0"] is None and out["gain_margin"] is None


@pytest.mark.parametrize("argv, word", [
    (["--w0", "32.97", "--zeta", "1.1"], "--sample-time"),
    ([str(SITUM)], "--x"),
    ([str(SITUM), "--x", "0.25", "--w0", "30"], "--w0"),
    (["--x", "0.25", "--w0", "30"], "PLANT.toml"),
    (["--w0", "30", "--zeta", "1.1", "--sample-time", "0.01", "--kp", "10"], "--kv"),
    (["--w0", "30", "--zeta", "1.1", "--sample-time", "0.01", "--kp", "1", "--k0", "1"],
     "not both"),
    (["--w0", "-1", "--zeta", "1.1", "--sample-time", "0.01"], "w0"),
])
def test_cli_bad_arguments(argv, word, capsys):
    assert main(["limits", *argv]) == 2
    err = capsys.readouterr().err
    assert "workbench limits: error:" in err and word in err


# ---------------------------------------------------------------------- every JSON value
def _ref_crossing_frequency(num, den, T):
    """rad/s of the oscillation at the sampled limit: bisect the limit on the poles of
    python-control's loop, take the pole nearest the unit circle there, angle / T."""
    k = _bisect_limit(num, den, rtol=1e-13)
    char = den.copy()
    char[den.size - num.size:] += k * num
    r = np.roots(char)
    z = r[np.argmin(np.abs(np.abs(r) - 1.0))]
    return abs(np.angle(z)) / T


def _ref_phase_margin(num, den, k0, T):
    """Phase margin (deg) of k0 G(e^{jwT}) at its gain crossover, found by brentq."""
    from scipy.optimize import brentq

    def loop(w):
        z = np.exp(1j * w * T)
        return k0 * np.polyval(num, z) / np.polyval(den, z)
    wc = brentq(lambda w: abs(loop(w)) - 1.0, 1e-3, math.pi / T * 0.999, xtol=1e-13)
    return 180.0 + math.degrees(np.angle(loop(wc)))


def _check_every_value(out, w0, zeta, T, k0, kv):
    """Each key `workbench limits --json` writes, against a value computed here."""
    num, den = _ref_discrete_loop(w0, zeta, T)
    dnum, dden = _ref_discrete_loop(w0, zeta, T, delay=True)
    ref = {"continuous": 2 * zeta * w0,                         # Hurwitz, closed form
           "pct": 2 * zeta / (T / 2 + 1 / w0),                  # paper 000, PCT
           "sampled": _bisect_limit(num, den, rtol=1e-12),
           "sampled_delay": _bisect_limit(dnum, dden, rtol=1e-12)}
    # bisection to 1e-12 against crossings refined by brentq: 1e-9 covers both
    for key, value in ref.items():
        assert out[key] == pytest.approx(value, rel=1e-9), key
        assert out["kp_limits"][key] == pytest.approx(value / kv, rel=1e-9), key
    assert out["k0"] == pytest.approx(k0, rel=1e-12)
    assert out["kv"] == pytest.approx(kv, rel=1e-12)
    assert out["kp"] == pytest.approx(k0 / kv, rel=1e-12)
    assert (out["w0"], out["zeta"], out["sample_time"]) == pytest.approx((w0, zeta, T), rel=1e-12)
    assert out["pct_time_constant_s"] == pytest.approx(T / 2 + 1 / w0, rel=1e-12)
    # python-control's frd margin ~1e-9 (see test_table_ii_margins_agree_...)
    assert out["gain_margin"] == pytest.approx(ref["sampled"] / k0, rel=1e-7)
    assert out["phase_margin_deg"] == pytest.approx(_ref_phase_margin(num, den, k0, T), abs=1e-6)
    # theta / T: the angle of the critical pole over the sample time (rad/s), below
    # Nyquist pi / T; the pole's angle at a limit bisected to 1e-13 moves ~1e-7 rad/s
    for key, (n, d) in (("sampled_frequency_rad_s", (num, den)),
                        ("sampled_delay_frequency_rad_s", (dnum, dden))):
        w = _ref_crossing_frequency(n, d, T)
        assert 0.0 < w < math.pi / T
        assert out[key] == pytest.approx(w, rel=1e-6), key


def test_cli_model_json_every_value(capsys):
    """Table II with kp = 10 V/m and Kv = 0.7 m/(V s) (K0 = 7 1/s): every key."""
    assert main(["limits", "--w0", "32.97", "--zeta", "1.1", "--sample-time", "0.01",
                 "--kp", "10", "--kv", "0.7", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"k0", "continuous", "pct", "sampled", "sampled_delay",
                        "gain_margin", "phase_margin_deg", "w0", "zeta", "sample_time",
                        "pct_time_constant_s", "sampled_frequency_rad_s",
                        "sampled_delay_frequency_rad_s", "kv", "kp", "kp_limits"}
    _check_every_value(out, W0, ZETA, T, 7.0, 0.7)
    # the crossing of the undelayed Table II loop by hand: G(e^{j theta}) real and
    # negative; Im(N conj D) = 0 solved by brentq on python-control's polynomials
    from scipy.optimize import brentq
    num, den = _ref_discrete_loop(W0, ZETA, T)
    im = lambda th: np.imag(np.polyval(num, np.exp(1j * th))                # noqa: E731
                            * np.conj(np.polyval(den, np.exp(1j * th))))
    theta = brentq(im, 0.05, 3.0, xtol=1e-15)
    g = np.polyval(num, np.exp(1j * theta)) / np.polyval(den, np.exp(1j * theta))
    assert -1.0 / g.real == pytest.approx(out["sampled"], rel=1e-9)
    assert out["sampled_frequency_rad_s"] == pytest.approx(theta / T, rel=1e-9)


def test_cli_plant_json_every_value(capsys):
    """The situm plant at x = 0.25 m: w0, zeta, Kv from the exact tangent model
    (its nonzero eigenvalues p1, p2: w0^2 = p1 p2, 2 zeta w0 = -(p1 + p2); Kv =
    lim s G(s), evaluated at s = 1e-3 j, where the error is (1e-3 / 13.6)^2 ~ 1e-8),
    then every key against the model route's references."""
    assert main(["limits", str(SITUM), "--x", "0.25", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    plant = Plant.from_toml(SITUM)
    lin = linearize.tangent(plant, x=0.25)
    ev = np.linalg.eigvals(lin.A)
    p1, p2 = ev[np.abs(ev) > 1e-6]
    w0 = math.sqrt((p1 * p2).real)
    zeta = -(p1 + p2).real / (2 * w0)
    s = 1e-3j
    ix = list(lin.output_names).index("x")
    g = lin.C[ix] @ np.linalg.solve(s * np.eye(lin.A.shape[0]) - lin.A, lin.B[:, 0])
    kv = abs(s * g)
    # the reduced model is exact for this four-state drive: the fit reaches ~1e-9
    assert out["w0"] == pytest.approx(w0, rel=1e-7)
    assert out["zeta"] == pytest.approx(zeta, rel=1e-7)
    assert out["kv"] == pytest.approx(kv, rel=1e-6)
    kp = plant.params["controller.kp"]
    assert out["kp"] == kp and out["plant"] == str(SITUM) and out["x"] == 0.25
    assert out["notes"] == []                    # the file's controller is a P (kind = "p")
    _check_every_value(out, out["w0"], out["zeta"], out["sample_time"], kp * out["kv"],
                       out["kv"])
    assert out["sample_time"] == plant.params["controller.sample_time"]


def test_cli_plant_json_notes_a_non_p_controller(capsys):
    """The 25 mm rig's file has a PD controller: the JSON says the limits are for a P
    controller with its kp, and every limit, margin and frequency still follows from
    the written w0, zeta, T, kp and Kv (references of _check_every_value)."""
    rig = ROOT / "designs" / "plants" / "rig25_mpye.toml"
    assert main(["limits", str(rig), "--x", "0.25", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    prm = Plant.from_toml(rig).params
    assert prm["controller.kind"] == "pd"
    assert len(out["notes"]) == 1 and "pd" in out["notes"][0] and "P controller" in out["notes"][0]
    assert out["kp"] == pytest.approx(prm["controller.kp"], rel=1e-12)
    _check_every_value(out, out["w0"], out["zeta"], out["sample_time"],
                       prm["controller.kp"] * out["kv"], out["kv"])
