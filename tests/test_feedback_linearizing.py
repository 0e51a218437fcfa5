"""Feedback-linearising position controller: gains, reference model, the must-show,
refusal of infeasible bandwidths, and the design script in smoke mode."""

from __future__ import annotations

import json
import math
import runpy
from pathlib import Path

import numpy as np
import pytest

from workbench import Plant, simulate, validate
from workbench.controllers.base import DiscreteController
from workbench.controllers.feedback_linearizing import (SAMPLING_LIMIT, ReferenceModel,
                                                        error_gains, feedback_linearizing)
from workbench.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
AFFINE = ROOT / "tests" / "data" / "plants" / "input_affine.toml"
RIG = ROOT / "designs" / "plants" / "rig25_mpye.toml"


@pytest.fixture(scope="module")
def affine():
    return Plant.from_toml(AFFINE)


@pytest.mark.parametrize("integral", [False, True])
@pytest.mark.parametrize("damping", [1.0, 0.7])
def test_error_gains_place_the_poles(integral, damping):
    lam = 25.0
    g = error_gains(lam, damping, integral)
    coeffs = [1.0, g["k2"], g["k1"], g["k0"]] + ([g["ki"]] if integral else [])
    poles = np.sort_complex(np.roots(coeffs))
    pair = lam * np.array([-damping - 1j * math.sqrt(max(1 - damping ** 2, 0.0)),
                           -damping + 1j * math.sqrt(max(1 - damping ** 2, 0.0))])
    want = np.sort_complex(np.concatenate([np.full(2 if integral else 1, -lam), pair]))
    # repeated roots are ill-conditioned: a fourfold root moves by ~eps^(1/4) relative
    np.testing.assert_allclose(poles, want, atol=lam * 2e-3)


def test_reference_model_is_the_exact_sampled_triple_pole():
    lam, T = 25.0, 0.01
    rm = ReferenceModel(lam, 1.0, T)
    r = np.ones(80)
    st = rm.response(r, start=np.zeros(3))
    t = T * np.arange(80)
    exact = 1.0 - np.exp(-lam * t) * (1.0 + lam * t + (lam * t) ** 2 / 2.0)
    np.testing.assert_allclose(st[:, 0], exact, atol=1e-12)      # ZOH-exact for a held step
    np.testing.assert_allclose(st[:, 1], lam ** 3 * t ** 2 / 2.0 * np.exp(-lam * t), atol=1e-10)
    assert st[-1, 0] == pytest.approx(1.0, abs=1e-4)                 # unit DC gain


def test_controller_protocol(affine):
    fl = feedback_linearizing(affine, 20.0)
    assert isinstance(fl, DiscreteController)
    st = fl.reset()
    y = {"x": 0.25, "v": 0.0, "p_a": 4.455e5, "p_b": 4.455e5}
    st, u = fl.update(st, 0.25, y)
    assert u == pytest.approx(5.0, abs=1e-3)                     # at rest on target: centred


def test_must_show_follows_the_reference_model(affine):
    """Nominal plant with the controller's own valve law: |x - x_r| < 2 % of each step
    (seen: 0.3..0.65 % at 25 rad/s, T = 10 ms)."""
    ref = simulate.steps([0.25, 0.35, 0.15, 0.16, 0.25], hold=0.8)
    fl = feedback_linearizing(affine, 25.0, reference=ref)
    run = simulate.closed_loop(affine, fl, ref, x0=0.25)
    tk, xr = fl.reference_response(ref, ref.duration, x0=0.25)
    err = run["x"] - xr
    for seg in validate.find_segments(ref):
        if seg.kind != "step":
            continue
        sel = (tk >= seg.start - 1e-9) & (tk <= seg.end + 1e-9)
        assert np.max(np.abs(err[sel])) < 0.02 * abs(seg.size), seg.describe()


def test_refuses_bandwidth_beyond_the_sampling_limit(affine):
    T = affine.params["controller.sample_time"]
    with pytest.raises(InputError) as exc:
        feedback_linearizing(affine, 1.2 * SAMPLING_LIMIT / T)
    msg = str(exc.value)
    assert "sampling limit" in msg and "31.4 rad/s" in msg and "largest bandwidth" in msg


def test_refuses_bandwidth_the_valve_cannot_supply(affine):
    # at T = 1 ms the sampling limit is 314 rad/s: the valve's flow binds first
    with pytest.raises(InputError) as exc:
        feedback_linearizing(affine, 150.0, sample_time=0.001)
    msg = str(exc.value)
    assert "valve cannot supply" in msg and "g/s" in msg and "sampling" not in msg
    best = float(msg.rsplit("about ", 1)[1].split(" rad/s")[0])
    assert 30.0 < best < 150.0
    fl = feedback_linearizing(affine, 0.95 * best, sample_time=0.001)    # just below: accepted
    assert fl.design.feasible and fl.design.gamma_needed <= 0.8 * fl.design.gamma_available


def test_fl_design_smoke(tmp_path):
    mod = runpy.run_path(str(ROOT / "designs" / "fl_position.py"), run_name="design")
    rc = mod["main"](["--quick", "--out", str(tmp_path)])
    s = json.loads((tmp_path / "summary.json").read_text())
    assert rc == (0 if s["design_passed"] else 1) and s["design_passed"]
    assert s["must_show"]["worst_fraction"] < 0.02
    assert all("refused" in row[2] for row in s["refused"])
    assert set(s["metrics"]) == {"FL nominal", "PD nominal", "FL full", "PD full"}
    html = (tmp_path / "report.html").read_text()
    for heading in ("Feedback-linearising design", "Must-show", "Validation: FL vs PD", "Provenance"):
        assert heading in html
    assert (tmp_path / "report.pdf").read_bytes().startswith(b"%PDF")
