"""Recordings as they come from a rig (issue 12, point 4): jittered sample times and a
recorded supply pressure. (Position-only and open-loop recordings: test_diagnose_sets.py
and test_diagnose_failsafe.py; units: workbench.recording.)"""

from __future__ import annotations

import numpy as np
import pytest

from workbench import Plant
from workbench.diagnose import synth
from workbench.diagnose.data import prepare, recorded_supply, uniform
from workbench.recording import Recording


def test_jittered_sample_times_are_resampled_on_a_uniform_grid():
    """Logger times with +-30 % jitter around 1 ms: a smooth measured signal is
    interpolated within the linear-interpolation error h^2 |y''| / 8 (here
    (1.3 ms)^2 * 40 m/s^2 / 8 = 8.5 um), the command is held from the last sample at or
    before each grid time (a logger's output between updates)."""
    rng = np.random.default_rng(3)
    t = np.cumsum(np.r_[0.0, 1e-3 * (1 + rng.uniform(-0.3, 0.3, 3999))])
    x = 0.25 + 0.1 * np.sin(20 * t)                       # |x''| <= 40 m/s^2
    u = np.where(np.arange(len(t)) % 10 < 5, 5.2, 4.8)
    rec = Recording.from_arrays(t, u=u, x=x)
    out = uniform(rec, 1e-3)
    tg = np.asarray(out.t)
    assert np.allclose(np.diff(tg), 1e-3, rtol=1e-9)
    assert np.max(np.abs(out["x"] - (0.25 + 0.1 * np.sin(20 * tg)))) < 8.5e-6
    held = u[np.searchsorted(t, tg, side="right") - 1]
    assert np.array_equal(out["u"], held)


def test_prepare_resamples_and_says_so():
    case = synth.concealed_case("none", seed=1)
    rec = synth.record(case, seed=1, duration=3.0)
    rng = np.random.default_rng(0)
    t = np.asarray(rec.t) + rng.uniform(-2e-4, 2e-4, len(rec))
    t[0] = 0.0
    cols = {k: np.asarray(rec[k]) for k in rec.columns if k != "t"}
    prep = prepare(case.nominal_plant, Recording.from_arrays(t, **cols))
    assert any("resampled on a uniform 1 ms grid" in n for n in prep.notes), prep.notes
    assert prep.dt == pytest.approx(1e-3, rel=1e-3)


def test_recorded_supply_pressure_is_used_and_a_sag_is_noted():
    """p_s recorded at 5.6 bar on a plant file saying 6 bar: the diagnosis uses 5.6 bar
    (the median) and says so; a p_s dipping by 0.4 bar under flow is named as a sag."""
    plant = synth.concealed_case("none", seed=1).nominal_plant
    t = np.arange(1000) * 1e-3
    flat = Recording.from_arrays(t, u=np.full_like(t, 5.0), x=np.full_like(t, 0.2),
                                 p_s=np.full_like(t, 5.6e5))
    p2, notes = recorded_supply(plant, flat)
    assert p2.params["supply.pressure"] == pytest.approx(5.6e5)
    assert any("5.6 bar" in n for n in notes) and not any("sags" in n for n in notes)
    sag = 5.6e5 - 0.4e5 * (np.sin(10 * t) > 0.5)
    _, notes = recorded_supply(plant, Recording.from_arrays(t, u=np.full_like(t, 5.0),
                                                            x=np.full_like(t, 0.2), p_s=sag))
    assert any("sags under flow" in n for n in notes), notes
    same, notes = recorded_supply(plant, Recording.from_arrays(t, u=t, x=t))
    assert same is plant and notes == []
