"""Issue 15: identification refuses what the data cannot support, fast, and the CLI
reads recordings as rigs write them (--columns, --window, no u column for arx)."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from workbench.cli import main
from workbench.errors import InputError
from workbench.identify.arx import fit_arx, validate
from workbench.identify.rls import rls
from workbench.recording import Recording


def _arx_data(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """y(k) = 0.8 y(k-1) + 0.5 u(k-1) + small noise, PRBS input."""
    rng = np.random.default_rng(seed)
    u = rng.choice([-1.0, 1.0], n)
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = 0.8 * y[k - 1] + 0.5 * u[k - 1] + 1e-3 * rng.standard_normal()
    return y, u


def test_rls_with_40_parameters_on_1001_samples_is_fast_and_right():
    # On 8c8e7dd this built a 40-parameter symbolic step for > 120 s.
    y, u = _arx_data(1001)
    start = time.perf_counter()
    res = rls(y, u, (20, 20, 1), forgetting=1.0, p0=1e4)
    elapsed = time.perf_counter() - start
    # 1001 samples x ~0.15 ms per sample with numpy; 20 s leaves room for a loaded CI
    # machine and is still 6x below what the symbolic build took.
    assert elapsed < 20.0, elapsed
    assert res.method == "numpy"
    # Independent check: with lambda = 1, RLS from theta0 = 0, P0 = p0 I is exactly the
    # regularised least-squares solution (Phi'Phi + I/p0)^-1 Phi'y on the same rows.
    na = nb = 20
    phi = np.array([np.concatenate([-y[k - na:k][::-1], u[k - nb:k][::-1]])
                    for k in range(na, 1001)])
    theta = np.linalg.solve(phi.T @ phi + np.eye(40) / 1e4, phi.T @ y[na:])
    # cond(Phi'Phi) ~ 1e3 here: 1e-9 is far above rounding, far below any real error
    np.testing.assert_allclose(res.theta[-1], theta, rtol=0, atol=1e-9)


def test_rls_casadi_with_too_many_parameters_is_refused_with_the_cost():
    y, u = _arx_data(200)
    with pytest.raises(InputError, match=r"method='casadi' with 40 parameters would spend "
                                         r"about \d+ s"):
        rls(y, u, (20, 20, 1), method="casadi")


def test_arx_validation_lags_beyond_the_data_are_refused():
    y, u = _arx_data(400)
    model = fit_arx(y, u, (1, 1, 1))
    with pytest.raises(InputError, match=r"lags = 1000000 is more than a quarter of the "
                                         r"399 residuals of these data; give at most 99"):
        validate(model, y, u, lags=1_000_000)
    assert validate(model, y, u, lags=99).lags[-1] == 99
    assert validate(model, y, u).lags[-1] == 25        # the default, unchanged


@pytest.fixture(scope="module")
def rig_file(tmp_path_factory):
    """A rig log: ms time, mm position, no u column; pressure p_a drives x."""
    y, u = _arx_data(600, seed=2)
    t_ms = np.arange(600) * 10.0                        # 100 Hz, ms
    p_a = 3.5e5 + 0.5e5 * u                             # Pa
    x_mm = 250.0 + 20.0 * y                             # mm
    path = tmp_path_factory.mktemp("rig") / "log.csv"
    rows = "".join(f"{a!r},{b!r},{c!r},\n" for a, b, c in zip(t_ms.tolist(), x_mm.tolist(),
                                                             p_a.tolist()))
    path.write_text("time_ms,pos_mm,p_a,\n" + rows)      # trailing delimiters, as loggers do
    return path


def test_cli_arx_with_column_mapping_and_no_u_column(rig_file, capsys):
    code = main(["identify", "arx", str(rig_file), "--input", "p_a", "--output", "x",
                 "--orders", "1", "1", "1", "--offset", "--columns",
                 "t=time_ms:ms,x=pos_mm:mm", "--json"])
    out = capsys.readouterr()
    assert code == 0, out.err
    result = json.loads(out.out)
    assert result["sample_time"] == pytest.approx(0.01, rel=1e-12)    # from ms
    # In SI: x = 0.25 m + 0.02 m * y, p_a = 3.5e5 Pa + 0.5e5 Pa * u, so a1 = -0.8 and
    # b1 = 0.5 * 0.02 / 0.5e5 = 2e-7 m/Pa. Equation noise 1e-3 of a unit signal on 300
    # samples: std(a1) ~ 2e-3, so 1e-2 and 2 % are > 5 sigma.
    assert result["a"][0] == pytest.approx(-0.8, abs=1e-2)
    assert result["b"][0] == pytest.approx(2e-7, rel=2e-2)


def test_cli_without_the_mapping_names_the_columns_and_the_option(rig_file, capsys):
    code = main(["identify", "arx", str(rig_file), "--input", "p_a", "--output", "x",
                 "--orders", "1", "1", "1"])
    err = capsys.readouterr().err
    assert code == 2
    assert "missing required columns 't', 'x'" in err and "--columns" in err


def test_cli_window_option(rig_file, capsys):
    code = main(["identify", "arx", str(rig_file), "--input", "p_a", "--output", "x",
                 "--orders", "1", "1", "1", "--columns", "t=time_ms:ms,x=pos_mm:mm",
                 "--window", "1:4", "--json"])
    out = capsys.readouterr()
    assert code == 0, out.err
    result = json.loads(out.out)
    assert result["n_estimation"] + result["n_validation"] == 301   # t = 1.00 .. 4.00 s
    with pytest.raises(SystemExit):
        main(["identify", "arx", str(rig_file), "--window", "4:1"])
